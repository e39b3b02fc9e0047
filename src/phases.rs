//! Wall-clock phases of one command, to find what stays serial on a many-core machine
//! (docs/PERFORMANCE.md, "Scaling with cores"). Off unless the environment sets `NDFIT_PHASES`; then
//! each [`phase`] guard records its name and span, and the binary prints them on standard error when
//! it ends ([`take`]). Off, a guard costs one initialized-once load.

use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// One recorded phase, in milliseconds since the first use of this module in the process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// The phase's name (`read`, `ndf.histogram`, ...).
    pub name: &'static str,
    /// When it began.
    pub start_ms: f64,
    /// How long it took.
    pub ms: f64,
}

/// The clock's origin and the spans recorded, when `NDFIT_PHASES` is set.
fn state() -> Option<&'static (Instant, Mutex<Vec<Span>>)> {
    static STATE: OnceLock<Option<(Instant, Mutex<Vec<Span>>)>> = OnceLock::new();
    STATE.get_or_init(|| std::env::var_os("NDFIT_PHASES").map(|_| (Instant::now(), Mutex::new(Vec::new())))).as_ref()
}

/// Whether phases are recorded (also starts the clock: call it first thing).
pub fn enabled() -> bool {
    state().is_some()
}

/// A running phase: recorded when dropped.
#[derive(Debug)]
pub struct Phase {
    name: &'static str,
    t0: Instant,
}

/// Time `name` until the returned guard is dropped; `None` (nothing recorded) when phases are off.
pub fn phase(name: &'static str) -> Option<Phase> {
    state().map(|_| Phase { name, t0: Instant::now() })
}

impl Drop for Phase {
    fn drop(&mut self) {
        if let Some((origin, spans)) = state() {
            let span = Span {
                name: self.name,
                start_ms: self.t0.duration_since(*origin).as_secs_f64() * 1e3,
                ms: self.t0.elapsed().as_secs_f64() * 1e3,
            };
            spans.lock().unwrap_or_else(|e| e.into_inner()).push(span);
        }
    }
}

/// The spans recorded so far, by start (empty when phases are off), and the milliseconds since the
/// origin; the record is emptied.
pub fn take() -> (Vec<Span>, f64) {
    let Some((origin, spans)) = state() else { return (Vec::new(), 0.0) };
    let mut v = std::mem::take(&mut *spans.lock().unwrap_or_else(|e| e.into_inner()));
    v.sort_by(|a, b| a.start_ms.total_cmp(&b.start_ms));
    (v, origin.elapsed().as_secs_f64() * 1e3)
}
