//! `--plot FIT.png`: the data against the fit.
//!
//! Top row: three maps of the projected hemisphere `(m_x, m_y)` around the peak: the empirical `log10 D`,
//! the fitted `log10 D` on the same colour scale (viridis, four decades below the larger maximum), and
//! the residual `log10(D_data / D_fit)` on its own diverging scale (blue: data below the fit, red: above,
//! +-1 decade). Bottom row: slices of D through the fit's peak along its two principal axes
//! ([`crate::models::LobeAxes`]; the data's principal slope axes for an isotropic model): data as dots, the
//! fit as a line through them. Legends are written under the panels, never over data.

use std::path::Path;

use nalgebra::Vector3;
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;

use crate::error::{Error, ErrorKind, Result};
use crate::models::{Model, Ndf};
use crate::ndf::EmpiricalNdf;

fn perr<E: std::fmt::Display>(e: E) -> Error {
    Error::new(ErrorKind::Io, format!("plot failed: {}", e.to_string().replace('\n', " ")))
}

/// The colour of map pixel `k` (`None` outside the disk).
type Colourer<'a> = Box<dyn Fn(usize) -> Option<RGBColor> + 'a>;

/// Pixels across each map.
const RES: usize = 200;

/// Blue - white - red for `t` in `[-1, 1]`.
fn diverging(t: f64) -> RGBColor {
    let t = t.clamp(-1.0, 1.0);
    let k = |a: f64| (255.0 * (1.0 - a.abs() * 0.85)) as u8;
    if t < 0.0 {
        RGBColor(k(t), k(t), 255)
    } else {
        RGBColor(255, k(t), k(t))
    }
}

/// Draw the plot to `path` (PNG, written atomically). Values that are not finite are left out; an axis
/// that would not be finite is an error naming the file, and then no file is written.
pub fn plot_fit(path: &Path, ndf: &EmpiricalNdf, model: &Model, title: &str) -> Result<()> {
    plot_fit_to(path, ndf, model, title).map_err(|e| e.with_path(path))
}

fn plot_fit_to(path: &Path, ndf: &EmpiricalNdf, model: &Model, title: &str) -> Result<()> {
    crate::plot::ensure_font();
    let axes = model.canonical().axes();
    let peak = axes.map_or(Vector3::z(), |a| Vector3::from(a.peak));
    // Guard: a degenerate model (its peak not a direction) is drawn about the normal.
    let peak = if peak.iter().all(|v| v.is_finite()) && peak.z > 0.0 { peak } else { Vector3::z() };
    let half = crate::ndf::plot::zoom_half(ndf, peak);
    let c = [peak.x, peak.y];
    let px = 2.0 * half / RES as f64;
    let at = |row: usize, col: usize| -> Option<Vector3<f64>> {
        let x = c[0] - half + (col as f64 + 0.5) * px;
        let y = c[1] + half - (row as f64 + 0.5) * px;
        let r2 = x * x + y * y;
        (r2 < 1.0).then(|| Vector3::new(x, y, (1.0 - r2).sqrt()))
    };
    let mut data = vec![None; RES * RES];
    let mut fit = vec![None; RES * RES];
    for row in 0..RES {
        for col in 0..RES {
            if let Some(m) = at(row, col) {
                // Values that overflow (a denormal bin, an extreme model) are left out, not drawn.
                data[row * RES + col] = Some(ndf.d_at(m)).filter(|v| v.is_finite());
                fit[row * RES + col] = Some(model.d(m)).filter(|v| v.is_finite());
            }
        }
    }
    let dmax = data.iter().chain(&fit).flatten().cloned().fold(0.0f64, f64::max);
    let (lo, hi) = if dmax > 0.0 { (dmax.log10() - 4.0, dmax.log10()) } else { (-1.0, 0.0) };
    let d_colour =
        |d: f64| if d > 0.0 { ViridisRGB::get_color(((d.log10() - lo) / (hi - lo)).clamp(0.0, 1.0)) } else { RGBColor(200, 200, 200) };
    let resid: Vec<Option<RGBColor>> = data
        .iter()
        .zip(&fit)
        .map(|(d, f)| match (d, f) {
            (Some(d), Some(f)) if *d > 0.0 && *f > 0.0 => Some(diverging((d / f).log10())),
            (Some(_), Some(_)) => Some(RGBColor(200, 200, 200)),
            _ => None,
        })
        .collect();

    // Slices along the axes, parameterized by slope offset t from the peak.
    let s0 = [-peak.x / peak.z, -peak.y / peak.z];
    let (dirs, widths, names) = match axes {
        Some(a) => ([[a.alpha_x[0], a.alpha_x[1]], [a.alpha_y[0], a.alpha_y[1]]], a.widths, ["alpha_x", "alpha_y"]),
        None => {
            let cv = ndf.frame.cov;
            let phi = 0.5 * (2.0 * cv[0][1]).atan2(cv[0][0] - cv[1][1]);
            let a = model.params()[0];
            ([[phi.cos(), phi.sin()], [-phi.sin(), phi.cos()]], [a, a], ["major data axis", "minor data axis"])
        }
    };
    let mut slices = Vec::new();
    for (k, e) in dirs.iter().enumerate() {
        let range = 5.0 * widths[k].max(1e-6);
        let range = if range.is_finite() { range } else { 1.0 };
        let (mut pts_d, mut pts_f) = (Vec::new(), Vec::new());
        for i in -300..=300 {
            let t = range * i as f64 / 300.0;
            let m = Vector3::new(-(s0[0] + t * e[0]), -(s0[1] + t * e[1]), 1.0).normalize();
            let ang = m.angle(&peak).to_degrees() * t.signum();
            let (d, f) = (ndf.d_at(m), model.d(m));
            if d > 0.0 && d.is_finite() && ang.is_finite() && i % 3 == 0 {
                pts_d.push((ang, d.log10()));
            }
            if f > 0.0 && f.is_finite() && ang.is_finite() {
                pts_f.push((ang, f.log10()));
            }
        }
        slices.push((pts_d, pts_f, names[k], (e[1]).atan2(e[0]).to_degrees()));
    }

    let (w, h) = (1500u32, 1060u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root.titled(title, (crate::plot::FONT, 22)).map_err(perr)?;
        let (top, rest) = root.split_vertically(520);
        let (bottom, footer) = rest.split_vertically(rest.dim_in_pixel().1 - 60);
        let maps = top.split_evenly((1, 3));
        let panels: [(&str, Colourer); 3] = [
            ("data: log10 D", Box::new(|k| data[k].map(d_colour))),
            ("fit: log10 D (same scale)", Box::new(|k| fit[k].map(d_colour))),
            ("residual log10(D_data / D_fit)", Box::new(|k| resid[k])),
        ];
        for (area, (label, colour)) in maps.iter().zip(panels.iter()) {
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .caption(*label, (crate::plot::FONT, 16))
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d((c[0] - half)..(c[0] + half), (c[1] - half)..(c[1] + half))
                .map_err(perr)?;
            chart.configure_mesh().disable_mesh().x_desc("m_x").y_desc("m_y").label_style((crate::plot::FONT, 12)).draw().map_err(perr)?;
            chart
                .draw_series((0..RES * RES).filter_map(|k| {
                    let (row, col) = (k / RES, k % RES);
                    let x = c[0] - half + col as f64 * px;
                    let y = c[1] + half - (row as f64 + 1.0) * px;
                    colour(k).map(|col| Rectangle::new([(x, y), (x + px, y + px)], col.filled()))
                }))
                .map_err(perr)?;
        }
        let plots = bottom.split_evenly((1, 2));
        for (area, (pts_d, pts_f, name, az)) in plots.iter().zip(&slices) {
            let all = pts_d.iter().chain(pts_f.iter());
            let (x0, x1) = all.clone().fold((0.0f64, 0.0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let ymax = all.clone().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
            let ymin = pts_d.iter().map(|p| p.1).fold(f64::INFINITY, f64::min).max(ymax - 6.0);
            let (x0, x1) = if x1 > x0 { (x0, x1) } else { (-1.0, 1.0) };
            let (ymin, ymax) = if ymax > ymin { (ymin - 0.3, ymax + 0.3) } else { (-1.0, 1.0) };
            let (xr, yr) = (crate::plot::axis(x0, x1, 1.0, "slice angle")?, crate::plot::axis(ymin, ymax, 1.0, "log10 D")?);
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .caption(format!("slice through the peak along {name} (azimuth {az:.1} deg)"), (crate::plot::FONT, 16))
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(xr, yr)
                .map_err(perr)?;
            chart
                .configure_mesh()
                .x_desc("signed angle from the peak (deg)")
                .y_desc("log10 D (1/sr)")
                .label_style((crate::plot::FONT, 13))
                .draw()
                .map_err(perr)?;
            chart
                .draw_series(pts_d.iter().filter(|p| p.1 >= ymin).map(|p| Circle::new(*p, 3, RGBColor(90, 90, 90).filled())))
                .map_err(perr)?;
            chart
                .draw_series(LineSeries::new(pts_f.iter().cloned().filter(|p| p.1 >= ymin), RGBColor(210, 30, 30).stroke_width(2)))
                .map_err(perr)?;
        }
        footer
            .draw(&Text::new(
                format!(
                    "maps: colour log10 D from {lo:.2} (dark) to {hi:.2} (yellow) 1/sr, grey = no sample; residual: blue data below the fit, red above, full colour at 1 decade.   slices: grey dots data, red line fit."
                ),
                (15, 10),
                (crate::plot::FONT, 15),
            ))
            .map_err(perr)?;
        root.present().map_err(perr)?;
    }
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(&mut out, &buf, w, h, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
        .map_err(|e| Error::new(ErrorKind::Io, format!("PNG encoding failed: {e}")).with_path(path))?;
    crate::io::write_bytes_atomic(path, out.get_ref())
}
