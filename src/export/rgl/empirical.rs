//! A scan's empirical NDF as the function the table samples: the bins where they are measured well, the
//! fitted model where they are not.
//!
//! Inside the fit region (`theta <= max_theta`) the value at `m` is the fit at `m` times the bins' ratios
//! to it, interpolated bilinearly in `ln` between the bins' centres. A bin's ratio is
//! `(w D_bin + (1 - w) F_bin) / F_bin`, `F_bin` the fit's mean over the bin and
//! `w = 1 / (1 + (s / (REL_NOISE D_bin))^2)`, `s` the bin's standard error: a bin whose relative error is
//! `REL_NOISE` keeps half its own value, an empty or unmeasured bin none (ratio 1: the fit). A bin holds
//! the NDF's mean over it, not its value at the centre, and a lobe's tail falls by decades across one
//! bin: taken for the centre's value and interpolated, the means drew a ring around every highlight where
//! the scan follows its lobe exactly. Beyond `max_theta` (the tail the fit left out: the scan does not
//! resolve it) the fitted model stands alone. The writer then renormalizes the table.

use nalgebra::Vector3;

use crate::models::{Model, Ndf};
use crate::ndf::{EmpiricalNdf, QuadOrder, SlopeFrame};
use rayon::prelude::*;

/// The relative standard error at which a bin and the fit weigh equally.
pub const REL_NOISE: f64 = 0.2;

/// The regularized empirical NDF.
pub struct Regularized<'a> {
    ndf: &'a EmpiricalNdf,
    fit: &'a Model,
    cos_max: f64,
    /// Per grid cell (row-major), `ln` of the blended bin over the fit's mean over the bin: 0 where the
    /// bin is empty or the cell has none. Read four per lookup: a renderer reads `D` hundreds of
    /// thousands of times.
    ln_ratio: Vec<f64>,
    /// The largest blended bin value: with the fit at `m`, the most a value may be.
    cap: f64,
}

/// `ln x`, finite for every `x >= 0`: a fit that underflows in a far tail stays a number.
fn ln0(x: f64) -> f64 {
    x.max(f64::MIN_POSITIVE).ln()
}

/// The quadrature nodes of an NDF's measured bins (direction and projected solid angle, as
/// [`EmpiricalNdf::bin_integral`] takes them), for the tables of many fits over one grid: a table's bin
/// means of its fit are then one evaluation per node. The halves of a dispersion split share them.
pub struct BinNodes {
    /// Per bin, where its nodes start in `nodes` (and, one past the last bin, where they end).
    start: Vec<usize>,
    nodes: Vec<(Vector3<f64>, f64)>,
}

impl BinNodes {
    /// The nodes of every bin of `ndf` with a count.
    pub fn new(ndf: &EmpiricalNdf) -> BinNodes {
        let per_bin: Vec<Vec<(Vector3<f64>, f64)>> = (0..ndf.bins.len())
            .into_par_iter()
            .map(|k| {
                let mut v = Vec::new();
                if ndf.bins[k].count > 0 {
                    ndf.bin_nodes(k, QuadOrder::Standard, |m, dw| v.push((m, dw)));
                }
                v
            })
            .collect();
        let mut start = Vec::with_capacity(per_bin.len() + 1);
        let mut nodes = Vec::with_capacity(per_bin.iter().map(Vec::len).sum());
        for v in per_bin {
            start.push(nodes.len());
            nodes.extend(v);
        }
        start.push(nodes.len());
        BinNodes { start, nodes }
    }

    /// `integral of f(m) (m.n) dw` over bin `k` (0 for a bin without nodes).
    fn integral(&self, k: usize, f: impl Fn(Vector3<f64>) -> f64) -> f64 {
        self.nodes[self.start[k]..self.start[k + 1]].iter().map(|&(m, dw)| f(m) * dw).sum()
    }
}

impl<'a> Regularized<'a> {
    /// The empirical `ndf` regularized by the `fit`, the bins trusted up to `max_theta_deg`.
    pub fn new(ndf: &'a EmpiricalNdf, fit: &'a Model, max_theta_deg: f64) -> Regularized<'a> {
        Self::with_nodes(ndf, fit, max_theta_deg, &BinNodes::new(ndf))
    }

    /// As [`Regularized::new`], the bins' quadrature `nodes` given (of `ndf`'s grid and frame, with a
    /// node set for every bin `ndf` counts in).
    pub fn with_nodes(ndf: &'a EmpiricalNdf, fit: &'a Model, max_theta_deg: f64, nodes: &BinNodes) -> Regularized<'a> {
        let mut ln_ratio = vec![0.0; ndf.grid.n * ndf.grid.n];
        let measured: Vec<(usize, f64, f64)> = (0..ndf.bins.len().min(nodes.start.len().saturating_sub(1)))
            .into_par_iter()
            .filter_map(|k| {
                let (b, c) = (&ndf.bins[k], ndf.bin_cells[k] as usize);
                // An empty or zero bin takes the fit; a cell outside the grid cannot be looked up.
                if !(b.count > 0 && b.d > 0.0 && c < ln_ratio.len()) || nodes.start[k] == nodes.start[k + 1] {
                    return None;
                }
                let r = b.stderr / (REL_NOISE * b.d);
                let w = 1.0 / (1.0 + r * r);
                let mean = nodes.integral(k, |m| fit.d(m)) / b.proj_solid_angle;
                let v = w * b.d + (1.0 - w) * mean;
                Some((c, ln0(v) - ln0(mean), v))
            })
            .collect();
        let mut cap = 0.0f64;
        for (c, r, v) in measured {
            ln_ratio[c] = r;
            cap = cap.max(v);
        }
        Regularized { ndf, fit, cos_max: max_theta_deg.to_radians().cos(), ln_ratio, cap }
    }

    /// `D(m)` (scan frame, `z` up): the fit at `m` times the bins' ratios to it (each the blended bin over
    /// the fit's mean over that bin) interpolated bilinearly in `ln` between the bins' centres on the
    /// binning grid. A table finer than the bins then reads a smooth NDF, not the histogram's steps, and a
    /// bin's mean is not taken for the value at its centre: where the scan follows the fit the table is
    /// the fit, however fast it falls across a bin (the tail's bins span decades).
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
                return 0.0;
            }
            self.ln_ratio[cy as usize * grid.n + cx as usize]
        };
        let ln_ratio = (1.0 - ty) * ((1.0 - tx) * value(ix, iy) + tx * value(ix + 1.0, iy))
            + ty * ((1.0 - tx) * value(ix, iy + 1.0) + tx * value(ix + 1.0, iy + 1.0));
        // A fit narrower than a bin has a mean there far below the bin (even 0): its ratio is no shape, and
        // the product is held to the larger of the fit and the data's largest value (not an overflow).
        (ln0(fit) + ln_ratio).exp().min(fit.max(self.cap))
    }

    /// The sentence the file's `description` carries about how the NDF was made.
    pub fn describe(&self, max_theta_deg: f64) -> String {
        format!(
            "empirical NDF of {} bins ({} normals) as the fitted {} times each bin's ratio to the fit's mean over it (log-bilinear \
             between the bins' centres), each bin blended with the fit by the weight 1/(1+(stderr/({REL_NOISE} D))^2) \
             (noisy and empty bins take the fit); beyond max_theta = {max_theta_deg:.1} deg (the fit region) the fitted {} alone",
            self.ndf.bins.len(),
            self.ndf.n_samples,
            self.fit.id(),
            self.fit.id()
        )
    }
}
