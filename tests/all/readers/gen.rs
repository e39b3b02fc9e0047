//! Writers of small valid files of every binary and plain format, built here from the published
//! layouts (data_formats/formats.md), independently of the readers. They give the readers a known
//! truth, seed the robustness checks, and (via `generate_seed_corpus`) the cargo-fuzz corpora.

#![allow(dead_code)]

use std::io::Write;

/// Grid size of the generated files: small, non-square, odd.
pub const NX: usize = 7;
/// Rows.
pub const NY: usize = 5;
/// Points that are invalid in generated files (where the format can mark them).
pub const HOLES: [usize; 2] = [3, 17];

/// The stored value at (i, j): small integers so every format holds it exactly.
pub fn stored(i: usize, j: usize) -> i32 {
    (i as i32 * 37 - j as i32 * 11 + ((i * j) as i32 % 5) * 3) - 40
}

fn is_hole(k: usize) -> bool {
    HOLES.contains(&k)
}

fn pad(s: &str, n: usize) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.resize(n, 0);
    v
}

/// Sensofar PLU, µm per pixel 1.5 x 2.5, heights in µm = stored / 4.
pub fn plu() -> Vec<u8> {
    plu_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn plu_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut b = pad("Fri Mar 10 16:35:59 2023", 128);
    b.extend(1_678_462_559u32.to_le_bytes());
    b.extend(pad("(None)", 256));
    b.extend((ny as u32).to_le_bytes());
    b.extend((nx as u32).to_le_bytes());
    b.extend((nx as u32).to_le_bytes());
    for f in [1.0f32, 1.5, 2.5, 0.0, 0.0, 1.5, 0.0] {
        b.extend(f.to_le_bytes());
    }
    for u in [3u32, 1, 0, 14, 3] {
        b.extend(u.to_le_bytes());
    }
    b.extend([0u8; 40]);
    b.extend([0u8, 1, 251, 6, 1, 0, 0, 0]);
    b.extend(1u32.to_le_bytes());
    assert_eq!(b.len(), 500);
    b.extend((ny as u32).to_le_bytes());
    b.extend((nx as u32).to_le_bytes());
    for k in 0..nx * ny {
        let v = if is_hole(k) { 1_000_001.0f32 } else { stored(k / nx, k % nx) as f32 / 4.0 };
        b.extend(v.to_le_bytes());
    }
    b.extend((-1.0f32).to_le_bytes());
    b.extend(1.0f32.to_le_bytes());
    b
}

/// Digital Surf SUR: 32-bit points, spacing 2 µm x 3 µm (unit µm), z spacing 0.5 nm (unit nm),
/// z offset 10 nm, non-measured flag set with value min - 2 at the holes.
pub fn sur(compressed: bool) -> Vec<u8> {
    sur_grid(NX, NY, compressed)
}

/// The same file for an `nx` x `ny` grid.
pub fn sur_grid(nx: usize, ny: usize, compressed: bool) -> Vec<u8> {
    let mut h = vec![0u8; 512];
    h[..12].copy_from_slice(if compressed { b"DSCOMPRESSED" } else { b"DIGITAL SURF" });
    let put = |h: &mut Vec<u8>, off: usize, v: &[u8]| h[off..off + v.len()].copy_from_slice(v);
    put(&mut h, 14, &1u16.to_le_bytes());
    put(&mut h, 16, &1u16.to_le_bytes());
    put(&mut h, 18, &2u16.to_le_bytes());
    put(&mut h, 20, b"generated");
    put(&mut h, 86, &1u16.to_le_bytes());
    put(&mut h, 98, &32u16.to_le_bytes());
    let zmin = -1000i32;
    put(&mut h, 100, &zmin.to_le_bytes());
    put(&mut h, 104, &1000i32.to_le_bytes());
    put(&mut h, 108, &(nx as i32).to_le_bytes());
    put(&mut h, 112, &(ny as i32).to_le_bytes());
    put(&mut h, 116, &((nx * ny) as u32).to_le_bytes());
    put(&mut h, 120, &2.0f32.to_le_bytes());
    put(&mut h, 124, &3.0f32.to_le_bytes());
    put(&mut h, 128, &0.5f32.to_le_bytes());
    for (k, name) in ["X", "Y", "Z"].iter().enumerate() {
        put(&mut h, 132 + 16 * k, name.as_bytes());
    }
    for (k, unit) in ["\u{b5}m", "\u{b5}m", "nm", "\u{b5}m", "\u{b5}m", "nm"].iter().enumerate() {
        // Latin-1 micro sign, as Digital Surf writes it.
        let bytes: Vec<u8> = unit.chars().map(|c| c as u32 as u8).collect();
        put(&mut h, 180 + 16 * k, &bytes);
    }
    for k in 0..3 {
        put(&mut h, 276 + 4 * k, &1.0f32.to_le_bytes());
    }
    put(&mut h, 316, &2024u16.to_le_bytes());
    put(&mut h, 474, &10.0f32.to_le_bytes());
    let mut data = Vec::new();
    for k in 0..nx * ny {
        let v = if is_hole(k) { zmin - 2 } else { stored(k / nx, k % nx) };
        data.extend(v.to_le_bytes());
    }
    if compressed {
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&data).expect("zlib");
        let z = enc.finish().expect("zlib");
        let mut block = 1u32.to_le_bytes().to_vec();
        block.extend((data.len() as u32).to_le_bytes());
        block.extend((z.len() as u32).to_le_bytes());
        block.extend(&z);
        h[324..328].copy_from_slice(&(block.len() as u32).to_le_bytes());
        h.extend(block);
    } else {
        h.extend(data);
    }
    h
}

fn opd_entry(name: &str, t: i16, len: i32) -> Vec<u8> {
    let mut e = pad(name, 16);
    e.extend(t.to_le_bytes());
    e.extend(len.to_le_bytes());
    e.extend(0u16.to_le_bytes());
    e
}

/// Wyko OPD with float32 values (wavelength 600 nm, mult 2, pixel 0.002 mm, aspect 1.5).
/// Heights (m) = stored * 600e-9 / 2; values are stored column by column from the top row.
pub fn opd(int16: bool) -> Vec<u8> {
    opd_grid(NX, NY, int16)
}

/// The same file for an `nx` x `ny` grid.
pub fn opd_grid(nx: usize, ny: usize, int16: bool) -> Vec<u8> {
    let el = if int16 { 2 } else { 4 };
    let raw_len = 6 + nx * ny * el;
    let entries = [
        ("Directory", 1i16, 24 * 6),
        ("RAW_DATA", 3, raw_len as i32),
        ("Wavelength", 7, 4),
        ("Mult", 6, 2),
        ("Pixel_size", 7, 4),
        ("Aspect", 7, 4),
    ];
    let mut b = vec![1u8, 0];
    for (n, t, l) in entries {
        b.extend(opd_entry(n, t, l));
    }
    b.extend((nx as u16).to_le_bytes());
    b.extend((ny as u16).to_le_bytes());
    b.extend((el as u16).to_le_bytes());
    for j in 0..nx {
        for r in 0..ny {
            let i = ny - 1 - r;
            let k = i * nx + j;
            if int16 {
                let v = if is_hole(k) { i16::MAX } else { stored(i, j) as i16 };
                b.extend(v.to_le_bytes());
            } else {
                let v = if is_hole(k) { 1.7014118e38f32 } else { stored(i, j) as f32 };
                b.extend(v.to_le_bytes());
            }
        }
    }
    b.extend(600.0f32.to_le_bytes());
    b.extend(2u16.to_le_bytes());
    b.extend(0.002f32.to_le_bytes());
    b.extend(1.5f32.to_le_bytes());
    b
}

/// MetroPro DAT, header format 1: scale 0.5, wavelength 632.8 nm, obliquity 1, phase_res 1
/// (R = 32768), lateral 1e-6 m; heights = stored * 0.5 * 632.8e-9 / 32768 (f32 constants).
pub fn metropro() -> Vec<u8> {
    metropro_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn metropro_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut h = vec![0u8; 834];
    let put = |h: &mut Vec<u8>, off: usize, v: &[u8]| h[off..off + v.len()].copy_from_slice(v);
    put(&mut h, 0, &0x881B036Fu32.to_be_bytes());
    put(&mut h, 4, &1u16.to_be_bytes());
    put(&mut h, 6, &834u32.to_be_bytes());
    put(&mut h, 68, &(nx as u16).to_be_bytes());
    put(&mut h, 70, &(ny as u16).to_be_bytes());
    put(&mut h, 72, &((nx * ny * 4) as u32).to_be_bytes());
    put(&mut h, 164, &0.5f32.to_be_bytes());
    put(&mut h, 168, &632.8e-9f32.to_be_bytes());
    put(&mut h, 176, &1.0f32.to_be_bytes());
    put(&mut h, 184, &1e-6f32.to_be_bytes());
    put(&mut h, 218, &1i16.to_be_bytes());
    put(&mut h, 246, b"20X Mirau");
    for k in 0..nx * ny {
        let v = if is_hole(k) { i32::MAX } else { stored(k / nx, k % nx) };
        h.extend(v.to_be_bytes());
    }
    h
}

fn al3d_tag(k: &str, v: &str) -> Vec<u8> {
    let mut t = pad(k, 20);
    t.extend(pad(v, 30));
    t.extend(b"\r\n");
    t
}

/// Alicona AL3D: float32 metres = stored * 1e-6, pixel 0.5 µm x 0.75 µm, invalid 3e15.
pub fn al3d() -> Vec<u8> {
    al3d_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn al3d_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut b = b"AliconaImaging\x00\r\n".to_vec();
    b.extend(al3d_tag("Version", "1"));
    b.extend(al3d_tag("TagCount", "6"));
    let offset = 17 + 8 * 52;
    for (k, v) in [
        ("Cols", nx.to_string()),
        ("Rows", ny.to_string()),
        ("PixelSizeXMeter", "5e-07".to_string()),
        ("PixelSizeYMeter", "7.5e-07".to_string()),
        ("DepthImageOffset", offset.to_string()),
        ("InvalidPixelValue", "3.000000028082e+15".to_string()),
    ] {
        b.extend(al3d_tag(k, &v));
    }
    assert_eq!(b.len(), offset);
    for k in 0..nx * ny {
        // The file's hole marker written digit for digit as the format's producers write it.
        #[allow(clippy::excessive_precision)]
        let v = if is_hole(k) { 3.000000028082e15f32 } else { stored(k / nx, k % nx) as f32 * 1e-6 };
        b.extend(v.to_le_bytes());
    }
    b
}

/// TrueMap TMD: field 14 mm x 10 mm, heights in mm = stored / 1000 (f32).
pub fn tmd() -> Vec<u8> {
    tmd_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn tmd_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut b = pad("Binary TrueMap Data File v2.0\r\n", 32);
    b.extend(b"Created by TrueMap v6\r\n\0");
    b.extend((nx as u32).to_le_bytes());
    b.extend((ny as u32).to_le_bytes());
    for f in [14.0f32, 10.0, 0.0, 0.0] {
        b.extend(f.to_le_bytes());
    }
    for k in 0..nx * ny {
        let v = if is_hole(k) { f32::NAN } else { stored(k / nx, k % nx) as f32 / 1000.0 };
        b.extend(v.to_le_bytes());
    }
    b
}

/// Gwyddion Simple Field in µm laterally and nm vertically.
pub fn gsf() -> Vec<u8> {
    gsf_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn gsf_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut b = format!(
        "Gwyddion Simple Field 1.0\nXRes = {nx}\nYRes = {ny}\nXReal = 14\nYReal = 15\nXYUnits = um\nZUnits = nm\nTitle = generated\n"
    )
    .into_bytes();
    let padn = 4 - b.len() % 4;
    b.extend(std::iter::repeat_n(0u8, padn));
    for k in 0..nx * ny {
        let v = if is_hole(k) { f32::NAN } else { stored(k / nx, k % nx) as f32 };
        b.extend(v.to_le_bytes());
    }
    b
}

/// The NumPy v1 file header (magic, version, length, dict padded to 64 bytes) for an array of `descr`.
pub fn npy_header(descr: &str, fortran: bool, ny: usize, nx: usize) -> Vec<u8> {
    let order = if fortran { "True" } else { "False" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': ({ny}, {nx}), }}").into_bytes();
    let total = 10 + header.len() + 1;
    header.extend(std::iter::repeat_n(b' ', (64 - total % 64) % 64));
    header.push(b'\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header);
    b
}

/// NumPy v1 `<f8` array (rows, columns), C order.
pub fn npy() -> Vec<u8> {
    let mut b = npy_header("<f8", false, NY, NX);
    for k in 0..NX * NY {
        let v = if is_hole(k) { f64::NAN } else { stored(k / NX, k % NX) as f64 };
        b.extend(v.to_le_bytes());
    }
    b
}

/// 16-bit grey PNG of stored + 1000 (holes carry alpha 0).
pub fn png16() -> Vec<u8> {
    png16_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn png16_grid(nx: usize, ny: usize) -> Vec<u8> {
    let mut px = Vec::new();
    for k in 0..nx * ny {
        px.push((stored(k / nx, k % nx) + 1000) as u16);
        px.push(if is_hole(k) { 0 } else { u16::MAX });
    }
    let img = image::ImageBuffer::<image::LumaA<u16>, Vec<u16>>::from_raw(nx as u32, ny as u32, px).expect("buffer");
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).expect("png");
    out.into_inner()
}

/// 16-bit grey TIFF of stored + 1000 (no holes: TIFF grey has no alpha here).
pub fn tiff16() -> Vec<u8> {
    tiff16_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn tiff16_grid(nx: usize, ny: usize) -> Vec<u8> {
    let px: Vec<u16> = (0..nx * ny).map(|k| (stored(k / nx, k % nx) + 1000) as u16).collect();
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(nx as u32, ny as u32, px).expect("buffer");
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Tiff).expect("tiff");
    out.into_inner()
}

/// OpenEXR with one float channel `Z` of stored values (holes NaN).
pub fn exr() -> Vec<u8> {
    exr_grid(NX, NY)
}

/// The same file for an `nx` x `ny` grid.
pub fn exr_grid(nx: usize, ny: usize) -> Vec<u8> {
    use exr::prelude::*;
    let vals: Vec<f32> = (0..nx * ny).map(|k| if is_hole(k) { f32::NAN } else { stored(k / nx, k % nx) as f32 }).collect();
    let ch = AnyChannel::new("Z", FlatSamples::F32(vals));
    let layer = Layer::new((nx, ny), LayerAttributes::named("height"), Encoding::FAST_LOSSLESS, AnyChannels::sort(vec![ch].into()));
    let img = Image::from_layer(layer);
    let mut out = std::io::Cursor::new(Vec::new());
    img.write().to_buffered(&mut out).expect("exr");
    out.into_inner()
}

/// Text matrix, optionally with the `AsciiMatrix cols rows du dv` header (du = 2, dv = 3).
pub fn ascii(header: bool, sep: &str) -> Vec<u8> {
    let mut s = String::new();
    if header {
        s.push_str(&format!("AsciiMatrix {NX} {NY} 2 3\n"));
    }
    for i in 0..NY {
        let row: Vec<String> = (0..NX).map(|j| if is_hole(i * NX + j) { "nan".to_string() } else { stored(i, j).to_string() }).collect();
        s.push_str(&row.join(sep));
        s.push('\n');
    }
    s.into_bytes()
}

/// XYZ list on a grid with step 0.5 x 0.25 (file units), origin (10, -2), one node left out.
pub fn xyz(csv_header: bool) -> Vec<u8> {
    let mut s = String::new();
    if csv_header {
        s.push_str("x,y,z\n");
    }
    let sep = if csv_header { "," } else { " " };
    for i in 0..NY {
        for j in 0..NX {
            let k = i * NX + j;
            if k == HOLES[0] {
                continue; // a missing node
            }
            let z = if k == HOLES[1] { "NaN".to_string() } else { stored(i, j).to_string() };
            s.push_str(&format!("{}{sep}{}{sep}{z}\n", 10.0 + 0.5 * j as f64, -2.0 + 0.25 * i as f64));
        }
    }
    s.into_bytes()
}

/// X3P written by the library itself from a heightfield of the stored values.
pub fn x3p() -> Vec<u8> {
    let z: Vec<f64> = (0..NX * NY).map(|k| if is_hole(k) { f64::NAN } else { stored(k / NX, k % NX) as f64 * 1e-9 }).collect();
    let hf = ndfit::Heightfield::new(NX, NY, 1e-6, 2e-6, z).expect("grid");
    ndfit::io::x3p_bytes(&hf).expect("x3p")
}

/// X3P layouts other writers produce (instruments deflate the point data; float32 and int16 types), so
/// the fuzzer starts from the inflate and conversion paths as well as ndfit's own stored float64.
pub fn x3p_layouts() -> Vec<(&'static str, Vec<u8>)> {
    use super::x3p_deflated::{values, x3p};
    let make = |ztype: &str, cz: &str, deflated: bool| {
        let data = values(ztype, NX, NY);
        x3p(ztype, cz, NX, NY, &data, &crate::common::md5_hex(&data), deflated)
    };
    vec![
        ("deflated_f64.x3p", make("D", "", true)),
        ("deflated_f32.x3p", make("F", "", true)),
        ("deflated_i16.x3p", make("I", "<Increment>1e-8</Increment>", true)),
        ("stored_f32.x3p", make("F", "", false)),
    ]
}

/// Every generated binary file with its file name.
pub fn binary_files() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("gen.plu", plu()),
        ("gen.sur", sur(false)),
        ("gen_compressed.sur", sur(true)),
        ("gen.opd", opd(false)),
        ("gen_int16.opd", opd(true)),
        ("gen.dat", metropro()),
        ("gen.al3d", al3d()),
        ("gen.tmd", tmd()),
        ("gen.gsf", gsf()),
        ("gen.npy", npy()),
        ("gen.png", png16()),
        ("gen.tif", tiff16()),
        ("gen.exr", exr()),
        ("gen.x3p", x3p()),
    ]
}

/// Small RGL tensor files written by the library's own writer: an isotropic and a rotated anisotropic
/// GGX in RGB, and the anisotropic one as a gold spectral table.
pub fn rgl_files() -> Vec<(&'static str, Vec<u8>)> {
    use ndfit::export::rgl::{tabulate, Flavour, Material, RglOptions};
    use ndfit::models::{Model, ModelId, Ndf};
    let small = |material, flavour| RglOptions { theta_i: 3, phi_i: 3, ndf_res: Some(8), warp_res: 4, material, flavour };
    let iso = Model::from_params(ModelId::Ggx, &[0.2]).expect("ggx");
    let aniso = Model::from_params(ModelId::GgxAniso, &[0.3, 0.1, -1.043]).expect("ggx-aniso");
    let table = |m: &Model, opts| tabulate(&|w| m.d(w), "fuzz seed", &opts, false).expect("table").tensor.to_bytes();
    vec![
        ("iso.bsdf", table(&iso, small(Material::None, Flavour::Rgb))),
        ("aniso.bsdf", table(&aniso, small(Material::Cu, Flavour::Rgb))),
        ("spectral.bsdf", table(&aniso, small(Material::Au, Flavour::Spectral))),
    ]
}

/// Inputs of the `x3p_write` target (byte 0: columns - 1 mod 16, bytes 1..9: the spacing as f64, then
/// heights as f64, all little-endian): a plain grid, one with NaN, infinities and a subnormal, and one
/// with a spacing the writer refuses.
pub fn x3p_write_inputs() -> Vec<(&'static str, Vec<u8>)> {
    let input = |nx: u8, dx: f64, z: &[f64]| {
        let mut b = vec![nx - 1, 0, 0, 0, 0, 0, 0, 0, 0];
        b[1..9].copy_from_slice(&dx.to_le_bytes());
        z.iter().for_each(|v| b.extend(v.to_le_bytes()));
        b
    };
    let grid: Vec<f64> = (0..NX * NY).map(|k| stored(k / NX, k % NX) as f64 * 1e-9).collect();
    let mut odd = grid.clone();
    odd[HOLES[0]] = f64::NAN;
    odd[HOLES[1]] = f64::INFINITY;
    odd[1] = f64::NEG_INFINITY;
    odd[2] = 5e-324;
    vec![
        ("grid.bin", input(NX as u8, 1e-6, &grid)),
        ("nonfinite.bin", input(NX as u8, 2.5e-7, &odd)),
        ("bad_spacing.bin", input(3, -1.0, &grid[..12])),
    ]
}

/// Batch manifests: every fixed column, option columns (a value, a bare flag, an empty cell), a comment,
/// quoting, and an id that would escape the output folder.
pub fn manifests() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("plain.csv", b"path\na.x3p\nsub/b.sur\n".to_vec()),
        (
            "columns.csv",
            b"# scans of the rough set\npath,id,model,options,dx,z_scale,quiet\na.x3p,first,ggx,--max-theta 60,1.5e-6,,true\n\"b c.plu\",second,,,,1e-3,false\n".to_vec(),
        ),
        ("escape.csv", b"path,id\nx.npy,../../outside\ny.npy,/abs/name\nz.npy,a/./b\n".to_vec()),
    ]
}

/// Write the seed corpora of the cargo-fuzz targets (one directory per target) under `root`.
pub fn write_seed_corpus(root: &std::path::Path) {
    let readers = binary_files().into_iter().map(|(name, bytes)| {
        let target = match name.rsplit('.').next().expect("extension") {
            "dat" => "metropro",
            "tif" => "tiff",
            other => other,
        };
        (target, name, bytes)
    });
    let others = [("x3p", x3p_layouts()), ("rgl", rgl_files()), ("x3p_write", x3p_write_inputs()), ("manifest", manifests())]
        .into_iter()
        .flat_map(|(target, files)| files.into_iter().map(move |(name, bytes)| (target, name, bytes)));
    for (target, name, bytes) in readers.chain(others) {
        let dir = root.join(target);
        std::fs::create_dir_all(&dir).expect("corpus dir");
        std::fs::write(dir.join(name), bytes).expect("seed");
    }
}

/// `cargo test --test all write_fuzz_seed_corpus -- --ignored` writes fuzz/corpus/<target>/.
#[test]
#[ignore = "writes the cargo-fuzz seed corpus into fuzz/corpus; run on demand"]
fn write_fuzz_seed_corpus() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    write_seed_corpus(&root);
}
