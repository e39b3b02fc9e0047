//! `ndfit info` read band by band ([`surface_stats_of`]) against the whole-grid statistics
//! ([`surface_stats`] of the heights [`apply`] makes): the same counts, range, Sq and Sdq, bit for bit,
//! with holes and masked spikes, on odd grid sizes, with bands of 1 and 3 rows and the default; and the
//! command on a stored X3P (heights mapped) prints the whole-grid statistics of the same heights.

use ndfit::preprocess::{apply, prepare, FormRemoval, Preprocess};
use ndfit::scan::set_band_rows;
use ndfit::stats::{surface_stats, surface_stats_of};
use ndfit::Heightfield;

fn scan(nx: usize, ny: usize) -> Heightfield {
    let z = (0..nx * ny)
        .map(|k| {
            let (i, j) = ((k / nx) as f64, (k % nx) as f64);
            if k % 31 == 4 {
                f64::NAN
            } else if k % 997 == 13 {
                5e-5
            } else {
                2e-3 + 1e-4 * j - 3e-5 * i + 3e-7 * (0.7 * j + 0.2 * i).sin() + 1e-7 * (0.13 * j * i).cos()
            }
        })
        .collect();
    Heightfield::new(nx, ny, 1e-6, 2e-6, z).expect("grid")
}

#[test]
fn band_statistics_equal_the_whole_grid() {
    for (nx, ny) in [(131, 77), (3, 5), (64, 2)] {
        let hf = scan(nx, ny);
        let pre = Preprocess { form: FormRemoval::None, ..Preprocess::default() };
        let want = surface_stats(&apply(hf.clone(), &pre).expect("apply")).expect("stats");
        for rows in [Some(1), Some(3), None] {
            set_band_rows(rows);
            let p = prepare(hf.clone(), &pre).expect("prepare");
            let got = surface_stats_of(&p).expect("band stats");
            let bits = |s: &ndfit::stats::SurfaceStats| {
                (s.valid, s.invalid, s.sdq_points, [s.z_min, s.z_max, s.z_mean, s.sq, s.sdq].map(f64::to_bits))
            };
            assert_eq!(bits(&got), bits(&want), "{nx} x {ny}, rows {rows:?}: {got:?} vs {want:?}");
            if nx * ny > 1000 {
                assert!(!p.masked().is_empty(), "spikes masked");
                assert!(got.sq > 0.0 && got.sdq > 0.0 && got.invalid > 0);
            }
        }
        set_band_rows(None);
    }
}

#[test]
fn info_of_a_mapped_x3p_equals_the_whole_grid_statistics() {
    let hf = scan(1100, 700);
    let dir = tempfile::tempdir().expect("temp dir");
    let x3p = dir.path().join("s.x3p");
    ndfit::io::write_x3p(&x3p, &hf).expect("write x3p");
    assert!(ndfit::io::read_scan(&x3p, &Default::default()).expect("read").z.is_mapped());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ndfit")).arg("info").arg(&x3p).arg("--json").output().expect("run");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    // The file as stored: the heights as read, nothing masked, in memory; the statistics remove the plane.
    // What the default preprocessing masks is reported apart, as `spikes`.
    let pre = Preprocess { form: FormRemoval::None, despike: ndfit::preprocess::Despike::None, ..Preprocess::default() };
    let want = surface_stats(&apply(hf, &pre).expect("apply")).expect("stats");
    let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    assert_eq!(
        [num("z_min"), num("z_max"), num("z_mean"), num("sq"), num("sdq")].map(f64::to_bits),
        [want.z_min, want.z_max, want.z_mean, want.sq, want.sdq].map(f64::to_bits)
    );
    assert_eq!([num("valid"), num("invalid"), num("sdq_points")], [want.valid as f64, want.invalid as f64, want.sdq_points as f64]);
    assert!(num("spikes") > 0.0, "the planted spikes are reported apart: {v}");
}
