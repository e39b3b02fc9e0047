//! The traced surface: the scan's heights as two triangles per grid cell, and the ray-cell test.
//!
//! Cell `(i, j)` spans columns `j..j+1` and rows `i..i+1` of the grid (cell units: `X = x / dx`,
//! `Y = y / dy`; heights stay in metres). With `u = X - j`, `v = Y - i` its corners `h00 = h[i][j]`,
//! `h10 = h[i][j+1]`, `h01 = h[i+1][j]`, `h11 = h[i+1][j+1]` make two planar triangles split along the
//! diagonal `u = v`: `T0` (`u >= v`: corners 00, 10, 11) and `T1` (`u < v`: 00, 01, 11). Each triangle's
//! normal is exact: `m = (-sx, -sy, 1) / |.|` with its own slopes (CONTRACT.md, Heitz eq. 61-62), e.g.
//! `T0`: `sx = (h10 - h00) / dx`, `sy = (h11 - h10) / dy`. Neighbouring cells share their edges' heights,
//! so the surface is continuous (watertight) and every point has one normal.
//!
//! Borders: [`Border::Periodic`] wraps the grid (column `nx - 1` joins column 0), a closed surface on
//! which every path ends going up; [`Border::Open`] traces `(nx - 1) x (ny - 1)` cells and a ray that
//! leaves the grid sideways has left the surface. Holes (NaN heights) are filled for tracing by linear
//! interpolation along rows, then columns, so a path can cross them; no ray starts (lands first) in a
//! cell with a filled corner or in a wrap cell of a periodic grid, and later hits there are counted.

use crate::error::{Error, ErrorKind, Result};
use crate::scan::Scan;

/// What happens at the edges of the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Border {
    /// The grid repeats: column `nx - 1` joins column 0 and row `ny - 1` row 0. Energy is conserved
    /// exactly (no ray leaves sideways); a scan that is not periodic gets a seam where its edges meet.
    Periodic,
    /// Only the scan's own `(nx - 1) x (ny - 1)` cells: a ray that leaves the grid sideways has left the
    /// surface (counted as `escaped` in the report, by its direction; one going down is lost).
    Open,
}

impl std::str::FromStr for Border {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "periodic" => Ok(Border::Periodic),
            "open" => Ok(Border::Open),
            other => Err(Error::invalid(format!("unknown border {other:?}: use periodic or open"))),
        }
    }
}

/// A point where a ray meets the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Hit {
    /// Ray parameter.
    pub t: f64,
    /// Cell row, column (within the grid) and triangle (0 or 1).
    pub i: usize,
    pub j: usize,
    pub tri: u8,
}

impl Hit {
    /// The triangle's id (for excluding it as the start of the next segment).
    pub fn id(&self) -> u64 {
        ((self.i as u64) << 33) | ((self.j as u64) << 1) | self.tri as u64
    }
}

/// The heightfield ready for tracing (holes filled, validity of each cell for landing).
#[derive(Debug, Clone)]
pub(crate) struct Surface {
    /// Grid points.
    pub nx: usize,
    pub ny: usize,
    /// Cells along x and y (`nx`, `ny` periodic; one less open).
    pub ncx: usize,
    pub ncy: usize,
    /// Spacing (m).
    pub dx: f64,
    pub dy: f64,
    /// Heights, holes filled (m), row-major.
    pub h: Vec<f64>,
    /// One bit per cell: the cell's four corners are measured points (and it is no wrap cell).
    valid: Vec<u64>,
    /// Number of valid cells.
    pub valid_cells: usize,
    /// Points filled.
    pub filled_points: usize,
    /// Lowest and highest height (m).
    pub zmin: f64,
    pub zmax: f64,
    /// The border rule.
    pub border: Border,
}

impl Surface {
    /// The surface of a scan (its heights as given: the caller removes the form first).
    pub fn new(scan: &Scan, border: Border) -> Result<Surface> {
        let (nx, ny) = (scan.nx, scan.ny);
        // Two points per axis at least: a cell needs four corners.
        if nx < 2 || ny < 2 {
            return Err(Error::new(ErrorKind::BadData, format!("a {nx} x {ny} grid has no cell to trace (at least 2 x 2 points)")));
        }
        let (ncx, ncy) = match border {
            Border::Periodic => (nx, ny),
            Border::Open => (nx - 1, ny - 1),
        };
        // Cells must fit the 31 bits of a hit's column and the id packing (2^31 per side is far beyond any scan).
        if ncx >= 1 << 31 || ncy >= 1 << 31 {
            return Err(Error::new(ErrorKind::TooLarge, format!("grid {nx} x {ny} too large to trace")));
        }
        crate::budget::check_bytes((nx as u64 * ny as u64).saturating_mul(8 + 1), "the traced copy of the heights")?;
        // Huge pages: rays read the heights at random places, and 4 KiB pages would miss the TLB.
        let mut h = crate::scan::heights::zeroed(nx * ny);
        h.copy_from_slice(&scan.z[..]);
        let measured: Vec<bool> = h.iter().map(|v| v.is_finite()).collect();
        let filled_points = measured.iter().filter(|&&m| !m).count();
        // Nothing measured leaves nothing to trace.
        if filled_points == h.len() {
            return Err(Error::new(ErrorKind::BadData, "every height is invalid: nothing to trace"));
        }
        fill_holes(&mut h, nx, ny);
        let (mut zmin, mut zmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for &v in &h {
            zmin = zmin.min(v);
            zmax = zmax.max(v);
        }
        let mut valid = vec![0u64; (ncx * ncy).div_ceil(64)];
        let mut valid_cells = 0;
        for i in 0..ncy {
            for j in 0..ncx {
                // Wrap cells join the last row or column to the first: not the scan's own area.
                if i + 1 >= ny || j + 1 >= nx {
                    continue;
                }
                let ok = measured[i * nx + j] && measured[i * nx + j + 1] && measured[(i + 1) * nx + j] && measured[(i + 1) * nx + j + 1];
                if ok {
                    let c = i * ncx + j;
                    valid[c / 64] |= 1 << (c % 64);
                    valid_cells += 1;
                }
            }
        }
        // Rays land only on measured cells: a scan without one has no area to trace.
        if valid_cells == 0 {
            return Err(Error::new(ErrorKind::BadData, "no grid cell has four valid corners: nothing to trace"));
        }
        Ok(Surface { nx, ny, ncx, ncy, dx: scan.dx, dy: scan.dy, h, valid, valid_cells, filled_points, zmin, zmax, border })
    }

    /// Whether rays may land in cell `(i, j)`.
    #[inline]
    pub fn is_valid(&self, i: usize, j: usize) -> bool {
        let c = i * self.ncx + j;
        self.valid[c / 64] >> (c % 64) & 1 == 1
    }

    /// The corners `h00, h10, h01, h11` of cell `(i, j)` (periodic wrap).
    #[inline]
    pub fn corners(&self, i: usize, j: usize) -> [f64; 4] {
        let j1 = if j + 1 == self.nx { 0 } else { j + 1 };
        let i1 = if i + 1 == self.ny { 0 } else { i + 1 };
        let (r0, r1) = (i * self.nx, i1 * self.nx);
        [self.h[r0 + j], self.h[r0 + j1], self.h[r1 + j], self.h[r1 + j1]]
    }

    /// Slopes `(dh/dx, dh/dy)` of triangle `tri` of cell `(i, j)`.
    #[inline]
    pub fn slopes(&self, i: usize, j: usize, tri: u8) -> [f64; 2] {
        let [h00, h10, h01, h11] = self.corners(i, j);
        if tri == 0 {
            [(h10 - h00) / self.dx, (h11 - h10) / self.dy]
        } else {
            [(h11 - h01) / self.dx, (h01 - h00) / self.dy]
        }
    }

    /// The unit normal of triangle `tri` of cell `(i, j)`.
    #[inline]
    pub fn normal(&self, i: usize, j: usize, tri: u8) -> [f64; 3] {
        let [sx, sy] = self.slopes(i, j, tri);
        let r = 1.0 / (1.0 + sx * sx + sy * sy).sqrt();
        [-sx * r, -sy * r, r]
    }

    /// The cell and triangle under the point `(X, Y)` (cell units, inside the grid).
    #[inline]
    pub fn locate(&self, x: f64, y: f64) -> (usize, usize, u8) {
        // Truncation is the floor here: negative coordinates go to cell 0 either way.
        let j = (x.max(0.0) as usize).min(self.ncx - 1);
        let i = (y.max(0.0) as usize).min(self.ncy - 1);
        let tri = if x - j as f64 >= y - i as f64 { 0 } else { 1 };
        (i, j, tri)
    }

    /// Height of the surface at `(X, Y)` in cell `(i, j)` (`u, v` clamped to the cell).
    #[inline]
    pub fn height_in(&self, c: &[f64; 4], i: usize, j: usize, x: f64, y: f64) -> f64 {
        let u = (x - j as f64).clamp(0.0, 1.0);
        let v = (y - i as f64).clamp(0.0, 1.0);
        let [h00, h10, h01, h11] = *c;
        if u >= v {
            h00 + (h10 - h00) * u + (h11 - h10) * v
        } else {
            h00 + (h11 - h01) * u + (h01 - h00) * v
        }
    }

    /// Highest corner of cell `(i, j)`: the cell's triangles lie below it.
    #[inline]
    pub fn cell_max(&self, i: usize, j: usize) -> f64 {
        let c = self.corners(i, j);
        c[0].max(c[1]).max(c[2].max(c[3]))
    }

    /// The first crossing of the ray `o + t d` (cell units, `o` relative to the cell's tile) into cell
    /// `(i, j)` over `[t0, t1]`, the part of the ray above the cell; `exclude` is the triangle the ray
    /// leaves (it cannot meet its own plane again). Along the ray `f(t) = z(t) - h(t)` is linear on each
    /// triangle, so a crossing is a sign change of `f` between the ends of a triangle's segment; a ray
    /// already below at a segment's start (rounding at a crease) meets it there.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn cross_cell(&self, o: [f64; 3], d: [f64; 3], i: usize, j: usize, t0: f64, t1: f64, exclude: u64) -> Option<Hit> {
        let c = self.corners(i, j);
        let (fi, fj) = (i as f64, j as f64);
        // The diagonal u = v: (ou - ov) + t (du - dv) = 0.
        let (w0, dw) = (o[0] - fj - (o[1] - fi), d[0] - d[1]);
        let td = if dw != 0.0 { -w0 / dw } else { f64::NAN };
        let mut segs = [(t0, t1, 0u8); 2];
        let n = if td > t0 && td < t1 {
            segs[0].1 = td;
            segs[1].0 = td;
            2
        } else {
            1
        };
        for s in segs.iter_mut().take(n) {
            let tm = 0.5 * (s.0 + s.1);
            s.2 = if (o[0] + tm * d[0] - fj) >= (o[1] + tm * d[1] - fi) { 0 } else { 1 };
        }
        let f = |t: f64| o[2] + t * d[2] - self.height_in(&c, i, j, o[0] + t * d[0], o[1] + t * d[1]);
        for &(a, b, tri) in segs.iter().take(n) {
            let hit = Hit { t: a, i, j, tri };
            if hit.id() == exclude {
                continue;
            }
            let fa = f(a);
            if fa <= 0.0 {
                return Some(hit);
            }
            let fb = f(b);
            if fb <= 0.0 {
                let t = a + (b - a) * (fa / (fa - fb));
                return Some(Hit { t: t.clamp(a, b), ..hit });
            }
        }
        None
    }
}

/// Fill NaN heights in place: along each row by linear interpolation between the nearest measured points
/// (constant beyond the ends), then rows without any measured point along the columns the same way.
pub(crate) fn fill_holes(h: &mut [f64], nx: usize, ny: usize) {
    let mut empty_rows = Vec::new();
    for i in 0..ny {
        let row = &mut h[i * nx..(i + 1) * nx];
        if !fill_line(row.iter_mut().collect::<Vec<_>>()) {
            empty_rows.push(i);
        }
    }
    if empty_rows.is_empty() {
        return;
    }
    for j in 0..nx {
        let col: Vec<&mut f64> = h.iter_mut().skip(j).step_by(nx).collect();
        fill_line(col);
    }
}

/// Fill one line of heights; false when it has no measured point (left as it is).
fn fill_line(mut v: Vec<&mut f64>) -> bool {
    let known: Vec<usize> = (0..v.len()).filter(|&k| v[k].is_finite()).collect();
    let (Some(&first), Some(&last)) = (known.first(), known.last()) else { return false };
    let (a, b) = (*v[first], *v[last]);
    for x in v.iter_mut().take(first) {
        **x = a;
    }
    for x in v.iter_mut().skip(last + 1) {
        **x = b;
    }
    for w in known.windows(2) {
        let (p, q) = (w[0], w[1]);
        if q > p + 1 {
            let (hp, hq) = (*v[p], *v[q]);
            for (k, x) in v.iter_mut().enumerate().take(q).skip(p + 1) {
                let s = (k - p) as f64 / (q - p) as f64;
                **x = hp + (hq - hp) * s;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holes_are_filled_linearly_and_cells_touching_them_are_not_landing_cells() {
        let mut z = vec![0.0; 16];
        for (k, v) in z.iter_mut().enumerate() {
            *v = (k % 4) as f64;
        }
        z[5] = f64::NAN;
        let scan = crate::scan::Heightfield::new(4, 4, 1.0, 1.0, z).unwrap();
        let s = Surface::new(&scan, Border::Open).unwrap();
        assert_eq!(s.h[5], 1.0);
        assert_eq!(s.filled_points, 1);
        assert!(!s.is_valid(0, 0) && !s.is_valid(1, 1) && s.is_valid(2, 2));
        assert_eq!(s.valid_cells, 9 - 4);
    }

    #[test]
    fn a_vertical_ray_meets_the_triangle_below_it() {
        // A plane of slope 0.5 along x: a ray straight down at X = 1.25 meets z = 0.625.
        let z: Vec<f64> = (0..9).map(|k| 0.5 * (k % 3) as f64).collect();
        let scan = crate::scan::Heightfield::new(3, 3, 1.0, 1.0, z).unwrap();
        let s = Surface::new(&scan, Border::Open).unwrap();
        let hit = s.cross_cell([1.25, 0.5, 10.0], [0.0, 0.0, -1.0], 0, 1, 0.0, 100.0, u64::MAX).unwrap();
        assert!((10.0 - hit.t - 0.625).abs() < 1e-12, "{hit:?}");
        let n = s.normal(0, 1, hit.tri);
        assert!((n[0] + 0.5 / 1.25f64.sqrt()).abs() < 1e-12);
    }
}
