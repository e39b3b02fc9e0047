//! A mirror export as text in each renderer's own syntax (export/mirror.rs for what each writes and why):
//! Mitsuba 3 scene XML, pbrt-v4 scene text, a Blender script, MaterialX 1.39 documents.

use super::blender::{about, Script};
use super::mirror::MirrorExport;
use super::snippet::{comment, tangent_nodes, xml_comment};
use super::{Export, Target};

impl MirrorExport {
    /// The snippet for the renderer; `source` names the fit file in its header comment.
    pub fn snippet(&self, source: &str) -> String {
        let mut head = format!("ndfit export of {source} ({}) to {}", self.answer, self.target.as_str());
        match &self.haze {
            None => head.push_str(": a smooth conductor (the mirror share is 1 at every incidence and wavelength)"),
            Some(h) => {
                // `+ 0.0` writes an isotropic haze's `-0` angle as 0.
                let t = h.lobe.tangent_angle + 0.0;
                head.push_str(&format!(
                    ": the mirror and the haze lobe, blended by the haze's share\n\
                     the haze's tangent (u) axis at azimuth {t:.6} rad from the scan's +x towards +y, i.e. along ({:.6}, {:.6}, 0) in the scan frame",
                    t.cos(),
                    t.sin()
                ));
            }
        }
        for n in self.notes() {
            head.push('\n');
            head.push_str(&n);
        }
        match self.target {
            Target::Mitsuba => self.mitsuba(&head, source),
            Target::Pbrt => self.pbrt(&head),
            Target::Blender => self.blender(&head),
            Target::OpenPbr => self.openpbr(&head),
            Target::MaterialX => self.materialx(&head),
        }
    }

    /// The haze's share the constant blends hold.
    fn weight(&self) -> f64 {
        self.weight.unwrap_or(0.0)
    }

    fn mitsuba(&self, head: &str, source: &str) -> String {
        let head = xml_comment(head);
        let Some(h) = &self.haze else { return format!("<!-- {head} -->\n<bsdf type=\"conductor\"/>\n") };
        let s = h.snippet(source);
        let haze = s[s.find("<bsdf").unwrap_or(0)..].lines().map(|l| format!("    {l}")).collect::<Vec<_>>().join("\n");
        format!(
            "<!-- {head}\n     blendbsdf weight = the haze's share: 0 the conductor (mirror) alone, 1 the roughconductor (haze) alone. -->\n\
             <bsdf type=\"blendbsdf\">\n    <float name=\"weight\" value=\"{}\"/>\n    <bsdf type=\"conductor\"/>\n{haze}\n</bsdf>\n",
            self.weight()
        )
    }

    fn pbrt(&self, head: &str) -> String {
        let conductor = |a: [f64; 2]| {
            format!("    \"float uroughness\" [ {} ]\n    \"float vroughness\" [ {} ]\n    \"bool remaproughness\" false\n", a[0], a[1])
        };
        let Some(h) = &self.haze else { return format!("{}\nMaterial \"conductor\"\n{}", comment(head, "# "), conductor([0.0; 2])) };
        format!(
            "{}\n# MixMaterial: amount = the probability of the second material, the haze.\n\
             MakeNamedMaterial \"ndfit_mirror\"\n    \"string type\" [ \"conductor\" ]\n{}\
             MakeNamedMaterial \"ndfit_haze\"\n    \"string type\" [ \"conductor\" ]\n{}\
             Material \"mix\"\n    \"string materials\" [ \"ndfit_mirror\" \"ndfit_haze\" ]\n    \"float amount\" [ {} ]\n",
            comment(head, "# "),
            conductor([0.0; 2]),
            conductor([h.lobe.alpha_u, h.lobe.alpha_v]),
            self.weight()
        )
    }

    fn blender(&self, head: &str) -> String {
        let Some(h) = &self.haze else {
            let mut s = Script::new(head, &about(&[]));
            s.mirror("mirror");
            return s.finish("mirror");
        };
        let mut s = Script::new(head, &about(&[&h.lobe]));
        s.mirror("mirror");
        s.lobe("haze", &h.lobe);
        s.mix("mirror", "haze");
        s.fac_of_angle(self.form.map_or(0.0, |f| f.b));
        s.finish("mix")
    }

    fn openpbr(&self, head: &str) -> String {
        let surface = |name: &str, e: Option<&Export>| {
            let (r, a, tangent) = match e {
                Some(e) => {
                    let (r, a) = super::openpbr_params(e.lobe.alpha_u, e.lobe.alpha_v);
                    (r, a, "    <input name=\"geometry_tangent\" type=\"vector3\" nodename=\"ndfit_tangent\"/>\n")
                }
                None => (0.0, 0.0, ""),
            };
            format!(
                "  <open_pbr_surface name=\"{name}\" type=\"surfaceshader\">\n{tangent}    \
                 <input name=\"base_metalness\" type=\"float\" value=\"1.0\"/>\n    \
                 <input name=\"specular_roughness\" type=\"float\" value=\"{r}\"/>\n    \
                 <input name=\"specular_roughness_anisotropy\" type=\"float\" value=\"{a}\"/>\n  </open_pbr_surface>\n"
            )
        };
        let body = match &self.haze {
            None => surface("ndfit_surface", None),
            Some(h) => format!(
                "{}{}{}{}",
                tangent_nodes(h.lobe.tangent_angle),
                surface("ndfit_mirror", None),
                surface("ndfit_haze", Some(h)),
                mix("ndfit_surface", "surfaceshader", self.weight())
            ),
        };
        document(head, &body, "ndfit_surface")
    }

    fn materialx(&self, head: &str) -> String {
        let conductor = |name: &str, a: [f64; 2], tangent: bool| {
            format!(
                "  <conductor_bsdf name=\"{name}\" type=\"BSDF\">\n    <input name=\"roughness\" type=\"vector2\" value=\"{}, {}\"/>\n{}  </conductor_bsdf>\n",
                a[0],
                a[1],
                if tangent { "    <input name=\"tangent\" type=\"vector3\" nodename=\"ndfit_tangent\"/>\n" } else { "" }
            )
        };
        let (nodes, bsdf) = match &self.haze {
            None => (conductor("ndfit_mirror", [0.0; 2], false), "ndfit_mirror"),
            Some(h) => (
                format!(
                    "{}{}{}{}",
                    tangent_nodes(h.lobe.tangent_angle),
                    conductor("ndfit_mirror", [0.0; 2], false),
                    conductor("ndfit_haze", [h.lobe.alpha_u, h.lobe.alpha_v], true),
                    mix("ndfit_mix", "BSDF", self.weight())
                ),
                "ndfit_mix",
            ),
        };
        let surface = format!(
            "{nodes}  <surface name=\"ndfit_surface\" type=\"surfaceshader\">\n    <input name=\"bsdf\" type=\"BSDF\" nodename=\"{bsdf}\"/>\n  </surface>\n"
        );
        document(head, &surface, "ndfit_surface")
    }
}

/// A MaterialX `mix` node `name` of `ndfit_mirror` (`bg`, taken at mix 0) and `ndfit_haze` (`fg`), `type`
/// `BSDF` or `surfaceshader`; the nodes of that type are named `ndfit_mirror` / `ndfit_haze` for both.
fn mix(name: &str, ty: &str, w: f64) -> String {
    format!(
        "  <mix name=\"{name}\" type=\"{ty}\">\n    <input name=\"fg\" type=\"{ty}\" nodename=\"ndfit_haze\"/>\n    \
         <input name=\"bg\" type=\"{ty}\" nodename=\"ndfit_mirror\"/>\n    <input name=\"mix\" type=\"float\" value=\"{w}\"/>\n  </mix>\n"
    )
}

/// A MaterialX 1.39 document of `nodes` and a material on the surface shader `surface`.
fn document(head: &str, nodes: &str, surface: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<!-- {} -->\n<materialx version=\"1.39\">\n{nodes}  \
         <surfacematerial name=\"ndfit\" type=\"material\">\n    \
         <input name=\"surfaceshader\" type=\"surfaceshader\" nodename=\"{surface}\"/>\n  </surfacematerial>\n</materialx>\n",
        xml_comment(head)
    )
}
