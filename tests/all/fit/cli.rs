//! `ndfit fit` on the command line: a real scan gives schema-valid JSON and a plot; bad input gives one
//! line on stderr, a non-zero exit and no output file.

use std::process::Command;

use crate::common::{ndfit_bin, shared_scans};

#[test]
fn fit_real_scan_writes_valid_json_and_plot_needs_shared() {
    let Some(dir) = shared_scans("fit_real_scan_writes_valid_json_and_plot_needs_shared") else { return };
    let scan = dir.join("hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p");
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("fit.json");
    let png = tmp.path().join("fit.png");
    let st = Command::new(ndfit_bin())
        .arg("fit")
        .arg(&scan)
        .args(["--model", "auto", "-o"])
        .arg(&out)
        .arg("--plot")
        .arg(&png)
        .output()
        .expect("runs");
    assert!(st.status.success(), "stderr: {}", String::from_utf8_lossy(&st.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).expect("json written")).expect("json");
    super::schema::assert_valid(&v);
    // The peer reading of this file (peer_readings.json, SurfaceTopography via x3pio): 303 x 85 grid.
    assert_eq!((v["input"]["nx"].as_u64(), v["input"]["ny"].as_u64()), (Some(303), Some(85)));
    assert!(std::fs::metadata(&png).map(|m| m.len() > 1000).unwrap_or(false), "plot written");
    // Without -o the same JSON goes to stdout.
    let st = Command::new(ndfit_bin()).arg("fit").arg(&scan).args(["--model", "ggx"]).output().expect("runs");
    assert!(st.status.success());
    let v: serde_json::Value = serde_json::from_slice(&st.stdout).expect("stdout is JSON");
    super::schema::assert_valid(&v);
    assert_eq!(v["model"], "ggx");
}

#[test]
fn bad_input_is_one_line_and_no_output() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let bad = tmp.path().join("garbage.x3p");
    std::fs::write(&bad, b"not a zip at all").expect("write");
    let out = tmp.path().join("fit.json");
    let st = Command::new(ndfit_bin()).arg("fit").arg(&bad).arg("-o").arg(&out).output().expect("runs");
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains("garbage.x3p"), "names the file: {err}");
    assert!(!out.exists(), "no output file on failure");
    let st = Command::new(ndfit_bin()).arg("fit").arg(&bad).args(["--model", "nonsense"]).output().expect("runs");
    assert!(!st.status.success());
}

/// `--subsample 0` is refused with one line naming the file, with or without a preset (whose stride
/// multiplies it, and must not turn the 0 into a silent 1).
#[test]
fn subsample_zero_is_refused_even_with_a_preset() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let scan = tmp.path().join("small.txt");
    let text: String = (0..40)
        .map(|i| (0..40).map(|j| format!("{:e}", 1e-7 * ((i * 7 + j * 3) % 11) as f64)).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(&scan, text).expect("write");
    for preset in [None, Some("fast")] {
        let mut cmd = Command::new(ndfit_bin());
        cmd.arg("fit").arg(&scan).args(["--dx", "1e-6", "--z-scale", "1", "--subsample", "0"]);
        if let Some(p) = preset {
            cmd.args(["--preset", p]);
        }
        let st = cmd.output().expect("runs");
        assert!(!st.status.success(), "preset {preset:?}: --subsample 0 must fail");
        let err = String::from_utf8_lossy(&st.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains("small.txt") && err.contains("at least 1"), "preset {preset:?}: {err}");
    }
}
