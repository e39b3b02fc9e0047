//! The fitter of `src/fit/` behind [`Fitter`]: Levenberg-Marquardt on the Poisson deviance
//! (data_formats/objective.md), canonical parameters.

use super::analyze::{Fitted, Fitter};
use crate::error::Result;
use crate::fit::{fit_model, FitOptions};
use crate::models::ModelId;
use crate::ndf::EmpiricalNdf;

/// [`crate::fit::fit_model`] with the given options.
#[derive(Debug, Clone, Copy, Default)]
pub struct FitFitter {
    /// Options passed to every fit.
    pub options: FitOptions,
}

impl Fitter for FitFitter {
    fn fit(&self, ndf: &EmpiricalNdf, id: ModelId) -> Result<Fitted> {
        let r = fit_model(ndf, id, &self.options)?;
        Ok(Fitted {
            model: r.to_model()?,
            objective: Some(r.quality.objective_value),
            reduced_chi2: r.quality.reduced_chi2,
            n_samples: r.quality.n_samples,
        })
    }
}
