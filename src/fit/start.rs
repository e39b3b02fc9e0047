//! Starting points from the empirical NDF's slope distribution, in closed form.
//!
//! Every model here is a stretched isotropic slope distribution (Heitz eq. 88-90): in the principal frame
//! `s' = Rz(theta_z) s`, the marginal of `s'_x / alpha_x` is a fixed distribution, so the median of
//! `|s'_x|` is `alpha_x` times a constant:
//! - Beckmann: the marginal is normal with variance 1/2 (Heitz eq. 82), median `|t|` = 0.476936;
//! - GGX: the marginal density is `(1/2)(1 + t^2)^(-3/2)` (P22 of Heitz eq. 85 integrated over the other
//!   slope), whose CDF gives `P(|t| < T) = T / sqrt(1 + T^2)`, so the median `|t|` is `1/sqrt(3)`.
//!
//! Medians, not variances: the GGX slope variance is infinite. `theta_z` comes from the eigenvectors of
//! the (bounded) covariance of the normals' tangential components, which share the principal axes.
//! The ellipsoid's skew starts from the mean normal direction (the peak of a narrow lobe lies along the
//! ellipsoid's third axis, row 3 of R in Walter et al. eq. 3).

use rayon::prelude::*;

use super::objective::{Bin, FitData};
use crate::models::table::{Kernel, L1};
use crate::models::{ModelId, Role};

/// Median `|t|` of the unit Beckmann marginal: `0.6744898 / sqrt(2)`.
const BECKMANN_MEDIAN: f64 = 0.476_936_276_204_47;
/// Median `|t|` of the unit GGX marginal: `1 / sqrt(3)`.
const GGX_MEDIAN: f64 = 0.577_350_269_189_625_8;
/// Smallest starting alpha: a lobe narrower than this is reached by LM from above in a few steps.
const START_ALPHA_MIN: f64 = 1e-3;

/// Weighted median of `(value, weight)` pairs: the first value, in ascending order, at which the
/// cumulative weight reaches half the total (the values are reordered in place).
///
/// By quickselect, O(n) (a full sort was a tenth of a 1024^2 ellipsoid fit): each partition keeps the
/// side where the cumulative weight crosses one half. The partitioned order is an ascending order, so
/// the crossing value is the sorted one's; with integer counts as weights every partial sum is exact,
/// so the result is bit-identical to sorting.
fn weighted_median(v: &mut [(f64, f64)]) -> f64 {
    let total: f64 = v.iter().map(|p| p.1).sum();
    // Guard: no positive finite weight (not expected: the bins have counts); the largest value, as a
    // scan of the sorted values that never crosses the half would give.
    if !(total > 0.0 && total.is_finite()) {
        return v.iter().map(|p| p.0).max_by(f64::total_cmp).unwrap_or(0.0);
    }
    let half = 0.5 * total;
    let cmp = |a: &(f64, f64), b: &(f64, f64)| a.0.total_cmp(&b.0);
    let mut before = 0.0;
    // The largest value seen above the crossing side, returned should rounding leave no crossing.
    let mut fallback = v.iter().map(|p| p.0).max_by(f64::total_cmp).unwrap_or(0.0);
    let mut s = v;
    while s.len() > 16 {
        let mid = s.len() / 2;
        let (left, pivot, right) = s.select_nth_unstable_by(mid, cmp);
        let wl: f64 = left.iter().map(|p| p.1).sum();
        if before + wl >= half {
            fallback = pivot.0;
            s = left;
        } else if before + wl + pivot.1 >= half {
            return pivot.0;
        } else {
            before += wl + pivot.1;
            s = right;
        }
    }
    s.sort_by(cmp);
    let mut acc = before;
    for &(x, w) in s.iter() {
        acc += w;
        if acc >= half {
            return x;
        }
    }
    s.last().map_or(fallback, |p| p.0)
}

/// Summary of the data used for starting points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlopeSummary {
    /// `theta_z` of the principal frame (local x axis = major axis).
    pub theta_z: f64,
    /// Median `|s'_x|`, `|s'_y|` in the principal frame.
    pub median_abs: [f64; 2],
    /// Median radial slope `|s|`.
    pub median_radial: f64,
    /// Count-weighted mean normal (unit).
    pub mean_normal: [f64; 3],
}

/// The slope summary of the bins (count-weighted, each bin at its central direction).
pub fn summarize(data: &FitData) -> SlopeSummary {
    let (mut sw, mut mx, mut my, mut mz) = (0.0, 0.0, 0.0, 0.0);
    for b in &data.bins {
        sw += b.c;
        mx += b.c * b.m.x;
        my += b.c * b.m.y;
        mz += b.c * b.m.z;
    }
    let (mx, my, mz) = (mx / sw, my / sw, mz / sw);
    let (mut cxx, mut cxy, mut cyy) = (0.0, 0.0, 0.0);
    for b in &data.bins {
        let (dx, dy) = (b.m.x - mx, b.m.y - my);
        cxx += b.c * dx * dx;
        cxy += b.c * dx * dy;
        cyy += b.c * dy * dy;
    }
    // Major axis angle phi of the 2x2 covariance; the local frame m' = Rz(theta_z) m puts it on x
    // when theta_z = -phi.
    let phi = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    let tz = -phi;
    let (s, c) = tz.sin_cos();
    // The bins with counts, in bin order; each median's list is made on every thread in that order,
    // and the three medians are independent: side by side.
    let counted: Vec<&Bin> = data.bins.iter().filter(|b| b.c > 0.0).collect();
    let slope = |b: &Bin| (-b.m.x / b.m.z, -b.m.y / b.m.z);
    let median_of = |f: &(dyn Fn((f64, f64)) -> f64 + Sync)| {
        let mut v: Vec<(f64, f64)> = counted.par_iter().map(|b| (f(slope(b)), b.c)).collect();
        weighted_median(&mut v)
    };
    let norm = (mx * mx + my * my + mz * mz).sqrt();
    let ((mx_med, my_med), rad_med) = rayon::join(
        || rayon::join(|| median_of(&|(sx, sy)| (c * sx - s * sy).abs()), || median_of(&|(sx, sy)| (s * sx + c * sy).abs())),
        || median_of(&|(sx, sy)| sx.hypot(sy)),
    );
    SlopeSummary { theta_z: tz, median_abs: [mx_med, my_med], median_radial: rad_med, mean_normal: [mx / norm, my / norm, mz / norm] }
}

/// The closed-form starting point (contract parameters) of any model, by its parameters' roles: the
/// first lobe's kernel sets the medians' constant, the skew angles start at 0 (see [`skew_start`]), a
/// Student-t tail at GGX's `gamma = 2`; a mixture starts with a core a little narrower than the median slopes
/// say and a tail three times wider, weighted 0.7 : 0.3.
pub fn closed_form(id: ModelId, s: &SlopeSummary) -> Vec<f64> {
    let spec = id.spec();
    let beck = spec.lobes[0].kernel == Kernel::Beckmann;
    let k = if beck { 1.0 / BECKMANN_MEDIAN } else { 1.0 / GGX_MEDIAN };
    // Radial median: GGX P(|s| < R) = 1 - 1/(1 + R^2/a^2) gives R = a; Beckmann 1 - exp(-R^2/a^2)
    // gives R = a sqrt(ln 2).
    let iso = if beck { s.median_radial / std::f64::consts::LN_2.sqrt() } else { s.median_radial };
    // The floor scales both alphas together: flooring each one alone would turn a narrow anisotropic
    // lobe into an isotropic start, from which theta_z is undetermined and LM stalls at alpha_x = alpha_y.
    let (ax, ay) = (k * s.median_abs[0], k * s.median_abs[1]);
    let lift = (START_ALPHA_MIN / ax.min(ay)).max(1.0);
    let (ax, ay) = if lift.is_finite() { (ax * lift, ay * lift) } else { (START_ALPHA_MIN, START_ALPHA_MIN) };
    let two = spec.is_mixture();
    spec.roles
        .iter()
        .map(|&(role, lobes)| {
            let scale = match (two, lobes) {
                (false, _) => 1.0,
                (true, L1) => 0.7,
                (true, _) => 3.0,
            };
            match role {
                Role::Alpha if two => scale * (ax * ay).sqrt(),
                Role::Alpha => iso.max(START_ALPHA_MIN),
                Role::AlphaX => scale * ax,
                Role::AlphaY => scale * ay,
                Role::ThetaX | Role::ThetaY => 0.0,
                Role::ThetaZ => s.theta_z,
                Role::Gamma => 2.0,
                Role::Weight => 0.7,
            }
        })
        .collect()
}

/// `(theta_x, theta_y)` that put the ellipsoid's third axis along the mean normal, given `theta_z`:
/// row 3 of `R = Rx Ry Rz` is `w^T Rz` with `w = (-cx sy, sx, cx cy)`, so `w = Rz(theta_z) p`.
pub fn skew_start(s: &SlopeSummary, theta_z: f64) -> (f64, f64) {
    let [px, py, pz] = s.mean_normal;
    let (sn, cs) = theta_z.sin_cos();
    let w = [cs * px - sn * py, sn * px + cs * py, pz];
    let tx = w[1].clamp(-1.0, 1.0).asin();
    let ty = (-w[0]).atan2(w[2]);
    (tx, ty)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The reference: sort, then scan the cumulative weight (the definition).
    fn by_sorting(v: &[(f64, f64)]) -> f64 {
        let mut v = v.to_vec();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let total: f64 = v.iter().map(|p| p.1).sum();
        let mut acc = 0.0;
        for &(x, w) in &v {
            acc += w;
            if acc >= 0.5 * total {
                return x;
            }
        }
        v.last().map_or(0.0, |p| p.0)
    }

    /// Quickselect equals the sorted definition bit for bit, with integer counts as weights, many ties
    /// (values on a coarse grid) and sizes around the small-slice cutoff.
    #[test]
    fn weighted_median_equals_sorting() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for n in [1usize, 2, 3, 15, 16, 17, 33, 100, 1000, 5000] {
            for ties in [false, true] {
                let v: Vec<(f64, f64)> = (0..n)
                    .map(|_| {
                        let x: f64 = rng.random_range(0.0..1.0);
                        let x = if ties { (x * 10.0).floor() } else { x };
                        (x, rng.random_range(1..50) as f64)
                    })
                    .collect();
                let want = by_sorting(&v);
                let got = weighted_median(&mut v.clone());
                assert_eq!(got.to_bits(), want.to_bits(), "n {n} ties {ties}");
            }
        }
    }
}
