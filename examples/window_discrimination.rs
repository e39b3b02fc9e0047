//! What the window scene tells apart that the sphere scenes do not (data_formats/render.md, "What the
//! window tells apart"): mean HDR-FLIP between a GGX lobe and a GGX lobe 10% and 25% rougher, and a Beckmann
//! lobe of the same roughness, in the point, broad and window scenes, for roughnesses 0.02 to 0.3.
//!
//!     cargo run --release --example window_discrimination
use ndfit::answer::choice::flip_mean;
use ndfit::export::rgl::{AnalyticBrdf, Material};
use ndfit::models::{Beckmann, Ggx, Model};
use ndfit::render::{Scene, Stage, Window};
fn main() {
    let scenes: Vec<(&str, Stage)> =
        vec![("point", Scene::point().into()), ("broad", Scene::broad().into()), ("window", Stage::Window(Window::default()))];
    for a in [0.02, 0.05, 0.1, 0.2, 0.3] {
        let t = AnalyticBrdf { model: Model::Ggx(Ggx::new(a, a, 0.0).unwrap()), material: Material::Al };
        for (name, m) in [
            ("ggx 1.1a", Model::Ggx(Ggx::new(1.1 * a, 1.1 * a, 0.0).unwrap())),
            ("ggx 1.25a", Model::Ggx(Ggx::new(1.25 * a, 1.25 * a, 0.0).unwrap())),
            ("beckmann a", Model::Beckmann(Beckmann::new(a, a, 0.0).unwrap())),
        ] {
            let l = AnalyticBrdf { model: m, material: Material::Al };
            let v: Vec<String> = scenes
                .iter()
                .map(|(n, s)| format!("{n} {:.4}", flip_mean(&s.render(&t).unwrap(), &s.render(&l).unwrap()).unwrap()))
                .collect();
            println!("ggx {a} vs {name}: {}", v.join("  "));
        }
    }
}
