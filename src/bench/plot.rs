//! The Pareto plot: whole-pipeline time against the fit error, every point of the knob sweep in grey,
//! the front in red, the presets labelled.

use std::path::Path;

use plotters::prelude::*;

use super::sweep::Row;
use crate::error::{Error, ErrorKind, Result};

fn perr<E: std::fmt::Display>(e: E) -> Error {
    Error::new(ErrorKind::Io, format!("plot failed: {e}"))
}

/// Draw `rows` (those with a fit error) and the `front` (indices into `rows`) to `path` (PNG, atomic).
pub fn plot_pareto(path: &Path, rows: &[Row], front: &[usize], title: &str) -> Result<()> {
    crate::plot::ensure_font();
    let pts: Vec<(f64, f64, &Row)> =
        rows.iter().filter_map(|r| r.fit_delta.filter(|d| *d > 0.0 && r.t_total_ms > 0.0).map(|d| (r.t_total_ms, d, r))).collect();
    if pts.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "no point with a fit error to plot").with_path(path));
    }
    let (tmin, tmax) = pts.iter().fold((f64::INFINITY, 0.0f64), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (emin, emax) = pts.iter().fold((f64::INFINITY, 0.0f64), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let tmp = tempfile::Builder::new().suffix(".png").tempfile_in(dir).map_err(|e| Error::io(e).with_path(path))?;
    {
        let root = BitMapBackend::new(tmp.path(), (1000, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let mut c = ChartBuilder::on(&root)
            .caption(title, (crate::plot::FONT, 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((tmin / 1.5..tmax * 1.5).log_scale(), (emin / 1.5..emax * 1.5).log_scale())
            .map_err(perr)?;
        c.configure_mesh()
            .x_desc("whole pipeline time (ms, median)")
            .y_desc("fit error delta(D_fit; D_truth)")
            .x_labels(6)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((crate::plot::FONT, 14))
            .draw()
            .map_err(perr)?;
        c.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 4, RGBColor(120, 120, 120).filled())))
            .map_err(perr)?
            .label("sweep point")
            .legend(|(x, y)| Circle::new((x, y), 4, RGBColor(120, 120, 120).filled()));
        let fr: Vec<(f64, f64)> =
            front.iter().filter_map(|&i| rows.get(i)).filter_map(|r| r.fit_delta.map(|d| (r.t_total_ms, d))).collect();
        c.draw_series(LineSeries::new(fr.iter().copied(), RED.stroke_width(2)))
            .map_err(perr)?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new([(x - 10, y), (x + 10, y)], RED.stroke_width(2)));
        c.draw_series(fr.iter().map(|p| Circle::new(*p, 5, RED.filled()))).map_err(perr)?;
        // Labels: every front point by its group, the presets by name.
        for p in &pts {
            let on_front = front.iter().any(|&i| std::ptr::eq(&rows[i], p.2));
            let preset = p.2.group.strip_prefix("preset_");
            if let Some(name) = preset {
                c.draw_series(std::iter::once(Circle::new((p.0, p.1), 7, BLUE.stroke_width(2)))).map_err(perr)?;
                c.draw_series(std::iter::once(
                    EmptyElement::at((p.0, p.1)) + Text::new(name.to_string(), (10, 4), (crate::plot::FONT, 15).into_font().color(&BLUE)),
                ))
                .map_err(perr)?;
            } else if on_front {
                let label = label_of(p.2);
                c.draw_series(std::iter::once(
                    EmptyElement::at((p.0, p.1)) + Text::new(label, (8, -16), (crate::plot::FONT, 12).into_font().color(&RED)),
                ))
                .map_err(perr)?;
            }
        }
        c.configure_series_labels().border_style(BLACK).background_style(WHITE).label_font((crate::plot::FONT, 14)).draw().map_err(perr)?;
        root.present().map_err(perr)?;
    }
    tmp.persist(path).map_err(|e| Error::io(e.error).with_path(path))?;
    Ok(())
}

/// A short label of the knob a row varies.
pub fn label_of(r: &Row) -> String {
    match r.group.as_str() {
        "stride" => format!("stride {}", r.stride),
        "target_count" | "cells" => format!("bins {}", r.cells),
        "scheme" => r.scheme.clone(),
        "binning" => format!("{} bins", r.binning),
        "storage" => format!("{} heights", r.storage),
        "solver" => r.solver.clone(),
        "tol" => format!("tol {:e}", r.tol),
        "starts" => format!("+{} starts", r.extra_starts),
        "model" => r.model.clone(),
        "size" => "balanced".into(),
        "defaults" => "NDF defaults".into(),
        g => g.to_string(),
    }
}
