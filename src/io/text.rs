//! Plain text heightfields: ASCII matrix (optionally with an `AsciiMatrix cols rows [du dv]` header),
//! CSV matrix or x,y,z columns, and XYZ point lists on a regular grid.
//!
//! Separators are any run of spaces, tabs, commas or semicolons; `#` and `%` start comments; blank
//! lines are skipped. `nan`, `NaN`, `-nan` (and infinities) are invalid points. None of these
//! formats carries units, so heights need `--z-scale` (metres per unit). Spacing: `--dx`/`--dy`, or
//! for an `AsciiMatrix` header its `du dv` and for XYZ the grid step of the x/y columns, both taken
//! in the same unit as the heights (so slopes need no unit at all) and converted with `--z-scale`.
//! Row 0 is the first row in the file (y grows down the file).

use crate::error::{Error, ErrorKind, Result};
use crate::io::raw_opts::{spacing, z_scale};
use crate::io::ReadOptions;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `ascii` format ([`crate::io::Reader`]).
pub const ASCII_READER: crate::io::Reader = crate::io::Reader {
    id: "ascii",
    extensions: &["asc", "txt", "ascii"],
    magic: Some(|h| h.starts_with(b"AsciiMatrix")),
    read: read_ascii_matrix,
};
/// The registry entry of the `csv` format ([`crate::io::Reader`]). No signature: found by extension.
pub const CSV_READER: crate::io::Reader = crate::io::Reader { id: "csv", extensions: &["csv"], magic: None, read: read_csv };
/// The registry entry of the `xyz` format ([`crate::io::Reader`]). No signature: found by extension.
pub const XYZ_READER: crate::io::Reader = crate::io::Reader { id: "xyz", extensions: &["xyz"], magic: None, read: read_xyz };

/// Largest text file parsed (bounds memory: tokens are held as f64).
const MAX_TEXT: usize = 1 << 31;

fn tokens(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_whitespace() || c == ',' || c == ';').filter(|t| !t.is_empty())
}

fn strip_comment(line: &str) -> &str {
    match line.find(['#', '%']) {
        Some(k) => &line[..k],
        None => line,
    }
}

fn number(t: &str, line: usize) -> Result<f64> {
    match t {
        "nan" | "NaN" | "NAN" | "-nan" | "-NaN" | "NA" | "***" => Ok(f64::NAN),
        _ => t.parse::<f64>().map_err(|_| Error::corrupt(format!("line {line}: {t:?} is not a number"))),
    }
}

/// Memory a text scan may need per byte of the file (see [`text_of`]).
const TEXT_BYTES_PER_FILE_BYTE: u64 = 24;

fn text_of(bytes: &[u8]) -> Result<&str> {
    if bytes.len() > MAX_TEXT {
        return Err(Error::new(ErrorKind::Unsupported, format!("text file over {MAX_TEXT} bytes")));
    }
    // Every value is at least two bytes of text: parsing holds at most ~12 bytes per file byte (an XYZ
    // triple per line), and the grid's later stages ~24 bytes per point, i.e. ~12 per file byte.
    crate::budget::check_bytes((bytes.len() as u64).saturating_mul(TEXT_BYTES_PER_FILE_BYTE), "reading this text scan")?;
    std::str::from_utf8(bytes).map_err(|e| Error::corrupt(format!("not UTF-8/ASCII text (byte {})", e.valid_up_to())))
}

/// Rows of numbers (comments and blank lines skipped), each with its 1-based line number.
fn numeric_rows(text: &str, skip_first: bool) -> Result<Vec<(usize, Vec<f64>)>> {
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate().skip(usize::from(skip_first)) {
        let line = strip_comment(line);
        let row: Vec<f64> = tokens(line).map(|t| number(t, k + 1)).collect::<Result<_>>()?;
        if !row.is_empty() {
            rows.push((k + 1, row));
        }
    }
    Ok(rows)
}

/// Read an ASCII matrix (one grid row per line).
pub fn read_ascii_matrix(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    let text = text_of(bytes)?;
    let first = text.lines().next().unwrap_or("").trim();
    // Columns, rows and the optional spacing the header declares.
    #[allow(clippy::type_complexity)]
    let mut header: Option<(usize, usize, Option<(f64, f64)>)> = None;
    if first.starts_with("AsciiMatrix") {
        let t: Vec<&str> = tokens(first).skip(1).collect();
        let bad = || Error::corrupt(format!("header {first:?} is not `AsciiMatrix cols rows [du dv]`"));
        if t.len() != 2 && t.len() != 4 {
            return Err(bad());
        }
        let cols: usize = t[0].parse().map_err(|_| bad())?;
        let rows: usize = t[1].parse().map_err(|_| bad())?;
        let d = if t.len() == 4 {
            let du: f64 = t[2].parse().map_err(|_| bad())?;
            let dv: f64 = t[3].parse().map_err(|_| bad())?;
            if !(du.is_finite() && du > 0.0 && dv.is_finite() && dv > 0.0) {
                return Err(Error::corrupt(format!("AsciiMatrix spacing {du} {dv} is not positive")));
            }
            Some((du, dv))
        } else {
            None
        };
        header = Some((cols, rows, d));
    }
    let rows = numeric_rows(text, header.is_some())?;
    if rows.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "no numbers in the file"));
    }
    let nx = rows[0].1.len();
    for (line, r) in &rows {
        if r.len() != nx {
            return Err(Error::corrupt(format!("line {line} has {} values, the first row has {nx}", r.len())));
        }
    }
    let ny = rows.len();
    if let Some((cols, nrows, _)) = header {
        if (cols, nrows) != (nx, ny) {
            return Err(Error::corrupt(format!("AsciiMatrix header says {cols} x {nrows} but the file holds {nx} x {ny}")));
        }
    }
    let zs = z_scale(opts, "ASCII matrix")?;
    let (dx, dy) = match (header.and_then(|h| h.2), opts.dx) {
        (_, Some(_)) => spacing(opts, "ASCII matrix")?,
        (Some((du, dv)), None) => (du * zs.abs(), dv * zs.abs()),
        (None, None) => spacing(opts, "ASCII matrix")?,
    };
    let z: Vec<f64> = rows.into_iter().flat_map(|(_, r)| r).map(|v| v * zs).collect();
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: "ascii".into(), ..Default::default() };
    if header.is_some() {
        hf.meta.instrument.insert("ascii.header".into(), first.to_string());
    }
    Ok(hf)
}

/// Read a CSV file: x,y,z columns when its header names them, else a matrix of heights.
pub fn read_csv(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    let text = text_of(bytes)?;
    let first = text.lines().next().unwrap_or("");
    let names: Vec<String> = tokens(first).map(|t| t.trim_matches('"').to_ascii_lowercase()).collect();
    let is_header = !names.is_empty() && names.iter().any(|n| n.parse::<f64>().is_err() && !n.contains("nan"));
    if is_header {
        let col = |n: &str| {
            names.iter().position(|c| {
                c == n || c.starts_with(&format!("{n} ")) || c.starts_with(&format!("{n}(")) || c.starts_with(&format!("{n}["))
            })
        };
        if let (Some(x), Some(y), Some(z)) = (col("x"), col("y"), col("z")) {
            let rows = numeric_rows(text, true)?;
            let pts = rows
                .iter()
                .map(|(line, r)| {
                    let need = x.max(y).max(z);
                    if r.len() <= need {
                        return Err(Error::corrupt(format!("line {line} has {} columns, x/y/z need {}", r.len(), need + 1)));
                    }
                    Ok((r[x], r[y], r[z]))
                })
                .collect::<Result<Vec<_>>>()?;
            let mut hf = grid_from_points(&pts, opts, "CSV")?;
            hf.meta.format = "csv".into();
            return Ok(hf);
        }
        return Err(Error::corrupt(format!("CSV header {first:?} names no x, y and z columns")));
    }
    let mut hf = read_ascii_matrix(bytes, opts)?;
    hf.meta.format = "csv".into();
    Ok(hf)
}

/// Read an XYZ point list lying on a regular grid.
pub fn read_xyz(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    let text = text_of(bytes)?;
    let rows = numeric_rows(text, false)?;
    let pts = rows
        .iter()
        .map(|(line, r)| {
            if r.len() != 3 {
                return Err(Error::corrupt(format!("line {line} has {} values, XYZ needs 3", r.len())));
            }
            Ok((r[0], r[1], r[2]))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut hf = grid_from_points(&pts, opts, "XYZ")?;
    hf.meta.format = "xyz".into();
    Ok(hf)
}

/// Place (x, y, z) points on the regular grid they sample. Grid nodes without a point are invalid.
/// Coordinates and heights share the file's unit, converted with `--z-scale`.
pub fn grid_from_points(pts: &[(f64, f64, f64)], opts: &ReadOptions, what: &str) -> Result<Heightfield> {
    if pts.is_empty() {
        return Err(Error::new(ErrorKind::BadData, format!("{what}: no points")));
    }
    if pts.iter().any(|p| !(p.0.is_finite() && p.1.is_finite())) {
        return Err(Error::corrupt(format!("{what}: a point has a non-finite x or y")));
    }
    let zs = z_scale(opts, what)?;
    let (sx, x0) = axis_step(pts.iter().map(|p| p.0), what, "x")?;
    let (sy, y0) = axis_step(pts.iter().map(|p| p.1), what, "y")?;
    let (sx, sy) = match (sx.is_nan(), sy.is_nan()) {
        (false, false) => (sx, sy),
        (true, false) => (sy, sy),
        (false, true) => (sx, sx),
        (true, true) => return Err(Error::new(ErrorKind::BadData, format!("{what}: all points share one x and one y"))),
    };
    let idx = |v: f64, o: f64, s: f64| ((v - o) / s).round();
    let nx = pts.iter().map(|p| idx(p.0, x0, sx)).fold(0.0f64, f64::max) as usize + 1;
    let ny = pts.iter().map(|p| idx(p.1, y0, sy)).fold(0.0f64, f64::max) as usize + 1;
    // A grid much larger than the point count is not a grid sampled by these points.
    let cells = nx
        .checked_mul(ny)
        .filter(|&c| c <= pts.len().saturating_mul(4).max(16))
        .ok_or_else(|| Error::corrupt(format!("{what}: {} points do not sample a regular grid ({nx} x {ny} nodes)", pts.len())))?;
    let mut z = vec![f64::NAN; cells];
    let mut seen = vec![false; cells];
    for p in pts {
        let (fj, fi) = ((p.0 - x0) / sx, (p.1 - y0) / sy);
        let (j, i) = (fj.round(), fi.round());
        // Nodes sit on the grid to within 1e-3 of a step (text rounding), else it is not a grid.
        if (fj - j).abs() > 1e-3 || (fi - i).abs() > 1e-3 {
            return Err(Error::corrupt(format!("{what}: point ({}, {}) is off the regular grid", p.0, p.1)));
        }
        let k = i as usize * nx + j as usize;
        if seen[k] {
            return Err(Error::corrupt(format!("{what}: two points at grid node ({}, {})", p.0, p.1)));
        }
        seen[k] = true;
        z[k] = p.2 * zs;
    }
    let (dx, dy) = if opts.dx.is_some() { spacing(opts, what)? } else { (sx * zs.abs(), sy * zs.abs()) };
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.x0 = x0 * zs.abs();
    hf.y0 = y0 * zs.abs();
    Ok(hf)
}

/// Smallest step between distinct values of one coordinate, and the minimum.
fn axis_step(vals: impl Iterator<Item = f64>, what: &str, axis: &str) -> Result<(f64, f64)> {
    let mut v: Vec<f64> = vals.collect();
    v.sort_by(f64::total_cmp);
    let lo = v[0];
    let span = v[v.len() - 1] - lo;
    if span == 0.0 {
        // A single column/row of points: one node along this axis; the caller borrows the other
        // axis's step (a profile has no spacing across it).
        return Ok((f64::NAN, lo));
    }
    // Values closer than 1e-9 of the span are the same node written with rounding.
    let tol = span * 1e-9;
    let mut step = f64::INFINITY;
    for w in v.windows(2) {
        let d = w[1] - w[0];
        if d > tol {
            step = step.min(d);
        }
    }
    if !step.is_finite() || step <= 0.0 {
        return Err(Error::corrupt(format!("{what}: cannot find the {axis} grid step")));
    }
    Ok((step, lo))
}
