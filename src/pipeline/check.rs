//! Range checks of the options a user types, shared by the CLI and the Python binding so both refuse the
//! same values with the same message. Each message names the option as the caller spells it
//! ([`Spelling`]): `--max-theta` on the command line, `max_theta` as a Python keyword.

use crate::error::{Error, Result};
use crate::fit::objective::DEFAULT_MAX_THETA_DEG;
use crate::fit::options::MAX_EXTRA_STARTS;
use crate::ndf::grid::MAX_CELLS_ACROSS;
use crate::ndf::{NdfOptions, NormalScheme, DEFAULT_TARGET_COUNT};

/// How an option's name appears in a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Spelling {
    /// A command-line flag: `max_theta` is `--max-theta`.
    Flag,
    /// A keyword argument: `max_theta` as it is.
    Keyword,
}

impl Spelling {
    /// `field` (snake_case) as this spelling writes it.
    pub fn name(self, field: &str) -> String {
        match self {
            Spelling::Flag => format!("--{}", field.replace('_', "-")),
            Spelling::Keyword => field.to_string(),
        }
    }
}

/// The fit region's largest polar angle (degrees) from `max_theta` (degrees, (0, 90]) and the numerical
/// aperture `na` ((0, 1], max_theta = asin(NA)); both given must agree to 1e-6 degrees. Neither: the
/// default, [`DEFAULT_MAX_THETA_DEG`].
pub fn aperture_deg(max_theta: Option<f64>, na: Option<f64>, s: Spelling) -> Result<f64> {
    let (t_name, na_name) = (s.name("max_theta"), s.name("na"));
    if let Some(t) = max_theta {
        if !(t > 0.0 && t <= 90.0) {
            return Err(Error::invalid(format!("{t_name} {t} must be in (0, 90] degrees")));
        }
    }
    let from_na = match na {
        Some(a) if !(a > 0.0 && a <= 1.0) => return Err(Error::invalid(format!("{na_name} {a} must be in (0, 1]"))),
        Some(a) => Some(a.asin().to_degrees()),
        None => None,
    };
    match (max_theta, from_na) {
        (Some(t), Some(n)) if (t - n).abs() > 1e-6 => {
            Err(Error::invalid(format!("{t_name} {t} and {na_name} disagree: the aperture sets max_theta = asin(NA) = {n:.6} degrees")))
        }
        (Some(t), _) => Ok(t),
        (None, Some(n)) => Ok(n),
        (None, None) => Ok(DEFAULT_MAX_THETA_DEG),
    }
}

/// The NDF options of a normal scheme, an optional odd grid size (3 to [`MAX_CELLS_ACROSS`]) and the
/// mean samples per bin (at least 1; default [`DEFAULT_TARGET_COUNT`]).
pub fn ndf_options(scheme: NormalScheme, cells_across: Option<usize>, target_count: Option<f64>, s: Spelling) -> Result<NdfOptions> {
    if let Some(c) = cells_across {
        let name = s.name("ndf_cells");
        if !(3..=MAX_CELLS_ACROSS).contains(&c) {
            return Err(Error::invalid(format!("{name} {c} must be between 3 and {MAX_CELLS_ACROSS}")));
        }
        if c % 2 == 0 {
            return Err(Error::invalid(format!("{name} {c} must be odd (the grid has a centre cell): use {} or {}", c - 1, c + 1)));
        }
    }
    let target_count = target_count.unwrap_or(DEFAULT_TARGET_COUNT);
    if !(target_count.is_finite() && target_count >= 1.0) {
        return Err(Error::invalid(format!("{} {target_count} must be at least 1", s.name("target_count"))));
    }
    Ok(NdfOptions { scheme, cells_across, target_count, frame: None, resolution: None })
}

/// The tolerance on the NDF error beyond counting noise: positive and finite; none is the default,
/// [`crate::fit::verdict::DEFAULT_TOLERANCE`].
pub fn tolerance(t: Option<f64>, s: Spelling) -> Result<f64> {
    match t {
        None => Ok(crate::fit::verdict::DEFAULT_TOLERANCE),
        Some(t) if t.is_finite() && t > 0.0 => Ok(t),
        Some(t) => Err(Error::invalid(format!("{} {t} must be a positive number (an NDF error, 0.05 = 5%)", s.name("tolerance")))),
    }
}

/// The render choice of `auto` from `scene` (`none`, or the specs of
/// [`crate::answer::choice::parse_scenes`]), `render_tolerance` (a positive mean FLIP) and `material`
/// (the conductor of the renders); `None` for `scene = "none"`.
pub fn render(scene: &str, render_tolerance: f64, material: &str, s: Spelling) -> Result<Option<crate::answer::choice::RenderOptions>> {
    use crate::answer::choice::{parse_scenes, RenderOptions};
    if scene.trim() == "none" {
        return Ok(None);
    }
    let scenes = parse_scenes(scene).map_err(|e| Error::invalid(format!("{}: {}", s.name("scene"), e.message())))?;
    let material = parse("material", material, s)?;
    if !(render_tolerance.is_finite() && render_tolerance > 0.0) {
        return Err(Error::invalid(format!("{} {render_tolerance} must be a positive number (a mean FLIP)", s.name("render_tolerance"))));
    }
    Ok(Some(RenderOptions { scenes, tolerance: render_tolerance, material }))
}

/// Extra ellipsoid starts beyond the default two: 0 to [`MAX_EXTRA_STARTS`].
pub fn extra_starts(n: usize, s: Spelling) -> Result<usize> {
    if n > MAX_EXTRA_STARTS {
        return Err(Error::invalid(format!("{} {n} must be between 0 and {MAX_EXTRA_STARTS}", s.name("extra_starts"))));
    }
    Ok(n)
}

/// `value` parsed as `T`, an error naming the option: `--form: unknown form "x": ...`.
pub fn parse<T: std::str::FromStr<Err = Error>>(field: &str, value: &str, s: Spelling) -> Result<T> {
    value.parse::<T>().map_err(|e| Error::invalid(format!("{}: {}", s.name(field), e.message())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_spelling() {
        let e = aperture_deg(Some(95.0), None, Spelling::Flag).unwrap_err();
        assert_eq!(e.message(), "--max-theta 95 must be in (0, 90] degrees");
        let e = aperture_deg(Some(30.0), Some(0.7), Spelling::Keyword).unwrap_err();
        assert!(e.message().starts_with("max_theta 30 and na disagree"), "{}", e.message());
        let e = ndf_options(NormalScheme::Central, Some(4), None, Spelling::Flag).unwrap_err();
        assert!(e.message().starts_with("--ndf-cells 4 must be odd"), "{}", e.message());
    }

    #[test]
    fn aperture_is_asin_na() {
        // NA 0.5 is a 30-degree cone: asin(1/2) = pi/6 exactly.
        assert!((aperture_deg(None, Some(0.5), Spelling::Flag).unwrap() - 30.0).abs() < 1e-12);
        assert_eq!(aperture_deg(Some(30.0), Some(0.5), Spelling::Flag).unwrap(), 30.0);
        assert_eq!(aperture_deg(None, None, Spelling::Flag).unwrap(), DEFAULT_MAX_THETA_DEG);
    }
}
