//! The acceleration structure: a maximum-height pyramid (a max mipmap) over the cells, and the first
//! hit of a ray by descending it.
//!
//! Level `L >= 1` holds, per block of `2^L x 2^L` cells, the highest corner in the block, rounded up to
//! `f32` (conservative, half the memory: about 1/3 of a height per point at 8192^2 when level 1 is
//! `f32`). Level 0 is the cells themselves, whose highest corner is read from the heights. A ray's part
//! over a block is skipped when its lowest point there (entry or exit: `z` is linear in `t`) is above the
//! block's maximum; otherwise the block's children are visited in the order the ray meets them, so the
//! first crossing found is the nearest. Over a periodic grid the ray walks the tiles it crosses (2D DDA)
//! and descends the pyramid in each, until it is above the highest point going up (it has left) or
//! below the lowest going down (a numerical leak, counted by the caller).

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

/// The pending blocks of a descent: (level, block row, block column, t in, t out). Kept by the caller
/// between rays so that no ray allocates.
pub(crate) type Stack = Vec<(u8, u32, u32, f64, f64)>;

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

    /// Height above which the block `(bi, bj)` of `level` has nothing (level 0: a cell).
    #[inline]
    fn max_of(&self, s: &Surface, level: usize, bi: usize, bj: usize) -> f64 {
        if level == 0 {
            s.cell_max(bi, bj)
        } else {
            let (bx, _, v) = &self.levels[level - 1];
            v[bi * bx + bj] as f64
        }
    }

    /// The first hit of the ray `o + t d` (`o` in grid cell units inside the grid, `t >= 0`), not on
    /// triangle `exclude`.
    pub fn first_hit(&self, s: &Surface, o: [f64; 3], d: [f64; 3], exclude: u64, stack: &mut Stack) -> Outcome {
        let (w, h) = (s.ncx as f64, s.ncy as f64);
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
        let (mut tx, mut ty) = (0i64, 0i64);
        let mut tmin = 0.0f64;
        for _ in 0..MAX_TILES {
            let lo = [o[0] - tx as f64 * w, o[1] - ty as f64 * h, o[2]];
            let (a0, a1) = slab(lo[0], inv[0], 0.0, w);
            let (b0, b1) = slab(lo[1], inv[1], 0.0, h);
            let t0 = a0.max(b0).max(tmin);
            let t1 = a1.min(b1).min(t_end);
            if t0 <= t1 {
                if let Some(hit) = self.descend(s, lo, d, t0, t1, exclude, stack) {
                    let p = [lo[0] + hit.t * d[0], lo[1] + hit.t * d[1], lo[2] + hit.t * d[2]];
                    return Outcome::Hit(hit, p);
                }
            }
            if t1 >= t_end {
                return if d[2] > 0.0 { Outcome::Left { side: false } } else { Outcome::Lost };
            }
            // Off the side of an open grid: gone, whatever lies beyond.
            if s.border == Border::Open || !t1.is_finite() {
                return if d[2] > 0.0 { Outcome::Left { side: true } } else { Outcome::Lost };
            }
            tmin = t1;
            if a1 <= b1 {
                tx += if d[0] > 0.0 { 1 } else { -1 };
            }
            if b1 <= a1 {
                ty += if d[1] > 0.0 { 1 } else { -1 };
            }
        }
        Outcome::Lost
    }

    /// The first hit inside one tile over `[t0, t1]` (`o` relative to the tile), by descending the pyramid.
    #[allow(clippy::too_many_arguments)]
    fn descend(&self, s: &Surface, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64, exclude: u64, stack: &mut Stack) -> Option<Hit> {
        let top = self.levels.len();
        if !(self.max_of(s, top, 0, 0).is_finite()) {
            return None;
        }
        let inv = [1.0 / d[0], 1.0 / d[1]];
        let zlow = |a: f64, b: f64| o[2] + if d[2] < 0.0 { b } else { a } * d[2];
        stack.clear();
        if zlow(t0, t1) <= self.max_of(s, top, 0, 0) {
            stack.push((top as u8, 0, 0, t0, t1));
        }
        while let Some((level, bi, bj, ta, tb)) = stack.pop() {
            let (bi, bj) = (bi as usize, bj as usize);
            if level == 0 {
                if let Some(hit) = s.cross_cell(o, d, bi, bj, ta, tb, exclude) {
                    return Some(hit);
                }
                continue;
            }
            let cl = level as usize - 1;
            let size = (1usize << cl) as f64;
            let mut kids: [(f64, f64, u32, u32); 4] = [(0.0, 0.0, 0, 0); 4];
            let mut nk = 0;
            for ci in 2 * bi..2 * bi + 2 {
                if (ci << cl) >= s.ncy {
                    continue;
                }
                let (y0, y1) = (ci as f64 * size, ((ci + 1) as f64 * size).min(s.ncy as f64));
                let (b0, b1) = slab(o[1], inv[1], y0, y1);
                for cj in 2 * bj..2 * bj + 2 {
                    if (cj << cl) >= s.ncx {
                        continue;
                    }
                    let (x0, x1) = (cj as f64 * size, ((cj + 1) as f64 * size).min(s.ncx as f64));
                    let (a0, a1) = slab(o[0], inv[0], x0, x1);
                    let (c0, c1) = (a0.max(b0).max(ta), a1.min(b1).min(tb));
                    if c0 > c1 || zlow(c0, c1) > self.max_of(s, cl, ci, cj) {
                        continue;
                    }
                    kids[nk] = (c0, c1, ci as u32, cj as u32);
                    nk += 1;
                }
            }
            // Push the farthest first, so the nearest is popped first.
            kids[..nk].sort_unstable_by(|p, q| q.0.total_cmp(&p.0));
            for k in &kids[..nk] {
                stack.push((cl as u8, k.2, k.3, k.0, k.1));
            }
        }
        None
    }
}

/// The ray's `t` range inside `[lo, hi]` along one axis (`inv = 1 / d`; a ray along the slab is inside
/// for every `t` or none).
#[inline]
fn slab(o: f64, inv: f64, lo: f64, hi: f64) -> (f64, f64) {
    if inv.is_infinite() {
        return if o >= lo && o < hi { (f64::NEG_INFINITY, f64::INFINITY) } else { (f64::INFINITY, f64::NEG_INFINITY) };
    }
    let (a, b) = ((lo - o) * inv, (hi - o) * inv);
    if a <= b {
        (a, b)
    } else {
        (b, a)
    }
}
