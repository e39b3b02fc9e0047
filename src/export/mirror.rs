//! Renderer export of a mirror answer (`selection.answer` `mirror` or `mirror+ggx`, with the `optics` block
//! of `ndfit.fit/1`): the material `f = s(theta_i, lambda) f_mirror + (1 - s(theta_i, lambda)) f_haze`, both
//! with the conductor's Fresnel, `s` the mirror share (`optics.specular`), `f_haze` the haze lobe
//! (`optics.haze`); `mirror` alone is `s = 1`. The ladder's `model` / `params` are not this answer.
//!
//! No renderer's blend follows the wavelength, and only Blender's follows the angle. The share is taken in
//! the form of Gaussian heights, `s = exp(-b cos^2 theta)` (`b = (2 k sigma)^2`, `k = 2 pi / lambda`, the
//! Debye-Waller factor of Kirchhoff scattering), fitted at 550 nm ([`ShareForm`]). Blender's Mix Shader
//! builds that form from the view angle; Mitsuba's `blendbsdf`, pbrt-v4's `MixMaterial` and MaterialX's
//! `mix` hold a constant, its cosine-weighted hemispherical mean ([`ShareForm::mean_haze`]): the constant
//! that splits the light reflected under uniform illumination between mirror and haze as the form does.
//! Each export reports how far its blend is from the listed shares over 0-75 degrees, at every wavelength.
//!
//! Per renderer (the haze as [`super::export`] writes a single lobe; the mirror its smooth conductor, with
//! the same Fresnel as the haze's, the renderer's conductor default, as the lobe exports):
//! - Mitsuba 3: `conductor`; with haze a `blendbsdf`, `weight` the haze's share (0 the `conductor`, 1 the
//!   haze's `roughconductor`);
//! - pbrt-v4: `conductor` at roughness 0; with haze `MixMaterial` of it and the haze's `conductor`, `amount`
//!   (the probability of the second) the haze's share;
//! - Blender: a white Glossy BSDF at Roughness 0; with haze a Mix Shader, Fac `1 - exp(-b cos^2 theta)`
//!   (export/blender.rs);
//! - MaterialX: `conductor_bsdf` at roughness 0; with haze a BSDF `mix` (`bg` the mirror, `fg` the haze).
//!   MaterialX 1.39's `viewdirection` belongs to the optional NPR library and is defined for camera rays
//!   only, so `mix` is the constant;
//! - OpenPBR: `open_pbr_surface` with `base_metalness` 1 and `specular_roughness` 0; with haze a `mix` of two
//!   such surfaces (one OpenPBR surface has one specular lobe), `mix` the constant.

use serde_json::{json, Map, Value};

use super::{export, Export, Target};
use crate::error::{Error, Result};
use crate::models::Model;

/// The wavelength (nm) at which the share's form is fitted: the middle of the visible band.
pub const SHARE_WAVELENGTH_NM: f64 = 550.0;
/// Smallest share whose logarithm enters the form's fit: below it a share is at the incoherent floor of the
/// wave computation's patches (docs/WAVE.md) and its logarithm is noise.
const SHARE_FLOOR: f64 = 0.01;
/// The incidences (deg) over which a blend is compared with the shares: those the contract lists.
const COMPARED_UP_TO_DEG: f64 = 75.0;

/// One listed mirror share: the part of the light reflected as a mirror at an incidence and wavelength
/// (Fresnel excluded).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
pub struct Share {
    /// Incidence (degrees from the normal).
    pub theta_deg: f64,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// The mirror share `s`, in `[0, 1]`.
    pub weight: f64,
}

/// A mirror answer read from a fit's JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorAnswer {
    /// `selection.answer` (`mirror`, `mirror+ggx`).
    pub answer: String,
    /// `optics.specular`.
    pub specular: Vec<Share>,
    /// `optics.haze`, the lobe that takes `1 - s` (`None` for a mirror alone).
    pub haze: Option<Model>,
}

impl MirrorAnswer {
    /// The mirror answer of a fit's JSON, `None` when `selection.answer` has no `mirror` in it (then the fit
    /// is exported as its model).
    pub fn from_json(v: &Value) -> Result<Option<MirrorAnswer>> {
        let Some(answer) = v.pointer("/selection/answer").and_then(Value::as_str).filter(|a| a.contains("mirror")) else {
            return Ok(None);
        };
        let optics = v.get("optics");
        let haze = match (answer, optics.and_then(|o| o.get("haze"))) {
            ("mirror", _) => None,
            (_, Some(h)) => Some(Model::from_json(h).map_err(|e| Error::invalid(format!("optics.haze: {}", e.message())))?),
            (_, None) => return Err(Error::invalid(format!("the answer {answer} has a haze lobe, but optics.haze is missing"))),
        };
        let specular = match optics.and_then(|o| o.get("specular")) {
            Some(s) => serde_json::from_value::<Vec<Share>>(s.clone())
                .map_err(|e| Error::invalid(format!("optics.specular: {e}")))?
                .into_iter()
                .enumerate()
                .map(|(i, s)| checked(s).map_err(|why| Error::invalid(format!("optics.specular[{i}]: {why}"))))
                .collect::<Result<Vec<Share>>>()?,
            None => Vec::new(),
        };
        // A haze lobe takes 1 - s: without shares there is no split to write.
        if haze.is_some() && specular.is_empty() {
            return Err(Error::invalid(format!("the answer {answer} blends a mirror and a haze lobe, but optics.specular is missing")));
        }
        Ok(Some(MirrorAnswer { answer: answer.to_string(), specular, haze }))
    }
}

/// `s` if it is a share at a real incidence and wavelength; rounding may lift a flat patch's share a hair
/// above 1, which is taken as 1.
fn checked(s: Share) -> std::result::Result<Share, String> {
    if !(s.theta_deg >= 0.0 && s.theta_deg < 90.0) {
        return Err(format!("theta_deg {} is not an incidence in [0, 90)", s.theta_deg));
    }
    if !(s.wavelength_nm > 0.0 && s.wavelength_nm.is_finite()) {
        return Err(format!("wavelength_nm {} is not a wavelength", s.wavelength_nm));
    }
    if !(s.weight >= 0.0 && s.weight <= 1.0 + 1e-6) {
        return Err(format!("weight {} is not a share in [0, 1]", s.weight));
    }
    Ok(Share { weight: s.weight.min(1.0), ..s })
}

/// The mirror share's form `s(theta) = exp(-b cos^2 theta)` at one wavelength.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShareForm {
    /// The listed wavelength it was fitted at (nm): the one nearest [`SHARE_WAVELENGTH_NM`].
    pub wavelength_nm: f64,
    /// `b`; `(2 k sigma)^2` for Gaussian heights of RMS `sigma`.
    pub b: f64,
    /// How many listed incidences the fit used (those with `s >= 0.01`).
    pub used: usize,
}

impl ShareForm {
    /// Least squares on `ln s = -b cos^2 theta` over the incidences listed at the wavelength nearest
    /// `wavelength_nm` where `s >= 0.01`: `b = sum x y / sum x^2`, `x = cos^2 theta`, `y = -ln s`.
    pub fn fit(specular: &[Share], wavelength_nm: f64) -> Result<ShareForm> {
        let lambda = specular
            .iter()
            .map(|s| s.wavelength_nm)
            .min_by(|a, b| (a - wavelength_nm).abs().total_cmp(&(b - wavelength_nm).abs()))
            .ok_or_else(|| Error::invalid("optics.specular lists no share"))?;
        let used: Vec<(f64, f64)> = specular
            .iter()
            .filter(|s| s.wavelength_nm == lambda && s.weight >= SHARE_FLOOR)
            .map(|s| (s.theta_deg.to_radians().cos().powi(2), -s.weight.ln()))
            .collect();
        // No share above the floor: the mirror is too faint to give its form.
        if used.is_empty() {
            return Err(Error::invalid(format!(
                "every mirror share at {lambda} nm is below {SHARE_FLOOR}: no mirror to blend with the haze"
            )));
        }
        let sxy: f64 = used.iter().map(|(x, y)| x * y).sum();
        let sxx: f64 = used.iter().map(|(x, _)| x * x).sum();
        Ok(ShareForm { wavelength_nm: lambda, b: sxy / sxx, used: used.len() })
    }

    /// `s(theta) = exp(-b cos^2 theta)`.
    pub fn share(&self, theta_deg: f64) -> f64 {
        (-self.b * theta_deg.to_radians().cos().powi(2)).exp()
    }

    /// The cosine-weighted hemispherical mean of the haze share `1 - s`:
    /// `int_0^1 (1 - exp(-b mu^2)) 2 mu dmu = 1 - (1 - exp(-b)) / b` (0 at `b = 0`, its limit).
    pub fn mean_haze(&self) -> f64 {
        if self.b <= 0.0 {
            return 0.0;
        }
        1.0 + (-self.b).exp_m1() / self.b
    }
}

/// The largest distance of a blend from the listed shares at one wavelength.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Gap {
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// `max |s_blend(theta) - s(theta)|` over the listed incidences up to 75 degrees.
    pub max_abs: f64,
}

/// The largest `|mirror(theta) - s|` over the listed incidences up to 75 degrees, per listed wavelength
/// (ascending). `mirror` is the mirror share the renderer's blend gives.
fn gaps(specular: &[Share], mirror: impl Fn(f64) -> f64) -> Vec<Gap> {
    let mut lambdas: Vec<f64> = specular.iter().map(|s| s.wavelength_nm).collect();
    lambdas.sort_by(f64::total_cmp);
    lambdas.dedup();
    lambdas
        .into_iter()
        .map(|l| Gap {
            wavelength_nm: l,
            max_abs: specular
                .iter()
                .filter(|s| s.wavelength_nm == l && s.theta_deg <= COMPARED_UP_TO_DEG)
                .map(|s| (mirror(s.theta_deg) - s.weight).abs())
                .fold(0.0, f64::max),
        })
        .collect()
}

/// `0.2681 at 450 nm, ...`.
fn gaps_text(gaps: &[Gap]) -> String {
    gaps.iter().map(|g| format!("{:.4} at {} nm", g.max_abs, g.wavelength_nm)).collect::<Vec<_>>().join(", ")
}

/// One mirror export.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorExport {
    /// The renderer.
    pub target: Target,
    /// The answer's id (`mirror`, `mirror+ggx`).
    pub answer: String,
    /// The haze lobe's export (`None` for a mirror alone).
    pub haze: Option<Export>,
    /// The share's form (`None` for a mirror alone).
    pub form: Option<ShareForm>,
    /// The constant haze share the renderer's blend holds, `form.mean_haze()`; `None` for Blender (its Fac
    /// follows the angle) and for a mirror alone.
    pub weight: Option<f64>,
    /// How far the blend's mirror share is from the listed ones, per wavelength: the constant's
    /// `|weight - (1 - s)|`, or Blender's `|exp(-b cos^2) - s|`.
    pub gaps: Vec<Gap>,
}

/// Export a mirror answer to `target` (module docs); `max_theta_deg` as for [`super::export`] (the haze lobe's
/// region should it need approximating).
pub fn export_mirror(answer: &MirrorAnswer, target: Target, max_theta_deg: f64) -> Result<MirrorExport> {
    let mut out = MirrorExport { target, answer: answer.answer.clone(), haze: None, form: None, weight: None, gaps: Vec::new() };
    let Some(haze) = &answer.haze else { return Ok(out) };
    let form = ShareForm::fit(&answer.specular, SHARE_WAVELENGTH_NM)?;
    out.haze = Some(export(haze, target, max_theta_deg)?);
    out.form = Some(form);
    if target == Target::Blender {
        out.gaps = gaps(&answer.specular, |t| form.share(t));
    } else {
        let w = form.mean_haze();
        out.weight = Some(w);
        out.gaps = gaps(&answer.specular, |_| 1.0 - w);
    }
    Ok(out)
}

impl MirrorExport {
    /// What the user must know (stderr and `note`): the haze lobe's approximation, and what the blend
    /// approximates and how far.
    pub fn notes(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(n) = self.haze.as_ref().and_then(|h| h.note.as_ref()) {
            out.push(format!("haze: {n}"));
        }
        let Some(form) = &self.form else { return out };
        let fitted = format!(
            "s(theta) = exp(-b cos^2 theta), b = {:.6}, fitted at {} nm (least squares on ln s over the {} listed incidences with s >= {SHARE_FLOOR}; the form of Gaussian heights)",
            form.b, form.wavelength_nm, form.used
        );
        out.push(match self.weight {
            Some(w) => format!(
                "{}: {}'s blend weight cannot follow the incidence{} or the wavelength: wrote the haze share {w:.6}, the cosine-weighted hemispherical mean of 1 - s with {fitted}; it differs from the listed 1 - s by at most {} over 0-75 deg",
                self.answer,
                self.target.as_str(),
                match self.target {
                    Target::MaterialX | Target::OpenPbr => " (MaterialX's viewdirection is an optional NPR-library node, defined for camera rays only)",
                    _ => "",
                },
                gaps_text(&self.gaps)
            ),
            None => format!(
                "{}: the Mix Shader's Fac follows the view angle as 1 - s, {fitted}; the wavelength dependence is collapsed to {} nm: the form differs from the listed shares by at most {} over 0-75 deg",
                self.answer,
                form.wavelength_nm,
                gaps_text(&self.gaps)
            ),
        });
        out
    }

    /// `--json`: `answer`; for a mirror alone the renderer's mirror keys; with haze the blend (`blend`, and
    /// `weight`, `weight_of`, `weight_error` for a constant or `fac`, `fac_error` for Blender's angle), the
    /// share's form (`mirror_share`), both BSDFs' keys under `bsdfs` (mirror first), the haze's
    /// `tangent_angle`, and `note`.
    pub fn to_json(&self) -> Value {
        let mut m = Map::new();
        m.insert("answer".into(), Value::from(self.answer.clone()));
        let mirror = mirror_keys(self.target);
        let (Some(haze), Some(form)) = (&self.haze, &self.form) else {
            m.extend(mirror);
            return Value::Object(m);
        };
        let (blend, name) = match self.target {
            Target::Mitsuba => ("blendbsdf", "weight"),
            Target::Pbrt => ("MixMaterial", "amount"),
            Target::Blender => ("ShaderNodeMixShader", "Fac"),
            Target::OpenPbr | Target::MaterialX => ("mix", "mix"),
        };
        m.insert("blend".into(), Value::from(blend));
        match self.weight {
            Some(w) => {
                m.insert("weight".into(), Value::from(w));
                m.insert(
                    "weight_of".into(),
                    Value::from(format!("{name} = the second (haze) BSDF's share, the cosine-weighted hemispherical mean of 1 - s; the first (mirror) has 1 - {name}")),
                );
                m.insert("weight_error".into(), json!(self.gaps));
            }
            None => {
                m.insert(
                    "fac".into(),
                    Value::from(
                        "1 - exp(-b cos^2 theta), theta the view's angle to the normal; Fac 0 the first (mirror) BSDF, 1 the second (haze)",
                    ),
                );
                m.insert("fac_error".into(), json!(self.gaps));
            }
        }
        m.insert(
            "mirror_share".into(),
            json!({"form": "exp(-b cos^2 theta)", "b": form.b, "wavelength_nm": form.wavelength_nm, "incidences_used": form.used}),
        );
        m.insert("bsdfs".into(), json!([Value::Object(mirror), haze.to_json()]));
        m.insert("tangent_angle".into(), Value::from(haze.lobe.tangent_angle));
        m.insert("note".into(), Value::from(self.notes().join("; ")));
        Value::Object(m)
    }
}

/// The renderer's keys of its smooth conductor (the contract's keys, at roughness 0).
fn mirror_keys(target: Target) -> Map<String, Value> {
    let v = match target {
        Target::Mitsuba => json!({"plugin": "conductor"}),
        Target::Pbrt => json!({"uroughness": 0.0, "vroughness": 0.0, "remaproughness": false, "tangent_angle": 0.0}),
        Target::Blender => json!({
            "node": "glossy", "distribution": "ggx", "roughness": 0.0, "anisotropic": 0.0, "anisotropic_rotation": 0.0,
            "inputs": {"Roughness": 0.0, "Anisotropy": 0.0, "Rotation": 0.0}
        }),
        Target::OpenPbr => json!({"specular_roughness": 0.0, "specular_roughness_anisotropy": 0.0, "tangent_angle": 0.0}),
        Target::MaterialX => json!({"roughness": [0.0, 0.0], "tangent_angle": 0.0}),
    };
    match v {
        Value::Object(m) => m,
        _ => Map::new(),
    }
}
