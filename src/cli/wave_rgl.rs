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
    /// Write the table as the haze of the whole material, the smooth conductor blended with it: its
    /// reflectance at 1/w for a blend of weight w (the constant `ndfit export` writes for a mirror
    /// answer), and the blend printed on standard output for Mitsuba 3 (`blendbsdf`, spectral variants;
    /// a GGX conductor of alpha 1e-4 stands for the mirror) and pbrt-v4 (`mix`).
    #[arg(long)]
    pub with_mirror: bool,
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
    let mut t = wave_rgl(&scan, &opts, &format!("the scan {name}"), Some(&progress)).map_err(|e| anyhow!("{path}: {}", e.message()))?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let blend = if a.rgl.with_mirror { Some(t.blend_with_mirror().map_err(|e| anyhow!("{path}: {}", e.message()))?) } else { None };
    let file = out.file_name().map_or(out.display().to_string(), |n| n.to_string_lossy().into_owned());
    let mut sidecar_json = t.sidecar(&file);
    if let (Some(b), Some(o)) = (&blend, sidecar_json.as_object_mut()) {
        o.insert("blend".into(), serde_json::to_value(b)?);
    }
    let json = serde_json::to_string_pretty(&sidecar_json)? + "\n";
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
    if let Some(b) = &blend {
        print!("{}", blend_snippets(&name, &out.display().to_string(), b, opts.wave.material));
    }
    Ok(ExitCode::SUCCESS)
}

/// The roughness of the GGX lobe that stands for the mirror in Mitsuba's blend: Mitsuba 3.9.1's path tracer
/// over-counts a `blendbsdf` of the delta `conductor` and a `measured` BSDF (2.1x at weight 0.5), not one of
/// a `roughconductor` (data_formats/rgl.md, "Blended with the mirror"); at 1e-4 the light's image is as sharp.
const MITSUBA_MIRROR_ALPHA: f64 = 1e-4;

/// The smooth conductor blended with the table at `file` (`--with-mirror`), for Mitsuba 3 and pbrt-v4.
fn blend_snippets(scan: &str, file: &str, b: &ndfit::wave::MirrorBlend, material: ndfit::export::rgl::Material) -> String {
    use ndfit::export::rgl::Material;
    let w = b.weight;
    let head = format!(
        "the smooth conductor and the wave optics' haze ({file}), blended: weight w = {w:.6}, the haze's share (the cosine-weighted \
         hemispherical mean of 1 - s, s(theta) = exp(-b cos^2 theta), b = {:.6}, fitted at 550 nm); the table's reflectance is written at 1/w",
        b.b
    );
    let mitsuba_material = match material {
        Material::None => String::new(),
        m => format!("\n        <string name=\"material\" value=\"{}\"/>", m.as_str()),
    };
    let alpha = MITSUBA_MIRROR_ALPHA;
    let (pbrt_eta, pbrt_note) = match material {
        Material::Al | Material::Ag | Material::Au | Material::Cu => {
            let m = material.as_str();
            (format!("\n    \"spectrum eta\" [ \"metal-{m}-eta\" ]\n    \"spectrum k\" [ \"metal-{m}-k\" ]"), String::new())
        }
        m => (
            String::new(),
            format!(
                "\n# pbrt-v4 has no named spectra for the conductor {} of the table: its default conductor is written; give --material Al, Ag, Au or Cu for one both parts share",
                m.as_str()
            ),
        ),
    };
    format!(
        "<!-- ndfit wave of {scan}: {head}. Mitsuba 3's spectral variants (the table is spectral); the mirror is a GGX lobe of alpha {alpha}: Mitsuba's path tracer over-counts a blend of the delta conductor and a measured BSDF. -->
<bsdf type=\"blendbsdf\">
    <float name=\"weight\" value=\"{w}\"/>
    <bsdf type=\"roughconductor\">
        <string name=\"distribution\" value=\"ggx\"/>
        <float name=\"alpha\" value=\"{alpha}\"/>{mitsuba_material}
    </bsdf>
    <bsdf type=\"measured\">
        <string name=\"filename\" value=\"{file}\"/>
    </bsdf>
</bsdf>
# ndfit wave of {scan}: {head}. pbrt-v4: amount = the probability of the second material, the haze.{pbrt_note}
MakeNamedMaterial \"ndfit_mirror\"
    \"string type\" [ \"conductor\" ]
    \"float roughness\" [ 0 ]{pbrt_eta}
MakeNamedMaterial \"ndfit_haze\"
    \"string type\" [ \"measured\" ]
    \"string filename\" [ \"{file}\" ]
Material \"mix\"
    \"string materials\" [ \"ndfit_mirror\" \"ndfit_haze\" ]
    \"float amount\" [ {w} ]
"
    )
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
