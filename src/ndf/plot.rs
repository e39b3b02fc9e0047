//! PNG plots of an empirical NDF: a false-colour map of `log10 D` over the projected hemisphere (whole,
//! and zoomed on the data), and slices of `D` through the peak along the principal slope axes.

use std::path::Path;

use nalgebra::Vector3;
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;

use super::output::raster;
use super::EmpiricalNdf;
use crate::error::{Error, ErrorKind, Result};
use crate::io::write_bytes_atomic;

fn perr<E: std::fmt::Display>(e: E) -> Error {
    Error::new(ErrorKind::Io, format!("plot failed: {}", e.to_string().replace('\n', " ")))
}

/// Encode an RGB buffer as PNG and write it atomically.
fn save_png(path: &Path, buf: &[u8], w: u32, h: u32) -> Result<()> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(&mut out, buf, w, h, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
        .map_err(|e| Error::new(ErrorKind::Io, format!("PNG encoding failed: {e}")).with_path(path))?;
    write_bytes_atomic(path, out.get_ref())
}

/// The direction of the peak bin (largest D among bins with at least 10 samples, else any).
fn peak(ndf: &EmpiricalNdf) -> Vector3<f64> {
    let best = ndf.bins.iter().filter(|b| b.count >= 10).max_by(|a, b| a.d.total_cmp(&b.d));
    best.or_else(|| ndf.bins.iter().max_by(|a, b| a.d.total_cmp(&b.d))).map_or(Vector3::z(), |b| b.m)
}

/// Half-width (in `m_x`, `m_y`) of a window around `pk` that holds the data: 1.2 times the distance from
/// `pk` within which 99% of the samples lie, at most 0.5 (a quarter of the disk's width, so the window is
/// always a zoom) and at least 1e-4.
pub fn zoom_half(ndf: &EmpiricalNdf, pk: Vector3<f64>) -> f64 {
    let mut d: Vec<(f64, u64)> =
        ndf.bins.iter().filter(|b| b.count > 0).map(|b| (((b.m.x - pk.x).powi(2) + (b.m.y - pk.y).powi(2)).sqrt(), b.count)).collect();
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: u64 = d.iter().map(|x| x.1).sum();
    let mut acc = 0u64;
    let mut r = 0.5;
    for (dist, c) in d {
        acc += c;
        if acc as f64 >= 0.99 * total as f64 {
            r = dist;
            break;
        }
    }
    (1.2 * r).clamp(1e-4, 0.5)
}

/// The false-colour map: left the whole projected hemisphere `(m_x, m_y)`, right a window around the
/// peak holding 99% of the samples ([`zoom_half`]). Colour is `log10 D` over four
/// decades below the maximum; grey where D = 0.
pub fn plot_map(path: &Path, ndf: &EmpiricalNdf, title: &str) -> Result<()> {
    plot_map_to(path, ndf, title).map_err(|e| e.with_path(path))
}

fn plot_map_to(path: &Path, ndf: &EmpiricalNdf, title: &str) -> Result<()> {
    crate::plot::ensure_font();
    let (w, h) = (1160u32, 620u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let res = 480usize;
    let pk = peak(ndf);
    let pk = if pk.x.is_finite() && pk.y.is_finite() { pk } else { Vector3::z() };
    let half = zoom_half(ndf, pk);
    let half = if half.is_finite() { half } else { 0.5 };
    let full = raster(ndf, res, [0.0, 0.0], 1.0);
    let zoom = raster(ndf, res, [pk.x, pk.y], half);
    let dmax = full.iter().chain(&zoom).cloned().filter(|d| d.is_finite()).fold(0.0f64, f64::max);
    let (lo, hi) = if dmax > 0.0 { (dmax.log10() - 4.0, dmax.log10()) } else { (-1.0, 0.0) };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let root = root.titled(title, (crate::plot::FONT, 20)).map_err(perr)?;
        let (panels, _footer) = root.split_vertically(h - 70);
        let (left, right) = panels.split_horizontally(w / 2);
        for (area, data, c, hw, label) in
            [(&left, &full, [0.0, 0.0], 1.0, "projected hemisphere (m_x, m_y)"), (&right, &zoom, [pk.x, pk.y], half, "zoom on the peak")]
        {
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .caption(label, (crate::plot::FONT, 15))
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d((c[0] - hw)..(c[0] + hw), (c[1] - hw)..(c[1] + hw))
                .map_err(perr)?;
            chart.configure_mesh().disable_mesh().x_desc("m_x").y_desc("m_y").label_style((crate::plot::FONT, 12)).draw().map_err(perr)?;
            let px = 2.0 * hw / res as f64;
            chart
                .draw_series(data.iter().enumerate().filter_map(|(k, &d)| {
                    let (row, col) = (k / res, k % res);
                    let x = c[0] - hw + col as f64 * px;
                    let y = c[1] + hw - (row as f64 + 1.0) * px;
                    if x * x + y * y > 1.0 {
                        return None;
                    }
                    let colour = if d > 0.0 && d.is_finite() {
                        let t = ((d.log10() - lo) / (hi - lo)).clamp(0.0, 1.0);
                        ViridisRGB::get_color(t)
                    } else {
                        RGBColor(200, 200, 200)
                    };
                    Some(Rectangle::new([(x, y), (x + px, y + px)], colour.filled()))
                }))
                .map_err(perr)?;
        }
        root.draw(&Text::new(
            format!("colour: log10 D from {lo:.2} (dark) to {hi:.2} (yellow) 1/sr; grey: no sample; N = {}", ndf.n_samples),
            (20, h as i32 - 60),
            (crate::plot::FONT, 14),
        ))
        .map_err(perr)?;
        root.present().map_err(perr)?;
    }
    save_png(path, &buf, w, h)
}

/// Slices of the empirical D through the peak along the two principal axes of the robust slope
/// covariance, against the signed angle from the peak direction (degrees), log scale.
pub fn plot_slices(path: &Path, ndf: &EmpiricalNdf, title: &str) -> Result<()> {
    plot_slices_to(path, ndf, title).map_err(|e| e.with_path(path))
}

fn plot_slices_to(path: &Path, ndf: &EmpiricalNdf, title: &str) -> Result<()> {
    crate::plot::ensure_font();
    let (w, h) = (1000u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let pk = peak(ndf);
    let s0 = [-pk.x / pk.z, -pk.y / pk.z];
    let c = ndf.frame.cov;
    let half = (0.25 * (c[0][0] - c[1][1]).powi(2) + c[0][1] * c[0][1]).sqrt();
    let l = [0.5 * (c[0][0] + c[1][1]) + half, (0.5 * (c[0][0] + c[1][1]) - half).max(0.0)];
    let phi = 0.5 * (2.0 * c[0][1]).atan2(c[0][0] - c[1][1]);
    let axes = [[phi.cos(), phi.sin()], [-phi.sin(), phi.cos()]];
    let mut series = Vec::new();
    for (k, e) in axes.iter().enumerate() {
        let range = 8.0 * l[k].sqrt().max(1e-9);
        let pts: Vec<(f64, f64)> = (-400..=400)
            .filter_map(|i| {
                let t = range * i as f64 / 400.0;
                let s = [s0[0] + t * e[0], s0[1] + t * e[1]];
                let m = Vector3::new(-s[0], -s[1], 1.0).normalize();
                let d = ndf.d_at(m);
                let ang = m.angle(&pk).to_degrees() * t.signum();
                (d > 0.0 && d.is_finite() && ang.is_finite()).then(|| (ang, d.log10()))
            })
            .collect();
        series.push(pts);
    }
    let all = series.iter().flatten();
    let (xmin, xmax) = all.clone().fold((0.0f64, 0.0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (ymin, ymax) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let x = crate::plot::axis(xmin, xmax, 1.0, "angle").map_err(|e| e.with_path(path))?;
    let y =
        if ymax >= ymin { crate::plot::axis(ymin - 0.2, ymax + 0.2, 1.0, "log10 D").map_err(|e| e.with_path(path))? } else { -1.0..1.0 };
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(15)
            .caption(title, (crate::plot::FONT, 20))
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x, y)
            .map_err(perr)?;
        chart
            .configure_mesh()
            .x_desc("signed angle from the peak direction (deg)")
            .y_desc("log10 D (1/sr)")
            .label_style((crate::plot::FONT, 13))
            .draw()
            .map_err(perr)?;
        let colours = [RGBColor(200, 30, 30), RGBColor(30, 60, 200)];
        let names = ["major slope axis", "minor slope axis"];
        for (k, pts) in series.iter().enumerate() {
            let col = colours[k];
            chart
                .draw_series(LineSeries::new(pts.iter().cloned(), col.stroke_width(2)))
                .map_err(perr)?
                .label(format!("{} (robust sigma {:.3e})", names[k], l[k].sqrt()))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE)
            .label_font((crate::plot::FONT, 14))
            .draw()
            .map_err(perr)?;
        root.present().map_err(perr)?;
    }
    save_png(path, &buf, w, h)
}
