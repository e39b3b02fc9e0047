//! `ndfit trace SCAN --to rgl -o OUT.bsdf`: the scan's traced BRDF (all bounces, true shadowing) as an
//! RGL table on the warps of its measured NDF, the layout `ndfit export SCAN --to rgl` writes
//! (`ndfit::trace::trace_rgl`; docs/TRACE.md, "The scan's own BRDF as a material").

use std::io::IsTerminal;
use std::process::ExitCode;

use anyhow::{anyhow, bail};
use ndfit::export::rgl;
use ndfit::models::Ndf;
use ndfit::trace::{trace_rgl, TracedRglOptions};

use super::export::{material_text, params_text, scan_table_ndf, TableArgs};

/// The table's flags of `ndfit trace --to rgl` (as `ndfit export --to rgl` names them).
#[derive(Debug, Clone, clap::Args)]
pub struct RglArgs {
    /// Paths traced per incident direction of the table (the nodes of one direction share them).
    #[arg(long, default_value_t = TracedRglOptions::default().paths)]
    pub paths: usize,
    /// The table's resolution and channels (the 90-degree incident node is traced at 89.9 degrees;
    /// with `--spectral` the paths carry the Fresnel factor at each wavelength).
    #[command(flatten)]
    pub table: TableArgs,
}

/// Run `ndfit trace --to rgl`.
pub fn run(a: &super::trace::Args) -> anyhow::Result<ExitCode> {
    let path = a.scan.scan.display().to_string();
    let Some(out) = &a.out else { bail!("{path}: --to rgl writes a file: give it with -o OUT.bsdf") };
    if a.tables.is_some() {
        bail!("{path}: --tables writes the bins of --to json; it is not for --to rgl");
    }
    if a.plot.is_some() {
        bail!("{path}: --plot draws the comparison of --to json; it is not for --to rgl");
    }
    let r = &a.rgl;
    let opts = TracedRglOptions {
        rgl: r.table.options(a.material, TracedRglOptions::default().rgl),
        paths: r.paths,
        bounces: a.bounces,
        seed: a.seed,
        border: a.border,
    };
    opts.validate().map_err(|e| anyhow!("{path}: {}", e.message()))?;
    a.scan.check_outputs([out.as_path()])?;
    // The NDF as `ndfit export SCAN --to rgl` tabulates it (the fit's flags at their defaults).
    let how = &a.scan.how;
    let options = ndfit::Options {
        read: how.read_options(),
        preprocess: how.preprocess(),
        model: ndfit::ModelChoice::Auto,
        ..ndfit::Options::default()
    };
    options.validate().map_err(|e| e.with_path(&a.scan.scan))?;
    let (outcome, fit, max_theta) = scan_table_ndf(options, &a.scan.scan)?;
    let reg = rgl::Regularized::new(&outcome.ndf, &fit, max_theta);
    let scan = a.scan.load()?;
    let name = a.scan.scan.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
    let description = format!(
        "ndfit traced BRDF of the scan {name}: reflectance from {} geometric-optics paths per incident direction over the scan's heights \
         (two triangles per cell, {:?} border, up to {} bounces, Fresnel per bounce, seed {}); conductor {}; on the warps of its measured NDF: {}; \
         fitted {} {}; phi = 0 and the tangent u along the scan's +x",
        opts.paths,
        opts.border,
        opts.bounces,
        opts.seed,
        material_text(a.material),
        reg.describe(max_theta),
        fit.id(),
        params_text(&fit)
    );
    let bar = (std::io::stderr().is_terminal() && !a.quiet).then(|| {
        let b = indicatif::ProgressBar::new(0);
        if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} paths ({per_sec}, {eta} left)") {
            b.set_style(style);
        }
        b
    });
    let progress = |done: u64, total: u64| {
        if let Some(b) = &bar {
            b.set_length(total);
            b.set_position(done);
        }
    };
    let t = trace_rgl(&scan, &|m| reg.d(m), &|m| fit.d(m), &description, &opts, Some(&progress))
        .map_err(|e| anyhow!("{path}: {}", e.message()))?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let bytes = t.table.tensor.to_bytes();
    ndfit::io::write_bytes_atomic(out, &bytes)?;
    if !a.quiet {
        eprintln!(
            "ndfit: {path}: wrote {} ({} bytes; {} incident directions x {} paths; NDF grid {}^2)",
            out.display(),
            bytes.len(),
            t.traced_directions,
            opts.paths,
            t.table.ndf_res
        );
        let mut noise: Vec<f64> = t.nodes.iter().map(|r| r.noise).collect();
        noise.sort_by(f64::total_cmp);
        if let Some(w) = t.worst_uncarried() {
            eprintln!(
                "ndfit: trace: energy the table cannot carry (half vectors where D < {:.0e} of its peak): up to {:.3}% of the reflected, at {:.0}/{:.0} deg",
                ndfit::trace::CARRY_FLOOR,
                100.0 * w.uncarried,
                w.theta_deg,
                w.phi_deg
            );
        }
        if let Some((gap, w)) = t.worst_albedo_gap() {
            eprintln!(
                "ndfit: trace: the table's albedo within {:.4} of the traced carried energy below grazing (worst {:.4} vs {:.4} at {:.0}/{:.0} deg); median noise of R per node {:.1}%",
                gap,
                w.table_albedo,
                (1.0 - w.uncarried) * w.albedo,
                w.theta_deg,
                w.phi_deg,
                100.0 * noise.get(noise.len() / 2).copied().unwrap_or(0.0)
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
