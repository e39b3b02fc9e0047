//! Export of a mirror answer (`selection.answer` `mirror` / `mirror+ggx` with `optics`): fit documents
//! written here with the mirror shares of Gaussian heights, `s = exp(-(2 k sigma cos theta)^2)`, so the
//! share's form is known in closed form: `b = (2 k sigma)^2`, and the constant blends' weight is the
//! cosine-weighted hemispherical mean of `1 - s`, computed here by a midpoint rule in `theta`.

use std::f64::consts::PI;
use std::process::Command;

use serde_json::{json, Value};

use crate::common::ndfit_bin;
use crate::export_blender::run_blender_script;

const SIGMA: f64 = 40e-9;
const HAZE_ALPHA: f64 = 0.0123;
const THETAS: [f64; 5] = [0.0, 30.0, 45.0, 60.0, 75.0];
const LAMBDAS: [f64; 3] = [450.0, 550.0, 650.0];

/// `(2 k sigma)^2` at `lambda_nm`.
fn beta(lambda_nm: f64) -> f64 {
    (2.0 * 2.0 * PI / (lambda_nm * 1e-9) * SIGMA).powi(2)
}

/// The mirror share of Gaussian heights of RMS `SIGMA`.
fn share(theta_deg: f64, lambda_nm: f64) -> f64 {
    (-beta(lambda_nm) * theta_deg.to_radians().cos().powi(2)).exp()
}

/// `int (1 - s(theta)) cos theta dw / pi` over the hemisphere at `lambda_nm`, by a midpoint rule in theta.
fn mean_haze(lambda_nm: f64) -> f64 {
    let n = 200_000;
    let h = 0.5 * PI / n as f64;
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) * h;
            (1.0 - (-beta(lambda_nm) * t.cos().powi(2)).exp()) * 2.0 * t.cos() * t.sin() * h
        })
        .sum()
}

/// A fit document whose answer is `answer`: the ladder's own lobe (not the answer), and `optics` with the
/// Gaussian shares and, for `mirror+ggx`, the haze.
fn fit_doc(answer: &str) -> Value {
    let specular: Vec<Value> = LAMBDAS
        .iter()
        .flat_map(|&l| THETAS.iter().map(move |&t| json!({"theta_deg": t, "wavelength_nm": l, "weight": share(t, l)})))
        .collect();
    let mut optics = json!({"regime": "wave", "wavelength_nm": LAMBDAS, "coherence_m": 1.8925e-05, "specular": specular});
    if answer != "mirror" {
        optics["haze"] = json!({"model": "ggx", "params": {"alpha": HAZE_ALPHA}});
    }
    json!({"schema": "ndfit.fit/1", "model": "beckmann", "params": {"alpha": 0.3}, "quality": {"max_theta_deg": 70.0},
           "selection": {"answer": answer}, "optics": optics})
}

/// `ndfit export` of `doc` (written as `dir/name`) to `to`, `--json` when asked: (exit code, stdout, stderr).
fn run_export(dir: &std::path::Path, name: &str, doc: &Value, to: &str, as_json: bool) -> (i32, String, String) {
    let path = dir.join(name);
    std::fs::write(&path, doc.to_string()).unwrap();
    let mut cmd = Command::new(ndfit_bin());
    cmd.current_dir(dir).args(["export", name, "--to", to]);
    if as_json {
        cmd.arg("--json");
    }
    let out = cmd.output().expect("runs");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// An XML element: name, attributes, children.
#[derive(Debug)]
struct Elem {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Elem>,
}

impl Elem {
    fn attr(&self, k: &str) -> Option<&str> {
        self.attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
    }

    /// The child element named `name` with attribute `k` = `v`.
    fn child(&self, name: &str, k: &str, v: &str) -> &Elem {
        self.children
            .iter()
            .find(|c| c.name == name && c.attr(k) == Some(v))
            .unwrap_or_else(|| panic!("no <{name} {k}=\"{v}\"> in {self:?}"))
    }
}

/// The root element of an XML document, by quick-xml.
fn parse_xml(text: &str) -> Elem {
    use quick_xml::events::{BytesStart, Event};
    let elem = |s: &BytesStart| Elem {
        name: s.name().as_ref().to_string(),
        attrs: s
            .attributes()
            .map(|a| {
                let a = a.unwrap();
                (a.key.as_ref().to_string(), a.normalized_value(quick_xml::XmlVersion::Implicit1_0).unwrap().into_owned())
            })
            .collect(),
        children: Vec::new(),
    };
    let mut reader = quick_xml::Reader::from_str(text);
    let mut stack: Vec<Elem> = vec![Elem { name: String::new(), attrs: Vec::new(), children: Vec::new() }];
    loop {
        match reader.read_event().expect("well-formed XML") {
            Event::Start(s) => stack.push(elem(&s)),
            Event::Empty(s) => stack.last_mut().unwrap().children.push(elem(&s)),
            Event::End(_) => {
                let e = stack.pop().unwrap();
                stack.last_mut().unwrap().children.push(e);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    let mut doc = stack.pop().unwrap();
    assert_eq!(doc.children.len(), 1, "one root element");
    doc.children.pop().unwrap()
}

/// The largest `|c - (1 - s(theta))|` over the listed incidences at `lambda_nm`.
fn constant_gap(c: f64, lambda_nm: f64) -> f64 {
    THETAS.iter().map(|&t| (c - (1.0 - share(t, lambda_nm))).abs()).fold(0.0, f64::max)
}

/// Mitsuba: a `blendbsdf` whose first BSDF is a `conductor` and second the haze's `roughconductor`; its weight
/// is the cosine-weighted hemispherical mean of `1 - s` at 550 nm, and its reported distance from the shares
/// is `max |weight - (1 - s)|` at each wavelength; stderr says so.
#[test]
fn mitsuba_blends_a_conductor_and_the_haze() {
    let dir = tempfile::tempdir().unwrap();
    let want = mean_haze(550.0);
    let (code, xml, err) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "mitsuba", false);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("mg.json") && err.contains("cannot follow the incidence"), "{err}");
    let root = parse_xml(&xml);
    assert_eq!((root.name.as_str(), root.attr("type")), ("bsdf", Some("blendbsdf")), "{root:?}");
    let kinds: Vec<(&str, Option<&str>)> = root.children.iter().map(|c| (c.name.as_str(), c.attr("type").or(c.attr("name")))).collect();
    assert_eq!(kinds, [("float", Some("weight")), ("bsdf", Some("conductor")), ("bsdf", Some("roughconductor"))]);
    let weight: f64 = root.child("float", "name", "weight").attr("value").unwrap().parse().unwrap();
    assert!((weight - want).abs() < 1e-9, "{weight} vs {want}");
    let haze = root.child("bsdf", "type", "roughconductor");
    assert_eq!(haze.child("string", "name", "distribution").attr("value"), Some("ggx"));
    for a in ["alpha_u", "alpha_v"] {
        assert_eq!(haze.child("float", "name", a).attr("value"), Some(HAZE_ALPHA.to_string().as_str()));
    }
    let (_, out, _) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "mitsuba", true);
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!((&v["answer"], &v["blend"], &v["bsdfs"][0]), (&json!("mirror+ggx"), &json!("blendbsdf"), &json!({"plugin": "conductor"})));
    assert!((v["weight"].as_f64().unwrap() - want).abs() < 1e-9);
    for (i, l) in LAMBDAS.iter().enumerate() {
        let gap = &v["weight_error"][i];
        assert_eq!(gap["wavelength_nm"].as_f64(), Some(*l));
        assert!((gap["max_abs"].as_f64().unwrap() - constant_gap(want, *l)).abs() < 1e-9, "{gap}");
    }
    assert!(v["note"].as_str().unwrap().contains("cosine-weighted"), "{v}");
}

/// pbrt-v4, MaterialX, OpenPBR: the same constant, as `MixMaterial`'s `amount` (the haze named second) and as
/// the `mix` input of a BSDF `mix` (MaterialX) or a `surfaceshader` `mix` of two OpenPBR surfaces, with the
/// mirror as `bg` and the haze as `fg`.
#[test]
fn constant_blends_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let want = mean_haze(550.0);
    let (code, pbrt, err) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "pbrt", false);
    assert_eq!(code, 0, "{err}");
    let amount = pbrt.split("\"float amount\" [ ").nth(1).and_then(|r| r.split(' ').next()).unwrap();
    assert!((amount.parse::<f64>().unwrap() - want).abs() < 1e-9, "{pbrt}");
    assert!(pbrt.contains("\"string materials\" [ \"ndfit_mirror\" \"ndfit_haze\" ]"), "{pbrt}");
    let haze = pbrt.split("MakeNamedMaterial \"ndfit_haze\"").nth(1).unwrap();
    assert!(haze.contains(&format!("\"float uroughness\" [ {HAZE_ALPHA} ]")), "{pbrt}");
    for (to, ty, shader) in [("materialx", "BSDF", "conductor_bsdf"), ("openpbr", "surfaceshader", "open_pbr_surface")] {
        let (code, xml, err) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), to, false);
        assert_eq!(code, 0, "{err}");
        let root = parse_xml(&xml);
        assert_eq!(root.attr("version"), Some("1.39"));
        let mix = root.children.iter().find(|c| c.name == "mix").expect("a mix node");
        assert_eq!(mix.attr("type"), Some(ty));
        assert_eq!(mix.child("input", "name", "fg").attr("nodename"), Some("ndfit_haze"));
        assert_eq!(mix.child("input", "name", "bg").attr("nodename"), Some("ndfit_mirror"));
        let w: f64 = mix.child("input", "name", "mix").attr("value").unwrap().parse().unwrap();
        assert!((w - want).abs() < 1e-9, "{to}: {w}");
        let mirror = root.child(shader, "name", "ndfit_mirror");
        let rough = if to == "materialx" { "roughness" } else { "specular_roughness" };
        let zero = mirror.child("input", "name", rough).attr("value").unwrap();
        assert!(zero.split(',').all(|x| x.trim().parse::<f64>().unwrap() == 0.0), "{to}: {zero}");
        assert!(err.contains("cannot follow the incidence"), "{err}");
    }
}

/// Blender: the fitted form's `b` is `(2 k sigma)^2` at 550 nm for Gaussian shares, the script (run in the
/// stand-in bpy) mixes a Glossy mirror at Roughness 0 (Fac 0) with the GGX haze (Fac 1) and its Fac at every
/// view angle is `1 - exp(-b cos^2 theta)`; the reported distance of the form from the shares is the
/// wavelength's: `max |exp(-b_550 cos^2) - exp(-b_l cos^2)|`.
#[test]
fn blender_fac_follows_the_angle() {
    let dir = tempfile::tempdir().unwrap();
    let (code, out, err) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "blender", true);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("collapsed to 550 nm"), "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let b = v["mirror_share"]["b"].as_f64().unwrap();
    assert!((b - beta(550.0)).abs() < 1e-6 * beta(550.0), "{b} vs {}", beta(550.0));
    for (i, l) in LAMBDAS.iter().enumerate() {
        let want = THETAS.iter().map(|&t| (share(t, 550.0) - share(t, *l)).abs()).fold(0.0, f64::max);
        assert!((v["fac_error"][i]["max_abs"].as_f64().unwrap() - want).abs() < 1e-9, "{}", v["fac_error"]);
    }
    // The blends' render error: per scene and the worst; Blender's Fac, which follows the angle, renders
    // closer to the listed shares than Mitsuba's constant.
    let (_, mitsuba, _) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "mitsuba", true);
    let m: Value = serde_json::from_str(&mitsuba).unwrap();
    let worst = |v: &Value| {
        let e = &v["render_error"];
        let scenes = ["point", "broad", "window"].map(|s| e[s].as_f64().unwrap());
        assert_eq!(e["worst"].as_f64(), Some(scenes.iter().copied().fold(0.0, f64::max)), "{e}");
        e["worst"].as_f64().unwrap()
    };
    assert!(worst(&v) < worst(&m), "Blender {} against Mitsuba {}", v["render_error"], m["render_error"]);
    assert!(err.contains("blend renders within mean HDR-FLIP"), "{err}");
    let (_, script, _) = run_export(dir.path(), "mg.json", &fit_doc("mirror+ggx"), "blender", false);
    let thetas = [0.0, 20.0, 45.0, 70.0, 89.0];
    let Some(g) = run_blender_script(&script, &thetas) else { return };
    let mix = g.surface();
    let mirror = g.node(g.feeding(mix, 1).unwrap());
    assert_eq!((&mirror["idname"], &mirror["inputs"]["Roughness"]), (&json!("ShaderNodeBsdfAnisotropic"), &json!(0.0)), "{mirror}");
    let haze = g.node(g.feeding(mix, 2).unwrap());
    assert_eq!(haze["idname"], json!("ShaderNodeBsdfPrincipled"));
    assert!((haze["inputs"]["Roughness"].as_f64().unwrap() - HAZE_ALPHA.sqrt()).abs() < 1e-12, "{haze}");
    for (k, t) in thetas.iter().enumerate() {
        let fac = g.0["fac"][k][1].as_f64().unwrap();
        let want = 1.0 - share(*t, 550.0);
        assert!((fac - want).abs() < 1e-6, "theta {t}: Fac {fac} vs {want}");
    }
}

/// A mirror alone: every renderer's smooth conductor (Mitsuba `conductor`, pbrt and the MaterialX nodes at
/// roughness 0, a Glossy BSDF at Roughness 0 into the Material Output), with nothing approximated.
#[test]
fn mirror_alone_is_the_smooth_conductor() {
    let dir = tempfile::tempdir().unwrap();
    let doc = fit_doc("mirror");
    let (code, xml, err) = run_export(dir.path(), "m.json", &doc, "mitsuba", false);
    assert_eq!(code, 0, "{err}");
    assert!(err.is_empty(), "{err}");
    let root = parse_xml(&xml);
    assert_eq!((root.name.as_str(), root.attr("type"), root.children.len()), ("bsdf", Some("conductor"), 0));
    let (_, pbrt, _) = run_export(dir.path(), "m.json", &doc, "pbrt", false);
    assert!(pbrt.contains("Material \"conductor\"\n    \"float uroughness\" [ 0 ]\n    \"float vroughness\" [ 0 ]"), "{pbrt}");
    for to in ["mitsuba", "pbrt", "blender", "openpbr", "materialx"] {
        let (code, out, err) = run_export(dir.path(), "m.json", &doc, to, true);
        assert_eq!(code, 0, "{to}: {err}");
        let v: Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["answer"], json!("mirror"));
        assert!(v.get("note").is_none() && v.get("blend").is_none(), "{to}: {v}");
    }
    let (_, script, _) = run_export(dir.path(), "m.json", &doc, "blender", false);
    let Some(g) = run_blender_script(&script, &[]) else { return };
    let mirror = g.node(g.surface());
    assert_eq!((&mirror["idname"], &mirror["inputs"]["Roughness"]), (&json!("ShaderNodeBsdfAnisotropic"), &json!(0.0)), "{mirror}");
}

/// `--to rgl` of a mirror answer: refused, one line naming the file and pointing at `--to mitsuba`, no table.
#[test]
fn rgl_refuses_a_mirror() {
    let dir = tempfile::tempdir().unwrap();
    for answer in ["mirror", "mirror+ggx"] {
        std::fs::write(dir.path().join("m.json"), fit_doc(answer).to_string()).unwrap();
        let out =
            Command::new(ndfit_bin()).current_dir(dir.path()).args(["export", "m.json", "--to", "rgl", "-o", "m.bsdf"]).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && out.stdout.is_empty(), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains("m.json") && err.contains("--to mitsuba"), "{err}");
        assert!(!dir.path().join("m.bsdf").exists());
    }
}

/// An answer without a mirror exports its model exactly as a file with the model alone: the same bytes on
/// stdout and stderr for every renderer, with and without `--json`.
#[test]
fn answers_without_a_mirror_export_the_model() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let model = json!({"schema": "ndfit.fit/1", "model": "beckmann-aniso", "params": {"alpha_x": 0.3, "alpha_y": 0.12, "theta_z": 0.7},
                       "quality": {"max_theta_deg": 70.0}});
    let mut with_optics = fit_doc("mirror+ggx");
    for k in ["model", "params", "quality"] {
        with_optics[k] = model[k].clone();
    }
    with_optics["selection"]["answer"] = json!("beckmann-aniso");
    for to in ["mitsuba", "pbrt", "blender", "openpbr", "materialx"] {
        for as_json in [false, true] {
            let plain = run_export(a.path(), "f.json", &model, to, as_json);
            assert_eq!(plain.0, 0, "{}", plain.2);
            assert_eq!(run_export(b.path(), "f.json", &with_optics, to, as_json), plain, "{to}");
        }
    }
}

/// A malformed mirror answer is one line naming the file: a haze answer without its lobe, a share outside
/// [0, 1].
#[test]
fn bad_mirror_answers_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let mut no_haze = fit_doc("mirror+ggx");
    no_haze["optics"].as_object_mut().unwrap().remove("haze");
    let mut bad_share = fit_doc("mirror+ggx");
    bad_share["optics"]["specular"][3]["weight"] = json!(1.7);
    for (doc, why) in [(no_haze, "optics.haze"), (bad_share, "specular[3]")] {
        let (code, out, err) = run_export(dir.path(), "bad.json", &doc, "mitsuba", false);
        assert_ne!(code, 0);
        assert!(out.is_empty() && err.lines().count() == 1 && err.contains("bad.json") && err.contains(why), "{err}");
    }
}
