//! Blender scripts: one Python script per export that builds the whole node material for Cycles (Blender 4.x
//! and 5.0 `bpy`): the lobes' BSDF nodes, a Mix Shader where there are two, the UV map's tangent, the
//! Material Output. Node and socket names are Blender's own (`source/blender/nodes/shader/nodes/`):
//! - `ShaderNodeBsdfPrincipled` (a GGX lobe): "Base Color", "Metallic", "Roughness", "Anisotropic",
//!   "Anisotropic Rotation", "Tangent"; `distribution` `GGX`, the single-scattering lobe that was fitted
//!   (Blender's default `MULTI_GGX` adds the energy of further bounces);
//! - `ShaderNodeBsdfGlossy` (a Beckmann lobe; the mirror at Roughness 0, which Cycles reflects as a delta
//!   because `alpha_x alpha_y <= 1e-7`): "Color", "Roughness", "Anisotropy", "Rotation", "Tangent";
//!   `distribution` `BECKMANN` or `GGX`. Blender 4.0 merged the Anisotropic BSDF into it (idname
//!   `ShaderNodeBsdfAnisotropic`) and keeps `ShaderNodeBsdfGlossy` as its alias for `nodes.new`;
//! - `ShaderNodeMixShader`: "Fac", then two inputs both named "Shader", taken by index: 1 at Fac 0, 2 at Fac 1;
//! - `ShaderNodeLayerWeight` output "Facing" = `1 - |cos|` of the view and the normal at its Blend 0.5
//!   exactly (Cycles `svm_node_layer_weight` raises `|cos|` to a power only for another Blend);
//!   `ShaderNodeMath` (`SUBTRACT`, `MULTIPLY`, `EXPONENT`; inputs by index, output "Value");
//! - `ShaderNodeTangent` (`direction_type` `UV_MAP`, output "Tangent"); `ShaderNodeOutputMaterial` "Surface".
//!
//! Every lobe is white: F = 1 (the Glossy BSDF's Color scales it; the Principled BSDF's metallic Fresnel,
//! F82-tint from Base Color and Specular Tint, is 1 when both are), as Mitsuba's conductor default and
//! `--to rgl --material none`: the export is the NDF, the metal's color is the user's.

use std::fmt::Display;

use super::{glossy_params, Distribution, Export, RendererLobe, Target};

/// A Blender script under construction: Python lines that create nodes and link them.
pub(crate) struct Script {
    text: String,
}

impl Script {
    /// The header (`head` and `about`, as comments), the material, its Material Output and the UV tangent.
    pub(crate) fn new(head: &str, about: &[String]) -> Script {
        let mut s = Script { text: String::new() };
        for l in head.lines().chain(about.iter().flat_map(|a| a.lines())) {
            s.line(format!("# {l}"));
        }
        for l in [
            "import bpy",
            "",
            "mat = bpy.data.materials.new(\"ndfit\")",
            "mat.use_nodes = True",
            "nodes, links = mat.node_tree.nodes, mat.node_tree.links",
            "nodes.clear()",
            "output = nodes.new(\"ShaderNodeOutputMaterial\")",
            "tangent = nodes.new(\"ShaderNodeTangent\")",
            "tangent.direction_type = \"UV_MAP\"",
        ] {
            s.line(l);
        }
        s
    }

    fn line(&mut self, l: impl AsRef<str>) {
        self.text.push_str(l.as_ref());
        self.text.push('\n');
    }

    /// `var = nodes.new(idname)`.
    fn node(&mut self, var: &str, idname: &str) {
        self.line(format!("{var} = nodes.new(\"{idname}\")"));
    }

    /// `var.inputs[socket].default_value = value`; `socket` is a quoted name or an index.
    fn set(&mut self, var: &str, socket: &str, value: impl Display) {
        self.line(format!("{var}.inputs[{socket}].default_value = {value}"));
    }

    /// `set` of a number, written as a Python float literal.
    fn set_number(&mut self, var: &str, socket: &str, x: f64) {
        self.set(var, socket, py(x));
    }

    /// `links.new(from, to)`, both socket expressions.
    fn link(&mut self, from: &str, to: &str) {
        self.line(format!("links.new({from}, {to})"));
    }

    /// The BSDF node `var` of a renderer lobe: a Principled BSDF for GGX, a Glossy BSDF for Beckmann, both
    /// white and fed the UV tangent.
    pub(crate) fn lobe(&mut self, var: &str, lobe: &RendererLobe) {
        let (au, av, t) = (lobe.alpha_u, lobe.alpha_v, lobe.tangent_angle);
        match lobe.distribution {
            Distribution::Ggx => {
                let p = super::blender_params(au, av, t);
                self.node(var, "ShaderNodeBsdfPrincipled");
                self.line(format!("{var}.distribution = \"GGX\""));
                self.set(var, "\"Base Color\"", "(1.0, 1.0, 1.0, 1.0)");
                self.set(var, "\"Metallic\"", "1.0");
                self.set_number(var, "\"Roughness\"", p[0]);
                self.set_number(var, "\"Anisotropic\"", p[1]);
                self.set_number(var, "\"Anisotropic Rotation\"", p[2]);
            }
            Distribution::Beckmann => {
                let g = glossy_params(au, av, t);
                self.glossy(var, "BECKMANN", g);
            }
        }
        self.link("tangent.outputs[\"Tangent\"]", &format!("{var}.inputs[\"Tangent\"]"));
    }

    /// The mirror `var`: a white Glossy BSDF at Roughness 0 (module doc: a delta reflection in Cycles).
    pub(crate) fn mirror(&mut self, var: &str) {
        self.glossy(var, "GGX", [0.0; 3]);
    }

    fn glossy(&mut self, var: &str, distribution: &str, inputs: [f64; 3]) {
        self.node(var, "ShaderNodeBsdfGlossy");
        self.line(format!("{var}.distribution = \"{distribution}\""));
        self.set(var, "\"Color\"", "(1.0, 1.0, 1.0, 1.0)");
        self.set_number(var, "\"Roughness\"", inputs[0]);
        self.set_number(var, "\"Anisotropy\"", inputs[1]);
        self.set_number(var, "\"Rotation\"", inputs[2]);
    }

    /// A Mix Shader `mix` of `first` (taken at Fac 0) and `second` (at Fac 1).
    pub(crate) fn mix(&mut self, first: &str, second: &str) {
        self.node("mix", "ShaderNodeMixShader");
        self.link(&format!("{first}.outputs[\"BSDF\"]"), "mix.inputs[1]");
        self.link(&format!("{second}.outputs[\"BSDF\"]"), "mix.inputs[2]");
    }

    /// The Mix Shader's Fac, a constant.
    pub(crate) fn fac(&mut self, t: f64) {
        self.set_number("mix", "\"Fac\"", t);
    }

    /// The Mix Shader's Fac `1 - exp(-b cos^2 theta)`, `cos theta = 1 - Facing` of a Layer Weight at Blend 0.5.
    pub(crate) fn fac_of_angle(&mut self, b: f64) {
        self.node("facing", "ShaderNodeLayerWeight");
        self.set("facing", "\"Blend\"", "0.5");
        self.math("cos_t", "SUBTRACT", ["1.0", "facing.outputs[\"Facing\"]"]);
        self.math("cos2_t", "MULTIPLY", ["cos_t.outputs[\"Value\"]", "cos_t.outputs[\"Value\"]"]);
        self.math("exponent", "MULTIPLY", ["cos2_t.outputs[\"Value\"]", &py(-b)]);
        self.math("share", "EXPONENT", ["exponent.outputs[\"Value\"]"]);
        self.math("fac", "SUBTRACT", ["1.0", "share.outputs[\"Value\"]"]);
        self.link("fac.outputs[\"Value\"]", "mix.inputs[\"Fac\"]");
    }

    /// A Math node `var` of `operation` whose inputs are, in order, sockets (`...outputs[...]`) or values.
    fn math<const N: usize>(&mut self, var: &str, operation: &str, inputs: [&str; N]) {
        self.node(var, "ShaderNodeMath");
        self.line(format!("{var}.operation = \"{operation}\""));
        for (i, x) in inputs.iter().enumerate() {
            if x.contains(".outputs[") {
                self.link(x, &format!("{var}.inputs[{i}]"));
            } else {
                self.set(var, &i.to_string(), x);
            }
        }
    }

    /// The script, with `shader`'s output (`BSDF` of a lobe, `Shader` of the mix) into the Material Output.
    pub(crate) fn finish(mut self, shader: &str) -> String {
        let out = if shader == "mix" { "Shader" } else { "BSDF" };
        self.link(&format!("{shader}.outputs[\"{out}\"]"), "output.inputs[\"Surface\"]");
        self.text
    }
}

/// `x` as a Python float literal (Rust's `Debug` form: `0.0`, `0.25`, `1e-7`).
fn py(x: f64) -> String {
    format!("{x:?}")
}

/// What the script's nodes mean, for its header: the map of each kind of lobe node present, and where the
/// tangent comes from.
pub(crate) fn about(lobes: &[&RendererLobe]) -> Vec<String> {
    let mut out = Vec::new();
    if lobes.iter().any(|l| l.distribution == Distribution::Ggx) {
        out.push(
            "Principled BSDF (GGX, single scattering): alpha_x = Roughness^2 / sqrt(1 - 0.9 Anisotropic) along the Tangent,\n\
             alpha_y = Roughness^2 sqrt(1 - 0.9 Anisotropic), the Tangent turned about the normal by Anisotropic Rotation turns."
                .to_string(),
        );
    }
    if lobes.iter().any(|l| l.distribution == Distribution::Beckmann) {
        out.push(
            "Glossy BSDF (Beckmann): alpha_x = Roughness^2 / (1 + Anisotropy) along the Tangent (Anisotropy <= 0),\n\
             alpha_y = Roughness^2 (1 + Anisotropy), the Tangent turned about the normal by Rotation turns."
                .to_string(),
        );
    }
    out.push(
        "The Tangent is the UV map's U direction: lay the UV map with the scan's +x along U. Every BSDF is white\n\
         (F = 1): put the metal's color in Base Color / Color. Assign `mat` to the object."
            .to_string(),
    );
    out
}

impl Export {
    /// The Blender script of one lobe under the header `head`.
    pub(crate) fn blender_script(&self, head: &str) -> String {
        debug_assert_eq!(self.target, Target::Blender);
        let mut s = Script::new(head, &about(&[&self.lobe]));
        s.lobe("bsdf", &self.lobe);
        s.finish("bsdf")
    }
}
