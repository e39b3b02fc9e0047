//! The per-bin tables of a trace as CSV (`ndfit trace --tables OUT.csv`), for checks outside ndfit:
//! one row per incidence and outgoing bin, with the bin's layout (indices, edges, centre, projected
//! solid angle) and the binned energies of [`Tables`](super::Tables). Columns in [`COLUMNS`] and
//! docs/TRACE.md.

use std::path::Path;

use super::tally::lum;
use super::TraceReport;
use crate::error::{Error, ErrorKind, Result};

/// The header row. Angles in degrees; energies per unit incident energy (per landed path), so the BRDF
/// averaged over a bin is the energy over `proj_solid_angle`; each energy per channel (`_r`, `_g`, `_b`:
/// 612, 549, 465 nm) and as luminance (no suffix).
pub const COLUMNS: [&str; 29] = [
    "incidence",
    "theta_i_deg",
    "phi_i_deg",
    "bin",
    "i_theta",
    "i_phi",
    "theta_lo_deg",
    "theta_hi_deg",
    "phi_lo_deg",
    "phi_hi_deg",
    "theta_o_deg",
    "phi_o_deg",
    "ox",
    "oy",
    "oz",
    "proj_solid_angle",
    "single_r",
    "single_g",
    "single_b",
    "single",
    "multi_r",
    "multi_g",
    "multi_b",
    "multi",
    "model_r",
    "model_g",
    "model_b",
    "model",
    "var_total",
];

/// Write `report`'s tables to `path` atomically (complete or absent under its name).
pub fn write_tables_csv(path: &Path, report: &TraceReport) -> Result<()> {
    let csv_err = |e: csv::Error| Error::new(ErrorKind::Io, e.to_string()).with_path(path);
    crate::io::write_atomic(path, |w| {
        let mut c = csv::Writer::from_writer(w);
        c.write_record(COLUMNS).map_err(csv_err)?;
        let t = report.table;
        for (inc, (rec, tab)) in report.incidences.iter().zip(&report.tables).enumerate() {
            for k in 0..t.len() {
                let (it, ip) = (k / t.n_phi, k % t.n_phi);
                let o = t.centre(k);
                let u = (it as f64 + 0.5) / t.n_theta as f64;
                let phi_c = 0.5 * (t.phi_edge(ip) + t.phi_edge(ip + 1));
                let deg = |r: f64| r.to_degrees().to_string();
                let mut row = vec![
                    inc.to_string(),
                    rec.theta_deg.to_string(),
                    rec.phi_deg.to_string(),
                    k.to_string(),
                    it.to_string(),
                    ip.to_string(),
                    deg(t.theta_edge(it)),
                    deg(t.theta_edge(it + 1)),
                    deg(t.phi_edge(ip)),
                    deg(t.phi_edge(ip + 1)),
                    deg(u * u * std::f64::consts::FRAC_PI_2),
                    deg(phi_c),
                    format!("{:e}", o[0]),
                    format!("{:e}", o[1]),
                    format!("{:e}", o[2]),
                    format!("{:e}", t.proj_solid_angle(k)),
                ];
                for e in [tab.single[k], tab.multi[k], tab.model[k]] {
                    row.extend(e.iter().map(|v| format!("{v:e}")));
                    row.push(format!("{:e}", lum(e)));
                }
                row.push(format!("{:e}", tab.var_total[k]));
                c.write_record(&row).map_err(csv_err)?;
            }
        }
        c.flush().map_err(Error::io)
    })
}
