//! `ndfit fit` and `ndfit batch -- ...` share one set of per-scan flags and one pipeline: the same flags
//! give the same fit, and the batch honours the flags it gained (`--max-theta`, `--preset`).

use std::path::Path;
use std::process::Command;

fn run(dir: &Path, args: &[&str]) -> std::process::Output {
    let o = Command::new(crate::common::ndfit_bin()).current_dir(dir).args(args).output().expect("run ndfit");
    assert!(o.status.success(), "ndfit {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    o
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("read JSON")).expect("JSON")
}

/// The fit of one scan through `batch -- FLAGS` equals `fit FLAGS` bit for bit (parameters, standard
/// errors, quality with the fitted region, the scan read), for flags that change the result (a narrower `--max-theta`, the `fast`
/// preset's stride and tolerance); without them the result differs, so the flags did reach the batch.
#[test]
fn batch_and_fit_share_flags_and_results() {
    let d = tempfile::tempdir().expect("temp dir");
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).expect("mkdir");
    run(
        d.path(),
        &[
            "synth",
            "scans/s.x3p",
            "--nx",
            "192",
            "--ny",
            "192",
            "--alpha-x",
            "0.3",
            "--alpha-y",
            "0.15",
            "--theta-z",
            "0.4",
            "--truth",
            "s.truth.json",
        ],
    );
    let flags = ["--max-theta", "50", "--preset", "fast"];
    let mut fit_args = vec!["fit", "scans/s.x3p", "--model", "ggx-aniso", "-q", "-o", "fit.json"];
    fit_args.extend(flags);
    run(d.path(), &fit_args);
    let mut batch_args = vec!["batch", "scans", "-o", "out", "--model", "ggx-aniso", "--"];
    batch_args.extend(flags);
    run(d.path(), &batch_args);
    run(d.path(), &["batch", "scans", "-o", "plain", "--model", "ggx-aniso"]);
    let (f, b, plain) = (
        json(&d.path().join("fit.json")),
        json(&d.path().join("out/fits/s.x3p.fit.json")),
        json(&d.path().join("plain/fits/s.x3p.fit.json")),
    );
    for key in ["params", "std_errors", "quality"] {
        assert_eq!(f.get(key), b.get(key), "{key}");
    }
    for key in ["nx", "ny", "dx", "dy", "invalid", "file_grid"] {
        assert_eq!(f["input"].get(key), b["input"].get(key), "input.{key}");
    }
    assert!(f["params"].is_object() && f["quality"]["max_theta_deg"] == 50.0, "{}", f["quality"]);
    assert_eq!(b["input"]["nx"], 48, "the fast preset's stride of 4 on 192 columns");
    assert_ne!(b["params"], plain["params"]);
    assert_eq!(plain["input"]["nx"], 192);
}
