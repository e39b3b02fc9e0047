//! Renderer export of a two-lobe mixture ([`crate::models::mixture`]): a weighted blend of two of the
//! renderer's own lobes, `f = (1 - t) f_core + t f_tail` with `t = 1 - weight`, the TAIL's share (the
//! fit's `weight` is the core's):
//! - Mitsuba 3 `blendbsdf`: `weight` is `t` (0 gives the first, nested BSDF alone, 1 the second);
//! - pbrt-v4 `MixMaterial`: `amount` is `t` (the probability of choosing the second material);
//! - Blender Mix Shader: `Fac` is `t` (0 gives the upper Shader input, 1 the lower), in one script that
//!   builds both lobes (export/blender.rs);
//! - OpenPBR and MaterialX: a `mix` node with `mix = t` (`fg` the tail, `bg` the core).
//!
//! Each lobe is exported as a single model ([`super::export`], so a lobe the renderer cannot hold is
//! approximated and said so). The blend is exact in D (the renderer mixes `D` linearly through the BSDFs)
//! but each renderer lobe masks with its own Smith G, where the mixture's exact Smith `Lambda` is the
//! weighted mean of the lobes' (models/mixture.rs); the difference is only at grazing angles.
//! `ggx2` and `beckmann2` share one tangent frame: the tail is written in the core's tangent frame
//! (`alpha_u`, `alpha_v` swapped when its canonical axes are the core's turned by 90 degrees).

use serde_json::{json, Map, Value};

use super::{export, Export, Target};
use crate::error::{Error, Result};
use crate::models::{Lobe, Mixture, Model};

/// One mixture export: the core and tail lobes and the tail's share.
#[derive(Debug, Clone, PartialEq)]
pub struct MixtureExport {
    /// The renderer.
    pub target: Target,
    /// The core (the fit's first, narrower lobe).
    pub core: Export,
    /// The tail.
    pub tail: Export,
    /// The tail's share `t = 1 - weight` (the renderer's blend weight, module docs).
    pub tail_weight: f64,
}

fn lobe_model(l: &Lobe) -> Model {
    match *l {
        Lobe::Ggx(g) if g.alpha_x == g.alpha_y => Model::Ggx(g),
        Lobe::Ggx(g) => Model::GgxAniso(g),
        Lobe::Beckmann(b) if b.alpha_x == b.alpha_y => Model::Beckmann(b),
        Lobe::Beckmann(b) => Model::BeckmannAniso(b),
        Lobe::Ellipsoid(e) => Model::Ellipsoid(e),
    }
}

/// Export a mixture to `target` (module docs); `max_theta_deg` as for [`export`].
pub fn export_mixture(x: &Mixture, target: Target, max_theta_deg: f64) -> Result<MixtureExport> {
    let x = x.canonical();
    let core = export(&lobe_model(&x.lobe1), target, max_theta_deg)?;
    let mut tail = export(&lobe_model(&x.lobe2), target, max_theta_deg)?;
    // One tangent per surface where the renderer has no per-lobe rotation (Mitsuba, pbrt, MaterialX):
    // the tail in the core's frame.
    let d = crate::models::canonical::fold_half_turn(tail.lobe.tangent_angle - core.lobe.tangent_angle);
    let round = (tail.lobe.alpha_u - tail.lobe.alpha_v).abs() <= 1e-12 * tail.lobe.alpha_u;
    if round || d.abs() <= 1e-9 {
        tail.lobe.tangent_angle = core.lobe.tangent_angle;
    } else if (d.abs() - 0.5 * std::f64::consts::PI).abs() <= 1e-9 {
        tail.lobe.tangent_angle = core.lobe.tangent_angle;
        (tail.lobe.alpha_u, tail.lobe.alpha_v) = (tail.lobe.alpha_v, tail.lobe.alpha_u);
    } else if matches!(target, Target::Mitsuba | Target::Pbrt | Target::MaterialX) {
        return Err(Error::invalid(format!(
            "{}: the lobes' axes differ by {d:.4} rad, and {} blends two lobes in one tangent frame",
            Model::Mixture(x).id(),
            target.as_str()
        )));
    }
    Ok(MixtureExport { target, core, tail, tail_weight: 1.0 - x.weight })
}

impl MixtureExport {
    /// `--json`: the blend (`blend`, `weight` = the tail's share, `weight_of` naming it), the two lobes'
    /// own keys under `bsdfs` (core first), the core's `tangent_angle`, and the notes of either lobe.
    pub fn to_json(&self) -> Value {
        let (blend, weight_name) = match self.target {
            Target::Mitsuba => ("blendbsdf", "weight"),
            Target::Pbrt => ("MixMaterial", "amount"),
            Target::Blender => ("ShaderNodeMixShader", "Fac"),
            Target::OpenPbr | Target::MaterialX => ("mix", "mix"),
        };
        let mut m = Map::new();
        m.insert("blend".into(), Value::from(blend));
        m.insert("weight".into(), Value::from(self.tail_weight));
        m.insert(
            "weight_of".into(),
            Value::from(format!("{weight_name} = the second (tail) lobe's share; the first (core) lobe has 1 - {weight_name}")),
        );
        m.insert("bsdfs".into(), json!([self.core.to_json(), self.tail.to_json()]));
        m.insert("tangent_angle".into(), Value::from(self.core.lobe.tangent_angle));
        let notes: Vec<String> =
            [("core", &self.core), ("tail", &self.tail)].iter().filter_map(|(n, e)| e.note.as_ref().map(|t| format!("{n}: {t}"))).collect();
        if !notes.is_empty() {
            m.insert("note".into(), Value::from(notes.join("; ")));
        }
        Value::Object(m)
    }

    /// The snippet: for Mitsuba a `blendbsdf` with the two `roughconductor`s nested; for Blender one script
    /// that builds both lobes and the Mix Shader; for the others both lobes' snippets under a header that
    /// says how to blend them.
    pub fn snippet(&self, source: &str) -> String {
        let t = self.tail_weight;
        match self.target {
            Target::Blender => self.blender_script(source),
            Target::Mitsuba => {
                let inner = |e: &Export| {
                    let s = e.snippet(source);
                    let body = &s[s.find("<bsdf").unwrap_or(0)..];
                    body.lines().map(|l| format!("    {l}")).collect::<Vec<_>>().join("\n")
                };
                format!(
                    "<!-- ndfit export of {source} (two lobes) to mitsuba: blendbsdf weight = the tail's share {t};\n     \
                     put the tangent (u) axis at azimuth {:.6} rad from the scan's +x towards +y. -->\n\
                     <bsdf type=\"blendbsdf\">\n    <float name=\"weight\" value=\"{t}\"/>\n{}\n{}\n</bsdf>\n",
                    self.core.lobe.tangent_angle,
                    inner(&self.core),
                    inner(&self.tail)
                )
            }
            _ => {
                let how = match self.target {
                    Target::Pbrt => format!("MakeNamedMaterial \"core\" and \"tail\" from these, then Material \"mix\" \"string materials\" [ \"core\" \"tail\" ] \"float amount\" [ {t} ]"),
                    _ => format!("mix the two surface shaders with a <mix> node, mix = {t} (fg = tail, bg = core)"),
                };
                format!("two lobes: {how}\n\n--- core ---\n{}\n--- tail ---\n{}", self.core.snippet(source), self.tail.snippet(source))
            }
        }
    }

    /// One Blender script: the core and tail lobes, a Mix Shader with Fac = the tail's share (the core is
    /// its first Shader input, taken at Fac 0), into the Material Output.
    fn blender_script(&self, source: &str) -> String {
        let mut head = format!("ndfit export of {source} (two lobes) to blender: Mix Shader Fac = the tail's share {}", self.tail_weight);
        for (name, e) in [("core", &self.core), ("tail", &self.tail)] {
            if let Some(n) = &e.note {
                head.push_str(&format!("\n{name}: {n}"));
            }
        }
        let mut s = super::blender::Script::new(&head, &super::blender::about(&[&self.core.lobe, &self.tail.lobe]));
        s.lobe("core", &self.core.lobe);
        s.lobe("tail", &self.tail.lobe);
        s.mix("core", "tail");
        s.fac(self.tail_weight);
        s.finish("mix")
    }
}
