//! Spike removal (`data_formats/objective.md`, "Spikes"): isolated height outliers (optical spikes, single
//! bad pixels) are masked (set invalid), never replaced.
//!
//! A valid point with all 8 neighbours valid ([`MIN_NEIGHBOURS`]; the rim of the data is not tested, where a smooth surface ends steeply) is a spike when its
//! height departs from the median `m` of those neighbours by more than [`SPIKE_THRESHOLD`] times their
//! own spread, `1.4826 median |h_n - m|` (the Gaussian-consistent MAD), floored by the scan's typical
//! departure (the same statistic's median over the scan) and by the height quantum. A smooth surface,
//! however steep, keeps every point: on a quadratic patch the departure is at most about twice the
//! neighbours' spread, and a plane's is zero. The median of 8 neighbours is unmoved by a second spike
//! among them, so pairs are found too.

use rayon::prelude::*;

use crate::ndf::bands::{bands_of, Band, BandSource};
use crate::ndf::HeightRows;
use crate::scan::Scan;

/// Departure from the neighbours' median, in units of their spread, beyond which a point is a spike.
pub const SPIKE_THRESHOLD: f64 = 30.0;
/// Fewest valid neighbours (of 8) for a point to be tested.
pub const MIN_NEIGHBOURS: usize = 8;
/// Gaussian-consistent MAD factor.
const MAD_NORMAL: f64 = 1.482_602_218_505_602;

/// Whether to remove spikes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Despike {
    /// The median test of this module (default).
    #[default]
    Median,
    /// Keep every point.
    None,
}

/// What the despiking did (the fit JSON's `input.despike`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DespikeReport {
    /// `median`.
    pub method: String,
    /// Points masked.
    pub masked: usize,
    /// Of them, above their neighbours (the rest below).
    pub masked_high: usize,
    /// Why: the rule in one line.
    pub rule: String,
    /// The spread floor used (metres).
    pub floor: f64,
}

/// Per point: `Some((departure, spread))` when the point is valid with enough valid neighbours.
fn departure(z: &Band<'_, f64>, nx: usize, ny: usize, i: usize, j: usize) -> Option<(f64, f64)> {
    let c = z.row(i)[j];
    if !c.is_finite() {
        return None;
    }
    let mut nb = [0.0f64; 8];
    let mut k = 0;
    for di in -1i64..=1 {
        for dj in -1i64..=1 {
            if di == 0 && dj == 0 {
                continue;
            }
            let (ii, jj) = (i as i64 + di, j as i64 + dj);
            if ii < 0 || jj < 0 || ii >= ny as i64 || jj >= nx as i64 {
                continue;
            }
            let v = z.row(ii as usize)[jj as usize];
            if v.is_finite() {
                nb[k] = v;
                k += 1;
            }
        }
    }
    if k < MIN_NEIGHBOURS {
        return None;
    }
    let nb = &mut nb[..k];
    nb.sort_by(|a, b| a.total_cmp(b));
    let med = if k % 2 == 1 { nb[k / 2] } else { 0.5 * (nb[k / 2 - 1] + nb[k / 2]) };
    let mut dev: [f64; 8] = [0.0; 8];
    for (d, v) in dev.iter_mut().zip(nb.iter()) {
        *d = (v - med).abs();
    }
    let dev = &mut dev[..k];
    dev.sort_by(|a, b| a.total_cmp(b));
    let mad = if k % 2 == 1 { dev[k / 2] } else { 0.5 * (dev[k / 2 - 1] + dev[k / 2]) };
    Some((c - med, MAD_NORMAL * mad))
}

/// Points sampled (strided) for the scan's typical departure, the spread floor.
const FLOOR_SAMPLE: usize = 1 << 16;

/// Mask the spikes of `hf` (module documentation). Returns the report; `Despike::None` does nothing.
pub fn despike(hf: &mut Scan<'_>, how: Despike) -> Option<DespikeReport> {
    let (spikes, report) = find_spikes(&*hf, how, hf.meta.height_quantum)?;
    for k in spikes {
        hf.z[k] = f64::NAN;
    }
    Some(report)
}

/// The spikes of the heights `src` ([`despike`]) as sorted flat indices `i * nx + j`, with the report,
/// without writing the heights: the heights are read in bands of rows (each with the rows around it),
/// so they can be a mapped file or residuals computed band by band. `quantum`: the height quantum (a
/// floor of the spread).
pub fn find_spikes<S: BandSource<T = f64>>(src: &S, how: Despike, quantum: Option<f64>) -> Option<(Vec<usize>, DespikeReport)> {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    if how == Despike::None || nx < 3 || ny < 3 {
        return None;
    }
    let bands: Vec<std::ops::Range<usize>> = bands_of(0..ny, src.band_rows()).collect();
    // The floor: the median departure (Gaussian-consistent) over a strided sample of the scan (its
    // relative standard error is about 1 / sqrt(2^16): the threshold moves by under 1%), and the quantum.
    let stride = ((nx * ny) / FLOOR_SAMPLE).max(1);
    let mut all: Vec<f64> = bands
        .par_iter()
        .flat_map_iter(|b| {
            let mut buf = Vec::new();
            let z = src.band(b.start.saturating_sub(1), (b.end + 1).min(ny), &mut buf);
            let first = (b.start * nx).next_multiple_of(stride);
            (first..b.end * nx)
                .step_by(stride)
                .filter_map(|k| departure(&z, nx, ny, k / nx, k % nx))
                .map(|d| d.0.abs())
                .collect::<Vec<f64>>()
        })
        .collect();
    let typical = if all.is_empty() {
        0.0
    } else {
        let mid = all.len() / 2;
        MAD_NORMAL * *all.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    };
    let floor = typical.max(quantum.unwrap_or(0.0));
    let limit = SPIKE_THRESHOLD * floor;
    // Exact pre-screen: the median lies between the neighbours' extremes, so a point within `limit` of
    // both cannot depart by more than the threshold (which is at least `limit`).
    let spikes: Vec<(usize, bool)> = bands
        .par_iter()
        .flat_map_iter(|b| {
            let mut out = Vec::new();
            let mut buf = Vec::new();
            let z = src.band(b.start.saturating_sub(1), (b.end + 1).min(ny), &mut buf);
            for i in b.start.max(1)..b.end.min(ny - 1) {
                let (r0, r1, r2) = (z.row(i - 1), z.row(i), z.row(i + 1));
                for j in 1..nx - 1 {
                    let c = r1[j];
                    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                    for r in [r0, r1, r2] {
                        for v in &r[j - 1..j + 2] {
                            lo = lo.min(*v);
                            hi = hi.max(*v);
                        }
                    }
                    if c - lo <= limit && hi - c <= limit {
                        continue;
                    }
                    if let Some((d, s)) = departure(&z, nx, ny, i, j) {
                        if d.abs() > SPIKE_THRESHOLD * s.max(floor) && d.abs() > 0.0 {
                            out.push((i * nx + j, d > 0.0));
                        }
                    }
                }
            }
            out
        })
        .collect();
    let high = spikes.iter().filter(|s| s.1).count();
    let report = DespikeReport {
        method: "median".into(),
        masked: spikes.len(),
        masked_high: high,
        rule: format!(
            "a height more than {SPIKE_THRESHOLD} times the spread of its 8 neighbours (1.4826 MAD, at least {floor:.3e} m) from their median"
        ),
        floor,
    };
    Some((spikes.into_iter().map(|s| s.0).collect(), report))
}
