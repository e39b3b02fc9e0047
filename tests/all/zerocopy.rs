//! Zero-copy reads and the band-wise preprocessing against the copying path: a stored float64 X3P is
//! read in place (the scan's heights are the mapped file), and the NDF built from a [`Prepared`] scan
//! (form and spike mask kept apart, residual rows made band by band, pages released after each band on
//! a tiled scan) has the same bins, counts and frame, bit for bit, as the NDF of the residual heights
//! [`ndfit::preprocess::apply`] makes, whatever the band size; the slope moments agree to rounding (a
//! plane form is folded into the slopes, see `plane_fold`).

use ndfit::ndf::{empirical_ndf, EmpiricalNdf, NdfOptions, NormalScheme};
use ndfit::pipeline::{ndf_prepared, read_prepared};
use ndfit::preprocess::{apply, prepare, FormRemoval, Preprocess};
use ndfit::scan::{set_band_rows, set_release_threshold};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::Heightfield;

/// A Gaussian surface on a tilted, curved form with a large stage offset, holes and a few spikes: every
/// preprocessing step has something to do.
fn scan(nx: usize, ny: usize) -> Heightfield {
    let s = SynthSettings { nx, ny, dx: 1e-6, dy: 1e-6, seed: 7, holes: 0.002, offset: 0.0, ..Default::default() };
    let (mut hf, _) = gaussian_surface(&s, &GaussianParams { corr_length: 6e-6, ..Default::default() }).expect("valid");
    for i in 0..ny {
        for j in 0..nx {
            let (x, y) = (j as f64 * 1e-6, i as f64 * 1e-6);
            let k = i * nx + j;
            hf.z[k] += 3e-3 + 0.02 * x - 0.01 * y + 40.0 * x * y;
            if k % 9973 == 17 {
                hf.z[k] += 5e-5;
            }
        }
    }
    hf
}

fn same_ndf(a: &EmpiricalNdf, b: &EmpiricalNdf, what: &str) {
    assert_eq!(a.n_samples, b.n_samples, "{what}: samples");
    assert_eq!(a.n_skipped, b.n_skipped, "{what}: skipped");
    assert_eq!(a.frame, b.frame, "{what}: frame");
    assert_eq!(a.grid, b.grid, "{what}: grid");
    assert_eq!(a.bins, b.bins, "{what}: bins");
    assert_eq!(a.counts_odd, b.counts_odd, "{what}: odd counts");
    assert_eq!(a.unresolved, b.unresolved, "{what}: unresolved");
    // A plane form is folded into the counting pass's slopes (raw heights, moved frame): the moments
    // agree to rounding, within 1e-9 of the slope scale (the counts above stay exact on these data).
    let scale = a.frame.cov[0][0].max(a.frame.cov[1][1]).sqrt();
    for k in 0..2 {
        assert!((a.slope_mean[k] - b.slope_mean[k]).abs() <= 1e-9 * scale, "{what}: slope mean {:?} {:?}", a.slope_mean, b.slope_mean);
        for l in 0..2 {
            assert!((a.slope_cov[k][l] - b.slope_cov[k][l]).abs() <= 1e-9 * scale * scale, "{what}: slope covariance");
        }
    }
}

/// Band-wise preprocessing (despiking on the lazily formed heights, frame, lattice, histogram and
/// resolution passes over bands) gives the NDF of the materialized residual heights, bit for bit, for
/// every form and both normal schemes, with one-row bands (a band edge at every row), three-row bands
/// and the default size.
#[test]
fn prepared_bands_equal_the_residual_copy() {
    let hf = scan(203, 157);
    for form in [FormRemoval::Plane, FormRemoval::Polynomial(2), FormRemoval::Polynomial(3), FormRemoval::None] {
        let pre = Preprocess { form, ..Preprocess::default() };
        let copied = apply(hf.clone(), &pre).expect("apply");
        for scheme in [NormalScheme::Central, NormalScheme::Triangles] {
            let opts = NdfOptions { scheme, ..NdfOptions::default() };
            let want = empirical_ndf(&copied, &opts).expect("ndf of the copy");
            for rows in [Some(1), Some(3), None] {
                set_band_rows(rows);
                let p = prepare(hf.clone(), &pre).expect("prepare");
                assert_eq!(p.meta().despike, copied.meta.despike, "{form:?}: the same spikes");
                assert_eq!(p.invalid_count(), copied.invalid_count());
                let got = ndf_prepared(&p, &opts).expect("ndf of the bands");
                same_ndf(&got, &want, &format!("{form:?} {scheme:?} rows {rows:?}"));
                let bits = |z: &[f64]| z.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
                assert_eq!(bits(&p.clone().into_scan().z), bits(&copied.z), "materialized heights are apply's");
            }
            set_band_rows(None);
        }
    }
    // The spikes were found (and masked apart from the heights).
    let p = prepare(hf.clone(), &Preprocess::default()).expect("prepare");
    assert!(p.masked().len() >= 3, "spikes masked: {}", p.masked().len());
    assert!(p.masked().iter().all(|&k| !hf.z[k].is_nan()), "masked points were valid heights");
}

/// A stored float64 X3P (as `write_x3p` writes it: data entry 8-byte aligned) is read in place: the
/// heights are the mapped file's bytes, equal to what was written, and stay mapped through
/// preprocessing (plane and despiking); the NDF and fit equal those of the copying path. With every band
/// released after use (a tiled read), the results are the same again.
#[test]
fn stored_x3p_is_read_in_place_and_gives_the_copying_path_bits() {
    let hf = scan(1100, 700); // 6.2 MB of heights: above the size that is mapped rather than read
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.x3p");
    ndfit::io::write_x3p(&path, &hf).expect("write");
    let read = ndfit::io::read_scan(&path, &Default::default()).expect("read");
    assert!(read.z.is_mapped(), "stored float64 X3P read in place");
    assert!(read.z.iter().zip(hf.z.iter()).all(|(a, b)| a.to_bits() == b.to_bits()), "the bytes written");
    // The copying path: the heights decoded into memory, then preprocessed by `apply`.
    let owned = Heightfield::new(hf.nx, hf.ny, hf.dx, hf.dy, read.z.to_vec()).expect("copy");
    let pre = Preprocess::default();
    let want = empirical_ndf(&apply(owned, &pre).expect("apply"), &NdfOptions::default()).expect("ndf");
    for release in [None, Some(1)] {
        set_release_threshold(release);
        let p = read_prepared(&path, &Default::default(), &pre).expect("prepared");
        assert!(p.raw().z.is_mapped(), "no copy through form removal and despiking");
        let got = ndf_prepared(&p, &NdfOptions::default()).expect("ndf");
        same_ndf(&got, &want, &format!("mapped, release {release:?}"));
    }
    set_release_threshold(None);
    let fit_file = ndfit::Pipeline::default().run_path(&path).expect("fit");
    let fit_mem = ndfit::Pipeline::default().run(hf.clone(), "mem").expect("fit");
    assert_eq!(fit_file.fit.params, fit_mem.fit.params);
    assert_eq!(fit_file.fit.input.expect("input").invalid, fit_mem.fit.input.expect("input").invalid);
}

/// A stored X3P whose data entry is not 8-byte aligned (another writer), or that scales its values
/// (`Increment`), is decoded into memory: the same heights, not mapped.
#[test]
fn misaligned_or_scaled_stored_x3p_is_decoded() {
    let hf = scan(1100, 700);
    let dir = tempfile::tempdir().expect("temp dir");
    let bytes = ndfit::io::x3p_bytes(&hf).expect("bytes");
    // Rebuild the zip with the data entry one byte off alignment: a 1-byte longer comment file first.
    let mut src = zip::ZipArchive::new(std::io::Cursor::new(&bytes)).expect("zip");
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut zw = zip::ZipWriter::new(&mut out);
        let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        zw.start_file("a", stored).expect("pad");
        std::io::Write::write_all(&mut zw, b"x").expect("pad");
        for k in 0..src.len() {
            let mut e = src.by_index(k).expect("entry");
            let name = e.name().expect("name").to_string();
            let mut data = Vec::new();
            std::io::Read::read_to_end(&mut e, &mut data).expect("read entry");
            if name.ends_with('/') {
                continue;
            }
            zw.start_file(name, stored).expect("entry");
            std::io::Write::write_all(&mut zw, &data).expect("write entry");
        }
        zw.finish().expect("finish");
    }
    let path = dir.path().join("m.x3p");
    std::fs::write(&path, out.into_inner()).expect("write");
    let read = ndfit::io::read_scan(&path, &Default::default()).expect("read");
    let data_at = {
        let f = std::fs::File::open(&path).expect("open");
        let mut z = zip::ZipArchive::new(f).expect("zip");
        let e = z.by_name("bindata/data.bin").expect("data");
        e.data_start().expect("offset")
    };
    assert_eq!(read.z.is_mapped(), data_at % 8 == 0, "mapped exactly when aligned (data at byte {data_at})");
    assert!(read.z.iter().zip(hf.z.iter()).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// The in-place read's checks on a stored float64 X3P of several 1 MiB blocks (hashed on every thread):
/// a byte changed in a late block is a CRC-32 error, and infinities in late blocks send the scan to the
/// decoding path, which masks exactly those points (NaN) and keeps every other height.
#[test]
fn stored_x3p_checks_hold_in_every_block() {
    let mut hf = scan(1100, 700);
    let n = hf.z.len();
    let (a, b) = (n - 3, 2 * n / 3);
    hf.z[a] = f64::INFINITY;
    hf.z[b] = f64::NEG_INFINITY;
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("inf.x3p");
    let bytes = ndfit::io::x3p_bytes(&hf).expect("bytes");
    std::fs::write(&path, &bytes).expect("write");
    let read = ndfit::io::read_scan(&path, &Default::default()).expect("read");
    assert!(!read.z.is_mapped(), "infinities need the decoding copy");
    for k in 0..n {
        if k == a || k == b {
            assert!(read.z[k].is_nan(), "infinity at {k} masked");
        } else {
            assert_eq!(read.z[k].to_bits(), hf.z[k].to_bits(), "height {k}");
        }
    }
    // One byte of the last MiB of the point data changed: the zip's CRC-32 no longer matches. The scan
    // is above the size whose MD5 is checked (`MAX_POINT_MD5`), so the CRC-32 is the check that sees it.
    let (nx, ny) = (2100, 2050);
    assert!(nx * ny * 8 > ndfit::io::MAX_POINT_MD5);
    let z: Vec<f64> = (0..nx * ny).map(|k| 1e-7 * ((k % nx) as f64 * 0.01).sin() + 1e-9 * (k / nx) as f64).collect();
    let big = Heightfield::new(nx, ny, 1e-6, 1e-6, z).expect("shape");
    let bytes = ndfit::io::x3p_bytes(&big).expect("bytes");
    let start = {
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes)).expect("zip");
        let entry = zip.by_name("bindata/data.bin").expect("data entry");
        entry.data_start().expect("offset") as usize
    };
    let path = dir.path().join("good.x3p");
    std::fs::write(&path, &bytes).expect("write");
    assert!(ndfit::io::read_scan(&path, &Default::default()).expect("intact").z.is_mapped());
    let mut bad = bytes;
    bad[start + 8 * nx * ny - 5000] ^= 0x10;
    let path = dir.path().join("bad.x3p");
    std::fs::write(&path, &bad).expect("write");
    let err = ndfit::io::read_scan(&path, &Default::default()).expect_err("corrupt data").to_string();
    assert!(err.contains("CRC-32"), "{err}");
}
