//! Canonical parameters: one labeling for each distinct distribution.
//!
//! Walter et al. eq. 1 depends on A only through `A^T A` up to scale (sec. 1: `c A` and `Q A` with `Q`
//! orthogonal give the same D). The principal axes of the ellipsoid `p^T A^T A p = C_e^2` (eq. 8) are the
//! right singular vectors `r_i` of `A` (the rows of `R` in `A = S R`, eq. 2), with semi-axes `1 / s_i`.
//! Which axis is called the third one, the sign of each axis and the order of the first two are free; each
//! choice gives different alphas and angles for the same D. The canonical form fixes them:
//!
//! 1. the third axis `r3` is the principal axis nearest `n` (largest `|r3 . n|`), signed so `r3 . n > 0`;
//!    this makes `cos(theta_x) cos(theta_y) = r3 . n` largest, i.e. `|theta_x|`, `|theta_y|` smallest.
//!    A is scaled so its third singular value is 1: `alpha_i = s_i / s_3`.
//! 2. `alpha_x >= alpha_y` (the first axis is the rougher one).
//! 3. `theta_z` in `(-pi/2, pi/2]`: flipping the first two axes together (`diag(-1,-1,1) A`) maps
//!    `(theta_x, theta_y, theta_z)` to `(-theta_x, -theta_y, theta_z + pi)`, and one of the two lands there.
//!    Then `theta_x`, `theta_y` are in `(-pi/2, pi/2)`.
//!
//! Ties (singular values equal to a relative [`TIE`]) have a rotational freedom:
//! - `alpha_x == alpha_y` (a spheroid about `r3`): `theta_z = 0` and `R = Rx(theta_x) Ry(theta_y)` with third
//!   row `r3`;
//! - the third singular value tied with another (e.g. GGX with alpha = 1 and a tilt is a sphere in that plane):
//!   `r3` is the unit vector of the tied plane nearest `n`, and the rules above apply to the rest;
//! - all three tied (a sphere): `(1, 1, 0, 0, 0)`.
//!
//! For `ggx-aniso` and `beckmann-aniso` the same rules read: swap the alphas (and add `pi/2` to `theta_z`)
//! when `alpha_x < alpha_y`, fold `theta_z` into `(-pi/2, pi/2]`, and `theta_z = 0` when the alphas tie.

use nalgebra::{Matrix3, Vector3};

use super::ellipsoid::singular_error;
use crate::error::{Error, Result};

/// Relative tolerance under which two singular values (or two alphas) count as tied. The SVD of
/// `A = S R` returns singular values to a few ulps of the largest, far inside it; distributions closer than
/// it differ by less than `1e-9` relative in D.
pub const TIE: f64 = 1e-9;

/// Fold an angle into `(-pi/2, pi/2]` modulo `pi`.
pub fn fold_half_turn(t: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let r = t.rem_euclid(pi); // in [0, pi)
    if r > 0.5 * pi {
        r - pi
    } else {
        r
    }
}

/// A principal axis and its singular value.
type AxisSv = (Vector3<f64>, f64);

fn ties(a: f64, b: f64) -> bool {
    (a - b).abs() <= TIE * a.abs().max(b.abs())
}

/// Canonical `(alpha_x, alpha_y, theta_z)` of an axis-aligned-and-rotated anisotropic model (GGX or
/// Beckmann): `alpha_x >= alpha_y`, `theta_z` in `(-pi/2, pi/2]`, `theta_z = 0` on a tie.
pub fn canonical_aniso(ax: f64, ay: f64, tz: f64) -> (f64, f64, f64) {
    if ties(ax, ay) {
        return (ax.max(ay), ax.max(ay), 0.0);
    }
    let (ax, ay, tz) = if ax < ay { (ay, ax, tz + 0.5 * std::f64::consts::PI) } else { (ax, ay, tz) };
    (ax, ay, fold_half_turn(tz))
}

/// The canonical `[alpha_x, alpha_y, theta_x, theta_y, theta_z]` of any invertible A (module docs).
/// Refuses a matrix that is not finite or whose smallest singular value is below `1e-12` times its largest.
///
/// Accuracy: an SVD gives each singular vector to `eps sigma_max / gap`, poor for the two small singular
/// values of a smooth ellipsoid (alpha ~ 1e-4: gaps of 1e-4 against sigma_max = 1). So the axis of the largest
/// singular value comes from the SVD of A, the axis of the smallest from the SVD of `A^-T` (where it is the
/// largest), and the middle one is their cross product: every axis to `eps / (relative gap)`.
pub fn decompose(a: &Matrix3<f64>) -> Result<[f64; 5]> {
    let (v, s) = principal_axes(a)?;
    label(v, s)
}

/// The canonical parameters of `A = S R` from its known principal axes (the rows of R) and singular values
/// `(alpha_x, alpha_y, 1)`, without any decomposition: exact to rounding.
pub fn relabel(r: &Matrix3<f64>, alpha_x: f64, alpha_y: f64) -> Result<[f64; 5]> {
    let v = [0, 1, 2].map(|i| r.row(i).transpose().into_owned());
    label(v, Vector3::new(alpha_x, alpha_y, 1.0))
}

/// Principal axes (unit right singular vectors) and singular values of A, each axis accurate to the
/// relative gap of its singular value (see [`decompose`]).
fn principal_axes(a: &Matrix3<f64>) -> Result<([Vector3<f64>; 3], Vector3<f64>)> {
    if a.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid("ellipsoid matrix A has a non-finite entry"));
    }
    let svd = a.svd(false, true);
    let vt = svd.v_t.ok_or_else(singular_error)?;
    let s = svd.singular_values;
    let smax = s.max();
    // Condition number beyond 1e12: the ellipsoid is a disc or a needle and its alphas have no digits left.
    if !(smax > 0.0) || s.min() < 1e-12 * smax {
        return Err(singular_error());
    }
    let inv_t = a.try_inverse().ok_or_else(singular_error)?.transpose();
    let svd_b = inv_t.svd(false, true);
    let vt_b = svd_b.v_t.ok_or_else(singular_error)?;
    let imax = s.imax();
    let jmax = svd_b.singular_values.imax();
    let v_max = vt.row(imax).transpose().normalize();
    let v_min = vt_b.row(jmax).transpose();
    // Orthogonal to v_max already to rounding; make it exact.
    let v_min = (v_min - v_max * v_min.dot(&v_max)).normalize();
    let v_mid = v_min.cross(&v_max).normalize();
    let s_max = (a * v_max).norm();
    let s_min = 1.0 / (inv_t * v_min).norm();
    // ||A v|| is accurate to eps s_max / s_mid, 1 / ||A^-T v|| to eps s_mid / s_min: take the better one.
    let (sa, sb) = ((a * v_mid).norm(), 1.0 / (inv_t * v_mid).norm());
    let s_mid = if sa * sa >= s_max * s_min { sa } else { sb };
    // Cannot happen after the condition check above; kept so that no NaN alpha can ever leave.
    if !(s_max.is_finite() && s_min > 0.0 && s_mid.is_finite() && s_mid > 0.0) {
        return Err(singular_error());
    }
    Ok(([v_max, v_mid, v_min], Vector3::new(s_max, s_mid, s_min)))
}

/// The labeling rules of the module docs applied to principal axes `v` with singular values `s`.
fn label(v: [Vector3<f64>; 3], s: Vector3<f64>) -> Result<[f64; 5]> {
    let z = Vector3::z();

    // Pick r3 and the two remaining (axis, singular value) pairs.
    let (r3, s3, rest): (Vector3<f64>, f64, Option<[AxisSv; 2]>) = if ties(s[0], s[1]) && ties(s[1], s[2]) {
        (z, s[0], None) // a sphere: every labeling is equivalent
    } else {
        // A tied pair (i, j) and the odd one k, if any.
        let pair = [(0, 1, 2), (1, 2, 0), (0, 2, 1)].into_iter().find(|&(i, j, _)| ties(s[i], s[j]));
        match pair {
            Some((i, j, k)) => {
                let p = v[i] * v[i].z + v[j] * v[j].z; // projection of n onto the tied plane
                if p.norm_squared() >= v[k].z * v[k].z {
                    let r3 = p.normalize();
                    let w = v[k].cross(&r3); // in the tied plane, orthogonal to r3
                    (r3, s[i], Some([(w, s[i]), (v[k], s[k])]))
                } else {
                    (v[k], s[k], Some([(v[i], s[i]), (v[j], s[j])]))
                }
            }
            None => {
                let k = (0..3).max_by(|&p, &q| v[p].z.abs().total_cmp(&v[q].z.abs())).unwrap_or(2);
                let others: Vec<usize> = (0..3).filter(|&i| i != k).collect();
                (v[k], s[k], Some([(v[others[0]], s[others[0]]), (v[others[1]], s[others[1]])]))
            }
        }
    };
    let r3 = if r3.z < 0.0 { -r3 } else { r3 };
    let Some(rest) = rest else {
        return Ok([1.0, 1.0, 0.0, 0.0, 0.0]);
    };
    let (ax, ay) = (rest[0].1 / s3, rest[1].1 / s3);
    if ties(ax, ay) {
        // Spheroid about r3: R = Rx(tx) Ry(ty), third row (-cx sy, sx, cx cy) = r3.
        let tx = r3.y.clamp(-1.0, 1.0).asin();
        let ty = (-r3.x).atan2(r3.z);
        let a = ax.max(ay);
        return Ok([a, a, tx, ty, 0.0]);
    }
    let (r1, ax, ay) = if ax >= ay { (rest[0].0, ax, ay) } else { (rest[1].0, ay, ax) };
    // Make r1 exactly orthogonal to r3 (it is, to rounding) and sign it so theta_z = atan2(-r1.y, r1.x)
    // lands in (-pi/2, pi/2].
    let r1 = (r1 - r3 * r1.dot(&r3)).normalize();
    let r1 = if r1.x < 0.0 || (r1.x == 0.0 && r1.y > 0.0) { -r1 } else { r1 };
    let r2 = r3.cross(&r1);
    // R = [r1; r2; r3] = Rx Ry Rz: column 3 is (sy, -sx cy, cx cy), row 1 is (cy cz, -cy sz, sy).
    let ty = r1.z.clamp(-1.0, 1.0).asin();
    let tx = (-r2.z).atan2(r3.z);
    let tz = (-r1.y).atan2(r1.x);
    Ok([ax, ay, tx, ty, tz])
}
