//! Measurement tool (not a test): the pieces of `auto`'s render choice on one scan, each timed as the
//! median of `REPEATS` runs (default 7): the table's projected area, the renders of the table and of the
//! answer's lobe in both default scenes (alone and in one pass, as the choice renders them), HDR-FLIP's prepared reference and one score against it. It prints
//! the scores in full so that two builds can be compared for equal values.
//! `cargo run --release --example time_render -- SCAN` (without SCAN, the scan of
//! `ndfit bench --process --work-dir bench_out/work`);
//! `RENDER=broad` (or `point`) renders that scene's table and lobe ten times and stops, `ONLY=point` (or
//! `broad`) scores its FLIP thirty times and stops: loops for `perf record`.

use std::time::Instant;

use ndfit::answer::choice::{default_scenes, prepare, RenderJudge, RenderOptions, ScanBrdf, TableAndLobe, DEFAULT_MATERIAL};
use ndfit::export::rgl::{AnalyticBrdf, ProjectedArea, Regularized};
use ndfit::flip::RgbImage;
use ndfit::render::Image;

/// The process's CPU time so far (s, every thread).
fn cpu() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a live local the call fills.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// The median wall and CPU times of `n` runs of `f` (seconds) and its last result.
fn timed<T>(n: usize, mut f: impl FnMut() -> T) -> (Time, T) {
    let (mut wall, mut busy) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut last = None;
    for _ in 0..n {
        let (t, c) = (Instant::now(), cpu());
        last = Some(f());
        wall.push(t.elapsed().as_secs_f64());
        busy.push(cpu() - c);
    }
    wall.sort_by(f64::total_cmp);
    busy.sort_by(f64::total_cmp);
    (Time { wall: wall[n / 2], cpu: busy[n / 2] }, last.expect("at least one run"))
}

/// A median wall time and CPU time (s).
struct Time {
    wall: f64,
    cpu: f64,
}

impl std::fmt::Display for Time {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:.4} s ({:.4} CPU)", self.wall, self.cpu)
    }
}

fn rgb(i: &Image) -> RgbImage {
    RgbImage::new(i.width, i.height, i.data.clone()).expect("finite")
}

fn main() -> ndfit::Result<()> {
    let path = std::env::args().nth(1).unwrap_or_else(|| "bench_out/work/x3p_1024_deflated/scan000.x3p".into());
    let n: usize = std::env::var("REPEATS").ok().and_then(|s| s.parse().ok()).unwrap_or(7).max(1);
    let options = ndfit::Options { model: ndfit::ModelChoice::Auto, ..ndfit::Options::default() };
    let pipeline = ndfit::Pipeline::new(options.clone());
    let (_, ndf) = pipeline.ndf_path(std::path::Path::new(&path))?;
    let render = RenderOptions::default();
    let judge = RenderJudge::new(&ndf, render.clone());
    let (t_choice, report) = timed(1, || {
        let mut r = ndfit::fit::fit_auto_with(&ndf, &options.fit_options(), &judge)?;
        judge.apply(&mut r, &path).map(|_| r)
    });
    let report = report?;
    let lobe = report.to_model()?;
    let filler = report.table_model()?;
    let max_theta = report.quality.max_theta_deg;
    println!(
        "{path}: answer {:?}, lobe {}, table filled by {}",
        report.selection.as_ref().and_then(|s| s.answer.clone()),
        lobe.id(),
        filler.id()
    );
    println!("ladder with the render choice (once, cold): {t_choice}");

    let reg = Regularized::new(&ndf, &filler, max_theta);
    let (t_area, area) = timed(n, || ProjectedArea::new(&|m| reg.d(m), 64, 32, true));
    let area = area?;
    println!("projected area of the table: {t_area}");
    let table = ScanBrdf { reg: &reg, area: &area, material: DEFAULT_MATERIAL };
    let analytic = AnalyticBrdf { model: lobe, material: DEFAULT_MATERIAL };
    for s in default_scenes() {
        println!("evaluations: table {}, lobe {}", count(&s.scene, &table), count(&s.scene, &analytic));
        let (t_table, ti) = timed(n, || s.scene.render(&table));
        let (t_lobe, li) = timed(n, || s.scene.render(&analytic));
        let (ti, li) = (ti?, li?);
        // Both in one pass, as the choice renders the table and its first lobe.
        let (t_both, both) = timed(n, || s.scene.render_set(&TableAndLobe { table, lobe: analytic }));
        let [bt, bl] = both?;
        assert!(bt == ti && bl == li, "the renders in one pass differ from the renders alone");
        if std::env::var("RENDER").is_ok_and(|v| v == s.name) {
            // Profile one scene's renders alone (`RENDER=broad perf record ...`).
            for _ in 0..10 {
                s.scene.render(&table)?;
                s.scene.render(&analytic)?;
            }
            return Ok(());
        }
        if std::env::var("ONLY").is_ok_and(|v| v == s.name) {
            // Profile one scene's FLIP alone (`ONLY=point perf record ...`).
            for _ in 0..30 {
                prepare(&ti)?.mean(&rgb(&li))?;
            }
            return Ok(());
        }
        let (t_prep, reference) = timed(n, || prepare(&ti));
        let reference = reference?;
        let (t_mean, mean) = timed(n, || reference.mean(&rgb(&li)));
        println!(
            "{:>5}: render table {t_table}, lobe {t_lobe}, both in one pass {t_both}; FLIP reference {t_prep}, mean {t_mean}; FLIP {:.15}",
            s.name, mean?
        );
    }
    Ok(())
}

/// How many BRDF evaluations a render of `scene` takes.
fn count(scene: &ndfit::render::Stage, brdf: &dyn ndfit::render::Brdf) -> usize {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let n = AtomicUsize::new(0);
    let f = |wi: nalgebra::Vector3<f64>, wo: nalgebra::Vector3<f64>| {
        n.fetch_add(1, Ordering::Relaxed);
        brdf.eval(wi, wo)
    };
    scene.render(&f).unwrap();
    n.into_inner()
}
