//! Blender scripts (`ndfit export --to blender`): each script is run by Python against a stand-in `bpy` that
//! knows Blender's node types, socket names and enum items (written here from Blender's sources:
//! `source/blender/nodes/shader/nodes/node_shader_*.cc`, the RNA enums) and refuses anything else; the
//! graph it builds is then read back: its nodes, their values and links, and the Mix Shader's Fac evaluated
//! through its Math nodes at given view angles (Layer Weight Facing = `1 - |cos|` at Blend 0.5, as Cycles'
//! `svm_node_layer_weight`).

use std::io::Write;
use std::process::{Command, Stdio};

use ndfit::export::{export, export_mixture, Target};
use ndfit::models::{Model, ModelId};
use serde_json::{json, Value};

/// The stand-in `bpy` and the dump of the graph the script on stdin builds (argv: view angles in degrees).
const MOCK_BPY: &str = r#"
import ast, json, math, sys, types

SOCKETS = {
    "ShaderNodeOutputMaterial": (["Surface", "Volume", "Displacement", "Thickness"], []),
    "ShaderNodeTangent": ([], ["Tangent"]),
    "ShaderNodeBsdfPrincipled": (["Base Color", "Metallic", "Roughness", "IOR", "Alpha", "Normal", "Weight",
        "Diffuse Roughness", "Subsurface Weight", "Subsurface Radius", "Subsurface Scale", "Subsurface IOR",
        "Subsurface Anisotropy", "Specular IOR Level", "Specular Tint", "Anisotropic", "Anisotropic Rotation",
        "Tangent", "Transmission Weight", "Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint", "Coat Normal",
        "Sheen Weight", "Sheen Roughness", "Sheen Tint", "Emission Color", "Emission Strength",
        "Thin Film Thickness", "Thin Film IOR"], ["BSDF"]),
    "ShaderNodeBsdfAnisotropic": (["Color", "Roughness", "Anisotropy", "Rotation", "Normal", "Tangent", "Weight"], ["BSDF"]),
    "ShaderNodeMixShader": (["Fac", "Shader", "Shader"], ["Shader"]),
    "ShaderNodeLayerWeight": (["Blend", "Normal"], ["Fresnel", "Facing"]),
    "ShaderNodeMath": (["Value", "Value", "Value"], ["Value"]),
}
ALIASES = {"ShaderNodeBsdfGlossy": "ShaderNodeBsdfAnisotropic"}
ENUMS = {
    ("ShaderNodeBsdfPrincipled", "distribution"): {"GGX", "MULTI_GGX"},
    ("ShaderNodeBsdfAnisotropic", "distribution"): {"BECKMANN", "GGX", "ASHIKHMIN_SHIRLEY", "MULTI_GGX"},
    ("ShaderNodeTangent", "direction_type"): {"RADIAL", "UV_MAP"},
    ("ShaderNodeMath", "operation"): {"ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM",
        "SQRT", "INVERSE_SQRT", "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM"},
}

class Socket:
    def __init__(self, node, name, index, output):
        self.node, self.name, self.index, self.is_output, self.default_value = node, name, index, output, None

class Sockets:
    def __init__(self, node, names, output):
        self.items = [Socket(node, n, i, output) for i, n in enumerate(names)]
    def __getitem__(self, key):
        if isinstance(key, int):
            return self.items[key]
        for s in self.items:
            if s.name == key:
                return s
        raise KeyError("%s has no socket %r" % (self.items[0].node.bl_idname if self.items else "node", key))

class Node:
    def __init__(self, idname):
        ins, outs = SOCKETS[idname]
        self.__dict__.update(bl_idname=idname, props={}, inputs=Sockets(self, ins, False), outputs=Sockets(self, outs, True))
    def __setattr__(self, key, value):
        allowed = ENUMS.get((self.bl_idname, key))
        if allowed is None:
            raise AttributeError("%s has no property %r" % (self.bl_idname, key))
        if value not in allowed:
            raise TypeError("%s.%s: %r is not one of %s" % (self.bl_idname, key, value, sorted(allowed)))
        self.props[key] = value

class Nodes(list):
    def new(self, idname):
        idname = ALIASES.get(idname, idname)
        if idname not in SOCKETS:
            raise RuntimeError("Node type %s undefined" % idname)
        self.append(Node(idname))
        return self[-1]
    def clear(self):
        del self[:]

class Links(list):
    def new(self, a, b):
        if not (a.is_output and not b.is_output):
            raise RuntimeError("a link goes from an output to an input")
        self.append((a, b))

class Material:
    def __init__(self, name):
        self.name, self.use_nodes = name, False
        self.node_tree = types.SimpleNamespace(nodes=Nodes(), links=Links())

class Materials(list):
    def new(self, name):
        self.append(Material(name))
        return self[-1]

bpy = types.ModuleType("bpy")
bpy.data = types.SimpleNamespace(materials=Materials())
sys.modules["bpy"] = bpy
script = sys.stdin.read()
ast.parse(script)
exec(compile(script, "ndfit_export.py", "exec"), {})
(mat,) = bpy.data.materials
tree = mat.node_tree
nodes = list(tree.nodes)

def source(sock):
    for a, b in tree.links:
        if b is sock:
            return a
    return None

def value(sock, cos):
    a = source(sock)
    if a is None:
        return sock.default_value
    n = a.node
    if n.bl_idname == "ShaderNodeLayerWeight":
        if a.name != "Facing" or n.inputs["Blend"].default_value != 0.5:
            raise RuntimeError("only Facing at Blend 0.5 is 1 - |cos|")
        return 1.0 - abs(cos)
    if n.bl_idname == "ShaderNodeMath":
        x = [value(n.inputs[i], cos) for i in range(3)]
        op = n.props["operation"]
        return {"SUBTRACT": lambda: x[0] - x[1], "MULTIPLY": lambda: x[0] * x[1], "ADD": lambda: x[0] + x[1],
                "EXPONENT": lambda: math.exp(x[0]), "POWER": lambda: x[0] ** x[1]}[op]()
    raise RuntimeError("cannot evaluate %s" % n.bl_idname)

def node_json(n):
    return {"idname": n.bl_idname, "props": n.props,
            "inputs": {s.name if s.name != "Shader" else str(s.index): s.default_value for s in n.inputs.items if s.default_value is not None}}

links = [[nodes.index(a.node), a.name, nodes.index(b.node), b.index] for a, b in tree.links]
fac = []
for n in nodes:
    if n.bl_idname == "ShaderNodeMixShader":
        fac = [[t, value(n.inputs["Fac"], math.cos(math.radians(float(t))))] for t in sys.argv[1:]]
print(json.dumps({"use_nodes": mat.use_nodes, "nodes": [node_json(n) for n in nodes], "links": links, "fac": fac}))
"#;

/// The graph `script` builds in the stand-in `bpy` (module doc), with the Mix Shader's Fac at `thetas`
/// (degrees); `None`, said on stderr, when there is no `python3` to run it.
pub fn run_blender_script(script: &str, thetas: &[f64]) -> Option<Graph> {
    let mut cmd = Command::new("python3");
    cmd.arg("-c").arg(MOCK_BPY).args(thetas.iter().map(|t| t.to_string()));
    let Ok(mut child) = cmd.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn() else {
        eprintln!("SKIP: no python3 to run the Blender script against the stand-in bpy");
        return None;
    };
    child.stdin.take().unwrap().write_all(script.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "the script fails in the stand-in bpy:\n{}\n{script}", String::from_utf8_lossy(&out.stderr));
    Some(Graph(serde_json::from_slice(&out.stdout).expect("the dump is JSON")))
}

/// A dumped graph: `nodes` (`idname`, `props`, `inputs` set), `links` (`[from, output name, to, input
/// index]`), `fac` (`[theta, Fac]`).
pub struct Graph(pub Value);

impl Graph {
    /// The nodes of an idname, by index.
    pub fn of(&self, idname: &str) -> Vec<usize> {
        let nodes = self.0["nodes"].as_array().unwrap();
        (0..nodes.len()).filter(|&i| nodes[i]["idname"] == json!(idname)).collect()
    }

    /// Node `i`.
    pub fn node(&self, i: usize) -> &Value {
        &self.0["nodes"][i]
    }

    /// The node linked into input `input` of node `to`.
    pub fn feeding(&self, to: usize, input: usize) -> Option<usize> {
        self.0["links"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l[2] == json!(to) && l[3] == json!(input))
            .map(|l| l[0].as_u64().unwrap() as usize)
    }

    /// The node whose output feeds the Material Output's Surface.
    pub fn surface(&self) -> usize {
        let out = self.of("ShaderNodeOutputMaterial");
        assert_eq!(out.len(), 1, "{}", self.0);
        self.feeding(out[0], 0).expect("Surface is linked")
    }

    /// Whether node `i`'s Tangent input comes from the UV map's tangent.
    pub fn tangent_from_uv(&self, i: usize, input: usize) -> bool {
        self.feeding(i, input).is_some_and(|t| {
            self.node(t)["idname"] == json!("ShaderNodeTangent") && self.node(t)["props"]["direction_type"] == json!("UV_MAP")
        })
    }
}

/// A lobe node's socket values against the export's keys: Principled inputs for GGX (single scattering,
/// metallic, white), Glossy inputs for Beckmann, both fed the UV tangent.
pub fn assert_lobe_node(g: &Graph, i: usize, keys: &Value) {
    let n = g.node(i);
    let near = |a: &Value, b: &Value| (a.as_f64().unwrap() - b.as_f64().unwrap()).abs() <= 1e-15;
    if keys["node"] == json!("glossy") {
        assert_eq!(n["idname"], json!("ShaderNodeBsdfAnisotropic"), "{n}");
        assert_eq!(n["props"]["distribution"], json!(keys["distribution"].as_str().unwrap().to_uppercase()), "{n}");
        assert_eq!(n["inputs"]["Color"], json!([1.0, 1.0, 1.0, 1.0]));
        for k in ["Roughness", "Anisotropy", "Rotation"] {
            assert!(near(&n["inputs"][k], &keys["inputs"][k]), "{k}: {n} vs {keys}");
        }
        assert!(g.tangent_from_uv(i, 5), "{}", g.0);
    } else {
        assert_eq!(n["idname"], json!("ShaderNodeBsdfPrincipled"), "{n}");
        assert_eq!(n["props"]["distribution"], json!("GGX"));
        assert_eq!((&n["inputs"]["Metallic"], &n["inputs"]["Base Color"]), (&json!(1.0), &json!([1.0, 1.0, 1.0, 1.0])));
        for (k, j) in [("Roughness", "roughness"), ("Anisotropic", "anisotropic"), ("Anisotropic Rotation", "anisotropic_rotation")] {
            assert!(near(&n["inputs"][k], &keys[j]), "{k}: {n} vs {keys}");
        }
        assert!(g.tangent_from_uv(i, 17), "{}", g.0);
    }
}

/// One lobe: its node (Principled for GGX, Glossy for Beckmann) carries the export's values and feeds the
/// Material Output directly.
#[test]
fn blender_script_builds_the_lobe() {
    for (id, p) in [(ModelId::GgxAniso, vec![0.4, 0.1, -1.043]), (ModelId::BeckmannAniso, vec![0.3, 0.012, 0.7])] {
        let e = export(&Model::from_params(id, &p).unwrap(), Target::Blender, 70.0).unwrap();
        let Some(g) = run_blender_script(&e.snippet("fit.json"), &[]) else { return };
        assert_lobe_node(&g, g.surface(), &e.to_json());
    }
}

/// A two-lobe fit is one script: both lobes, a Mix Shader with the core first (Fac 0) and the tail second,
/// Fac = the tail's share `1 - weight`, into the Material Output.
#[test]
fn mixture_is_one_blender_script() {
    for id in [ModelId::Ggx2, ModelId::Beckmann2] {
        let weight = 0.7;
        let fit = Model::from_params(id, &[0.1, 0.05, 0.4, 0.3, 0.3, weight]).unwrap();
        let Model::Mixture(x) = &fit else { panic!("{id} is a mixture") };
        let e = export_mixture(x, Target::Blender, 70.0).unwrap();
        let Some(g) = run_blender_script(&e.snippet("fit.json"), &[]) else { return };
        let mix = g.surface();
        assert_eq!(g.node(mix)["idname"], json!("ShaderNodeMixShader"), "{}", g.0);
        assert!((g.node(mix)["inputs"]["Fac"].as_f64().unwrap() - (1.0 - weight)).abs() < 1e-15);
        let keys = e.to_json();
        assert_lobe_node(&g, g.feeding(mix, 1).unwrap(), &keys["bsdfs"][0]);
        assert_lobe_node(&g, g.feeding(mix, 2).unwrap(), &keys["bsdfs"][1]);
    }
}
