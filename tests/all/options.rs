//! The library refuses out-of-range options instead of cutting them ([`ndfit::Options::validate`]), for
//! a caller from Rust and through the CLI; and every flag of `ndfit fit` and `ndfit ndf` that changes
//! the result has a keyword of the Python module with the same default.

use std::collections::BTreeMap;
use std::process::Command;

use ndfit::fit::{fit_model, FitOptions, Tolerances};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::preprocess::Preprocess;
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::{ErrorKind, ModelChoice, Options, Pipeline};

fn scan() -> ndfit::Heightfield {
    let truth = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.2, theta_z: 0.3, ..Default::default() };
    ellipsoid_surface(&SynthSettings { nx: 96, ny: 96, ..Default::default() }, &truth).expect("valid").0
}

/// `err` is an invalid-input error whose message starts with `want` (the option's name and value).
fn refused<T: std::fmt::Debug>(r: ndfit::Result<T>, want: &str) {
    let e = r.expect_err(want);
    assert_eq!(e.kind(), ErrorKind::InvalidInput, "{want}: {e}");
    assert!(e.message().starts_with(want), "message {:?} should start with {want:?}", e.message());
}

/// More extra starts than there are skews used to be cut to 4 by the fit; now the fit refuses them,
/// and the pipeline refuses every out-of-range option before reading anything.
#[test]
fn out_of_range_options_are_refused_not_cut() {
    let hf = scan();
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    refused(fit_model(&ndf, ModelId::Ellipsoid, &FitOptions { extra_starts: 9, ..FitOptions::default() }), "extra_starts 9 ");
    refused(fit_model(&ndf, ModelId::Ggx, &FitOptions { max_theta: 2.0, ..FitOptions::default() }), "max_theta 2 rad");
    refused(fit_model(&ndf, ModelId::Ggx, &FitOptions { max_theta: 0.0, ..FitOptions::default() }), "max_theta 0 rad");
    let rel = Tolerances { rel: f64::NAN, ..Tolerances::default() };
    refused(fit_model(&ndf, ModelId::Ggx, &FitOptions { tolerances: rel, ..FitOptions::default() }), "tolerances.rel NaN");
    // The edges of the ranges are accepted: 4 starts, the whole hemisphere as the command line gives it.
    let edge = FitOptions { extra_starts: 4, max_theta: 90f64.to_radians(), ..FitOptions::default() };
    fit_model(&ndf, ModelId::Ellipsoid, &edge).expect("4 starts and 90 degrees are in range");

    let run = |o: Options| Pipeline::new(o).run(hf.clone(), "mem");
    let model = ModelChoice::Model(ModelId::Ggx);
    let fit = FitOptions { extra_starts: 5, ..FitOptions::default() };
    refused(run(Options { model, fit, ..Options::default() }), "extra_starts 5 ");
    let ndf_opts = |cells, target_count| NdfOptions { cells_across: cells, target_count, ..NdfOptions::default() };
    refused(run(Options { model, ndf: ndf_opts(Some(64), 64.0), ..Options::default() }), "cells_across 64 must be odd");
    refused(run(Options { model, ndf: ndf_opts(Some(1), 64.0), ..Options::default() }), "cells_across 1 must be between 3");
    refused(run(Options { model, ndf: ndf_opts(None, 0.5), ..Options::default() }), "target_count 0.5 ");
    refused(run(Options { model, ndf: ndf_opts(None, f64::INFINITY), ..Options::default() }), "target_count inf ");
    let pre = Preprocess { subsample: 0, ..Preprocess::default() };
    refused(run(Options { model, preprocess: pre, ..Options::default() }), "subsample 0 ");
    refused(Pipeline::new(Options { ndf: ndf_opts(Some(64), 64.0), ..Options::default() }).ndf(hf.clone()), "cells_across 64");
    run(Options { model, ndf: ndf_opts(Some(63), 1.0), ..Options::default() }).expect("63 cells are in range");
}

/// Through the CLI, what the flags' own checks leave is refused by the same validation before the scan
/// is read: a `--subsample 0` of a scan that does not exist names the option, not the missing file.
#[test]
fn the_cli_validates_before_reading() {
    let d = tempfile::tempdir().expect("temp dir");
    let missing = d.path().join("absent.x3p");
    let out = Command::new(crate::common::ndfit_bin()).arg("fit").arg(&missing).args(["--subsample", "0"]).output().expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains("absent.x3p") && err.contains("subsample 0 must be at least 1"), "{err}");
    let out = Command::new(crate::common::ndfit_bin()).arg("fit").arg(&missing).args(["--extra-starts", "5"]).output().expect("runs");
    assert!(String::from_utf8_lossy(&out.stderr).contains("--extra-starts 5 must be between 0 and 4"));
}

/// The flags of `ndfit <command> --help` that the command itself adds (the global ones of `ndfit
/// --help` aside), snake_case, with the default clap shows (`None`: none shown).
fn cli_flags(command: &[&str]) -> BTreeMap<String, Option<String>> {
    let help = |args: &[&str]| {
        let out = Command::new(crate::common::ndfit_bin()).args(args).arg("--help").env("COLUMNS", "100").output().expect("runs");
        assert!(out.status.success());
        String::from_utf8(out.stdout).expect("UTF-8 help")
    };
    let parse = |text: &str| {
        let mut flags: BTreeMap<String, String> = BTreeMap::new();
        let mut current: Option<String> = None;
        for line in text.lines() {
            let t = line.trim_start();
            let flag = t.strip_prefix("--").or_else(|| t.get(6..).filter(|_| t.starts_with('-') && t[2..].starts_with(", --")));
            // Flags sit at most 6 spaces in; a wrapped description line may begin with a flag's name too.
            match flag {
                Some(f) if line.len() - t.len() <= 6 => {
                    let name: String = f.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
                    current = Some(name.replace('-', "_"));
                    flags.insert(current.clone().unwrap(), t.to_string());
                }
                _ => {
                    if let Some(c) = &current {
                        let entry = flags.get_mut(c).unwrap();
                        entry.push(' ');
                        entry.push_str(t);
                    }
                }
            }
        }
        flags
    };
    let globals = parse(&help(&[]));
    parse(&help(command))
        .into_iter()
        .filter(|(name, _)| !globals.contains_key(name))
        .map(|(name, text)| {
            let default = text.split("[default: ").nth(1).map(|d| d.split(']').next().unwrap_or(d).trim().to_string());
            (name, default)
        })
        .collect()
}

/// The keywords of the Python function `name` and their defaults as the binding declares them
/// (`#[pyo3(signature = (...))]` in python/src/lib.rs); `None`: no default or `None`.
fn binding_keywords(lib: &str, name: &str) -> BTreeMap<String, Option<String>> {
    let at = lib.find(&format!("fn {name}(")).unwrap_or_else(|| panic!("fn {name} in python/src/lib.rs"));
    let sig_at = lib[..at].rfind("#[pyo3(signature = (").expect("its signature") + "#[pyo3(signature = (".len();
    let sig = &lib[sig_at..sig_at + lib[sig_at..].find("))]").expect("closed signature")];
    // Commas inside a quoted default (`scene="point,broad"`) do not split.
    let mut parts = vec![String::new()];
    let mut quoted = false;
    for ch in sig.chars() {
        match ch {
            '"' => {
                quoted = !quoted;
                parts.last_mut().expect("one part").push(ch);
            }
            ',' if !quoted => parts.push(String::new()),
            _ => parts.last_mut().expect("one part").push(ch),
        }
    }
    parts
        .iter()
        .map(|p| p.trim())
        .filter(|p| !p.is_empty() && *p != "*")
        .map(|p| match p.split_once('=') {
            Some((k, v)) => (k.trim().to_string(), Some(v.trim().trim_matches('"').to_string()).filter(|v| v != "None")),
            None => (p.to_string(), None),
        })
        .collect()
}

/// The keywords of `def name(...)` in the type stub and their defaults (`None`: none or `None`).
fn stub_keywords(pyi: &str, name: &str) -> BTreeMap<String, Option<String>> {
    let at = pyi.find(&format!("def {name}(")).unwrap_or_else(|| panic!("def {name} in _ndfit.pyi"));
    let body = &pyi[at..at + pyi[at..].find(") ->").expect("closed def")];
    body.lines()
        .skip(1)
        .filter_map(|l| l.trim().strip_suffix(','))
        .filter(|l| *l != "*")
        .map(|l| {
            let name = l.split(':').next().unwrap_or(l).trim().to_string();
            let default = l.split_once(" = ").map(|(_, d)| d.trim().trim_matches('"').to_string()).filter(|d| d != "None");
            (name, default)
        })
        .collect()
}

/// Defaults written differently are the same value: `64` and `64.0`.
fn same_default(a: &Option<String>, b: &Option<String>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(x), Ok(y)) => x == y,
            _ => a == b,
        },
        (None, None) => true,
        _ => false,
    }
}

/// Every flag of `ndfit fit` and `ndfit ndf` that changes what is computed has a keyword of `ndfit.fit`
/// and `ndfit.ndf` (the binding and its type stub) with the same default. The flags that only say where
/// the results go or how the command talks have none.
#[test]
fn every_cli_flag_has_a_python_keyword_with_its_default() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let lib = std::fs::read_to_string(root.join("python/src/lib.rs")).expect("python/src/lib.rs");
    let pyi = std::fs::read_to_string(root.join("python/ndfit/_ndfit.pyi")).expect("_ndfit.pyi");
    let output_only = ["output", "plot", "quiet", "help", "version", "exr", "exr_size", "png"];
    // `--form` has no clap default because `ndfit convert` shares it and removes nothing by default;
    // the fitting commands fall back to `plane` (cli/scan_args.rs, `ScanArgs::preprocess`).
    let fallback = BTreeMap::from([("form", "plane")]);
    let mut wrong = Vec::new();
    for command in ["fit", "ndf"] {
        let flags = cli_flags(&[command]);
        assert!(flags.len() >= 10 && flags.contains_key("subsample"), "the help of `ndfit {command}` was not read: {flags:?}");
        let binding = binding_keywords(&lib, command);
        let stub = stub_keywords(&pyi, command);
        for (flag, cli_default) in flags.iter().filter(|(f, _)| !output_only.contains(&f.as_str())) {
            let cli_default = cli_default.clone().or_else(|| fallback.get(flag.as_str()).map(|d| d.to_string()));
            match (binding.get(flag), stub.get(flag)) {
                (Some(b), Some(s)) => {
                    if !same_default(&cli_default, b) || !same_default(&cli_default, s) {
                        wrong.push(format!("{command} --{flag}: CLI default {cli_default:?}, binding {b:?}, stub {s:?}"));
                    }
                }
                (b, s) => wrong.push(format!("{command} --{flag}: no Python keyword (binding {b:?}, stub {s:?})")),
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
