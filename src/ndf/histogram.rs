//! The counting pass of the empirical NDF: slopes mapped to the Lambert disk in vectorized blocks and
//! counted into u32 counters, about one set per thread, merged once (step 3 of [`super`]).

use std::sync::{Mutex, PoisonError};

use rayon::prelude::*;

use super::frame::LAMBERT_RADIUS;
use super::resolution::{RowSlopes, RowTest, Tally, COUNTED, UNRESOLVED, VALID};
use super::{BinGrid, NormalScheme, SlopeFrame};
use crate::scan::bands::bands_of;
use crate::scan::bands::BandSource;

/// Per-task accumulator: counts per cell and slope moments about the frame centre.
///
/// Counting goes through `counters`, one u32 per cell and row-block parity: the even and the odd row
/// blocks of the dispersion split count apart, and are folded into the u64 `counts` (and `odd`) once,
/// at the end, or before a u32 could overflow. One counter per cell: the block's cells are all known
/// before it is counted, and a small footprint keeps the counters in the L2 cache beside the rows.
pub(super) struct Acc {
    /// Counts per cell (empty until the first fold).
    pub(super) counts: Vec<u64>,
    /// The part of `counts` from the odd row blocks of the dispersion split ([`DISPERSION_BLOCKS`]).
    pub(super) odd: Vec<u64>,
    /// Whether the samples being counted come from an odd row block (they go to `counters[1]`).
    odd_pending: bool,
    /// The counters of the even (`[0]`) and the odd (`[1]`) row blocks.
    counters: [Vec<u32>; 2],
    /// Samples counted into `counters` since they were last folded.
    pending: u64,
    pub(super) n: u64,
    /// The slope moments `sum dx, sum dy` and `sum dx^2, sum dx dy, sum dy^2` about the frame centre: of
    /// the open tile while counting, of the whole pass after [`histogram`] summed the tiles.
    pub(super) m1: [f64; 2],
    pub(super) m2: [f64; 3],
    /// The moments of each closed tile, by tile index ([`Acc::close_tile`]).
    tiles: Vec<(usize, [f64; 5])>,
    /// The resolution test's tallies, when it runs in this pass.
    pub(super) res: Tally,
}

impl Acc {
    fn new(cells: usize) -> Self {
        Acc {
            counts: Vec::new(),
            odd: Vec::new(),
            odd_pending: false,
            counters: [vec![0; cells], vec![0; cells]],
            pending: 0,
            n: 0,
            m1: [0.0; 2],
            m2: [0.0; 3],
            tiles: Vec::new(),
            res: Tally::default(),
        }
    }

    /// Add the counters into `counts` (the odd ones into `odd` too) and clear them.
    fn fold(&mut self) {
        if self.pending == 0 {
            return;
        }
        let [even, odd] = &mut self.counters;
        if self.counts.is_empty() {
            // The first fold writes the counts rather than adding to zeroed memory: a fresh zeroed page
            // read before it is written costs a second fault (a copy-on-write, with a TLB shootdown).
            self.counts = even.iter().zip(odd.iter()).map(|(&e, &d)| e as u64 + d as u64).collect();
            self.odd = odd.iter().map(|&d| d as u64).collect();
        } else {
            for ((c, o), (&e, &d)) in self.counts.iter_mut().zip(self.odd.iter_mut()).zip(even.iter().zip(odd.iter())) {
                *c += e as u64 + d as u64;
                *o += d as u64;
            }
        }
        even.fill(0);
        odd.fill(0);
        self.pending = 0;
    }

    /// Close tile `index`: its moments (counted since the last close) are set aside under its index.
    fn close_tile(&mut self, index: usize) {
        let [m0, m1] = self.m1;
        let [m2, m3, m4] = self.m2;
        self.tiles.push((index, [m0, m1, m2, m3, m4]));
        (self.m1, self.m2) = ([0.0; 2], [0.0; 3]);
    }

    /// The moments of the whole pass: the closed tiles' sums added in tile order, so that they do not
    /// depend on which task counted which tile.
    fn sum_tiles(&mut self) {
        self.tiles.sort_unstable_by_key(|t| t.0);
        let mut m = [0.0f64; 5];
        for (_, t) in &self.tiles {
            for (a, b) in m.iter_mut().zip(t) {
                *a += b;
            }
        }
        (self.m1, self.m2) = ([m[0], m[1]], [m[2], m[3], m[4]]);
    }

    fn merge(mut self, mut o: Acc) -> Acc {
        self.fold();
        o.fold();
        if self.counts.is_empty() {
            (self.counts, self.odd) = (std::mem::take(&mut o.counts), std::mem::take(&mut o.odd));
        } else {
            for (a, b) in self.counts.iter_mut().zip(&o.counts) {
                *a += b;
            }
            for (a, b) in self.odd.iter_mut().zip(&o.odd) {
                *a += b;
            }
        }
        self.n += o.n;
        // Moments travel as the closed tiles' sums (the open tile's are zero between tiles).
        self.tiles.append(&mut o.tiles);
        self.res = std::mem::take(&mut self.res).merge(o.res);
        self
    }
}

/// Slopes are mapped in blocks: the arithmetic loop over a block has no branches and no scatter, so
/// the compiler vectorizes its square roots and divisions; counting follows in a scalar loop.
const BLOCK: usize = 256;

/// Slopes whose unresolved flags [`Block::flush`] tests at once.
const UNRESOLVED_RUN: usize = 32;

/// How far from a cell's edge an f32 cell coordinate of [`Block::cells_body`] must lie to be taken, per
/// cell across the grid: 2^-19 n, i.e. 16 units of `2^-23 n` (f32's precision at the coordinate's
/// largest value `n`), over five times the bound on its difference from the f64 coordinate (3 such
/// units: the conversion, the map's roundings, the offset and scale).
const CELL_MARGIN: f32 = 1.0 / (1u32 << 19) as f32;

/// Independent partial sums of the slope moments in a block (a multiple of the widest vector, 4 f64).
const LANES: usize = 8;

pub(super) struct Block {
    pub(super) n: usize,
    pub(super) sx: [f64; BLOCK],
    pub(super) sy: [f64; BLOCK],
    px: [f64; BLOCK],
    py: [f64; BLOCK],
    cell: [i32; BLOCK],
    /// The whitened slopes in f32 ([`Block::cells_body`]).
    wx: [f32; BLOCK],
    wy: [f32; BLOCK],
    /// Per slope: 1 when the resolution test found it unresolved and its row is binned (`nu` of them).
    u: [u8; BLOCK],
    nu: usize,
}

impl Block {
    pub(super) const LEN: usize = BLOCK;

    pub(super) fn new() -> Self {
        Block {
            n: 0,
            sx: [0.0; BLOCK],
            sy: [0.0; BLOCK],
            px: [0.0; BLOCK],
            py: [0.0; BLOCK],
            cell: [0; BLOCK],
            wx: [0.0; BLOCK],
            wy: [0.0; BLOCK],
            u: [0; BLOCK],
            nu: 0,
        }
    }

    /// Add one slope (`unresolved`: also bin it among the unresolved); flush when the block is full.
    #[inline(always)]
    fn push(&mut self, sx: f64, sy: f64, unresolved: bool, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        let n = self.n;
        (self.sx[n], self.sy[n], self.u[n]) = (sx, sy, unresolved as u8);
        self.nu += unresolved as usize;
        self.n += 1;
        if self.n == BLOCK {
            self.flush(frame, grid, acc);
        }
    }

    /// Add the counted samples of a row, in order, flushing each time the block fills: each run of
    /// counted samples is copied whole (a row without holes is one run; a scan's edge or a hole ends
    /// one). With `bin`, the unresolved ones are binned among the unresolved too (those the histogram
    /// does not count, through `res` apart). The blocks hold the same samples in the same order as
    /// samples pushed one by one ([`Block::push`]), so counts and moments are the same bits.
    fn feed(&mut self, rs: &RowSlopes, bin: bool, res: Option<&RowTest>, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        let m = rs.sx.len();
        let unresolved = |c: u8| bin && c & (VALID | UNRESOLVED) == VALID | UNRESOLVED;
        let counted = |c: &u8| c & COUNTED != 0;
        let mut k = 0;
        while k < m {
            // The run of counted samples from k, then the samples not counted after it.
            let run = rs.code[k..].iter().position(|c| !counted(c)).map_or(m, |p| k + p);
            while k < run {
                let n = self.n;
                let len = (BLOCK - n).min(run - k);
                self.sx[n..n + len].copy_from_slice(&rs.sx[k..k + len]);
                self.sy[n..n + len].copy_from_slice(&rs.sy[k..k + len]);
                let mut nu = 0;
                for (u, &c) in self.u[n..n + len].iter_mut().zip(&rs.code[k..k + len]) {
                    *u = unresolved(c) as u8;
                    nu += *u as usize;
                }
                self.nu += nu;
                self.n += len;
                k += len;
                if self.n == BLOCK {
                    self.flush(frame, grid, acc);
                }
            }
            let end = rs.code[k..].iter().position(counted).map_or(m, |p| k + p);
            if let (true, Some(t)) = (bin, res) {
                for j in k..end {
                    if unresolved(rs.code[j]) {
                        t.bin_apart(rs.sx[j], rs.sy[j], &mut acc.res);
                    }
                }
            }
            k = end;
        }
    }

    /// Find the cells of the block's slopes (as `grid.cell_of(frame.to_lambert(..))`, through
    /// [`Block::cells_body`]), count them, add the moments, and empty the block. On x86-64 CPUs with AVX2
    /// or AVX-512 the same code is compiled for wider vectors (the default target has SSE2); the
    /// results are bit-identical (IEEE square roots and divisions, no contraction into FMA), see
    /// `blocked_mapping_matches_scalar` and `f32_cells_match_f64_at_the_edges`.
    #[inline(never)]
    fn flush(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        #[cfg(target_arch = "x86_64")]
        {
            if avx512() {
                // SAFETY: the CPU supports these AVX-512 subsets (checked just above); the body is safe Rust.
                unsafe { self.flush_avx512(frame, grid, acc) };
                return;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
                unsafe { self.flush_avx2(frame, grid, acc) };
                return;
            }
        }
        self.flush_body(frame, grid, acc)
    }

    /// [`Block::flush`] compiled for 512-bit vectors (the same IEEE arithmetic, bit for bit).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    unsafe fn flush_avx512(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        self.flush_body(frame, grid, acc)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn flush_avx2(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        self.flush_body(frame, grid, acc)
    }

    /// Count the block's slopes into `counts` (one counter per cell, as
    /// `counts[grid.cell_of(frame.to_lambert(sx, sy))] += 1`) and empty the block.
    pub(super) fn count_into(&mut self, frame: &SlopeFrame, grid: &BinGrid, counts: &mut [u64]) {
        self.cells(frame, grid);
        for k in 0..self.n {
            counts[self.cell_at(k, frame, grid)] += 1;
        }
        self.n = 0;
    }

    /// Hand the block's slopes to `f` in order as `(slope, cell)`, the cell that of
    /// `grid.cell_of(frame.to_lambert(..))` (through [`Block::cells_body`]), then empty the block.
    pub(super) fn cell_each(&mut self, frame: &SlopeFrame, grid: &BinGrid, mut f: impl FnMut([f64; 2], usize)) {
        self.cells(frame, grid);
        for k in 0..self.n {
            f([self.sx[k], self.sy[k]], self.cell_at(k, frame, grid));
        }
        self.n = 0;
    }

    /// Map the block's slopes and hand each to `f` in order as `(k, slope, Lambert point, cell)`, the point
    /// and the cell those of `frame.to_lambert` and `grid.cell_of` slope by slope (the vectorized f64 map,
    /// [`Block::map_body`], bit for bit where `1 + |s'|^2` stays below 1e300), then empty the block.
    pub(super) fn map_each(&mut self, frame: &SlopeFrame, grid: &BinGrid, mut f: impl FnMut(usize, [f64; 2], [f64; 2], usize)) {
        self.map(frame, grid);
        for k in 0..self.n {
            let s = [self.sx[k], self.sy[k]];
            // Where the guard marked the vector result, the exact map gives the point as well as the cell.
            let p = if self.cell[k] >= 0 { [self.px[k], self.py[k]] } else { frame.to_lambert(s[0], s[1]) };
            f(k, s, p, self.cell_at(k, frame, grid));
        }
        self.n = 0;
    }

    /// [`Block::cells_body`] compiled for the widest vectors the CPU has (the same IEEE arithmetic).
    fn cells(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        #[cfg(target_arch = "x86_64")]
        {
            if avx512() {
                // SAFETY: the CPU supports these AVX-512 subsets (checked just above); the body is safe Rust.
                return unsafe { self.cells_avx512(frame, grid) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
                return unsafe { self.cells_avx2(frame, grid) };
            }
        }
        self.cells_body(frame, grid)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    unsafe fn cells_avx512(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        self.cells_body(frame, grid)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn cells_avx2(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        self.cells_body(frame, grid)
    }

    /// [`Block::map_body`] compiled for the widest vectors the CPU has (the same IEEE arithmetic).
    fn map(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        #[cfg(target_arch = "x86_64")]
        {
            if avx512() {
                // SAFETY: the CPU supports these AVX-512 subsets (checked just above); the body is safe Rust.
                return unsafe { self.map_avx512(frame, grid) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above); the body is safe Rust.
                return unsafe { self.map_avx2(frame, grid) };
            }
        }
        self.map_body(frame, grid)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    unsafe fn map_avx512(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        self.map_body(frame, grid)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn map_avx2(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        self.map_body(frame, grid)
    }

    /// The Lambert points and cells of the block's slopes (into `px`, `py`, `cell`).
    #[inline(always)]
    fn map_body(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        let (cx, cy) = (frame.center[0], frame.center[1]);
        let w = frame.whiten;
        let n = self.n;
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
            let c = unsafe { iy.to_int_unchecked::<i32>() * cols + ix.to_int_unchecked::<i32>() };
            // Guard: |s'| > 1e150 overflows t (p = 0 or NaN); marked -1 for the exact map, which sends
            // it to the rim.
            cell[k] = if px[k] * px[k] + py[k] * py[k] > 0.0 { c } else { -1 };
        }
    }

    /// The cell of slope `k` after [`Block::map_body`] or [`Block::cells_body`]: the vector result, or the
    /// exact map where either marked it.
    #[inline(always)]
    fn cell_at(&self, k: usize, frame: &SlopeFrame, grid: &BinGrid) -> usize {
        match self.cell[k] {
            c if c >= 0 => c as usize,
            _ => grid.cell_of(frame.to_lambert(self.sx[k], self.sy[k])),
        }
    }

    /// The cells of the block's slopes (into `cell`) as [`Block::map_body`] finds them, for less: the
    /// whitened slope in f64 as there, the Lambert point and its cell coordinates in f32 (twice the
    /// lanes, cheaper square roots and division). The f32 coordinates are within [`CELL_MARGIN`] of
    /// the f64 ones; where one lies that close to a cell's edge, or the slope is too steep for f32
    /// (`t >= 1e30`, or not finite), the cell is marked -1 for the exact map ([`Block::cell_at`]).
    /// So every cell is the f64 map's, bit for bit (`f32_cells_match_f64_at_the_edges`).
    #[inline(always)]
    fn cells_body(&mut self, frame: &SlopeFrame, grid: &BinGrid) {
        let (cx, cy) = (frame.center[0], frame.center[1]);
        let w = frame.whiten;
        let n = self.n;
        let (sx, sy, cell) = (&self.sx[..n], &self.sy[..n], &mut self.cell[..n]);
        let (wxs, wys) = (&mut self.wx[..n], &mut self.wy[..n]);
        // Two loops: the f64 one fills half the vector's f32 lanes, the f32 one all of them.
        for k in 0..n {
            let (dx, dy) = (sx[k] - cx, sy[k] - cy);
            (wxs[k], wys[k]) = ((w[0][0] * dx + w[0][1] * dy) as f32, (w[1][0] * dx + w[1][1] * dy) as f32);
        }
        let (r, inv_h, last, cols) = (LAMBERT_RADIUS as f32, grid.inv_h() as f32, (grid.n - 1) as f32, grid.n as i32);
        let margin = CELL_MARGIN * grid.n as f32;
        for k in 0..n {
            let (wx, wy) = (wxs[k], wys[k]);
            let t = 1.0 + wx * wx + wy * wy;
            let f = (2.0 / (t + t.sqrt())).sqrt();
            let ux = (wx * f + r) * inv_h;
            let uy = (wy * f + r) * inv_h;
            let (fx, fy) = (ux - ux.floor(), uy - uy.floor());
            let clear = (t < 1e30) & (fx > margin) & (fx < 1.0 - margin) & (fy > margin) & (fy < 1.0 - margin);
            let ix = ux.max(0.0).min(last);
            let iy = uy.max(0.0).min(last);
            // SAFETY: ix, iy are finite and in [0, n - 1] with n <= 1023 (clamped just above; `max` drops a NaN).
            let c = unsafe { iy.to_int_unchecked::<i32>() * cols + ix.to_int_unchecked::<i32>() };
            cell[k] = if clear { c } else { -1 };
        }
    }

    #[inline(always)]
    fn flush_body(&mut self, frame: &SlopeFrame, grid: &BinGrid, acc: &mut Acc) {
        self.cells_body(frame, grid);
        let n = self.n;
        let (sx, sy) = (&self.sx[..n], &self.sy[..n]);
        let (cx, cy) = (frame.center[0], frame.center[1]);
        let counters = &mut acc.counters[acc.odd_pending as usize];
        for k in 0..n {
            counters[self.cell_at(k, frame, grid)] += 1;
        }
        if self.nu > 0 {
            let cells = &mut acc.res.cells;
            if cells.is_empty() {
                *cells = vec![0; grid.cells()];
            }
            // Few slopes are unresolved (the rim of each row, as a rule): runs without one are skipped
            // after one branch-free test of the whole run.
            for (q, run) in self.u[..n].chunks(UNRESOLVED_RUN).enumerate() {
                if run.iter().fold(0, |any, &u| any | u) == 0 {
                    continue;
                }
                for (k, &u) in run.iter().enumerate() {
                    if u != 0 {
                        cells[self.cell_at(q * UNRESOLVED_RUN + k, frame, grid)] += 1;
                    }
                }
            }
            self.nu = 0;
        }
        acc.pending += n as u64;
        // Fold long before a u32 counter could overflow (every sample in one cell).
        if acc.pending >= u32::MAX as u64 - BLOCK as u64 {
            acc.fold();
        }
        // The moments in LANES independent partial sums: a single running sum per moment would chain
        // every addition on the previous one (latency-bound); lanes vectorize and are summed at the end.
        let (mut m0, mut m1, mut m2, mut m3, mut m4) = ([0.0f64; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
        let (hx, hy) = (sx.chunks_exact(LANES), sy.chunks_exact(LANES));
        let (tx, ty) = (hx.remainder(), hy.remainder());
        // One loop per coordinate and one for the product: each maps lane for lane onto vector registers.
        for q in hx.clone() {
            for l in 0..LANES {
                let dx = q[l] - cx;
                m0[l] += dx;
                m2[l] += dx * dx;
            }
        }
        for q in hy.clone() {
            for l in 0..LANES {
                let dy = q[l] - cy;
                m1[l] += dy;
                m4[l] += dy * dy;
            }
        }
        for (qx, qy) in hx.zip(hy) {
            for l in 0..LANES {
                m3[l] += (qx[l] - cx) * (qy[l] - cy);
            }
        }
        let mut m = [m0, m1, m2, m3, m4];
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

/// Whether the CPU has the AVX-512 subsets the 8-wide kernels are compiled for (detected at run time:
/// the binary stays portable).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512dq")
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

/// Rows per tile of the counting pass, for `rows` rows: about [`TILES`] tiles, each at least
/// [`MIN_TILE_ROWS`] rows. A function of the scan alone, never of the thread count.
fn tile_rows(rows: usize) -> usize {
    rows.div_ceil(TILES).max(MIN_TILE_ROWS)
}

/// Tiles the counting pass aims at: enough for every thread of a large machine to take several.
const TILES: usize = 128;

/// The fewest rows in a tile: each tile reads its stencil's rows above and below once more.
const MIN_TILE_ROWS: usize = 8;

/// What a tile is counted with: a histogram, the block of slopes being mapped, a band buffer and a
/// row's slopes.
type Counting<T> = (Acc, Block, Vec<T>, RowSlopes);

/// The parallel pass over `rows`, in tiles of [`tile_rows`] rows, handed out one by one. Each tile is
/// counted into a histogram of a free list, about one per thread (integer counts, merged in any order); the
/// slope moments are summed per tile and the tiles' sums added in tile order, so the whole result is the
/// same bit for bit on any number of threads. With `res` (central differences only) the resolution test
/// runs on each row too, while its rows are in cache.
pub(super) fn histogram<S: BandSource>(
    src: &S,
    scheme: NormalScheme,
    frame: &SlopeFrame,
    grid: &BinGrid,
    rows: std::ops::Range<usize>,
    res: Option<&RowTest>,
) -> Acc {
    let cells = grid.cells();
    let tile = tile_rows(rows.len());
    let tiles = rows.len().div_ceil(tile);
    let rows = &rows;
    let (ny, step) = (src.shape().ny, src.band_rows());
    let count_tile = |(mut acc, mut blk, mut buf, mut rs): Counting<S::T>, t: usize| {
        let start = rows.start + t * tile;
        for b in bands_of(start..(start + tile).min(rows.end), step) {
            let (lo, hi) = match res {
                Some(t) => (t.stencil_rows(b.start).0, t.stencil_rows(b.end - 1).1),
                None => (scheme.stencil_rows(b.start, ny).0, scheme.stencil_rows(b.end - 1, ny).1),
            };
            let hf = &src.band(lo, hi, &mut buf);
            for i in b {
                // The dispersion split: samples of odd row blocks are also counted apart (the block
                // is flushed where the parity changes, so that none mixes the two).
                let odd = dispersion_block(i - rows.start, rows.len()) % 2 == 1;
                if odd != acc.odd_pending {
                    blk.flush(frame, grid, &mut acc);
                    acc.odd_pending = odd;
                }
                if scheme == NormalScheme::Central {
                    // Slopes (and the resolution test) of the whole row in one vectorized loop.
                    let bin = match res {
                        Some(t) => t.row(hf, i, &mut acc.res, &mut rs),
                        None => {
                            rs.central(hf, i);
                            false
                        }
                    };
                    acc.n += rs.counted;
                    blk.feed(&rs, bin, res, frame, grid, &mut acc);
                    continue;
                }
                acc.n += scheme.row_slopes(hf, i, 1, |sx, sy| blk.push(sx, sy, false, frame, grid, &mut acc));
            }
        }
        blk.flush(frame, grid, &mut acc);
        acc.close_tile(t);
        (acc, blk, buf, rs)
    };
    // Counting states are kept in a free list and reused tile after tile, not made per task: a state's
    // counters are fresh memory (megabytes for a large grid), and a process's threads fault fresh pages
    // in slowly all at once. So tiles go out one by one (balance) for about one state per thread. A
    // tile takes a state out for its whole count, so no two tiles ever share one.
    let free: Mutex<Vec<Counting<S::T>>> = Mutex::new(Vec::new());
    // The list is only pushed and popped; a poisoned lock means a panic that is already unwinding.
    let list = || free.lock().unwrap_or_else(PoisonError::into_inner);
    (0..tiles).into_par_iter().for_each(|t| {
        let reused = list().pop();
        let state = reused.unwrap_or_else(|| (Acc::new(cells), Block::new(), Vec::new(), RowSlopes::default()));
        let state = count_tile(state, t);
        list().push(state);
    });
    let states: Vec<Acc> = free.into_inner().unwrap_or_else(PoisonError::into_inner).into_iter().map(|s| s.0).collect();
    let mut acc = states
        .into_par_iter()
        .map(|mut acc| {
            acc.fold();
            if let Some(t) = res {
                t.settle(&mut acc.res);
            }
            acc
        })
        // No identity accumulators (each would allocate and zero the counters): the list's histograms
        // are merged pairwise, and there is at least one (the caller checked for stencils).
        .reduce_with(Acc::merge)
        .unwrap_or_else(|| Acc::new(cells));
    acc.sum_tiles();
    if let Some(t) = res {
        t.bin_deferred(src, &mut acc.res);
    }
    // Nothing counted anywhere: no fold made the counts.
    if acc.counts.is_empty() {
        (acc.counts, acc.odd) = (vec![0; cells], vec![0; cells]);
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ndf::{empirical_ndf, NdfOptions};
    use crate::Heightfield;

    /// The counters of both parities fold into `counts`, the odd ones into `odd` too, and are cleared.
    #[test]
    fn counters_fold_into_counts() {
        let cells = 9;
        let mut acc = Acc::new(cells);
        // Even blocks: 3 samples in cell 2, 5 in the last cell; odd blocks: 4 in cell 2 and 1 in cell 0.
        for (parity, c, v) in [(0, 2, 3u32), (0, cells - 1, 5), (1, 2, 4), (1, 0, 1)] {
            acc.counters[parity][c] += v;
        }
        acc.pending = 13;
        acc.fold();
        assert_eq!((acc.counts[0], acc.counts[2], acc.counts[cells - 1], acc.counts.iter().sum::<u64>()), (1, 7, 5, 13));
        assert_eq!((acc.odd[0], acc.odd[2], acc.odd.iter().sum::<u64>()), (1, 4, 5));
        assert!(acc.counters.iter().flatten().all(|&v| v == 0) && acc.pending == 0);
        // A later fold adds to the counts.
        (acc.counters[0][2], acc.counters[1][0], acc.pending) = (2, 3, 5);
        acc.fold();
        assert_eq!((acc.counts[0], acc.counts[2], acc.odd[0], acc.odd[2]), (4, 9, 4, 4));
    }

    /// The blocked, vectorized mapping agrees with the scalar `to_lambert` cell by cell, including
    /// slopes so large that `t = 1 + |s'|^2` overflows (they go to the rim, not to the centre).
    #[test]
    fn blocked_mapping_matches_scalar() {
        let nx = 40;
        let z: Vec<f64> = (0..nx * 5)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                if k % 7 == 0 {
                    1e180 * j
                } else {
                    1e-7 * (j * j * 0.3 + i * j * 0.1)
                }
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

    /// The f32 cells of [`Block::cells_body`] are the f64 map's, slope by slope, also for Lambert points
    /// from 1e-12 to 1e-3 of a cell's width on either side of every inner edge (grids of 21, 255 and 1023
    /// cells across), for slopes from 1e-9 to 1e200 whitened, and on the widest vectors the CPU has as on
    /// the default target. The edge points closest to an edge are sent to the exact map: the margin is
    /// what keeps them right (with a zero margin the test fails).
    #[test]
    fn f32_cells_match_f64_at_the_edges() {
        use crate::ndf::frame::LAMBERT_RADIUS;
        let frame = SlopeFrame::new([0.03, -0.02], [[0.04, 0.012], [0.012, 0.01]]);
        let u = frame.unwhiten;
        for n in [21, 255, 1023] {
            let grid = BinGrid::new(n);
            let h = 2.0 * LAMBERT_RADIUS / grid.n as f64;
            let mut slopes = Vec::new();
            for k in 1..grid.n {
                for d in [0.0, 1e-12, 1e-9, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3].into_iter().flat_map(|d| [d, -d]) {
                    let e = -LAMBERT_RADIUS + (k as f64 + d) * h;
                    // The other coordinate anywhere along the edge's chord (a fixed irrational stride).
                    let half = (1.99 - e * e).max(0.0).sqrt();
                    let o = half * (2.0 * (k as f64 * 0.618_033_988_75 + d * 1e6).rem_euclid(1.0) - 1.0);
                    for p in [[e, o], [o, e]] {
                        slopes.push(SlopeFrame::slope_of(frame.normal_at(p)));
                    }
                }
            }
            let edges = slopes.len();
            // Whitened slopes of every magnitude and direction, past f32's range and the f64 guard.
            for m in -9..=200 {
                for a in 0..7 {
                    let (sn, cs) = (a as f64 * 0.9).sin_cos();
                    let w = [10f64.powi(m) * cs, 10f64.powi(m) * sn];
                    let c = frame.center;
                    slopes.push([c[0] + u[0][0] * w[0] + u[0][1] * w[1], c[1] + u[1][0] * w[0] + u[1][1] * w[1]]);
                }
            }
            for wide in [true, false] {
                let (mut blk, mut exact) = (Block::new(), 0);
                for (q, chunk) in slopes.chunks(BLOCK).enumerate() {
                    blk.n = chunk.len();
                    for (k, s) in chunk.iter().enumerate() {
                        (blk.sx[k], blk.sy[k]) = (s[0], s[1]);
                    }
                    if wide {
                        blk.cells(&frame, &grid);
                    } else {
                        blk.cells_body(&frame, &grid);
                    }
                    exact += (0..blk.n).filter(|&k| q * BLOCK + k < edges && blk.cell[k] < 0).count();
                    for (k, s) in chunk.iter().enumerate() {
                        assert_eq!(blk.cell_at(k, &frame, &grid), grid.cell_of(frame.to_lambert(s[0], s[1])), "n {n}, slope {s:?}");
                    }
                }
                // The points within 1e-5 of a cell of an edge (3 in 4) are inside every grid's margin; those at
                // 1e-3 are outside it up to 255 cells across.
                let taken = exact * 4 >= edges * 3 && (grid.n > 255 || exact < edges);
                assert!(taken, "n {n}: {exact} of {edges} edge points to the exact map");
            }
        }
    }

    /// A row fed in runs ([`Block::feed`]) fills the blocks with the same samples in the same order as
    /// samples pushed one by one: the same counts, unresolved cells and moments, bit for bit, over rows
    /// with holes at the start, inside and at the end, unresolved samples counted and not counted, and
    /// blocks that fill across rows.
    #[test]
    fn feeding_runs_matches_pushing_one_by_one() {
        use crate::scan::bands::GridShape;
        let frame = SlopeFrame::new([0.02, -0.01], [[0.04, 0.01], [0.01, 0.02]]);
        let grid = BinGrid::new(33);
        let shape = GridShape { nx: 1000, ny: 10, dx: 1e-6, dy: 1e-6, quantum: None };
        let test = RowTest::new(frame, grid, shape, 10_000);
        let (mut fed, mut pushed) = ((Acc::new(grid.cells()), Block::new()), (Acc::new(grid.cells()), Block::new()));
        for row in 0..7u64 {
            let m = 300 + 97 * row as usize;
            let mut rs = RowSlopes::default();
            for k in 0..m {
                let h = (k as u64 * 2654435761 + row * 40503) % 1000;
                rs.sx.push(0.3 * ((k as f64) * 0.37 + row as f64).sin());
                rs.sy.push(0.2 * ((k as f64) * 0.11 - row as f64).cos());
                // Holes: the first row's first 40, runs inside, the last row's tail, and scattered ones.
                let hole = (row == 0 && k < 40) || (k / 50) % 5 == 3 || (row == 6 && k + 30 > m) || h < 30;
                let unresolved = h.is_multiple_of(7);
                rs.code.push(VALID | (unresolved as u8) << 1 | (!hole as u8) << 2);
            }
            rs.counted = rs.code.iter().filter(|&&c| c & COUNTED != 0).count() as u64;
            let bin = row != 3;
            fed.1.feed(&rs, bin, Some(&test), &frame, &grid, &mut fed.0);
            let (acc, blk) = (&mut pushed.0, &mut pushed.1);
            for k in 0..m {
                let (c, unresolved) = (rs.code[k], bin && rs.code[k] & UNRESOLVED != 0);
                if c & COUNTED != 0 {
                    blk.push(rs.sx[k], rs.sy[k], unresolved, &frame, &grid, acc);
                } else if unresolved {
                    test.bin_apart(rs.sx[k], rs.sy[k], &mut acc.res);
                }
            }
        }
        for (acc, blk) in [&mut fed, &mut pushed] {
            blk.flush(&frame, &grid, acc);
            acc.fold();
            test.settle(&mut acc.res);
        }
        let (a, b) = (&fed.0, &pushed.0);
        assert!(a.counts.iter().sum::<u64>() > 1000 && a.res.cells.iter().sum::<u64>() > 100);
        assert_eq!((&a.counts, &a.odd, &a.res.cells), (&b.counts, &b.odd, &b.res.cells));
        let bits = |acc: &Acc| [acc.m1[0], acc.m1[1], acc.m2[0], acc.m2[1], acc.m2[2]].map(f64::to_bits);
        assert_eq!(bits(a), bits(b));
    }

    /// The odd row blocks' counts of the dispersion split against a scalar count of the samples of the
    /// rows whose block is odd, on a grid tall enough for every block and several tasks, with holes;
    /// with the resolution test in the pass (its row loop makes the slopes) and without it (the plain
    /// row loop). The slope moments against a direct two-pass sum.
    #[test]
    fn odd_block_counts_match_a_scalar_count() {
        let (nx, ny) = (37, 203);
        let z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                if k % 97 == 5 {
                    return f64::NAN;
                }
                1e-7 * ((0.31 * j).sin() * 3.0 + (0.17 * i + 0.05 * j).cos() * 2.0 + 0.01 * i * j)
            })
            .collect();
        let hf = Heightfield::new(nx, ny, 1e-6, 1e-6, z).expect("shape");
        for resolution in [None, Some(false)] {
            let ndf = empirical_ndf(&hf, &NdfOptions { cells_across: Some(15), resolution, ..Default::default() }).expect("valid");
            assert_eq!(ndf.unresolved_share.is_some(), resolution.is_none());
            let (mut all, mut odd) = (vec![0u64; ndf.grid.cells()], vec![0u64; ndf.grid.cells()]);
            let mut slopes = Vec::new();
            let rows = NormalScheme::Central.rows(&hf);
            for i in rows.clone() {
                let is_odd = dispersion_block(i - rows.start, rows.len()) % 2 == 1;
                NormalScheme::Central.row_slopes(&hf, i, 1, |sx, sy| {
                    let c = ndf.grid.cell_of(ndf.frame.to_lambert(sx, sy));
                    all[c] += 1;
                    odd[c] += is_odd as u64;
                    slopes.push([sx, sy]);
                });
            }
            for (k, &c) in ndf.bin_cells.iter().enumerate() {
                assert_eq!((ndf.bins[k].count, ndf.counts_odd[k]), (all[c as usize], odd[c as usize]), "cell {c}");
            }
            let odd_total: u64 = ndf.counts_odd.iter().sum();
            assert!(odd_total > 0 && odd_total < ndf.n_samples, "both parities hold samples");
            assert_eq!(ndf.n_samples, slopes.len() as u64);
            let n = slopes.len() as f64;
            let mean = [0, 1].map(|a| slopes.iter().map(|s| s[a]).sum::<f64>() / n);
            let cov = |a: usize, b: usize| slopes.iter().map(|s| (s[a] - mean[a]) * (s[b] - mean[b])).sum::<f64>() / n;
            let scale = cov(0, 0).max(cov(1, 1));
            for (a, (&got, want)) in ndf.slope_mean.iter().zip(mean).enumerate() {
                assert!((got - want).abs() < 1e-12 * scale.sqrt(), "mean {a}");
                for (b, &c) in ndf.slope_cov[a].iter().enumerate() {
                    assert!((c - cov(a, b)).abs() < 1e-12 * scale, "cov {a} {b}");
                }
            }
        }
    }
}
