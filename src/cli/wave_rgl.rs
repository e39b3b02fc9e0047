//! `ndfit wave SCAN --to rgl -o OUT.bsdf`: the diffuse part of the scan's wave BRDF as a spectral RGL
//! table in the layout `ndfit export SCAN --to rgl` writes, and beside it `OUT.bsdf.json`, the
//! `ndfit.wave/1` report at the table's incidences with the mirror share a renderer adds as a conductor
//! (`ndfit::wave::wave_rgl`; data_formats/rgl.md, "The wave BRDF's table").

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, bail};
use ndfit::export::rgl::RglOptions;
use ndfit::wave::{wave_rgl, WaveRglOptions, DEFAULT_INCIDENCES_DEG};

use super::export::TableArgs;

/// The table's flags of `ndfit wave --to rgl` (as `ndfit export --to rgl` names them).
#[derive(Debug, Clone, clap::Args)]
pub struct RglArgs {
    /// The table's resolution (the defaults of `ndfit export`). The table is always spectral, at the
    /// wavelengths of --wavelength (--spectral changes nothing); its incidences are its --theta-i nodes,
    /// the 90-degree node computed at 89.9 degrees.
    #[command(flatten)]
    pub table: TableArgs,
}

/// Run `ndfit wave --to rgl`.
pub fn run(a: &super::wave::Args) -> anyhow::Result<ExitCode> {
    let path = a.scan.scan.display().to_string();
    let Some(out) = &a.out else { bail!("{path}: --to rgl writes a file: give it with -o OUT.bsdf") };
    if a.grid_out.is_some() {
        bail!("{path}: --grid-out writes the grid of --to json; it is not for --to rgl");
    }
    if a.incidence != DEFAULT_INCIDENCES_DEG {
        bail!("{path}: --incidence is not for --to rgl: the table's incidences are its --theta-i nodes from 0 to 90 degrees");
    }
    let wave = a.options()?;
    let opts = WaveRglOptions { wave, rgl: a.rgl.table.options(a.material, RglOptions::default()) };
    opts.validate().map_err(|e| anyhow!("{path}: {}", e.message()))?;
    let sidecar = {
        let mut s = out.clone().into_os_string();
        s.push(".json");
        PathBuf::from(s)
    };
    a.scan.check_outputs([out.as_path(), sidecar.as_path()])?;
    let scan = a.scan.load()?;
    let name = a.scan.scan.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
    let bar = super::wave::patch_bar(a.quiet);
    let progress = |done: usize, total: usize| super::wave::show(&bar, done, total);
    let t = wave_rgl(&scan, &opts, &format!("the scan {name}"), Some(&progress)).map_err(|e| anyhow!("{path}: {}", e.message()))?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let file = out.file_name().map_or(out.display().to_string(), |n| n.to_string_lossy().into_owned());
    let json = serde_json::to_string_pretty(&t.sidecar(&file))? + "\n";
    let bytes = t.table.tensor.to_bytes();
    // Both or neither: the report first, withdrawn if the table cannot be written.
    ndfit::io::write_atomic(&sidecar, |w| w.write_all(json.as_bytes()).map_err(ndfit::Error::io))?;
    if let Err(e) = ndfit::io::write_bytes_atomic(out, &bytes) {
        let _ = std::fs::remove_file(&sidecar);
        return Err(e.into());
    }
    if !a.quiet {
        let r = &opts.rgl;
        eprintln!(
            "ndfit: {path}: wrote {} ({} bytes; {} x {} incident nodes, warps of {}^2, NDF grid {}^2) and {}",
            out.display(),
            bytes.len(),
            r.theta_i,
            r.phi_i,
            r.warp_res,
            t.table.ndf_res,
            sidecar.display()
        );
        for line in mirror_lines(&t) {
            eprintln!("ndfit: wave: {line}");
        }
        if let Some((i, gap)) = t.worst_albedo_gap(ndfit::wave::MAX_INCIDENCE_DEG) {
            let w = &t.report.records[i];
            eprintln!(
                "ndfit: wave: the table's albedo within {gap:.4} of the diffuse albedo (worst {:.4} against {:.4} at {} nm, {:.1} deg)",
                t.table_albedo[i], t.wave_diffuse[i], w.wavelength_nm, w.theta_deg
            );
        }
        for w in &t.report.warnings {
            eprintln!("ndfit: wave: note: {w}");
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// One line per wavelength: the mirror share (not in the table) at normal incidence, and at the table's
/// incident elevation nodes.
fn mirror_lines(t: &ndfit::wave::WaveTable) -> Vec<String> {
    let mut lines = Vec::new();
    let records = &t.report.records;
    let mut start = 0;
    while start < records.len() {
        let nm = records[start].wavelength_nm;
        let end = start + records[start..].iter().take_while(|r| r.wavelength_nm == nm).count();
        let these = &records[start..end];
        let shares: Vec<String> = these.iter().map(|r| format!("{:.3}", r.specular)).collect();
        let angles: Vec<String> = these.iter().map(|r| format!("{}", (r.theta_deg * 10.0).round() / 10.0)).collect();
        lines.push(format!(
            "mirror share at {nm} nm (not in the table; add a conductor of this weight): {:.4} at normal incidence; at {} deg: {}",
            these[0].specular,
            angles.join("/"),
            shares.join(" ")
        ));
        start = end;
    }
    lines
}
