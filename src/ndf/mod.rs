//! The empirical NDF: the projected-area-weighted density of microfacet normals of a heightfield
//! (Walter et al. sec. 2 and eq. 9; Heitz sec. 2.2, eq. 9 and 64).
//!
//! Pipeline ([`empirical_ndf`]):
//! 1. slopes `s = grad h` by central differences or the exact Gauss map of the triangulated surface
//!    ([`NormalScheme`]); every sample has the same projected area on a regular grid;
//! 2. a robust centre and covariance of the slopes from a subsample of [`FRAME_SUBSAMPLE`] normals
//!    ([`SlopeFrame::robust`]); heights on a coarse lattice are detected here ([`quantum`]) and cap the
//!    automatic grid;
//! 3. each slope is whitened, turned into the stretched normal `m'` and mapped with the Lambert
//!    azimuthal equal-area map onto the disk `|p| <= sqrt 2` ([`SlopeFrame::to_lambert`]), which covers
//!    every slope up to infinity with no trigonometry per point; a square grid of odd size `n` over the
//!    disk holds the counts ([`BinGrid`]), one histogram per rayon task, merged once;
//! 4. per bin, the projected solid angle `W_k = integral of m.n dw` over the bin in the scan frame follows
//!    from the closed-form Jacobian [`SlopeFrame::proj_density`] by Gauss-Legendre quadrature over the
//!    cell (its exact part of the disk on the rim; interior cells by a cheap tensor rule whose error is
//!    bounded a priori, see `cell_integrals`), and `D_k = count_k / (N W_k)`, so that
//!    `sum_k D_k W_k = 1` (Heitz eq. 9).
//!
//! The heights are read as f64 ([`empirical_ndf`]) or from f32 storage ([`empirical_ndf_f32`],
//! [`precision`]) by the same kernel, generic over [`HeightRows`].
//!
//! The bin's central direction `m_k` is the image of the `W`-weighted centroid of the cell, which makes
//! the midpoint rule `E_k = N D(m_k) W_k` of `data_formats/objective.md` exact for any `D` that is linear
//! over the cell in Lambert coordinates (second-order error).

pub mod frame;
pub mod grid;
pub mod lattice;
pub mod normals;
pub mod output;
pub mod plot;
pub mod precision;
pub mod quantum;
pub mod resolution;

use nalgebra::Vector3;
use rayon::prelude::*;

pub use frame::SlopeFrame;
pub use grid::{BinGrid, QuadOrder, RimShape};
pub use normals::{HeightRows, NormalScheme};
pub use precision::{F32Storage, HeightsF32, Precision};
pub use quantum::{HeightQuantum, SlopeLattice};

use crate::error::{Error, ErrorKind, Result};
use crate::heightfield::Heightfield;
use frame::LAMBERT_RADIUS;

/// One bin of the empirical NDF.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NdfBin {
    /// The bin's central direction (unit vector, `m.z > 0`).
    pub m: Vector3<f64>,
    /// D at the bin: projected-area fraction in the bin divided by the bin's projected solid angle.
    pub d: f64,
    /// Standard error of `d` (Poisson on the count).
    pub stderr: f64,
    /// Number of samples (stencils or facets) in the bin.
    pub count: u64,
    /// Solid angle of the bin (sr).
    pub solid_angle: f64,
    /// Projected solid angle of the bin, the integral of `m.n` over it (sr).
    pub proj_solid_angle: f64,
}

/// An empirical NDF: bins covering the hemisphere with `sum(d * proj_solid_angle) = 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct EmpiricalNdf {
    /// All bins, empty ones included.
    pub bins: Vec<NdfBin>,
    /// Number of samples binned.
    pub n_samples: u64,
    /// Number of stencils (or triangles) skipped because they touch an invalid point.
    pub n_skipped: u64,
    /// The normal scheme used.
    pub scheme: NormalScheme,
    /// The binning frame: robust slope centre and covariance, whitening (see [`SlopeFrame`]).
    pub frame: SlopeFrame,
    /// The grid over the Lambert disk (`n = 0` for an NDF assembled by [`EmpiricalNdf::from_bins`]).
    pub grid: BinGrid,
    /// The grid cell of each bin (ascending), for lookups.
    pub bin_cells: Vec<u32>,
    /// Mean slope `grad h` of all samples (projected-area weighted; Heitz eq. 61 convention, so the
    /// mean normal tilt is `m ~ (-mean, 1)`).
    pub slope_mean: [f64; 2],
    /// Covariance of the slopes of all samples (projected-area weighted). Heavy-tailed NDFs (GGX) have
    /// an infinite population covariance, so prefer [`SlopeFrame::cov`] (robust) for starting values.
    pub slope_cov: [[f64; 2]; 2],
    /// Projected area of one sample in m^2 (`dx dy`, or `dx dy / 2` for triangles).
    pub sample_area: f64,
    /// Heights found on a coarse lattice (see [`quantum`]), and the grid cap it imposed.
    pub quantization: Option<HeightQuantum>,
    /// Set when the heights were read from f32 storage ([`empirical_ndf_f32`]): what it cost.
    pub f32_storage: Option<F32Storage>,
    /// Per bin, the part of `count` from the odd row blocks of the dispersion split
    /// ([`DISPERSION_BLOCKS`]); empty when the NDF was not counted from a scan. The fit compares the two
    /// halves to estimate the overdispersion the data show ([`crate::fit::verdict`]).
    pub counts_odd: Vec<u64>,
    /// Per bin, how many of its normals the sampling does not resolve ([`resolution`]); empty when not
    /// assessed (triangle normals, NDFs not counted from a scan).
    pub unresolved: Vec<u64>,
    /// The relative slope error above which a normal counts in `unresolved`.
    pub resolution_tolerance: f64,
    /// Warnings for the user (one line each), e.g. a requested grid finer than the height lattice.
    pub warnings: Vec<String>,
}

/// How the empirical NDF is computed.
#[derive(Debug, Clone, PartialEq)]
pub struct NdfOptions {
    /// Normal scheme (default: central differences).
    pub scheme: NormalScheme,
    /// Cells across the Lambert disk (odd, 3 to [`grid::MAX_CELLS_ACROSS`]); `None` chooses from the
    /// sample count so that the mean count per bin is about [`NdfOptions::target_count`].
    pub cells_across: Option<usize>,
    /// Mean samples per bin aimed at when `cells_across` is `None`.
    pub target_count: f64,
    /// Use this binning frame instead of estimating one (to put two NDFs on identical bins).
    pub frame: Option<SlopeFrame>,
}

/// Default mean count per bin: see `data_formats/ndf_csv.md` ("resolution") for the measurement behind it.
pub const DEFAULT_TARGET_COUNT: f64 = 64.0;
/// Fewest cells across the disk when chosen from the data.
pub const MIN_AUTO_CELLS: usize = 15;
/// Most cells across the disk when chosen from the data.
pub const MAX_AUTO_CELLS: usize = 255;
/// Samples used for the robust frame (a strided subsample of the scan).
/// Samples used for the robust frame (a strided subsample of the scan). The frame only places the bins
/// (every sample is still counted); the robust scale's relative standard error is about `1.17 / sqrt(n)`
/// (IQR of a normal sample), 0.65% at 2^15, which moves bin edges by far less than a bin. Measured cost:
/// see `data_formats/ndf_csv.md` ("frame subsample").
pub const FRAME_SUBSAMPLE: usize = 1 << 15;

impl Default for NdfOptions {
    fn default() -> Self {
        NdfOptions { scheme: NormalScheme::Central, cells_across: None, target_count: DEFAULT_TARGET_COUNT, frame: None }
    }
}

impl NdfOptions {
    /// The grid size used for `n` samples.
    pub fn cells_for(&self, n: u64) -> usize {
        match self.cells_across {
            Some(c) => c,
            None => {
                let t = if self.target_count.is_finite() && self.target_count > 0.0 { self.target_count } else { DEFAULT_TARGET_COUNT };
                // The disk holds about pi n^2 / 4 cells.
                let c = (4.0 * n as f64 / (std::f64::consts::PI * t)).sqrt().round() as usize;
                c.clamp(MIN_AUTO_CELLS, MAX_AUTO_CELLS)
            }
        }
    }
}

/// Per-task accumulator: counts per cell and slope moments about the frame centre.
///
/// Counting goes through `lanes`: each cell has `2^shift` u32 counters side by side (one cache line),
/// and consecutive samples alternate between them. Neighbouring normals of a smooth surface mostly
/// fall in the same cell, and a single counter would chain every increment on the previous one's
/// store (perf: 20% of the pass); interleaved counters let them overlap. They are folded into the u64
/// `counts` at the end, or before a u32 could overflow.
struct Acc {
    counts: Vec<u64>,
    /// The part of `counts` from the odd row blocks of the dispersion split ([`DISPERSION_BLOCKS`]).
    odd: Vec<u64>,
    /// Whether the samples pending in `lanes` come from an odd row block.
    odd_pending: bool,
    lanes: Vec<u32>,
    shift: u32,
    /// Samples counted into `lanes` since they were last folded.
    pending: u64,
    n: u64,
    m1: [f64; 2],
    m2: [f64; 3],
}

/// Most cells for which counting uses 4 interleaved counters per cell (4 MiB of u32 per task at the
/// 1023-cell maximum would leave the caches; the automatic grid has at most 255^2 = 65025 cells).
const MAX_LANED_CELLS: usize = 1 << 16;

impl Acc {
    fn new(cells: usize) -> Self {
        let shift = if cells <= MAX_LANED_CELLS { 2 } else { 0 };
        Acc { counts: vec![0; cells], odd: vec![0; cells], odd_pending: false, lanes: vec![0; cells << shift], shift, pending: 0, n: 0, m1: [0.0; 2], m2: [0.0; 3] }
    }

    /// Add the interleaved counters into `counts` and clear them.
    fn fold(&mut self) {
        if self.pending == 0 {
            return;
        }
        let k = 1usize << self.shift;
        for ((c, o), l) in self.counts.iter_mut().zip(self.odd.iter_mut()).zip(self.lanes.chunks_exact_mut(k)) {
            let v = l.iter().map(|&v| v as u64).sum::<u64>();
            *c += v;
            if self.odd_pending {
                *o += v;
            }
            l.fill(0);
        }
        self.pending = 0;
    }

    fn merge(mut self, mut o: Acc) -> Acc {
        self.fold();
        o.fold();
        for (a, b) in self.counts.iter_mut().zip(&o.counts) {
            *a += b;
        }
        for (a, b) in self.odd.iter_mut().zip(&o.odd) {
            *a += b;
        }
        self.n += o.n;
        for k in 0..2 {
            self.m1[k] += o.m1[k];
        }
        for k in 0..3 {
            self.m2[k] += o.m2[k];
        }
        self
    }
}

/// Compute the empirical NDF of `hf` (see the module documentation for the method).
///
/// Heights on a coarse lattice (see [`quantum`]) cap the automatic grid (`cells_across: None`) so that
/// bins are no finer than the slope lattice; an explicit `cells_across` finer than the cap is kept with
/// a warning in [`EmpiricalNdf::warnings`].
///
/// Errors: [`ErrorKind::BadData`] when no stencil is valid (all points masked, or the grid is smaller
/// than one stencil).
pub fn empirical_ndf(hf: &Heightfield, opts: &NdfOptions) -> Result<EmpiricalNdf> {
    let mut ndf = ndf_of(hf, opts, || hf.invalid_count())?;
    resolution::assess(hf, &mut ndf);
    Ok(ndf)
}

/// [`empirical_ndf`] over f32 storage of the heights ([`HeightsF32`], mean removed in f64 first). The
/// result carries [`EmpiricalNdf::f32_storage`] (offset, rounding bound).
///
/// Errors: as [`empirical_ndf`], and [`ErrorKind::BadData`] when the f32 rounding of the heights bounds
/// a slope error above [`precision::MAX_ROUNDING_FRACTION`] of the smallest robust slope scale (use f64).
pub fn empirical_ndf_f32(h: &HeightsF32, opts: &NdfOptions) -> Result<EmpiricalNdf> {
    let mut ndf = ndf_of(h, opts, || h.invalid)?;
    resolution::assess(h, &mut ndf);
    let bound = h.slope_rounding_bound(opts.scheme);
    let (a, b, c) = (ndf.frame.cov[0][0], ndf.frame.cov[0][1], ndf.frame.cov[1][1]);
    let lmin = (0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt()).max(0.0);
    let frac = bound / lmin.sqrt();
    if !(frac <= precision::MAX_ROUNDING_FRACTION) {
        return Err(Error::new(
            ErrorKind::BadData,
            format!(
                "f32 storage rounds slopes by up to {bound:.3e} ({:.1}% of the slope scale {:.3e}; heights span {:.3e} m around their mean): use f64",
                100.0 * frac,
                lmin.sqrt(),
                h.max_deviation
            ),
        ));
    }
    ndf.f32_storage = Some(F32Storage { offset: h.offset, max_deviation: h.max_deviation, slope_rounding_bound: bound, fraction_of_slope_scale: frac });
    Ok(ndf)
}

/// The NDF with heights stored as `precision` asks: f64 reads `hf` itself; f32 makes the f32 copy
/// first (time and memory of the copy included; to save memory, build [`HeightsF32`] and drop `hf`).
pub fn empirical_ndf_with(hf: &Heightfield, opts: &NdfOptions, precision: Precision) -> Result<EmpiricalNdf> {
    match precision {
        Precision::F64 => empirical_ndf(hf, opts),
        Precision::F32 => empirical_ndf_f32(&HeightsF32::from_heightfield(hf), opts),
    }
}

fn ndf_of<H: HeightRows>(hf: &H, opts: &NdfOptions, invalid: impl Fn() -> usize) -> Result<EmpiricalNdf> {
    let scheme = opts.scheme;
    let rows = scheme.rows(hf);
    let stencils = rows.len() as u64 * scheme.per_row(hf) as u64;
    let no_valid = || {
        let (nx, ny) = (hf.nx(), hf.ny());
        Error::new(ErrorKind::BadData, format!("no valid normal stencil in the {nx} x {ny} grid ({} of {} points invalid)", invalid(), nx * ny))
    };
    if stencils == 0 {
        return Err(Error::new(ErrorKind::BadData, format!("grid {} x {} is too small for {} normals", hf.nx(), hf.ny(), scheme.as_str())));
    }
    // The strided subsample gives the robust frame and the valid fraction (for the automatic grid size;
    // the exact count is known only after the full pass).
    let need_sample = opts.frame.is_none() || opts.cells_across.is_none();
    // The frame and the height lattice are independent passes over the data: side by side.
    let ((mut sample, visited, frame), lattice) = rayon::join(
        || {
            let (mut sample, visited) = if need_sample { subsample(hf, scheme, FRAME_SUBSAMPLE) } else { (Vec::new(), 0) };
            let frame = match opts.frame {
                Some(f) => f,
                None => SlopeFrame::robust(&mut sample),
            };
            (sample, visited, frame)
        },
        || hf.known_quantum().and_then(quantum::Lattice::known).or_else(|| quantum::lattice(hf)),
    );
    if need_sample && sample.is_empty() {
        return Err(no_valid());
    }
    let n_est = if visited > 0 { (stencils as f64 * sample.len() as f64 / visited as f64).round() as u64 } else { stencils };
    let mut warnings = Vec::new();
    let mut quantization = lattice.and_then(|l| quantum::assess(l, hf, scheme, &frame));
    let mut cells = BinGrid::new(opts.cells_for(n_est)).n;
    if let Some(q) = quantization.as_mut() {
        if sample.is_empty() {
            sample = subsample(hf, scheme, FRAME_SUBSAMPLE).0;
        }
        let (offset, rigidity) = quantum::phase(&sample, q.slope_step);
        q.rigidity = rigidity;
        if rigidity[0].min(rigidity[1]) >= quantum::RIGID {
            // Bins that respect the lattice (module `lattice`): any grid is free of a comb.
            q.lattice = Some(SlopeLattice { offset, step: q.slope_step });
        } else if cells > q.max_cells {
            if opts.cells_across.is_none() {
                q.coarsened_from = Some(cells);
                warnings.push(format!(
                    "heights are quantized in steps of {:.3e} m (slope lattice {:.3e} x {:.3e}, smeared by the form removal): automatic grid coarsened from {} to {} cells across",
                    q.quantum, q.slope_step[0], q.slope_step[1], cells, q.max_cells
                ));
                cells = q.max_cells;
            } else {
                warnings.push(format!(
                    "heights are quantized in steps of {:.3e} m (slope lattice {:.3e} x {:.3e}): {} cells across is finer than the lattice (at most {}), expect a comb of empty bins",
                    q.quantum, q.slope_step[0], q.slope_step[1], cells, q.max_cells
                ));
            }
        }
        warnings.extend(q.unresolved_reason());
    }
    let grid = BinGrid::new(cells);

    let acc = histogram(hf, scheme, &frame, &grid, rows);
    if acc.n == 0 {
        return Err(no_valid());
    }
    let n = acc.n as f64;
    let mean = [acc.m1[0] / n, acc.m1[1] / n];
    let cov = [
        [acc.m2[0] / n - mean[0] * mean[0], acc.m2[1] / n - mean[0] * mean[1]],
        [acc.m2[1] / n - mean[0] * mean[1], acc.m2[2] / n - mean[1] * mean[1]],
    ];
    let slope_mean = [frame.center[0] + mean[0], frame.center[1] + mean[1]];

    let (bins, bin_cells) = build_bins(&frame, &grid, &acc.counts, acc.n, quantization.as_ref().and_then(|q| q.lattice.as_ref()));
    let counts_odd = bin_cells.iter().map(|&c| acc.odd[c as usize]).collect();
    // Heights so large that their slopes overflow (or a frame that is not finite) leave bins without a
    // direction: an error, never rows of NaN.
    if !(frame.center.iter().chain(frame.cov.iter().flatten()).all(|v| v.is_finite()))
        || bins.iter().any(|b| !(b.m.iter().all(|v| v.is_finite()) && b.d.is_finite()))
        || !bins.iter().any(|b| b.count > 0)
    {
        return Err(Error::new(
            ErrorKind::BadData,
            format!(
                "the NDF is not finite: the slopes of these heights (centre {:e}, {:e}) are beyond floating-point range; check the height unit (--z-scale)",
                frame.center[0], frame.center[1]
            ),
        ));
    }
    Ok(EmpiricalNdf {
        bins,
        n_samples: acc.n,
        n_skipped: stencils - acc.n,
        scheme,
        frame,
        grid,
        bin_cells,
        slope_mean,
        slope_cov: cov,
        sample_area: scheme.sample_area(hf),
        quantization,
        f32_storage: None,
        counts_odd,
        unresolved: Vec::new(),
        resolution_tolerance: resolution::RESOLUTION_TOLERANCE,
        warnings,
    })
}

/// A strided subsample of about `target` valid slopes (all of them for small scans), and the number of
/// stencils visited to get them.
fn subsample<H: HeightRows>(hf: &H, scheme: NormalScheme, target: usize) -> (Vec<[f64; 2]>, u64) {
    let rows = scheme.rows(hf);
    let total = rows.len() * scheme.per_row(hf);
    let stride = ((total as f64 / target as f64).sqrt().floor() as usize).max(1);
    let mut out = Vec::with_capacity(target.min(total) + 16);
    let mut visited = 0u64;
    let per_row = scheme.per_row(hf) as u64;
    let per_visit = if scheme == NormalScheme::Triangles { 2 } else { 1 };
    for i in rows.step_by(stride) {
        scheme.row_slopes(hf, i, stride, |sx, sy| out.push([sx, sy]));
        visited += (per_row / per_visit).div_ceil(stride as u64) * per_visit;
    }
    if out.is_empty() && stride > 1 {
        // Sparse valid data can fall between the strided rows: take every stencil instead (none of the
        // visited ones was valid, so this collects only the few valid ones there are).
        for i in scheme.rows(hf) {
            scheme.row_slopes(hf, i, 1, |sx, sy| out.push([sx, sy]));
        }
        visited = total as u64;
    }
    (out, visited)
}

/// Slopes are mapped in blocks: the arithmetic loop over a block has no branches and no scatter, so
/// the compiler vectorizes its square roots and divisions; counting follows in a scalar loop.
const BLOCK: usize = 256;

/// Independent partial sums of the slope moments in a block (a multiple of the widest vector, 4 f64).
const LANES: usize = 8;

struct Block {
    n: usize,
    sx: [f64; BLOCK],
    sy: [f64; BLOCK],
    px: [f64; BLOCK],
    py: [f64; BLOCK],
    cell: [i32; BLOCK],
}

impl Block {
    fn new() -> Self {
        Block { n: 0, sx: [0.0; BLOCK], sy: [0.0; BLOCK], px: [0.0; BLOCK], py: [0.0; BLOCK], cell: [0; BLOCK] }
    }

    /// Map the block's slopes to Lambert points (as [`SlopeFrame::to_lambert`]), count them, add the
    /// moments, and empty the block. On x86-64 CPUs with AVX2 the same code is compiled for 4-wide
    /// vectors (the default target has 2-wide SSE2); the results are bit-identical (IEEE square roots
    /// and divisions, no contraction into FMA), see `blocked_mapping_matches_scalar`.
    #[inline(never)]
    fn flush(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
                unsafe { self.flush_avx2(frame, grid, acc) };
                return;
            }
        }
        self.flush_body(frame, grid, acc)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn flush_avx2(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        self.flush_body(frame, grid, acc)
    }

    #[inline(always)]
    fn flush_body(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        let n = self.n;
        let (cx, cy) = (frame.center[0], frame.center[1]);
        let w = frame.whiten;
        let (sx, sy) = (&self.sx[..n], &self.sy[..n]);
        let (px, py, cell) = (&mut self.px[..n], &mut self.py[..n], &mut self.cell[..n]);
        let (r, inv_h, last, cols) = (LAMBERT_RADIUS, grid.inv_h(), (grid.n - 1) as f64, grid.n as i32);
        for k in 0..n {
            let (dx, dy) = (sx[k] - cx, sy[k] - cy);
            let (wx, wy) = (w[0][0] * dx + w[0][1] * dy, w[1][0] * dx + w[1][1] * dy);
            let t = 1.0 + wx * wx + wy * wy;
            let f = (2.0 / (t + t.sqrt())).sqrt();
            px[k] = wx * f;
            py[k] = wy * f;
            // The cell as [`BinGrid::cell_of`] finds it, in vector registers: clamped in f64 first
            // (`max` drops a NaN), so the truncation to i32 is in range.
            let ix = ((px[k] + r) * inv_h).max(0.0).min(last);
            let iy = ((py[k] + r) * inv_h).max(0.0).min(last);
            // SAFETY: ix, iy are finite and in [0, n - 1] with n <= 1023 (clamped just above).
            cell[k] = unsafe { iy.to_int_unchecked::<i32>() * cols + ix.to_int_unchecked::<i32>() };
        }
        let (shift, mask) = (acc.shift, (1usize << acc.shift) - 1);
        for k in 0..n {
            let mut c = cell[k] as usize;
            // Guard: |s'| > 1e150 overflows t (p = 0 or NaN); the exact map sends it to the rim.
            if !(px[k] * px[k] + py[k] * py[k] > 0.0) {
                c = grid.cell_of(frame.to_lambert(sx[k], sy[k]));
            }
            acc.lanes[(c << shift) + (k & mask)] += 1;
        }
        acc.pending += n as u64;
        // Fold long before a u32 counter could overflow (every sample in one cell and one lane).
        if acc.pending >= u32::MAX as u64 - BLOCK as u64 {
            acc.fold();
        }
        // The moments in LANES independent partial sums: a single running sum per moment would chain
        // every addition on the previous one (latency-bound); lanes vectorize and are summed at the end.
        let mut m = [[0.0f64; LANES]; 5];
        let (hx, hy) = (sx.chunks_exact(LANES), sy.chunks_exact(LANES));
        let (tx, ty) = (hx.remainder(), hy.remainder());
        for (qx, qy) in hx.zip(hy) {
            for l in 0..LANES {
                let (dx, dy) = (qx[l] - cx, qy[l] - cy);
                m[0][l] += dx;
                m[1][l] += dy;
                m[2][l] += dx * dx;
                m[3][l] += dx * dy;
                m[4][l] += dy * dy;
            }
        }
        for (l, (x, y)) in tx.iter().zip(ty).enumerate() {
            let (dx, dy) = (x - cx, y - cy);
            m[0][l] += dx;
            m[1][l] += dy;
            m[2][l] += dx * dx;
            m[3][l] += dx * dy;
            m[4][l] += dy * dy;
        }
        let sum = |v: &[f64; LANES]| v.iter().sum::<f64>();
        acc.m1[0] += sum(&m[0]);
        acc.m1[1] += sum(&m[1]);
        acc.m2[0] += sum(&m[2]);
        acc.m2[1] += sum(&m[3]);
        acc.m2[2] += sum(&m[4]);
        self.n = 0;
    }
}

/// Row blocks of the dispersion split: the rows are cut into this many blocks of equal height, and the
/// counts of the odd blocks are kept beside the total ([`crate::fit::verdict::data_dispersion`]). Blocks many correlation lengths
/// tall make the two halves' counts independent; sixteen alternate often enough to average the scan's
/// large-scale variation into both halves.
pub const DISPERSION_BLOCKS: usize = 16;

#[inline(always)]
fn dispersion_block(i: usize, rows: usize) -> usize {
    i * DISPERSION_BLOCKS / rows.max(1)
}

/// The parallel pass: rows split into a few contiguous chunks per thread, one histogram per chunk.
fn histogram<H: HeightRows>(hf: &H, scheme: NormalScheme, frame: &SlopeFrame, grid: &BinGrid, rows: std::ops::Range<usize>) -> Acc {
    let cells = grid.cells();
    let chunks = (rayon::current_num_threads() * 2).max(1);
    let len = rows.len().div_ceil(chunks).max(1);
    let starts: Vec<usize> = rows.clone().step_by(len).collect();
    let end = rows.end;
    let rows = &rows;
    starts
        .into_par_iter()
        .map(|start| {
            let mut acc = Acc::new(cells);
            let mut blk = Block::new();
            for i in start..(start + len).min(end) {
                // The dispersion split: samples of odd row blocks are also counted apart (flushed and
                // folded where the parity changes, so no block of samples mixes the two).
                let odd = dispersion_block(i - rows.start, rows.len()) % 2 == 1;
                if odd != acc.odd_pending {
                    blk.flush(frame, grid, &mut acc);
                    acc.fold();
                    acc.odd_pending = odd;
                }
                let valid = scheme.row_slopes(hf, i, 1, |sx, sy| {
                    blk.sx[blk.n] = sx;
                    blk.sy[blk.n] = sy;
                    blk.n += 1;
                    if blk.n == BLOCK {
                        blk.flush(frame, grid, &mut acc);
                    }
                });
                acc.n += valid;
            }
            blk.flush(frame, grid, &mut acc);
            acc.fold();
            acc
        })
        // No identity accumulators (each would allocate and zero the interleaved counters): the chunks
        // are merged pairwise, and there is at least one chunk (the caller checked for stencils).
        .reduce_with(Acc::merge)
        .unwrap_or_else(|| Acc::new(cells))
}

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
fn cell_integrals(frame: &SlopeFrame, rim: &RimShape, grid: &BinGrid, c: usize) -> (f64, f64, [f64; 2]) {
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
pub(crate) fn build_bins(frame: &SlopeFrame, grid: &BinGrid, counts: &[u64], n: u64, lattice: Option<&quantum::SlopeLattice>) -> (Vec<NdfBin>, Vec<u32>) {
    let nf = n as f64;
    let cells: Vec<usize> = (0..grid.cells()).filter(|&c| grid.meets_disk(c) || counts[c] > 0).collect();
    let rim = frame.rim_shape();
    let mut ints: Vec<(f64, f64, [f64; 2])> = cells.par_iter().map(|&c| cell_integrals(frame, &rim, grid, c)).collect();
    if let Some(lat) = lattice {
        lattice::respect_lattice(frame, grid, lat, &cells, &mut ints);
    }
    let bins: Vec<NdfBin> = cells
        .iter()
        .zip(&ints)
        .map(|(&c, &(w, o, centroid))| {
            let count = counts[c];
            // Guard: W = 0 only for a rim sliver of zero projected solid angle, or a lattice cell that
            // holds no node; D there is 0, not 0/0.
            let (d, stderr) = if w > 0.0 {
                (count as f64 / (nf * w), (count.max(1) as f64).sqrt() / (nf * w))
            } else {
                (0.0, 0.0)
            };
            NdfBin { m: frame.normal_at(centroid), d, stderr, count, solid_angle: o, proj_solid_angle: w }
        })
        .collect();
    (bins, cells.into_iter().map(|c| c as u32).collect())
}

impl EmpiricalNdf {
    /// An NDF from bins alone (no grid: lookups return `None`). For hand-made test data.
    pub fn from_bins(bins: Vec<NdfBin>, n_samples: u64) -> Self {
        EmpiricalNdf {
            bins,
            n_samples,
            n_skipped: 0,
            scheme: NormalScheme::Central,
            frame: SlopeFrame::new([0.0, 0.0], [[1.0, 0.0], [0.0, 1.0]]),
            grid: BinGrid::none(),
            bin_cells: Vec::new(),
            slope_mean: [0.0; 2],
            slope_cov: [[0.0; 2]; 2],
            sample_area: f64::NAN,
            quantization: None,
            f32_storage: None,
            counts_odd: Vec::new(),
            unresolved: Vec::new(),
            resolution_tolerance: resolution::RESOLUTION_TOLERANCE,
            warnings: Vec::new(),
        }
    }

    /// The index of the bin holding direction `m` (`m.z > 0`), if the NDF has a grid.
    pub fn bin_of(&self, m: Vector3<f64>) -> Option<usize> {
        if self.grid.n == 0 || !(m.z > 0.0) {
            return None;
        }
        let s = SlopeFrame::slope_of(m);
        let c = self.grid.cell_of(self.frame.to_lambert(s[0], s[1])) as u32;
        self.bin_cells.binary_search(&c).ok()
    }

    /// Empirical D at direction `m` (0 outside the hemisphere or without a grid).
    pub fn d_at(&self, m: Vector3<f64>) -> f64 {
        self.bin_of(m).map_or(0.0, |k| self.bins[k].d)
    }

    /// `integral of f(m) (m.n) dw` over bin `k`, by quadrature in Lambert coordinates; `None` without a
    /// grid. With `f = D_model` this is the bin-integrated model, the exact counterpart of the midpoint
    /// value `D_model(m_k) W_k`.
    pub fn bin_integral(&self, k: usize, order: QuadOrder, f: impl Fn(Vector3<f64>) -> f64) -> Option<f64> {
        let c = *self.bin_cells.get(k)? as usize;
        let mut sum = 0.0;
        self.grid.quadrature(c, order, &self.frame.rim_shape(), |p, wt| {
            let dw = self.frame.proj_density(p) * wt;
            if dw > 0.0 {
                sum += f(self.frame.normal_at(p)) * dw;
            }
        });
        Some(sum)
    }

    /// Sum of `d * proj_solid_angle` (1 up to rounding for a computed NDF).
    pub fn total(&self) -> f64 {
        self.bins.iter().map(|b| b.d * b.proj_solid_angle).sum()
    }
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
                eprintln!("frame {:?} n {n}: W - pi = {:.2e}, omega - 2pi = {:.2e}", f.cov, w - std::f64::consts::PI, o - 2.0 * std::f64::consts::PI);
                // Measured: <= 1e-10 for ordinary frames, 6e-7 at the anisotropy cap with a tilted centre.
                assert!((w - std::f64::consts::PI).abs() < 2e-6, "W {w}");
                assert!((o - 2.0 * std::f64::consts::PI).abs() < 2e-6, "omega {o}");
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

    /// The cost of the smaller frame subsample (2^15 instead of 2^17 normals): on the 1024^2 ellipsoid of
    /// the issue-8 sweep the robust scales from 2^15 and from every normal differ by less than four
    /// standard errors of an IQR scale from 2^15 independent samples (4 x 1.17 / sqrt(2^15) = 2.6%; a
    /// regular sub-grid of a smooth surface does better), and the centre by less than 2.6% of the scale.
    #[test]
    fn frame_subsample_costs_little() {
        let s = crate::synth::SynthSettings { nx: 1024, ny: 1024, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
        let p = crate::synth::EllipsoidParams { alpha_x: 0.35, alpha_y: 0.18, theta_x: 0.15, theta_y: -0.1, theta_z: 0.6, ..Default::default() };
        let (hf, _) = crate::synth::ellipsoid_surface(&s, &p).expect("valid");
        let mut all = subsample(&hf, NormalScheme::Central, usize::MAX).0;
        let full = SlopeFrame::robust(&mut all);
        for target in [1usize << 15, 1 << 17] {
            let mut sm = subsample(&hf, NormalScheme::Central, target).0;
            let n = sm.len();
            let f = SlopeFrame::robust(&mut sm);
            let rel = |a: f64, b: f64| (a.sqrt() / b.sqrt() - 1.0).abs();
            let (ex, ey) = (rel(f.cov[0][0], full.cov[0][0]), rel(f.cov[1][1], full.cov[1][1]));
            let dc = (f.center[0] - full.center[0]).hypot(f.center[1] - full.center[1]) / full.cov[1][1].min(full.cov[0][0]).sqrt();
            eprintln!("frame from {n} of {} normals: scale errors {ex:.2e} {ey:.2e}, centre {dc:.2e} (of sigma_min)", all.len());
            let bound = 4.0 * 1.17 / ((1u64 << 15) as f64).sqrt();
            assert!(ex < bound && ey < bound && dc < bound, "{ex} {ey} {dc} vs {bound}");
        }
    }

    /// The blocked, vectorized mapping agrees with the scalar `to_lambert` cell by cell, including
    /// slopes so large that `t = 1 + |s'|^2` overflows (they go to the rim, not to the centre).
    #[test]
    fn interleaved_counters_fold_into_counts() {
        for cells in [9, MAX_LANED_CELLS + 1] {
            let mut acc = Acc::new(cells);
            let k = 1usize << acc.shift;
            // 3 samples in cell 2 spread over lanes, 5 in the last cell in one lane.
            for (c, lane, v) in [(2, 0, 1u32), (2, k - 1, 2), (cells - 1, 0, 5)] {
                acc.lanes[c * k + lane] += v;
            }
            acc.pending = 8;
            acc.fold();
            assert_eq!((acc.counts[2], acc.counts[cells - 1], acc.counts.iter().sum::<u64>()), (3, 5, 8));
            assert!(acc.lanes.iter().all(|&v| v == 0) && acc.pending == 0);
        }
    }

    #[test]
    fn blocked_mapping_matches_scalar() {
        let nx = 40;
        let z: Vec<f64> = (0..nx * 5)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                if k % 7 == 0 { 1e180 * j } else { 1e-7 * (j * j * 0.3 + i * j * 0.1) }
            })
            .collect();
        let hf = Heightfield::new(nx, 5, 1e-6, 1e-6, z).expect("shape");
        let frame = SlopeFrame::new([0.01, 0.0], [[1e-4, 0.0], [0.0, 4e-4]]);
        let ndf = empirical_ndf(&hf, &NdfOptions { frame: Some(frame), cells_across: Some(21), ..Default::default() }).expect("valid");
        let mut want = vec![0u64; ndf.grid.cells()];
        for i in NormalScheme::Central.rows(&hf) {
            NormalScheme::Central.row_slopes(&hf, i, 1, |sx, sy| want[ndf.grid.cell_of(frame.to_lambert(sx, sy))] += 1);
        }
        for (b, &c) in ndf.bins.iter().zip(&ndf.bin_cells) {
            assert_eq!(b.count, want[c as usize]);
        }
        assert_eq!(ndf.n_samples, want.iter().sum::<u64>());
        assert!((ndf.total() - 1.0).abs() < 1e-12);
    }
}
