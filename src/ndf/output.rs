//! Writing an empirical NDF: CSV and JSON (`data_formats/ndf_csv.md`) and an OpenEXR image of D over
//! the orthographically projected hemisphere. Every file is written atomically.

use std::path::Path;

use nalgebra::Vector3;
use serde_json::json;

use super::EmpiricalNdf;
use crate::error::{Error, ErrorKind, Result};
use crate::io::{write_atomic, write_bytes_atomic};

/// The CSV header (the contract's `mx,my,mz,d` first).
pub const CSV_HEADER: &str = "mx,my,mz,d,stderr,count,solid_angle,proj_solid_angle,slope_x,slope_y,unresolved";

/// Write the NDF as CSV, one row per bin, empty bins included.
pub fn write_csv(path: &Path, ndf: &EmpiricalNdf) -> Result<()> {
    write_atomic(path, |w| write_csv_to(w, ndf))
}

/// The CSV of [`write_csv`] into any writer (standard output).
///
/// Formatting the shortest round-trip decimals of ten numbers per bin dominates for large grids, so
/// blocks of rows are formatted on the thread pool, a wave of blocks while the previous wave is written
/// here (the same bytes). The writing stays on the calling thread and the pool's work is scoped to it,
/// so a call from inside the pool cannot deadlock. Floats go through `zmij` (shortest round-trip digits,
/// like `core::fmt` but several times faster; it writes an exponent for very small or large magnitudes,
/// e.g. `7.4e-6` or `1e+17`, which every CSV reader parses).
pub fn write_csv_to<W: std::io::Write + ?Sized>(w: &mut W, ndf: &EmpiricalNdf) -> Result<()> {
    use rayon::prelude::*;
    // About 50 kB a block: below the allocator's mapping threshold, so blocks reuse freed heap memory.
    const ROWS: usize = 256;
    const WAVE: usize = 16 * ROWS;
    writeln!(w, "{CSV_HEADER}")?;
    let mut done: Vec<Vec<u8>> = Vec::new();
    for (q, wave) in ndf.bins.chunks(WAVE).enumerate() {
        let mut next = Vec::new();
        let mut wrote = Ok(());
        rayon::in_place_scope(|s| {
            s.spawn(|_| {
                next = wave.par_chunks(ROWS).enumerate().map(|(k, rows)| csv_rows(ndf, q * WAVE + k * ROWS, rows)).collect();
            });
            wrote = done.iter().try_for_each(|b| w.write_all(b));
        });
        wrote?;
        done = next;
    }
    for b in &done {
        w.write_all(b)?;
    }
    Ok(())
}

/// The CSV rows of `bins`, the bins of `ndf` from index `first` on.
fn csv_rows(ndf: &EmpiricalNdf, first: usize, bins: &[super::NdfBin]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bins.len() * 200);
    let mut fb = zmij::Buffer::new();
    let mut ib = itoa::Buffer::new();
    for (k, b) in bins.iter().enumerate() {
        let (sx, sy) = (-b.m.x / b.m.z, -b.m.y / b.m.z);
        for v in [b.m.x, b.m.y, b.m.z, b.d, b.stderr] {
            out.extend_from_slice(fb.format(v).as_bytes());
            out.push(b',');
        }
        out.extend_from_slice(ib.format(b.count).as_bytes());
        for v in [b.solid_angle, b.proj_solid_angle, sx, sy] {
            out.push(b',');
            out.extend_from_slice(fb.format(v).as_bytes());
        }
        out.push(b',');
        // Not assessed (triangle normals): an empty field.
        if let Some(&u) = ndf.unresolved.get(first + k) {
            out.extend_from_slice(ib.format(u).as_bytes());
        }
        out.push(b'\n');
    }
    out
}

/// The NDF as a JSON value (`ndfit.ndf/1`); `input` describes the scan (path, format, grid).
pub fn to_json(ndf: &EmpiricalNdf, input: serde_json::Value) -> serde_json::Value {
    let bins: Vec<serde_json::Value> = ndf
        .bins
        .iter()
        .map(|b| {
            json!({
                "m": [b.m.x, b.m.y, b.m.z], "d": b.d, "stderr": b.stderr, "count": b.count,
                "solid_angle": b.solid_angle, "proj_solid_angle": b.proj_solid_angle,
            })
        })
        .collect();
    json!({
        "schema": "ndfit.ndf/1",
        "input": input,
        "options": {"normals": ndf.scheme.as_str(), "cells_across": ndf.grid.n, "domain": "lambert-whitened"},
        "n_samples": ndf.n_samples,
        "n_skipped": ndf.n_skipped,
        "sample_area": ndf.sample_area,
        "slope_mean": ndf.slope_mean,
        "slope_cov": ndf.slope_cov,
        "frame": ndf.frame,
        "quantization": ndf.quantization,
        "f32_storage": ndf.f32_storage,
        "warnings": ndf.warnings,
        "bins": bins,
    })
}

/// Write `to_json` to `path`.
pub fn write_json(path: &Path, ndf: &EmpiricalNdf, input: serde_json::Value) -> Result<()> {
    let v = to_json(ndf, input);
    write_atomic(path, |w| serde_json::to_writer(w, &v).map_err(|e| Error::new(ErrorKind::Io, e.to_string())))
}

/// D on a `res x res` raster of the orthographic projection of the hemisphere: pixel `(row, col)` is
/// `m = (mx, my, sqrt(1 - mx^2 - my^2))` with `mx = -1 + (col + 0.5) 2 / res`, `my = 1 - (row + 0.5) 2 / res`
/// (+y up); 0 outside the unit disk. The window can be narrowed to `center +- half` in `(mx, my)`.
pub fn raster(ndf: &EmpiricalNdf, res: usize, center: [f64; 2], half: f64) -> Vec<f64> {
    let mut out = vec![0.0; res * res];
    for (row, line) in out.chunks_mut(res).enumerate() {
        let my = center[1] + half * (1.0 - (row as f64 + 0.5) * 2.0 / res as f64);
        for (col, v) in line.iter_mut().enumerate() {
            let mx = center[0] + half * (-1.0 + (col as f64 + 0.5) * 2.0 / res as f64);
            let r2 = mx * mx + my * my;
            if r2 < 1.0 {
                *v = ndf.d_at(Vector3::new(mx, my, (1.0 - r2).sqrt()));
            }
        }
    }
    out
}

/// Write an OpenEXR image (one float channel `D`, `res x res`) of `raster` over the whole hemisphere.
pub fn write_exr(path: &Path, ndf: &EmpiricalNdf, res: usize) -> Result<()> {
    use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, WritableImage};
    if res == 0 || res > 8192 {
        return Err(Error::invalid(format!("EXR size {res} must be between 1 and 8192")).with_path(path));
    }
    let data: Vec<f32> = raster(ndf, res, [0.0, 0.0], 1.0).into_iter().map(|v| v as f32).collect();
    let channel = AnyChannel::new("D", FlatSamples::F32(data));
    let layer = Layer::new(
        (res, res),
        LayerAttributes::named("ndf"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let image = Image::from_layer(layer);
    let mut buf = std::io::Cursor::new(Vec::new());
    image.write().to_buffered(&mut buf).map_err(|e| Error::new(ErrorKind::Io, format!("EXR encoding failed: {e}")).with_path(path))?;
    write_bytes_atomic(path, buf.get_ref())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ndf::NdfBin;

    /// Every row parses back to its bin's values bit for bit, in bin order (magnitudes from 1e-300 to
    /// 1e+300, exponent forms included), and the bytes are the same whether written from outside the pool
    /// or from every thread of the pool at once (each call scopes its formatting: none waits on
    /// another's).
    #[test]
    fn csv_rows_parse_back_from_inside_the_pool() {
        use rayon::prelude::*;
        let bins: Vec<NdfBin> = (0..9000)
            .map(|k| {
                let t = k as f64 * 1e-4;
                // Every 7th normal grazes the rim: its slopes pass 1e16.
                let mz = if k % 7 == 0 { 1e-18 * (1.0 + t) } else { 0.5 + 0.4 * t.cos() };
                let m = Vector3::new(0.5 * t.sin(), 0.5 * t.cos(), mz);
                let d = 10f64.powi(k % 601 - 300) * (1.0 + t);
                NdfBin { m, d, stderr: 1e-3 * t, count: k as u64, solid_angle: 1e-4 + t, proj_solid_angle: 1e-4 * t }
            })
            .collect();
        let ndf = EmpiricalNdf::from_bins(bins, 9000);
        let mut alone = Vec::new();
        write_csv_to(&mut alone, &ndf).unwrap();
        let text = String::from_utf8(alone.clone()).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(CSV_HEADER));
        let mut n = 0;
        for (line, b) in lines.zip(&ndf.bins) {
            let f: Vec<&str> = line.split(',').collect();
            let want = [b.m.x, b.m.y, b.m.z, b.d, b.stderr, b.solid_angle, b.proj_solid_angle, -b.m.x / b.m.z, -b.m.y / b.m.z];
            for (&i, w) in [0, 1, 2, 3, 4, 6, 7, 8, 9].iter().zip(want) {
                assert_eq!(f[i].parse::<f64>().unwrap().to_bits(), w.to_bits(), "{line}");
            }
            assert_eq!((f[5].parse::<u64>().unwrap(), f[10]), (b.count, ""), "{line}");
            n += 1;
        }
        assert_eq!(n, ndf.bins.len());
        assert!(text.contains("e+"), "large magnitudes are written with an exponent");
        let calls = 2 * rayon::current_num_threads() + 1;
        let outs: Vec<Vec<u8>> = (0..calls)
            .into_par_iter()
            .map(|_| {
                let mut out = Vec::new();
                write_csv_to(&mut out, &ndf).unwrap();
                out
            })
            .collect();
        assert!(outs.iter().all(|o| *o == alone));
    }
}
