//! A fit does not depend on the thread count: its per-bin work (`ln D`, its gradient, the residuals, the
//! quality metrics) runs on rayon's threads, but every sum over bins is taken in bin order and the best
//! start is the first of the lowest in the starts' order. Checked bit for bit: the same fits, from the
//! same NDF, in a one-thread pool (every pass serial, the reference) and in a five-thread pool.

use ndfit::fit::{fit_auto, fit_model, FitOptions, FitReport};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, gaussian_surface, EllipsoidParams, GaussianParams, SynthSettings};

/// The report as JSON without its timings (the one field that may differ).
fn json(r: &FitReport) -> serde_json::Value {
    let mut v = serde_json::to_value(r).expect("report serializes");
    v.as_object_mut().expect("an object").remove("timings");
    v
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool").install(f)
}

#[test]
fn fits_are_the_same_bit_for_bit_on_one_thread_and_on_five() {
    let s = SynthSettings { nx: 400, ny: 400, seed: 11, noise: 2e-9, ..SynthSettings::default() };
    let skewed = EllipsoidParams { alpha_x: 0.35, alpha_y: 0.15, theta_x: 0.2, theta_y: -0.1, theta_z: 0.5, ..EllipsoidParams::default() };
    let cap = ellipsoid_surface(&s, &skewed).expect("synth").0;
    let rough = GaussianParams { sigma_x: 0.25, sigma_y: 0.12, theta_z: 0.3, ..GaussianParams::default() };
    let gauss = gaussian_surface(&s, &rough).expect("synth").0;
    for (name, hf) in [("ellipsoid cap", &cap), ("gaussian surface", &gauss)] {
        let ndf = empirical_ndf(hf, &NdfOptions { cells_across: Some(121), ..NdfOptions::default() }).expect("ndf");
        // Enough bins for several tasks of the residual pass, and the merged-bin first pass.
        assert!(ndf.bins.len() > 4000, "{name}: {} bins", ndf.bins.len());
        let opts = FitOptions::default();
        let fits = |threads: usize| {
            in_pool(threads, || {
                let mut out: Vec<(String, serde_json::Value)> =
                    [ModelId::GgxAniso, ModelId::Ellipsoid, ModelId::Ggx2, ModelId::StudentAniso]
                        .iter()
                        .map(|&id| (id.to_string(), json(&fit_model(&ndf, id, &opts).expect("fit"))))
                        .collect();
                out.push(("auto".into(), json(&fit_auto(&ndf, &opts).expect("auto"))));
                out
            })
        };
        let (one, five) = (fits(1), fits(5));
        for ((id, a), (_, b)) in one.iter().zip(&five) {
            assert_eq!(a, b, "{name}: {id} differs between one thread and five");
        }
    }
}
