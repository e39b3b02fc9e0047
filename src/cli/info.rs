//! `ndfit info`: format, grid, spacing, units, instrument metadata, the file's invalid count, height range,
//! Sq, Sdq, and apart from them the points the fit's spike test would mask.

use std::process::ExitCode;

use ndfit::stats::{surface_stats, surface_stats_of};

use super::scan_args::ScanArgs;

/// Arguments of `ndfit info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    scan: ScanArgs,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Run `ndfit info`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let raw = args.scan.load_raw()?;
    // The file as stored (after any crop/subsample the user asked for): its own invalid points, its
    // height range, and Sq and Sdq after the requested form removal (the plane by default), with nothing
    // masked. What the requested preprocessing would mask on top (`spikes`) is reported apart.
    let pre = args.scan.how.preprocess();
    let pre_form = pre.form;
    let path = &args.scan.scan;
    let as_stored = ndfit::preprocess::Preprocess { despike: ndfit::preprocess::Despike::None, ..pre.clone() };
    let shape_only = ndfit::preprocess::Preprocess { form: ndfit::preprocess::FormRemoval::None, ..as_stored.clone() };
    let (prepared, materialized);
    let (shaped, range, st, despike) = match pre_form {
        // Sq removes the least-squares plane itself: the statistics are read band by band from the
        // heights as read (a mapped or tiled scan is never copied), the same numbers as in memory. The
        // spikes are those the fit masks (after the form removal), kept apart from the heights.
        ndfit::preprocess::FormRemoval::Plane | ndfit::preprocess::FormRemoval::None => {
            prepared = ndfit::preprocess::prepare(raw, &pre).map_err(|e| e.with_path(path))?;
            let st = surface_stats_of(prepared.raw()).map_err(|e| e.with_path(path))?;
            (prepared.raw(), st, st, prepared.meta().despike.clone())
        }
        // Other forms are removed first (into memory).
        _ => {
            materialized = ndfit::preprocess::apply(raw, &shape_only).map_err(|e| e.with_path(path))?;
            let whole = |p: &ndfit::preprocess::Preprocess| ndfit::preprocess::Preprocess { crop: None, subsample: 1, ..p.clone() };
            let leveled = ndfit::preprocess::apply(materialized.clone(), &whole(&as_stored)).map_err(|e| e.with_path(path))?;
            let despiked = ndfit::preprocess::prepare(materialized.clone(), &whole(&pre)).map_err(|e| e.with_path(path))?;
            let range = surface_stats(&materialized).map_err(|e| e.with_path(path))?;
            let st = surface_stats(&leveled).map_err(|e| e.with_path(path))?;
            (&materialized, range, st, despiked.meta().despike.clone())
        }
    };
    let spikes = despike.as_ref().map_or(0, |d| d.masked);
    let m = &shaped.meta;
    if args.json {
        let v = serde_json::json!({
            "path": args.scan.scan.display().to_string(),
            "format": m.format,
            "nx": shaped.nx,
            "ny": shaped.ny,
            "dx": shaped.dx,
            "dy": shaped.dy,
            "x0": shaped.x0,
            "y0": shaped.y0,
            "units": "m",
            "file_xy_unit": m.file_xy_unit,
            "file_z_unit": m.file_z_unit,
            "invalid": range.invalid,
            "spikes": spikes,
            "despike": despike,
            "valid": range.valid,
            "z_min": range.z_min,
            "z_max": range.z_max,
            "z_mean": range.z_mean,
            "form": format!("{:?}", pre_form).to_lowercase(),
            "sq": st.sq,
            "sdq": if st.sdq.is_finite() { serde_json::json!(st.sdq) } else { serde_json::Value::Null },
            "sdq_points": st.sdq_points,
            "instrument": m.instrument,
        });
        super::write_stdout((serde_json::to_string_pretty(&v)? + "\n").as_bytes())?;
    } else {
        use std::fmt::Write as _;
        let mut text = String::new();
        let _ = writeln!(text, "file:       {}", args.scan.scan.display());
        let _ = writeln!(text, "format:     {}", m.format);
        let _ = writeln!(text, "grid:       {} x {} ({} points)", shaped.nx, shaped.ny, shaped.nx * shaped.ny);
        let _ = writeln!(text, "spacing:    dx = {} m, dy = {} m", sig(shaped.dx), sig(shaped.dy));
        let _ = writeln!(text, "origin:     x0 = {} m, y0 = {} m", sig(shaped.x0), sig(shaped.y0));
        let _ = writeln!(
            text,
            "file units: lateral {}, height {} (held in metres)",
            m.file_xy_unit.as_deref().unwrap_or("none"),
            m.file_z_unit.as_deref().unwrap_or("none")
        );
        let _ = writeln!(text, "invalid:    {} of {} (as stored)", range.invalid, range.invalid + range.valid);
        let _ = match &despike {
            Some(d) => writeln!(text, "spikes:     {spikes} more masked by the fit's spike test ({})", d.rule),
            None => writeln!(text, "spikes:     not tested (--despike none)"),
        };
        let _ = writeln!(text, "heights:    {} .. {} m (mean {} m)", sig(range.z_min), sig(range.z_max), sig(range.z_mean));
        let _ = writeln!(text, "Sq:         {} m (after {} removal)", sig(st.sq), format!("{pre_form:?}").to_lowercase());
        let _ = writeln!(text, "Sdq:        {} (central differences, {} points with 4 valid neighbours)", sig(st.sdq), st.sdq_points);
        for (k, v) in &m.instrument {
            let _ = writeln!(text, "meta:       {k} = {}", super::one_line(v));
        }
        super::write_stdout(text.as_bytes())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// A value for people: six significant digits, no trailing zeros, `0` for zero (the JSON keeps every digit).
fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { v.to_string() };
    }
    let s = format!("{v:.5e}");
    let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let mant = if mant.contains('.') { mant.trim_end_matches('0').trim_end_matches('.') } else { mant };
    if exp == "0" {
        mant.to_string()
    } else {
        format!("{mant}e{exp}")
    }
}
