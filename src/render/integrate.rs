//! The pixel and light quadratures.
//!
//! A pixel is the mean of the radiance over its square: an `n x n` Gauss-Legendre rule, and where the
//! rule's points disagree (the silhouette, a highlight narrower than the pixel) the square is split into
//! 2 x 2 cells, each integrated the same way, up to `Camera::refine` times. The centre rule
//! (`PixelRule::Centre`) takes one point per pixel and the neighbours' second differences instead, and the
//! Gauss rule only where the image is not smooth at the pixel's scale.
//!
//! The cap light is integrated per shading point in polar coordinates `(rho, phi)` about the mirror
//! direction `r` of the view, where every lobe whose peak is the normal has its peak: rings of radii
//! growing geometrically from `RHO0` (so a lobe of any width from near-mirror to Lambertian meets rings of
//! its own size), Gauss-Legendre in `ln rho` on each ring, and on each radius the exact arc of azimuths
//! inside the cap (spherical law of cosines), Gauss-Legendre over the arc (points in proportion to its
//! length, 6 to 12) or the trapezoid rule over a full circle. Where a ring touches the cap's rim the arc's length has a square-root edge; those
//! intervals take the map `rho = a + (b - a)(1 - cos(pi s))/2`, which makes it smooth.

use std::f64::consts::PI;

use nalgebra::Vector3;
use rayon::prelude::*;

use super::quadrature::gauss_legendre;
#[cfg(test)]
use super::Brdf;
use super::{sphere_frame, to_local, BrdfSet, Image, Light, PixelRule, Scene};

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
pub(super) struct Ring {
    /// Gauss-Legendre in radius, per ring.
    radial: Vec<(f64, f64)>,
    /// `(cos, sin, weight)` of the trapezoid rule on a full circle.
    circle: Vec<(f64, f64, f64)>,
    /// Gauss-Legendre rules of 0 to `AZIMUTH` points, for arcs.
    arcs: Vec<Vec<(f64, f64)>>,
}

impl Ring {
    pub(super) fn new() -> Ring {
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

/// Render every pixel of `scene` (validated) with every BRDF of `set`: image `k` is, bit for bit, what
/// rendering `set`'s BRDF `k` alone gives. The shading points, their frames and the cap's light points
/// are found once for all of them; each image still takes its own refinements where its own values
/// disagree (a BRDF is evaluated only at the points its image needs).
pub(super) fn render<const K: usize>(scene: &Scene, set: &dyn BrdfSet<K>) -> [Image; K] {
    let rules = Rules { pixel: gauss_legendre(scene.camera.points), ring: Ring::new() };
    let c = &scene.camera;
    let ext = c.extent;
    let grid = Grid {
        width: c.size,
        height: c.size,
        left: -ext,
        top: ext,
        side: 2.0 * ext / c.size as f64,
        rule: c.rule,
        refine: c.refine,
        tolerance: c.tolerance,
        floor: 1e-3 * scene.light.white_radiance(),
        rough_refine: 0,
    };
    let sphere = Sphere { scene, set, axes: scene.image_axes(), rules: &rules };
    pixels(&grid, &sphere, &rules.pixel)
}

/// The image's pixels on the image plane and the pixel rule's settings.
pub(super) struct Grid {
    /// Pixels per row and rows.
    pub width: usize,
    pub height: usize,
    /// The image plane's left edge and top edge.
    pub left: f64,
    pub top: f64,
    /// A pixel's side on the image plane (pixels are square).
    pub side: f64,
    /// The pixel rule, its refinements and their tolerance ([`super::Camera`]).
    pub rule: PixelRule,
    pub refine: usize,
    pub tolerance: f64,
    /// The absolute part of the refinement's threshold (radiance).
    pub floor: f64,
    /// How many times the centre rule's pixel that is not smooth is refined (0: its Gauss rule as it is).
    pub rough_refine: usize,
}

/// What the pixel rules integrate: the radiance of each BRDF `k` with `active[k]` seen at a point of the
/// image plane, `None` off the object.
pub(super) trait Geometry<const K: usize>: Sync {
    /// The radiances at image-plane point `(x, y)` (`y` up), `None` off the object.
    fn shade(&self, x: f64, y: f64, active: [bool; K]) -> Option<[[f64; 3]; K]>;
    /// Whether the object's outline crosses the square of side `side` with lower-left corner `at`.
    fn crossed(&self, at: [f64; 2], side: f64) -> bool;
}

/// The unit sphere of a [`Scene`] under its distant light.
struct Sphere<'a, const K: usize> {
    scene: &'a Scene,
    set: &'a dyn BrdfSet<K>,
    axes: [Vector3<f64>; 2],
    rules: &'a Rules,
}

impl<const K: usize> Geometry<K> for Sphere<'_, K> {
    fn shade(&self, x: f64, y: f64, active: [bool; K]) -> Option<[[f64; 3]; K]> {
        normal_at(self.scene, self.axes, x, y).map(|nrm| radiance(self.scene, self.set, nrm, self.rules, active))
    }

    fn crossed(&self, at: [f64; 2], side: f64) -> bool {
        on_silhouette(at, side)
    }
}

/// Every pixel of `grid` over `geo` by its pixel rule (`rule` the Gauss-Legendre points per axis).
pub(super) fn pixels<const K: usize>(grid: &Grid, geo: &dyn Geometry<K>, rule: &[(f64, f64)]) -> [Image; K] {
    let (w, h, side) = (grid.width, grid.height, grid.side);
    let floor = grid.floor;
    let all = [true; K];
    let shade = |x: f64, y: f64, active: [bool; K]| geo.shade(x, y, active).unwrap_or([[0.0; 3]; K]);
    let crossed = |at: [f64; 2], side: f64| geo.crossed(at, side);
    // The lower-left corner of pixel (i, j), row j from the top.
    let corner = |i: usize, j: usize| [grid.left + i as f64 * side, grid.top - (j + 1) as f64 * side];
    let gauss = |i: usize, j: usize, active: [bool; K]| {
        cell(&shade, &crossed, corner(i, j), side, grid.refine, grid.tolerance, floor, rule, active)
    };
    // A pixel of the centre rule whose image is not smooth: the Gauss rule, refined `rough_refine` times
    // (on the sphere not at all: refining it would cost as much as the rest of the image, and its points
    // still resolve a highlight's edge to a half pixel; a mirror's sharp image needs its edges' coverage).
    let rough = |i: usize, j: usize, active: [bool; K]| {
        cell(&shade, &crossed, corner(i, j), side, grid.rough_refine, grid.tolerance, floor, rule, active)
    };
    let mut data = vec![[[0f32; 3]; K]; w * h];
    if grid.rule == PixelRule::Centre && grid.refine > 0 {
        // Each centre's values, `None` off the object.
        let mut centres = vec![None; w * h];
        centres.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                let [x, y] = corner(i, j).map(|a| a + side / 2.0);
                *v = geo.shade(x, y, all);
            }
        });
        let at = |i: isize, j: isize| {
            let inside = (0..w as isize).contains(&i) && (0..h as isize).contains(&j);
            if inside {
                centres[j as usize * w + i as usize]
            } else {
                None
            }
        };
        data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                let v = if crossed(corner(i, j), side) {
                    gauss(i, j, all)
                } else {
                    let (ii, jj) = (i as isize, j as isize);
                    match [at(ii, jj), at(ii - 1, jj), at(ii + 1, jj), at(ii, jj - 1), at(ii, jj + 1)] {
                        // Off the object and not on its outline: the whole square is background.
                        [None, ..] => [[0.0; 3]; K],
                        [Some(m), Some(l), Some(r), Some(d), Some(u)] => {
                            let mut v = [[0.0; 3]; K];
                            let mut rougher = [false; K];
                            for k in 0..K {
                                let (m, l, r, d, u) = (m[k], l[k], r[k], d[k], u[k]);
                                let fix = [0, 1, 2].map(|q| (l[q] + r[q] + d[q] + u[q] - 4.0 * m[q]) / 24.0);
                                let level = m[0] + m[1] + m[2];
                                let size = fix[0].abs() + fix[1].abs() + fix[2].abs();
                                // Where the correction is large the image is not smooth at the pixel's scale.
                                if size <= 0.1 * grid.tolerance * (level + 3.0 * floor) {
                                    v[k] = [0, 1, 2].map(|q| m[q] + fix[q]);
                                } else {
                                    rougher[k] = true;
                                }
                            }
                            if rougher.contains(&true) {
                                let g = rough(i, j, rougher);
                                (0..K).filter(|&k| rougher[k]).for_each(|k| v[k] = g[k]);
                            }
                            v
                        }
                        // A neighbour off the object (or off the image): no second difference across it.
                        _ => gauss(i, j, all),
                    }
                };
                *out = v.map(|v| v.map(|x| x as f32));
            }
        });
    } else {
        data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                *out = gauss(i, j, all).map(|v| v.map(|x| x as f32));
            }
        });
    }
    std::array::from_fn(|k| Image { width: w, height: h, data: data.iter().map(|p| p[k]).collect() })
}

/// [`Scene::normal_at`] with the image's axes found once.
fn normal_at(scene: &Scene, [right, up]: [Vector3<f64>; 2], x: f64, y: f64) -> Option<Vector3<f64>> {
    let r2 = x * x + y * y;
    if r2 >= 1.0 {
        return None;
    }
    Some(right * x + up * y + scene.camera.view * (1.0 - r2).sqrt())
}

/// The mean of `shade` over the square of side `side` with lower-left corner `at`, split where its
/// points disagree, for each image `k` with `active[k]` (each split where its own points disagree; the
/// values of the others are left at 0).
#[allow(clippy::too_many_arguments)]
fn cell<const K: usize>(
    shade: &dyn Fn(f64, f64, [bool; K]) -> [[f64; 3]; K],
    crossed: &dyn Fn([f64; 2], f64) -> bool,
    at: [f64; 2],
    side: f64,
    depth: usize,
    tol: f64,
    floor: f64,
    rule: &[(f64, f64)],
    active: [bool; K],
) -> [[f64; 3]; K] {
    let mut mean = [[0.0; 3]; K];
    let (mut lo, mut hi) = ([f64::INFINITY; K], [f64::NEG_INFINITY; K]);
    for &(gy, wy) in rule {
        for &(gx, wx) in rule {
            let v = shade(at[0] + gx * side, at[1] + gy * side, active);
            for k in (0..K).filter(|&k| active[k]) {
                (0..3).for_each(|c| mean[k][c] += wx * wy * v[k][c]);
                let s = v[k][0] + v[k][1] + v[k][2];
                (lo[k], hi[k]) = (lo[k].min(s), hi[k].max(s));
            }
        }
    }
    // One point cannot disagree with itself; a rule of one point is never refined. A cell the silhouette
    // crosses is split even when its points agree (all on or all off the sphere).
    if depth == 0 || rule.len() < 2 {
        return mean;
    }
    let crossed_here = crossed(at, side);
    let split: [bool; K] = std::array::from_fn(|k| {
        let level = mean[k][0] + mean[k][1] + mean[k][2];
        // Its points agree (a NaN spread does not), and no silhouette crosses it.
        let settled = hi[k] - lo[k] <= tol * (level + 3.0 * floor) && !crossed_here;
        active[k] && !settled
    });
    if !split.contains(&true) {
        return mean;
    }
    let h = side / 2.0;
    let mut sum = [[0.0; 3]; K];
    for (dx, dy) in [(0.0, 0.0), (h, 0.0), (0.0, h), (h, h)] {
        let v = cell(shade, crossed, [at[0] + dx, at[1] + dy], h, depth - 1, tol, floor, rule, split);
        for k in (0..K).filter(|&k| split[k]) {
            (0..3).for_each(|c| sum[k][c] += 0.25 * v[k][c]);
        }
    }
    std::array::from_fn(|k| if split[k] { sum[k] } else { mean[k] })
}

/// Whether the unit circle (the sphere's outline) crosses the square of side `side` at `at`.
fn on_silhouette(at: [f64; 2], side: f64) -> bool {
    // The distance from 0 to the interval [a, a + side].
    let near = |a: f64| a.max(0.0) + (-(a + side)).max(0.0);
    let (nx, ny) = (near(at[0]), near(at[1]));
    let far = |a: f64| a.abs().max((a + side).abs());
    nx * nx + ny * ny < 1.0 && far(at[0]).powi(2) + far(at[1]).powi(2) > 1.0
}

/// The radiance toward the camera from the point of the sphere with normal `n` (world frame), for each
/// BRDF `k` of `set` with `active[k]`.
fn radiance<const K: usize>(scene: &Scene, set: &dyn BrdfSet<K>, n: Vector3<f64>, rules: &Rules, active: [bool; K]) -> [[f64; 3]; K] {
    let frame = sphere_frame(n);
    let wi = to_local(&frame, scene.camera.view);
    match scene.light {
        Light::Point { dir, irradiance } => {
            let wo = to_local(&frame, dir);
            // Below the horizon the sphere hides the light.
            if wo.z <= 0.0 {
                return [[0.0; 3]; K];
            }
            let mut f = [[0.0; 3]; K];
            set.eval(wi, wo, active, &mut f);
            f.map(|f| f.map(|f| f * irradiance * wo.z))
        }
        Light::Cap { dir, half_angle, radiance } => {
            let c = to_local(&frame, dir);
            let mut v = cap(set, wi, c, half_angle, &rules.ring, active);
            // A smooth part reflects the cap where the mirror direction meets it above the horizon.
            let r = Vector3::new(-wi.x, -wi.y, wi.z);
            if r.z > 0.0 && r.dot(&c) >= half_angle.cos() {
                add_mirror(&mut v, set.mirror(wi, active), active);
            }
            v.map(|v| v.map(|v| v * radiance))
        }
    }
}

/// `v[k] += m[k]` for each BRDF `k` with `active[k]` whose smooth part `m[k]` is not zero (a BRDF without
/// one keeps its bits).
pub(super) fn add_mirror<const K: usize>(v: &mut [[f64; 3]; K], m: [[f64; 3]; K], active: [bool; K]) {
    for k in (0..K).filter(|&k| active[k] && m[k] != [0.0; 3]) {
        (0..3).for_each(|q| v[k][q] += m[k][q]);
    }
}

/// `int_cap f(wi, wo) max(wo.z, 0) dwo` over the cap of `half_angle` about `c` (local frame), by the
/// rings about the mirror direction of the module's documentation.
#[cfg(test)]
fn cap_integral(brdf: &dyn Brdf, wi: Vector3<f64>, c: Vector3<f64>, half_angle: f64) -> [f64; 3] {
    cap(&[brdf], wi, c, half_angle, &Ring::new(), [true])[0]
}

/// `int_cap f_k(wi, wo) max(wo.z, 0) dwo` over the cap of half-angle `delta` about `c` (local frame) for
/// each BRDF `k` of `set` with `active[k]`, on one set of light points.
fn cap<const K: usize>(
    set: &dyn BrdfSet<K>,
    wi: Vector3<f64>,
    c: Vector3<f64>,
    delta: f64,
    rules: &Ring,
    active: [bool; K],
) -> [[f64; 3]; K] {
    // The whole cap below the horizon: the sphere hides it.
    if c.z <= -delta.sin() {
        return [[0.0; 3]; K];
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
            let (rho, jac) = radial_map(a, b, rim_a || rim_b, s);
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
    gather(set, wi, &dirs, &weights, active)
}

/// `sum_j w_j f_k(wi, l_j) l_j.z` over the light points `dirs` and their `weights`, for each BRDF `k` of
/// `set` with `active[k]`, every point evaluated in one call.
fn gather<const K: usize>(
    set: &dyn BrdfSet<K>,
    wi: Vector3<f64>,
    dirs: &[Vector3<f64>],
    weights: &[f64],
    active: [bool; K],
) -> [[f64; 3]; K] {
    let mut f: [Vec<[f64; 3]>; K] = std::array::from_fn(|k| if active[k] { vec![[0.0; 3]; dirs.len()] } else { Vec::new() });
    set.eval_many(wi, dirs, active, &mut f);
    std::array::from_fn(|k| {
        let mut acc = [0.0; 3];
        for ((l, w), f) in dirs.iter().zip(weights).zip(&f[k]) {
            (0..3).for_each(|q| acc[q] += w * f[q] * l.z);
        }
        acc
    })
}

/// `int f_k(wi, wo) max(wo.z, 0) dwo` over the convex spherical polygon of unit vertices `q` (local frame,
/// in order around it) for each BRDF `k` of `set` with `active[k]`, and whether the mirror direction of
/// `wi` lies inside the polygon above the horizon. Rings about the mirror direction, as the cap's: each
/// ring's azimuths inside the polygon are the intersection of the arcs inside its edges' great circles;
/// the radial breaks are the distances to the vertices and to the edges, where the arcs' ends have
/// square-root edges (those intervals take the cap's smoothing map).
pub(super) fn polygon<const K: usize>(
    set: &dyn BrdfSet<K>,
    wi: Vector3<f64>,
    q: &[Vector3<f64>],
    rules: &Ring,
    active: [bool; K],
) -> ([[f64; 3]; K], bool) {
    let n = q.len();
    let r = Vector3::new(-wi.x, -wi.y, wi.z);
    let centroid = q.iter().sum::<Vector3<f64>>().normalize();
    // The edges' great circles, their unit normals pointing inside.
    let m: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let m = q[k].cross(&q[(k + 1) % n]).normalize();
            if m.dot(&centroid) < 0.0 {
                -m
            } else {
                m
            }
        })
        .collect();
    let inside = m.iter().all(|m| r.dot(m) >= 0.0);
    let dist = |v: Vector3<f64>| r.dot(&v).clamp(-1.0, 1.0).acos();
    // The radii where a ring's arcs change: the vertices, and the edges where r's foot lies on them.
    let mut features: Vec<f64> = q.iter().map(|&v| dist(v)).collect();
    for k in 0..n {
        let (a, b) = (q[k], q[(k + 1) % n]);
        let foot = r - m[k] * r.dot(&m[k]);
        if foot.norm() > 1e-12 {
            let (foot, ab) = (foot.normalize(), a.cross(&b));
            if a.cross(&foot).dot(&ab) >= 0.0 && foot.cross(&b).dot(&ab) >= 0.0 {
                features.push(dist(foot));
            }
        }
    }
    let hi = q.iter().map(|&v| dist(v)).fold(0.0, f64::max);
    let lo = if inside { 0.0 } else { features.iter().copied().fold(f64::INFINITY, f64::min) };
    let mut breaks = vec![(lo, lo > 0.0), (hi, true)];
    breaks.extend(features.iter().filter(|&&f| f > lo * (1.0 + 1e-9) && hi - f > 1e-9).map(|&f| (f, true)));
    let mut rho = RHO0;
    while rho < hi {
        if rho > lo * (1.0 + 1e-9) && features.iter().all(|f| (rho - f).abs() > 1e-9) && hi - rho > 1e-9 {
            breaks.push((rho, false));
        }
        rho *= GROWTH;
    }
    breaks.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The azimuth origin e1 points from r toward the polygon (any perpendicular when they coincide).
    let toward = centroid - r * r.dot(&centroid);
    let e1 = if toward.norm() > 1e-12 { toward.normalize() } else { any_perpendicular(r) };
    let e2 = r.cross(&e1);
    // Per edge: (r . m, e1 . m, e2 . m).
    let proj: Vec<[f64; 3]> = m.iter().map(|m| [r.dot(m), e1.dot(m), e2.dot(m)]).collect();
    let (mut dirs, mut weights) = (Vec::new(), Vec::new());
    let mut arcs: Vec<(f64, f64)> = Vec::with_capacity(4);
    for pair in breaks.windows(2) {
        let ((a, rim_a), (b, rim_b)) = (pair[0], pair[1]);
        if b <= a {
            continue;
        }
        for &(s, ws) in &rules.radial {
            let (rho, jac) = radial_map(a, b, rim_a || rim_b, s);
            let (sr, cr) = rho.sin_cos();
            let w_rho = ws * jac * sr;
            let whole = ring_arcs(&proj, sr, cr, &mut arcs);
            let mut add = |cp: f64, sp: f64, w: f64| {
                let l = r * cr + (e1 * cp + e2 * sp) * sr;
                // Below the horizon the plate hides the light.
                if l.z > 0.0 {
                    dirs.push(l);
                    weights.push(w_rho * w);
                }
            };
            if whole {
                rules.circle.iter().for_each(|&(cp, sp, w)| add(cp, sp, w));
                continue;
            }
            for &(lo, hi) in &arcs {
                rules.arc((hi - lo) / 2.0).iter().for_each(|&(x, w)| {
                    let (sp, cp) = (lo + (hi - lo) * x).sin_cos();
                    add(cp, sp, (hi - lo) * w)
                });
            }
        }
    }
    (gather(set, wi, &dirs, &weights, active), inside && r.z > 0.0)
}

/// The azimuths of the ring of radius `rho` (`sin`, `cos` given) inside every edge of `proj` (per edge
/// `(r . m, e1 . m, e2 . m)`, `m` its inward normal) as intervals of `[0, 2 pi)` into `arcs`; true when no
/// edge cuts the ring (the whole circle, `arcs` then unused).
fn ring_arcs(proj: &[[f64; 3]], sr: f64, cr: f64, arcs: &mut Vec<(f64, f64)>) -> bool {
    const TAU: f64 = 2.0 * PI;
    arcs.clear();
    arcs.push((0.0, TAU));
    let mut whole = true;
    for &[c0, a, b] in proj {
        // Inside the edge: cr c0 + sr (a cos phi + b sin phi) >= 0.
        let amp = sr * a.hypot(b);
        let t = if amp > 0.0 {
            -cr * c0 / amp
        } else if cr * c0 >= 0.0 {
            -1.0
        } else {
            1.0
        };
        if t <= -1.0 {
            continue;
        }
        whole = false;
        if t >= 1.0 {
            arcs.clear();
            return false;
        }
        let (mid, half) = (b.atan2(a), t.acos());
        let start = (mid - half).rem_euclid(TAU);
        let end = start + 2.0 * half;
        let cut: [(f64, f64); 2] = if end <= TAU { [(start, end), (0.0, 0.0)] } else { [(start, TAU), (0.0, end - TAU)] };
        let before = std::mem::take(arcs);
        for (lo, hi) in before {
            for &(c, d) in &cut {
                let (x, y) = (lo.max(c), hi.min(d));
                if y > x {
                    arcs.push((x, y));
                }
            }
        }
    }
    whole
}

/// The radius and `d(rho)/ds` at `s` in `[0, 1]` of the ring interval `[a, b]`: the cosine map where a
/// ring at an end touches the light's edge (`rim`: the arc's square-root edge made smooth), linear from 0,
/// else geometric (Gauss-Legendre in `ln rho`).
#[inline]
fn radial_map(a: f64, b: f64, rim: bool, s: f64) -> (f64, f64) {
    if rim {
        (a + (b - a) * (1.0 - (PI * s).cos()) / 2.0, (b - a) * PI / 2.0 * (PI * s).sin())
    } else if a == 0.0 {
        (b * s, b)
    } else {
        let rho = a * (b / a).powf(s);
        (rho, rho * (b / a).ln())
    }
}

/// A unit vector perpendicular to the unit vector `v`.
fn any_perpendicular(v: Vector3<f64>) -> Vector3<f64> {
    let a = if v.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    (a - v * v.dot(&a)).normalize()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// An anisotropic GGX lobe with separable Smith masking and `F = 1`, written out here (Heitz 2014
    /// eq. 85 and 86) so the renderer's tests depend on nothing else.
    pub(in crate::render) fn ggx(ax: f64, ay: f64) -> impl Fn(Vector3<f64>, Vector3<f64>) -> [f64; 3] + Sync {
        move |wi: Vector3<f64>, wo: Vector3<f64>| {
            if wi.z <= 0.0 || wo.z <= 0.0 {
                return [0.0; 3];
            }
            let h = (wi + wo).normalize();
            let q = (h.x / ax).powi(2) + (h.y / ay).powi(2) + h.z * h.z;
            let d = 1.0 / (PI * ax * ay * q * q);
            let g1 = |w: Vector3<f64>| {
                let t2 = ((ax * w.x).powi(2) + (ay * w.y).powi(2)) / (w.z * w.z);
                2.0 / (1.0 + (1.0 + t2).sqrt())
            };
            [d * g1(wi) * g1(wo) / (4.0 * wi.z * wo.z); 3]
        }
    }

    /// The cap integral by brute force: polar coordinates about the cap's centre, `n` midpoints in radius
    /// and `4 n` in azimuth.
    fn brute(brdf: &dyn Brdf, wi: Vector3<f64>, c: Vector3<f64>, delta: f64, n: usize) -> f64 {
        let e1 = any_perpendicular(c);
        let e2 = c.cross(&e1);
        let (dr, dp) = (delta / n as f64, 2.0 * PI / (4 * n) as f64);
        let mut acc = 0.0;
        for a in 0..n {
            let rho = (a as f64 + 0.5) * dr;
            for b in 0..4 * n {
                let phi = (b as f64 + 0.5) * dp;
                let l = c * rho.cos() + (e1 * phi.cos() + e2 * phi.sin()) * rho.sin();
                if l.z > 0.0 {
                    acc += brdf.eval(wi, l)[0] * l.z * rho.sin() * dr * dp;
                }
            }
        }
        acc
    }

    /// The rings about the mirror direction against the brute-force sum, for lobes from near-mirror to
    /// rough, anisotropic too, with the mirror direction inside the cap, near its rim and outside it.
    #[test]
    fn cap_rule_matches_brute_force() {
        let delta = 25f64.to_radians();
        let c = super::super::direction(0.5, 0.3);
        let lobes: [(f64, f64); 6] = [(0.02, 0.02), (0.05, 0.05), (0.1, 0.1), (0.3, 0.3), (1.0, 1.0), (0.3, 0.08)];
        let mut worst: f64 = 0.0;
        for (ax, ay) in lobes {
            let f = ggx(ax, ay);
            for (theta, phi) in [(0.5, 0.3 + PI), (0.2, 0.3 + PI), (0.1, 1.0), (0.7, 2.0), (0.3, 0.3)] {
                let wi = super::super::direction(theta, phi);
                let q = cap_integral(&f, wi, c, delta)[0];
                let b = brute(&f, wi, c, delta, 1500);
                let scale = b.max(1e-3);
                eprintln!("alpha {ax}/{ay} wi ({theta}, {phi:.2}): rings {q:.6} brute {b:.6} rel {:.2e}", (q - b).abs() / scale);
                worst = worst.max((q - b).abs() / scale);
            }
        }
        assert!(worst < 0.01, "worst relative error {worst}");
    }

    /// Images rendered together in one pass are, bit for bit, the images the renderer gave one BRDF at a
    /// time before it could render several (`render::before`): in both default scenes and with the other
    /// pixel rule in each, for lobes from near-mirror to rough, a BRDF with its own `eval_many` or not,
    /// and the same BRDF twice.
    #[test]
    fn rendering_together_gives_each_image_as_alone() {
        use super::super::before::render_before;
        use super::super::Camera;
        let (a, b, c) = (ggx(0.3, 0.3), ggx(0.05, 0.02), ggx(0.6, 0.2));
        let many = |wi: Vector3<f64>, wo: Vector3<f64>| ggx(0.15, 0.15)(wi, wo).map(|v| v * 0.5);
        let mut scenes = vec![Scene::point(), Scene::broad()];
        let centre = Camera { size: 48, refine: 1, rule: PixelRule::Centre, ..Camera::default() };
        let gauss = Camera { size: 32, refine: 1, rule: PixelRule::Gauss, ..Camera::default() };
        scenes.push(Scene { camera: centre, ..Scene::point() });
        scenes.push(Scene { camera: gauss, ..Scene::broad() });
        let bits = |i: &Image| i.data.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        for scene in &scenes {
            let [x, y] = integrate_pair(scene, [&a, &b]);
            assert_eq!(bits(&x), bits(&render_before(scene, &a)), "{scene:?}");
            assert_eq!(bits(&y), bits(&render_before(scene, &b)), "{scene:?}");
            let [z] = render(scene, &[&c as &dyn Brdf]);
            assert_eq!(bits(&z), bits(&render_before(scene, &c)), "{scene:?}");
            let [u, v] = integrate_pair(scene, [&many, &many]);
            let alone = render_before(scene, &many);
            assert_eq!((bits(&u), bits(&v)), (bits(&alone), bits(&alone)), "{scene:?}");
        }
    }

    fn integrate_pair(scene: &Scene, pair: [&dyn Brdf; 2]) -> [Image; 2] {
        render(scene, &pair)
    }
}
