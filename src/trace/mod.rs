//! Geometric optics on the scan's own microgeometry: does microfacet theory hold for this scan?
//!
//! Every BRDF ndfit exports is the microfacet model: `D` of the scan, Smith's masking from `D` alone
//! (heights uncorrelated with slopes), one bounce. The scan holds more than its NDF; this module traces
//! it and measures the model against the result.
//!
//! - Surface ([`surface`](self)): two planar triangles per grid cell, split along the diagonal
//!   `u = v`, each with its exact normal; heights as given (the caller removes the form, as `ndfit fit`
//!   does). Borders: [`Border::Periodic`](crate::trace::Border::Periodic) (default: a closed surface, exact energy balance; a non-periodic
//!   scan gets a seam where its edges meet, on which no ray lands) or [`Border::Open`](crate::trace::Border::Open). Holes are filled
//!   by linear interpolation for the paths; rays land only on cells of four measured corners, and later
//!   hits on filled cells are counted (`filled_hits_share`).
//! - Acceleration: a maximum-height pyramid, descended in the order the ray meets the blocks.
//! - Paths: from a uniform point of the plane above the surface along `-wi`; at each hit specular
//!   reflection about the triangle's normal, weighted by the conductor's Fresnel factor per channel
//!   (`Material`, as `export --to rgl`), up to `bounces`; the energy leaving after bounce `k` is binned
//!   by direction ([`DirTable`](crate::trace::DirTable)).
//! - Masking: `G1(w)` = projected area visible from `w` / projected area facing `w` (Heitz 2014 eq. 2,
//!   14-17), from uniform surface points weighted by `<w.m> / m.n` and a shadow ray each. On any
//!   heightfield this surface average is `cos(theta) / sigma(w)` (the masking constraint, eq. 14-17):
//!   Smith's `G1` of the surface's NDF (eq. 43). What Smith assumes beyond it, that masking does not
//!   depend on the facet's normal, shows in `g1_toward` / `g1_away` (facets tilted toward or away from
//!   `w`) and, with the shadowing-masking correlation, in the single-bounce BRDF.
//! - Comparison: the microfacet model's single scattering `F D G2 / (4 cos_i cos_o)` with the surface's
//!   `D` and Smith's height-correlated `G2` (Heitz eq. 99), against the first bounce, bin by bin; the
//!   energy in later bounces is what the model misses.
//!
//! Determinism: each block of rays has its own generator, seeded from the seed, the incidence and the
//! block's index; blocks are summed in order. The same seed gives the same report on any thread count.
//! Memory: the heights (8 bytes per point), a bit per cell, the pyramid (about 1.4 bytes per point) and
//! per block of rays a few tables of the outgoing bins.

mod compare;
mod hierarchy;
#[cfg(feature = "plot")]
mod plot;
mod surface;
mod table_csv;
mod tally;
mod to_rgl;
mod tracer;

use rayon::prelude::*;

pub use compare::SingleComparison;
#[cfg(feature = "plot")]
pub use plot::{plane_of_incidence, write_plot, PLOT_HEIGHT, PLOT_WIDTH};
pub use surface::Border;
pub use table_csv::{write_tables_csv, COLUMNS as TABLE_COLUMNS};
pub use tally::{DirTable, LUMA};
pub use to_rgl::{trace_rgl, NodeRecord, TracedRglOptions, TracedTable, CARRY_FLOOR};

use crate::error::{Error, Result};
use crate::export::rgl::Material;
use crate::scan::Scan;

/// Rays per block (one generator each).
const BLOCK: usize = 1 << 14;
/// Blocks traced between two merges (bounds the tallies held at once).
const CHUNK: usize = 64;

/// What to trace.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceOptions {
    /// Incident elevations (degrees from the normal, each in `[0, 89.9]`).
    pub incidences_deg: Vec<f64>,
    /// Incident azimuth (degrees; 0 = the scan's `+x`, 90 = `+y`).
    pub azimuth_deg: f64,
    /// The conductor (`none`: Fresnel 1, the white furnace).
    pub material: Material,
    /// Largest number of bounces a path follows (energy still on the surface after it is `lost`).
    pub bounces: usize,
    /// Seed of the random generators.
    pub seed: u64,
    /// Paths per incidence (masking rays: a quarter as many).
    pub rays: usize,
    /// The grid's edges.
    pub border: Border,
    /// The outgoing-direction bins.
    pub table: DirTable,
    /// Largest single-bounce error beyond noise, and largest multiple-scattering share, for the verdict
    /// `holds`.
    pub tolerance: f64,
    /// Draw each ray's incident direction over the incidence's bin of `table` (uniform in projected
    /// solid angle) instead of the exact direction: the bin-to-bin BRDF, exactly reciprocal.
    pub spread_over_bin: bool,
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions {
            incidences_deg: vec![0.0, 40.0, 70.0],
            azimuth_deg: 0.0,
            material: Material::None,
            bounces: 16,
            seed: 1,
            rays: 1 << 20,
            border: Border::Periodic,
            table: DirTable { n_theta: 32, n_phi: 64 },
            tolerance: 0.05,
            spread_over_bin: false,
        }
    }
}

/// Largest incidence accepted (degrees): at 90 no ray reaches the surface.
pub const MAX_INCIDENCE_DEG: f64 = 89.9;

impl TraceOptions {
    /// Check every value's range.
    pub fn validate(&self) -> Result<()> {
        if self.incidences_deg.is_empty() || self.incidences_deg.len() > 256 {
            return Err(Error::invalid(format!("give 1 to 256 incidences, got {}", self.incidences_deg.len())));
        }
        for &t in &self.incidences_deg {
            // A ray at or beyond grazing never reaches the surface; NaN is no angle.
            if !(0.0..=MAX_INCIDENCE_DEG).contains(&t) {
                return Err(Error::invalid(format!("incidence {t} deg is outside [0, {MAX_INCIDENCE_DEG}]")));
            }
        }
        if !self.azimuth_deg.is_finite() {
            return Err(Error::invalid(format!("azimuth must be finite, got {}", self.azimuth_deg)));
        }
        if !(1..=1000).contains(&self.bounces) {
            return Err(Error::invalid(format!("bounces must be in [1, 1000], got {}", self.bounces)));
        }
        if !(1..=1usize << 40).contains(&self.rays) {
            return Err(Error::invalid(format!("rays must be in [1, 2^40], got {}", self.rays)));
        }
        if !(2..=512).contains(&self.table.n_theta) || !(2..=1024).contains(&self.table.n_phi) {
            return Err(Error::invalid(format!(
                "table must have 2..512 elevation and 2..1024 azimuth bins, got {} x {}",
                self.table.n_theta, self.table.n_phi
            )));
        }
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(Error::invalid(format!("tolerance must be in (0, 1), got {}", self.tolerance)));
        }
        Ok(())
    }
}

/// The traced surface.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceInfo {
    /// Grid points along x and y.
    pub nx: usize,
    /// Grid points along y.
    pub ny: usize,
    /// Spacing (m).
    pub dx: f64,
    /// Spacing (m).
    pub dy: f64,
    /// `periodic` or `open`.
    pub border: Border,
    /// How the heights become a surface.
    pub representation: String,
    /// Share of the cells rays land on (four measured corners, no seam).
    pub landing_share: f64,
    /// Heights filled for tracing (holes).
    pub filled_points: usize,
}

/// One incidence's result (`OUT.json`'s `incidences[k]`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IncidenceRecord {
    /// Incident elevation (degrees).
    pub theta_deg: f64,
    /// Incident azimuth (degrees, 0 = `+x`).
    pub phi_deg: f64,
    /// Paths traced.
    pub rays: u64,
    /// Of them, landed first on a measured cell (the normalization of every energy below).
    pub landed: u64,
    /// Reflected energy per unit incident (luminance of the three channels), all bounces.
    pub albedo: f64,
    /// The same per channel (612, 549, 465 nm).
    pub albedo_rgb: [f64; 3],
    /// Energy leaving after bounce 1, 2, ... (luminance), first bounce first.
    pub albedo_by_bounce: Vec<f64>,
    /// Share of the reflected energy that took two or more bounces: what the one-bounce model misses.
    pub multiple_share: f64,
    /// Energy still on the surface after the last bounce, or leaked through rounding (luminance).
    pub lost: f64,
    /// Energy that left an open grid sideways (included in `albedo`).
    pub escaped_side: f64,
    /// Share of the hits after the first that fell on filled or seam cells.
    pub filled_hits_share: f64,
    /// Masking `G1(wi)` traced: visible over facing projected area.
    pub g1: f64,
    /// Its standard error.
    pub g1_stderr: f64,
    /// Traced `G1` of the facets tilted toward `wi` (their horizontal normal along its azimuth); `null`
    /// when none faces it.
    pub g1_toward: Option<f64>,
    /// Traced `G1` of the facets tilted away from `wi`.
    pub g1_away: Option<f64>,
    /// Smith's `G1(wi) = cos(theta) / sigma(wi)` of the traced surface's NDF (Heitz eq. 22, 43).
    pub g1_smith: f64,
    /// The first bounce against the microfacet model's single scattering.
    pub single: SingleComparison,
}

/// The outgoing energy of one incidence, per bin of [`TraceReport::table`] and channel, per unit incident
/// energy: the BRDF averaged over bin `k` is `e[k] / proj_solid_angle(k)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Tables {
    /// After one bounce.
    pub single: Vec<[f64; 3]>,
    /// After two or more.
    pub multi: Vec<[f64; 3]>,
    /// The microfacet model's single scattering.
    pub model: Vec<[f64; 3]>,
    /// Variance of the luminance of `single + multi` per bin (Monte Carlo).
    pub var_total: Vec<f64>,
}

/// The trace's verdict on the microfacet model.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TraceVerdict {
    /// `holds` or `does_not_hold`.
    pub verdict: String,
    /// The tolerance applied.
    pub tolerance: f64,
    /// Largest single-bounce error beyond twice its noise, and its incidence (degrees).
    pub worst_single: (f64, f64),
    /// Largest multiple-scattering share, and its incidence.
    pub worst_multiple: (f64, f64),
    /// Largest `|g1 / g1_smith - 1|`, and its incidence.
    pub worst_g1: (f64, f64),
    /// The line printed on standard error.
    pub line: String,
}

/// Everything `ndfit trace` writes (`schema: "ndfit.trace/1"`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TraceReport {
    /// `ndfit.trace/1`.
    pub schema: String,
    /// The traced surface.
    pub surface: SurfaceInfo,
    /// `none`, `Al`, ...
    pub material: String,
    /// Largest number of bounces.
    pub bounces: usize,
    /// Seed.
    pub seed: u64,
    /// The outgoing bins.
    pub table: DirTable,
    /// One record per incidence, in the order given.
    pub incidences: Vec<IncidenceRecord>,
    /// The verdict.
    pub verdict: TraceVerdict,
    /// The binned energies per incidence (not serialized).
    #[serde(skip)]
    pub tables: Vec<Tables>,
}

/// The unit direction of elevation `theta` and azimuth `phi` (degrees).
pub fn direction(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    [st * cp, st * sp, ct]
}

/// Trace `scan` (form already removed) at every incidence of `opts`. `progress(done, total)` is called
/// with the paths traced so far.
pub fn trace(scan: &Scan, opts: &TraceOptions, progress: Option<&(dyn Fn(u64, u64) + Sync)>) -> Result<TraceReport> {
    opts.validate()?;
    let s = surface::Surface::new(scan, opts.border)?;
    let pyr = hierarchy::Pyramid::new(&s)?;
    let sigma = compare::SigmaTable::new(&s, opts.seed);
    let dirs: Vec<[f64; 3]> = opts.incidences_deg.iter().map(|&t| direction(t, opts.azimuth_deg)).collect();
    let sigma_i = compare::sigma_exact(&s, &dirs);
    let blocks = opts.rays.div_ceil(BLOCK);
    let total = (opts.rays * dirs.len()) as u64;
    let mut done = 0u64;
    let mut records = Vec::new();
    let mut tables = Vec::new();
    for (inc, (&wi, &sig)) in dirs.iter().zip(&sigma_i).enumerate() {
        let lambda_i = (sig / wi[2] - 1.0).max(0.0);
        let spread = opts.spread_over_bin.then(|| {
            let k = opts.table.bin(wi).unwrap_or(0);
            let (it, ip) = (k / opts.table.n_phi, k % opts.table.n_phi);
            [opts.table.theta_edge(it), opts.table.theta_edge(it + 1), opts.table.phi_edge(ip), opts.table.phi_edge(ip + 1)]
        });
        let setup = tracer::Setup {
            s: &s,
            pyr: &pyr,
            table: opts.table,
            material: opts.material,
            bounces: opts.bounces,
            wi,
            lambda_i,
            sigma: &sigma,
            spread,
        };
        let mut t = tally::Tally::new(opts.table.len(), opts.bounces);
        for c0 in (0..blocks).step_by(CHUNK) {
            let parts: Vec<tally::Tally> = (c0..(c0 + CHUNK).min(blocks))
                .into_par_iter()
                .map(|b| {
                    let rays = BLOCK.min(opts.rays - b * BLOCK);
                    setup.block(rays, rays.div_ceil(4), tracer::block_seed(opts.seed, inc, b))
                })
                .collect();
            for p in &parts {
                t.add(p);
                done += p.landed + p.not_landed;
            }
            if let Some(f) = progress {
                f(done, total);
            }
        }
        let (rec, tab) = record(&t, opts, opts.incidences_deg[inc], sig / wi[2], &s);
        records.push(rec);
        tables.push(tab);
    }
    let verdict = verdict(&records, opts.tolerance);
    Ok(TraceReport {
        schema: "ndfit.trace/1".into(),
        surface: SurfaceInfo {
            nx: s.nx,
            ny: s.ny,
            dx: s.dx,
            dy: s.dy,
            border: s.border,
            representation: "two triangles per grid cell, split along the diagonal from (i, j) to (i+1, j+1)".into(),
            landing_share: s.valid_cells as f64 / (s.ncx * s.ncy) as f64,
            filled_points: s.filled_points,
        },
        material: opts.material.as_str().into(),
        bounces: opts.bounces,
        seed: opts.seed,
        table: opts.table,
        incidences: records,
        verdict,
        tables,
    })
}

/// One incidence's record from its tally (`sigma_over_cos = 1 + Lambda(wi)`).
fn record(t: &tally::Tally, opts: &TraceOptions, theta: f64, sigma_over_cos: f64, s: &surface::Surface) -> (IncidenceRecord, Tables) {
    use tally::lum;
    let n = t.landed.max(1) as f64;
    let by: Vec<f64> = t.by_bounce.iter().map(|b| lum(*b) / n).collect();
    let rgb = |tab: &Vec<tally::Bin>| -> [f64; 3] {
        let mut a = [0.0; 3];
        for b in tab {
            for c in 0..3 {
                a[c] += b[c] / n;
            }
        }
        a
    };
    let (s1, sm) = (rgb(&t.single), rgb(&t.multi));
    let albedo_rgb = [s1[0] + sm[0], s1[1] + sm[1], s1[2] + sm[2]];
    let albedo = lum(albedo_rgb);
    let ratio = |g: &[f64; 4]| if g[0] > 0.0 { Some(g[1] / g[0]) } else { None };
    let g = &t.g1[0];
    let g1 = ratio(g).unwrap_or(1.0);
    // Ratio estimator's variance: sum w^2 (V - G1)^2 / (sum w)^2, with V in {0, 1}.
    let g1_var = if g[0] > 0.0 { (g[3] * (1.0 - g1).powi(2) + (g[2] - g[3]) * g1 * g1) / (g[0] * g[0]) } else { 0.0 };
    let per = |tab: &Vec<tally::Bin>| tab.iter().map(|b| [b[0] / n, b[1] / n, b[2] / n]).collect::<Vec<_>>();
    let np = t.pred_samples.max(1) as f64;
    let var_total = t
        .single
        .iter()
        .zip(&t.multi)
        .map(|(a, b)| {
            let e = lum([a[0] + b[0], a[1] + b[1], a[2] + b[2]]) / n;
            (((a[3] + b[3]) / n - e * e) / n).max(0.0)
        })
        .collect();
    let tables = Tables {
        single: per(&t.single),
        multi: per(&t.multi),
        model: t.pred.iter().map(|b| [b[0] / np, b[1] / np, b[2] / np]).collect(),
        var_total,
    };
    let rec = IncidenceRecord {
        theta_deg: theta,
        phi_deg: opts.azimuth_deg,
        rays: t.landed + t.not_landed,
        landed: t.landed,
        albedo,
        albedo_rgb,
        albedo_by_bounce: by.clone(),
        multiple_share: if albedo > 0.0 { (albedo - by.first().copied().unwrap_or(0.0)) / albedo } else { 0.0 },
        lost: lum(t.lost) / n,
        escaped_side: lum(t.side) / n,
        filled_hits_share: if t.later_hits > 0 { t.filled_hits as f64 / t.later_hits as f64 } else { 0.0 },
        g1,
        g1_stderr: g1_var.sqrt(),
        g1_toward: ratio(&t.g1[2]),
        g1_away: ratio(&t.g1[1]),
        g1_smith: 1.0 / sigma_over_cos.max(1.0),
        single: compare::compare(&opts.table, t),
    };
    let _ = s;
    (rec, tables)
}

/// The verdict over all incidences: the model holds when, at every incidence, its single-bounce error
/// beyond twice the noise and the multiple-scattering share are both within the tolerance.
fn verdict(recs: &[IncidenceRecord], tol: f64) -> TraceVerdict {
    let worst = |f: &dyn Fn(&IncidenceRecord) -> f64| {
        recs.iter().map(|r| (f(r), r.theta_deg)).filter(|p| p.0.is_finite()).fold((0.0, f64::NAN), |a, b| if b.0 > a.0 { b } else { a })
    };
    let single = worst(&|r| (r.single.error - 2.0 * r.single.noise).max(0.0));
    let multi = worst(&|r| r.multiple_share);
    let g1 = worst(&|r| (r.g1 / r.g1_smith - 1.0).abs());
    let holds = single.0 <= tol && multi.0 <= tol;
    let at = |p: (f64, f64)| if p.1.is_finite() { format!(" at {} deg", p.1) } else { String::new() };
    let noise = recs.iter().map(|r| r.single.noise).fold(0.0, f64::max);
    let body = format!(
        "single-bounce error beyond noise {:.1}%{} (noise up to {:.1}%), multiple scattering {:.1}% of the reflected energy{}, G1 within {:.1}% of Smith's",
        100.0 * single.0,
        at(single),
        100.0 * noise,
        100.0 * multi.0,
        at(multi),
        100.0 * g1.0
    );
    let line = if holds {
        format!("microfacet model holds for this scan (tolerance {:.0}%): {body}", 100.0 * tol)
    } else {
        let by = if single.0 > tol && multi.0 > tol {
            "its single bounce departs from the trace and it misses the multiple scattering"
        } else if single.0 > tol {
            "its single bounce departs from the trace"
        } else {
            "it misses the multiple scattering"
        };
        format!("microfacet model does not hold for this scan (tolerance {:.0}%): {by}; {body}", 100.0 * tol)
    };
    TraceVerdict {
        verdict: if holds { "holds" } else { "does_not_hold" }.into(),
        tolerance: tol,
        worst_single: single,
        worst_multiple: multi,
        worst_g1: g1,
        line,
    }
}
