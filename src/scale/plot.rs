//! `scale.png`: how alpha_x, alpha_y, the tilt angles and the skew change with footprint, both routes.

use std::path::Path;

use plotters::prelude::*;

use super::analyze::{model_skew, FootprintResult};
use crate::error::{Error, ErrorKind, Result};
use crate::io::write_bytes_atomic;
use crate::models::{Model, ModelId};
use crate::plot::{ensure_font, FONT};

const W: u32 = 900;
const H: u32 = 1050;

fn plot_err(e: impl std::fmt::Display) -> Error {
    Error::new(ErrorKind::Io, format!("plot: {e}"))
}

/// `(footprint, value)` points of a route's parameter `k` for model `id`.
fn series(results: &[FootprintResult], id: ModelId, analytic: bool, f: impl Fn(&Model) -> Option<f64>) -> Vec<(f64, f64)> {
    results
        .iter()
        .filter_map(|r| {
            let m = r.models.iter().find(|m| m.id == id)?;
            let rr = if analytic { &m.analytic } else { &m.empirical };
            let v = f(rr.model.as_ref()?)?;
            v.is_finite().then_some((r.stats.footprint, v))
        })
        .collect()
}

/// Render the plot for the most general model present (the ellipsoid when it was run) and write it
/// atomically to `path`.
pub fn write_plot(path: &Path, results: &[FootprintResult]) -> Result<()> {
    ensure_font();
    let id = results
        .iter()
        .flat_map(|r| r.models.iter().map(|m| m.id))
        .max_by_key(|id| id.n_params())
        .ok_or_else(|| Error::invalid("nothing to plot: no model results"))?;
    let fps: Vec<f64> = results.iter().map(|r| r.stats.footprint).filter(|f| *f > 0.0).collect();
    if fps.is_empty() {
        return Err(Error::invalid("nothing to plot: every footprint is 0 (no log axis)"));
    }
    let lo = fps.iter().cloned().fold(f64::INFINITY, f64::min) / 1.5;
    let hi = fps.iter().cloned().fold(0.0, f64::max) * 1.5;
    let mut buf = vec![0u8; (W * H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let panels = root.split_evenly((3, 1));
        let p = |m: &Model, k: usize| m.params().get(k).copied();
        let param = |k: usize| move |m: &Model| p(m, k);
        let deg = |k: usize| move |m: &Model| p(m, k).map(f64::to_degrees);
        let pix: Vec<(f64, f64, f64)> =
            results.iter().filter_map(|r| r.pixel_roughness.map(|(a, b, _)| (r.stats.footprint, a, b))).collect();
        // Footprints where the model's analytic route is flagged (analytic_caveats): hollow triangles.
        let untrusted: Vec<f64> =
            results.iter().filter(|r| r.models.iter().any(|m| m.id == id && !m.analytic_trusted())).map(|r| r.stats.footprint).collect();
        let untrusted = untrusted.as_slice();
        // Panel 1: alphas.
        // Label, points, colour, dashed: one row per series, read as a table below.
        #[allow(clippy::type_complexity)]
        let mut lines: Vec<(String, Vec<(f64, f64)>, RGBColor, bool)> = vec![
            ("alpha_x empirical".into(), series(results, id, false, param(0)), BLUE, false),
            ("alpha_x analytic".into(), series(results, id, true, param(0)), BLUE, true),
        ];
        if id.n_params() > 1 {
            lines.push(("alpha_y empirical".into(), series(results, id, false, param(1)), RED, false));
            lines.push(("alpha_y analytic".into(), series(results, id, true, param(1)), RED, true));
        }
        lines.push((
            "pixel roughness (2 Sigma_F) alpha_x".into(),
            pix.iter().map(|p| (p.0, p.1)).collect(),
            RGBColor(120, 120, 120),
            false,
        ));
        lines.push((
            "pixel roughness (2 Sigma_F) alpha_y".into(),
            pix.iter().map(|p| (p.0, p.2)).collect(),
            RGBColor(190, 190, 190),
            false,
        ));
        draw_panel(
            &panels[0],
            &format!("{id}: roughness vs footprint (hollow triangles: analytic route not trusted)"),
            "alpha",
            (lo, hi),
            &lines,
            untrusted,
        )?;
        // Panel 2: angles.
        let mut ang = Vec::new();
        if id.spec().slot_any(crate::models::Role::ThetaX).is_some() && !id.is_mixture() {
            ang.push(("theta_x empirical".to_string(), series(results, id, false, deg(2)), BLUE, false));
            ang.push(("theta_x analytic".to_string(), series(results, id, true, deg(2)), BLUE, true));
            ang.push(("theta_y empirical".to_string(), series(results, id, false, deg(3)), RED, false));
            ang.push(("theta_y analytic".to_string(), series(results, id, true, deg(3)), RED, true));
        }
        if id.n_params() >= 3 {
            let k = id.n_params() - 1;
            ang.push(("theta_z empirical".to_string(), series(results, id, false, deg(k)), GREEN, false));
            ang.push(("theta_z analytic".to_string(), series(results, id, true, deg(k)), GREEN, true));
        }
        draw_panel(&panels[1], &format!("{id}: angles (degrees) vs footprint"), "degrees", (lo, hi), &ang, untrusted)?;
        // Panel 3: skew.
        let skew = vec![
            ("skew offset empirical".to_string(), series(results, id, false, |m| Some(model_skew(m))), BLUE, false),
            ("skew offset analytic".to_string(), series(results, id, true, |m| Some(model_skew(m))), BLUE, true),
            (
                "slope skewness of the NDF at F (moments)".to_string(),
                results.iter().map(|r| (r.stats.footprint, r.at_f.skewness)).collect(),
                BLACK,
                false,
            ),
        ];
        draw_panel(&panels[2], "skew vs footprint", "skew (scale-free)", (lo, hi), &skew, untrusted)?;
        root.present().map_err(plot_err)?;
    }
    let img = image::RgbImage::from_raw(W, H, buf).ok_or_else(|| plot_err("buffer size"))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).map_err(plot_err)?;
    write_bytes_atomic(path, &png)
}

type Line = (String, Vec<(f64, f64)>, RGBColor, bool);

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    ylabel: &str,
    (lo, hi): (f64, f64),
    lines: &[Line],
    untrusted: &[f64],
) -> Result<()> {
    let ys: Vec<f64> = lines.iter().flat_map(|l| l.1.iter().map(|p| p.1)).collect();
    let (mut y0, mut y1) = ys.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if !(y0.is_finite() && y1.is_finite()) {
        (y0, y1) = (0.0, 1.0);
    }
    // A flat series still needs a non-empty axis.
    let pad = ((y1 - y0) * 0.08).max(1e-3 * y1.abs().max(1e-6));
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d((lo..hi).log_scale(), (y0 - pad)..(y1 + pad))
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("footprint F (m)")
        .y_desc(ylabel)
        .label_style((FONT, 13))
        .x_label_formatter(&|v| format!("{v:.1e}"))
        .draw()
        .map_err(plot_err)?;
    for (name, pts, color, analytic) in lines {
        if pts.is_empty() {
            continue;
        }
        let c = *color;
        let style = if *analytic { c.stroke_width(1) } else { c.stroke_width(2) };
        let s = chart.draw_series(LineSeries::new(pts.clone(), style)).map_err(plot_err)?;
        let w = if *analytic { 1 } else { 3 };
        s.label(name.as_str()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(w)));
        if *analytic {
            chart
                .draw_series(pts.iter().filter(|p| !untrusted.contains(&p.0)).map(|&(x, y)| TriangleMarker::new((x, y), 5, c.filled())))
                .map_err(plot_err)?;
            // TriangleMarker always fills: a hollow one is a white triangle with a coloured outline.
            let tri = vec![(0, -6), (5, 3), (-5, 3), (0, -6)];
            chart
                .draw_series(pts.iter().filter(|p| untrusted.contains(&p.0)).map(|&(x, y)| {
                    EmptyElement::at((x, y)) + Polygon::new(tri.clone(), WHITE.filled()) + PathElement::new(tri.clone(), c.stroke_width(2))
                }))
                .map_err(plot_err)?;
        } else {
            chart.draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 4, c.filled()))).map_err(plot_err)?;
        }
    }
    chart.configure_series_labels().label_font((FONT, 12)).background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(plot_err)?;
    Ok(())
}
