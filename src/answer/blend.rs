//! What a renderer's blend costs a mirror answer in the render: where a target's weight cannot follow the
//! angle and the wavelength (a constant, or Blender's form of the angle alone; `export::export_mirror`), the
//! answer rendered with that blend's mirror share against the answer rendered with its listed shares, in
//! the choice's default scenes and the window scene: the approximation's render error, printed with the
//! export.

use crate::error::Result;
use crate::export::rgl::Material;
use crate::export::{MirrorAnswer, MirrorBrdf, MirrorExport};
use crate::render::{Stage, Window};

use super::choice::{default_scenes, flip_mean};

/// The render error of an export's blend: the mean HDR-FLIP per scene and the worst.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendError {
    /// `(scene, FLIP)` in the order rendered: `point`, `broad`, `window`.
    pub per_scene: Vec<(String, f64)>,
    /// The largest of them.
    pub worst: f64,
}

/// The render error of `export`'s blend of `answer` (module docs), both renders with the conductor's
/// Fresnel at 1 (the blend is what differs); `None` for a mirror alone (there is no blend). A scene whose
/// reference shows nothing (a mirror under the point light with no haze) is left out.
pub fn blend_render_error(answer: &MirrorAnswer, export: &MirrorExport) -> Result<Option<BlendError>> {
    let Some(form) = export.form else { return Ok(None) };
    let exact = MirrorBrdf::new(answer, Material::None);
    let approx = match export.weight {
        Some(w) => MirrorBrdf::with_share(answer, &|_| 1.0 - w, Material::None),
        None => MirrorBrdf::with_share(answer, &|t| form.share(t), Material::None),
    };
    let mut scenes: Vec<(String, Stage)> = default_scenes().into_iter().map(|s| (s.name, s.scene)).collect();
    scenes.push(("window".into(), Stage::Window(Window::default())));
    let mut per_scene = Vec::new();
    for (name, scene) in scenes {
        let reference = scene.render(&exact)?;
        // Nothing to see: FLIP's exposures need a lit reference.
        if !reference.data.iter().any(|p| p.iter().any(|&v| v > 0.0)) {
            continue;
        }
        per_scene.push((name, flip_mean(&reference, &scene.render(&approx)?)?));
    }
    let worst = per_scene.iter().map(|p| p.1).fold(0.0, f64::max);
    Ok(Some(BlendError { per_scene, worst }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::{Share, ShareForm, Target};
    use crate::models::{Model, ModelId};

    fn answer(s: f64) -> MirrorAnswer {
        let specular = [450.0, 550.0, 650.0]
            .iter()
            .flat_map(|&nm| [0.0, 30.0, 45.0, 60.0, 75.0].map(|t| Share { theta_deg: t, wavelength_nm: nm, weight: s }))
            .collect();
        MirrorAnswer { answer: "mirror+ggx".into(), specular, haze: Some(Model::from_params(ModelId::Ggx, &[0.1]).unwrap()) }
    }

    /// A blend whose constant is the answer's own (constant) haze share renders the same image, FLIP 0 in
    /// every scene; a wrong constant shows in every scene, most where the mirror's image is (the window).
    #[test]
    fn a_blend_is_scored_by_what_it_changes() {
        let a = answer(0.7);
        let form = ShareForm { wavelength_nm: 550.0, b: 0.4, used: 5 };
        let blend = |w: f64| MirrorExport {
            target: Target::Mitsuba,
            answer: a.answer.clone(),
            haze: None,
            form: Some(form),
            weight: Some(w),
            gaps: Vec::new(),
        };
        let same = blend_render_error(&a, &blend(0.3)).unwrap().unwrap();
        assert_eq!(same.per_scene.iter().map(|p| p.0.as_str()).collect::<Vec<_>>(), ["point", "broad", "window"]);
        assert!(same.per_scene.iter().all(|p| p.1 == 0.0), "{same:?}");
        let off = blend_render_error(&a, &blend(0.5)).unwrap().unwrap();
        assert!(off.per_scene.iter().all(|p| p.1 > 0.01), "{off:?}");
        assert_eq!(off.worst, off.per_scene.iter().map(|p| p.1).fold(0.0, f64::max));
        let alone = MirrorExport { form: None, weight: None, ..blend(0.3) };
        assert_eq!(blend_render_error(&a, &alone).unwrap(), None);
    }
}
