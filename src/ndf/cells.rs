//! Per-cell integrals of the empirical NDF: projected solid angle, solid angle and centroid of each
//! Lambert-disk cell by Gauss-Legendre quadrature (step 4 of [`super`]), and the bins built from them.

use rayon::prelude::*;

use super::{grid, lattice, quantum, BinGrid, NdfBin, QuadOrder, RimShape, SlopeFrame};

/// Integrals over one cell: projected solid angle, solid angle and the W-weighted centroid.
///
/// The integrands ([`SlopeFrame::densities`]) are analytic in `p`; their complex singularities sit in
/// the rim zone (`q = 0` of [`SlopeFrame::proj_density`] at `u = m'_z ~ +-i ring`) and, for rough frames,
/// at the central peak (`|p| ~ i core`), see [`RimShape`]. For a cell wholly inside the disk,
/// [`cheap_rule`] bounds the Bernstein-ellipse parameter `rho` of the cell against them, and
/// Gauss-Legendre with `k` points per axis then errs like `rho^(-2k)` (Trefethen, "Is Gauss quadrature
/// better than Clenshaw-Curtis?", Thm. 4.5): 4 x 4 nodes when `rho^-8 <= CHEAP_RULE_EPS`, 8 x 8 when
/// `rho^-16 <= CHEAP_RULE_EPS`. Every other cell (rim cells, cells near the fast zones) takes the
/// accurate rule of [`BinGrid::quadrature`] with [`QuadOrder::Standard`] (polar with logarithmic
/// substitutions on the rim). The bound is asserted against a fine reference over extreme frames in
/// `cheap_rule_error_is_bounded_over_extreme_frames`.
pub(super) fn cell_integrals(frame: &SlopeFrame, rim: &RimShape, grid: &BinGrid, c: usize) -> (f64, f64, [f64; 2]) {
    let [x0, x1, y0, y1] = grid.bounds(c);
    let [w, o, px, py] = match cheap_rule(x0, x1, y0, y1, rim) {
        Some(rule) => tensor_sums(frame, x0, x1, y0, y1, rule),
        None => {
            let mut sums = DensitySums { frame, s: [0.0; 4] };
            grid.quadrature_into(c, QuadOrder::Standard, rim, &mut sums);
            sums.s
        }
    };
    let centroid = if w > 0.0 {
        [px / w, py / w]
    } else {
        // Guard: a cell with no projected solid angle (a sliver on the rim) takes its geometric centre.
        [0.5 * (x0 + x1), 0.5 * (y0 + y1)]
    };
    (w, o, centroid)
}

/// `[W, omega, int p_x dW, int p_y dW]` accumulated over quadrature nodes ([`cell_integrals`]'s
/// accurate rule).
struct DensitySums<'a> {
    frame: &'a SlopeFrame,
    s: [f64; 4],
}

impl grid::Nodes for DensitySums<'_> {
    #[inline]
    fn node(&mut self, p: [f64; 2], wt: f64) {
        let (dw, dom) = self.frame.densities(p);
        self.s[0] += dw * wt;
        self.s[1] += dom * wt;
        self.s[2] += p[0] * dw * wt;
        self.s[3] += p[1] * dw * wt;
    }

    /// A polar ray at once: rim cells take ~2000 nodes each and most of the time of small grids.
    #[inline]
    fn ray(&mut self, cs: f64, sn: f64, wphi: f64, u: &[f64], w: &[f64]) {
        let [w_sum, o_sum, r_sum] = ray_sums(self.frame, cs, sn, u, w);
        self.s[0] += wphi * w_sum;
        self.s[1] += wphi * o_sum;
        self.s[2] += wphi * cs * r_sum;
        self.s[3] += wphi * sn * r_sum;
    }
}

/// `[sum w_k dW_k, sum w_k domega_k, sum w_k r_k dW_k]` along the ray `(cs, sn)` at `u_k = m'_z`: the
/// densities of [`SlopeFrame::densities`] from `u` directly (`m'_xy = sqrt(1 - u^2) (cs, sn)`, `r =
/// sqrt(2 (1 - u))`), four nodes per step in vector lanes (AVX2 when the CPU has it, as
/// [`tensor_sums`]).
#[inline]
fn ray_sums(frame: &SlopeFrame, cs: f64, sn: f64, u: &[f64], w: &[f64]) -> [f64; 3] {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
            return unsafe { ray_sums_avx2(frame, cs, sn, u, w) };
        }
    }
    ray_sums_any(frame, cs, sn, u, w)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn ray_sums_avx2(frame: &SlopeFrame, cs: f64, sn: f64, u: &[f64], w: &[f64]) -> [f64; 3] {
    ray_sums_any(frame, cs, sn, u, w)
}

/// Vector lanes of [`ray_sums`].
const L: usize = 4;

#[inline(always)]
fn ray_sums_any(frame: &SlopeFrame, cs: f64, sn: f64, u: &[f64], w: &[f64]) -> [f64; 3] {
    let uw = &frame.unwhiten;
    // The scan vector's xy part is `c u + sqrt(1 - u^2) U (cs, sn)`.
    let (ax, ay) = (uw[0][0] * cs + uw[0][1] * sn, uw[1][0] * cs + uw[1][1] * sn);
    let (cx, cy, det) = (frame.center[0], frame.center[1], frame.det_unwhiten);
    let mut s = [[0.0f64; L]; 3];
    // A function, not a closure, so that it inlines into the AVX2 copy.
    #[inline(always)]
    fn add(s: &mut [[f64; L]; 3], k: [f64; 5], u: &[f64; L], wt: &[f64; L]) {
        let [ax, ay, cx, cy, det] = k;
        // Lane-wise array steps (the form the SLP vectorizer packs; the guard is a select as in
        // `densities_branch_free`).
        let m: [f64; L] = std::array::from_fn(|i| ((1.0 - u[i]) * (1.0 + u[i])).max(0.0).sqrt());
        let q: [f64; L] = std::array::from_fn(|i| {
            let (gx, gy) = (cx * u[i] + m[i] * ax, cy * u[i] + m[i] * ay);
            gx * gx + gy * gy + u[i] * u[i]
        });
        // Guard: q = 0 only by rounding on the rim, where both densities vanish (as in `densities`).
        let qs: [f64; L] = std::array::from_fn(|i| if q[i] > 0.0 { q[i] } else { f64::INFINITY });
        let dw: [f64; L] = std::array::from_fn(|i| det * u[i] / (qs[i] * qs[i]));
        let dom: [f64; L] = std::array::from_fn(|i| det / (qs[i] * qs[i].sqrt()));
        let r: [f64; L] = std::array::from_fn(|i| (2.0 * (1.0 - u[i])).max(0.0).sqrt());
        for i in 0..L {
            s[0][i] += dw[i] * wt[i];
            s[1][i] += dom[i] * wt[i];
            s[2][i] += r[i] * dw[i] * wt[i];
        }
    }
    let k = [ax, ay, cx, cy, det];
    let (uc, wc) = (u.chunks_exact(L), w.chunks_exact(L));
    let (ur, wr) = (uc.remainder(), wc.remainder());
    for (u4, w4) in uc.zip(wc) {
        add(&mut s, k, u4.try_into().expect("chunks of L"), w4.try_into().expect("chunks of L"));
    }
    if !ur.is_empty() {
        // The last nodes, padded with weight 0 at a harmless u.
        let (mut u4, mut w4) = ([0.5; L], [0.0; L]);
        u4[..ur.len()].copy_from_slice(ur);
        w4[..wr.len()].copy_from_slice(wr);
        add(&mut s, k, &u4, &w4);
    }
    s.map(|lanes| lanes.iter().sum())
}

/// Target relative error of the cheap cell rules (the a-priori `rho^(-2k)` estimate). The NDF's own
/// error per bin is far larger (Poisson: 12% at 64 counts; midpoint rule 1e-4 to 1e-2,
/// `data_formats/ndf_csv.md`).
pub const CHEAP_RULE_EPS: f64 = 1e-11;

/// The tensor Gauss-Legendre rule a cell may take instead of the accurate rule, if any (see
/// [`cell_integrals`]). `rho >= y + sqrt(1 + y^2)` where `y` is the distance of the nearest singularity
/// over the half-width of the cell; the worst case is a singularity facing the middle of the cell. Three
/// singularities, from `q = u^2 + |c u + U m'_xy|^2 = 0` (`U = Sigma^(1/2)`, `lambda` its eigenvalues):
/// - the rim zone, at a distance `d_u = hypot(u_min, ring)` in `u`, against half the cell's `u` range;
/// - beside the small principal axis, `lambda_max x^2` cancels `u^2 + lambda_min y^2` at a distance
///   `d_u / sqrt(lambda_max) = core d_u` in `p` (close for rough anisotropic frames), against half the side;
/// - the central peak of rough frames, at `hypot(|p|_min, core)` in `p`, against half the side.
fn cheap_rule(x0: f64, x1: f64, y0: f64, y1: f64, rim: &RimShape) -> Option<&'static [(f64, f64)]> {
    let far2 = x0.abs().max(x1.abs()).powi(2) + y0.abs().max(y1.abs()).powi(2);
    // Rim cells (and cells touching the rim) keep the polar rule.
    if far2 >= 2.0 {
        return None;
    }
    let (nx, ny) = (0.0f64.clamp(x0, x1), 0.0f64.clamp(y0, y1));
    let near2 = nx * nx + ny * ny;
    let (u_min, u_max) = (1.0 - 0.5 * far2, 1.0 - 0.5 * near2);
    let half_side = 0.5 * (x1 - x0).max(y1 - y0);
    let d_u = u_min.hypot(rim.ring);
    // Guard: a zero u range (impossible for a cell of positive size) must not divide by zero.
    let y_rim = d_u / (0.5 * (u_max - u_min)).max(f64::MIN_POSITIVE);
    let y_axis = rim.core * d_u / half_side;
    let y_core = near2.sqrt().hypot(rim.core) / half_side;
    let y = y_rim.min(y_axis).min(y_core);
    let rho = y + (1.0 + y * y).sqrt();
    // Non-finite rho: no singularity in reach (SMOOTH shapes), the cheapest rule is exact enough.
    if !rho.is_finite() || rho.powi(-8) <= CHEAP_RULE_EPS {
        Some(&grid::GL4)
    } else if rho.powi(-16) <= CHEAP_RULE_EPS {
        Some(&grid::GL8)
    } else {
        None
    }
}

/// `[W, omega, int p_x dW, int p_y dW]` over a rectangle inside the disk by tensor Gauss-Legendre.
///
/// Most cells of a grid take this rule (all but the rim), so it runs in vector registers: the `K` nodes
/// along x of one row of nodes are evaluated together with the branch-free densities, in `K` lanes of
/// partial sums, and on x86-64 CPUs with AVX2 the loop is compiled 4 wide (IEEE operations, no FMA, so
/// the same results as the default 2-wide build).
#[inline]
fn tensor_sums(frame: &SlopeFrame, x0: f64, x1: f64, y0: f64, y1: f64, rule: &[(f64, f64)]) -> [f64; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
            return unsafe { tensor_sums_avx2(frame, x0, x1, y0, y1, rule) };
        }
    }
    tensor_sums_any(frame, x0, x1, y0, y1, rule)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn tensor_sums_avx2(frame: &SlopeFrame, x0: f64, x1: f64, y0: f64, y1: f64, rule: &[(f64, f64)]) -> [f64; 4] {
    tensor_sums_any(frame, x0, x1, y0, y1, rule)
}

#[inline(always)]
fn tensor_sums_any(frame: &SlopeFrame, x0: f64, x1: f64, y0: f64, y1: f64, rule: &[(f64, f64)]) -> [f64; 4] {
    match rule.len() {
        4 => tensor_sums_k::<4>(frame, x0, x1, y0, y1, rule),
        8 => tensor_sums_k::<8>(frame, x0, x1, y0, y1, rule),
        k => unreachable!("the cheap rules are GL4 and GL8, not {k} points"),
    }
}

#[inline(always)]
fn tensor_sums_k<const K: usize>(frame: &SlopeFrame, x0: f64, x1: f64, y0: f64, y1: f64, rule: &[(f64, f64)]) -> [f64; 4] {
    let (hx, hy) = (0.5 * (x1 - x0), 0.5 * (y1 - y0));
    let (mx, my) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let xs: [f64; K] = std::array::from_fn(|i| mx + hx * rule[i].0);
    let wxs: [f64; K] = std::array::from_fn(|i| rule[i].1 * hx);
    let mut s = [[0.0f64; K]; 4];
    for &(v, wv) in &rule[..K] {
        let (y, wy) = (my + hy * v, wv * hy);
        for i in 0..K {
            let (dw, dom) = frame.densities_branch_free([xs[i], y]);
            let wt = wxs[i] * wy;
            s[0][i] += dw * wt;
            s[1][i] += dom * wt;
            s[2][i] += xs[i] * dw * wt;
            s[3][i] += y * dw * wt;
        }
    }
    s.map(|lanes| lanes.iter().sum())
}

/// Bins from per-cell counts: every cell that meets the disk or holds a count, with its exact `W`, solid
/// angle and W-weighted centroid. Shared with `scale`, which bins sampled slopes on the same grid.
pub(crate) fn build_bins(
    frame: &SlopeFrame,
    grid: &BinGrid,
    counts: &[u64],
    n: u64,
    lattice: Option<&quantum::SlopeLattice>,
) -> (Vec<NdfBin>, Vec<u32>) {
    let nf = n as f64;
    let cells: Vec<usize> = (0..grid.cells()).filter(|&c| grid.meets_disk(c) || counts[c] > 0).collect();
    let rim = frame.rim_shape();
    let mut ints: Vec<(f64, f64, [f64; 2])> = cells.par_iter().map(|&c| cell_integrals(frame, &rim, grid, c)).collect();
    if let Some(lat) = lattice {
        lattice::respect_lattice(frame, grid, lat, &cells, &mut ints);
    }
    let bins: Vec<NdfBin> = cells
        .par_iter()
        .zip(&ints)
        .map(|(&c, &(w, o, centroid))| {
            let count = counts[c];
            // Guard: W = 0 only for a rim sliver of zero projected solid angle, or a lattice cell that
            // holds no node; D there is 0, not 0/0.
            let (d, stderr) = if w > 0.0 { (count as f64 / (nf * w), (count.max(1) as f64).sqrt() / (nf * w)) } else { (0.0, 0.0) };
            NdfBin { m: frame.normal_at(centroid), d, stderr, count, solid_angle: o, proj_solid_angle: w }
        })
        .collect();
    (bins, cells.into_iter().map(|c| c as u32).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// For any frame, the bins' projected solid angles sum to pi (the integral of cos over the
    /// hemisphere) and their solid angles to 2 pi: exact values, reached to the quadrature error,
    /// including near-delta frames (the floor), strong anisotropy and tilted centres, where the whole
    /// hemisphere beyond the data is squeezed into a thin rim zone of the disk.
    #[test]
    fn bins_tile_the_hemisphere_for_extreme_frames() {
        let frames = [
            SlopeFrame::new([0.0, 0.0], [[0.09, 0.0], [0.0, 0.09]]),
            SlopeFrame::new([0.3, -0.1], [[0.0, 0.0], [0.0, 0.0]]),
            SlopeFrame::new([0.5, 0.4], [[1e-6, 0.0], [0.0, 1.0]]),
            SlopeFrame::new([-0.2, 0.1], [[4e-4, 3e-4], [3e-4, 9e-4]]),
            SlopeFrame::new([0.0, 0.0], [[100.0, 0.0], [0.0, 25.0]]),
        ];
        for f in frames {
            for n in [15, 61] {
                let g = BinGrid::new(n);
                let (mut w, mut o) = (0.0, 0.0);
                for c in 0..g.cells() {
                    let (cw, co, _) = cell_integrals(&f, &f.rim_shape(), &g, c);
                    w += cw;
                    o += co;
                }
                eprintln!(
                    "frame {:?} n {n}: W - pi = {:.2e}, omega - 2pi = {:.2e}",
                    f.cov,
                    w - std::f64::consts::PI,
                    o - 2.0 * std::f64::consts::PI
                );
                // Measured: <= 1e-10 for ordinary frames, a few 1e-6 at the anisotropy cap with a tilted
                // centre (the turned grid's cells cross its 0.01-radian rim zone obliquely).
                assert!((w - std::f64::consts::PI).abs() < 1e-5, "W {w}");
                assert!((o - 2.0 * std::f64::consts::PI).abs() < 1e-5, "omega {o}");
            }
        }
    }

    /// The cheap cell rules' a-priori bound holds: for every cell that takes 4 x 4 or 8 x 8
    /// Gauss-Legendre, `W` and the solid angle agree with an independent fine reference (6 x 6 sub-cells
    /// of 8 x 8 Gauss-Legendre each, `QuadOrder::Fine(6)` with the smooth shape: these cells are far from
    /// the fast zones, and the reference converges far faster than the rule under test; the polar rule
    /// is not used as reference because near the centre it is itself only good to ~4e-8) to 1e-8
    /// relative: `CHEAP_RULE_EPS` = 1e-11 with a factor 1000 for the constant of the Bernstein-ellipse bound (Trefethen Thm. 4.5 has
    /// `64 M / (15 (rho^2 - 1))`, M the integrand's size on the ellipse relative to its mean). Frames:
    /// near-delta, the plane floor with a tilt, anisotropy at the cap, tilted correlated, very rough, and
    /// rough with anisotropy 100 (the singularity beside the small axis).
    #[test]
    fn cheap_rule_error_is_bounded_over_extreme_frames() {
        let frames = [
            SlopeFrame::new([0.0, 0.0], [[4e-8, 0.0], [0.0, 4e-8]]),
            SlopeFrame::new([0.3, -0.1], [[0.0, 0.0], [0.0, 0.0]]),
            SlopeFrame::new([0.5, 0.4], [[1e-6, 0.0], [0.0, 1.0]]),
            SlopeFrame::new([-0.2, 0.1], [[4e-4, 3e-4], [3e-4, 9e-4]]),
            SlopeFrame::new([0.1, -0.05], [[0.12, 0.02], [0.02, 0.03]]),
            SlopeFrame::new([0.0, 0.0], [[100.0, 0.0], [0.0, 25.0]]),
            SlopeFrame::new([1.0, 0.5], [[100.0, 0.0], [0.0, 0.01]]),
        ];
        let mut worst = 0.0f64;
        for f in frames {
            let rim = f.rim_shape();
            for n in [15, 63, 255] {
                let g = BinGrid::new(n);
                let (mut cheap, mut all) = (0usize, 0usize);
                // Every cell on the small grids, a lattice of cells on the large one (time).
                let step = if n > 100 { 7 } else { 1 };
                for c in (0..g.cells()).step_by(step) {
                    if !g.meets_disk(c) {
                        continue;
                    }
                    all += 1;
                    let [x0, x1, y0, y1] = g.bounds(c);
                    let Some(rule) = cheap_rule(x0, x1, y0, y1, &rim) else { continue };
                    cheap += 1;
                    let s = tensor_sums(&f, x0, x1, y0, y1, rule);
                    let (mut w, mut o) = (0.0, 0.0);
                    g.quadrature(c, QuadOrder::Fine(6), &RimShape::SMOOTH, |p, wt| {
                        let (dw, dom) = f.densities(p);
                        w += dw * wt;
                        o += dom * wt;
                    });
                    let e = ((s[0] - w) / w).abs().max(((s[1] - o) / o).abs());
                    worst = worst.max(e);
                    assert!(e <= 1e-8, "frame {:?} n {n} cell {c}: cheap rule off by {e:.2e}", f.cov);
                }
                eprintln!("frame {:?} n {n}: {cheap} of {all} cells cheap", f.cov);
            }
        }
        eprintln!("worst relative error of the cheap rules: {worst:.2e}");
    }

    /// The rim cells' ray-at-once sums (`ray_sums`: densities from `u = m'_z` directly, in vector lanes)
    /// equal the same nodes evaluated one at a time through `SlopeFrame::densities(p)` (the generic
    /// path of `BinGrid::quadrature`), to rounding, for narrow, tilted, anisotropic and rough frames.
    #[test]
    fn ray_sums_match_pointwise_densities() {
        let frames = [
            SlopeFrame::new([0.0, 0.0], [[0.09, 0.0], [0.0, 0.09]]),
            SlopeFrame::new([0.5, 0.4], [[1e-6, 0.0], [0.0, 1.0]]),
            SlopeFrame::new([-0.2, 0.1], [[4e-4, 3e-4], [3e-4, 9e-4]]),
            SlopeFrame::new([0.8, 0.4], [[0.01, 0.0], [0.0, 0.04]]),
            SlopeFrame::new([0.0, 0.0], [[100.0, 0.0], [0.0, 25.0]]),
        ];
        for f in frames {
            let rim = f.rim_shape();
            let g = BinGrid::new(25);
            for c in 0..g.cells() {
                let [x0, x1, y0, y1] = g.bounds(c);
                if !g.meets_disk(c) || cheap_rule(x0, x1, y0, y1, &rim).is_some() {
                    continue;
                }
                let (w, o, m) = cell_integrals(&f, &rim, &g, c);
                let (mut rw, mut ro, mut rx) = (0.0, 0.0, 0.0);
                g.quadrature(c, QuadOrder::Standard, &rim, |p, wt| {
                    let (dw, dom) = f.densities(p);
                    rw += dw * wt;
                    ro += dom * wt;
                    rx += p[0] * dw * wt;
                });
                let tol = 1e-12;
                assert!((w - rw).abs() <= tol * rw.max(1e-300) + 1e-300, "frame {:?} cell {c}: W {w} vs {rw}", f.cov);
                assert!((o - ro).abs() <= tol * ro, "frame {:?} cell {c}: omega {o} vs {ro}", f.cov);
                if rw > 1e-12 {
                    assert!((m[0] * w - rx).abs() <= tol * (rx.abs() + rw), "frame {:?} cell {c}: centroid", f.cov);
                }
            }
        }
    }

    /// The polar rule's angular pieces grow with the frame's ring (`grid::angular_piece`): for frames
    /// of ring 0.05 and more (slope scales of 0.1 to 0.3, tilted and anisotropic), every rim cell's `W`
    /// and solid angle agree with an independent reference that resolves the angle 4 times finer in each
    /// direction (`QuadOrder::Fine(4)`: 4 x 4 sub-cells with their own polar pieces; `Fine(8)` agrees
    /// with it to 1e-10) to 3e-5 relative. Measured worst: 1.6e-5, on the coarsest grid (15 cells) of
    /// the tilted frame; 0.02 rad pieces everywhere gave 1.2e-5 there, so the rule's error on coarse
    /// rim cells comes mostly from elsewhere. Either is far below a bin's counting error (1/sqrt(64)).
    /// Every rim cell (one the cheap rule does not take) of an `n`-cell grid over frame `f`, against
    /// `QuadOrder::Fine(fine)`: `(cell, relative difference of W or solid angle, W, reference W)`. Slivers
    /// of the rim (W below 1e-12 of the hemisphere's pi) are compared absolutely.
    fn rim_cell_differences(f: &SlopeFrame, n: usize, fine: usize) -> Vec<(usize, f64, f64, f64)> {
        let (rim, g) = (f.rim_shape(), BinGrid::new(n));
        let mut out = Vec::new();
        for c in 0..g.cells() {
            let [x0, x1, y0, y1] = g.bounds(c);
            if !g.meets_disk(c) || cheap_rule(x0, x1, y0, y1, &rim).is_some() {
                continue;
            }
            let (w, o, _) = cell_integrals(f, &rim, &g, c);
            let (mut rw, mut ro) = (0.0, 0.0);
            g.quadrature(c, QuadOrder::Fine(fine), &rim, |p, wt| {
                let (dw, dom) = f.densities(p);
                rw += dw * wt;
                ro += dom * wt;
            });
            let e = ((w - rw).abs() / rw.max(1e-12 * std::f64::consts::PI)).max((o - ro).abs() / ro.max(1e-12));
            out.push((c, e, w, rw));
        }
        out
    }

    #[test]
    fn wide_rings_take_long_angular_pieces() {
        let frames = [
            SlopeFrame::new([0.0, 0.0], [[0.09, 0.0], [0.0, 0.09]]),
            SlopeFrame::new([0.0, 0.0], [[0.04, 0.0], [0.0, 0.01]]),
            SlopeFrame::new([0.3, -0.2], [[0.04, 0.01], [0.01, 0.02]]),
            SlopeFrame::new([0.8, 0.4], [[0.01, 0.0], [0.0, 0.04]]),
        ];
        let mut worst = 0.0f64;
        for f in frames {
            let rim = f.rim_shape();
            assert!(rim.ring >= 0.05, "{rim:?}");
            for n in [15, 25, 61] {
                for (c, e, w, rw) in rim_cell_differences(&f, n, 4) {
                    worst = worst.max(e);
                    assert!(e <= 3e-5, "frame {:?} n {n} cell {c}: {w} vs {rw}", f.cov);
                }
            }
        }
        eprintln!("worst relative rim-cell difference from the 4x finer reference: {worst:.2e}");
    }

    // Today's worst rim-cell error per frame of `rim_cells_of_tilted_and_near_delta_frames_stay_within_todays_error`,
    // rounded up by half (the measurements: data_formats/ndf_csv.md, step 4). The near-delta bounds are large
    // on tiny rim cells; lowering them is the open work on the rim rule.
    const BOUND_TILTED_2: f64 = 2.5e-4;
    const BOUND_TILTED_2_ANISO: f64 = 5e-5;
    const BOUND_TILTED_08: f64 = 2.5e-5;
    const BOUND_NEAR_DELTA: f64 = 0.25;
    const BOUND_NEAR_DELTA_TILTED: f64 = 1e-4;
    const BOUND_PLANE_TILTED: f64 = 0.25;

    /// Rim cells of tilted and near-delta frames against a finer reference (`QuadOrder::Fine(8)`: 8 x 8
    /// sub-cells, each with its own polar pieces; `Fine(16)` on the worst cell shows it has converged), per
    /// frame over 15, 25 and 61 cells across. The polar rule's error on these rim cells is not small on coarse
    /// grids of tilted frames (the frames of `wide_rings_take_long_angular_pieces` stay below 3e-5; these do
    /// not); the bounds are today's worst, so that it cannot grow unnoticed.
    #[test]
    fn rim_cells_of_tilted_and_near_delta_frames_stay_within_todays_error() {
        let cases: [(&str, SlopeFrame, f64); 6] = [
            ("tilted by 2", SlopeFrame::new([2.0, 0.0], [[0.04, 0.0], [0.0, 0.04]]), BOUND_TILTED_2),
            ("tilted by 2, anisotropic", SlopeFrame::new([1.5, -1.3], [[0.09, 0.02], [0.02, 0.01]]), BOUND_TILTED_2_ANISO),
            ("tilted 0.8, 0.4", SlopeFrame::new([0.8, 0.4], [[0.01, 0.0], [0.0, 0.04]]), BOUND_TILTED_08),
            ("near-delta", SlopeFrame::new([0.0, 0.0], [[4e-8, 0.0], [0.0, 4e-8]]), BOUND_NEAR_DELTA),
            ("near-delta, tilted", SlopeFrame::new([-0.2, 0.1], [[4e-4, 3e-4], [3e-4, 9e-4]]), BOUND_NEAR_DELTA_TILTED),
            ("plane floor, tilted", SlopeFrame::new([0.3, -0.1], [[0.0, 0.0], [0.0, 0.0]]), BOUND_PLANE_TILTED),
        ];
        let mut failures = Vec::new();
        for (name, f, bound) in cases {
            let rim = f.rim_shape();
            let mut worst = (0.0f64, 0usize, 0usize, 0.0f64, 0.0f64);
            for n in [15, 25, 61] {
                for (c, e, w, rw) in rim_cell_differences(&f, n, 8) {
                    if e > worst.0 {
                        worst = (e, n, c, w, rw);
                    }
                }
            }
            // The reference has converged where it matters: twice finer again moves the worst cell's W far less.
            let (e, n, c, w, rw) = worst;
            let g = BinGrid::new(n);
            let mut r16 = 0.0;
            g.quadrature(c, QuadOrder::Fine(16), &rim, |p, wt| r16 += f.densities(p).0 * wt);
            eprintln!("{name}: worst rim cell {e:.2e} relative (n {n}, cell {c}: W {w:.6e}, Fine(8) {rw:.6e}, Fine(16) {r16:.6e}), bound {bound:.1e}");
            if e > bound {
                failures.push(format!("{name}: {e:.2e} > {bound:.1e} (n {n}, cell {c})"));
            }
        }
        assert!(failures.is_empty(), "rim-cell error grew: {failures:?}");
    }
}
