//! Which normals the sampling resolves (`data_formats/objective.md`, "The tail the scan cannot resolve").
//!
//! The central difference `s = (h[j+1] - h[j-1]) / 2dx` has the truncation error `-(dx^2 / 6) h'''`; the
//! difference over twice the step, `s2 = (h[j+2] - h[j-2]) / 4dx`, four times that. Richardson's
//! estimate of the first is therefore `e = (s2 - s) / 3`, from the data alone. A sample is **unresolved**
//! when its error, whitened by the robust frame ([`SlopeFrame`]), exceeds [`RESOLUTION_TOLERANCE`] of its
//! whitened slope radius (at least of one robust scale), or when the wider stencil leaves the valid data
//! (the rim of a bump, the edge of a dropout: there the error cannot be bounded). The NDF keeps, per bin,
//! how many of its normals are unresolved ([`super::EmpiricalNdf::unresolved`]); the fit leaves out the
//! bins where they are the majority.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use super::{BinGrid, SlopeFrame};
use crate::scan::bands::{bands_of, Band, BandSource, GridShape, HeightRows};

/// Largest relative slope error (whitened, against `max(|s'|, 1)`) of a resolved normal. A relative
/// error `eps` of the slopes that grows as `|s'|^4` (the rim of a bump, `h ~ sqrt(d)`) changes the
/// density by about `6 eps`; see objective.md for the measurement behind the value.
pub const RESOLUTION_TOLERANCE: f64 = 0.005;

/// Whether the central-difference sample at row `i`, column `j` of `hf` (whose 5-point stencil is
/// valid) is unresolved, given its slope `(sx, sy)`.
#[inline(always)]
fn unresolved_at<H: HeightRows>(hf: &H, frame: &SlopeFrame, i: usize, j: usize, sx: f64, sy: f64, tol: f64) -> bool {
    let (nx, ny) = (hf.nx(), hf.ny());
    if j < 2 || j + 2 >= nx || i < 2 || i + 2 >= ny {
        return true;
    }
    let row = hf.row(i);
    let (l2, r2): (f64, f64) = (row[j - 2].into(), row[j + 2].into());
    let (d2, u2): (f64, f64) = (hf.row(i - 2)[j].into(), hf.row(i + 2)[j].into());
    let ex = ((r2 - l2) * (0.25 / hf.dx()) - sx) * THIRD;
    let ey = ((u2 - d2) * (0.25 / hf.dy()) - sy) * THIRD;
    let w = &frame.whiten;
    let (wx, wy) = (w[0][0] * ex + w[0][1] * ey, w[1][0] * ex + w[1][1] * ey);
    let p = frame.to_whitened(sx, sy);
    let r2s = (p[0] * p[0] + p[1] * p[1]).max(1.0);
    // Squared comparison; a NaN (the wide stencil leaves the valid data) counts as unresolved.
    !(wx * wx + wy * wy <= tol * tol * r2s)
}

/// `1 / 3` rounded: Richardson's factor as a product (a division costs several multiplications).
const THIRD: f64 = 1.0 / 3.0;

/// Largest share of all normals unresolved for which the per-bin counts are kept (and the fit's tail cut
/// can apply). Beyond it the surface is rough at the sampling step itself: the Richardson estimate then
/// measures the surface, not a truncation error, and the NDF is by definition that of the pixel footprint.
pub const MAX_UNRESOLVED_SHARE: f64 = 0.25;

/// Visit every central-difference sample of `src` (bands of rows in parallel), folding
/// `f(acc, band, i, j, sx, sy)`; the band holds rows `i - 2 ..= i + 2` (within the grid).
fn fold_samples<S: BandSource, A: Send>(
    src: &S,
    zero: impl Fn() -> A + Sync + Send,
    f: impl Fn(&mut A, &Band<'_, S::T>, usize, usize, f64, f64) + Sync + Send,
    merge: impl Fn(A, A) -> A + Sync + Send,
) -> A {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    if nx < 3 || ny < 3 {
        return zero();
    }
    // The slopes as the histogram's pass takes them ([`super::NormalScheme::row_slopes`]).
    let (kx, ky) = (0.5 / shape.dx, 0.5 / shape.dy);
    let bands: Vec<std::ops::Range<usize>> = bands_of(1..ny - 1, src.band_rows()).collect();
    bands
        .into_par_iter()
        .fold(&zero, |mut acc, b| {
            let mut buf = Vec::new();
            let band = src.band(b.start.saturating_sub(2), (b.end + 2).min(ny), &mut buf);
            for i in b {
                let (rd, rc, ru) = (band.row(i - 1), band.row(i), band.row(i + 1));
                for j in 1..nx - 1 {
                    let (c, l, r, d, u): (f64, f64, f64, f64, f64) =
                        (rc[j].into(), rc[j - 1].into(), rc[j + 1].into(), rd[j].into(), ru[j].into());
                    if !(c.is_finite() && l.is_finite() && r.is_finite() && d.is_finite() && u.is_finite()) {
                        continue;
                    }
                    f(&mut acc, &band, i, j, (r - l) * kx, (u - d) * ky);
                }
            }
            acc
        })
        .reduce(&zero, merge)
}

/// The resolution test run row by row inside the histogram's pass ([`super::histogram`]), on the rows
/// already in cache: the same samples, slopes and decisions as [`assess`], bit for bit, without its two
/// further passes over the scan. Unresolved normals are binned only while the share can still end at
/// or below [`MAX_UNRESOLVED_SHARE`] (past that the per-bin counts are dropped anyway); rows tested while
/// the share so far is above [`SKIP_SHARE`] are binned after the pass, if at all
/// ([`RowTest::bin_deferred`]).
pub(super) struct RowTest {
    frame: SlopeFrame,
    tol: f64,
    grid: BinGrid,
    nx: usize,
    ny: usize,
    dx: f64,
    dy: f64,
    /// Unresolved samples beyond which the share exceeds [`MAX_UNRESOLVED_SHARE`] whatever the rest.
    cap: f64,
    /// Unresolved samples found so far by every task.
    bad: AtomicU64,
    /// Valid samples tested so far by every task.
    seen: AtomicU64,
    /// Samples tested before the share so far may defer binning ([`SKIP_AFTER`] of the stencils).
    warm: f64,
}

/// Share of the stencils tested before the share so far may defer binning ([`RowTest::row`]).
const SKIP_AFTER: f64 = 1.0 / 64.0;

/// Share so far above which a row's unresolved slopes are not binned in the pass: at twice
/// [`MAX_UNRESOLVED_SHARE`], the share nearly always ends above it and the counts are dropped. When it
/// does not, the deferred rows are binned after the pass ([`RowTest::bin_deferred`]).
const SKIP_SHARE: f64 = 2.0 * MAX_UNRESOLVED_SHARE;

/// Per-task tallies of [`RowTest`].
#[derive(Default)]
pub(super) struct Tally {
    /// Valid central-difference samples.
    all: u64,
    /// Unresolved ones among them.
    bad: u64,
    /// Unresolved samples per cell (empty until the first is binned).
    pub(super) cells: Vec<u64>,
    /// Unresolved slopes the histogram does not count (an overflowing difference), binned apart.
    pending: Option<Box<super::histogram::Block>>,
    /// Rows whose unresolved slopes were not binned while the share so far was high.
    deferred: Vec<usize>,
}

/// The central-difference samples of one row (column `j` at `j - 1`): slopes and per-sample codes, made
/// by one vectorized loop ([`RowTest::row`], or [`RowSlopes::central`] without the test).
#[derive(Default)]
pub(super) struct RowSlopes {
    pub(super) sx: Vec<f64>,
    pub(super) sy: Vec<f64>,
    /// [`VALID`], [`UNRESOLVED`] and [`COUNTED`] bits.
    pub(super) code: Vec<u8>,
    /// Samples with [`COUNTED`] set.
    pub(super) counted: u64,
}

/// The stencil's five heights are finite (the resolution test's validity).
pub(super) const VALID: u8 = 1;
/// The sample is unresolved (set only on the test's rows).
pub(super) const UNRESOLVED: u8 = 2;
/// The histogram counts the sample: `sx + sy + h` is not NaN ([`super::NormalScheme::row_slopes`]).
pub(super) const COUNTED: u8 = 4;

impl RowSlopes {
    /// The slopes and [`COUNTED`] bits of row `i` of `hf` (`1 <= i < ny - 1`), as
    /// [`super::NormalScheme::row_slopes`] takes them, in one branch-free loop.
    pub(super) fn central<H: HeightRows>(&mut self, hf: &H, i: usize) {
        let m = hf.nx().saturating_sub(2);
        self.resize(m);
        let f = |v: H::T| -> f64 { v.into() };
        let (r0, r1, r2) = (hf.row(i - 1), hf.row(i), hf.row(i + 1));
        let (kx, ky) = (0.5 / hf.dx(), 0.5 / hf.dy());
        let (l, c, r, d, u) = (&r1[..m], &r1[1..m + 1], &r1[2..m + 2], &r0[1..m + 1], &r2[1..m + 1]);
        let (sx, sy, code) = (&mut self.sx[..m], &mut self.sy[..m], &mut self.code[..m]);
        let mut counted = 0u64;
        for k in 0..m {
            let (x, y) = ((f(r[k]) - f(l[k])) * kx, (f(u[k]) - f(d[k])) * ky);
            let ok = !(x + y + f(c[k])).is_nan();
            sx[k] = x;
            sy[k] = y;
            code[k] = (ok as u8) << 2;
            counted += ok as u64;
        }
        self.counted = counted;
    }

    fn resize(&mut self, m: usize) {
        self.sx.resize(m, 0.0);
        self.sy.resize(m, 0.0);
        self.code.resize(m, 0);
    }
}

impl Tally {
    pub(super) fn merge(mut self, o: Tally) -> Tally {
        self.all += o.all;
        self.bad += o.bad;
        if self.cells.len() < o.cells.len() {
            self.cells.resize(o.cells.len(), 0);
        }
        self.cells.iter_mut().zip(&o.cells).for_each(|(a, b)| *a += b);
        self.deferred.extend(o.deferred);
        self
    }

    /// Whether the share of unresolved samples is within [`MAX_UNRESOLVED_SHARE`] (the per-bin counts
    /// are kept), as [`RowTest::finish`] decides it.
    pub(super) fn within_cap(&self) -> bool {
        self.bad as f64 / self.all.max(1) as f64 <= MAX_UNRESOLVED_SHARE
    }
}

impl RowTest {
    /// The test for central differences binned on `grid` in `frame`; `stencils` bounds the valid samples.
    pub(super) fn new(frame: SlopeFrame, grid: BinGrid, shape: GridShape, stencils: u64) -> Self {
        RowTest {
            frame,
            tol: RESOLUTION_TOLERANCE,
            grid,
            nx: shape.nx,
            ny: shape.ny,
            dx: shape.dx,
            dy: shape.dy,
            cap: MAX_UNRESOLVED_SHARE * stencils as f64 + 1.0,
            bad: AtomicU64::new(0),
            seen: AtomicU64::new(0),
            warm: SKIP_AFTER * stencils as f64,
        }
    }

    /// Rows the test of row `i` reads: `i - 2 ..= i + 2` within the grid.
    pub(super) fn stencil_rows(&self, i: usize) -> (usize, usize) {
        (i.saturating_sub(2), (i + 3).min(self.ny))
    }

    /// Take the slopes of row `i` (`1 <= i < ny - 1`) of `hf`, which holds rows `i - 2 ..= i + 2`, and
    /// test every sample, into `rs`. Returns whether the row's unresolved samples are to be binned
    /// now: not while the share is already certain to exceed [`MAX_UNRESOLVED_SHARE`], and not while
    /// the share so far is above [`SKIP_SHARE`] (the row is then deferred, in `t`).
    pub(super) fn row<H: HeightRows>(&self, hf: &H, i: usize, t: &mut Tally, rs: &mut RowSlopes) -> bool {
        let (all, bad) = self.test_row(hf, i, rs);
        t.all += all;
        t.bad += bad;
        let seen = self.seen.fetch_add(all, Ordering::Relaxed) + all;
        if bad == 0 {
            return false;
        }
        let before = self.bad.fetch_add(bad, Ordering::Relaxed);
        // Past the cap the share is above the limit whatever the remaining rows hold: stop binning.
        if before as f64 > self.cap {
            return false;
        }
        if seen as f64 >= self.warm && (before + bad) as f64 > SKIP_SHARE * seen as f64 {
            t.deferred.push(i);
            return false;
        }
        true
    }

    /// The slopes and codes of row `i` into `rs` (as [`RowTest::row`], without the tallies): the valid
    /// and the unresolved samples.
    fn test_row<H: HeightRows>(&self, hf: &H, i: usize, rs: &mut RowSlopes) -> (u64, u64) {
        rs.resize(self.nx.saturating_sub(2));
        if self.nx < 3 {
            rs.counted = 0;
            return (0, 0);
        }
        #[cfg(target_arch = "x86_64")]
        let (all, bad, counted) = if super::histogram::avx512() {
            // SAFETY: the CPU supports these AVX-512 subsets (checked just above); the body is safe Rust.
            unsafe { self.codes_avx512(hf, i, rs) }
        } else if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
            unsafe { self.codes_avx2(hf, i, rs) }
        } else {
            self.codes(hf, i, rs)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (all, bad, counted) = self.codes(hf, i, rs);
        rs.counted = counted;
        (all, bad)
    }

    /// After the pass: when the share ends within the cap after all, bin the unresolved slopes of the
    /// rows deferred while it seemed high (read again from `src`), so that every unresolved slope is
    /// binned, as if none had been deferred (the same slopes, the same map: counts add in any order).
    pub(super) fn bin_deferred<S: BandSource>(&self, src: &S, t: &mut Tally) {
        let rows = std::mem::take(&mut t.deferred);
        if rows.is_empty() || !t.within_cap() {
            return;
        }
        // One tally per thread (a tally holds a counter per cell), merged at the end.
        let part = rows
            .par_iter()
            .fold(
                || (Tally::default(), RowSlopes::default(), Vec::new()),
                |(mut part, mut rs, mut buf), &i| {
                    let (lo, hi) = self.stencil_rows(i);
                    self.test_row(&src.band(lo, hi, &mut buf), i, &mut rs);
                    for ((&c, &sx), &sy) in rs.code.iter().zip(&rs.sx).zip(&rs.sy) {
                        if c & (VALID | UNRESOLVED) == VALID | UNRESOLVED {
                            self.bin_apart(sx, sy, &mut part);
                        }
                    }
                    (part, rs, buf)
                },
            )
            .map(|(mut part, _, _)| {
                self.settle(&mut part);
                part
            })
            .reduce(Tally::default, Tally::merge);
        // Binning tallies no samples (`all`, `bad`): only the cells add.
        *t = std::mem::take(t).merge(part);
    }

    /// Bin one unresolved sample that the histogram does not count (its slopes overflow) through the
    /// same blocked mapping, apart from the histogram's blocks.
    pub(super) fn bin_apart(&self, sx: f64, sy: f64, t: &mut Tally) {
        if t.cells.is_empty() {
            t.cells = vec![0; self.grid.cells()];
        }
        let blk = t.pending.get_or_insert_with(|| Box::new(super::histogram::Block::new()));
        blk.sx[blk.n] = sx;
        blk.sy[blk.n] = sy;
        blk.n += 1;
        if blk.n == super::histogram::Block::LEN {
            blk.count_into(&self.frame, &self.grid, &mut t.cells);
        }
    }

    /// Bin the unresolved slopes still waiting in `t` (at the end of a task).
    pub(super) fn settle(&self, t: &mut Tally) {
        if let Some(blk) = t.pending.as_mut() {
            blk.count_into(&self.frame, &self.grid, &mut t.cells);
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    unsafe fn codes_avx512<H: HeightRows>(&self, hf: &H, i: usize, rs: &mut RowSlopes) -> (u64, u64, u64) {
        self.codes(hf, i, rs)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn codes_avx2<H: HeightRows>(&self, hf: &H, i: usize, rs: &mut RowSlopes) -> (u64, u64, u64) {
        self.codes(hf, i, rs)
    }

    /// Fill `rs` for row `i` (column `j` at `j - 1`): the slopes as the histogram takes them, and the
    /// codes; return the valid, the unresolved and the counted samples. Branch-free loops over
    /// equal-length slices, so that they vectorize; the test's arithmetic is [`unresolved_at`]'s,
    /// operation for operation (no contraction into FMA). Where the wide stencil fits (rows
    /// `2..ny - 2`, columns `2..nx - 2`), one loop takes the slopes, the validity, the test and the
    /// counts; the rim of the grid is unresolved (the wide stencil leaves it).
    #[inline(always)]
    fn codes<H: HeightRows>(&self, hf: &H, i: usize, rs: &mut RowSlopes) -> (u64, u64, u64) {
        let nx = self.nx;
        let m = nx - 2;
        let (sxs, sys, code) = (&mut rs.sx[..m], &mut rs.sy[..m], &mut rs.code[..m]);
        let f = |v: H::T| -> f64 { v.into() };
        let (r0, r1, r2) = (hf.row(i - 1), hf.row(i), hf.row(i + 1));
        let (kx, ky, kx2, ky2) = (0.5 / self.dx, 0.5 / self.dy, 0.25 / self.dx, 0.25 / self.dy);
        let (mut all, mut bad, mut counted) = (0u64, 0u64, 0u64);
        let mut rim = |k: usize, sxs: &mut [f64], sys: &mut [f64], code: &mut [u8]| {
            let j = k + 1;
            let v =
                f(r1[j]).is_finite() & f(r1[j - 1]).is_finite() & f(r1[j + 1]).is_finite() & f(r0[j]).is_finite() & f(r2[j]).is_finite();
            let (x, y) = ((f(r1[j + 1]) - f(r1[j - 1])) * kx, (f(r2[j]) - f(r0[j])) * ky);
            let ok = !(x + y + f(r1[j])).is_nan();
            (sxs[k], sys[k]) = (x, y);
            code[k] = v as u8 | UNRESOLVED | (ok as u8) << 2;
            all += v as u64;
            bad += v as u64;
            counted += ok as u64;
        };
        if !(i >= 2 && i + 2 < self.ny && nx >= 5) {
            (0..m).for_each(|k| rim(k, sxs, sys, code));
            return (all, bad, counted);
        }
        rim(0, sxs, sys, code);
        rim(m - 1, sxs, sys, code);
        let n = nx - 4;
        let (rm, rp) = (hf.row(i - 2), hf.row(i + 2));
        let (l2, l, cc, r, r2x) = (&r1[..n], &r1[1..n + 1], &r1[2..n + 2], &r1[3..n + 3], &r1[4..n + 4]);
        let (d, u, d2, u2) = (&r0[2..n + 2], &r2[2..n + 2], &rm[2..n + 2], &rp[2..n + 2]);
        let (out, ox, oy) = (&mut code[1..n + 1], &mut sxs[1..n + 1], &mut sys[1..n + 1]);
        let (c, w) = (self.frame.center, self.frame.whiten);
        let tt = self.tol * self.tol;
        let (mut a, mut b, mut h) = (0u64, 0u64, 0u64);
        for k in 0..n {
            let valid = f(cc[k]).is_finite() & f(l[k]).is_finite() & f(r[k]).is_finite() & f(d[k]).is_finite() & f(u[k]).is_finite();
            let sx = (f(r[k]) - f(l[k])) * kx;
            let sy = (f(u[k]) - f(d[k])) * ky;
            // The histogram's own validity ([`super::NormalScheme::row_slopes`]).
            let ok = !(sx + sy + f(cc[k])).is_nan();
            let ex = ((f(r2x[k]) - f(l2[k])) * kx2 - sx) * THIRD;
            let ey = ((f(u2[k]) - f(d2[k])) * ky2 - sy) * THIRD;
            let (wx, wy) = (w[0][0] * ex + w[0][1] * ey, w[1][0] * ex + w[1][1] * ey);
            let (cx, cy) = (sx - c[0], sy - c[1]);
            let (px, py) = (w[0][0] * cx + w[0][1] * cy, w[1][0] * cx + w[1][1] * cy);
            let r2s = (px * px + py * py).max(1.0);
            // A NaN (the wide stencil leaves the valid data) counts as unresolved.
            let unresolved = !(wx * wx + wy * wy <= tt * r2s);
            ox[k] = sx;
            oy[k] = sy;
            out[k] = valid as u8 | (unresolved as u8) << 1 | (ok as u8) << 2;
            a += valid as u64;
            b += (valid & unresolved) as u64;
            h += ok as u64;
        }
        (all + a, bad + b, counted + h)
    }

    /// Fill the NDF's resolution fields from the merged tallies, as [`assess`] does.
    pub(super) fn finish(&self, t: Tally, ndf: &mut super::EmpiricalNdf) {
        let share = t.bad as f64 / t.all.max(1) as f64;
        ndf.unresolved_share = Some(share);
        ndf.unresolved = Vec::new();
        if !t.within_cap() {
            return;
        }
        ndf.unresolved = ndf.bin_cells.iter().map(|&c| t.cells.get(c as usize).copied().unwrap_or(0)).collect();
    }
}

/// Fill [`super::EmpiricalNdf::unresolved_share`] and, up to [`MAX_UNRESOLVED_SHARE`],
/// [`super::EmpiricalNdf::unresolved`] for an NDF of central differences counted from `hf` (other
/// schemes are left unassessed). Two passes: the share first (no binning), then the bins of the
/// unresolved normals only. The NDF's own pass runs the same test fused with its histogram
/// (`RowTest`); this form is the reference it is tested against.
pub fn assess<S: BandSource>(src: &S, ndf: &mut super::EmpiricalNdf) {
    if ndf.scheme != super::NormalScheme::Central || ndf.grid.n == 0 {
        return;
    }
    let (frame, tol) = (ndf.frame, ndf.resolution_tolerance);
    let (all, bad) = fold_samples(
        src,
        || (0u64, 0u64),
        |a, hf, i, j, sx, sy| {
            a.0 += 1;
            a.1 += unresolved_at(hf, &frame, i, j, sx, sy, tol) as u64;
        },
        |a, b| (a.0 + b.0, a.1 + b.1),
    );
    let share = bad as f64 / all.max(1) as f64;
    ndf.unresolved_share = Some(share);
    ndf.unresolved = Vec::new();
    if !(share <= MAX_UNRESOLVED_SHARE) {
        return;
    }
    let grid = ndf.grid;
    let cells = fold_samples(
        src,
        || vec![0u64; grid.cells()],
        |c, hf, i, j, sx, sy| {
            if unresolved_at(hf, &frame, i, j, sx, sy, tol) {
                c[grid.cell_of(frame.to_lambert(sx, sy))] += 1;
            }
        },
        |mut a, b| {
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        },
    );
    ndf.unresolved = ndf.bin_cells.iter().map(|&c| cells[c as usize]).collect();
}

/// The per-normal test against a truth: for every central-difference sample of an NDF, whether the
/// test flags it ([`assess`]'s decision) and whether it truly is unresolved, its slope `s` off the
/// exact gradient `g` by more than the tolerance in the test's own measure,
/// `|W (s - g)| > eps max(|W (s - c)|, 1)`; per bin, whether most of its normals are flagged
/// ([`super::EmpiricalNdf::unresolved`]) and whether most truly are.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Confusion {
    /// Samples with an exact gradient.
    pub normals: u64,
    /// Of them, truly unresolved.
    pub truly: u64,
    /// Flagged but truly resolved.
    pub false_pos: u64,
    /// Truly unresolved but not flagged.
    pub false_neg: u64,
    /// Non-empty bins.
    pub bins: u64,
    /// Of them, with a truly unresolved majority.
    pub bins_truly: u64,
    /// Majority flagged, not truly.
    pub bins_false_pos: u64,
    /// Majority truly unresolved, not flagged.
    pub bins_false_neg: u64,
}

impl Confusion {
    /// Share of the truly resolved normals that are flagged.
    pub fn fp_rate(&self) -> f64 {
        self.false_pos as f64 / (self.normals - self.truly).max(1) as f64
    }
    /// Share of the truly unresolved normals that are not flagged.
    pub fn fn_rate(&self) -> f64 {
        self.false_neg as f64 / self.truly.max(1) as f64
    }
    /// [`Confusion::fp_rate`] over bins.
    pub fn bin_fp_rate(&self) -> f64 {
        self.bins_false_pos as f64 / (self.bins - self.bins_truly).max(1) as f64
    }
    /// [`Confusion::fn_rate`] over bins.
    pub fn bin_fn_rate(&self) -> f64 {
        self.bins_false_neg as f64 / self.bins_truly.max(1) as f64
    }
}

/// [`Confusion`] of the test on the central-difference NDF `ndf` of `hf` (its frame, grid and
/// tolerance), against `exact(i, j)`, the true gradient at row `i`, column `j` (`None`: no truth
/// there, the sample is left out). A measurement of the estimate, not part of the pipeline.
pub fn confusion<S: BandSource>(
    src: &S,
    ndf: &super::EmpiricalNdf,
    exact: impl Fn(usize, usize) -> Option<[f64; 2]> + Sync + Send,
) -> Confusion {
    let (frame, tol, grid) = (ndf.frame, ndf.resolution_tolerance, ndf.grid);
    // Per cell: samples, flagged, truly unresolved; then the per-normal tallies.
    type Acc = (Vec<[u64; 3]>, [u64; 4]);
    let (cells, t) = fold_samples(
        src,
        || -> Acc { (vec![[0; 3]; grid.cells()], [0; 4]) },
        |a, hf, i, j, sx, sy| {
            let Some(g) = exact(i, j) else { return };
            let flagged = unresolved_at(hf, &frame, i, j, sx, sy, tol);
            let w = &frame.whiten;
            let (ex, ey) = (sx - g[0], sy - g[1]);
            let (wx, wy) = (w[0][0] * ex + w[0][1] * ey, w[1][0] * ex + w[1][1] * ey);
            let p = frame.to_whitened(sx, sy);
            let truly = !(wx * wx + wy * wy <= tol * tol * (p[0] * p[0] + p[1] * p[1]).max(1.0));
            let c = &mut a.0[grid.cell_of(frame.to_lambert(sx, sy))];
            c[0] += 1;
            c[1] += flagged as u64;
            c[2] += truly as u64;
            a.1[0] += 1;
            a.1[1] += truly as u64;
            a.1[2] += (flagged && !truly) as u64;
            a.1[3] += (truly && !flagged) as u64;
        },
        |mut a, b| {
            a.0.iter_mut().zip(&b.0).for_each(|(x, y)| (0..3).for_each(|k| x[k] += y[k]));
            (0..4).for_each(|k| a.1[k] += b.1[k]);
            a
        },
    );
    let mut c = Confusion { normals: t[0], truly: t[1], false_pos: t[2], false_neg: t[3], ..Confusion::default() };
    for &[n, f, u] in cells.iter().filter(|c| c[0] > 0) {
        let (flagged, truly) = (2 * f > n, 2 * u > n);
        c.bins += 1;
        c.bins_truly += truly as u64;
        c.bins_false_pos += (flagged && !truly) as u64;
        c.bins_false_neg += (truly && !flagged) as u64;
    }
    c
}
