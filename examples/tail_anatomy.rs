//! Measurement tool (not a test): what the hard-end error of the `core` rule is made of. For one cap
//! (`CASE` index into the hard-end set, `N` grid), the NDF counted from central differences, from the exact
//! slopes at the same samples, and from the exact slopes at `K x K` sub-samples of every pixel (the
//! continuous truth up to the midpoint rule); the core-region fit error of each; and the residuals of the
//! central counts against the dense ones, by whitened Lambert radius and azimuth; the core fit's error
//! over `p_max`, over 16 phases of the sample lattice, of the 2 x 2- and 3 x 3-merged counts (by EM), and
//! behind a 45-degree aperture.
//!
//!     CASE=1 cargo run --release --example tail_anatomy

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{ModelId, Ndf};
use ndfit::ndf::{empirical_ndf, EmpiricalNdf, NdfOptions};
use ndfit::synth::EllipsoidGeometry;
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings, HARD_END_SET};

#[path = "support/floor.rs"]
mod floor;

/// `ndf` with its counts replaced by those of `slopes` weighted by `w` each (same bins, frame and `W`).
fn recount(ndf: &EmpiricalNdf, slopes: &[[f64; 2]], w: f64) -> EmpiricalNdf {
    let mut cnt = vec![0f64; ndf.grid.cells()];
    for s in slopes {
        cnt[ndf.grid.cell_of(ndf.frame.to_lambert(s[0], s[1]))] += w;
    }
    let mut out = ndf.clone();
    for (b, &c) in out.bins.iter_mut().zip(&ndf.bin_cells) {
        b.count = cnt[c as usize].round() as u64;
    }
    out
}

fn env(k: &str, d: usize) -> usize {
    std::env::var(k).ok().map(|s| s.parse().expect(k)).unwrap_or(d)
}

fn main() {
    let (case, n, k) = (env("CASE", 1), env("N", 1024), env("K", 8));
    let p: [f64; 5] = std::env::var("P").ok().map_or(HARD_END_SET[case], |s| {
        let v: Vec<f64> = s.split(',').map(|t| t.parse().expect("P")).collect();
        [v[0], v[1], v[2], v[3], v[4]]
    });
    let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
    let s = SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() };
    let (hf, truth) = ellipsoid_surface(&s, &ep).unwrap();
    let g = EllipsoidGeometry::new(&ep, &s).unwrap();
    let truth = truth.to_model().unwrap();
    let cells = std::env::var("CELLS").ok().map(|s| s.parse().expect("CELLS"));
    let ndf = empirical_ndf(&hf, &NdfOptions { cells_across: cells, ..NdfOptions::default() }).unwrap();
    // ROT=deg: the bins of the same whitening turned by that angle further (W' = R W; the default frame is
    // already turned by `SlopeFrame::grid_turn`, so ROT=-22.5 on a theta_z = 0 cap gives the symmetric W).
    let rot = std::env::var("ROT").ok().map(|s| s.parse::<f64>().expect("ROT").to_radians());
    let turned = |nd: EmpiricalNdf, h: &ndfit::Heightfield| match rot {
        None => nd,
        Some(t) => {
            let mut f = nd.frame;
            let (sn, cs) = t.sin_cos();
            let (w, u) = (f.whiten, f.unwhiten);
            f.whiten =
                [[cs * w[0][0] - sn * w[1][0], cs * w[0][1] - sn * w[1][1]], [sn * w[0][0] + cs * w[1][0], sn * w[0][1] + cs * w[1][1]]];
            f.unwhiten =
                [[u[0][0] * cs - u[0][1] * sn, u[0][0] * sn + u[0][1] * cs], [u[1][0] * cs - u[1][1] * sn, u[1][0] * sn + u[1][1] * cs]];
            empirical_ndf(h, &NdfOptions { cells_across: cells, frame: Some(f), ..NdfOptions::default() }).unwrap()
        }
    };
    let ndf = turned(ndf, &hf);
    println!("{p:?} {n}^2: grid {} cells across, {} bins, {} samples", ndf.grid.n, ndf.bins.len(), ndf.n_samples);
    // Sample rows per bin along each grid axis through the footprint's centre: the cell side over the
    // step of the whitened Lambert point between neighbouring samples, near the lobe's centre and at |p| = 1.
    for (name, along_y) in [("columns (x)", false), ("rows (y)", true)] {
        let (mut at0, mut at1) = ((f64::INFINITY, 0.0), (f64::INFINITY, 0.0));
        for t in 1..n - 1 {
            let pt = |u: usize| {
                let (x, y) = if along_y { (s.xc(n / 2), s.yc(u)) } else { (s.xc(u), s.yc(n / 2)) };
                g.slope(x, y).map(|v| ndf.frame.to_lambert(v[0], v[1]))
            };
            let (Some(a), Some(b)) = (pt(t), pt(t + 1)) else { continue };
            let (r, step) = (a[0].hypot(a[1]), (b[0] - a[0]).hypot(b[1] - a[1]));
            if r < at0.0 {
                at0 = (r, ndf.grid.h / step);
            }
            if (r - 1.0).abs() < (at1.0 - 1.0f64).abs() {
                at1 = (r, ndf.grid.h / step);
            }
        }
        println!("  samples per bin along the {name}: {:.1} at |p| {:.2}, {:.1} at |p| {:.2}", at0.1, at0.0, at1.1, at1.0);
    }
    let z = |i: usize, j: usize| hf.z[i * n + j];
    let (mut same, mut dense) = (Vec::new(), Vec::new());
    for i in 0..n {
        for j in 0..n {
            if let Some(sl) = g.slope(s.xc(j), s.yc(i)) {
                if i >= 1 && j >= 1 && i + 1 < n && j + 1 < n && !(z(i, j - 1) + z(i, j + 1) + z(i - 1, j) + z(i + 1, j)).is_nan() {
                    same.push(sl);
                }
            }
            for a in 0..k {
                for b in 0..k {
                    let (x, y) =
                        (s.xc(j) + ((a as f64 + 0.5) / k as f64 - 0.5) * s.dx, s.yc(i) + ((b as f64 + 0.5) / k as f64 - 0.5) * s.dy);
                    if let Some(sl) = g.slope(x, y) {
                        dense.push(sl);
                    }
                }
            }
        }
    }
    // Dense counts scaled to the sample count (rounded: the fit takes integer counts).
    let scale = same.len() as f64 / dense.len() as f64;
    let ex = recount(&ndf, &same, 1.0);
    let de = recount(&ndf, &dense, scale);
    let de_big = recount(&ndf, &dense, 1.0);
    let fit = |nd: &EmpiricalNdf, tail: TailRule| {
        let r = fit_model(nd, ModelId::Ellipsoid, &FitOptions { tail, ..FitOptions::default() }).unwrap();
        100.0 * delta_to_model(&r.to_model().unwrap(), &truth).unwrap()
    };
    let integ = floor::bin_integral_counts(&ndf, &truth);
    let mut mid = ndf.clone();
    mid.unresolved.iter_mut().for_each(|u| *u *= 1000);
    for b in mid.bins.iter_mut() {
        b.count = (truth.d(b.m) * b.proj_solid_angle * 1000.0 * same.len() as f64).round() as u64;
    }
    for (name, nd) in [("central", &ndf), ("exact same", &ex), ("dense (scaled)", &de), ("bin integrals", &integ), ("midpoint", &mid)] {
        println!("  {name:>16}: core {:.3}%  all {:.3}%", fit(nd, TailRule::Core), fit(nd, TailRule::All));
    }
    let cutr = |nd: &EmpiricalNdf, pmax: f64| fit(&floor::cut_beyond_radius(nd, pmax), TailRule::Unresolved);
    for pm in [0.8, 0.9, 1.0, 1.1] {
        println!("   p_max {pm}: central {:.3}% exact {:.3}% integrals {:.3}%", cutr(&ndf, pm), cutr(&ex, pm), cutr(&integ, pm));
    }
    let (lo, med, hi) = floor::phase_spread(&ndf, &g, &s, &truth);
    println!("  16 lattice phases (exact slopes, core): min {:.3}% median {:.3}% max {:.3}%", 100.0 * lo, 100.0 * med, 100.0 * hi);
    // The Poisson likelihood of the 2 x 2-merged counts with the fine bins' midpoint model, by EM: each
    // block's count is shared among its fine bins in proportion to the current fit's D(m_k) W_k.
    let em = |nd: &EmpiricalNdf, iters: usize, block: usize| -> Vec<f64> {
        let nn = nd.grid.n;
        let blk = |k: usize| {
            let c = nd.bin_cells[k] as usize;
            ((c / nn) / block) * nn + (c % nn) / block
        };
        let mut work = nd.clone();
        for b in work.bins.iter_mut() {
            b.count *= 1000;
        }
        work.unresolved.iter_mut().for_each(|u| *u *= 1000);
        let mut out = Vec::new();
        for _ in 0..iters {
            let r = fit_model(&work, ModelId::Ellipsoid, &FitOptions::default()).unwrap();
            let m = r.to_model().unwrap();
            out.push(100.0 * delta_to_model(&m, &truth).unwrap());
            let mut tot_c = std::collections::HashMap::new();
            let mut tot_e = std::collections::HashMap::new();
            for k in 0..nd.bins.len() {
                let e = m.d(nd.bins[k].m) * nd.bins[k].proj_solid_angle;
                *tot_c.entry(blk(k)).or_insert(0.0) += nd.bins[k].count as f64;
                *tot_e.entry(blk(k)).or_insert(0.0) += e;
            }
            for k in 0..nd.bins.len() {
                let e = m.d(nd.bins[k].m) * nd.bins[k].proj_solid_angle;
                let (c, t) = (tot_c[&blk(k)], tot_e[&blk(k)]);
                work.bins[k].count = if t > 0.0 { (1000.0 * c * e / t).round() as u64 } else { 0 };
            }
        }
        out
    };
    println!("  EM 2x2: {:?}", em(&ndf, 6, 2).iter().map(|e| format!("{e:.3}")).collect::<Vec<_>>());
    println!("  EM 3x3: {:?}", em(&ndf, 6, 3).iter().map(|e| format!("{e:.3}")).collect::<Vec<_>>());
    // Behind an aperture of 45 degrees (points whose central-difference slope exceeds 1 are dropouts), the
    // fit over max_theta 45: the scan, the truth's bin integrals on its bins, and 16 lattice phases of the
    // exact slopes (those steeper than 1 dropped) on its bins.
    let mut nah = hf.clone();
    for i in 1..n - 1 {
        for j in 1..n - 1 {
            let sx = (hf.z[i * n + j + 1] - hf.z[i * n + j - 1]) / (2.0 * hf.dx);
            let sy = (hf.z[(i + 1) * n + j] - hf.z[(i - 1) * n + j]) / (2.0 * hf.dy);
            if sx.hypot(sy) > 1.0 {
                nah.z[i * n + j] = f64::NAN;
            }
        }
    }
    let nandf = turned(empirical_ndf(&nah, &NdfOptions::default()).unwrap(), &nah);
    let o45 = FitOptions { max_theta: 45f64.to_radians(), ..FitOptions::default() };
    let fit45 = |nd: &EmpiricalNdf| {
        let r = fit_model(nd, ModelId::Ellipsoid, &o45).unwrap();
        100.0 * delta_to_model(&r.to_model().unwrap(), &truth).unwrap()
    };
    let integ45 = floor::bin_integral_counts(&nandf, &truth);
    let mut na = Vec::new();
    for a in 0..4 {
        for b in 0..4 {
            let mut sl = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    if let Some(v) = g.slope(s.xc(j) + a as f64 * s.dx / 4.0, s.yc(i) + b as f64 * s.dy / 4.0) {
                        if v[0].hypot(v[1]) <= 1.0 {
                            sl.push(v);
                        }
                    }
                }
            }
            na.push(fit45(&recount(&nandf, &sl, 1.0)));
        }
    }
    na.sort_by(f64::total_cmp);
    println!(
        "  NA 45 ({} cells, {} samples): scan {:.3}%  bin integrals {:.3}%  16 lattice phases min {:.3}% median {:.3}% max {:.3}%",
        nandf.grid.n,
        nandf.n_samples,
        fit45(&nandf),
        fit45(&integ45),
        na[0],
        0.5 * (na[7] + na[8]),
        na[15]
    );
    // Residuals c - E against the dense counts, in the core, by radius band and azimuth sector.
    let cos_max = 70f64.to_radians().cos();
    let cut = ndfit::fit::tail_cut(&ndf, cos_max, TailRule::Core);
    let region: Vec<usize> = (0..ndf.bins.len())
        .filter(|&i| ndfit::fit::usable(&ndf.bins[i]) && ndf.bins[i].m.z >= cos_max * ndf.bins[i].m.norm() && !cut.excludes(&ndf, i))
        .collect();
    let nc: f64 = region.iter().map(|&i| ndf.bins[i].count as f64).sum();
    let nd: f64 = region.iter().map(|&i| de_big.bins[i].count as f64).sum();
    let nt: f64 = region.iter().map(|&i| truth.d(ndf.bins[i].m) * ndf.bins[i].proj_solid_angle).sum();
    println!("  region: {} bins, {} normals", region.len(), nc);
    println!("  band   sector  bins  sum c   bias vs dense  chi2/bin vs dense  bias vs midpoint-truth  chi2/bin vs truth");
    for band in 0..5 {
        for sec in 0..4 {
            let (mut nb, mut sc, mut se, mut chi, mut st, mut chit) = (0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for &i in &region {
                let b = &ndf.bins[i];
                let q = ndf.frame.to_lambert(-b.m.x / b.m.z, -b.m.y / b.m.z);
                let r = q[0].hypot(q[1]);
                let az = q[1].atan2(q[0]).rem_euclid(std::f64::consts::PI);
                let s4 = ((az / std::f64::consts::FRAC_PI_4 + 0.5) as usize) % 4;
                if (r * 5.0) as usize != band || s4 != sec {
                    continue;
                }
                let c = b.count as f64;
                let e = de_big.bins[i].count as f64 * nc / nd;
                let et = truth.d(b.m) * b.proj_solid_angle * nc / nt;
                nb += 1;
                sc += c;
                se += e;
                st += et;
                chi += (c - e).powi(2) / e.max(1.0);
                chit += (c - et).powi(2) / et.max(1.0);
            }
            if nb > 0 {
                println!(
                    "  {:.1}-{:.1}  {:>3}deg  {nb:>4}  {sc:>7.0}  {:>+8.3}%  {:>8.2}  {:>+8.3}%  {:>8.2}",
                    band as f64 / 5.0,
                    (band + 1) as f64 / 5.0,
                    sec * 45,
                    100.0 * (sc - se) / se,
                    chi / nb as f64,
                    100.0 * (sc - st) / st,
                    chit / nb as f64
                );
            }
        }
    }
    let w = ndf.frame.whiten;
    println!("  whiten {w:?}");
}
