//! Helpers shared by the integration tests.

#![allow(dead_code)]

use std::path::PathBuf;

/// Environment variable under which a test that needs `../shared` fails instead of skipping (`.ci/run` sets it).
pub const REQUIRE_SHARED: &str = "NDFIT_REQUIRE_SHARED";

/// `../shared/data/scans` beside the repository, or `None` when it is absent.
///
/// Every test that calls this is named `*_needs_shared`, so that a skip is visible where cargo shows it (the
/// test list; `cargo test needs_shared` runs just them) and not only on the captured stderr. With
/// `NDFIT_REQUIRE_SHARED` set to anything but empty or `0` an absent folder is a failure naming it.
pub fn shared_scans(test: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scans");
    if dir.join("peer_readings.json").is_file() {
        return Some(dir);
    }
    let why = format!("{test}: {} is absent (no peer_readings.json there)", dir.display());
    if std::env::var(REQUIRE_SHARED).is_ok_and(|v| !v.is_empty() && v != "0") {
        panic!("{why}, and {REQUIRE_SHARED} is set: the real-scan checks must run");
    }
    eprintln!("SKIP {why}; set {REQUIRE_SHARED}=1 to make this a failure");
    None
}

/// Path of the built `ndfit` binary, for CLI tests.
pub fn ndfit_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ndfit"))
}

/// `|det d(m_x, m_y) / dp|` at Lambert point `p` of `frame`: the projected-solid-angle density of the
/// bins (`(m.n) dw = dm_x dm_y`, the orthographic projection), written here from the documented map
/// (data_formats/ndf_csv.md, step 3) by the chain rule, independently of `SlopeFrame::densities`:
/// `m'_xy = p sqrt(1 - |p|^2/4)`, `m'_z = 1 - |p|^2/2`, `s = c + Unwhiten m'_xy / m'_z`,
/// `m_xy = -s / sqrt(1 + |s|^2)`. Zero on the rim, where the whole rest of the hemisphere is squeezed.
pub fn proj_density(frame: &ndfit::ndf::SlopeFrame, p: [f64; 2]) -> f64 {
    type M2 = nalgebra::Matrix2<f64>;
    type V2 = nalgebra::Vector2<f64>;
    let p = V2::new(p[0], p[1]);
    let r2 = p.norm_squared();
    let (g, mz) = ((1.0 - 0.25 * r2).max(0.0).sqrt(), 1.0 - 0.5 * r2);
    if g <= 0.0 || mz <= 0.0 {
        return 0.0;
    }
    let m1 = p * g;
    let dm1 = M2::identity() * g - p * p.transpose() / (4.0 * g);
    let ds1 = dm1 / mz + m1 * p.transpose() / (mz * mz);
    let u = M2::new(frame.unwhiten[0][0], frame.unwhiten[0][1], frame.unwhiten[1][0], frame.unwhiten[1][1]);
    let s = V2::new(frame.center[0], frame.center[1]) + u * (m1 / mz);
    let q = (1.0 + s.norm_squared()).sqrt();
    let dm = -(M2::identity() / q - s * s.transpose() / (q * q * q));
    (dm * u * ds1).determinant().abs()
}

/// Heitz eq. 9 checked against independent bin integrals: `sum_k d_k W_k` where each `W_k` is
/// [`proj_density`] integrated over the bin's cell with the grid's `QuadOrder::Fine(k)` nodes (k x k
/// sub-cells, polar pieces on the rim; on cells reaching beyond |p| = 1.3, the rim zone, at least 8 x 8
/// and finer on coarse grids, so that the sub-cells stay below 1/192 of the disk's width) instead
/// of the NDF's own rule and density. 1 when the NDF's projected solid angles are right; a wrong `W` on
/// a share `f` of the mass moves it by about `f`.
pub fn reference_total(ndf: &ndfit::ndf::EmpiricalNdf, k: usize) -> f64 {
    assert!(ndf.grid.n > 0 && ndf.bin_cells.len() == ndf.bins.len(), "an NDF with its grid");
    let rim = ndf.frame.rim_shape();
    let mut total = 0.0;
    for (b, &c) in ndf.bins.iter().zip(&ndf.bin_cells) {
        if b.count == 0 {
            continue;
        }
        let [x0, x1, y0, y1] = ndf.grid.bounds(c as usize);
        let far = x0.abs().max(x1.abs()).hypot(y0.abs().max(y1.abs()));
        let order = ndfit::ndf::QuadOrder::Fine(if far > 1.3 { k.max(8).max(192 / ndf.grid.n) } else { k });
        let mut w = 0.0;
        ndf.grid.quadrature(c as usize, order, &rim, |p, wt| w += proj_density(&ndf.frame, p) * wt);
        total += b.d * w;
    }
    total
}

/// Lower-case hex MD5 of `data` (RustCrypto's `md-5`, not ndfit's own wrapper): the checksums test X3P files carry.
pub fn md5_hex(data: &[u8]) -> String {
    use md5::Digest;
    md5::Md5::digest(data).iter().map(|b| format!("{b:02x}")).collect()
}

/// `ndfit synth` of a 64 x 64 Gaussian surface at `dir/g.x3p` with the extra flags `extra` (a small scan
/// for the commands' own tests); its path.
pub fn synth_small_gaussian(dir: &std::path::Path, extra: &[&str]) -> PathBuf {
    let scan = dir.join("g.x3p");
    let synth = std::process::Command::new(ndfit_bin())
        .args(["synth", scan.to_str().expect("utf-8 path"), "--surface", "gaussian", "--nx", "64", "--ny", "64"])
        .args(extra)
        .output()
        .expect("ndfit synth runs");
    assert!(synth.status.success(), "{}", String::from_utf8_lossy(&synth.stderr));
    scan
}
