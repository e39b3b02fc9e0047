//! The options raw formats need (CONTRACT.md: `--dx METRES`, `--dy` defaulting to `dx`,
//! `--z-scale METRES_PER_UNIT`), with messages that say what is missing.

use crate::error::{Error, ErrorKind, Result};
use crate::io::ReadOptions;

/// Spacing (dx, dy) in metres from the options, or an error naming the format and the flag.
pub fn spacing(opts: &ReadOptions, format: &str) -> Result<(f64, f64)> {
    let dx = opts.dx.ok_or_else(|| {
        Error::new(ErrorKind::MissingOption, format!("{format} files carry no lateral spacing: give --dx METRES (and --dy if it differs)"))
    })?;
    let dy = opts.dy.unwrap_or(dx);
    check_positive(dx, "--dx")?;
    check_positive(dy, "--dy")?;
    Ok((dx, dy))
}

/// Metres per stored height unit from the options, or an error naming the format and the flag.
pub fn z_scale(opts: &ReadOptions, format: &str) -> Result<f64> {
    let s = opts.z_scale.ok_or_else(|| {
        Error::new(ErrorKind::MissingOption, format!("{format} files carry no height unit: give --z-scale METRES_PER_UNIT"))
    })?;
    if !(s.is_finite() && s != 0.0) {
        return Err(Error::invalid(format!("--z-scale must be finite and non-zero, got {s}")));
    }
    Ok(s)
}

/// Refuse a given `--dx` or `--dy` that is not a finite positive length, whatever the format (one that
/// carries its own spacing ignores them, but a negative or zero spacing is a mistake to report, not to
/// pass over in silence).
pub fn check_given_spacing(opts: &ReadOptions) -> Result<()> {
    if let Some(dx) = opts.dx {
        check_positive(dx, "--dx")?;
    }
    if let Some(dy) = opts.dy {
        check_positive(dy, "--dy")?;
    }
    Ok(())
}

fn check_positive(v: f64, flag: &str) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(format!("{flag} must be a finite positive length in metres, got {v}")))
    }
}
