//! Integration tests: the CLI as CONTRACT.md describes it, across commands.

use std::process::Command;

use crate::common::ndfit_bin;

/// `--version` names the package version; `--help` lists the contract's commands (`export` is added on
/// another branch).
#[test]
fn version_and_the_contract_commands_are_listed() {
    let o = Command::new(ndfit_bin()).arg("--version").output().expect("runs");
    assert!(o.status.success());
    let v = String::from_utf8_lossy(&o.stdout);
    assert!(v.contains(env!("CARGO_PKG_VERSION")), "version line {v:?}");
    let o = Command::new(ndfit_bin()).arg("--help").output().expect("runs");
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    for cmd in ["fit", "info", "ndf", "eval", "batch"] {
        assert!(help.lines().any(|l| l.trim_start().starts_with(&format!("{cmd} "))), "`{cmd}` missing from --help:\n{help}");
    }
}

/// CONTRACT.md "Any failure": for a scan that does not exist, every scan-reading command exits non-zero
/// with exactly one line on stderr naming the file, and writes no output file.
#[test]
fn a_missing_scan_gives_one_line_naming_it_and_no_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scan = dir.path().join("no-such-scan.x3p");
    let out_of = |ext: &str| dir.path().join(format!("out.{ext}"));
    let cases: [(&str, Option<&str>); 3] = [("fit", Some("json")), ("ndf", Some("csv")), ("info", None)];
    for (cmd, ext) in cases {
        let mut c = Command::new(ndfit_bin());
        c.arg(cmd).arg(&scan);
        if let Some(ext) = ext {
            c.arg("-o").arg(out_of(ext));
        }
        let o = c.output().expect("runs");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{cmd}: exit 0 on a missing scan");
        assert_eq!(err.trim_end().lines().count(), 1, "{cmd}: stderr {err:?}");
        assert!(err.contains("no-such-scan.x3p"), "{cmd}: the line must name the file: {err:?}");
        assert!(!err.contains("panicked"), "{cmd}: {err:?}");
        if let Some(ext) = ext {
            assert!(!out_of(ext).exists(), "{cmd}: wrote an output file");
        }
    }
}
