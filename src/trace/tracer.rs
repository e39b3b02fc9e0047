//! The paths: rays from one incident direction, landing, reflecting specularly off the triangles'
//! true normals with the conductor's Fresnel factor, up to the last bounce; the masking rays; and one
//! sample of the microfacet model's single scattering per path, at the path's start point.
//!
//! Energy: a ray starts at a uniform point of the plane above the surface (uniform in the incident flux
//! per unit of macro area), so the energy leaving per landed ray estimates the albedo. Each path ends
//! once, in one bin, which makes the per-bin sums of squares the variance of the bin's estimate.

use rand::{RngExt, SeedableRng};

use super::compare::SigmaTable;
use super::hierarchy::{Outcome, Pyramid};
use super::surface::Surface;
use super::tally::{deposit, warp, DirTable, Tally};
use crate::export::rgl::Material;

/// The random generator of the tracer: xoshiro256++, seeded per block of rays.
pub(crate) type TraceRng = rand::rngs::Xoshiro256PlusPlus;

/// Everything a block of paths from one incidence reads.
pub(crate) struct Setup<'a> {
    pub s: &'a Surface,
    pub pyr: &'a Pyramid,
    pub table: DirTable,
    pub material: Material,
    pub bounces: usize,
    /// The incident direction (unit, physical, towards the light).
    pub wi: [f64; 3],
    /// Smith's `Lambda(wi)` of the traced surface's NDF.
    pub lambda_i: f64,
    pub sigma: &'a SigmaTable,
    /// When set, each ray's incident direction is drawn uniformly in projected solid angle over this
    /// range (`theta` from, to; `phi` from, to; radians) instead of `wi`: the bin-averaged BRDF, which is
    /// exactly reciprocal between two bins.
    pub spread: Option<[f64; 4]>,
}

/// How many rays ahead of the traced one the first reads are prefetched.
const PREFETCH: usize = 4;

/// A well-mixed seed for block `block` of incidence `inc` (SplitMix64 finalizer).
pub(crate) fn block_seed(seed: u64, inc: usize, block: usize) -> u64 {
    let mut z = seed ^ (inc as u64).wrapping_mul(0xD1B5_4A32_D192_ED03) ^ (block as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The Morton (Z-order) code of a cell: the bits of `x` and `y` interleaved.
#[inline]
pub(crate) fn morton(x: u32, y: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        v = (v | (v << 1)) & 0x5555_5555_5555_5555;
        v
    }
    spread(x) | (spread(y) << 1)
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Setup<'_> {
    /// A physical direction in grid cell units (x, y per cell; z in metres).
    #[inline]
    fn to_grid(&self, d: [f64; 3]) -> [f64; 3] {
        [d[0] / self.s.dx, d[1] / self.s.dy, d[2]]
    }

    /// Fresnel reflectance per channel at the cosine `c`.
    #[inline]
    fn fresnel(&self, c: f64) -> [f64; 3] {
        self.material.fresnel_rgb(c)
    }

    /// `rays` paths and `g1_rays` masking rays with the generator seeded by `seed`.
    pub fn block(&self, rays: usize, g1_rays: usize, seed: u64) -> Tally {
        let mut t = Tally::new(self.table.len(), self.bounces);
        let mut rng = TraceRng::seed_from_u64(seed);
        let s = self.s;
        let (w, h) = (s.ncx as f64, s.ncy as f64);
        let z_top = s.zmax + 1e-3 * ((s.zmax - s.zmin) + s.dx.min(s.dy));
        let draw = |rng: &mut TraceRng| match self.spread {
            None => (self.wi, self.lambda_i),
            Some([t0, t1, p0, p1]) => {
                // sin^2(theta) is uniform under the projected solid angle.
                let (a, b) = (t0.sin().powi(2), t1.sin().powi(2));
                let st = (a + (b - a) * rng.random::<f64>()).sqrt().min(1.0);
                let phi = p0 + (p1 - p0) * rng.random::<f64>();
                let wi = [st * phi.cos(), st * phi.sin(), (1.0 - st * st).sqrt()];
                (wi, self.sigma.lambda(wi))
            }
        };
        // The block's start points, independent and uniform, are traced in Morton order of their cells:
        // neighbours in the order share the pyramid's blocks and the heights' cache lines.
        let starts = |rng: &mut TraceRng, n: usize| {
            let mut v: Vec<(u64, f64, f64, [f64; 3], f64)> = (0..n)
                .map(|_| {
                    let (wi, li) = draw(rng);
                    let (x, y) = (rng.random::<f64>() * w, rng.random::<f64>() * h);
                    (morton(x as u32, y as u32), x, y, wi, li)
                })
                .collect();
            v.sort_unstable_by_key(|p| p.0);
            v
        };
        // A few rays ahead, their first reads are fetched while this one is traced.
        let ahead = |v: &[(u64, f64, f64, [f64; 3], f64)], k: usize| {
            if let Some(p) = v.get(k + PREFETCH) {
                self.pyr.prefetch(s, p.2 as usize, p.1 as usize);
            }
        };
        let v = starts(&mut rng, rays);
        for (k, &(_, x, y, wi, li)) in v.iter().enumerate() {
            ahead(&v, k);
            self.predict(&mut t, x, y, wi, li);
            self.path(&mut t, [x, y, z_top], wi);
        }
        let v = starts(&mut rng, g1_rays);
        for (k, &(_, x, y, wi, _)) in v.iter().enumerate() {
            ahead(&v, k);
            self.masking(&mut t, x, y, wi);
        }
        t
    }

    /// One path from the plane above the surface.
    fn path(&self, t: &mut Tally, o: [f64; 3], wi: [f64; 3]) {
        let s = self.s;
        let d = self.to_grid([-wi[0], -wi[1], -wi[2]]);
        let Outcome::Hit(mut hit, mut p) = self.pyr.first_hit(s, o, d, None, u64::MAX) else {
            t.not_landed += 1;
            return;
        };
        if !s.is_valid(hit.i, hit.j) {
            t.not_landed += 1;
            return;
        }
        t.landed += 1;
        let mut dir = [-wi[0], -wi[1], -wi[2]];
        let mut wt = [1.0f64; 3];
        for k in 0..self.bounces {
            let m = s.normal(hit.i, hit.j, hit.tri);
            let c = -dot(dir, m);
            // Met from behind: the ray leaked under the surface through rounding; its energy is lost.
            if !(c > 0.0) {
                break;
            }
            let f = self.fresnel(c);
            for ch in 0..3 {
                wt[ch] *= f[ch];
            }
            dir = [dir[0] + 2.0 * c * m[0], dir[1] + 2.0 * c * m[1], dir[2] + 2.0 * c * m[2]];
            match self.pyr.first_hit(s, p, self.to_grid(dir), Some((hit.i, hit.j)), hit.id()) {
                Outcome::Hit(h2, p2) => {
                    t.later_hits += 1;
                    if !s.is_valid(h2.i, h2.j) {
                        t.filled_hits += 1;
                    }
                    hit = h2;
                    p = p2;
                }
                Outcome::Left { side } => {
                    if let Some(b) = self.table.bin(dir) {
                        let table = if k == 0 { &mut t.single } else { &mut t.multi };
                        deposit(table, b, wt);
                        for (ch, w) in wt.iter().enumerate() {
                            t.by_bounce[k][ch] += w;
                            if side {
                                t.side[ch] += w;
                            }
                        }
                        return;
                    }
                    break;
                }
                Outcome::Lost => break,
            }
        }
        for (l, w) in t.lost.iter_mut().zip(wt) {
            *l += w;
        }
    }

    /// One sample of the microfacet model's single scattering at the point above `(x, y)`: the facet
    /// there, drawn with density `D(m) (m.n)`, reflects `wi` into `o` with weight
    /// `<wi.m> / (m.n cos_i) F G2(wi, o)` (Heitz 2014 eq. 99 for `G2`), the estimator of
    /// `int f(wi, o) cos_o do` by the Jacobian `do = 4 |wi.m| dm`.
    fn predict(&self, t: &mut Tally, x: f64, y: f64, wi: [f64; 3], lambda_i: f64) {
        let (i, j, tri) = self.s.locate(x, y);
        if !self.s.is_valid(i, j) {
            return;
        }
        t.pred_samples += 1;
        let m = self.s.normal(i, j, tri);
        let c = dot(wi, m);
        if !(c > 0.0) {
            return;
        }
        let o = [2.0 * c * m[0] - wi[0], 2.0 * c * m[1] - wi[1], 2.0 * c * m[2] - wi[2]];
        let Some((u, p)) = warp(o) else { return };
        let b = self.table.bin_at(u, p);
        let g2 = 1.0 / (1.0 + lambda_i + self.sigma.lambda_at(o, u, p));
        let a = c / (m[2] * wi[2]) * g2;
        let f = self.fresnel(c);
        deposit(&mut t.pred, b, [a * f[0], a * f[1], a * f[2]]);
    }

    /// One masking sample: the point above `(x, y)`, weighted by its projected area towards `wi`
    /// (`<wi.m> / m.n` per unit of macro area), and whether a ray from it towards `wi` leaves unblocked.
    fn masking(&self, t: &mut Tally, x: f64, y: f64, wi: [f64; 3]) {
        let s = self.s;
        let (i, j, tri) = s.locate(x, y);
        if !s.is_valid(i, j) {
            return;
        }
        let m = s.normal(i, j, tri);
        let c = dot(wi, m);
        if !(c > 0.0) {
            return;
        }
        let wt = c / m[2];
        let cz = s.corners(i, j);
        let p = [x, y, s.height_in(&cz, i, j, x, y)];
        let hit = super::surface::Hit { t: 0.0, i, j, tri };
        let seen = matches!(self.pyr.first_hit(s, p, self.to_grid(wi), Some((i, j)), hit.id()), Outcome::Left { .. });
        let v = if seen { 1.0 } else { 0.0 };
        // Toward: the facet's horizontal normal points along the light's azimuth.
        let side = if m[0] * wi[0] + m[1] * wi[1] > 0.0 { 2 } else { 1 };
        for k in [0, side] {
            let g = &mut t.g1[k];
            g[0] += wt;
            g[1] += wt * v;
            g[2] += wt * wt;
            g[3] += wt * wt * v;
        }
    }
}
