//! `--plot FIT.png`: the data against the fit, with residuals.
//!
//! Top: `log10 D` of every non-empty bin (grey) and of the fitted model at the same bins (red) against
//! the polar angle of the bin's direction. Bottom: the bins' deviance residuals (objective.md), which
//! are about N(0, 1) where the model is right and the normals independent.

use std::path::Path;

use plotters::prelude::*;

use super::objective::{residual, FitData, Objective};
use crate::error::{Error, ErrorKind, Result};
use crate::models::{Model, Ndf};
use crate::ndf::EmpiricalNdf;

fn perr<E: std::fmt::Display>(e: E) -> Error {
    Error::new(ErrorKind::Io, format!("plot failed: {}", e.to_string().replace('\n', " ")))
}

/// Draw the plot to `path` (PNG, written atomically). Points whose value is not finite (a D that
/// overflows) are left out; an NDF with nothing finite to show is an error, and no file is written.
pub fn plot_fit(path: &Path, ndf: &EmpiricalNdf, model: &Model, title: &str) -> Result<()> {
    let (w, h) = (1000u32, 800u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    draw_fit(&mut buf, (w, h), ndf, model, title).map_err(|e| e.with_path(path))?;
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(&mut out, &buf, w, h, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
        .map_err(|e| Error::new(ErrorKind::Io, format!("PNG encoding failed: {e}")).with_path(path))?;
    crate::io::write_bytes_atomic(path, out.get_ref())
}

fn draw_fit(buf: &mut [u8], size: (u32, u32), ndf: &EmpiricalNdf, model: &Model, title: &str) -> Result<()> {
    crate::plot::ensure_font();
    // The whole hemisphere: the plot shows every bin, those beyond the fit's max_theta too.
    let data = FitData::new(ndf, Objective::Poisson, std::f64::consts::FRAC_PI_2)?;
    let ln_s = data.ln_norm(&data.bins.iter().map(|b| model.d(b.m).max(f64::MIN_POSITIVE).ln()).collect::<Vec<_>>());
    let mut pts_d = Vec::new();
    let mut pts_f = Vec::new();
    let mut pts_r = Vec::new();
    for b in &data.bins {
        let th = b.m.z.clamp(-1.0, 1.0).acos().to_degrees();
        let dm = model.d(b.m);
        let yd = (b.c / (data.n * b.w)).log10();
        if b.c > 0.0 && yd.is_finite() {
            pts_d.push((th, yd));
        }
        if dm > 0.0 && dm.is_finite() {
            pts_f.push((th, dm.log10()));
        }
        // Guard: a D of 0 (Beckmann far in its tail) has ln D = -inf; its residual is still finite.
        let (r, _) = residual(Objective::Poisson, b, if dm > 0.0 { dm.ln() } else { -745.0 } - ln_s);
        if r.is_finite() && (b.c > 0.0 || r.abs() > 0.5) {
            pts_r.push((th, r));
        }
    }
    let th_max = pts_d.iter().map(|p| p.0).fold(1.0_f64, f64::max).min(90.0) * 1.05;
    let y_hi = pts_d.iter().chain(&pts_f).map(|p| p.1).fold(f64::NEG_INFINITY, f64::max) + 0.3;
    let y_lo = pts_d.iter().map(|p| p.1).fold(f64::INFINITY, f64::min) - 0.5;
    let r_max = pts_r.iter().map(|p| p.1.abs()).fold(3.0_f64, f64::max).min(50.0);
    if pts_d.is_empty() && pts_f.is_empty() {
        return Err(Error::invalid("cannot plot: no bin has a finite D, in the data or the fit"));
    }
    let y_lo = if pts_d.is_empty() { pts_f.iter().map(|p| p.1).fold(f64::INFINITY, f64::min) - 0.5 } else { y_lo };
    let y = crate::plot::axis(y_lo, y_hi, 1.0, "log10 D")?;
    let th = crate::plot::axis(0.0, th_max, 1.0, "polar angle")?;
    {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(perr)?;
        let (top, bottom) = root.split_vertically(520);
        let mut c = ChartBuilder::on(&top)
            .caption(title, (crate::plot::FONT, 20))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(th.clone(), y)
            .map_err(perr)?;
        c.configure_mesh().x_desc("polar angle of m (deg)").y_desc("log10 D (1/sr)").label_style((crate::plot::FONT, 14)).draw().map_err(perr)?;
        c.draw_series(pts_d.iter().map(|p| Circle::new(*p, 2, RGBColor(110, 110, 110).filled())))
            .map_err(perr)?
            .label("data (bins)")
            .legend(|(x, y)| Circle::new((x, y), 3, RGBColor(110, 110, 110).filled()));
        c.draw_series(pts_f.iter().filter(|p| p.1 >= y_lo).map(|p| Circle::new(*p, 1, RED.filled())))
            .map_err(perr)?
            .label("fit at the same bins")
            .legend(|(x, y)| Circle::new((x, y), 3, RED.filled()));
        c.configure_series_labels().border_style(BLACK).background_style(WHITE).label_font((crate::plot::FONT, 14)).draw().map_err(perr)?;
        let mut c2 = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(th, -r_max..r_max)
            .map_err(perr)?;
        c2.configure_mesh().x_desc("polar angle of m (deg)").y_desc("deviance residual").label_style((crate::plot::FONT, 14)).draw().map_err(perr)?;
        c2.draw_series(pts_r.iter().map(|p| Circle::new((p.0, p.1.clamp(-r_max, r_max)), 2, BLUE.mix(0.5).filled()))).map_err(perr)?;
        c2.draw_series(LineSeries::new([(0.0, 0.0), (th_max, 0.0)], BLACK)).map_err(perr)?;
        root.present().map_err(perr)?;
    }
    Ok(())
}
