//! The range checks of [`FitOptions`]: every fit refuses an out-of-range option with an error naming
//! it, rather than clamping it.

use super::FitOptions;
use crate::error::{Error, Result};

/// Most extra ellipsoid starts: the skews `(+-0.3, 0), (0, +-0.3)`.
pub const MAX_EXTRA_STARTS: usize = 4;

impl FitOptions {
    /// Refuse out-of-range values ([`crate::ErrorKind::InvalidInput`], the message naming the field):
    /// `extra_starts` above [`MAX_EXTRA_STARTS`], a `max_theta` outside (0, pi/2] radians, a relative
    /// tolerance that is not finite and positive, no iteration, or a `tolerance` on the NDF error that is not
    /// finite and positive. Every fit calls it first.
    pub fn validate(&self) -> Result<()> {
        if self.extra_starts > MAX_EXTRA_STARTS {
            return Err(Error::invalid(format!("extra_starts {} must be between 0 and {MAX_EXTRA_STARTS}", self.extra_starts)));
        }
        // The bound as the command line computes it from 90 degrees, so `--max-theta 90` passes.
        if !(self.max_theta > 0.0 && self.max_theta <= 90f64.to_radians()) {
            return Err(Error::invalid(format!(
                "max_theta {} rad ({} degrees) must be in (0, pi/2]",
                self.max_theta,
                self.max_theta.to_degrees()
            )));
        }
        let t = &self.tolerances;
        if !(t.rel.is_finite() && t.rel > 0.0) {
            return Err(Error::invalid(format!("tolerances.rel {} must be finite and positive", t.rel)));
        }
        if t.max_iter == 0 {
            return Err(Error::invalid("tolerances.max_iter must be at least 1"));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::invalid(format!("tolerance {} must be finite and positive (an NDF error, 0.05 = 5%)", self.tolerance)));
        }
        Ok(())
    }
}
