//! A mirror answer's haze against the wave prediction (docs/ANSWER.md, "No one alpha serves every scene"):
//! the answer's haze alpha scaled by k (0: the mirror alone), and the ladder's lobe as the haze, each
//! rendered in the point, broad and window scenes and scored by mean HDR-FLIP against the wave prediction
//! (`ndfit wave SCAN --to rgl`), or against the joined reference of a mixed scan when the scan's geometric
//! table (`ndfit export SCAN --to rgl`) is given, over the whole image and over the pixels where the
//! reference holds light. Material none on both sides.
//!
//!     ndfit fit SCAN -o FIT.json; ndfit wave SCAN --to rgl -o W.bsdf [; ndfit export SCAN --to rgl -o G.bsdf]
//!     cargo run --release --example haze_against_wave -- FIT.json W.bsdf [G.bsdf]
use ndfit::answer::choice::{exposures, flip_mean};
use ndfit::flip::{hdr, RgbImage, DEFAULT_PPD};
use ndfit::render::Image;

/// Mean HDR-FLIP over the pixels where the reference holds light in every channel (the wave prediction is
/// 0 beyond the band the scan resolves: there it is silent, not dark).
fn flip_in_band(reference: &Image, test: &Image) -> f64 {
    let rgb = |i: &Image| RgbImage::new(i.width, i.height, i.data.clone()).unwrap();
    let map = hdr(&rgb(reference), &rgb(test), DEFAULT_PPD, &exposures(reference).unwrap()).unwrap();
    let lit: Vec<f64> =
        reference.data.iter().zip(map.values()).filter(|(p, _)| p.iter().all(|&c| c > 0.0)).map(|(_, &v)| v as f64).collect();
    lit.iter().sum::<f64>() / lit.len().max(1) as f64
}
use ndfit::export::rgl::{Material, TensorFile};
use ndfit::export::{MirrorAnswer, MirrorBrdf};
use ndfit::models::Model;
use ndfit::render::{Scene, Stage, Window};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (fit, table) = (&args[1], &args[2]);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(fit).unwrap()).unwrap();
    let answer = MirrorAnswer::from_json(&json).unwrap().unwrap();
    let wt = TensorFile::parse(&std::fs::read(table).unwrap()).unwrap();
    let wave = match args.get(3) {
        Some(g) => MirrorBrdf::joined(&wt, &TensorFile::parse(&std::fs::read(g).unwrap()).unwrap(), Material::None, [0.05, 0.5]).unwrap(),
        None => MirrorBrdf::wave(&wt, Material::None).unwrap(),
    };
    let ladder = Model::from_json(&json).unwrap();
    let scenes: Vec<(&str, Stage)> =
        vec![("point", Scene::point().into()), ("broad", Scene::broad().into()), ("window", Stage::Window(Window::default()))];
    let refs: Vec<_> = scenes.iter().map(|(_, s)| s.render(&wave).unwrap()).collect();
    let a0 = match answer.haze {
        Some(Model::Ggx(g)) => g.alpha_x,
        ref h => panic!("{h:?}"),
    };
    let mut variants: Vec<(String, Option<Model>)> = vec![("mirror".into(), None)];
    for k in [1.0, 1.5, 2.0, 3.0] {
        variants.push((format!("ggx k {k} alpha {:.4}", a0 * k), Some(Model::Ggx(ndfit::models::Ggx::new(a0 * k, a0 * k, 0.0).unwrap()))));
    }
    variants.push((format!("ladder {:?}", ladder), Some(ladder)));
    for (name, haze) in variants {
        let mut a = answer.clone();
        a.answer = if haze.is_some() { "mirror+ggx".into() } else { "mirror".into() };
        a.haze = haze;
        let b = MirrorBrdf::new(&a, Material::None);
        let v: Vec<String> = scenes
            .iter()
            .zip(&refs)
            .map(|((n, s), r)| {
                let t = s.render(&b).unwrap();
                format!("{n} {:.4} (in band {:.4})", flip_mean(r, &t).unwrap(), flip_in_band(r, &t))
            })
            .collect();
        println!("{name}: {}", v.join("  "));
    }
}
