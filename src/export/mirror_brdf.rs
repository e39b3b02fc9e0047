//! A mirror and what it scatters as ndfit's renderer draws them ([`crate::render::Brdf`]): the mirror is
//! the conductor's smooth part, `s F(theta_i)` toward the mirror direction, with the share
//! `s(theta_i, lambda)` read from listed shares at each of the renderer's RGB wavelengths (linear in the
//! wavelength and in the incidence between the listed ones, held beyond them). Beside it:
//! - a mirror answer ([`super::MirrorAnswer`]): `f = s f_mirror + (1 - s) f_haze`, the haze lobe with the
//!   same conductor ([`MirrorBrdf::new`]);
//! - the wave prediction itself (`ndfit wave SCAN --to rgl`): the mirror share of its `mirror_share` field
//!   and the diffuse wave BRDF its table holds, as it is ([`MirrorBrdf::wave`]): what light sees of a
//!   polished scan, the reference a mirror answer is held to.

use nalgebra::Vector3;

use super::mirror::{MirrorAnswer, Share};
use super::rgl::{AnalyticBrdf, Material, Measured, TensorFile, RGB_NM};
use crate::error::{Error, ErrorKind, Result};
use crate::render::Brdf;

/// What scatters beside the mirror.
enum Diffuse {
    /// Nothing: a mirror alone.
    None,
    /// A haze lobe that takes `1 - s` of the light.
    Haze(Box<AnalyticBrdf>),
    /// The diffuse wave BRDF's table, as it is (it holds its own energy).
    Wave(Box<Measured>),
    /// A table written for a blend (`ndfit wave --to rgl --with-mirror`), at its weight `w`.
    Blend(Box<Measured>, f64),
    /// The wave prediction joined by incidence with the geometric table: `g(theta_i)` of the wave's diffuse
    /// table and mirror, `1 - g` of the geometric table.
    Joined { wave: Box<Measured>, geometric: Box<Measured>, ramp: [f64; 2] },
}

/// A mirror with its diffuse part for the renderer: `s F` toward the mirror direction, and a haze lobe
/// taking `1 - s`, a wave table as it is, or a wave table joined with a geometric one by incidence.
pub struct MirrorBrdf {
    /// Per RGB channel, `(theta_deg, s)` by incidence.
    shares: [Vec<(f64, f64)>; 3],
    /// What scatters beside the mirror.
    diffuse: Diffuse,
    /// The conductor of the mirror (and of a haze lobe).
    material: Material,
}

impl MirrorBrdf {
    /// `answer` with the conductor `material`; `mirror` alone is `s = 1`.
    pub fn new(answer: &MirrorAnswer, material: Material) -> MirrorBrdf {
        let haze = answer.haze.map(|model| AnalyticBrdf { model, material });
        let shares =
            RGB_NM.map(
                |nm| if haze.is_none() || answer.specular.is_empty() { vec![(0.0, 1.0)] } else { at_wavelength(&answer.specular, nm) },
            );
        MirrorBrdf { shares, diffuse: haze.map_or(Diffuse::None, |h| Diffuse::Haze(Box::new(h))), material }
    }

    /// The reference of a scan whose regime changes with the angle: its wave prediction (`wave`, as
    /// [`MirrorBrdf::wave`]) and its geometric table (`geometric`, `ndfit export SCAN --to rgl`) joined by
    /// incidence. Per channel the wave's weight is `g = clamp((s - lo) / (hi - lo), 0, 1)` of the wave's own
    /// mirror share `s(theta_i)`, `[lo, hi] = ramp` (the regime's thresholds: geometric below `lo`, a mirror
    /// from `hi`): `f = g (s F delta + f_wave) + (1 - g) f_geometric`, continuous in the angle.
    pub fn joined(wave: &TensorFile, geometric: &TensorFile, material: Material, ramp: [f64; 2]) -> Result<MirrorBrdf> {
        let MirrorBrdf { shares, diffuse, .. } = MirrorBrdf::wave(wave, material)?;
        let Diffuse::Wave(w) = diffuse else {
            return Err(Error::invalid("a table written for a blend with the mirror (--with-mirror) is not the wave prediction"));
        };
        if !(ramp[0] < ramp[1]) {
            return Err(Error::invalid(format!("the join's ramp {ramp:?} must rise")));
        }
        let geometric = Box::new(Measured::new(geometric)?);
        Ok(MirrorBrdf { shares, diffuse: Diffuse::Joined { wave: w, geometric, ramp }, material })
    }

    /// The wave's weight per channel at `wi` (1 unless joined).
    fn wave_weight(&self, wi: Vector3<f64>) -> [f64; 3] {
        match self.diffuse {
            Diffuse::Joined { ramp: [lo, hi], .. } => self.shares_at(wi).map(|s| ((s - lo) / (hi - lo)).clamp(0.0, 1.0)),
            _ => [1.0; 3],
        }
    }

    /// `answer` with the mirror share `share(theta_deg)` at every wavelength instead of its listed shares:
    /// what a renderer's blend draws when its weight is a constant (`share` constant) or follows the angle
    /// alone (Blender's Fac).
    pub fn with_share(answer: &MirrorAnswer, share: &dyn Fn(f64) -> f64, material: Material) -> MirrorBrdf {
        let mut b = MirrorBrdf::new(answer, material);
        let curve: Vec<(f64, f64)> = (0..=90).map(|t| (t as f64, share(t as f64).clamp(0.0, 1.0))).collect();
        b.shares = [curve.clone(), curve.clone(), curve];
        b
    }

    /// The wave prediction of an `ndfit wave --to rgl` table `t`: its diffuse table and, as a mirror of
    /// the conductor `material` (the table's), the shares of its `mirror_share` field (`[wavelengths,
    /// theta_i]`). A table without that field is refused. A table written for a blend (its `blend_weight`
    /// field `w`, `--with-mirror`) is drawn as the renderers' blends draw it: `1 - w` of the mirror at every
    /// angle and wavelength, `w` of the table.
    pub fn wave(t: &TensorFile, material: Material) -> Result<MirrorBrdf> {
        let bad = |m: &str| Error::new(ErrorKind::Corrupt, format!("not a wave table: {m}"));
        let values = |name: &str| t.field(name).and_then(|f| f.as_f32()).ok_or_else(|| bad(&format!("no {name} field")));
        let (share, nm, theta) = (values("mirror_share")?, values("wavelengths")?, values("theta_i")?);
        if share.len() != nm.len() * theta.len() || share.is_empty() {
            return Err(bad(&format!(
                "mirror_share holds {} values for {} wavelengths x {} incidences",
                share.len(),
                nm.len(),
                theta.len()
            )));
        }
        let specular: Vec<Share> = share
            .iter()
            .enumerate()
            .map(|(k, &w)| Share {
                theta_deg: (theta[k % theta.len()] as f64).to_degrees(),
                wavelength_nm: nm[k / theta.len()] as f64,
                weight: (w as f64).clamp(0.0, 1.0),
            })
            .collect();
        let table = Box::new(Measured::new(t)?);
        if let Some(w) = t.field("blend_weight").and_then(|f| f.as_f32()).and_then(|v| v.first().copied()) {
            let w = w as f64;
            if !(w > 0.0 && w <= 1.0) {
                return Err(bad(&format!("blend_weight {w} is not in (0, 1]")));
            }
            return Ok(MirrorBrdf { shares: RGB_NM.map(|_| vec![(0.0, 1.0 - w)]), diffuse: Diffuse::Blend(table, w), material });
        }
        Ok(MirrorBrdf { shares: RGB_NM.map(|nm| at_wavelength(&specular, nm)), diffuse: Diffuse::Wave(table), material })
    }

    /// The mirror share of channel `c` at incidence `theta_deg`.
    pub fn share(&self, c: usize, theta_deg: f64) -> f64 {
        interpolate(&self.shares[c], theta_deg)
    }

    /// `s` per channel at the direction `wi` (local frame).
    fn shares_at(&self, wi: Vector3<f64>) -> [f64; 3] {
        let theta = wi.z.clamp(-1.0, 1.0).acos().to_degrees();
        [0, 1, 2].map(|c| self.share(c, theta))
    }
}

/// `(theta_deg, s)` at wavelength `nm`: per listed incidence, `s` linear in the wavelength between the
/// listed ones (held beyond them).
fn at_wavelength(specular: &[Share], nm: f64) -> Vec<(f64, f64)> {
    let mut thetas: Vec<f64> = specular.iter().map(|s| s.theta_deg).collect();
    thetas.sort_by(f64::total_cmp);
    thetas.dedup();
    thetas
        .into_iter()
        .map(|t| {
            let mut by_nm: Vec<(f64, f64)> = specular.iter().filter(|s| s.theta_deg == t).map(|s| (s.wavelength_nm, s.weight)).collect();
            by_nm.sort_by(|a, b| a.0.total_cmp(&b.0));
            (t, interpolate(&by_nm, nm))
        })
        .collect()
}

/// The piecewise-linear function through `points` (sorted by `x`) at `x`, held beyond the ends.
fn interpolate(points: &[(f64, f64)], x: f64) -> f64 {
    match points {
        [] => 1.0,
        [(_, y)] => *y,
        _ => {
            let k = points.partition_point(|p| p.0 <= x);
            if k == 0 {
                points[0].1
            } else if k == points.len() {
                points[k - 1].1
            } else {
                let ((x0, y0), (x1, y1)) = (points[k - 1], points[k]);
                y0 + (y1 - y0) * (x - x0) / (x1 - x0)
            }
        }
    }
}

impl Brdf for MirrorBrdf {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        match &self.diffuse {
            Diffuse::None => [0.0; 3],
            Diffuse::Haze(haze) => {
                let (s, f) = (self.shares_at(wi), haze.eval(wi, wo));
                [0, 1, 2].map(|c| (1.0 - s[c]) * f[c])
            }
            Diffuse::Wave(table) => table.eval(wi, wo),
            Diffuse::Blend(table, w) => table.eval(wi, wo).map(|v| v * w),
            Diffuse::Joined { wave, geometric, .. } => {
                let (g, w, t) = (self.wave_weight(wi), wave.eval(wi, wo), geometric.eval(wi, wo));
                [0, 1, 2].map(|c| g[c] * w[c] + (1.0 - g[c]) * t[c])
            }
        }
    }

    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], out: &mut [[f64; 3]]) {
        match &self.diffuse {
            Diffuse::None => out.iter_mut().for_each(|o| *o = [0.0; 3]),
            Diffuse::Haze(haze) => {
                haze.eval_many(wi, wos, out);
                let s = self.shares_at(wi);
                out.iter_mut().for_each(|o| (0..3).for_each(|c| o[c] *= 1.0 - s[c]));
            }
            Diffuse::Wave(table) => table.eval_many(wi, wos, out),
            Diffuse::Blend(table, w) => {
                table.eval_many(wi, wos, out);
                out.iter_mut().for_each(|o| o.iter_mut().for_each(|v| *v *= w));
            }
            Diffuse::Joined { .. } => out.iter_mut().zip(wos).for_each(|(o, &wo)| *o = self.eval(wi, wo)),
        }
    }

    fn mirror(&self, wi: Vector3<f64>) -> [f64; 3] {
        // Reflection only.
        if wi.z <= 0.0 {
            return [0.0; 3];
        }
        let (s, f, g) = (self.shares_at(wi), self.material.fresnel_rgb(wi.z), self.wave_weight(wi));
        [0, 1, 2].map(|c| g[c] * s[c] * f[c])
    }
}

#[cfg(test)]
mod tests {
    use super::super::mirror::Share;
    use super::*;
    use crate::models::{Model, ModelId};

    fn answer(haze: bool) -> MirrorAnswer {
        let specular = [450.0, 550.0, 650.0]
            .iter()
            .flat_map(|&nm| {
                [0.0, 30.0, 60.0].map(|t: f64| Share { theta_deg: t, wavelength_nm: nm, weight: 0.5 + t / 200.0 + (nm - 550.0) / 1000.0 })
            })
            .collect();
        let haze = haze.then(|| Model::from_params(ModelId::Ggx, &[0.1]).unwrap());
        MirrorAnswer { answer: if haze.is_some() { "mirror+ggx" } else { "mirror" }.into(), specular, haze }
    }

    /// The shares are read linearly between the listed incidences and wavelengths and held beyond them;
    /// `mirror` alone reflects all as a mirror; the haze takes the rest of the light.
    #[test]
    fn shares_and_parts() {
        let b = MirrorBrdf::new(&answer(true), Material::None);
        // Green (549 nm) at 45 deg: halfway between 30 and 60 deg, 1 nm below 550.
        let want = 0.5 + 45.0 / 200.0 - 1.0 / 1000.0;
        assert!((b.share(1, 45.0) - want).abs() < 1e-12, "{}", b.share(1, 45.0));
        assert!((b.share(0, 80.0) - (0.5 + 0.3 + 0.062)).abs() < 1e-12);
        let wi = Vector3::new(0.5f64.sqrt(), 0.0, 0.5f64.sqrt());
        let m = b.mirror(wi);
        assert!((m[1] - want).abs() < 1e-12, "F = 1 for material none: {m:?}");
        let wo = Vector3::new(-0.6, 0.0, 0.8);
        let haze = AnalyticBrdf { model: Model::from_params(ModelId::Ggx, &[0.1]).unwrap(), material: Material::None }.eval(wi, wo);
        assert!((b.eval(wi, wo)[1] - (1.0 - want) * haze[1]).abs() < 1e-12 * haze[1]);
        let mut many = [[0.0; 3]; 1];
        b.eval_many(wi, &[wo], &mut many);
        assert_eq!(many[0], b.eval(wi, wo));
        let alone = MirrorBrdf::new(&answer(false), Material::None);
        assert_eq!((alone.mirror(wi), alone.eval(wi, wo)), ([1.0; 3], [0.0; 3]));
    }
}
