//! Hostile inputs and faults (CONTRACT.md "Any failure"): every command, run under an address-space
//! limit, ends with its exit status and one line naming the file, never a panic or an abort, leaves no
//! output behind and clobbers nothing. The bombs are built here at test time, never committed.

#![cfg(target_os = "linux")]

use std::io::Write;
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::common::ndfit_bin;

/// Address-space limit of every run: what the issue's campaign used.
const AS_LIMIT: u64 = 4 << 30;

/// `ndfit ARGS` in `dir` under an address-space limit of `limit` bytes and umask 027, killed after 20 s.
fn run_limited(dir: &Path, args: &[&str], limit: u64) -> Output {
    let mut cmd = Command::new(ndfit_bin());
    cmd.args(args).current_dir(dir).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    // SAFETY: setrlimit and umask are async-signal-safe and touch only the child.
    unsafe {
        cmd.pre_exec(move || {
            let r = libc::rlimit { rlim_cur: limit as libc::rlim_t, rlim_max: limit as libc::rlim_t };
            if libc::setrlimit(libc::RLIMIT_AS, &r) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            libc::umask(0o027);
            Ok(())
        });
    }
    let child = cmd.spawn().expect("spawn ndfit");
    wait_killing_after(child, Duration::from_secs(20))
}

fn run(dir: &Path, args: &[&str]) -> Output {
    run_limited(dir, args, AS_LIMIT)
}

/// Wait for `child`, killing it (and failing the test) if it takes longer than `limit`.
fn wait_killing_after(mut child: std::process::Child, limit: Duration) -> Output {
    let t0 = Instant::now();
    loop {
        if child.try_wait().expect("wait").is_some() {
            return child.wait_with_output().expect("output");
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().expect("output");
            panic!("ndfit did not finish within {limit:?} (hangs); stderr: {}", String::from_utf8_lossy(&out.stderr));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The failure contract: no signal, no panic (101), a non-zero exit, exactly one stderr line that
/// contains `names`.
fn assert_refused(out: &Output, names: &[&str]) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.signal().is_none(), "killed by signal {:?} (abort?); stderr: {err}", out.status.signal());
    let code = out.status.code().expect("exit code");
    assert!(code != 0 && code != 101, "exit {code}, expected a clean failure; stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.starts_with("ndfit batch: [")).collect();
    assert_eq!(lines.len(), 1, "exactly one stderr line expected, got: {err:?}");
    for n in names {
        assert!(lines[0].contains(n), "the line must name {n:?}: {err}");
    }
    err
}

fn synth(dir: &Path, name: &str, n: usize) -> PathBuf {
    let n = n.to_string();
    let out = run(dir, &["synth", "--nx", &n, "--ny", &n, name]);
    assert!(out.status.success(), "synth: {}", String::from_utf8_lossy(&out.stderr));
    dir.join(name)
}

/// An X3P of `main` and entries `(name, chunk, repeats)`: each entry is `chunk` written `repeats`
/// times, deflated (a bomb is a small chunk of zeros repeated).
fn x3p(path: &Path, main: &str, entries: &[(&str, &[u8], usize)]) {
    let f = std::fs::File::create(path).expect("create");
    let mut zw = zip::ZipWriter::new(std::io::BufWriter::new(f));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .compression_level(Some(6))
        .large_file(true);
    zw.start_file("main.xml", opts).expect("start");
    zw.write_all(main.as_bytes()).expect("write");
    for (name, chunk, repeats) in entries {
        zw.start_file(*name, opts).expect("start");
        for _ in 0..*repeats {
            zw.write_all(chunk).expect("write");
        }
    }
    zw.finish().expect("finish");
}

fn main_xml(nx: usize, ny: usize, ztype: &str, record3_data: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2">
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>SUR</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-6</Increment><Offset>0</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-6</Increment><Offset>0</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>{ztype}</DataType></CZ></Axes></Record1>
<Record3><MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>{record3_data}</Record3>
</p:ISO5436_2>"#
    )
}

#[test]
fn closed_standard_output_ends_quietly_and_a_full_one_fails_in_one_line() {
    let d = tempfile::tempdir().unwrap();
    synth(d.path(), "s.x3p", 64);
    for args in [&["info", "s.x3p", "--json"][..], &["info", "s.x3p"], &["fit", "s.x3p", "--model", "ggx"]] {
        // A reader that closed its end before anything was written (`| head -c0`).
        let (rd, wr) = std::io::pipe().expect("pipe");
        drop(rd);
        let out = Command::new(ndfit_bin()).args(args).current_dir(d.path()).stdout(wr).stderr(Stdio::piped()).output().unwrap();
        assert_eq!(out.status.code(), Some(0), "{args:?} into a closed pipe: {}", String::from_utf8_lossy(&out.stderr));
        assert!(out.stderr.is_empty(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        // A full disk (`> /dev/full`).
        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let out = Command::new(ndfit_bin()).args(args).current_dir(d.path()).stdout(full).stderr(Stdio::piped()).output().unwrap();
        assert_refused(&out, &["<stdout>", "No space left"]);
    }
}

#[test]
fn outputs_follow_symlinks_and_fifos_keep_their_mode_and_never_replace_the_input() {
    let d = tempfile::tempdir().unwrap();
    let scan = synth(d.path(), "s.x3p", 64);
    let scan_bytes = std::fs::read(&scan).unwrap();

    // The input itself, directly and through a link: refused, untouched.
    std::os::unix::fs::symlink("s.x3p", d.path().join("alias.json")).unwrap();
    for o in ["s.x3p", "alias.json"] {
        let out = run(d.path(), &["fit", "s.x3p", "--model", "ggx", "-o", o]);
        assert_refused(&out, &[o, "input"]);
        assert_eq!(std::fs::read(&scan).unwrap(), scan_bytes, "-o {o} clobbered the input");
    }
    let out = run(d.path(), &["convert", "s.x3p", "s.x3p"]);
    assert_refused(&out, &["s.x3p", "input"]);

    // A symlink is written through: the link stays, its target gets the JSON.
    std::fs::write(d.path().join("target.json"), "old").unwrap();
    std::os::unix::fs::symlink("target.json", d.path().join("link.json")).unwrap();
    // A temporary file a killed run left behind is cleaned up by the next write of that name.
    let stale = d.path().join(".target.json.k1LLed.tmp");
    std::fs::write(&stale, "half").unwrap();
    let out = run(d.path(), &["fit", "s.x3p", "--model", "ggx", "-o", "link.json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(std::fs::symlink_metadata(d.path().join("link.json")).unwrap().file_type().is_symlink());
    let fit: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.path().join("target.json")).unwrap()).unwrap();
    assert_eq!(fit["model"], "ggx");
    assert!(!stale.exists(), "stale temporary file left");

    // A new output follows the umask (027 in run): 0666 & !027 = 0640.
    let out = run(d.path(), &["fit", "s.x3p", "--model", "ggx", "-o", "new.json"]);
    assert!(out.status.success());
    assert_eq!(std::fs::metadata(d.path().join("new.json")).unwrap().permissions().mode() & 0o777, 0o640);

    // A FIFO is written into, not replaced by a regular file.
    let fifo = d.path().join("pipe.json");
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: mkfifo on a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    let out = run(d.path(), &["fit", "s.x3p", "--model", "ggx", "-o", "pipe.json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = reader.join().unwrap();
    assert!(text.contains("\"schema\": \"ndfit.fit/1\""), "{text}");
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo(), "the FIFO was replaced");
}

#[test]
fn small_files_declaring_huge_grids_are_refused_within_the_budget() {
    let d = tempfile::tempdir().unwrap();
    // 8192 x 8192 float64 (512 MiB) from ~0.5 MiB of deflated zeros, under a 1 GiB address space.
    let zeros = vec![0u8; 1 << 20];
    x3p(
        &d.path().join("bomb.x3p"),
        &main_xml(8192, 8192, "D", "<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink>"),
        &[("bindata/data.bin", &zeros, 512)],
    );
    let size = std::fs::metadata(d.path().join("bomb.x3p")).unwrap().len();
    assert!(size < 2 << 20, "{size} bytes");
    // 4M XML elements (hundreds of MiB as a tree) from a small deflated main.xml.
    let data = format!("<DataList>{}</DataList>", "<Datum/>".repeat(4 << 20));
    x3p(&d.path().join("xml.x3p"), &main_xml(2048, 2048, "D", &data), &[]);
    for (file, what) in [("bomb.x3p", "8192 x 8192"), ("xml.x3p", "elements")] {
        for cmd in ["info", "fit", "ndf"] {
            let mut args = vec![cmd, file];
            if cmd == "ndf" {
                args.extend(["-o", "n.csv"]);
            }
            let t0 = Instant::now();
            let out = run_limited(d.path(), &args, 1 << 30);
            let err = assert_refused(&out, &[file, what, "memory budget"]);
            assert!(t0.elapsed() < Duration::from_secs(5), "{cmd} {file}: refusal took {:?}: {err}", t0.elapsed());
        }
    }
    assert!(!d.path().join("n.csv").exists());
    // `--max-memory` moves the budget: a 64 x 64 scan is refused under 64 KiB.
    synth(d.path(), "s.x3p", 64);
    let out = run(d.path(), &["--max-memory", "64K", "info", "s.x3p"]);
    assert_refused(&out, &["s.x3p", "64 x 64", "64.0 KiB"]);
    // In-range requests that exceed the budget are refused the same way.
    let out = run(d.path(), &["synth", "--nx", "32768", "--ny", "32768", "big.x3p"]);
    assert_refused(&out, &["32768 x 32768", "memory budget"]);
    assert!(!d.path().join("big.x3p").exists());
}

#[test]
fn batch_keeps_going_past_a_bomb_and_refuses_colliding_names_and_a_second_writer() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    synth(&scans, "a.x3p", 48);
    let zeros = vec![0u8; 1 << 20];
    x3p(
        &scans.join("bomb.x3p"),
        &main_xml(8192, 8192, "D", "<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink>"),
        &[("bindata/data.bin", &zeros, 512)],
    );
    // One unreadable file is an error entry; the run finishes with its summary and exit 2.
    let out = run_limited(d.path(), &["batch", "scans", "-o", "out", "--jobs", "1"], 1 << 30);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.path().join("out/summary.json")).unwrap()).unwrap();
    let text = summary.to_string();
    assert!(text.contains("memory budget") && text.contains("a.x3p"), "{text}");
    std::fs::remove_file(scans.join("bomb.x3p")).unwrap();

    // Two scans whose keys map to one output name: refused, naming both, nothing written.
    std::fs::copy(scans.join("a.x3p"), scans.join("a:b.x3p")).unwrap();
    std::fs::copy(scans.join("a.x3p"), scans.join("a_b.x3p")).unwrap();
    let out = run(d.path(), &["batch", "scans", "-o", "out2"]);
    assert_refused(&out, &["a:b.x3p", "a_b.x3p", "same output"]);
    assert!(!d.path().join("out2/summary.json").exists());
    std::fs::remove_file(scans.join("a:b.x3p")).unwrap();

    // A second batch on an OUT_DIR in use is refused with one line; the first finishes normally.
    let first = Command::new(ndfit_bin())
        .args(["batch", "scans", "-o", "out3", "--debug-delay-ms", "1500", "--jobs", "1"])
        .current_dir(d.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lock = d.path().join("out3/.ndfit-batch.lock");
    let t0 = Instant::now();
    while !lock.exists() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));
    let out = run(d.path(), &["batch", "scans", "-o", "out3"]);
    assert_refused(&out, &["out3", "another ndfit batch"]);
    let first = wait_killing_after(first, Duration::from_secs(30));
    assert_eq!(first.status.code(), Some(0), "{}", String::from_utf8_lossy(&first.stderr));
}

#[test]
fn huge_heights_special_files_and_bad_arguments_fail_in_one_line() {
    let d = tempfile::tempdir().unwrap();
    // Heights near 1e200: slopes overflow; the NDF is an error, no CSV and no plot are left.
    let mut text = String::new();
    for i in 0..32 {
        let row: Vec<String> = (0..32).map(|j| format!("{:e}", (((i * 7 + j * 13) % 17) as f64 - 8.0) * 1e200)).collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    std::fs::write(d.path().join("huge.asc"), text).unwrap();
    let out = run(d.path(), &["ndf", "huge.asc", "--dx", "1e-6", "--z-scale", "1", "-o", "h.csv", "--png", "h"]);
    assert_refused(&out, &["huge.asc", "not finite"]);
    let left: Vec<String> = std::fs::read_dir(d.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["huge.asc"], "outputs or temporary files left behind");

    // A FIFO with no writer and an endless device are refused at once, not waited on or read forever.
    let fifo = d.path().join("f.x3p");
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: mkfifo on a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    assert_refused(&run(d.path(), &["info", "f.x3p"]), &["f.x3p", "regular file"]);
    assert_refused(&run(d.path(), &["info", "/dev/zero"]), &["/dev/zero", "regular file"]);

    // A newline inside the file's text stays inside the one line.
    let link = "<DataLink><PointDataLink>bin\ndata.bin</PointDataLink></DataLink>";
    x3p(&d.path().join("nl.x3p"), &main_xml(4, 4, "D", link), &[("bindata/data.bin", &[0u8; 128], 1)]);
    assert_refused(&run(d.path(), &["info", "nl.x3p"]), &["nl.x3p", "bin\\ndata.bin"]);

    // Argument errors are one line; a timeout beyond any Duration is refused, not a panic.
    assert_refused(&run(d.path(), &["fit", "--bogus"]), &["--bogus"]);
    assert_refused(&run(d.path(), &["batch", "x", "-o", "y", "--isolate", "process", "--timeout", "1e20"]), &["--timeout"]);
    // Values out of range are refused, not silently changed.
    synth(d.path(), "s.x3p", 32);
    assert_refused(&run(d.path(), &["fit", "s.x3p", "--ndf-cells", "4"]), &["--ndf-cells 4", "odd"]);
    assert_refused(&run(d.path(), &["fit", "s.x3p", "--extra-starts", "100"]), &["--extra-starts 100"]);
}

#[test]
fn eval_gives_tiny_directions_their_value() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("f.json"), r#"{"model": "ggx", "params": {"alpha": 0.3}}"#).unwrap();
    let eval = |input: &str| {
        let mut child = Command::new(ndfit_bin())
            .args(["eval", "f.json"])
            .current_dir(d.path())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
        child.wait_with_output().unwrap()
    };
    // (1e-310, 0, 1e-310) is the direction (1, 0, 1)/sqrt(2): the same D, not "the zero vector".
    let tiny = eval("mx,my,mz\n1e-310,0,1e-310\n");
    let unit = eval("mx,my,mz\n1,0,1\n");
    assert!(tiny.status.success(), "{}", String::from_utf8_lossy(&tiny.stderr));
    assert_eq!(String::from_utf8_lossy(&tiny.stdout), String::from_utf8_lossy(&unit.stdout));
    assert_refused(&eval("mx,my,mz\n0,0,0\n"), &["line 2", "zero vector"]);
}

#[test]
fn a_tiff_strip_shorter_than_its_rows_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let (nx, ny) = (64u32, 64u32);
    let px: Vec<u16> = (0..nx * ny).map(|k| (k % 977) as u16 + 1000).collect();
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(nx, ny, px).unwrap();
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Tiff).unwrap();
    let mut bytes = bytes.into_inner();
    std::fs::write(d.path().join("ok.tif"), &bytes).unwrap();
    let out = run(d.path(), &["info", "ok.tif", "--dx", "1e-6", "--z-scale", "1e-9"]);
    assert!(out.status.success(), "the intact TIFF reads: {}", String::from_utf8_lossy(&out.stderr));
    // Little-endian classic TIFF: find StripByteCounts (279) in the first directory and shorten the
    // last strip by one row.
    assert_eq!(&bytes[..4], b"II*\0");
    let u16at = |b: &[u8], o: usize| u16::from_le_bytes([b[o], b[o + 1]]) as usize;
    let u32at = |b: &[u8], o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
    let ifd = u32at(&bytes, 4);
    let entry = (0..u16at(&bytes, ifd)).map(|k| ifd + 2 + 12 * k).find(|&e| u16at(&bytes, e) == 279).expect("StripByteCounts");
    let (typ, count) = (u16at(&bytes, entry + 2), u32at(&bytes, entry + 4));
    let size = if typ == 3 { 2 } else { 4 };
    let at = if count * size <= 4 { entry + 8 } else { u32at(&bytes, entry + 8) } + (count - 1) * size;
    let last = if size == 2 { u16at(&bytes, at) } else { u32at(&bytes, at) };
    let short = last - 2 * nx as usize;
    if size == 2 {
        bytes[at..at + 2].copy_from_slice(&(short as u16).to_le_bytes());
    } else {
        bytes[at..at + 4].copy_from_slice(&(short as u32).to_le_bytes());
    }
    std::fs::write(d.path().join("short.tif"), &bytes).unwrap();
    let out = run(d.path(), &["info", "short.tif", "--dx", "1e-6", "--z-scale", "1e-9"]);
    assert_refused(&out, &["short.tif", "strip", &format!("holds {short} bytes")]);
}

#[test]
fn resume_writes_a_deleted_fit_file_again() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    synth(&scans, "a.x3p", 48);
    let out = run(d.path(), &["batch", "scans", "-o", "out", "--model", "ggx"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let fit = d.path().join("out/fits/a.x3p.fit.json");
    let first = std::fs::read_to_string(&fit).unwrap();
    std::fs::remove_file(&fit).unwrap();
    let out = run(d.path(), &["batch", "scans", "-o", "out", "--model", "ggx", "--resume"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read_to_string(&fit).expect("the fit file is back"), first);
}

#[test]
fn resume_rewrites_a_fit_file_a_power_loss_left_empty_or_cut() {
    // Batch files are renamed into place unsynced and synced once per run: a power loss before that
    // sync can leave a fit file empty or cut short beside a complete record. --resume restores it.
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    synth(&scans, "a.x3p", 48);
    let out = run(d.path(), &["batch", "scans", "-o", "out", "--model", "ggx"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let fit = d.path().join("out/fits/a.x3p.fit.json");
    let first = std::fs::read_to_string(&fit).unwrap();
    for damaged in [String::new(), first[..first.len() / 2].to_string()] {
        std::fs::write(&fit, &damaged).unwrap();
        let out = run(d.path(), &["batch", "scans", "-o", "out", "--model", "ggx", "--resume"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(std::fs::read_to_string(&fit).unwrap(), first, "fit file left {} bytes", damaged.len());
    }
}

#[test]
fn negative_values_reach_batch_scans_from_the_command_line_and_the_manifest() {
    let d = tempfile::tempdir().unwrap();
    // A rough ASCII grid (height units; slopes about 0.3 at --z-scale 1e-9 over --dx 1e-6).
    let rows: Vec<String> = (0..48)
        .map(|i| {
            let h = |j: usize| {
                let (x, y) = (i as f64, j as f64);
                300.0 * (0.7 * x + 0.3 * y).sin() + 200.0 * (1.3 * y + 0.2 * x).cos() + 50.0 * (2.1 * ((i * j) % 7) as f64).sin()
            };
            (0..48).map(|j| format!("{:.3}", h(j))).collect::<Vec<_>>().join(" ")
        })
        .collect();
    std::fs::write(d.path().join("r.asc"), rows.join("\n") + "\n").unwrap();
    // Negative values with exponents, after `--` and in manifest cells; a scan's own value replaces the run's.
    std::fs::write(
        d.path().join("m.csv"),
        "path,id,z_scale,options\nr.asc,neg,-2e-9,\nr.asc,pos,2e-9,\nr.asc,opt,,--z-scale -2e-9\nr.asc,run,,\n",
    )
    .unwrap();
    let out = run(d.path(), &["batch", "m.csv", "-o", "out", "--model", "ggx", "--", "--dx", "1e-6", "--z-scale", "-1e-9"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.path().join("out/summary.json")).unwrap()).unwrap();
    let alpha = |key: &str| {
        let e = summary["entries"].as_array().unwrap().iter().find(|e| e["path"] == key).unwrap();
        assert_eq!(e["status"], "ok", "{e}");
        e["fit"]["params"]["alpha"].as_f64().unwrap()
    };
    // Negated heights give the point-reflected NDF: an isotropic fit sees the same roughness; GGX alpha
    // is a slope scale, so twice the heights give about twice the alpha.
    assert_eq!(alpha("opt"), alpha("neg"));
    assert!((alpha("neg") / alpha("pos") - 1.0).abs() < 1e-3, "{} vs {}", alpha("neg"), alpha("pos"));
    assert!((alpha("pos") / (2.0 * alpha("run")) - 1.0).abs() < 0.03, "{} vs {}", alpha("pos"), alpha("run"));
    // A negative count is a one-line error naming the option, not a stray argument.
    std::fs::write(d.path().join("bad.csv"), "path,extra_starts\nr.asc,-1\n").unwrap();
    let out = run(d.path(), &["batch", "bad.csv", "-o", "out2", "--", "--dx", "1e-6"]);
    assert_refused(&out, &["r.asc", "'-1' for '--extra-starts"]);
    assert_refused(&run(d.path(), &["batch", "m.csv", "-o", "out3", "--", "--extra-starts", "100"]), &["--extra-starts 100"]);
}

#[test]
fn an_x3p_whose_main_xml_does_not_match_its_md5_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let main = main_xml(4, 4, "D", "<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink>");
    let data: Vec<u8> = (0..16).flat_map(|k| (k as f64 * 1e-7).to_le_bytes()).collect();
    // The checksum file of a different main.xml (one byte more).
    let sum = format!("{} *main.xml\n", crate::common::md5_hex(format!("{main} ").as_bytes()));
    x3p(&d.path().join("m.x3p"), &main, &[("bindata/data.bin", &data, 1), ("md5checksum.hex", sum.as_bytes(), 1)]);
    let out = run(d.path(), &["info", "m.x3p"]);
    assert_refused(&out, &["m.x3p", "md5checksum.hex", "main.xml"]);
    // With the right sum it reads.
    let sum = format!("{} *main.xml\n", crate::common::md5_hex(main.as_bytes()));
    x3p(&d.path().join("m.x3p"), &main, &[("bindata/data.bin", &data, 1), ("md5checksum.hex", sum.as_bytes(), 1)]);
    let out = run(d.path(), &["info", "m.x3p"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Degenerate NDFs for the plots: one bin, every bin empty (D constant 0), D equal everywhere, D over
/// six hundred decades, a bin at the pole only.
fn degenerate_ndfs() -> Vec<(&'static str, ndfit::ndf::EmpiricalNdf)> {
    use ndfit::ndf::{EmpiricalNdf, NdfBin};
    let bin = |th: f64, d: f64, count: u64| NdfBin {
        m: nalgebra::Vector3::new(th.sin(), 0.0, th.cos()),
        d,
        stderr: 0.0,
        count,
        solid_angle: 1e-3,
        proj_solid_angle: 1e-3 * th.cos(),
    };
    let ramp = |f: &dyn Fn(usize) -> (f64, u64)| {
        (0..40)
            .map(|k| {
                let (d, c) = f(k);
                bin(k as f64 * 0.035, d, c)
            })
            .collect::<Vec<_>>()
    };
    vec![
        ("one bin", EmpiricalNdf::from_bins(vec![bin(0.0, 1.0 / 1e-3, 100)], 100)),
        ("all empty", EmpiricalNdf::from_bins(ramp(&|_| (0.0, 0)), 0)),
        ("constant", EmpiricalNdf::from_bins(ramp(&|_| (25.0, 10)), 400)),
        ("huge range", EmpiricalNdf::from_bins(ramp(&|k| (10f64.powi(300 - 15 * k as i32), 1 + k as u64)), 820)),
        ("tiny", EmpiricalNdf::from_bins(ramp(&|_| (f64::MIN_POSITIVE, 1)), 40)),
        (
            "zero solid angle",
            EmpiricalNdf::from_bins(
                ramp(&|k| (1.0, k as u64)).into_iter().map(|b| NdfBin { proj_solid_angle: 0.0, solid_angle: 0.0, ..b }).collect(),
                780,
            ),
        ),
        (
            "denormal solid angle",
            EmpiricalNdf::from_bins(
                ramp(&|k| (1e300, k as u64)).into_iter().map(|b| NdfBin { proj_solid_angle: 1e-320, ..b }).collect(),
                780,
            ),
        ),
    ]
}

#[test]
fn plots_of_degenerate_ndfs_draw_or_fail_cleanly() {
    let d = tempfile::tempdir().unwrap();
    let models = [
        ndfit::models::Model::from_json(&serde_json::json!({"model": "ggx", "params": {"alpha": 0.3}})).unwrap(),
        ndfit::models::Model::from_json(&serde_json::json!({"model": "beckmann", "params": {"alpha": 1e-3}})).unwrap(),
        ndfit::models::Model::from_json(&serde_json::json!({"model": "ggx", "params": {"alpha": 1e-170}})).unwrap(),
    ];
    let mut bad = Vec::new();
    for (name, ndf) in degenerate_ndfs() {
        let outs: Vec<(String, ndfit::Result<()>)> = vec![
            ("map".into(), ndfit::ndf::plot_map(&d.path().join("map.png"), &ndf, name)),
            ("slices".into(), ndfit::ndf::plot_slices(&d.path().join("slices.png"), &ndf, name)),
        ]
        .into_iter()
        .chain(
            models
                .iter()
                .enumerate()
                .map(|(k, m)| (format!("fit{k}"), ndfit::fit::plot_fit(&d.path().join(format!("fit{k}.png")), &ndf, m, name))),
        )
        .collect();
        for (what, r) in outs {
            let p = d.path().join(format!("{what}.png"));
            match r {
                Ok(()) => match image::open(&p) {
                    Ok(img) if img.width() > 100 => std::fs::remove_file(&p).unwrap(),
                    other => bad.push(format!("{name} {what}: not a PNG: {:?}", other.err())),
                },
                Err(e) => {
                    let msg = e.to_string();
                    if msg.contains('\n') || !msg.contains(&format!("{what}.png")) {
                        bad.push(format!("{name} {what}: the error must be one line naming the file: {msg}"));
                    }
                    if p.exists() {
                        bad.push(format!("{name} {what}: a failed plot left its file"));
                    }
                }
            }
        }
        let left: Vec<_> = std::fs::read_dir(d.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        if !left.is_empty() {
            bad.push(format!("{name}: left behind {left:?}"));
            for f in left {
                std::fs::remove_file(d.path().join(f)).unwrap();
            }
        }
    }
    assert!(bad.is_empty(), "{bad:#?}");
}

#[test]
fn resume_writes_deleted_ndf_files_and_plots_again() {
    let d = tempfile::tempdir().unwrap();
    let scans = d.path().join("scans");
    std::fs::create_dir(&scans).unwrap();
    synth(&scans, "a.x3p", 48);
    synth(&scans, "b.x3p", 40);
    let args = ["batch", "scans", "-o", "out", "--model", "ggx", "--write-ndf", "--plots", "--jobs", "1"];
    let out = run(d.path(), &args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (ndf, png, other) =
        (d.path().join("out/ndf/a.x3p.ndf.csv"), d.path().join("out/plots/a.x3p.png"), d.path().join("out/ndf/b.x3p.ndf.csv"));
    let (first_ndf, first_png) = (std::fs::read(&ndf).unwrap(), std::fs::read(&png).unwrap());
    let other_mtime = std::fs::metadata(&other).unwrap().modified().unwrap();
    std::fs::remove_file(&ndf).unwrap();
    std::fs::remove_file(&png).unwrap();
    let out = run(d.path(), &[&args[..], &["--resume"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read(&ndf).expect("the NDF file is back"), first_ndf);
    assert_eq!(std::fs::read(&png).expect("the plot is back"), first_png);
    // The scan whose files are all there is reused, not fitted again.
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ok (resumed) b.x3p") && !err.contains("ok (resumed) a.x3p"), "{err}");
    assert_eq!(std::fs::metadata(&other).unwrap().modified().unwrap(), other_mtime);
}

/// Text scans have no header to declare their size, so the budget is checked against the file's own size
/// (24 bytes of memory per file byte, `data_formats/limits.md`): a 1.2 MB matrix needs ~29 MB, refused under
/// an 8 MiB budget in one line naming the file, read under 64 MiB.
#[test]
fn a_text_scan_beyond_the_budget_is_refused_before_parsing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.txt");
    let row: String = (0..400).map(|j| format!("{} ", (j * 7919) % 1000)).collect::<String>() + "\n";
    std::fs::write(&path, row.repeat(400)).unwrap();
    let len = std::fs::metadata(&path).unwrap().len();
    assert!(len * 24 > 8 << 20 && len * 24 < 64 << 20, "{len} bytes");
    let p = path.to_str().unwrap();
    let out = run(dir.path(), &["--max-memory", "8M", "info", p, "--dx", "1e-6", "--z-scale", "1e-9"]);
    let err = assert_refused(&out, &["big.txt", "memory budget"]);
    assert!(err.contains("text scan"), "{err}");
    let ok = run(dir.path(), &["--max-memory", "64M", "info", p, "--dx", "1e-6", "--z-scale", "1e-9", "--json"]);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let v: serde_json::Value = serde_json::from_slice(&ok.stdout).unwrap();
    assert_eq!((v["nx"].as_u64(), v["ny"].as_u64()), (Some(400), Some(400)));
}
