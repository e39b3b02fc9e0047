//! A scan's empirical NDF as the function the table samples: the bins where they are measured well, the
//! fitted model where they are not.
//!
//! Inside the fit region (`theta <= max_theta`) each bin's value at `m` is
//! `w D_bin + (1 - w) D_fit(m)` (interpolated bilinearly between the bins' centres) with `w = 1 / (1 + (s / (REL_NOISE D_bin))^2)`, `D_bin` the bin holding `m` and
//! `s` its standard error: a bin whose relative error is `REL_NOISE` keeps half its own value, an empty or
//! unmeasured bin none. Beyond `max_theta` (the tail the fit left out: the scan does not resolve it) the
//! fitted model stands alone. The writer then renormalizes the table.

use nalgebra::Vector3;

use crate::models::{Model, Ndf};
use crate::ndf::{EmpiricalNdf, SlopeFrame};

/// The relative standard error at which a bin and the fit weigh equally.
pub const REL_NOISE: f64 = 0.2;

/// The regularized empirical NDF.
pub struct Regularized<'a> {
    ndf: &'a EmpiricalNdf,
    fit: &'a Model,
    cos_max: f64,
    /// Per grid cell (row-major), the index in `blend` of its measured bin, `u32::MAX` for none: a
    /// lookup per corner instead of a search of the bins (a renderer reads `D` hundreds of thousands
    /// of times).
    cells: Vec<u32>,
    /// Per measured bin (`count > 0`, `D > 0`), its weight `w` and its `D`.
    blend: Vec<[f64; 2]>,
}

impl<'a> Regularized<'a> {
    /// The empirical `ndf` regularized by the `fit`, the bins trusted up to `max_theta_deg`.
    pub fn new(ndf: &'a EmpiricalNdf, fit: &'a Model, max_theta_deg: f64) -> Regularized<'a> {
        let n = ndf.grid.n;
        let mut cells = vec![u32::MAX; n * n];
        let mut blend = Vec::new();
        for (&c, b) in ndf.bin_cells.iter().zip(&ndf.bins) {
            // An empty or zero bin takes the fit; a cell outside the grid cannot be looked up.
            if b.count > 0 && b.d > 0.0 && (c as usize) < cells.len() {
                let r = b.stderr / (REL_NOISE * b.d);
                cells[c as usize] = blend.len() as u32;
                blend.push([1.0 / (1.0 + r * r), b.d]);
            }
        }
        Regularized { ndf, fit, cos_max: max_theta_deg.to_radians().cos(), cells, blend }
    }

    /// `D(m)` (scan frame, `z` up): the blended values of the four bins around `m` interpolated bilinearly
    /// between their centres on the binning grid (a table finer than the bins then reads a smooth NDF, not
    /// the histogram's steps); a cell without a measured bin takes the fit.
    pub fn d(&self, m: Vector3<f64>) -> f64 {
        let fit = self.fit.d(m);
        let grid = &self.ndf.grid;
        if m.z < self.cos_max || grid.n == 0 {
            return fit;
        }
        let s = SlopeFrame::slope_of(m);
        let p = self.ndf.frame.to_lambert(s[0], s[1]);
        // Cell coordinates with the cell centres on whole numbers.
        let [x0, x1, y0, _] = grid.bounds(0);
        let h = x1 - x0;
        let (fx, fy) = ((p[0] - x0) / h - 0.5, (p[1] - y0) / h - 0.5);
        if !(fx.is_finite() && fy.is_finite()) {
            return fit;
        }
        let (ix, iy) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - ix, fy - iy);
        let value = |cx: f64, cy: f64| {
            let n = grid.n as f64;
            if !(0.0..n).contains(&cx) || !(0.0..n).contains(&cy) {
                return fit;
            }
            match self.blend.get(self.cells[cy as usize * grid.n + cx as usize] as usize) {
                Some(&[w, d]) => w * d + (1.0 - w) * fit,
                None => fit,
            }
        };
        (1.0 - ty) * ((1.0 - tx) * value(ix, iy) + tx * value(ix + 1.0, iy))
            + ty * ((1.0 - tx) * value(ix, iy + 1.0) + tx * value(ix + 1.0, iy + 1.0))
    }

    /// The sentence the file's `description` carries about how the NDF was made.
    pub fn describe(&self, max_theta_deg: f64) -> String {
        format!(
            "empirical NDF of {} bins ({} normals), each bin blended with the fitted {} by the weight 1/(1+(stderr/({REL_NOISE} D))^2) \
             (noisy and empty bins take the fit); beyond max_theta = {max_theta_deg:.1} deg (the fit region) the fitted {} alone",
            self.ndf.bins.len(),
            self.ndf.n_samples,
            self.fit.id(),
            self.fit.id()
        )
    }
}
