//! The scan's own BRDF as a material: the traced reflectance written as an RGL table (Dupuy & Jakob
//! 2018), which Mitsuba 3's and pbrt-v4's `measured` materials render.
//!
//! The table keeps the layout of the scan's microfacet table (`ndf`, `sigma` and `vndf` of the
//! regularized NDF, the same incident grid); only the reflectance differs. The renderer evaluates
//! `f(wi, wo) cos(theta_o) = R(s) D(m) / (4 sigma(wi))` (eq. 11 with the Jacobian flag), `m` the half
//! vector and `s` the point of the sample space that the node's `vndf` warp sends to `u(m)`. Per incident
//! node the paths of the tracer (all bounces, Fresnel per bounce and wavelength) give the energy leaving
//! per unit incident, `dE/dwo = f cos(theta_o)`; with `|dwo/ds| = 4 |wi.m| (2 pi^2 u_theta sin(theta_m)) /
//! p(u)` (the half-vector Jacobian, Walter et al. 2007 eq. 14, times the grid's, over the normalized
//! written density `p`), `R(s) = dE/ds J(s)` with `J = 4 sigma(wi) / (D(m) |dwo/ds|)`. Each path's energy is splatted with tent
//! weights `T_n` on the four nodes around its `s`; node `n` holds its tent's energy over
//! `int T_n(s) / J(s) ds` (a quadrature over the sample space where `wo` is above the horizon). That is `R`
//! averaged over the tent with the weight `1 / J`, and the renderer's bilinear `R` times `1 / J`
//! integrates back to exactly the energy splatted (the tents sum to one): the table conserves the traced
//! energy by construction, up to that quadrature.
//!
//! What the parameterization cannot hold is counted, not hidden: a path whose half vector has a
//! tabulated `D(m)` below [`CARRY_FLOOR`] of its peak (or no density of the warp) is left out of the table
//! (`uncarried`), and each node's table albedo (the renderer's `eval`, [`Measured`], integrated over the
//! sample space) is set against the traced one.

use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use nalgebra::Vector3;

use super::hierarchy::{Outcome, Pyramid};
use super::surface::{Border, Surface};
use super::tracer::{block_seed, morton, TraceRng};
use super::{direction, BLOCK, MAX_INCIDENCE_DEG};
use crate::error::{Error, Result};
use crate::export::rgl::{self, dir2u, u2dir, u2theta, Field, Measured, NdfGrids, RglOptions, SliceWarp, Table, RGB_NM};
use crate::scan::Scan;

/// A path whose half vector has a tabulated `D(m)` below this share of the NDF's peak is not carried by
/// the table: the reflectance there would have to grow as `1 / D` by more than six decades over its
/// ordinary scale, between nodes that the renderer interpolates linearly.
pub const CARRY_FLOOR: f64 = 1e-6;

/// Seed salt of the table's paths (apart from the streams of `ndfit trace`'s incidences).
const SALT: u64 = 0x5247_4c5f_7461_626c;

/// Bytes of the per-block accumulators held at once, at most.
const ACC_BUDGET: usize = 64 << 20;

/// What to trace and how to tabulate it.
#[derive(Debug, Clone, PartialEq)]
pub struct TracedRglOptions {
    /// The table's grid, conductor (the Fresnel factor of every bounce) and flavour.
    pub rgl: RglOptions,
    /// Paths per traced incident direction.
    pub paths: usize,
    /// Largest number of bounces a path follows.
    pub bounces: usize,
    /// Seed of the random generators.
    pub seed: u64,
    /// The grid's edges.
    pub border: Border,
}

impl Default for TracedRglOptions {
    fn default() -> Self {
        TracedRglOptions { rgl: RglOptions::coarse(), paths: 1 << 18, bounces: 16, seed: 1, border: Border::Periodic }
    }
}

impl TracedRglOptions {
    /// Check every value's range.
    pub fn validate(&self) -> Result<()> {
        self.rgl.check()?;
        if !(1..=1000).contains(&self.bounces) {
            return Err(Error::invalid(format!("bounces must be in [1, 1000], got {}", self.bounces)));
        }
        if !(1..=1usize << 36).contains(&self.paths) {
            return Err(Error::invalid(format!("paths must be in [1, 2^36], got {}", self.paths)));
        }
        Ok(())
    }
}

/// One incident node of the traced table.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NodeRecord {
    /// The node's incident elevation (degrees).
    pub theta_deg: f64,
    /// Its azimuth (degrees, 0 = the scan's `+x`).
    pub phi_deg: f64,
    /// The elevation traced for it (the node's, or [`MAX_INCIDENCE_DEG`] for a grazing node).
    pub traced_theta_deg: f64,
    /// Energy leaving per unit incident, all bounces (luminance of the red, green and blue channels).
    pub albedo: f64,
    /// Share of that energy the table does not carry (half vectors where `D` is below [`CARRY_FLOOR`]).
    pub uncarried: f64,
    /// The table's albedo as the renderer evaluates it ([`Measured`], integrated over the sample space).
    pub table_albedo: f64,
    /// Median relative standard error (Monte Carlo) of the luminance of `R` over the nodes that hold it.
    pub noise: f64,
}

/// The traced table and what was measured on the way.
#[derive(Debug, Clone)]
pub struct TracedTable {
    /// The file's fields, with three more per incident node (`[phi_i, theta_i]`, luminance):
    /// `traced_albedo`, `uncarried` and `table_albedo` of [`NodeRecord`].
    pub table: Table,
    /// One record per incident node, `phi_i` outermost as the file lays them.
    pub nodes: Vec<NodeRecord>,
    /// Distinct incident directions traced.
    pub traced_directions: usize,
    /// Paths traced in all.
    pub paths: u64,
}

impl TracedTable {
    /// The largest uncarried share and its node.
    pub fn worst_uncarried(&self) -> Option<&NodeRecord> {
        self.nodes.iter().max_by(|a, b| a.uncarried.total_cmp(&b.uncarried))
    }

    /// The largest `|table_albedo - (1 - uncarried) albedo|` over the nodes below grazing, and its node:
    /// what the table loses or adds beyond what it was told it cannot carry.
    pub fn worst_albedo_gap(&self) -> Option<(f64, &NodeRecord)> {
        self.nodes
            .iter()
            .filter(|r| r.theta_deg < 89.0)
            .map(|r| ((r.table_albedo - (1.0 - r.uncarried) * r.albedo).abs(), r))
            .max_by(|a, b| a.0.total_cmp(&b.0))
    }
}

/// Trace `scan` (form already removed) at every incident node of `opts.rgl` and write its reflectance on
/// the warps of the NDF `d` (regularized, renormalized; its `ndf` grid chosen for `guide`, as
/// [`rgl::tabulate_guided`]). `progress(done, total)` is called with the paths traced so far.
pub fn trace_rgl(
    scan: &Scan,
    d: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    description: &str,
    opts: &TracedRglOptions,
    progress: Option<&(dyn Fn(u64, u64) + Sync)>,
) -> Result<TracedTable> {
    opts.validate()?;
    let s = Surface::new(scan, opts.border)?;
    let pyr = Pyramid::new(&s)?;
    let kept = std::cell::RefCell::new(None);
    let reflectance = |grids: &NdfGrids, slices: &[SliceWarp], lambdas: &[f64]| -> Result<Vec<Vec<f64>>> {
        let (refl, stats, groups, paths) = reflect(&s, &pyr, grids, slices, lambdas, opts, progress);
        kept.replace(Some((slices.to_vec(), stats, groups, paths)));
        Ok(refl)
    };
    let mut table = rgl::tabulate_with(d, guide, description, &opts.rgl, true, &reflectance)?;
    let (slices, stats, groups, paths) = kept.into_inner().ok_or_else(|| Error::invalid("no slice was traced"))?;
    let measured = Measured::new(&table.tensor)?;
    let table_albedo: Vec<f64> = slices.par_iter().map(|sl| table_albedo(&measured, sl)).collect();
    let nodes: Vec<NodeRecord> = slices
        .iter()
        .zip(&stats)
        .zip(table_albedo)
        .map(|((sl, st), ta)| {
            let (theta, phi) = angles(sl.wi);
            NodeRecord {
                theta_deg: theta,
                phi_deg: phi,
                traced_theta_deg: theta.min(MAX_INCIDENCE_DEG),
                albedo: st.albedo,
                uncarried: if st.albedo > 0.0 { st.uncarried / st.albedo } else { 0.0 },
                table_albedo: ta,
                noise: st.noise,
            }
        })
        .collect();
    let (np, nt) = (opts.rgl.phi_i, opts.rgl.theta_i);
    table.tensor.fields.push(Field::f32("traced_albedo", &[np, nt], &nodes.iter().map(|r| r.albedo).collect::<Vec<_>>()));
    table.tensor.fields.push(Field::f32("uncarried", &[np, nt], &nodes.iter().map(|r| r.uncarried).collect::<Vec<_>>()));
    table.tensor.fields.push(Field::f32("table_albedo", &[np, nt], &nodes.iter().map(|r| r.table_albedo).collect::<Vec<_>>()));
    Ok(TracedTable { table, nodes, traced_directions: groups, paths })
}

/// Elevation and azimuth (degrees) of a unit direction.
fn angles(w: Vector3<f64>) -> (f64, f64) {
    (w.z.clamp(-1.0, 1.0).acos().to_degrees(), w.y.atan2(w.x).to_degrees())
}

/// Per slice: traced albedo (luminance), its uncarried part, and the median noise of `R`.
#[derive(Debug, Clone, Copy, Default)]
struct SliceStats {
    albedo: f64,
    uncarried: f64,
    noise: f64,
}

/// One distinct warp of a traced direction: the slice's incident direction, its warp, `sigma(wi)` as the
/// renderer reads it.
struct Target<'a> {
    wi: Vector3<f64>,
    warp: rgl::warp::Bilinear<'a>,
    sigma: f64,
}

/// Per block of paths, per target: the tent-weighted energy per channel and node, the squares of its
/// luminance's terms, the uncarried energy; and the energy leaving per channel, the landed paths.
#[derive(Clone)]
struct Acc {
    sum: Vec<Vec<f64>>,
    sq: Vec<Vec<f64>>,
    uncarried: Vec<f64>,
    out: Vec<f64>,
    landed: u64,
    rays: u64,
}

impl Acc {
    fn new(targets: usize, nc: usize, nodes: usize) -> Acc {
        Acc {
            sum: vec![vec![0.0; nc * nodes]; targets],
            sq: vec![vec![0.0; nodes]; targets],
            uncarried: vec![0.0; targets],
            out: vec![0.0; nc],
            landed: 0,
            rays: 0,
        }
    }

    fn add(&mut self, o: &Acc) {
        let add = |a: &mut [f64], b: &[f64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        for (a, b) in self.sum.iter_mut().zip(&o.sum) {
            add(a, b);
        }
        for (a, b) in self.sq.iter_mut().zip(&o.sq) {
            add(a, b);
        }
        add(&mut self.uncarried, &o.uncarried);
        add(&mut self.out, &o.out);
        self.landed += o.landed;
        self.rays += o.rays;
    }
}

/// The luminance of per-channel values: Rec. 709 weights of red, green and blue read at [`RGB_NM`]
/// (interpolated linearly between the wavelengths of a spectral table, as the renderer reads them).
fn luminance(v: &[f64], lambdas: &[f64]) -> f64 {
    let at = |nm: f64| {
        if lambdas.len() == 1 {
            return v[0];
        }
        let k = lambdas[1..lambdas.len() - 1].partition_point(|&l| l < nm);
        let t = ((nm - lambdas[k]) / (lambdas[k + 1] - lambdas[k])).clamp(0.0, 1.0);
        v[k] + (v[k + 1] - v[k]) * t
    };
    let rgb = if lambdas == RGB_NM { [v[0], v[1], v[2]] } else { RGB_NM.map(at) };
    super::tally::lum(rgb)
}

/// Trace every distinct incident direction of `slices` and estimate each slice's reflectance at its
/// nodes. Returns the reflectance per slice (`channels x w x w`), the slices' statistics, the number of
/// directions traced and the paths.
fn reflect(
    s: &Surface,
    pyr: &Pyramid,
    grids: &NdfGrids,
    slices: &[SliceWarp],
    lambdas: &[f64],
    opts: &TracedRglOptions,
    progress: Option<&(dyn Fn(u64, u64) + Sync)>,
) -> (Vec<Vec<f64>>, Vec<SliceStats>, usize, u64) {
    let w = opts.rgl.warp_res;
    let (nn, nc) = (w * w, lambdas.len());
    // Slices of one traced direction form a group; within it, slices of the same written density share
    // their estimate.
    let traced = |wi: Vector3<f64>| {
        let (theta, phi) = angles(wi);
        direction(theta.min(MAX_INCIDENCE_DEG), phi)
    };
    let mut groups: Vec<([f64; 3], Vec<usize>)> = Vec::new();
    let mut alias = vec![usize::MAX; slices.len()];
    for (k, sl) in slices.iter().enumerate() {
        let t = traced(sl.wi);
        match groups.iter_mut().find(|g| g.0.iter().zip(&t).all(|(a, b)| (a - b).abs() < 1e-9)) {
            Some(g) => match g.1.iter().find(|&&r| slices[r].vndf == sl.vndf) {
                Some(&r) => alias[k] = r,
                None => g.1.push(k),
            },
            None => groups.push((t, vec![k])),
        }
    }
    let etas: Vec<_> = lambdas.iter().map(|&nm| opts.rgl.material.eta(nm)).collect();
    let peak = grids.ndf.iter().copied().fold(0.0, f64::max);
    let blocks = opts.paths.div_ceil(BLOCK);
    let total = (opts.paths * groups.len()) as u64;
    let mut done = 0u64;
    let mut refl = vec![Vec::new(); slices.len()];
    let mut stats = vec![SliceStats::default(); slices.len()];
    for (g, (wi_t, members)) in groups.iter().enumerate() {
        let targets: Vec<Target> =
            members.iter().map(|&k| Target { wi: slices[k].wi, warp: slices[k].warp(), sigma: grids.sigma_at(slices[k].wi) }).collect();
        let tents: Vec<Vec<f64>> = targets.iter().map(|tg| tent_integrals(tg, grids, w)).collect();
        let per_block = targets.len() * (nc + 1) * nn * 8;
        let chunk = (ACC_BUDGET / per_block.max(1)).clamp(1, 64);
        let mut acc = Acc::new(targets.len(), nc, nn);
        for c0 in (0..blocks).step_by(chunk) {
            let parts: Vec<Acc> = (c0..(c0 + chunk).min(blocks))
                .into_par_iter()
                .map(|b| {
                    let rays = BLOCK.min(opts.paths - b * BLOCK);
                    let mut a = Acc::new(targets.len(), nc, nn);
                    let mut rng = TraceRng::seed_from_u64(block_seed(opts.seed ^ SALT, g, b));
                    let mut wt = vec![0.0; nc];
                    for (x, y) in starts(s, &mut rng, rays) {
                        a.rays += 1;
                        wt.iter_mut().for_each(|v| *v = 1.0);
                        let left = match walk(s, pyr, [x, y], *wi_t, opts.bounces, &etas, &mut wt) {
                            Walk::NotLanded => continue,
                            Walk::Lost => None,
                            Walk::Left(dir) => Some(dir),
                        };
                        a.landed += 1;
                        let Some(dir) = left else { continue };
                        a.out.iter_mut().zip(&wt).for_each(|(o, v)| *o += v);
                        let wo = Vector3::new(dir[0], dir[1], dir[2]);
                        for (t, tg) in targets.iter().enumerate() {
                            splat(&mut a, t, tg, wo, &wt, grids, peak, lambdas, w);
                        }
                    }
                    a
                })
                .collect();
            for p in &parts {
                acc.add(p);
                done += p.rays;
            }
            if let Some(f) = progress {
                f(done, total);
            }
        }
        let n = acc.landed.max(1) as f64;
        let albedo = luminance(&acc.out, lambdas) / n;
        for (t, &k) in members.iter().enumerate() {
            let tent = &tents[t];
            let r: Vec<f64> = (0..nc * nn).map(|q| if tent[q % nn] > 0.0 { acc.sum[t][q] / (n * tent[q % nn]) } else { 0.0 }).collect();
            let mass = |q: usize| luminance(&(0..nc).map(|c| acc.sum[t][c * nn + q]).collect::<Vec<_>>(), lambdas) / n;
            // Energy on a node whose tent reflects nothing above the horizon has no reflectance to carry it.
            let stranded: f64 = (0..nn).filter(|&q| !(tent[q] > 0.0)).map(mass).sum();
            // Relative standard error of each node's luminance estimate, median over the nodes that hold any.
            let mut rel: Vec<f64> = (0..nn)
                .filter_map(|q| {
                    let mean = mass(q);
                    let var = (acc.sq[t][q] / n - mean * mean).max(0.0) / n;
                    (mean > 0.0).then(|| var.sqrt() / mean)
                })
                .collect();
            rel.sort_by(f64::total_cmp);
            let noise = rel.get(rel.len() / 2).copied().unwrap_or(0.0);
            stats[k] = SliceStats { albedo, uncarried: acc.uncarried[t] / n + stranded, noise };
            refl[k] = r;
        }
    }
    for k in 0..slices.len() {
        if alias[k] != usize::MAX {
            refl[k] = refl[alias[k]].clone();
            stats[k] = stats[alias[k]];
        }
    }
    (refl, stats, groups.len(), total)
}

/// One leaving path's energy `wt` (per channel, per path) on target `t`: its half vector's point of the
/// sample space, tent weights on the four nodes around; uncarried where the table's `D(m)` is below
/// [`CARRY_FLOOR`] of its peak or the warp has no density there.
#[allow(clippy::too_many_arguments)]
#[inline]
fn splat(a: &mut Acc, t: usize, tg: &Target, wo: Vector3<f64>, wt: &[f64], grids: &NdfGrids, peak: f64, lambdas: &[f64], w: usize) {
    let h = tg.wi + wo;
    let m = h / h.norm();
    let u = dir2u(m);
    let p = tg.warp.density(u);
    let dm = grids.d(m);
    let c = tg.wi.dot(&m);
    let jac = 2.0 * std::f64::consts::PI.powi(2) * u[0] * u2theta(u[0]).sin();
    if !(dm > CARRY_FLOOR * peak && p > 0.0 && c > 0.0 && jac > 0.0) {
        a.uncarried[t] += luminance(wt, lambdas);
        return;
    }
    let sp = tg.warp.invert(u);
    let f = |v: f64| {
        let x = v * (w - 1) as f64;
        let i = (x as usize).min(w - 2);
        (i, x - i as f64)
    };
    let ((i, tx), (k, ty)) = (f(sp[0]), f(sp[1]));
    let nn = w * w;
    let lum = luminance(wt, lambdas);
    for (node, tw) in [
        (k * w + i, (1.0 - tx) * (1.0 - ty)),
        (k * w + i + 1, tx * (1.0 - ty)),
        ((k + 1) * w + i, (1.0 - tx) * ty),
        ((k + 1) * w + i + 1, tx * ty),
    ] {
        for (ch, v) in wt.iter().enumerate() {
            a.sum[t][ch * nn + node] += v * tw;
        }
        a.sq[t][node] += (lum * tw).powi(2);
    }
}

/// Quadrature points per axis across the whole sample space, at least, for [`tent_integrals`]: the
/// integrand is cut where `wo` meets the horizon, inside cells, which a rule of a few points per cell
/// places coarsely.
const TENT_POINTS: usize = 256;

/// `int T_n(s) / J(s) ds` for every node `n` of the target's sample space: `1 / J = D(m) |dwo/ds| /
/// (4 sigma(wi)) = D(m) |wi.m| (2 pi^2 u_theta sin(theta_m)) / (p(u) sigma(wi))`, zero where `wo` is at or
/// below the horizon (the renderer evaluates nothing there); a midpoint rule of at least [`TENT_POINTS`]
/// points per axis.
fn tent_integrals(tg: &Target, grids: &NdfGrids, w: usize) -> Vec<f64> {
    let h = 1.0 / (w - 1) as f64;
    let q = TENT_POINTS.div_ceil(w - 1).max(2);
    let pts: Vec<(f64, f64)> = (0..q).map(|a| ((a as f64 + 0.5) / q as f64, 1.0 / q as f64)).collect();
    let rows: Vec<Vec<(usize, f64)>> = (0..w - 1)
        .into_par_iter()
        .map(|j| {
            let mut out = Vec::with_capacity(4 * (w - 1));
            for i in 0..w - 1 {
                let mut corner = [0.0; 4];
                for &(gx, wx) in &pts {
                    for &(gy, wy) in &pts {
                        let u = tg.warp.sample([(i as f64 + gx) * h, (j as f64 + gy) * h]);
                        let m = u2dir(u);
                        let c = tg.wi.dot(&m);
                        let wo = 2.0 * c * m - tg.wi;
                        let p = tg.warp.density(u);
                        let jac = 2.0 * std::f64::consts::PI.powi(2) * u[0] * u2theta(u[0]).sin();
                        if !(wo.z > 0.0 && p > 0.0 && c > 0.0 && tg.sigma > 0.0) {
                            continue;
                        }
                        let inv_j = grids.d(m) * c * jac / (p * tg.sigma) * wx * wy * h * h;
                        corner[0] += inv_j * (1.0 - gx) * (1.0 - gy);
                        corner[1] += inv_j * gx * (1.0 - gy);
                        corner[2] += inv_j * (1.0 - gx) * gy;
                        corner[3] += inv_j * gx * gy;
                    }
                }
                out.extend([
                    (j * w + i, corner[0]),
                    (j * w + i + 1, corner[1]),
                    ((j + 1) * w + i, corner[2]),
                    ((j + 1) * w + i + 1, corner[3]),
                ]);
            }
            out
        })
        .collect();
    let mut tent = vec![0.0; w * w];
    for row in &rows {
        for &(k, v) in row {
            tent[k] += v;
        }
    }
    tent
}

/// Uniform start points over the grid (cell units) in Morton order of their cells, as the tracer's.
fn starts(s: &Surface, rng: &mut TraceRng, n: usize) -> Vec<(f64, f64)> {
    let (w, h) = (s.ncx as f64, s.ncy as f64);
    let mut v: Vec<(u64, f64, f64)> = (0..n)
        .map(|_| {
            let (x, y) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
            (morton(x as u32, y as u32), x, y)
        })
        .collect();
    v.sort_unstable_by_key(|p| p.0);
    v.into_iter().map(|p| (p.1, p.2)).collect()
}

/// What became of one path.
enum Walk {
    /// It met no measured cell first.
    NotLanded,
    /// It left upward in this direction.
    Left([f64; 3]),
    /// Still on the surface after the last bounce, or lost to rounding.
    Lost,
}

/// One path from the plane above `(x, y)` along `-wi`, reflecting specularly with the conductor's Fresnel
/// factor per wavelength (`etas`) multiplied into `wt`, as the tracer's paths.
fn walk(
    s: &Surface,
    pyr: &Pyramid,
    xy: [f64; 2],
    wi: [f64; 3],
    bounces: usize,
    etas: &[Option<nalgebra::Complex<f64>>],
    wt: &mut [f64],
) -> Walk {
    let z_top = s.zmax + 1e-3 * ((s.zmax - s.zmin) + s.dx.min(s.dy));
    let grid = |d: [f64; 3]| [d[0] / s.dx, d[1] / s.dy, d[2]];
    let Outcome::Hit(mut hit, mut p) = pyr.first_hit(s, [xy[0], xy[1], z_top], grid([-wi[0], -wi[1], -wi[2]]), None, u64::MAX) else {
        return Walk::NotLanded;
    };
    if !s.is_valid(hit.i, hit.j) {
        return Walk::NotLanded;
    }
    let mut dir = [-wi[0], -wi[1], -wi[2]];
    for _ in 0..bounces {
        let m = s.normal(hit.i, hit.j, hit.tri);
        let c = -(dir[0] * m[0] + dir[1] * m[1] + dir[2] * m[2]);
        // Met from behind: the ray leaked under the surface through rounding.
        if !(c > 0.0) {
            return Walk::Lost;
        }
        for (v, eta) in wt.iter_mut().zip(etas) {
            if let Some(e) = eta {
                *v *= crate::models::fresnel::fresnel_conductor(c, *e);
            }
        }
        dir = [dir[0] + 2.0 * c * m[0], dir[1] + 2.0 * c * m[1], dir[2] + 2.0 * c * m[2]];
        match pyr.first_hit(s, p, grid(dir), Some((hit.i, hit.j)), hit.id()) {
            Outcome::Hit(h2, p2) => {
                hit = h2;
                p = p2;
            }
            Outcome::Left { .. } if dir[2] > 0.0 => return Walk::Left(dir),
            _ => return Walk::Lost,
        }
    }
    Walk::Lost
}

/// The table's albedo at one slice as the renderer evaluates it: `int eval_cos(wi, wo) dwo` over the
/// sample space of the slice's warp (`dwo = |dwo/ds| ds`), a midpoint rule of `4 w` points per axis (at most
/// [`TENT_POINTS`]), luminance.
fn table_albedo(measured: &Measured, sl: &SliceWarp) -> f64 {
    let q = (4 * sl.w).min(TENT_POINTS);
    let warp = sl.warp();
    let wi = [sl.wi.x as f32, sl.wi.y as f32, sl.wi.z as f32];
    let mut sum = 0.0;
    for k in 0..q * q {
        let u = warp.sample([((k % q) as f64 + 0.5) / q as f64, ((k / q) as f64 + 0.5) / q as f64]);
        let m = u2dir(u);
        let c = sl.wi.dot(&m);
        let wo = 2.0 * c * m - sl.wi;
        let p = warp.density(u);
        let jac = 2.0 * std::f64::consts::PI.powi(2) * u[0] * u2theta(u[0]).sin();
        if !(wo.z > 0.0 && p > 0.0 && c > 0.0) {
            continue;
        }
        let f = measured.eval_cos(wi, [wo.x as f32, wo.y as f32, wo.z as f32]);
        sum += super::tally::lum(f.map(|v| v as f64)) * 4.0 * c * jac / p;
    }
    sum / (q * q) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luminance_reads_a_spectrum_at_the_rgb_wavelengths() {
        let flat = vec![0.5; rgl::SPECTRAL_NM.len()];
        assert!((luminance(&flat, &rgl::SPECTRAL_NM) - 0.5).abs() < 1e-12);
        assert!((luminance(&[1.0, 0.0, 0.0], &RGB_NM) - super::super::LUMA[0]).abs() < 1e-12);
    }
}
