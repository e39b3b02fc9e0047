//! The render decides: the simplest fitted lobe whose render a viewer cannot tell from the render of the
//! scan's own table, or the table itself.
//!
//! Each candidate lobe and the table are rendered in the same scenes by [`crate::render`] (no external
//! renderer, no noise) and scored by HDR-FLIP ([`crate::flip`]; Andersson et al. 2021) against the
//! table's render. A lobe is the answer when its worst score over the scenes is within the tolerance; the
//! first such lobe in the candidates' order (simplest first) wins. When none is, the answer is the table,
//! and the closest lobe (the smallest worst score) is still reported for renderers that cannot load one.
//! Both sides use the same Smith masking (from their own NDF) and the same conductor, so the renders
//! differ only by the NDF.

use nalgebra::Vector3;

use super::rgl::{AnalyticBrdf, Material, NdfGrids};
use crate::error::Result;
use crate::flip::{auto_exposures, hdr, HdrOptions, RgbImage, DEFAULT_PPD};
use crate::models::Model;
use crate::render::{Brdf, Image, Scene};

/// The scan's table as a renderer shows it: `D` read bilinearly from the table's `ndf` grid, Smith's `G1`
/// from its `sigma` grid, both directions' masking separable (as Mitsuba's `measured` with `jacobian`),
/// and the conductor's Fresnel term at the [`RGB_NM`](super::rgl::RGB_NM) wavelengths.
#[derive(Debug, Clone, Copy)]
pub struct TableBrdf<'a> {
    /// The table's NDF and projected-area grids.
    pub grids: &'a NdfGrids,
    /// The conductor.
    pub material: Material,
}

impl Brdf for TableBrdf<'_> {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        // Reflection only; on the horizon the cosines' quotient has the limit 0.
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return [0.0; 3];
        }
        let h = (wi + wo).normalize();
        let bare = self.grids.d(h) * self.grids.g1(wi) * self.grids.g1(wo) / (4.0 * wi.z * wo.z);
        let c = wi.dot(&h);
        self.material.fresnel_rgb(c).map(|f| bare * f)
    }
}

/// A scene of the choice with the name the report gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NamedScene {
    /// `point` or `broad` for the defaults.
    pub name: &'static str,
    /// The scene.
    pub scene: Scene,
}

/// The default scenes: the sphere under a point light (every half vector in one image) and under a broad
/// light (the NDF blurred, as a room lights an object); `data_formats/render.md` states them.
pub fn default_scenes() -> Vec<NamedScene> {
    vec![NamedScene { name: "point", scene: Scene::point() }, NamedScene { name: "broad", scene: Scene::broad() }]
}

/// One candidate's scores: the mean HDR-FLIP of its render against the table's, per scene, and the worst.
#[derive(Debug, Clone, PartialEq)]
pub struct Score {
    /// The mean FLIP per scene, in the scenes' order.
    pub per_scene: Vec<f64>,
    /// The largest of `per_scene`.
    pub worst: f64,
}

/// What the renders decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The scenes' names, in the scores' order.
    pub scenes: Vec<&'static str>,
    /// Each candidate's scores, in the candidates' order.
    pub scores: Vec<Score>,
    /// The index of the answer among the candidates, or `None` for the table itself.
    pub answer: Option<usize>,
    /// The index of the closest candidate (the smallest worst score; the first on a tie).
    pub closest: usize,
    /// The tolerance the worst score was held to.
    pub tolerance: f64,
}

impl Choice {
    /// The candidate whose render error the report states: the answer, or the closest lobe when the
    /// answer is the table.
    pub fn reported(&self) -> usize {
        self.answer.unwrap_or(self.closest)
    }
}

/// The darkest level, relative to the reference's brightest pixel, that the exposures reach: a highlight's
/// skirt is judged down to `1e-3` of its peak, the level the tables are held to (data_formats/rgl.md).
/// FLIP's own stop exposure maps the image's median to mid-grey, and on a sphere against black the median
/// is 0: 23 stops up, where a lobe's tail a millionth of its peak dominates the score.
pub const DYNAMIC_RANGE: f64 = 1e3;

/// The HDR-FLIP exposures for `reference`: FLIP's start (its brightest pixel at 0.85 after the tone
/// mapper), the stop FLIP's own or [`DYNAMIC_RANGE`] below the start, whichever is brighter.
pub fn exposures(reference: &Image) -> Result<HdrOptions> {
    let (start, stop) = auto_exposures(&RgbImage::new(reference.width, reference.height, reference.data.clone())?)?;
    Ok(HdrOptions { start_exposure: Some(start), stop_exposure: Some(stop.min(start + DYNAMIC_RANGE.log2())), num_exposures: None })
}

/// The mean HDR-FLIP of `test` against `reference` at FLIP's default viewing condition, over the
/// [`exposures`] of the reference.
pub fn flip_mean(reference: &Image, test: &Image) -> Result<f64> {
    let to_rgb = |i: &Image| RgbImage::new(i.width, i.height, i.data.clone());
    Ok(hdr(&to_rgb(reference)?, &to_rgb(test)?, DEFAULT_PPD, &exposures(reference)?)?.mean())
}

/// Render the table and every candidate (simplest first) in `scenes`, score each candidate by FLIP
/// against the table, and choose: the first candidate whose worst score is at most `tolerance`, else the
/// table. An empty candidate list is an error (there is no closest lobe to report).
pub fn decide(table: &dyn Brdf, candidates: &[Model], material: Material, scenes: &[NamedScene], tolerance: f64) -> Result<Choice> {
    if candidates.is_empty() || scenes.is_empty() {
        return Err(crate::Error::invalid("the render choice needs at least one candidate lobe and one scene"));
    }
    let references: Vec<Image> = scenes.iter().map(|s| s.scene.render(table)).collect::<Result<_>>()?;
    let mut scores = Vec::with_capacity(candidates.len());
    for &model in candidates {
        let lobe = AnalyticBrdf { model, material };
        let per_scene: Vec<f64> =
            scenes.iter().zip(&references).map(|(s, r)| flip_mean(r, &s.scene.render(&lobe)?)).collect::<Result<_>>()?;
        let worst = per_scene.iter().copied().fold(0.0, f64::max);
        scores.push(Score { per_scene, worst });
    }
    let answer = scores.iter().position(|s| s.worst <= tolerance);
    let closest = (0..scores.len()).fold(0, |best, k| if scores[k].worst < scores[best].worst { k } else { best });
    Ok(Choice { scenes: scenes.iter().map(|s| s.name).collect(), scores, answer, closest, tolerance })
}

/// The picture of one scene: the table's render, the lobe's render and the FLIP map side by side (each
/// panel scaled up to at least 256 pixels), the renders tone-mapped by FLIP's ACES curve at exposure 0
/// and sRGB-encoded, the map in FLIP's magma colours, under a title with the score. PNG bytes.
#[cfg(feature = "plot")]
pub fn picture(table: &Image, lobe: &Image, title: &str) -> Result<Vec<u8>> {
    use plotters::prelude::*;
    let err = |e: String| crate::Error::new(crate::ErrorKind::Io, format!("picture: {e}"));
    let to_rgb = |i: &Image| RgbImage::new(i.width, i.height, i.data.clone());
    let map = hdr(&to_rgb(table)?, &to_rgb(lobe)?, DEFAULT_PPD, &exposures(table)?)?;
    let (iw, ih) = (table.width, table.height);
    let k = 256usize.div_ceil(iw.max(1)).max(1);
    let (pw, ph) = (iw * k, ih * k);
    let (gap, head) = (12usize, 64usize);
    let (w, h) = (3 * pw + 4 * gap, ph + head + gap);
    let mut buf = vec![255u8; w * h * 3];
    let srgb = |v: f64| {
        let v = crate::flip::aces(v.max(0.0)).clamp(0.0, 1.0);
        let e = if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
        (e * 255.0).round() as u8
    };
    let magma = map.magma_rgb8();
    for y in 0..ph {
        for x in 0..pw {
            let (sx, sy) = (x / k, y / k);
            let at = |panel: usize| ((head + y) * w + gap + panel * (pw + gap) + x) * 3;
            let (a, b) = (table.get(sx, sy), lobe.get(sx, sy));
            buf[at(0)..at(0) + 3].copy_from_slice(&a.map(|v| srgb(v as f64)));
            buf[at(1)..at(1) + 3].copy_from_slice(&b.map(|v| srgb(v as f64)));
            let m = (sy * iw + sx) * 3;
            buf[at(2)..at(2) + 3].copy_from_slice(&magma[m..m + 3]);
        }
    }
    crate::plot::ensure_font();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w as u32, h as u32)).into_drawing_area();
        let font = (crate::plot::FONT, 18);
        root.draw(&Text::new(title.to_string(), (gap as i32, 8), font)).map_err(|e| err(e.to_string()))?;
        for (panel, label) in ["the scan's table", "the lobe", &format!("FLIP map, mean {:.4}", map.mean())].iter().enumerate() {
            let x = (gap + panel * (pw + gap)) as i32;
            root.draw(&Text::new(label.to_string(), (x, 38), font)).map_err(|e| err(e.to_string()))?;
        }
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(&mut out, &buf, w as u32, h as u32, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
        .map_err(|e| err(format!("PNG encoding failed: {e}")))?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::{ModelId, Ndf};

    fn ggx(alpha: f64) -> Model {
        Model::from_params(ModelId::Ggx, &[alpha]).unwrap()
    }

    /// A lobe's own table renders as the lobe (FLIP near 0: only the table's interpolation differs), a
    /// wrong roughness does not, and the scores fall as the candidate's alpha nears the table's.
    #[test]
    fn a_lobe_is_chosen_for_its_own_table_and_roughness_is_ranked() {
        let truth = ggx(0.3);
        let grids = NdfGrids::new(&|m| truth.d(m), &|m| truth.d(m), None, false).unwrap();
        let table = TableBrdf { grids: &grids, material: Material::Au };
        let candidates = [ggx(0.6), ggx(0.4), ggx(0.3)];
        let c = decide(&table, &candidates, Material::Au, &default_scenes(), 0.02).unwrap();
        let worst: Vec<f64> = c.scores.iter().map(|s| s.worst).collect();
        assert!(worst[0] > worst[1] && worst[1] > worst[2], "{worst:?}");
        assert!(worst[2] < 0.01, "{worst:?}");
        assert!(worst[0] > 0.1, "{worst:?}");
        assert_eq!((c.answer, c.closest, c.reported()), (Some(2), 2, 2));
    }

    /// A two-lobe surface that no single lobe renders like: the answer is the table, and the closest lobe
    /// is still named.
    #[test]
    fn the_table_answers_when_no_lobe_is_close() {
        let two = Model::from_params(ModelId::Ggx2, &[0.05, 0.05, 0.5, 0.5, 0.0, 0.5]).unwrap();
        let grids = NdfGrids::new(&|m| two.d(m), &|m| two.d(m), None, false).unwrap();
        let table = TableBrdf { grids: &grids, material: Material::None };
        let candidates = [ggx(0.05), ggx(0.5)];
        let c = decide(&table, &candidates, Material::None, &default_scenes(), 0.02).unwrap();
        assert_eq!(c.answer, None, "{:?}", c.scores);
        assert!(c.scores.iter().all(|s| s.worst > 0.05), "{:?}", c.scores);
        assert_eq!(c.reported(), c.closest);
    }
}
