//! A scan's empirical NDF as the function the table samples: the bins where they are measured well, the
//! fitted model where they are not.
//!
//! Inside the fit region (`theta <= max_theta`) the value at `m` is
//! `w D_bin + (1 - w) D_fit(m)` with `w = 1 / (1 + (s / (REL_NOISE D_bin))^2)`, `D_bin` the bin holding `m` and
//! `s` its standard error: a bin whose relative error is `REL_NOISE` keeps half its own value, an empty or
//! unmeasured bin none. Beyond `max_theta` (the tail the fit left out: the scan does not resolve it) the
//! fitted model stands alone. The writer then renormalizes the table.

use nalgebra::Vector3;

use crate::models::{Model, Ndf};
use crate::ndf::EmpiricalNdf;

/// The relative standard error at which a bin and the fit weigh equally.
pub const REL_NOISE: f64 = 0.2;

/// The regularized empirical NDF.
pub struct Regularized<'a> {
    ndf: &'a EmpiricalNdf,
    fit: &'a Model,
    cos_max: f64,
}

impl<'a> Regularized<'a> {
    /// The empirical `ndf` regularized by the `fit`, the bins trusted up to `max_theta_deg`.
    pub fn new(ndf: &'a EmpiricalNdf, fit: &'a Model, max_theta_deg: f64) -> Regularized<'a> {
        Regularized { ndf, fit, cos_max: max_theta_deg.to_radians().cos() }
    }

    /// `D(m)` (scan frame, `z` up).
    pub fn d(&self, m: Vector3<f64>) -> f64 {
        let fit = self.fit.d(m);
        if m.z < self.cos_max {
            return fit;
        }
        match self.ndf.bin_of(m).map(|k| &self.ndf.bins[k]) {
            Some(b) if b.count > 0 && b.d > 0.0 => {
                let r = b.stderr / (REL_NOISE * b.d);
                let w = 1.0 / (1.0 + r * r);
                w * b.d + (1.0 - w) * fit
            }
            _ => fit,
        }
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
