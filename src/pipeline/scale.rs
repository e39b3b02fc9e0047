//! `ndfit scale`'s answer by the render: at every footprint the NDF a renderer sees there is made a
//! table (as `auto` makes the scan's), each candidate fitted there is rendered against it in the render
//! choice's scenes (`answer::choice`), and the answer is the simplest candidate within the render
//! tolerance at every footprint, or the measured NDF when none is (data_formats/scale.md sec. 9).

use serde::Serialize;

use crate::answer::choice::{RenderJudge, RenderOptions, Score};
use crate::error::Result;
use crate::fit::{Decide, Offered};
use crate::models::{Model, ModelId};
use crate::ndf::EmpiricalNdf;
use crate::scale::{FootprintResult, Recommendation};

/// One candidate's standing in the render rule, over the footprints it was rendered at.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderedCandidate {
    /// Model id.
    pub model: ModelId,
    /// Number of parameters.
    pub n_params: usize,
    /// Per footprint rendered (ascending), the worst mean FLIP over the scenes against that footprint's
    /// table (`None` where the lobe was not rendered in every scene).
    pub worst_by_footprint: Vec<AtFootprint<Option<f64>>>,
    /// The largest FLIP beyond the tables' noise floors over the footprints rendered: what the tolerance
    /// holds (`None`: never rendered).
    pub worst_excess: Option<f64>,
    /// Within the tolerance at every footprint (`None`: not decided, a simpler candidate already passed).
    pub passes: Option<bool>,
}

/// What the render rule answers for a set of footprints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderRecommendation {
    /// The model a renderer should use at these footprints, or `measured` when no lobe renders within
    /// the tolerance at all of them (the NDF at the footprint itself is then what the scene needs).
    pub answer: String,
    /// The largest mean FLIP beyond the tables' noise, in every scene and at every footprint, of the answer.
    pub tolerance: f64,
    /// The scenes rendered, by name.
    pub scenes: Vec<String>,
    /// The conductor of the renders.
    pub material: &'static str,
    /// The candidates in the NDF rule's order (simplest first), with what their renders showed.
    pub candidates: Vec<RenderedCandidate>,
    /// Per footprint (ascending): the lobe that footprint alone would answer, or `measured`.
    pub per_footprint: Vec<AtFootprint<String>>,
    /// The reasoning in plain words.
    pub explanation: String,
}

/// A value at one footprint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AtFootprint<T> {
    /// The footprint (metres).
    pub footprint_m: f64,
    /// What holds there.
    pub value: T,
}

/// The render rule over `results` (the footprints a recommendation covers), candidates in the order of
/// the NDF rule's recommendation `ndf_rec` (simplest first). Each footprint's judge first decides alone
/// (the first candidate within the tolerance there); the answer is then the first candidate from the
/// latest of those answers on that is within the tolerance at every footprint. Lobes are rendered only
/// as the rule needs them.
pub fn recommend_rendered(results: &[FootprintResult], ndf_rec: &Recommendation, opts: &RenderOptions) -> Result<RenderRecommendation> {
    opts.validate()?;
    // With no footprint every candidate would pass vacuously.
    if results.is_empty() {
        return Err(crate::error::Error::invalid("the render rule needs at least one footprint"));
    }
    let ids: Vec<ModelId> = ndf_rec.candidates.iter().map(|c| c.model).collect();
    let max_theta_deg = crate::fit::FitOptions::default().max_theta.to_degrees();
    // Each footprint's NDF with its spatial halves as the split the judges measure the table's noise by.
    let ndfs: Vec<EmpiricalNdf> = results
        .iter()
        .map(|r| {
            let mut ndf = r.ndf_at.clone();
            ndf.counts_odd = r.first_half.clone();
            ndf
        })
        .collect();
    let judges: Vec<RenderJudge> = ndfs.iter().map(|n| RenderJudge::new(n, opts.clone())).collect();
    // Per footprint, each candidate's lobe fitted there (None: its empirical route failed).
    let lobes: Vec<Vec<Option<Model>>> = results
        .iter()
        .map(|r| ids.iter().map(|id| r.models.iter().find(|m| m.id == *id).and_then(|m| m.empirical.model)).collect())
        .collect();
    let mut scores: Vec<Vec<Option<Score>>> = vec![vec![None; ids.len()]; results.len()];
    // Each footprint alone: the index (into `ids`) of its answer, None for the table.
    let mut alone: Vec<Option<usize>> = Vec::with_capacity(results.len());
    for (k, r) in results.iter().enumerate() {
        let at: Vec<usize> = (0..ids.len()).filter(|&i| lobes[k][i].is_some()).collect();
        if at.is_empty() {
            alone.push(None);
            continue;
        }
        let delta = |i: usize| r.models.iter().find(|m| m.id == ids[i]).and_then(|m| m.empirical.delta).map(|d| d.delta);
        let offered: Vec<Offered> = at
            .iter()
            .map(|&i| Offered { model: lobes[k][i].expect("offered lobes exist"), supported: true, delta_data: delta(i) })
            .collect();
        let d = judges[k].decide(&offered, max_theta_deg)?;
        for &i in &at {
            scores[k][i] = judges[k].score_of(&lobes[k][i].expect("offered lobes exist"));
        }
        alone.push(d.answer.map(|a| at[a]));
    }
    // The simplest candidate at or after every footprint's own answer that passes at all of them.
    let mut answer = None;
    if let Some(start) = alone.iter().try_fold(0usize, |s, a| a.map(|a| s.max(a))) {
        'candidates: for i in start..ids.len() {
            for k in 0..results.len() {
                let Some(lobe) = lobes[k][i] else { continue 'candidates };
                let s = judges[k].full_score(&lobe)?;
                let pass = s.complete() && s.excess <= opts.tolerance;
                scores[k][i] = Some(s);
                if !pass {
                    continue 'candidates;
                }
            }
            answer = Some(i);
            break;
        }
    }
    let candidates: Vec<RenderedCandidate> = ids
        .iter()
        .enumerate()
        .map(|(i, &id)| {
            let rendered: Vec<(usize, &Score)> = (0..results.len()).filter_map(|k| scores[k][i].as_ref().map(|s| (k, s))).collect();
            let worst_by_footprint = rendered
                .iter()
                .map(|(k, s)| AtFootprint { footprint_m: results[*k].stats.footprint, value: s.complete().then_some(s.worst) })
                .collect();
            let worst_excess = rendered.iter().map(|(_, s)| s.excess).fold(None, |a: Option<f64>, e| Some(a.map_or(e, |a| a.max(e))));
            let failed = rendered.iter().any(|(_, s)| s.complete() && s.excess > opts.tolerance);
            let passes = if Some(i) == answer {
                Some(true)
            } else if failed || answer.is_none_or(|a| i < a) {
                Some(false)
            } else {
                None
            };
            RenderedCandidate { model: id, n_params: id.n_params(), worst_by_footprint, worst_excess, passes }
        })
        .collect();
    let per_footprint: Vec<AtFootprint<String>> = results
        .iter()
        .zip(&alone)
        .map(|(r, a)| AtFootprint {
            footprint_m: r.stats.footprint,
            value: a.map_or("measured".to_string(), |i| ids[i].as_str().to_string()),
        })
        .collect();
    let names: Vec<String> = opts.scenes.iter().map(|s| s.name.clone()).collect();
    let explanation = explain(answer.map(|i| &candidates[i]), &candidates, &per_footprint, opts, &names);
    Ok(RenderRecommendation {
        answer: answer.map_or("measured".to_string(), |i| ids[i].as_str().to_string()),
        tolerance: opts.tolerance,
        scenes: names,
        material: opts.material.as_str(),
        candidates,
        per_footprint,
        explanation,
    })
}

/// The render rule's reasoning in plain words.
fn explain(
    chosen: Option<&RenderedCandidate>,
    candidates: &[RenderedCandidate],
    per_footprint: &[AtFootprint<String>],
    opts: &RenderOptions,
    names: &[String],
) -> String {
    let mut words = vec![format!(
        "By the render: at each footprint the NDF a renderer sees there was made a table, and each model fitted there was rendered against it ({}; {}); a model passes a footprint when its mean FLIP beyond the table's own noise is at most {} in every scene.",
        names.join(", "),
        opts.material.as_str(),
        opts.tolerance
    )];
    let each: Vec<String> = per_footprint.iter().map(|a| format!("{} at {:.3e} m", a.value, a.footprint_m)).collect();
    words.push(format!("Each footprint alone answers {}.", each.join(", ")));
    for c in candidates.iter().filter(|c| c.passes == Some(false) && c.worst_excess.is_some()) {
        words.push(format!("{} renders {:.3} beyond the noise at worst: rejected.", c.model, c.worst_excess.unwrap_or(f64::NAN)));
    }
    words.push(match chosen {
        Some(c) => format!(
            "{} ({} parameter{}) is the simplest a renderer cannot tell from the measured NDF at every footprint ({:.3} beyond the noise at worst).",
            c.model,
            c.n_params,
            if c.n_params == 1 { "" } else { "s" },
            c.worst_excess.unwrap_or(f64::NAN)
        ),
        None => "No model renders within the tolerance at every footprint: only the measured NDF at those footprints shows what the scene needs (ndfit writes the scan's own table, at its sampling, with `ndfit export SCAN --to rgl`; not yet one per footprint).".into(),
    });
    words.join(" ")
}
