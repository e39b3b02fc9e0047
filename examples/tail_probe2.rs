use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid::EllipsoidParams, ellipsoid_surface, SynthSettings};

fn main() {
    let cases = [
        [0.35, 0.05, 0.16, 0.0, 0.3],
        [0.2, 0.02, 0.0, 0.4, 0.0],
        [0.05, 0.05, 0.4, 0.0, 0.0],
        [0.3, 0.3, 0.0, 0.0, 0.0],
    ];
    let n: usize = std::env::var("N").ok().map(|s| s.parse().unwrap()).unwrap_or(1024);
    for p in cases {
        let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, _) = ellipsoid_surface(&SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() }, &ep).unwrap();
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).unwrap();
        let mut v = ndfit::ndf::resolution::sample_errors(&hf, &ndf.frame);
        v.sort_by(|a, b| b.0.total_cmp(&a.0));
        println!("{p:?} n {}", v.len());
        for q in [0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5] {
            let k = (q * v.len() as f64) as usize;
            let lo = (k as f64 * 0.8) as usize;
            let seg = &v[lo..k.max(lo + 1)];
            let mut rel: Vec<f64> = seg.iter().map(|x| x.1 / x.0.max(1e-9)).collect();
            rel.sort_by(|a, b| a.total_cmp(b));
            let inf = seg.iter().filter(|x| x.1.is_infinite()).count() as f64 / seg.len() as f64;
            println!("  q {q}: r {:.2} rel err median {:.2e} p90 {:.2e} unknown {:.2}", v[k].0, rel[rel.len() / 2], rel[rel.len() * 9 / 10], inf);
        }
    }
}
