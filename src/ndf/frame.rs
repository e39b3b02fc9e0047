//! The data-adapted frame of the binning: a robust centre and covariance of the slopes, the whitening
//! that maps them to a unit-scale isotropic cloud, and the Lambert azimuthal equal-area map of the
//! whitened ("stretched") normals onto the disk of radius `sqrt(2)`.
//!
//! Slopes follow Heitz eq. 61-62: `s = grad h = -(m_x, m_y) / m_z`, so `m = (-s, 1) / sqrt(1 + |s|^2)`
//! (the contract's `m = (-dh/dx, -dh/dy, 1) / |...|`). Whitening is the non-axis-aligned stretch of slope
//! space of Heitz eq. 88-89 (a symmetric positive-definite quadric) plus the vertical shear of Heitz
//! sec. 5.3 ("non-centered distributions"); both are affine in slope space, so every bin's projected
//! solid angle follows in closed form from the Jacobians below.

use nalgebra::Vector3;

/// Smallest slope scale (standard deviation, dimensionless) the whitening accepts. A perfect plane has a
/// zero slope covariance (a delta NDF); without a floor the whitening would divide by zero. 1e-7 is three
/// decades below the smallest model roughness [`crate::models::ALPHA_MIN`] = 1e-4, so any surface a model
/// can describe is still resolved by many bins, while a plane lands in the single bin at the centre.
pub const SLOPE_SCALE_FLOOR: f64 = 1e-7;

/// Largest ratio of the two principal slope scales the whitening keeps. Scans whose slopes vary along one
/// axis only (a 1D grating) have a singular covariance; the floor keeps the map invertible. It also
/// bounds how narrowly the hemisphere outside the data is squeezed around the small axis at the rim
/// (angular width `1 / MAX_ANISOTROPY`), which the bin quadrature resolves. A stronger anisotropy is
/// still binned correctly, with the small axis resolved at most 100 times finer than the large one.
pub const MAX_ANISOTROPY: f64 = 100.0;

/// Gaussian-consistent factor: IQR of a standard normal (`2 * 0.6744897501960817`).
const IQR_NORMAL: f64 = 1.348_979_500_392_163_5;

/// Radius of the Lambert disk the hemisphere maps onto.
pub const LAMBERT_RADIUS: f64 = std::f64::consts::SQRT_2;

/// Where the bin grid puts the image of the sample lattice's axes: at this angle from its rows and
/// columns (modulo 45 degrees), by the turn `R(t)` of the frame's whitening `W = R(t) Sigma^(-1/2)` (any
/// `R W` whitens as well); see [`SlopeFrame::grid_turn`] for `t`. 22.5 degrees is midway between the
/// grid's axes and its diagonals, and `tan(22.5 deg) = sqrt 2 - 1` has the continued fraction
/// `[0; 2, 2, 2, ...]`: no short lattice vector lies near a bin row, so no row of samples runs along a
/// row of bins (the moire of a narrow lobe, objective.md "What the core leaves").
pub const LATTICE_IMAGE_ANGLE: f64 = std::f64::consts::FRAC_PI_8;

/// A centred, whitened frame of slope space: `s' = W (s - c)` with `W = R(t) Sigma^(-1/2)`
/// ([`SlopeFrame::grid_turn`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlopeFrame {
    /// Robust centre `c` of the slopes (coordinate-wise median), `grad h` convention of Heitz eq. 61.
    pub center: [f64; 2],
    /// Robust covariance `Sigma` of the slopes (Gaussian-consistent: IQR / 1.349 per axis and the
    /// Gnanadesikan-Kettenring identity for the correlation), after the floors.
    pub cov: [[f64; 2]; 2],
    /// Whitening `W = R(t) Sigma^(-1/2)` (`W Sigma W^T = I`; [`SlopeFrame::grid_turn`]).
    pub whiten: [[f64; 2]; 2],
    /// Its inverse `Sigma^(1/2) R(-t)`.
    pub unwhiten: [[f64; 2]; 2],
    /// `det Sigma^(1/2)`, the Jacobian `d^2 s / d^2 s'`.
    pub det_unwhiten: f64,
}

impl SlopeFrame {
    /// A frame from a centre and a covariance; the covariance's eigenvalues are floored by
    /// `SLOPE_SCALE_FLOOR` and `MAX_ANISOTROPY`.
    pub fn new(center: [f64; 2], cov: [[f64; 2]; 2]) -> Self {
        let (a, b, c) = (cov[0][0], 0.5 * (cov[0][1] + cov[1][0]), cov[1][1]);
        // Eigen-decomposition of the symmetric 2x2 matrix in closed form.
        let mean = 0.5 * (a + c);
        let half = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (l1, l2) = (mean + half, mean - half);
        let phi = 0.5 * (2.0 * b).atan2(a - c);
        let (sn, cs) = phi.sin_cos();
        // Floors: see the constants' comments (a plane, a 1D grating). Non-finite input falls to the floor.
        let floor = SLOPE_SCALE_FLOOR * SLOPE_SCALE_FLOOR;
        let l1 = if l1.is_finite() { l1.max(floor) } else { floor };
        let l2 = if l2.is_finite() { l2.max(floor).max(l1 / (MAX_ANISOTROPY * MAX_ANISOTROPY)) } else { l1 };
        let (r1, r2) = (l1.sqrt(), l2.sqrt());
        // M = V diag(d1, d2) V^T with V = [[cs, -sn], [sn, cs]].
        let sym =
            |d1: f64, d2: f64| [[cs * cs * d1 + sn * sn * d2, cs * sn * (d1 - d2)], [cs * sn * (d1 - d2), sn * sn * d1 + cs * cs * d2]];
        let center = if center[0].is_finite() && center[1].is_finite() { center } else { [0.0, 0.0] };
        // W = R S^-1 and U = S R^T with S = Sigma^(1/2) symmetric, R = [[ct, -st], [st, ct]].
        let (w, u) = (sym(1.0 / r1, 1.0 / r2), sym(r1, r2));
        let (st, ct) = Self::grid_turn(u).sin_cos();
        let whiten =
            [[ct * w[0][0] - st * w[1][0], ct * w[0][1] - st * w[1][1]], [st * w[0][0] + ct * w[1][0], st * w[0][1] + ct * w[1][1]]];
        let unwhiten =
            [[u[0][0] * ct - u[0][1] * st, u[0][0] * st + u[0][1] * ct], [u[1][0] * ct - u[1][1] * st, u[1][0] * st + u[1][1] * ct]];
        SlopeFrame { center, cov: sym(l1, l2), whiten, unwhiten, det_unwhiten: r1 * r2 }
    }

    /// The turn `t` of the whitening `W = R(t) Sigma^(-1/2)` for `Sigma^(1/2)` = `root` (symmetric).
    ///
    /// Derivation: on a lobe the slopes are an affine image of the positions, `s = c + H x` with `H` the
    /// height's Hessian (symmetric); a cap (Walter et al. sec. 4, the surfaces that give the ellipsoid NDF)
    /// covers the footprint `x^T H x <= r^2`, over which the positions have `Cov(x) ~ H^-1`, so
    /// `Sigma = H Cov(x) H ~ H`. A lattice step `e` (a sample row or column) then moves the symmetrically
    /// whitened slope by `Sigma^(-1/2) H e ~ Sigma^(1/2) e`: the images of the lattice's axes are the
    /// columns of `Sigma^(1/2)`, at the angles `g_x`, `g_y`. With `theta_z = 0` (or any round lobe) they
    /// are the grid's axes, the case of the moire; with a strong anisotropy both lie near the principal
    /// axis `-theta_z`, so no constant turn suits every `theta_z`. `t` puts the images' mean direction
    /// modulo 45 degrees (the circular mean of `8 g`, divided by 8) at `LATTICE_IMAGE_ANGLE`.
    pub fn grid_turn(root: [[f64; 2]; 2]) -> f64 {
        let (gx, gy) = (root[1][0].atan2(root[0][0]), root[1][1].atan2(root[0][1]));
        let (sy, sx) = ((8.0 * gx).sin() + (8.0 * gy).sin(), (8.0 * gx).cos() + (8.0 * gy).cos());
        // Guard: images exactly 22.5 degrees apart (mod 45) have no mean; any turn is as good, keep gx's.
        let mid = if sx.hypot(sy) > 1e-9 { sy.atan2(sx) / 8.0 } else { gx };
        let t = LATTICE_IMAGE_ANGLE - mid;
        if t.is_finite() {
            t
        } else {
            LATTICE_IMAGE_ANGLE
        }
    }

    /// The robust frame of a sample of slopes (any order; the slice is reordered). An empty sample gives
    /// the floor frame at the origin.
    pub fn robust(samples: &mut [[f64; 2]]) -> Self {
        if samples.is_empty() {
            return SlopeFrame::new([0.0, 0.0], [[0.0, 0.0], [0.0, 0.0]]);
        }
        let mut col: Vec<f64> = samples.iter().map(|s| s[0]).collect();
        let (cx, sx) = median_and_scale(&mut col);
        col.clear();
        col.extend(samples.iter().map(|s| s[1]));
        let (cy, sy) = median_and_scale(&mut col);
        // Correlation by the Gnanadesikan-Kettenring identity on standardized coordinates:
        // rho = (S(u+v)^2 - S(u-v)^2) / (S(u+v)^2 + S(u-v)^2), robust scale S = IQR/1.349.
        // Guard: a zero scale (more than half the slopes identical on an axis) means no usable correlation.
        let rho = if sx > 0.0 && sy > 0.0 {
            col.clear();
            col.extend(samples.iter().map(|s| (s[0] - cx) / sx + (s[1] - cy) / sy));
            let sp = median_and_scale(&mut col).1;
            col.clear();
            col.extend(samples.iter().map(|s| (s[0] - cx) / sx - (s[1] - cy) / sy));
            let sm = median_and_scale(&mut col).1;
            let den = sp * sp + sm * sm;
            if den > 0.0 {
                ((sp * sp - sm * sm) / den).clamp(-1.0, 1.0)
            } else {
                0.0
            }
        } else {
            0.0
        };
        let cxy = rho * sx * sy;
        SlopeFrame::new([cx, cy], [[sx * sx, cxy], [cxy, sy * sy]])
    }

    /// Whitened slope `s' = W (s - c)`.
    #[inline(always)]
    pub fn to_whitened(&self, sx: f64, sy: f64) -> [f64; 2] {
        let (dx, dy) = (sx - self.center[0], sy - self.center[1]);
        let w = &self.whiten;
        [w[0][0] * dx + w[0][1] * dy, w[1][0] * dx + w[1][1] * dy]
    }

    /// The Lambert point `p` of a slope: `p = sqrt(2 / (1 + m'_z)) (m'_x, m'_y)` for the stretched normal
    /// `m' = (s', 1) / sqrt(1 + |s'|^2)` (sign convention aside, an orientation-preserving relabelling).
    /// With `t = 1 + |s'|^2` this is `p = s' sqrt(2 / (t + sqrt t))`: two square roots, no trigonometry.
    #[inline(always)]
    pub fn to_lambert(&self, sx: f64, sy: f64) -> [f64; 2] {
        let w = self.to_whitened(sx, sy);
        let t = 1.0 + w[0] * w[0] + w[1] * w[1];
        if t < 1e300 {
            let k = (2.0 / (t + t.sqrt())).sqrt();
            [w[0] * k, w[1] * k]
        } else {
            // Guard: |s'| beyond 1e150 (or infinite) would overflow t; such a slope is on the rim.
            rim_direction(w)
        }
    }

    /// The stretched normal `(m'_x, m'_y, m'_z)` at a Lambert point `p` (inverse equal-area map):
    /// `m'_z = 1 - |p|^2 / 2`, `m'_xy = p sqrt(1 - |p|^2 / 4)`.
    #[inline]
    pub fn stretched_at(p: [f64; 2]) -> [f64; 3] {
        let r2 = (p[0] * p[0] + p[1] * p[1]).min(2.0);
        let k = (1.0 - 0.25 * r2).max(0.0).sqrt();
        [p[0] * k, p[1] * k, 1.0 - 0.5 * r2]
    }

    /// The unnormalized normal `(-(c m'_z + U m'_xy), m'_z)` in the scan frame for a stretched normal
    /// (`U = Sigma^(1/2)`): the slope is `s = c + U m'_xy / m'_z`, and scaling by `m'_z` keeps it finite
    /// on the rim (`m'_z = 0`).
    #[inline]
    fn scan_vector(&self, ms: [f64; 3]) -> [f64; 3] {
        let u = &self.unwhiten;
        let gx = self.center[0] * ms[2] + u[0][0] * ms[0] + u[0][1] * ms[1];
        let gy = self.center[1] * ms[2] + u[1][0] * ms[0] + u[1][1] * ms[1];
        [-gx, -gy, ms[2]]
    }

    /// The unit normal in the scan frame at a Lambert point `p`.
    pub fn normal_at(&self, p: [f64; 2]) -> Vector3<f64> {
        let v = self.scan_vector(Self::stretched_at(p));
        Vector3::new(v[0], v[1], v[2]).normalize()
    }

    /// Density of projected solid angle with respect to `d^2 p` at `p`:
    /// `dW/d^2p = det(U) m'_z / (m'_z^2 + |c m'_z + U m'_xy|^2)^2`.
    ///
    /// Derivation: `dW = m_z dw = m_z^4 d^2 s` (slope space, Heitz eq. 64 with `d^2 s = dw / m_z^3`),
    /// `d^2 s = det(U) d^2 s'`, `d^2 s' = dw' / m'_z^3`, and the Lambert map is equal-area (`dw' = d^2 p`);
    /// `m_z^4 = m'_z^4 / (m'_z^2 + |c m'_z + U m'_xy|^2)^2`. The form is regular on the rim `m'_z = 0`.
    #[inline]
    pub fn proj_density(&self, p: [f64; 2]) -> f64 {
        let ms = Self::stretched_at(p);
        let v = self.scan_vector(ms);
        let q = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        if q > 0.0 {
            self.det_unwhiten * ms[2] / (q * q)
        } else {
            0.0
        }
    }

    /// Density of solid angle with respect to `d^2 p`: `dw/d^2p = det(U) / (m'_z^2 + |c m'_z + U m'_xy|^2)^(3/2)`
    /// (same derivation, `dw = m_z^3 d^2 s`).
    #[inline]
    pub fn solid_density(&self, p: [f64; 2]) -> f64 {
        let v = self.scan_vector(Self::stretched_at(p));
        let q = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        if q > 0.0 {
            self.det_unwhiten / (q * q.sqrt())
        } else {
            0.0
        }
    }

    /// Both densities at once, `(dW/d^2p, dw/d^2p)` ([`SlopeFrame::proj_density`],
    /// [`SlopeFrame::solid_density`]), sharing the normal's computation.
    #[inline]
    pub fn densities(&self, p: [f64; 2]) -> (f64, f64) {
        let ms = Self::stretched_at(p);
        let v = self.scan_vector(ms);
        let q = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        // Guard: q = 0 cannot happen for |m'| = 1 but rounding at the rim; the densities vanish there.
        if q > 0.0 {
            (self.det_unwhiten * ms[2] / (q * q), self.det_unwhiten / (q * q.sqrt()))
        } else {
            (0.0, 0.0)
        }
    }

    /// [`SlopeFrame::densities`] without a branch (the guard is a select), so that loops over nodes
    /// vectorize.
    #[inline(always)]
    pub fn densities_branch_free(&self, p: [f64; 2]) -> (f64, f64) {
        let ms = Self::stretched_at(p);
        let v = self.scan_vector(ms);
        let q = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        // Guard: q = 0 only by rounding on the rim, where both densities vanish (as in `densities`).
        let ok = q > 0.0;
        let qs = if ok { q } else { 1.0 };
        let (dw, dom) = (self.det_unwhiten * ms[2] / (qs * qs), self.det_unwhiten / (qs * qs.sqrt()));
        (if ok { dw } else { 0.0 }, if ok { dom } else { 0.0 })
    }

    /// The rim zone of this frame for the bin quadrature ([`super::grid::RimShape`]).
    pub fn rim_shape(&self) -> super::grid::RimShape {
        let (a, b, c) = (self.cov[0][0], self.cov[0][1], self.cov[1][1]);
        let half = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (lmax, lmin) = (0.5 * (a + c) + half, (0.5 * (a + c) - half).max(0.0));
        // The squeezed direction of whitened (= Lambert) coordinates is where |U d| is smallest: the
        // eigenvector of U^T U (= R Sigma R^T, same eigenvalues) of the small eigenvalue, i.e. the angle
        // of the major axis plus 90 degrees. From U itself, so any whitening `R Sigma^(-1/2)` is followed.
        let u = &self.unwhiten;
        let (ma, mb, mc) =
            (u[0][0] * u[0][0] + u[1][0] * u[1][0], u[0][0] * u[0][1] + u[1][0] * u[1][1], u[0][1] * u[0][1] + u[1][1] * u[1][1]);
        let axis = 0.5 * (2.0 * mb).atan2(ma - mc) + std::f64::consts::FRAC_PI_2;
        super::grid::RimShape { ring: self.ring_scale(), axis, width: (lmin / lmax).sqrt(), core: 1.0 / lmax.sqrt() }
    }

    /// Width, in `u = m'_z`, of the rim zone of the Lambert disk where [`SlopeFrame::proj_density`] and
    /// [`SlopeFrame::solid_density`] change fast: the whole hemisphere outside the data's few whitened
    /// standard deviations is squeezed into `u < ring`. From `q = u^2 + |c u + U m'_xy|^2`, the
    /// transition sits at `u ~ |U m'_xy| / (1 + |c|) >= sqrt(lambda_min(Sigma)) / (1 + |c|)`.
    pub fn ring_scale(&self) -> f64 {
        let (a, b, c) = (self.cov[0][0], self.cov[0][1], self.cov[1][1]);
        let lmin = 0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let lmin = lmin.max(SLOPE_SCALE_FLOOR * SLOPE_SCALE_FLOOR);
        lmin.sqrt() / (1.0 + self.center[0].hypot(self.center[1]))
    }

    /// The slope (`grad h`) of a scan-frame normal with `m_z > 0`.
    pub fn slope_of(m: Vector3<f64>) -> [f64; 2] {
        [-m.x / m.z, -m.y / m.z]
    }
}

/// The rim point in the direction of a huge whitened slope.
#[cold]
fn rim_direction(w: [f64; 2]) -> [f64; 2] {
    if w[0].is_nan() || w[1].is_nan() {
        return [0.0, 0.0];
    }
    // Scale first so that the norm cannot overflow; infinite components become +-1.
    let (x, y) = if w[0].is_infinite() || w[1].is_infinite() {
        (inf_unit(w[0]), inf_unit(w[1]))
    } else {
        let big = w[0].abs().max(w[1].abs());
        (w[0] / big, w[1] / big)
    };
    let r = (x * x + y * y).sqrt();
    if r > 0.0 {
        [LAMBERT_RADIUS * x / r, LAMBERT_RADIUS * y / r]
    } else {
        [0.0, 0.0]
    }
}

fn inf_unit(v: f64) -> f64 {
    if v.is_infinite() {
        v.signum()
    } else {
        0.0
    }
}

/// Median and Gaussian-consistent IQR scale of `v` (reordered in place). Empty input gives `(0, 0)`.
fn median_and_scale(v: &mut [f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let n = v.len();
    let idx = |f: f64| ((f * (n - 1) as f64).round() as usize).min(n - 1);
    let (k1, k2, k3) = (idx(0.25), idx(0.5), idx(0.75));
    // One selection of the median splits the slice; the quartiles are then selected within the halves
    // (half the work of three selections over the whole slice, same order statistics).
    let med = *v.select_nth_unstable_by(k2, |a, b| a.total_cmp(b)).1;
    let q1 = if k1 < k2 { *v[..k2].select_nth_unstable_by(k1, |a, b| a.total_cmp(b)).1 } else { med };
    let q3 = if k3 > k2 { *v[k2 + 1..].select_nth_unstable_by(k3 - k2 - 1, |a, b| a.total_cmp(b)).1 } else { med };
    (med, ((q3 - q1) / IQR_NORMAL).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Lambert map sends the stretched normal to p with |p|^2 = 2 (1 - m'_z) (equal-area map), and
    /// `normal_at` inverts it.
    #[test]
    fn lambert_round_trip() {
        let f = SlopeFrame::new([0.3, -0.2], [[0.04, 0.01], [0.01, 0.09]]);
        for &(sx, sy) in &[(0.0, 0.0), (0.3, -0.2), (1.0, 2.0), (-5.0, 0.1), (40.0, -70.0)] {
            let p = f.to_lambert(sx, sy);
            let w = f.to_whitened(sx, sy);
            let mz = 1.0 / (1.0 + w[0] * w[0] + w[1] * w[1]).sqrt();
            assert!(((p[0] * p[0] + p[1] * p[1]) - 2.0 * (1.0 - mz)).abs() < 1e-12);
            let m = f.normal_at(p);
            let s = SlopeFrame::slope_of(m);
            assert!((s[0] - sx).abs() < 1e-9 * (1.0 + sx.abs()) && (s[1] - sy).abs() < 1e-9 * (1.0 + sy.abs()), "{s:?}");
        }
        // Infinite slopes go to the rim, never NaN.
        let p = f.to_lambert(f64::INFINITY, 1.0);
        assert!((p[0].hypot(p[1]) - LAMBERT_RADIUS).abs() < 1e-12);
    }

    /// W = R(t) Sigma^(-1/2): W Sigma W^T = I, W U = I, and a zero covariance is floored.
    #[test]
    fn whitening_and_floor() {
        let f = SlopeFrame::new([0.0, 0.0], [[0.04, 0.015], [0.015, 0.01]]);
        let (w, c) = (f.whiten, f.cov);
        for i in 0..2 {
            for j in 0..2 {
                let mut v = 0.0;
                for k in 0..2 {
                    for l in 0..2 {
                        v += w[i][k] * c[k][l] * w[j][l];
                    }
                }
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
                let u = f.unwhiten;
                let wu = w[i][0] * u[0][j] + w[i][1] * u[1][j];
                assert!((wu - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        let z = SlopeFrame::new([1.0, 2.0], [[0.0, 0.0], [0.0, 0.0]]);
        assert_eq!(z.det_unwhiten, SLOPE_SCALE_FLOOR * SLOPE_SCALE_FLOOR);
        assert!(z.to_lambert(1.0, 2.0) == [0.0, 0.0]);
    }
}
