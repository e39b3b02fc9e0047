//! One copy of the heights: `ndfit ndf` and `ndfit fit` on a 4096 x 4096 scan (128 MiB of float64
//! heights) of every binary layout that is decoded rather than read in place (other writers' X3P: stored
//! but not 8-byte aligned, deflated, float32, int16; the float32 and integer formats; 16-bit PNG and TIFF, EXR)
//! peak, as each command reports its own peak, within a tenth of the heights of the same command on the
//! same heights read in place (a native float64 NPY). A reader that holds the file's values beside the
//! decoded heights peaks a quarter to all of the heights higher.

#![cfg(target_os = "linux")]

use std::process::Command;

use super::gen;
use super::x3p_deflated::{values, x3p};

const MIB: f64 = 1024.0 * 1024.0;

/// Peak resident set of one `ndfit` run in bytes, as the command reports it (`--report-memory`: the
/// process's own `VmHWM`; a child's `ru_maxrss` would carry this test process's mark across `exec`).
fn peak_rss(args: &[&std::ffi::OsStr]) -> f64 {
    let out = Command::new(env!("CARGO_BIN_EXE_ndfit")).args(args).arg("--report-memory").output().expect("run ndfit");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "ndfit {args:?} failed: {err}");
    let mib: f64 = err
        .lines()
        .find_map(|l| l.strip_prefix("ndfit: peak resident memory ")?.strip_suffix(" MiB")?.parse().ok())
        .unwrap_or_else(|| panic!("no peak in ndfit's report: {err}"));
    mib * MIB
}

/// An X3P whose stored point data starts off an 8-byte boundary (as zip writers without alignment place
/// it), so that the reader must decode it.
fn unaligned_stored_x3p(nx: usize, ny: usize) -> Vec<u8> {
    let data = values("D", nx, ny);
    let md5 = crate::common::md5_hex(&data);
    // Blanks in main.xml (deflated before the data) move the data's offset.
    (0..32)
        .map(|pad| x3p("D", &" ".repeat(pad), nx, ny, &data, &md5, false))
        .find(|b| !data_start(b).is_multiple_of(8))
        .expect("some padding misaligns the data")
}

fn data_start(x3p: &[u8]) -> u64 {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(x3p)).expect("zip");
    let entry = zip.by_name("bindata/data.bin").expect("data entry");
    entry.data_start().expect("offset")
}

/// The heights of `path` as a native float64 NPY, which ndfit reads in place (the reference peak), and
/// the options that read that NPY with the same spacing.
fn in_place_twin(path: &std::path::Path, opts: &ndfit::io::ReadOptions, twin: &std::path::Path) -> Vec<String> {
    let hf = ndfit::io::read_scan(path, opts).expect("read the scan");
    let mut b = gen::npy_header("<f8", false, hf.ny, hf.nx);
    b.reserve(hf.z.len() * 8);
    for v in hf.z.iter() {
        b.extend(v.to_le_bytes());
    }
    std::fs::write(twin, b).expect("write the twin");
    vec!["--dx".into(), format!("{:e}", hf.dx), "--dy".into(), format!("{:e}", hf.dy), "--z-scale".into(), "1".into()]
}

#[test]
fn decoded_scans_hold_one_copy_of_their_heights() {
    let (nx, ny) = (4096, 4096);
    let heights = (nx * ny * 8) as f64;
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("ndf.csv");
    let fit_out = dir.path().join("fit.json");
    let twin = dir.path().join("twin.npy");
    type Make = fn(usize, usize) -> Vec<u8>;
    // (file, writer, whether `fit` is measured too); PNG, TIFF and EXR carry no unit or spacing: `--dx`, `--z-scale`.
    let cases: [(&str, Make, bool); 14] = [
        ("unaligned.x3p", unaligned_stored_x3p, true),
        (
            "deflated.x3p",
            |nx, ny| {
                let data = values("D", nx, ny);
                x3p("D", "", nx, ny, &data, &crate::common::md5_hex(&data), true)
            },
            true,
        ),
        (
            "float32.x3p",
            |nx, ny| {
                let data = values("F", nx, ny);
                x3p("F", "", nx, ny, &data, &crate::common::md5_hex(&data), false)
            },
            false,
        ),
        (
            "int16_deflated.x3p",
            |nx, ny| {
                let data = values("I", nx, ny);
                x3p("I", "<Increment>1e-8</Increment>", nx, ny, &data, &crate::common::md5_hex(&data), true)
            },
            false,
        ),
        ("scan.plu", gen::plu_grid, false),
        ("scan.sur", |nx, ny| gen::sur_grid(nx, ny, false), false),
        ("scan.opd", |nx, ny| gen::opd_grid(nx, ny, false), false),
        ("scan.dat", gen::metropro_grid, false),
        ("scan.al3d", gen::al3d_grid, false),
        ("scan.tmd", gen::tmd_grid, false),
        ("scan.gsf", gen::gsf_grid, false),
        ("scan.png", gen::png16_grid, false),
        ("scan.tif", gen::tiff16_grid, false),
        ("scan.exr", gen::exr_grid, false),
    ];
    let mut failures = Vec::new();
    for (name, make, also_fit) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, make(nx, ny)).expect("write scan");
        let image = name.ends_with(".png") || name.ends_with(".tif") || name.ends_with(".exr");
        let units: Vec<String> = if image { ["--dx", "1e-6", "--z-scale", "1e-9"].map(String::from).to_vec() } else { Vec::new() };
        let opts = ndfit::io::ReadOptions { dx: image.then_some(1e-6), z_scale: image.then_some(1e-9), ..Default::default() };
        let twin_units = in_place_twin(&path, &opts, &twin);
        let run = |cmd: &str, scan: &std::path::Path, units: &[String]| {
            let mut args: Vec<&std::ffi::OsStr> = vec![cmd.as_ref(), scan.as_os_str()];
            args.extend(units.iter().map(|u| std::ffi::OsStr::new(u.as_str())));
            match cmd {
                "ndf" => args.extend(["-o".as_ref(), out.as_os_str()]),
                _ => args.extend(["--model".as_ref(), "ggx-aniso".as_ref(), "-o".as_ref(), fit_out.as_os_str()]),
            }
            peak_rss(&args)
        };
        let cmds: &[&str] = if also_fit { &["ndf", "fit"] } else { &["ndf"] };
        for &cmd in cmds {
            let (peak, reference) = (run(cmd, &path, &units), run(cmd, &twin, &twin_units));
            let extra = (peak - reference) / heights;
            println!(
                "{name:<20} {cmd:<4} peak {:7.1} MiB, the same heights read in place {:7.1} MiB: {extra:+.3} x the heights",
                peak / MIB,
                reference / MIB
            );
            // The bound of a whole process (1.1x the heights + 64 MiB), and a tighter one this size can show:
            // at most a tenth of the heights above the same pipeline on the heights read in place (a copy of
            // the file's values, at 2 to 8 bytes a point, adds a quarter to all of them).
            if extra > 0.1 || peak > 1.1 * heights + 64.0 * MIB {
                failures.push(format!("{name} {cmd}: {:.1} MiB, {extra:+.3} x the heights over the in-place read", peak / MIB));
            }
        }
        std::fs::remove_file(&path).expect("remove scan");
    }
    assert!(failures.is_empty(), "more than one copy of the heights: {failures:?}");
}
