//! Tilted planes: one plane (a delta NDF) or several plane strips side by side (a sum of deltas).
//!
//! Facet `k` covers a strip of whole columns, widths proportional to the requested weights; its heights
//! are `h = s_x (x - x_k) + s_y y + h_k` with `h_k` chosen so that neighbouring strips meet along the
//! grid's middle row (they meet everywhere when their `s_y` agree; otherwise a step grows with |y|).
//! Central differences and triangles are exact on a plane, so every stencil wholly inside a strip has
//! exactly the facet's normal; only stencils straddling a strip boundary see anything else.

use serde_json::json;

use super::{FacetTruth, SynthSettings, Truth};
use crate::error::{Error, Result};
use crate::scan::Heightfield;

/// One plane facet: its slope `grad h` and its relative share of the grid's columns.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlaneFacet {
    /// Slope `(dh/dx, dh/dy)` (Heitz eq. 61).
    pub slope: [f64; 2],
    /// Relative weight (> 0); weights are normalized over the facets.
    pub weight: f64,
}

/// The strips of `facets` on the grid of `s` and their truth (model `planes`, no contract model).
pub fn tilted_planes(s: &SynthSettings, facets: &[PlaneFacet]) -> Result<(Heightfield, Truth)> {
    s.check()?;
    if facets.is_empty() || facets.len() > s.nx {
        return Err(Error::invalid(format!("between 1 and {} plane facets are needed, got {}", s.nx, facets.len())));
    }
    for f in facets {
        if !(f.weight.is_finite() && f.weight > 0.0 && f.slope.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(format!("plane facet {f:?}: slope must be finite and weight positive")));
        }
    }
    let total: f64 = facets.iter().map(|f| f.weight).sum();
    // Column boundaries by cumulative weight (each facet gets at least one column).
    let mut bounds = vec![0usize];
    let mut acc = 0.0;
    for (k, f) in facets.iter().enumerate() {
        acc += f.weight;
        let end = if k + 1 == facets.len() {
            s.nx
        } else {
            ((acc / total * s.nx as f64).round() as usize).clamp(bounds[k] + 1, s.nx - (facets.len() - k - 1))
        };
        bounds.push(end);
    }
    // Heights: continuous along the middle row (y = 0) across strip boundaries.
    let mut base = vec![0.0; facets.len()];
    for k in 1..facets.len() {
        let xb = s.xc(bounds[k]);
        let prev = facets[k - 1].slope[0] * (xb - s.xc(bounds[k - 1])) + base[k - 1];
        base[k] = prev;
    }
    let mut z = vec![0.0; s.nx * s.ny];
    for i in 0..s.ny {
        let y = s.yc(i);
        for k in 0..facets.len() {
            let x0 = s.xc(bounds[k]);
            for j in bounds[k]..bounds[k + 1] {
                z[i * s.nx + j] = facets[k].slope[0] * (s.xc(j) - x0) + facets[k].slope[1] * y + base[k];
            }
        }
    }
    let hf: Heightfield = s.finish(z)?;
    let facet_truth: Vec<FacetTruth> = facets
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let n = (1.0 + f.slope[0] * f.slope[0] + f.slope[1] * f.slope[1]).sqrt();
            FacetTruth {
                slope: f.slope,
                m: [-f.slope[0] / n, -f.slope[1] / n, 1.0 / n],
                weight: (bounds[k + 1] - bounds[k]) as f64 / s.nx as f64,
                columns: [bounds[k], bounds[k + 1]],
            }
        })
        .collect();
    let truth = Truth {
        schema: "ndfit.synth/1".into(),
        model: "planes".into(),
        params: serde_json::Map::new(),
        matrix_a: None,
        generator: "planes".into(),
        settings: json!({"grid": s, "facets": facets}),
        derived: json!({}),
        facets: Some(facet_truth),
        input: None,
    };
    Ok((hf, truth))
}
