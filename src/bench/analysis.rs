//! What the rows say: the Pareto front of time against error, and the cost model (log-log slopes of
//! time and memory against scan size and bin count).

use super::sweep::Row;

/// Indices of the rows on the Pareto front of `(time, error)` (both minimized), sorted by time. Rows
/// without an error are left out.
pub fn pareto_front(rows: &[Row], time: impl Fn(&Row) -> f64, error: impl Fn(&Row) -> Option<f64>) -> Vec<usize> {
    let mut idx: Vec<(usize, f64, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, r)| error(r).filter(|e| e.is_finite()).map(|e| (i, time(r), e)))
        .filter(|p| p.1.is_finite())
        .collect();
    idx.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.2.total_cmp(&b.2)));
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for (i, _, e) in idx {
        // Sorted by time: a point is on the front when it beats every faster point's error.
        if e < best {
            best = e;
            front.push(i);
        }
    }
    front
}

/// Least-squares line `ln y = a + b ln x`: returns `(b, a)`, or `None` with fewer than two usable points.
pub fn loglog_slope(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let pts: Vec<(f64, f64)> =
        points.iter().filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite()).map(|(x, y)| (x.ln(), y.ln())).collect();
    let n = pts.len() as f64;
    if pts.len() < 2 {
        return None;
    }
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    // Guard: all x equal gives no slope.
    if sxx <= 0.0 {
        return None;
    }
    let b = sxy / sxx;
    Some((b, my - b * mx))
}

/// One exponent of the cost model.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Exponent {
    /// What grows (`t_ndf_ms`, `peak_mib`, ...).
    pub quantity: String,
    /// Against what (`points`, `bins`).
    pub against: String,
    /// The fitted log-log slope.
    pub exponent: f64,
    /// Points in the fit.
    pub n: usize,
}

/// The cost model: exponents of the stage times and the peak memory against scan points (group
/// `size_ndf` for the NDF stages, `size` for the whole pipeline) and against bin count (group `cells`).
pub fn cost_model(rows: &[Row]) -> Vec<Exponent> {
    let mut out = Vec::new();
    let mut add = |group: &str, against: &str, quantity: &str, x: fn(&Row) -> f64, y: fn(&Row) -> Option<f64>| {
        let pts: Vec<(f64, f64)> = rows.iter().filter(|r| r.group == group).filter_map(|r| y(r).map(|v| (x(r), v))).collect();
        if let Some((b, _)) = loglog_slope(&pts) {
            out.push(Exponent { quantity: quantity.into(), against: against.into(), exponent: b, n: pts.len() });
        }
    };
    let points = |r: &Row| (r.size * r.size) as f64;
    let bins = |r: &Row| r.bins as f64;
    add("size_ndf", "points", "t_read_ms", points, |r| Some(r.t_read_ms));
    add("size_ndf", "points", "t_ndf_ms", points, |r| Some(r.t_ndf_ms));
    add("size_ndf", "points", "peak_mib", points, |r| r.peak_mib);
    add("size", "points", "t_total_ms", points, |r| Some(r.t_total_ms));
    add("size", "points", "t_fit_ms", points, |r| Some(r.t_fit_ms));
    add("cells", "bins", "t_ndf_ms", bins, |r| Some(r.t_ndf_ms));
    add("cells", "bins", "t_fit_ms", bins, |r| Some(r.t_fit_ms));
    add("cells", "bins", "peak_ndf_mib", bins, |r| r.peak_ndf_mib);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slope of exact power laws is recovered (closed form), and a constant has slope 0.
    #[test]
    fn loglog_recovers_power_laws() {
        let pts: Vec<(f64, f64)> = [1.0, 4.0, 16.0, 64.0].iter().map(|&x: &f64| (x, 3.0 * x.powf(1.5))).collect();
        let (b, a) = loglog_slope(&pts).expect("four points");
        assert!((b - 1.5).abs() < 1e-12 && (a - 3.0f64.ln()).abs() < 1e-12);
        assert!(loglog_slope(&[(1.0, 2.0)]).is_none());
        assert!(loglog_slope(&[(2.0, 1.0), (2.0, 3.0)]).is_none());
    }
}
