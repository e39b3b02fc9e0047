//! The export as text in each renderer's own syntax: Mitsuba 3 scene XML, pbrt-v4 scene text, Blender
//! Python (export/blender.rs), and MaterialX 1.39 documents for OpenPBR Surface and `conductor_bsdf`.

use std::fmt::Write;

use super::{Export, Target};

impl Export {
    /// The snippet for the renderer; `source` names the fit file in its header comment.
    pub fn snippet(&self, source: &str) -> String {
        let p = self.lobe.params(self.target);
        let num = |k: &str| p.get(k).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
        let t = self.lobe.tangent_angle;
        let (tc, ts) = (t.cos(), t.sin());
        let mut head = format!("ndfit export of {source} to {}", self.target.as_str());
        if let Some(n) = &self.note {
            let _ = write!(head, "\n{n}");
        }
        let tangent = format!(
            "tangent (u) axis at azimuth {t:.6} rad from the scan's +x towards +y, i.e. along ({tc:.6}, {ts:.6}, 0) in the scan frame"
        );
        match self.target {
            Target::Mitsuba => format!(
                "<!-- {}\n     alpha_u lies along the shading frame's s axis (dp/du): put the {tangent}. -->\n\
                 <bsdf type=\"roughconductor\">\n    <string name=\"distribution\" value=\"{}\"/>\n    \
                 <float name=\"alpha_u\" value=\"{}\"/>\n    <float name=\"alpha_v\" value=\"{}\"/>\n</bsdf>\n",
                xml_comment(&head),
                self.lobe.distribution.as_str(),
                num("alpha_u"),
                num("alpha_v")
            ),
            Target::Pbrt => format!(
                "{}\n# uroughness lies along dpdu: put the {tangent}.\nMaterial \"conductor\"\n    \"float uroughness\" [ {} ]\n    \
                 \"float vroughness\" [ {} ]\n    \"bool remaproughness\" false\n",
                comment(&head, "# "),
                num("uroughness"),
                num("vroughness")
            ),
            Target::Blender => self.blender_script(&head),
            Target::OpenPbr => format!(
                "<?xml version=\"1.0\"?>\n<!-- {} -->\n<materialx version=\"1.39\">\n  \
                 <!-- alpha_t lies along geometry_tangent: the {tangent}. -->\n{}  \
                 <open_pbr_surface name=\"ndfit_surface\" type=\"surfaceshader\">\n    \
                 <input name=\"geometry_tangent\" type=\"vector3\" nodename=\"ndfit_tangent\"/>\n    \
                 <input name=\"base_metalness\" type=\"float\" value=\"1.0\"/>\n    \
                 <input name=\"specular_roughness\" type=\"float\" value=\"{}\"/>\n    \
                 <input name=\"specular_roughness_anisotropy\" type=\"float\" value=\"{}\"/>\n  </open_pbr_surface>\n  \
                 <surfacematerial name=\"ndfit\" type=\"material\">\n    \
                 <input name=\"surfaceshader\" type=\"surfaceshader\" nodename=\"ndfit_surface\"/>\n  </surfacematerial>\n</materialx>\n",
                xml_comment(&head),
                tangent_nodes(t),
                num("specular_roughness"),
                num("specular_roughness_anisotropy")
            ),
            Target::MaterialX => {
                let r = [self.lobe.alpha_u, self.lobe.alpha_v];
                format!(
                    "<?xml version=\"1.0\"?>\n<!-- {} -->\n<materialx version=\"1.39\">\n  \
                     <!-- roughness = (alpha_x, alpha_y), alpha_x along the tangent input: the {tangent}. -->\n{}  \
                     <conductor_bsdf name=\"ndfit_conductor\" type=\"BSDF\">\n    \
                     <input name=\"roughness\" type=\"vector2\" value=\"{}, {}\"/>\n    \
                     <input name=\"tangent\" type=\"vector3\" nodename=\"ndfit_tangent\"/>\n  </conductor_bsdf>\n  \
                     <surface name=\"ndfit_surface\" type=\"surfaceshader\">\n    \
                     <input name=\"bsdf\" type=\"BSDF\" nodename=\"ndfit_conductor\"/>\n  </surface>\n  \
                     <surfacematerial name=\"ndfit\" type=\"material\">\n    \
                     <input name=\"surfaceshader\" type=\"surfaceshader\" nodename=\"ndfit_surface\"/>\n  </surfacematerial>\n</materialx>\n",
                    xml_comment(&head),
                    tangent_nodes(t),
                    r[0],
                    r[1]
                )
            }
        }
    }
}

/// MaterialX nodes whose output `ndfit_tangent` is the surface's world tangent (the scan's `+x`) turned
/// counter-clockwise about the normal by `t` radians. `rotate3d` computes
/// `v cos(a) + (v x axis) sin(a) + axis (axis.v) (1 - cos(a))`, a clockwise turn for a positive amount
/// (its GLSL and OSL sources), so the amount is `-t` in degrees.
pub(super) fn tangent_nodes(t: f64) -> String {
    format!(
        "  <tangent name=\"ndfit_surface_tangent\" type=\"vector3\">\n    <input name=\"space\" type=\"string\" value=\"world\"/>\n  </tangent>\n  \
         <normal name=\"ndfit_surface_normal\" type=\"vector3\">\n    <input name=\"space\" type=\"string\" value=\"world\"/>\n  </normal>\n  \
         <rotate3d name=\"ndfit_tangent\" type=\"vector3\">\n    <input name=\"in\" type=\"vector3\" nodename=\"ndfit_surface_tangent\"/>\n    \
         <input name=\"amount\" type=\"float\" value=\"{}\"/>\n    <input name=\"axis\" type=\"vector3\" nodename=\"ndfit_surface_normal\"/>\n  </rotate3d>\n",
        -t.to_degrees()
    )
}

/// Every line of `text` behind `prefix`.
pub(super) fn comment(text: &str, prefix: &str) -> String {
    text.lines().map(|l| format!("{prefix}{l}")).collect::<Vec<_>>().join("\n")
}

/// Text safe inside an XML comment (no `--`).
pub(super) fn xml_comment(text: &str) -> String {
    text.replace("--", "- -")
}
