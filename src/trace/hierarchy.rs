//! The acceleration structure: a maximum-height pyramid (a max mipmap) over the cells, and the first
//! hit of a ray by descending it.
//!
//! Level `L >= 1` holds, per block of `2^L x 2^L` cells, the highest corner in the block, rounded up to
//! `f32` (conservative, half the memory: about 1/3 of a height per point at 8192^2 when level 1 is
//! `f32`). Level 0 is the cells themselves, tested exactly. A ray's part over a block is skipped when its
//! lowest point there (entry or exit: `z` is linear in `t`) is above the block's maximum; otherwise the
//! ray descends into the child it is in. Without a stack (Tevs et al. 2008): after a skip the ray moves
//! to the next block at the same level, or one level up when it leaves the parent, so blocks are met in
//! the ray's order and the first crossing found is the nearest. Over a periodic grid the cell indices
//! wrap, until the ray is above the highest point going up (it has left) or below the lowest going down
//! (a numerical leak, counted by the caller).

use super::surface::{Border, Hit, Surface};

/// Tiles a ray may cross before it is given up (a ray travelling almost level over a periodic grid).
const MAX_TILES: usize = 4096;

/// The maximum pyramid of a surface.
#[derive(Debug, Clone)]
pub(crate) struct Pyramid {
    /// Levels 1.. (index 0 = level 1): (blocks along x, blocks along y, maxima).
    levels: Vec<(usize, usize, Vec<f32>)>,
}

/// An `f32` not below `v`.
fn up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
}

/// What became of a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Outcome {
    /// It met the surface: the hit, the position in grid cell units (wrapped into the grid).
    Hit(Hit, [f64; 3]),
    /// It left: above the surface going up, or sideways off an open grid (`side`).
    Left { side: bool },
    /// Below every height, too many tiles, or a non-finite step: lost.
    Lost,
}

impl Pyramid {
    /// Build the pyramid (level 1 from the cells' corners, each next level from the one below).
    pub fn new(s: &Surface) -> crate::Result<Pyramid> {
        let mut levels: Vec<(usize, usize, Vec<f32>)> = Vec::new();
        let (mut bx, mut by) = (s.ncx, s.ncy);
        let mut bytes = 0u64;
        while bx > 1 || by > 1 {
            bx = bx.div_ceil(2);
            by = by.div_ceil(2);
            bytes += 4 * (bx * by) as u64;
        }
        crate::budget::check_bytes(bytes, "the height pyramid of the traced surface")?;
        let (bx, by) = (s.ncx.div_ceil(2), s.ncy.div_ceil(2));
        let mut l1 = vec![0f32; bx * by];
        crate::scan::heights::advise_huge(l1.as_ptr() as usize, 4 * l1.len());
        use rayon::prelude::*;
        l1.par_chunks_mut(bx).enumerate().for_each(|(bi, row)| {
            for (bj, v) in row.iter_mut().enumerate() {
                let mut m = f64::NEG_INFINITY;
                for i in 2 * bi..(2 * bi + 2).min(s.ncy) {
                    for j in 2 * bj..(2 * bj + 2).min(s.ncx) {
                        m = m.max(s.cell_max(i, j));
                    }
                }
                *v = up(m);
            }
        });
        levels.push((bx, by, l1));
        while {
            let (bx, by, _) = levels.last().unwrap();
            *bx > 1 || *by > 1
        } {
            let (px, py, prev) = levels.last().unwrap();
            let (nx, ny) = (px.div_ceil(2), py.div_ceil(2));
            let mut next = vec![f32::NEG_INFINITY; nx * ny];
            for i in 0..*py {
                for j in 0..*px {
                    let k = (i / 2) * nx + j / 2;
                    next[k] = next[k].max(prev[i * px + j]);
                }
            }
            levels.push((nx, ny, next));
        }
        Ok(Pyramid { levels })
    }

    /// The maximum of block `(bi, bj)` of `level >= 1`.
    #[inline]
    fn max_at(&self, level: usize, bi: usize, bj: usize) -> f64 {
        let (bx, _, v) = &self.levels[level - 1];
        v[bi * bx + bj] as f64
    }

    /// Ask the memory for what a ray starting above cell `(i, j)` reads first: the cell's heights and
    /// the pyramid's blocks over it at the fine levels (the coarse ones stay cached). A hint only.
    #[inline]
    pub fn prefetch(&self, s: &Surface, i: usize, j: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let hint = |p: *const f32| {
                // SAFETY: a prefetch never faults and reads nothing; the pointers are in bounds anyway.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p as *const i8) }
            };
            for (l, (bx, _, v)) in self.levels.iter().enumerate().take(4) {
                let k = (i >> (l + 1)) * bx + (j >> (l + 1));
                if k < v.len() {
                    hint(v.as_ptr().wrapping_add(k));
                }
            }
            let i1 = if i + 1 >= s.ny { 0 } else { i + 1 };
            for r in [i, i1] {
                let k = r * s.nx + j;
                if k < s.h.len() {
                    hint(s.h.as_ptr().wrapping_add(k) as *const f32);
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (s, i, j);
    }

    /// The first hit of the ray `o + t d` (`o` in grid cell units inside the grid, `t >= 0`), not on
    /// triangle `exclude`. `start` is the cell the ray starts in when it starts on the surface (the cell
    /// of the hit it leaves); without it the ray starts above the surface and is located from `o`.
    ///
    /// Stackless descent (Tevs, Ihrke and Seidel 2008, maximum mipmaps): the ray is at the block of the
    /// current level holding its current point; a block whose maximum lies below the ray's lowest point
    /// over it is skipped whole (the ray moves to the block's exit, and one level up when that leaves the
    /// parent), otherwise the ray descends to the child holding its point; at level 0 the cell's two
    /// triangles are tested. Blocks are visited in the order the ray meets them, so the first crossing is
    /// the nearest. Over a periodic grid the cell indices wrap and the origin moves by one tile.
    pub fn first_hit(&self, s: &Surface, o: [f64; 3], d: [f64; 3], start: Option<(usize, usize)>, exclude: u64) -> Outcome {
        let (ncx, ncy) = (s.ncx as i64, s.ncy as i64);
        let top = self.levels.len();
        // A grid of one cell has no level above the cells: the top is the cell itself.
        let inv = [1.0 / d[0], 1.0 / d[1]];
        // Where the ray passes the lowest height going down (a hit must come before) or the highest going
        // up (nothing is met after); level rays have no such end.
        let t_end = if d[2] < 0.0 {
            ((s.zmin - o[2]) / d[2]) * (1.0 + 1e-9) + 1e-12
        } else if d[2] > 0.0 {
            (s.zmax - o[2]) / d[2]
        } else {
            f64::INFINITY
        };
        let gone = |side: bool| if d[2] > 0.0 { Outcome::Left { side } } else { Outcome::Lost };
        let mut lo = o;
        let (mut ci, mut cj, mut level) = match start {
            Some((i, j)) => (i as i64, j as i64, 0usize),
            None => (cell_of(o[1], d[1], ncy), cell_of(o[0], d[0], ncx), top),
        };
        let mut t = 0.0f64;
        let mut tiles = 0usize;
        loop {
            let (bi, bj) = (ci >> level, cj >> level);
            let (x0, x1) = (bj << level, ((bj + 1) << level).min(ncx));
            let (y0, y1) = (bi << level, ((bi + 1) << level).min(ncy));
            let tx = if d[0] > 0.0 {
                (x1 as f64 - lo[0]) * inv[0]
            } else if d[0] < 0.0 {
                (x0 as f64 - lo[0]) * inv[0]
            } else {
                f64::INFINITY
            };
            let ty = if d[1] > 0.0 {
                (y1 as f64 - lo[1]) * inv[1]
            } else if d[1] < 0.0 {
                (y0 as f64 - lo[1]) * inv[1]
            } else {
                f64::INFINITY
            };
            let te = tx.min(ty).max(t);
            if level == 0 {
                if let Some(hit) = s.cross_cell(lo, d, ci as usize, cj as usize, t, te.min(t_end), exclude) {
                    let p = [lo[0] + hit.t * d[0], lo[1] + hit.t * d[1], lo[2] + hit.t * d[2]];
                    return Outcome::Hit(hit, p);
                }
            } else {
                let zlow = lo[2] + d[2] * if d[2] < 0.0 { te.min(t_end) } else { t };
                if !(zlow > self.max_at(level, bi as usize, bj as usize)) {
                    level -= 1;
                    continue;
                }
            }
            // Nothing in this block: on to the next one the ray meets.
            if te >= t_end {
                return gone(false);
            }
            t = te;
            let (pi, pj) = (ci, cj);
            if tx <= ty {
                cj = if d[0] > 0.0 { x1 } else { x0 - 1 };
            } else {
                cj = floor(lo[0] + t * d[0]).clamp(x0, x1 - 1);
            }
            if ty <= tx {
                ci = if d[1] > 0.0 { y1 } else { y0 - 1 };
            } else {
                ci = floor(lo[1] + t * d[1]).clamp(y0, y1 - 1);
            }
            if cj < 0 || cj >= ncx || ci < 0 || ci >= ncy {
                // Off the side of an open grid: gone, whatever lies beyond.
                if s.border == Border::Open {
                    return gone(true);
                }
                tiles += 1;
                if tiles > MAX_TILES || !t.is_finite() {
                    return Outcome::Lost;
                }
                if cj < 0 {
                    cj += ncx;
                    lo[0] += ncx as f64;
                } else if cj >= ncx {
                    cj -= ncx;
                    lo[0] -= ncx as f64;
                }
                if ci < 0 {
                    ci += ncy;
                    lo[1] += ncy as f64;
                } else if ci >= ncy {
                    ci -= ncy;
                    lo[1] -= ncy as f64;
                }
            }
            // Left the parent block: its neighbour may be skipped whole.
            if level < top && ((ci >> (level + 1)) != (pi >> (level + 1)) || (cj >> (level + 1)) != (pj >> (level + 1))) {
                level += 1;
            }
        }
    }
}

/// The cell holding coordinate `x` along an axis of `n` cells, on a cell edge the one the ray enters
/// (direction component `d`).
#[inline]
fn cell_of(x: f64, d: f64, n: i64) -> i64 {
    let f = floor(x);
    let c = if d < 0.0 && f as f64 == x { f - 1 } else { f };
    c.clamp(0, n - 1)
}

/// `floor(x)` as an integer, saturating (without SSE4.1 `f64::floor` is a call into libm).
#[inline]
pub(crate) fn floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}
