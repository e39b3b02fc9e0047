//! `--plot OUT.png` of `ndfit trace`: (a) the BRDF in the plane of incidence, the traced first bounce
//! against the microfacet model's single scattering, per incidence; (b) the traced masking `G1` against
//! Smith's over the incidences. What the verdict summarizes, drawn so a reader sees where it departs.

use std::path::Path;

use plotters::prelude::*;

use super::{direction, TraceReport, LUMA};
use crate::error::{Error, ErrorKind, Result};
use crate::io::write_bytes_atomic;
use crate::plot::{axis, ensure_font, FONT};

/// Width of the PNG (pixels).
pub const PLOT_WIDTH: u32 = 1400;
/// Height of the PNG (pixels).
pub const PLOT_HEIGHT: u32 = 560;

const COLOURS: [RGBColor; 6] = [BLUE, RED, RGBColor(0, 140, 0), RGBColor(200, 120, 0), RGBColor(130, 0, 160), RGBColor(0, 150, 160)];

fn plot_err(e: impl std::fmt::Display) -> Error {
    Error::new(ErrorKind::Io, format!("plot: {e}"))
}

fn lum(c: [f64; 3]) -> f64 {
    LUMA[0] * c[0] + LUMA[1] * c[1] + LUMA[2] * c[2]
}

/// One incidence's slice: `(signed theta_o in degrees, traced BRDF, model BRDF)` over the elevation bins
/// at the incident azimuth + 180 (the specular side, positive angles) and at the incident azimuth
/// (negative); the BRDF of a bin is its energy over its projected solid angle (luminance).
pub fn plane_of_incidence(report: &TraceReport, k: usize) -> Vec<(f64, f64, f64)> {
    let t = report.table;
    let (Some(tab), Some(rec)) = (report.tables.get(k), report.incidences.get(k)) else { return Vec::new() };
    let mut pts = Vec::new();
    for (sign, phi) in [(-1.0, rec.phi_deg), (1.0, rec.phi_deg + 180.0)] {
        for it in 0..t.n_theta {
            let theta = 0.5 * (t.theta_edge(it) + t.theta_edge(it + 1));
            let Some(b) = t.bin(direction(theta.to_degrees(), phi)) else { continue };
            let psa = t.proj_solid_angle(b);
            pts.push((sign * theta.to_degrees(), lum(tab.single[b]) / psa, lum(tab.model[b]) / psa));
        }
    }
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts
}

/// Draw the two panels and write the PNG atomically to `path`.
pub fn write_plot(path: &Path, report: &TraceReport) -> Result<()> {
    ensure_font();
    let (w, h) = (PLOT_WIDTH, PLOT_HEIGHT);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (left, right) = root.split_horizontally(w * 3 / 5);
        draw_brdf(&left, report)?;
        draw_g1(&right, report)?;
        root.present().map_err(plot_err)?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| plot_err("buffer size"))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).map_err(plot_err)?;
    write_bytes_atomic(path, &png)
}

fn draw_brdf<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>, report: &TraceReport) -> Result<()> {
    let slices: Vec<Vec<(f64, f64, f64)>> = (0..report.incidences.len()).map(|k| plane_of_incidence(report, k)).collect();
    let top = slices.iter().flatten().flat_map(|p| [p.1, p.2]).filter(|v| v.is_finite()).fold(0.0, f64::max);
    let y = axis(0.0, top * 1.08, 1.0, "BRDF")?;
    let mut chart = ChartBuilder::on(area)
        .caption("first bounce in the plane of incidence: traced (solid) vs microfacet model (dashed)", (FONT, 17))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-90.0..90.0, y)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("outgoing elevation (degrees; > 0: specular side)")
        .y_desc("BRDF (1/sr, luminance)")
        .label_style((FONT, 13))
        .draw()
        .map_err(plot_err)?;
    for (k, pts) in slices.iter().enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        let theta = report.incidences[k].theta_deg;
        chart
            .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), c.stroke_width(2)))
            .map_err(plot_err)?
            .label(format!("{theta} deg traced"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(3)));
        chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 3, c.filled()))).map_err(plot_err)?;
        chart
            .draw_series(DashedLineSeries::new(pts.iter().map(|p| (p.0, p.2)), 6, 4, c.stroke_width(1)))
            .map_err(plot_err)?
            .label(format!("{theta} deg model"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(1)));
    }
    chart.configure_series_labels().label_font((FONT, 12)).background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(plot_err)?;
    Ok(())
}

fn draw_g1<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>, report: &TraceReport) -> Result<()> {
    let recs = &report.incidences;
    let lo = recs
        .iter()
        .flat_map(|r| [r.g1 - 2.0 * r.g1_stderr, r.g1_smith, r.g1_toward.unwrap_or(1.0), r.g1_away.unwrap_or(1.0)])
        .filter(|v| v.is_finite())
        .fold(1.0, f64::min);
    let pad = ((1.0 - lo) * 0.1).max(0.01);
    let y = axis(lo - pad, 1.0 + pad, 0.05, "G1")?;
    let mut chart = ChartBuilder::on(area)
        .caption("masking G1: traced (+- 2 s.e.) vs Smith", (FONT, 17))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..90.0, y)
        .map_err(plot_err)?;
    chart.configure_mesh().x_desc("incidence (degrees)").y_desc("G1").label_style((FONT, 13)).draw().map_err(plot_err)?;
    let mut by_theta: Vec<_> = recs.iter().collect();
    by_theta.sort_by(|a, b| a.theta_deg.total_cmp(&b.theta_deg));
    chart
        .draw_series(LineSeries::new(by_theta.iter().map(|r| (r.theta_deg, r.g1_smith)), BLACK.stroke_width(1)))
        .map_err(plot_err)?
        .label("Smith (the traced surface's NDF)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(1)));
    chart
        .draw_series(by_theta.iter().map(|r| {
            PathElement::new(vec![(r.theta_deg, r.g1 - 2.0 * r.g1_stderr), (r.theta_deg, r.g1 + 2.0 * r.g1_stderr)], BLUE.stroke_width(2))
        }))
        .map_err(plot_err)?;
    chart
        .draw_series(by_theta.iter().map(|r| Circle::new((r.theta_deg, r.g1), 4, BLUE.filled())))
        .map_err(plot_err)?
        .label("traced")
        .legend(|(x, y)| Circle::new((x + 9, y), 4, BLUE.filled()));
    for (pick, name, c) in [(0, "traced, facets tilted toward the light", RED), (1, "traced, facets tilted away", RGBColor(0, 140, 0))] {
        let pts: Vec<(f64, f64)> =
            by_theta.iter().filter_map(|r| if pick == 0 { r.g1_toward } else { r.g1_away }.map(|g| (r.theta_deg, g))).collect();
        chart
            .draw_series(pts.iter().map(|&p| TriangleMarker::new(p, 5, c.filled())))
            .map_err(plot_err)?
            .label(name)
            .legend(move |(x, y)| TriangleMarker::new((x + 9, y), 5, c.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    Ok(())
}
