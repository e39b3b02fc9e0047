//! Shared by the accuracy examples: the parts of a synthetic cap's fit error that no fit region removes
//! (data_formats/objective.md, "What the core leaves").

// Each example uses a part of it.
#![allow(dead_code)]

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{Model, ModelId, Ndf};
use ndfit::ndf::EmpiricalNdf;
use ndfit::ndf::QuadOrder;
use ndfit::synth::EllipsoidGeometry;
use ndfit::synth::SynthSettings;

/// The ellipsoid fit's NDF error against `truth` under `tail`, or NaN when the fit fails.
pub fn fit_error(ndf: &EmpiricalNdf, truth: &Model, tail: TailRule) -> f64 {
    fit_model(ndf, ModelId::Ellipsoid, &FitOptions { tail, ..FitOptions::default() })
        .and_then(|r| r.to_model())
        .ok()
        .and_then(|m| delta_to_model(&m, truth))
        .unwrap_or(f64::NAN)
}

/// `ndf` with its counts replaced by the truth's bin integrals (`integral of D (m.n) dw` over each cell,
/// Walter et al. eq. 1), scaled to a thousand times its sample count and rounded, the unresolved counts
/// scaled alike (so the tail rule decides as on the scan): data with no sampling at all, whose fit
/// error is the midpoint rule's on these bins.
pub fn bin_integral_counts(ndf: &EmpiricalNdf, truth: &Model) -> EmpiricalNdf {
    let mut out = ndf.clone();
    let n = 1000.0 * ndf.n_samples as f64;
    for k in 0..ndf.bins.len() {
        let t = ndf.bin_integral(k, QuadOrder::Fine(4), |m| truth.d(m)).unwrap_or(0.0);
        out.bins[k].count = (t * n).round() as u64;
    }
    out.unresolved.iter_mut().for_each(|u| *u *= 1000);
    out
}

/// `ndf` with its counts replaced by the bins of the exact slopes (Walter et al. eq. 15, 22) of the cap
/// `g` on the grid of `s` shifted by `(a, b)` steps; the unresolved counts are kept (the rule decides
/// as on the scan).
pub fn shifted_lattice_counts(ndf: &EmpiricalNdf, g: &EllipsoidGeometry, s: &SynthSettings, a: f64, b: f64) -> EmpiricalNdf {
    let mut cnt = vec![0u64; ndf.grid.cells()];
    for i in 0..s.ny {
        for j in 0..s.nx {
            if let Some(v) = g.slope(s.xc(j) + a * s.dx, s.yc(i) + b * s.dy) {
                cnt[ndf.grid.cell_of(ndf.frame.to_lambert(v[0], v[1]))] += 1;
            }
        }
    }
    let mut out = ndf.clone();
    for (bin, &c) in out.bins.iter_mut().zip(&ndf.bin_cells) {
        bin.count = cnt[c as usize];
    }
    out
}

/// The core fit's error over the 16 lattice phases (quarter steps along each axis) of the exact slopes:
/// `(min, median, max)`.
pub fn phase_spread(ndf: &EmpiricalNdf, g: &EllipsoidGeometry, s: &SynthSettings, truth: &Model) -> (f64, f64, f64) {
    let mut e: Vec<f64> = (0..16)
        .map(|k| fit_error(&shifted_lattice_counts(ndf, g, s, (k % 4) as f64 / 4.0, (k / 4) as f64 / 4.0), truth, TailRule::Core))
        .collect();
    e.sort_by(f64::total_cmp);
    (e[0], 0.5 * (e[7] + e[8]), e[15])
}

/// `nd` with every bin beyond whitened Lambert radius `pmax` marked unresolved (and the share set low
/// enough for the rule to apply), so that `TailRule::Unresolved` fits exactly the disc `|p| <= pmax`.
pub fn cut_beyond_radius(nd: &EmpiricalNdf, pmax: f64) -> EmpiricalNdf {
    let mut o = nd.clone();
    o.unresolved_share = Some(0.01);
    o.unresolved = o
        .bins
        .iter()
        .map(|b| {
            let q = nd.frame.to_lambert(-b.m.x / b.m.z, -b.m.y / b.m.z);
            if q[0].hypot(q[1]) > pmax {
                b.count + 1
            } else {
                0
            }
        })
        .collect();
    o
}
