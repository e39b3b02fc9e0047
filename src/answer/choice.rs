//! The render decides: the simplest fitted lobe whose render a viewer cannot tell from the render of the
//! scan's own table, or the table itself.
//!
//! Each candidate lobe and the table are rendered in the same scenes by [`crate::render`] (no external
//! renderer, no noise) and scored by HDR-FLIP ([`crate::flip`]; Andersson et al. 2021) against the
//! table's render. A lobe is the answer when its worst score over the scenes is within the tolerance; the
//! first such lobe in the candidates' order (simplest first) wins. When none is, the answer is the table,
//! and the closest lobe (the smallest worst score) is still reported for renderers that cannot load one.
//! Both sides use the same Smith masking (from their own NDF) and the same conductor, so the renders
//! differ only by the NDF. [`RenderJudge`] is that rule as `auto`'s judge ([`crate::fit::Decide`]):
//! lobes are rendered only until one is within the tolerance.

use std::collections::BTreeMap;
use std::sync::{Mutex, OnceLock};

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::export::rgl::{AnalyticBrdf, BinNodes, Material, NdfGrids, ProjectedArea, Regularized};
use crate::fit::{Decide, Decision, Offered};
use crate::flip::{auto_exposures, hdr, HdrOptions, HdrReference, RgbImage, DEFAULT_PPD};
use crate::models::Model;
use crate::ndf::EmpiricalNdf;
use crate::render::{direction, Brdf, BrdfSet, Image, Light, Scene, Stage, Window};

/// An exported table as a renderer shows it: `D` read bilinearly from the table's `ndf` grid, Smith's
/// `G1` from its `sigma` grid, both directions' masking separable (as Mitsuba's `measured` with
/// `jacobian`), and the conductor's Fresnel term at the [`RGB_NM`](crate::export::rgl::RGB_NM) wavelengths.
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
        self.material.fresnel_rgb(wi.dot(&h)).map(|f| bare * f)
    }
}

/// The quadrature nodes across the hemisphere of the scan table's projected area ([`ProjectedArea`]).
const AREA_QUAD: usize = 64;
/// The nodes across of its `sigma` grid: Smith's `G1` is smooth, and 32 nodes read it within a fraction
/// of a percent everywhere but the last degrees above the horizon.
const AREA_RES: usize = 32;

/// The scan's table as the choice renders it: `D` the regularized empirical NDF ([`Regularized`], the
/// function `ndfit export SCAN --to rgl` tabulates, read without that table's resampling), Smith's `G1`
/// from its projected area, the conductor's Fresnel term.
#[derive(Clone, Copy)]
pub struct ScanBrdf<'a> {
    /// The scan's NDF, regularized.
    pub reg: &'a Regularized<'a>,
    /// Its projected area and normalization.
    pub area: &'a ProjectedArea,
    /// The conductor.
    pub material: Material,
}

impl Brdf for ScanBrdf<'_> {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        // Reflection only; on the horizon the cosines' quotient has the limit 0.
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return [0.0; 3];
        }
        let h = (wi + wo).normalize();
        let bare = self.area.scale * self.reg.d(h) * self.area.g1(wi) * self.area.g1(wo) / (4.0 * wi.z * wo.z);
        self.material.fresnel_rgb(wi.dot(&h)).map(|f| bare * f)
    }

    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], out: &mut [[f64; 3]]) {
        // `G1(wi)` once for every light point (its reading of the `sigma` grid is the costly part).
        let gi = if wi.z > 0.0 { self.area.g1(wi) } else { 0.0 };
        for (o, &wo) in out.iter_mut().zip(wos) {
            // As `eval`: reflection only.
            if !(wi.z > 0.0 && wo.z > 0.0) {
                *o = [0.0; 3];
                continue;
            }
            let h = (wi + wo).normalize();
            let bare = self.area.scale * self.reg.d(h) * gi * self.area.g1(wo) / (4.0 * wi.z * wo.z);
            *o = self.material.fresnel_rgb(wi.dot(&h)).map(|f| bare * f);
        }
    }
}

impl ScanBrdf<'_> {
    /// `f(wi, wo)` as `bare F(c)`, `F` the conductor's Fresnel term, for `wi` and `wo` above the horizon
    /// (`None` otherwise): `(bare, c)` with `c = wi.normalize(wi + wo)`; `gi` is `G1(wi)`.
    #[inline]
    fn unshaded(&self, wi: Vector3<f64>, wo: Vector3<f64>, gi: f64) -> Option<(f64, f64)> {
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return None;
        }
        let h = (wi + wo).normalize();
        let bare = self.area.scale * self.reg.d(h) * gi * self.area.g1(wo) / (4.0 * wi.z * wo.z);
        Some((bare, wi.dot(&h)))
    }
}

/// The scan's table and a lobe rendered in one pass ([`Scene::render_set`]): where both are evaluated
/// at one pair of directions and are of one conductor, the Fresnel term is computed once (both take it
/// at the same cosine, bit for bit; where the cosines differ each takes its own). Each value is what the
/// BRDF's own `eval` gives.
pub struct TableAndLobe<'a> {
    /// The table.
    pub table: ScanBrdf<'a>,
    /// The lobe.
    pub lobe: AnalyticBrdf,
}

impl TableAndLobe<'_> {
    /// Both values from their unshaded forms, one Fresnel term where it is shared.
    #[inline]
    fn shade(&self, table: Option<(f64, f64)>, lobe: Option<(f64, f64)>) -> [[f64; 3]; 2] {
        let material = self.table.material;
        let ft = table.map(|(bare, c)| (bare, c, material.fresnel_rgb(c)));
        let t = ft.map_or([0.0; 3], |(bare, _, f)| f.map(|f| bare * f));
        let l = match (lobe, ft) {
            (None, _) => [0.0; 3],
            (Some((bare, c)), Some((_, ct, f))) if c.to_bits() == ct.to_bits() => f.map(|f| bare * f),
            (Some(_), _) => self.lobe.shaded(lobe),
        };
        [t, l]
    }

    /// Whether the two share their Fresnel term: both are wanted and of one conductor.
    fn shared(&self, active: [bool; 2]) -> bool {
        active == [true; 2] && self.table.material == self.lobe.material
    }
}

impl BrdfSet<2> for TableAndLobe<'_> {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>, active: [bool; 2], out: &mut [[f64; 3]; 2]) {
        if !self.shared(active) {
            return [&self.table as &dyn Brdf, &self.lobe].eval(wi, wo, active, out);
        }
        // As `ScanBrdf::eval`: `G1(wi)` only above the horizon.
        let table = if wi.z > 0.0 && wo.z > 0.0 { self.table.unshaded(wi, wo, self.table.area.g1(wi)) } else { None };
        *out = self.shade(table, self.lobe.unshaded(wi, wo, None));
    }

    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], active: [bool; 2], out: &mut [Vec<[f64; 3]>; 2]) {
        if !self.shared(active) {
            return [&self.table as &dyn Brdf, &self.lobe].eval_many(wi, wos, active, out);
        }
        // As each one's `eval_many`: `G1(wi)` and `Lambda(wi)` once for every light point.
        let gi = if wi.z > 0.0 { self.table.area.g1(wi) } else { 0.0 };
        let lambda_i = self.lobe.shared_lambda(wi);
        let [t, l] = out;
        for ((&wo, t), l) in wos.iter().zip(t.iter_mut()).zip(l.iter_mut()) {
            [*t, *l] = self.shade(self.table.unshaded(wi, wo, gi), self.lobe.unshaded(wi, wo, lambda_i));
        }
    }

    fn mirror(&self, wi: Vector3<f64>, active: [bool; 2]) -> [[f64; 3]; 2] {
        [&self.table as &dyn Brdf, &self.lobe].mirror(wi, active)
    }
}

/// A scene of the choice with the name the report gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedScene {
    /// `point`, `broad` or `window` for the defaults; a stated scene is named by its spec.
    pub name: String,
    /// The scene.
    pub scene: Stage,
}

/// The default scenes: the sphere under a point light (every half vector in one image) and under a broad
/// light (the NDF blurred, as a room lights an object); `data_formats/render.md` states them.
pub fn default_scenes() -> Vec<NamedScene> {
    vec![
        NamedScene { name: "point".into(), scene: Scene::point().into() },
        NamedScene { name: "broad".into(), scene: Scene::broad().into() },
    ]
}

/// The scenes a spec names, comma-separated: `point` or `broad`, each optionally followed by
/// `:KEY=VALUE` changes, `light=THETA/PHI` and `view=THETA/PHI` (degrees, the sphere's frame, `z` its
/// pole), `cap=DEG` (a cap light of that half-angle instead) and `size=N` (pixels); or `window` (the plate
/// under a window, [`Window`]), whose `size=N` is its width (the height three fifths of it). An unknown
/// name or key, a bad number or a scene that cannot be rendered is an error naming it.
pub fn parse_scenes(spec: &str) -> Result<Vec<NamedScene>> {
    let mut out: Vec<NamedScene> = Vec::new();
    for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let mut parts = item.split(':');
        let base = parts.next().unwrap_or("");
        let mut scene = match base {
            "point" => Scene::point(),
            "broad" => Scene::broad(),
            "window" => {
                let mut w = Window::default();
                for kv in parts {
                    let bad = |why: &str| Error::invalid(format!("scene '{item}': '{kv}': {why}"));
                    match kv.split_once('=') {
                        Some(("size", v)) => {
                            w.width = v.trim().parse().map_err(|_| bad("not a pixel count"))?;
                            w.height = (w.width * 3).div_ceil(5);
                        }
                        _ => return Err(bad("the window scene takes only size=N")),
                    }
                }
                w.validate().map_err(|e| Error::invalid(format!("scene '{item}': {}", e.message())))?;
                if !out.iter().any(|s| s.name == item) {
                    out.push(NamedScene { name: item.to_string(), scene: Stage::Window(w) });
                }
                continue;
            }
            _ => return Err(Error::invalid(format!("scene '{item}': unknown scene '{base}' (point, broad or window)"))),
        };
        for kv in parts {
            let bad = |why: &str| Error::invalid(format!("scene '{item}': '{kv}': {why}"));
            let (key, value) = kv.split_once('=').ok_or_else(|| bad("expected KEY=VALUE"))?;
            let number = |v: &str| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| bad("not a finite number"));
            let angles = |v: &str| -> Result<Vector3<f64>> {
                let (t, p) = v.split_once('/').ok_or_else(|| bad("expected THETA/PHI in degrees"))?;
                Ok(direction(number(t)?.to_radians(), number(p)?.to_radians()))
            };
            match key.trim() {
                "light" => {
                    let d = angles(value)?;
                    scene.light = match scene.light {
                        Light::Point { irradiance, .. } => Light::Point { dir: d, irradiance },
                        Light::Cap { half_angle, radiance, .. } => Light::Cap { dir: d, half_angle, radiance },
                    };
                }
                "view" => scene.camera.view = angles(value)?,
                "cap" => {
                    let deg = number(value)?;
                    if !(deg > 0.0 && deg <= 90.0) {
                        return Err(bad("the half-angle must be in (0, 90] degrees"));
                    }
                    let (dir, half_angle) = (light_dir(&scene.light), deg.to_radians());
                    scene.light = Light::Cap { dir, half_angle, radiance: 1.0 / half_angle.sin().powi(2) };
                }
                "size" => scene.camera.size = value.trim().parse().map_err(|_| bad("not a pixel count"))?,
                _ => return Err(bad("unknown key (light, view, cap or size)")),
            }
        }
        scene.validate().map_err(|e| Error::invalid(format!("scene '{item}': {}", e.message())))?;
        if !out.iter().any(|s| s.name == item) {
            out.push(NamedScene { name: item.to_string(), scene: scene.into() });
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(format!("no scene in '{spec}' (point, broad, window, or one with :KEY=VALUE changes)")));
    }
    Ok(out)
}

fn light_dir(light: &Light) -> Vector3<f64> {
    match *light {
        Light::Point { dir, .. } | Light::Cap { dir, .. } => dir,
    }
}

/// One candidate's scores: the mean HDR-FLIP of its render against the table's, per scene, and the worst.
/// A score can stop short (NaN for the scenes not rendered) once its worst already rules the lobe out.
#[derive(Debug, Clone, PartialEq)]
pub struct Score {
    /// The mean FLIP per scene, in the scenes' order (NaN: not rendered).
    pub per_scene: Vec<f64>,
    /// The largest of `per_scene` rendered: the worst, or a lower bound of it when not complete.
    pub worst: f64,
    /// The largest FLIP beyond the table's own noise floor over the scenes rendered
    /// (`per_scene - floor`; `worst` where there is no floor): what the tolerance is held to.
    pub excess: f64,
}

impl Score {
    /// Whether every scene was rendered.
    pub fn complete(&self) -> bool {
        self.per_scene.iter().all(|v| !v.is_nan())
    }

    /// Hold the scenes rendered to new noise `floors`: `excess` becomes the largest `per_scene - floor`.
    fn hold_to(&mut self, floors: &[f64]) {
        self.excess = self.per_scene.iter().zip(floors).filter(|(v, _)| !v.is_nan()).map(|(v, f)| v - f).fold(f64::NEG_INFINITY, f64::max);
    }

    /// The score as the fit report writes it: per scene rendered by name, and `worst` when complete.
    pub fn by_name(&self, scenes: &[NamedScene]) -> BTreeMap<String, f64> {
        let mut m: BTreeMap<String, f64> =
            scenes.iter().map(|s| s.name.clone()).zip(self.per_scene.iter().copied()).filter(|(_, v)| !v.is_nan()).collect();
        if self.complete() {
            m.insert("worst".into(), self.worst);
        }
        m
    }
}

/// What the renders decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The scenes' names, in the scores' order.
    pub scenes: Vec<String>,
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

/// The default render tolerance: the largest mean FLIP beyond the table's noise floor, in every scene, at
/// which a lobe is the answer (data_formats/render.md, "The tolerance").
pub const DEFAULT_RENDER_TOLERANCE: f64 = 0.02;

/// The conductor of the choice's renders unless told otherwise: aluminium, the metal most scanned samples
/// are, and a neutral one (its colour does not weigh one channel's error over another's).
pub const DEFAULT_MATERIAL: Material = Material::Al;

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

/// Whether any pixel of `image` has light.
fn lit(image: &Image) -> bool {
    image.data.iter().flatten().any(|&c| c > 0.0)
}

/// The mean HDR-FLIP of `test` against `reference` where the reference may be black: a lobe narrower
/// than a scene shows (a mirror under a point light) leaves its own table black there. Against a black
/// reference a black test is no difference, and a lit one is seen at its own exposures.
fn flip_black(reference: &Image, test: &Image) -> Result<f64> {
    let exposed = match (lit(reference), lit(test)) {
        (true, _) => reference,
        (false, true) => test,
        (false, false) => return Ok(0.0),
    };
    let to_rgb = |i: &Image| RgbImage::new(i.width, i.height, i.data.clone());
    HdrReference::new(&to_rgb(reference)?, DEFAULT_PPD, &exposures(exposed)?)?.mean(&to_rgb(test)?)
}

/// A score with no scene rendered yet.
fn unscored(scenes: usize) -> Score {
    Score { per_scene: vec![f64::NAN; scenes], worst: 0.0, excess: f64::NEG_INFINITY }
}

/// The table's render prepared as HDR-FLIP's reference at the choice's [`exposures`]: the work on the
/// reference alone is done once for every lobe scored against it.
pub fn prepare(reference: &Image) -> Result<HdrReference> {
    HdrReference::new(&RgbImage::new(reference.width, reference.height, reference.data.clone())?, DEFAULT_PPD, &exposures(reference)?)
}

/// The scores of `lobe` against the `references` (the table's renders in `scenes`, prepared, in order).
fn score(lobe: &dyn Brdf, scenes: &[NamedScene], references: &[HdrReference]) -> Result<Score> {
    let mut so_far = unscored(scenes.len());
    for (k, (s, r)) in scenes.iter().zip(references).enumerate() {
        let img = s.scene.render(lobe)?;
        let v = r.mean(&RgbImage::new(img.width, img.height, img.data)?)?;
        so_far.per_scene[k] = v;
        so_far.worst = so_far.worst.max(v);
        so_far.excess = so_far.excess.max(v);
    }
    Ok(so_far)
}

/// Render the table and every candidate (simplest first) in `scenes`, score each candidate by FLIP
/// against the table, and choose: the first candidate whose worst score is at most `tolerance`, else the
/// table. An empty candidate list is an error (there is no closest lobe to report).
pub fn decide(table: &dyn Brdf, candidates: &[Model], material: Material, scenes: &[NamedScene], tolerance: f64) -> Result<Choice> {
    if candidates.is_empty() || scenes.is_empty() {
        return Err(Error::invalid("the render choice needs at least one candidate lobe and one scene"));
    }
    let references: Vec<HdrReference> = scenes.iter().map(|s| prepare(&s.scene.render(table)?)).collect::<Result<_>>()?;
    let scores: Vec<Score> =
        candidates.iter().map(|&model| score(&AnalyticBrdf { model, material }, scenes, &references)).collect::<Result<_>>()?;
    let answer = scores.iter().position(|s| s.excess <= tolerance);
    let closest = (0..scores.len()).fold(0, |best, k| if scores[k].worst < scores[best].worst { k } else { best });
    Ok(Choice { scenes: scenes.iter().map(|s| s.name.clone()).collect(), scores, answer, closest, tolerance })
}

/// How the render choice runs: its scenes, tolerance and conductor.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// The scenes a lobe must pass in every one ([`default_scenes`], or [`parse_scenes`]).
    pub scenes: Vec<NamedScene>,
    /// The largest mean FLIP beyond the table's noise floor, in every scene, at which a lobe is the answer.
    pub tolerance: f64,
    /// The conductor of both renders.
    pub material: Material,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { scenes: default_scenes(), tolerance: DEFAULT_RENDER_TOLERANCE, material: DEFAULT_MATERIAL }
    }
}

impl RenderOptions {
    /// Refuse a tolerance that is not a positive number, or no scene.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::invalid(format!("render_tolerance must be a positive number, got {}", self.tolerance)));
        }
        if self.scenes.is_empty() {
            return Err(Error::invalid("the render choice needs at least one scene"));
        }
        self.scenes.iter().try_for_each(|s| s.scene.validate())
    }
}

/// What the judge holds of the scan's table: its fit region, and the noise floors of the table filled by
/// the offered lobe with the smallest NDF error.
struct Reference {
    lobe: Model,
    max_theta_deg: f64,
    /// Per scene, the FLIP the table's own counting noise shows ([`RenderJudge::noise_floors`]); measured
    /// only once a lobe fails the tolerance without it (a lobe within it passes whatever the floor).
    floors: Option<Vec<f64>>,
}

/// One half of `ndf`'s dispersion split (the odd row blocks, or the even), scaled to the whole: each bin's
/// `D` from its half's count, its standard error Poisson on that count. `None` without a split.
fn half(ndf: &EmpiricalNdf, odd: bool) -> Option<EmpiricalNdf> {
    if ndf.counts_odd.len() != ndf.bins.len() || ndf.n_samples == 0 {
        return None;
    }
    let f_odd = ndf.counts_odd.iter().sum::<u64>() as f64 / ndf.n_samples as f64;
    let share = if odd { f_odd } else { 1.0 - f_odd };
    // A split with (almost) nothing on one side says nothing about the noise.
    if !(share > 0.05) {
        return None;
    }
    let mut h = ndf.clone();
    for (b, &a) in h.bins.iter_mut().zip(&ndf.counts_odd) {
        let c = if odd { a } else { b.count.saturating_sub(a) };
        b.d = if b.count > 0 { b.d * (c as f64 / b.count as f64) / share } else { 0.0 };
        b.stderr = if c > 0 { b.d / (c as f64).sqrt() } else { 0.0 };
        b.count = c;
    }
    h.n_samples = (ndf.n_samples as f64 * share).round() as u64;
    Some(h)
}

/// What a judge has rendered: the table (with its noise floors) and each lobe's score so far.
type Judged = (Option<Reference>, Vec<(Model, Score)>);

/// The render choice as `auto`'s judge: each lobe, simplest first until one is within the tolerance,
/// rendered against the scan's table filled by that lobe itself ([`ScanBrdf`]: where the bins are too few
/// to trust, the table is the lobe, so no lobe is judged on what the scan does not resolve), each lobe
/// rendered at most once however often it is offered. The noise floors are the table's filled by the
/// offered lobe with the smallest NDF error ([`crate::fit::table_lobe`]), the table `measured` exports.
pub struct RenderJudge<'a> {
    ndf: &'a EmpiricalNdf,
    options: RenderOptions,
    state: Mutex<Judged>,
    /// The bins' quadrature nodes, for every table of the scan's grid (found once, when first needed).
    nodes: OnceLock<BinNodes>,
}

impl<'a> RenderJudge<'a> {
    /// A judge for the scan whose NDF is `ndf`.
    pub fn new(ndf: &'a EmpiricalNdf, options: RenderOptions) -> RenderJudge<'a> {
        RenderJudge { ndf, options, state: Mutex::new((None, Vec::new())), nodes: OnceLock::new() }
    }

    /// The options it runs with.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// The table's renders in each scene, filled by `lobe`, the bins trusted up to `max_theta_deg`.
    pub fn table_images(&self, lobe: &Model, max_theta_deg: f64) -> Result<Vec<Image>> {
        self.images_of(self.ndf, lobe, max_theta_deg)
    }

    fn images_of(&self, ndf: &EmpiricalNdf, lobe: &Model, max_theta_deg: f64) -> Result<Vec<Image>> {
        let (reg, area) = self.table_of(ndf, lobe, max_theta_deg)?;
        let table = ScanBrdf { reg: &reg, area: &area, material: self.options.material };
        self.options.scenes.par_iter().map(|s| s.scene.render(&table)).collect()
    }

    /// The table of `ndf` filled by `lobe`: its regularized NDF and its projected area.
    fn table_of<'n>(&self, ndf: &'n EmpiricalNdf, lobe: &'n Model, max_theta_deg: f64) -> Result<(Regularized<'n>, ProjectedArea)> {
        let _p = crate::phases::phase("choice.table.area");
        let nodes = self.nodes.get_or_init(|| BinNodes::new(self.ndf));
        let reg = Regularized::with_nodes(ndf, lobe, max_theta_deg, nodes);
        let area = ProjectedArea::new(&|m| reg.d(m), AREA_QUAD, AREA_RES, true)?;
        Ok((reg, area))
    }

    /// `so_far` with the scenes it lacks rendered in order, `lobe` against the scan's table filled by
    /// itself (both in one pass, [`TableAndLobe`]), stopping once its excess over the `floors` exceeds
    /// `stop_above` (the lobe can then be neither the answer nor the closest). Unknown `floors` count as 0
    /// until the lobe fails the tolerance without them; then, with `measure` (the filling lobe of the noise
    /// floors' table), they are measured ([`RenderJudge::noise_floors`]), `so_far` is held to them, and the
    /// scenes left go on against the same table.
    fn extend_own(
        &self,
        lobe: &Model,
        max_theta_deg: f64,
        floors: &mut Option<Vec<f64>>,
        measure: Option<&Model>,
        mut so_far: Score,
        stop_above: f64,
    ) -> Result<Score> {
        // A score kept from before the floors were dropped (a new filling lobe) may fail already.
        self.floors_on_failure(&mut so_far, floors, measure, max_theta_deg)?;
        if so_far.complete() || so_far.excess > stop_above {
            return Ok(so_far);
        }
        let (reg, area) = self.table_of(self.ndf, lobe, max_theta_deg)?;
        let material = self.options.material;
        let set = TableAndLobe { table: ScanBrdf { reg: &reg, area: &area, material }, lobe: AnalyticBrdf { model: *lobe, material } };
        for (k, s) in self.options.scenes.iter().enumerate() {
            if so_far.excess > stop_above {
                break;
            }
            if !so_far.per_scene[k].is_nan() {
                continue;
            }
            let v = {
                let _p = crate::phases::phase("choice.lobe");
                let [t, l] = s.scene.render_set(&set)?;
                flip_black(&t, &l)?
            };
            so_far.per_scene[k] = v;
            so_far.worst = so_far.worst.max(v);
            so_far.excess = so_far.excess.max(v - floors.as_ref().map_or(0.0, |f| f[k]));
            self.floors_on_failure(&mut so_far, floors, measure, max_theta_deg)?;
        }
        Ok(so_far)
    }

    /// Where the `floors` are unknown and `so_far` fails the tolerance without them, measure them with the
    /// filling lobe `measure` (if given) and hold `so_far` to them.
    fn floors_on_failure(
        &self,
        so_far: &mut Score,
        floors: &mut Option<Vec<f64>>,
        measure: Option<&Model>,
        max_theta_deg: f64,
    ) -> Result<()> {
        if let (None, Some(filler)) = (floors.as_ref(), measure) {
            if so_far.excess > self.options.tolerance {
                let measured = self.noise_floors(filler, max_theta_deg)?;
                so_far.hold_to(&measured);
                *floors = Some(measured);
            }
        }
        Ok(())
    }

    /// Per scene, the FLIP the table's own counting noise shows: half the FLIP between the tables of the
    /// two halves of the scan's dispersion split (each half's noise is `sqrt 2` times the whole's, and
    /// their difference `sqrt 2` times a half's: twice the whole table's noise against its truth). Even a
    /// lobe equal to the scan's true NDF scores about this against the table. Zeros without a split.
    pub fn noise_floors(&self, lobe: &Model, max_theta_deg: f64) -> Result<Vec<f64>> {
        let (Some(a), Some(b)) = (half(self.ndf, true), half(self.ndf, false)) else {
            return Ok(vec![0.0; self.options.scenes.len()]);
        };
        let (ia, ib) = rayon::join(|| self.images_of(&a, lobe, max_theta_deg), || self.images_of(&b, lobe, max_theta_deg));
        let (ia, ib) = (ia?, ib?);
        ia.par_iter().zip(&ib).map(|(x, y)| Ok(0.5 * flip_black(x, y)?)).collect()
    }

    /// The noise floors of the last decision's table (`None` before any decision).
    pub fn floors(&self) -> Option<Vec<f64>> {
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.0.as_ref().and_then(|r| r.floors.clone())
    }

    /// The renders of the scan's table filled by `lobe`, the table `lobe` is scored against (in the last
    /// decision's fit region). An error before any decision.
    pub fn table_renders(&self, lobe: &Model) -> Result<Vec<Image>> {
        let max_theta_deg = {
            let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
            state.0.as_ref().map(|r| r.max_theta_deg).ok_or_else(|| Error::invalid("no table rendered yet: the judge has not decided"))?
        };
        self.table_images(lobe, max_theta_deg)
    }

    /// The scores of every lobe of `lobes` against the last decision's table, rendering those not yet
    /// rendered (a report of every candidate, not only those the decision needed). An error before any
    /// decision.
    pub fn scores(&self, lobes: &[Model]) -> Result<Vec<Score>> {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let n = self.options.scenes.len();
        let Some((max_theta_deg, floors)) = state.0.as_ref().map(|r| (r.max_theta_deg, r.floors.clone().unwrap_or(vec![0.0; n]))) else {
            return Err(Error::invalid("no table rendered yet: the judge has not decided"));
        };
        let mut out = Vec::with_capacity(lobes.len());
        for &model in lobes {
            let at = state.1.iter().position(|(m, _)| *m == model);
            let so_far = at.map_or(unscored(self.options.scenes.len()), |i| state.1[i].1.clone());
            let s = self.extend_own(&model, max_theta_deg, &mut Some(floors.clone()), None, so_far, f64::INFINITY)?;
            match at {
                Some(i) => state.1[i].1 = s.clone(),
                None => state.1.push((model, s.clone())),
            }
            out.push(s);
        }
        Ok(out)
    }

    /// The scores of `lobe` so far (`None`: not rendered).
    pub fn score_of(&self, lobe: &Model) -> Option<Score> {
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.1.iter().find(|(m, _)| m == lobe).map(|(_, s)| s.clone())
    }
}

impl RenderJudge<'_> {
    /// Write the choice into `report` (an `auto` fit decided by this judge): `selection.answer`,
    /// `render_error` (of `model`, the answer's lobe or the closest), the scores of the lobes rendered,
    /// and the verdict: `ok` when a renderer cannot tell the lobe from the scan's table, `misfit` with
    /// the command that writes the table when no lobe is close enough, `unresolved` as the data said. The
    /// NDF's own reasons stay, marked as the NDF's. `scan` names the scan in the command.
    pub fn apply(&self, report: &mut crate::fit::FitReport, scan: &str) -> Result<()> {
        use crate::fit::Verdict;
        let opts = &self.options;
        let model = report.to_model()?;
        let Some(sel) = report.selection.as_mut() else {
            return Err(Error::invalid("the render choice applies to an `auto` fit (no selection in the report)"));
        };
        for c in sel.candidates.iter_mut() {
            let p: Vec<f64> = c.model.param_names().iter().map(|n| c.params.get(*n).copied().unwrap_or(f64::NAN)).collect();
            c.render_error = Model::from_params(c.model, &p).ok().and_then(|m| self.score_of(&m)).map(|s| s.by_name(&opts.scenes));
        }
        let score = self.score_of(&model);
        let worst = score.as_ref().map_or(f64::INFINITY, |s| s.worst);
        let excess = score.as_ref().map_or(f64::INFINITY, |s| s.excess);
        let supported = sel.candidates.iter().find(|c| c.model == model.id()).and_then(|c| c.supported).unwrap_or(true);
        let is_answer = supported && excess <= opts.tolerance;
        let floors = self.floors().unwrap_or_default();
        let worst_floor = floors.iter().copied().fold(0.0, f64::max);
        let names: Vec<&str> = opts.scenes.iter().map(|s| s.name.as_str()).collect();
        sel.answer = Some(if is_answer { model.id().as_str().to_string() } else { "measured".to_string() });
        sel.render_error = score.as_ref().map(|s| s.by_name(&opts.scenes));
        sel.render_tolerance = Some(opts.tolerance);
        sel.render_noise = (!floors.is_empty()).then(|| opts.scenes.iter().map(|s| s.name.clone()).zip(floors.iter().copied()).collect());
        sel.scenes = names.iter().map(|n| n.to_string()).collect();
        let sentence = if is_answer {
            format!(
                "a renderer cannot tell {} from the scan's table: worst mean FLIP {worst:.4}, beyond the table's own noise ({worst_floor:.4} at most) {excess:.4} <= {} over the scenes {} ({})",
                model.id(),
                opts.tolerance,
                names.join(", "),
                opts.material.as_str()
            )
        } else {
            format!(
                "no lobe renders within mean FLIP {} of the scan's table beyond its own noise in every scene ({}); the closest, {}, is at {worst:.4} ({excess:.4} beyond the noise): the material is the table, `ndfit export {scan} --to rgl -o OUT.bsdf` (with the reading and fit options given here)",
                opts.tolerance,
                names.join(", "),
                model.id()
            )
        };
        let q = &mut report.quality;
        let ndf_reasons: Vec<String> = q.reasons.iter().map(|r| format!("by the NDF alone: {r}")).collect();
        // The NDF's misfit lines in the warnings are the render's call now.
        let before = q.verdict;
        if before != Verdict::Unresolved {
            q.verdict = if is_answer { Verdict::Ok } else { Verdict::Misfit };
            if before == Verdict::Misfit {
                report.warnings.retain(|w| !w.starts_with("misfit: "));
            }
            if !is_answer {
                report.warnings.push(format!("misfit: {sentence}"));
            }
        }
        q.reasons = if before == Verdict::Unresolved {
            // The data's reasons stay the verdict's; the render's sentence follows them.
            q.reasons.iter().cloned().chain(std::iter::once(sentence)).collect()
        } else {
            std::iter::once(sentence).chain(ndf_reasons).collect()
        };
        // A verdict other than ok says every reason in the warnings too (and so on standard error).
        if q.verdict != Verdict::Ok {
            for r in &q.reasons {
                if !report.warnings.iter().any(|w| w.contains(r.as_str())) {
                    report.warnings.push(format!("{}: {r}", q.verdict));
                }
            }
        }
        Ok(())
    }
}

impl RenderJudge<'_> {
    /// `lobe`'s complete score against the last decision's table, held to the table's noise floors
    /// when it fails without them (measured then, as a decision measures them): whether the lobe passes
    /// here, not only where the decision stopped. An error before any decision.
    pub fn full_score(&self, lobe: &Model) -> Result<Score> {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let opts = &self.options;
        let Some(reference) = state.0.as_ref() else {
            return Err(Error::invalid("no table rendered yet: the judge has not decided"));
        };
        let (filler, max_theta_deg, known) = (reference.lobe, reference.max_theta_deg, reference.floors.clone());
        let at = state.1.iter().position(|(m, _)| m == lobe);
        let so_far = at.map_or(unscored(opts.scenes.len()), |i| state.1[i].1.clone());
        let mut floors = known.clone();
        let s = self.extend_own(lobe, max_theta_deg, &mut floors, Some(&filler), so_far, f64::INFINITY)?;
        if let (None, Some(floors)) = (known, floors) {
            state.1.iter_mut().for_each(|(_, sc)| sc.hold_to(&floors));
            state.0.as_mut().expect("the table was rendered above").floors = Some(floors);
        }
        match at {
            Some(i) => state.1[i].1 = s.clone(),
            None => state.1.push((*lobe, s.clone())),
        }
        Ok(s)
    }
}

impl Decide for RenderJudge<'_> {
    fn decide(&self, offered: &[Offered], max_theta_deg: f64) -> Result<Decision> {
        if offered.is_empty() {
            return Err(Error::invalid("the render choice needs at least one candidate lobe"));
        }
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let filler = offered[crate::fit::table_lobe(&offered.iter().map(|o| o.delta_data).collect::<Vec<_>>())].model;
        // Each lobe is scored against its own table, so a score stays; a new fit region (the old scores go)
        // or a new filling lobe (the whole ladder fitted after all: the floors go) is a new reference.
        if state.0.as_ref().is_none_or(|r| r.max_theta_deg != max_theta_deg) {
            *state = (Some(Reference { lobe: filler, max_theta_deg, floors: None }), Vec::new());
        } else if state.0.as_ref().is_some_and(|r| r.lobe != filler) {
            let r = state.0.as_mut().expect("checked above");
            if r.floors.take().is_some() {
                state.1.iter_mut().for_each(|(_, sc)| sc.hold_to(&vec![0.0; sc.per_scene.len()]));
            }
            state.0.as_mut().expect("checked above").lobe = filler;
        }
        let opts = &self.options;
        let mut answer = None;
        let mut closest: Option<(usize, f64)> = None;
        for (k, o) in offered.iter().enumerate().filter(|(_, o)| o.supported) {
            // A lobe whose excess so far exceeds both the tolerance and the closest complete one is out.
            let stop_above = opts.tolerance.max(closest.map_or(f64::INFINITY, |(_, w)| w));
            let at = state.1.iter().position(|(m, _)| *m == o.model);
            let so_far = at.map_or(unscored(opts.scenes.len()), |i| state.1[i].1.clone());
            // The first lobe that fails without the floor makes the floor worth measuring (in its pass, with
            // its table): every score so far is then held to it.
            let known = state.0.as_ref().expect("set above").floors.clone();
            let mut floors = known.clone();
            let s = self.extend_own(&o.model, max_theta_deg, &mut floors, Some(&filler), so_far, stop_above)?;
            if let (None, Some(floors)) = (known, floors) {
                state.1.iter_mut().for_each(|(_, sc)| sc.hold_to(&floors));
                state.0.as_mut().expect("set above").floors = Some(floors);
            }
            match at {
                Some(i) => state.1[i].1 = s.clone(),
                None => state.1.push((o.model, s.clone())),
            }
            if !s.complete() {
                continue;
            }
            if closest.is_none_or(|(_, w)| s.excess < w) {
                closest = Some((k, s.excess));
            }
            if s.excess <= opts.tolerance {
                answer = Some(k);
                break;
            }
        }
        // No lobe the guard supports: the simplest lobe is reported (and the table answers).
        let reported = answer.or(closest.map(|(k, _)| k)).unwrap_or(0);
        Ok(Decision { answer, reported })
    }
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

    /// A scan's NDF (an ellipsoid cap) and its truth as a lobe.
    fn cap_ndf() -> (EmpiricalNdf, Model) {
        use crate::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
        let p = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.15, theta_z: 0.4, ..Default::default() };
        let (hf, truth) = ellipsoid_surface(&SynthSettings { nx: 160, ny: 160, ..Default::default() }, &p).unwrap();
        let scan = crate::preprocess::apply(hf, &crate::preprocess::Preprocess::default()).unwrap();
        (crate::ndf::empirical_ndf(&scan, &crate::ndf::NdfOptions::default()).unwrap(), truth.to_model().unwrap())
    }

    /// Light points about a shading point: every direction of a coarse grid of the hemisphere, and a few
    /// below the horizon.
    fn directions() -> Vec<Vector3<f64>> {
        let mut d: Vec<Vector3<f64>> =
            (0..9).flat_map(|i| (0..16).map(move |j| direction(i as f64 * 0.19, j as f64 * 0.4 - 3.0))).collect();
        d.push(direction(1.7, 0.2));
        d.push(Vector3::new(0.0, 0.0, 1.0));
        d
    }

    /// `eval_many` gives, bit for bit, what `eval` gives pair by pair: the table's and every kind of lobe
    /// (Smith lobes, whose `Lambda(wi)` is shared, the ellipsoid and a mixture), for `wi` from the normal
    /// to below the horizon.
    #[test]
    fn evaluating_many_light_points_equals_one_by_one() {
        let (ndf, truth) = cap_ndf();
        let reg = Regularized::new(&ndf, &truth, 40.0);
        let area = ProjectedArea::new(&|m| reg.d(m), 24, 12, true).unwrap();
        let table = ScanBrdf { reg: &reg, area: &area, material: Material::Al };
        let lobes = [
            ggx(0.3),
            Model::from_params(ModelId::GgxAniso, &[0.3, 0.1, 0.7]).unwrap(),
            Model::from_params(ModelId::BeckmannAniso, &[0.2, 0.35, -0.3]).unwrap(),
            Model::from_params(ModelId::Student, &[0.25, 2.5]).unwrap(),
            truth,
            Model::from_params(ModelId::Ggx2, &[0.05, 0.05, 0.5, 0.5, 0.0, 0.5]).unwrap(),
        ];
        let analytic: Vec<AnalyticBrdf> = lobes.iter().map(|&model| AnalyticBrdf { model, material: Material::Au }).collect();
        let wos = directions();
        for wi in [direction(0.0, 0.0), direction(0.4, 1.0), direction(1.2, -2.0), direction(1.5, 0.3), direction(1.8, 0.0)] {
            for brdf in std::iter::once(&table as &dyn Brdf).chain(analytic.iter().map(|a| a as &dyn Brdf)) {
                let mut many = vec![[f64::NAN; 3]; wos.len()];
                brdf.eval_many(wi, &wos, &mut many);
                for (&wo, m) in wos.iter().zip(&many) {
                    assert_eq!(m.map(f64::to_bits), brdf.eval(wi, wo).map(f64::to_bits), "{wi:?} {wo:?}");
                }
            }
        }
    }

    /// The table and a lobe rendered in one pass, sharing the Fresnel term, are bit for bit each one
    /// rendered alone as the renderer rendered it before (`render::before`): Smith lobes, the ellipsoid
    /// and a mixture, in both default scenes, of one conductor and of two.
    #[test]
    fn the_table_and_a_lobe_together_render_as_alone() {
        use crate::render::before::render_before;
        let (ndf, truth) = cap_ndf();
        let reg = Regularized::new(&ndf, &truth, 40.0);
        let area = ProjectedArea::new(&|m| reg.d(m), 24, 12, true).unwrap();
        let bits = |i: &Image| i.data.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        let lobes = [
            (ggx(0.3), Material::Al),
            (Model::from_params(ModelId::BeckmannAniso, &[0.2, 0.35, -0.3]).unwrap(), Material::Al),
            (truth, Material::Al),
            (Model::from_params(ModelId::Ggx2, &[0.05, 0.05, 0.5, 0.5, 0.0, 0.5]).unwrap(), Material::Al),
            (ggx(0.2), Material::Au),
        ];
        for (model, material) in lobes {
            let table = ScanBrdf { reg: &reg, area: &area, material: Material::Al };
            let lobe = AnalyticBrdf { model, material };
            for s in default_scenes() {
                let Stage::Sphere(scene) = s.scene else { continue };
                let [t, l] = s.scene.render_set(&TableAndLobe { table, lobe }).unwrap();
                assert_eq!(bits(&t), bits(&render_before(&scene, &table)), "{} {model:?}", s.name);
                assert_eq!(bits(&l), bits(&render_before(&scene, &lobe)), "{} {model:?}", s.name);
            }
        }
    }

    /// The judge scores each lobe against the scan's table filled by that lobe (the same values as scoring
    /// it alone against that table's renders, and not those against another lobe's table), and a later
    /// lobe still stops at the first scene that rules it out.
    #[test]
    fn the_judge_scores_each_lobe_against_its_own_table_and_stops_the_rest() {
        let (ndf, truth) = cap_ndf();
        let judge = RenderJudge::new(&ndf, RenderOptions::default());
        let (near, far) = (ggx(0.08), ggx(0.03));
        let offered = [
            Offered { model: near, supported: true, delta_data: Some(0.5) },
            Offered { model: far, supported: true, delta_data: Some(0.9) },
            Offered { model: truth, supported: false, delta_data: Some(0.01) },
        ];
        let d = judge.decide(&offered, 40.0).unwrap();
        assert_eq!(d.answer, None);
        let bits = |s: &Score| s.per_scene.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let against = |filler: &Model, lobe: &Model| {
            let references: Vec<HdrReference> = judge.table_renders(filler).unwrap().iter().map(|i| prepare(i).unwrap()).collect();
            score(&AnalyticBrdf { model: *lobe, material: DEFAULT_MATERIAL }, &default_scenes(), &references).unwrap()
        };
        let first = judge.score_of(&near).unwrap();
        assert!(first.complete(), "{first:?}");
        assert_eq!(bits(&first), bits(&against(&near, &near)));
        assert_ne!(bits(&first), bits(&against(&truth, &near)));
        let second = judge.score_of(&far).unwrap();
        assert!(!second.complete() && !second.per_scene[0].is_nan(), "{second:?}");
        assert_eq!(second.per_scene[0].to_bits(), against(&far, &far).per_scene[0].to_bits());
    }

    /// The scan's NDF with every bin holding `mean(k)` exactly (no noise: each bin trusted alone).
    fn exact_bins(ndf: &EmpiricalNdf, mean: impl Fn(usize) -> f64) -> EmpiricalNdf {
        let mut exact = ndf.clone();
        for (k, b) in exact.bins.iter_mut().enumerate() {
            (b.d, b.stderr, b.count) = (mean(k), 0.0, b.count.max(1));
        }
        exact
    }

    /// A table whose bins hold a lobe's own means over them (by a finer quadrature than the table's)
    /// reads that lobe wherever it is filled by it, down to its tail 1e-4 of its peak (the renders judge to 1e-3): a bin's mean
    /// is not taken for its centre's value (which drew a ring around the highlight), and the table renders
    /// as the lobe.
    #[test]
    fn a_table_of_a_lobes_bin_means_reads_the_lobe() {
        use crate::models::Ndf;
        let (ndf, _) = cap_ndf();
        let truth = Model::from_params(ModelId::BeckmannAniso, &[0.35, 0.2, 0.4]).unwrap();
        let means: Vec<f64> = (0..ndf.bins.len())
            .map(|k| ndf.bin_integral(k, crate::ndf::QuadOrder::Fine(3), |m| truth.d(m)).unwrap() / ndf.bins[k].proj_solid_angle)
            .collect();
        let exact = exact_bins(&ndf, |k| means[k]);
        let reg = Regularized::new(&exact, &truth, 60.0);
        let peak = truth.d(Vector3::z());
        let mut checked = 0;
        for i in 0..120 {
            for j in 0..60 {
                let m = direction(i as f64 * 0.5f64.to_radians(), j as f64 * 0.105);
                if m.z >= 60f64.to_radians().cos() && truth.d(m) > 1e-4 * peak {
                    checked += 1;
                    // Far in the tail the two quadratures of a bin's mean part by up to a percent.
                    let tol = if truth.d(m) > 1e-3 * peak { 2e-3 } else { 2e-2 };
                    let rel = reg.d(m) / truth.d(m) - 1.0;
                    assert!(rel.abs() < tol, "{m:?}: {rel} at {} of the peak", truth.d(m) / peak);
                }
            }
        }
        assert!(checked > 3000, "{checked}");
        let lobe = AnalyticBrdf { model: truth, material: Material::Al };
        let area = ProjectedArea::new(&|m| reg.d(m), AREA_QUAD, AREA_RES, true).unwrap();
        let table = ScanBrdf { reg: &reg, area: &area, material: Material::Al };
        for s in default_scenes() {
            let v = flip_mean(&s.scene.render(&table).unwrap(), &s.scene.render(&lobe).unwrap()).unwrap();
            assert!(v < 0.002, "{}: {v}", s.name);
        }
    }

    /// A lobe far narrower than a bin (its mean over the bins around its peak underflows) fills the table
    /// with finite values no larger than the fit or the data allow, and the table renders: an unguarded
    /// ratio to such a fit overflows.
    #[test]
    fn a_fit_narrower_than_a_bin_keeps_the_table_finite() {
        use crate::models::Ndf;
        let (ndf, _) = cap_ndf();
        let largest = ndf.bins.iter().map(|b| b.d).fold(0.0, f64::max);
        for alpha in [1e-3, 1e-4] {
            let narrow = Model::from_params(ModelId::Beckmann, &[alpha]).unwrap();
            let reg = Regularized::new(&ndf, &narrow, 60.0);
            for i in 0..400 {
                for j in 0..40 {
                    let m = direction(i as f64 * 0.02f64.to_radians(), j as f64 * 0.157);
                    let (v, f) = (reg.d(m), narrow.d(m));
                    // The blended bins lie between the data and the fit's bin means, which are below its peak.
                    assert!(v.is_finite() && v >= 0.0 && v <= f.max(largest).max(narrow.d(Vector3::z())), "alpha {alpha}, {m:?}: {v}");
                }
            }
            let area = ProjectedArea::new(&|m| reg.d(m), AREA_QUAD, AREA_RES, true).unwrap();
            assert!(area.normalization.is_finite() && area.normalization > 0.0, "alpha {alpha}: {}", area.normalization);
            let img = Scene::point().render(&ScanBrdf { reg: &reg, area: &area, material: Material::Al }).unwrap();
            assert!(img.data.iter().flatten().all(|v| v.is_finite()), "alpha {alpha}");
        }
    }

    /// A lobe narrower than the point scene can show (its own table black there, as a mirror under a point
    /// light) is judged, not an error that stops the choice: black against black is no difference.
    #[test]
    fn a_lobe_too_narrow_for_a_scene_is_judged() {
        let (ndf, _) = cap_ndf();
        let judge = RenderJudge::new(&ndf, RenderOptions::default());
        let narrow = Model::from_params(ModelId::Beckmann, &[1e-4]).unwrap();
        let d = judge.decide(&[Offered { model: narrow, supported: true, delta_data: Some(0.9) }], 40.0).unwrap();
        let s = judge.score_of(&narrow).unwrap();
        assert!(s.per_scene.iter().all(|v| v.is_finite()), "{s:?} {d:?}");
        let black = Image { width: 4, height: 4, data: vec![[0.0; 3]; 16] };
        let mut lit = black.clone();
        lit.data[5] = [1.0; 3];
        assert_eq!(flip_black(&black, &black).unwrap(), 0.0);
        assert!(flip_black(&black, &lit).unwrap() > 0.0);
    }

    /// Stated scenes change what they name and nothing else; a bad name, key or value is refused naming it.
    #[test]
    fn scene_specs_state_their_changes() {
        let s = parse_scenes("point, broad:cap=40:light=30/0:size=48,point").unwrap();
        assert_eq!(s.len(), 2, "the repeated point is one scene");
        assert_eq!((s[0].name.as_str(), &s[0].scene), ("point", &Stage::Sphere(Scene::point())));
        let Stage::Sphere(b) = &s[1].scene else { panic!("a sphere") };
        assert_eq!(b.camera.size, 48);
        assert_eq!(b.camera.view, Scene::broad().camera.view);
        let Light::Cap { dir, half_angle, radiance } = b.light else { panic!("a cap") };
        assert!((dir - direction(30f64.to_radians(), 0.0)).norm() < 1e-12);
        assert!((half_angle - 40f64.to_radians()).abs() < 1e-12);
        // A white Lambertian surface facing the cap still shows 1.
        assert!((radiance * half_angle.sin().powi(2) - 1.0).abs() < 1e-12);
        let p = parse_scenes("point:view=0/0:cap=10").unwrap();
        let Stage::Sphere(p) = p[0].scene else { panic!("a sphere") };
        assert!(matches!(p.light, Light::Cap { .. }));
        assert!((p.camera.view - Vector3::z()).norm() < 1e-12);
        let w = parse_scenes("window:size=80").unwrap();
        assert_eq!(w[0].scene, Stage::Window(Window { width: 80, height: 48, ..Window::default() }));
        for (bad, says) in [
            ("spot", "unknown scene 'spot'"),
            ("point:light=30", "THETA/PHI"),
            ("point:glow=1", "unknown key"),
            ("broad:cap=0", "(0, 90]"),
            ("point:size=0", "image size"),
            ("window:size=0", "image size"),
            ("window:light=30/0", "only size=N"),
            ("point:light=a/3", "not a finite number"),
            ("", "no scene"),
        ] {
            let e = parse_scenes(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
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
