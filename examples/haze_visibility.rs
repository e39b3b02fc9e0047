//! When is a mirror's haze visible? A smooth conductor whose haze (a GGX lobe of roughness `alpha`) carries
//! the share `a` of its light, against the same conductor as a mirror alone, rendered in the choice's
//! scenes (point, broad, window; material Al) and scored by mean HDR-FLIP with the choice's exposures (the
//! reference is the mirror with its haze: what light sees). Prints per `alpha` the share at which the
//! broad scene's score reaches the render tolerance (bisection in `ln a`), and with `--all-scenes` the
//! score in every scene for a few shares (a mirror alone under the point light is black, so that scene
//! scores any haze alike; the window's black room shows hazes far below what a room would). docs/ANSWER.md, "When the haze is left out".
//!
//!     cargo run --release --example haze_visibility
use ndfit::answer::choice::{flip_mean, DEFAULT_RENDER_TOLERANCE};
use ndfit::export::rgl::Material;
use ndfit::export::{MirrorAnswer, MirrorBrdf, Share};
use ndfit::models::{Ggx, Model};
use ndfit::render::{Image, Scene, Stage, Window};

fn answer(alpha: f64, a: f64) -> MirrorAnswer {
    let specular = [450.0, 550.0, 650.0]
        .iter()
        .flat_map(|&wavelength_nm| [0.0, 30.0, 45.0, 60.0, 75.0].map(|theta_deg| Share { theta_deg, wavelength_nm, weight: 1.0 - a }))
        .collect();
    MirrorAnswer { answer: "mirror+ggx".into(), specular, haze: Some(Model::Ggx(Ggx::new(alpha, alpha, 0.0).unwrap())) }
}

fn main() {
    let scenes: Vec<(&str, Stage)> =
        vec![("point", Scene::point().into()), ("broad", Scene::broad().into()), ("window", Stage::Window(Window::default()))];
    let mirror = MirrorBrdf::new(&MirrorAnswer { answer: "mirror".into(), specular: Vec::new(), haze: None }, Material::Al);
    let bare: Vec<Image> = scenes.iter().map(|(_, s)| s.render(&mirror).unwrap()).collect();
    let score = |k: usize, alpha: f64, a: f64| -> f64 {
        let b = MirrorBrdf::new(&answer(alpha, a), Material::Al);
        flip_mean(&scenes[k].1.render(&b).unwrap(), &bare[k]).unwrap()
    };
    let tol = DEFAULT_RENDER_TOLERANCE;
    let full = std::env::args().any(|a| a == "--all-scenes");
    for alpha in [0.003, 0.005, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0] {
        if full {
            for a in [1e-5, 1e-4, 1e-3, 1e-2] {
                let v: Vec<String> = (0..3).map(|k| format!("{} {:.4}", scenes[k].0, score(k, alpha, a))).collect();
                println!("alpha {alpha:<5} a {a:<7.0e} {}", v.join(" "));
            }
        }
        // The broad scene's score rises with `a`: bisect `ln a` for the tolerance.
        let (mut lo, mut hi) = (1e-7_f64.ln(), 0.5_f64.ln());
        for _ in 0..16 {
            let mid = 0.5 * (lo + hi);
            if score(1, alpha, mid.exp()) < tol {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        println!("alpha {alpha}: the broad scene shows the haze from a = {:.4e}", (0.5 * (lo + hi)).exp());
    }
}
