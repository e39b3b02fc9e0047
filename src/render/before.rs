//! The renderer as it was before several BRDFs could be rendered in one pass, kept verbatim (but for
//! its name) so that the tests hold the new one to the same bits.

use std::f64::consts::PI;

use nalgebra::Vector3;
use rayon::prelude::*;

use super::quadrature::gauss_legendre;
use super::{sphere_frame, to_local, Brdf, Image, Light, PixelRule, Scene};

/// The innermost ring's radius about the mirror direction (radians): a quarter of the angular width of
/// the narrowest lobe (alpha 0.01, about 2 alpha wide in reflected directions) the rule resolves.
const RHO0: f64 = 0.005;
/// The ratio of successive ring radii.
const GROWTH: f64 = 3.0;
/// Gauss-Legendre points per ring in radius.
const RADIAL: usize = 4;
/// Points per ring in azimuth: the trapezoid rule on a full circle, and the most on an arc.
const AZIMUTH: usize = 12;
/// An arc's points relative to the full circle's density: an arc is smoother than its share of the
/// circle (the cap's edge is in the radial map), but its integrand still varies along it.
const ARC_DENSITY: f64 = 1.5;
/// The fewest points on an arc: short arcs near the cap's rim still carry a lobe's anisotropy.
const ARC_MIN: usize = 6;

/// The fixed rules of one render.
struct Rules {
    pixel: Vec<(f64, f64)>,
    ring: Ring,
}

/// The light rule's tables.
struct Ring {
    /// Gauss-Legendre in radius, per ring.
    radial: Vec<(f64, f64)>,
    /// `(cos, sin, weight)` of the trapezoid rule on a full circle.
    circle: Vec<(f64, f64, f64)>,
    /// Gauss-Legendre rules of 0 to `AZIMUTH` points, for arcs.
    arcs: Vec<Vec<(f64, f64)>>,
}

impl Ring {
    fn new() -> Ring {
        let circle = (0..AZIMUTH)
            .map(|k| {
                let (sp, cp) = (2.0 * PI * (k as f64 + 0.5) / AZIMUTH as f64).sin_cos();
                (cp, sp, 2.0 * PI / AZIMUTH as f64)
            })
            .collect();
        Ring { radial: gauss_legendre(RADIAL), circle, arcs: (0..=AZIMUTH).map(gauss_legendre).collect() }
    }

    /// The rule for an arc of azimuths `|phi| <= half`: `ARC_DENSITY` times the full circle's density of
    /// points, at least `ARC_MIN` and at most `AZIMUTH`.
    fn arc(&self, half: f64) -> &[(f64, f64)] {
        let m = (AZIMUTH as f64 * ARC_DENSITY * half / PI).ceil() as usize;
        &self.arcs[m.clamp(ARC_MIN, AZIMUTH)]
    }
}

/// Render every pixel of `scene` (validated) with `brdf`.
pub(crate) fn render_before(scene: &Scene, brdf: &dyn Brdf) -> Image {
    let rules = Rules { pixel: gauss_legendre(scene.camera.points), ring: Ring::new() };
    let c = &scene.camera;
    let n = c.size;
    let ext = c.extent;
    let side = 2.0 * ext / n as f64;
    let floor = 1e-3 * scene.light.white_radiance();
    let shade = |x: f64, y: f64| scene.normal_at(x, y).map_or([0.0; 3], |nrm| radiance(scene, brdf, nrm, &rules));
    // The lower-left corner of pixel (i, j), row j from the top.
    let corner = |i: usize, j: usize| [-ext + i as f64 * side, ext - (j + 1) as f64 * side];
    let gauss = |i: usize, j: usize| cell(&shade, corner(i, j), side, c.refine, c.tolerance, floor, &rules.pixel);
    // A pixel of the centre rule whose image is not smooth: the Gauss rule as it is (refining it would
    // cost as much as the rest of the image; its points still resolve a highlight's edge to a half pixel).
    let rough = |i: usize, j: usize| cell(&shade, corner(i, j), side, 0, c.tolerance, floor, &rules.pixel);
    let mut data = vec![[0f32; 3]; n * n];
    if c.rule == PixelRule::Centre && c.refine > 0 {
        // Each centre's value, `None` off the sphere.
        let mut centres = vec![None; n * n];
        centres.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                let [x, y] = corner(i, j).map(|a| a + side / 2.0);
                *v = scene.normal_at(x, y).map(|nrm| radiance(scene, brdf, nrm, &rules));
            }
        });
        let at = |i: isize, j: isize| {
            let inside = (0..n as isize).contains(&i) && (0..n as isize).contains(&j);
            if inside {
                centres[j as usize * n + i as usize]
            } else {
                None
            }
        };
        data.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                let v = if on_silhouette(corner(i, j), side) {
                    gauss(i, j)
                } else {
                    let (ii, jj) = (i as isize, j as isize);
                    match [at(ii, jj), at(ii - 1, jj), at(ii + 1, jj), at(ii, jj - 1), at(ii, jj + 1)] {
                        // Off the sphere and not on the silhouette: the whole square is background.
                        [None, ..] => [0.0; 3],
                        [Some(m), Some(l), Some(r), Some(d), Some(u)] => {
                            let fix = [0, 1, 2].map(|k| (l[k] + r[k] + d[k] + u[k] - 4.0 * m[k]) / 24.0);
                            let level = m[0] + m[1] + m[2];
                            let size = fix[0].abs() + fix[1].abs() + fix[2].abs();
                            // Where the correction is large the image is not smooth at the pixel's scale.
                            if size <= 0.1 * c.tolerance * (level + 3.0 * floor) {
                                [0, 1, 2].map(|k| m[k] + fix[k])
                            } else {
                                rough(i, j)
                            }
                        }
                        // A neighbour off the sphere: no second difference across the silhouette.
                        _ => gauss(i, j),
                    }
                };
                *out = v.map(|x| x as f32);
            }
        });
    } else {
        data.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                *out = gauss(i, j).map(|x| x as f32);
            }
        });
    }
    Image { width: n, height: n, data }
}

/// The mean of `shade` over the square of side `side` with lower-left corner `at`, split where its
/// points disagree.
fn cell(
    shade: &dyn Fn(f64, f64) -> [f64; 3],
    at: [f64; 2],
    side: f64,
    depth: usize,
    tol: f64,
    floor: f64,
    rule: &[(f64, f64)],
) -> [f64; 3] {
    let mut mean = [0.0; 3];
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(gy, wy) in rule {
        for &(gx, wx) in rule {
            let v = shade(at[0] + gx * side, at[1] + gy * side);
            (0..3).for_each(|c| mean[c] += wx * wy * v[c]);
            let s = v[0] + v[1] + v[2];
            (lo, hi) = (lo.min(s), hi.max(s));
        }
    }
    let level = mean[0] + mean[1] + mean[2];
    // One point cannot disagree with itself; a rule of one point is never refined. A cell the silhouette
    // crosses is split even when its points agree (all on or all off the sphere).
    if depth == 0 || rule.len() < 2 || (hi - lo <= tol * (level + 3.0 * floor) && !on_silhouette(at, side)) {
        return mean;
    }
    let h = side / 2.0;
    let mut sum = [0.0; 3];
    for (dx, dy) in [(0.0, 0.0), (h, 0.0), (0.0, h), (h, h)] {
        let v = cell(shade, [at[0] + dx, at[1] + dy], h, depth - 1, tol, floor, rule);
        (0..3).for_each(|c| sum[c] += 0.25 * v[c]);
    }
    sum
}

/// Whether the unit circle (the sphere's outline) crosses the square of side `side` at `at`.
fn on_silhouette(at: [f64; 2], side: f64) -> bool {
    // The distance from 0 to the interval [a, a + side].
    let near = |a: f64| a.max(0.0) + (-(a + side)).max(0.0);
    let (nx, ny) = (near(at[0]), near(at[1]));
    let far = |a: f64| a.abs().max((a + side).abs());
    nx * nx + ny * ny < 1.0 && far(at[0]).powi(2) + far(at[1]).powi(2) > 1.0
}

/// The radiance toward the camera from the point of the sphere with normal `n` (world frame).
fn radiance(scene: &Scene, brdf: &dyn Brdf, n: Vector3<f64>, rules: &Rules) -> [f64; 3] {
    let frame = sphere_frame(n);
    let wi = to_local(&frame, scene.camera.view);
    match scene.light {
        Light::Point { dir, irradiance } => {
            let wo = to_local(&frame, dir);
            // Below the horizon the sphere hides the light.
            if wo.z <= 0.0 {
                return [0.0; 3];
            }
            brdf.eval(wi, wo).map(|f| f * irradiance * wo.z)
        }
        Light::Cap { dir, half_angle, radiance } => cap(brdf, wi, to_local(&frame, dir), half_angle, &rules.ring).map(|v| v * radiance),
    }
}

fn cap(brdf: &dyn Brdf, wi: Vector3<f64>, c: Vector3<f64>, delta: f64, rules: &Ring) -> [f64; 3] {
    // The whole cap below the horizon: the sphere hides it.
    if c.z <= -delta.sin() {
        return [0.0; 3];
    }
    let r = Vector3::new(-wi.x, -wi.y, wi.z);
    let cos_d = r.dot(&c).clamp(-1.0, 1.0);
    let d = cos_d.acos();
    // The azimuth origin e1 points from r toward the cap's centre (any perpendicular when they coincide).
    let toward = c - r * cos_d;
    let e1 = if toward.norm() > 1e-12 { toward.normalize() } else { any_perpendicular(r) };
    let e2 = r.cross(&e1);
    let (lo, hi) = ((d - delta).max(0.0), (d + delta).min(PI));
    // Rings of radius below `full` lie wholly inside the cap.
    let full = delta - d;
    // Breaks of the radial range: (radius, whether a ring there touches the cap's rim).
    let mut breaks = vec![(lo, lo > 0.0), (hi, true)];
    if full > 0.0 {
        breaks.push((full, true));
    }
    let mut rho = RHO0;
    while rho < hi {
        if rho > lo * (1.0 + 1e-9) && (rho - full).abs() > 1e-9 && hi - rho > 1e-9 {
            breaks.push((rho, false));
        }
        rho *= GROWTH;
    }
    breaks.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (cos_delta, sin_d) = (delta.cos(), d.sin());
    // The light points above the horizon and their weights, evaluated together once gathered.
    let (mut dirs, mut weights) = (Vec::with_capacity(4 * AZIMUTH * breaks.len()), Vec::with_capacity(4 * AZIMUTH * breaks.len()));
    for pair in breaks.windows(2) {
        let ((a, rim_a), (b, rim_b)) = (pair[0], pair[1]);
        if b <= a {
            continue;
        }
        for &(s, ws) in &rules.radial {
            // The radius and d(rho)/ds of the interval's map.
            let (rho, jac) = if rim_a || rim_b {
                (a + (b - a) * (1.0 - (PI * s).cos()) / 2.0, (b - a) * PI / 2.0 * (PI * s).sin())
            } else if a == 0.0 {
                (b * s, b)
            } else {
                let rho = a * (b / a).powf(s);
                (rho, rho * (b / a).ln())
            };
            let (sr, cr) = rho.sin_cos();
            let w_rho = ws * jac * sr;
            let mut add = |cp: f64, sp: f64, w: f64| {
                let l = r * cr + (e1 * cp + e2 * sp) * sr;
                // Below the horizon the sphere hides the light.
                if l.z > 0.0 {
                    dirs.push(l);
                    weights.push(w_rho * w);
                }
            };
            if rho <= full {
                rules.circle.iter().for_each(|&(cp, sp, w)| add(cp, sp, w));
            } else {
                // The arc |phi| <= half of the ring inside the cap: cos(delta) <= cos(rho) cos(d) + sin(rho) sin(d) cos(phi).
                let denom = sr * sin_d;
                if denom <= 0.0 {
                    continue;
                }
                let half = ((cos_delta - cr * cos_d) / denom).clamp(-1.0, 1.0).acos();
                rules.arc(half).iter().for_each(|&(x, w)| {
                    let (sp, cp) = (half * (2.0 * x - 1.0)).sin_cos();
                    add(cp, sp, 2.0 * half * w)
                });
            }
        }
    }
    let mut f = vec![[0.0; 3]; dirs.len()];
    brdf.eval_many(wi, &dirs, &mut f);
    let mut acc = [0.0; 3];
    for ((l, w), f) in dirs.iter().zip(&weights).zip(&f) {
        (0..3).for_each(|k| acc[k] += w * f[k] * l.z);
    }
    acc
}

/// A unit vector perpendicular to the unit vector `v`.
fn any_perpendicular(v: Vector3<f64>) -> Vector3<f64> {
    let a = if v.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    (a - v * v.dot(&a)).normalize()
}
