//! The footprints a scene implies (data_formats/scale.md sec. 8).
//!
//! A pixel subtends `2 tan(fov/2) / pixels` radians across an image `pixels` wide with full field of view
//! `fov`, so at distance `d` its footprint on a surface facing the camera is `F = d * 2 tan(fov/2) / pixels`;
//! with a sensor of pixel pitch `p` behind a lens of focal length `f`, `F = d * p / f`. At incidence `theta`
//! the footprint stretches to `F / cos(theta)` along one axis.

use crate::error::{Error, Result};

/// A closed range of footprints (metres), `lo <= hi`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FootprintRange {
    /// Smallest footprint.
    pub lo: f64,
    /// Largest footprint.
    pub hi: f64,
}

impl FootprintRange {
    /// `n` log-spaced footprints from `lo` to `hi` (one when `lo == hi` or `n == 1`).
    pub fn log_spaced(&self, n: usize) -> Vec<f64> {
        if n <= 1 || self.hi <= self.lo {
            return vec![self.lo];
        }
        let (a, b) = (self.lo.ln(), self.hi.ln());
        (0..n).map(|k| (a + (b - a) * k as f64 / (n - 1) as f64).exp()).collect()
    }
}

/// Parse a `lo..hi` range or a single value.
fn parse_range(key: &str, v: &str) -> Result<(f64, f64)> {
    let num =
        |t: &str| -> Result<f64> { t.trim().parse::<f64>().map_err(|_| Error::invalid(format!("scene: {key}='{t}' is not a number"))) };
    let (lo, hi) = match v.split_once("..") {
        Some((a, b)) => (num(a)?, num(b)?),
        None => {
            let x = num(v)?;
            (x, x)
        }
    };
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo) {
        return Err(Error::invalid(format!("scene: {key} must be positive with lo <= hi, got {v}")));
    }
    Ok((lo, hi))
}

/// The footprint range of a scene description: comma-separated `key=value` with `footprint=LO..HI`, or
/// `distance=LO..HI` with either `fov_deg=` and `pixels=`, or `pixel_pitch=` and `focal=`; optional
/// `max_incidence_deg=`.
pub fn parse_scene(spec: &str) -> Result<FootprintRange> {
    let mut kv = std::collections::BTreeMap::new();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (k, v) = part.split_once('=').ok_or_else(|| Error::invalid(format!("scene: '{part}' is not key=value")))?;
        let k = k.trim();
        const KEYS: [&str; 7] = ["footprint", "distance", "fov_deg", "pixels", "pixel_pitch", "focal", "max_incidence_deg"];
        if !KEYS.contains(&k) {
            return Err(Error::invalid(format!("scene: unknown key '{k}' (expected one of {})", KEYS.join(", "))));
        }
        if kv.insert(k.to_string(), v.trim().to_string()).is_some() {
            return Err(Error::invalid(format!("scene: key '{k}' given twice")));
        }
    }
    let get = |k: &str| kv.get(k).map(|v| parse_range(k, v)).transpose();
    let (lo, hi) = if let Some(f) = get("footprint")? {
        if kv.contains_key("distance") {
            return Err(Error::invalid("scene: give footprint= or distance=, not both"));
        }
        f
    } else {
        let (d0, d1) = get("distance")?.ok_or_else(|| Error::invalid("scene: needs footprint= or distance="))?;
        let angle = match (get("fov_deg")?, get("pixels")?, get("pixel_pitch")?, get("focal")?) {
            (Some((fov, fov2)), Some((px, px2)), None, None) if fov == fov2 && px == px2 => {
                if fov >= 180.0 {
                    return Err(Error::invalid(format!("scene: fov_deg must be below 180, got {fov}")));
                }
                2.0 * (0.5 * fov.to_radians()).tan() / px
            }
            (None, None, Some((p, p2)), Some((f, f2))) if p == p2 && f == f2 => p / f,
            _ => {
                return Err(Error::invalid(
                    "scene: with distance= give either fov_deg= and pixels= or pixel_pitch= and focal= (single values)",
                ))
            }
        };
        (d0 * angle, d1 * angle)
    };
    let stretch = match get("max_incidence_deg")? {
        Some((t, _)) if t < 90.0 => 1.0 / t.to_radians().cos(),
        Some((t, _)) => return Err(Error::invalid(format!("scene: max_incidence_deg must be below 90, got {t}"))),
        None => 1.0,
    };
    Ok(FootprintRange { lo, hi: hi * stretch })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_geometry() {
        // 90 degree fov, 1000 px: a pixel subtends 2 tan(45 deg)/1000 = 2 mrad; at 0.5 m that is 1 mm.
        let r = parse_scene("distance=0.5, fov_deg=90, pixels=1000").unwrap();
        assert!((r.lo - 1e-3).abs() < 1e-15 && (r.hi - 1e-3).abs() < 1e-15);
        // 4 um pitch, 50 mm lens, 0.2..2 m: 16 um .. 160 um.
        let r = parse_scene("distance=0.2..2,pixel_pitch=4e-6,focal=0.05").unwrap();
        assert!((r.lo - 1.6e-5).abs() < 1e-18 && (r.hi - 1.6e-4).abs() < 1e-17);
        // Incidence 60 degrees doubles the far end.
        let r = parse_scene("footprint=1e-5..1e-4,max_incidence_deg=60").unwrap();
        assert!((r.hi - 2e-4).abs() < 1e-15 && r.lo == 1e-5);
        let f = r.log_spaced(3);
        assert!((f[1] - (1e-5f64 * 2e-4).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn bad_scenes() {
        for s in [
            "",
            "distance=1",
            "footprint=-1",
            "footprint=2..1",
            "fov_deg=40",
            "distance=1,fov_deg=200,pixels=10",
            "footprint=1e-5,footprint=2e-5",
            "color=red",
            "footprint=abc",
            "distance=1,fov_deg=40,pixels=100,focal=0.05",
        ] {
            assert!(parse_scene(s).is_err(), "{s}");
        }
    }
}
