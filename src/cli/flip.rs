//! `ndfit flip REFERENCE TEST [--ldr] [--ppd X] [--start-exposure E --stop-exposure E] [--png MAP.png]
//! [--json]`: the FLIP difference of two renders (`ndfit::flip`; data_formats/flip.md), HDR-FLIP unless
//! `--ldr`. Images are `.exr` (R, G, B, optional A; any sample type) or `.npy` (H x W x 3 or 4, float32 or
//! float64, little-endian, C order), linear RGB.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::bail;
use ndfit::flip::{self, HdrOptions, RgbImage};
use ndfit::{Error, ErrorKind};
use serde_json::json;

/// Arguments of `ndfit flip`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The reference image (`.exr` or `.npy`, linear RGB).
    pub reference: PathBuf,
    /// The test image, the same size as the reference.
    pub test: PathBuf,
    /// LDR-FLIP (values clamped to [0, 1]) instead of HDR-FLIP.
    #[arg(long)]
    pub ldr: bool,
    /// Pixels per degree of visual angle [default: 67.02, FLIP's 0.7 m from a 0.7 m wide 3840-pixel monitor].
    #[arg(long)]
    pub ppd: Option<f64>,
    /// HDR-FLIP's first exposure in stops [default: from the reference's largest luminance].
    #[arg(long, allow_hyphen_values = true)]
    pub start_exposure: Option<f64>,
    /// HDR-FLIP's last exposure in stops [default: from the reference's median luminance].
    #[arg(long, allow_hyphen_values = true)]
    pub stop_exposure: Option<f64>,
    /// HDR-FLIP's number of exposures [default: max(2, ceil(stop - start))].
    #[arg(long)]
    pub num_exposures: Option<usize>,
    /// Write the error map in FLIP's magma colour map as an 8-bit PNG (atomically).
    #[arg(long, value_name = "MAP.png")]
    pub png: Option<PathBuf>,
    /// Write the error map as a numpy `.npy` array, H x W float32 (atomically).
    #[arg(long, value_name = "MAP.npy")]
    pub npy: Option<PathBuf>,
    /// Print one JSON object (mean, mode, ppd, exposures, size) instead of the mean alone.
    #[arg(long)]
    pub json: bool,
}

/// Run `ndfit flip`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if args.ldr && (args.start_exposure.is_some() || args.stop_exposure.is_some() || args.num_exposures.is_some()) {
        bail!("--start-exposure, --stop-exposure and --num-exposures are HDR-FLIP options: drop them or --ldr");
    }
    let ppd = args.ppd.unwrap_or(flip::DEFAULT_PPD);
    if !(ppd.is_finite() && ppd > 0.0 && ppd <= 1e4) {
        bail!("--ppd must be in (0, 10000], got {ppd}");
    }
    ndfit::io::protect_input(&args.reference);
    ndfit::io::protect_input(&args.test);
    for out in args.png.iter().chain(&args.npy) {
        ndfit::io::check_output(out)?;
    }
    let reference = read_image(&args.reference)?;
    let test = read_image(&args.test)?;
    if (reference.width(), reference.height()) != (test.width(), test.height()) {
        let msg = format!(
            "is {} x {} pixels, the reference {} x {} pixels: FLIP compares images of one size",
            test.width(),
            test.height(),
            reference.width(),
            reference.height()
        );
        return Err(Error::invalid(msg).with_path(&args.test).into());
    }
    // The evaluation holds about 130 bytes a pixel (inputs, two colour-space copies, the filter pass, maps).
    let pixels = (reference.width() as u64).saturating_mul(reference.height() as u64);
    ndfit::budget::check_bytes(pixels.saturating_mul(130), "FLIP of these images")?;
    let map = if args.ldr {
        flip::ldr(&reference, &test, ppd)?
    } else {
        let opts = HdrOptions { start_exposure: args.start_exposure, stop_exposure: args.stop_exposure, num_exposures: args.num_exposures };
        // The automatic exposures come from the reference: its errors name it.
        flip::hdr(&reference, &test, ppd, &opts).map_err(|e| match e.kind() {
            ErrorKind::BadData => e.with_path(&args.reference),
            _ => e,
        })?
    };
    if let Some(png) = &args.png {
        write_png(png, map.width(), map.height(), &map.magma_rgb8())?;
    }
    if let Some(npy) = &args.npy {
        ndfit::io::write_bytes_atomic(npy, &npy_bytes(map.width(), map.height(), map.values()))?;
    }
    let mean = map.mean();
    let text = if args.json {
        let e = map.exposures();
        let v = json!({
            "mean": mean,
            "mode": map.mode().as_str(),
            "ppd": map.ppd(),
            "start_exposure": e.map(|e| e.start),
            "stop_exposure": e.map(|e| e.stop),
            "num_exposures": e.map(|e| e.count),
            "width": map.width(),
            "height": map.height(),
            "reference": args.reference.display().to_string(),
            "test": args.test.display().to_string(),
        });
        serde_json::to_string_pretty(&v)? + "\n"
    } else {
        format!("{mean}\n")
    };
    super::write_stdout(text.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}

/// The error map as an RGB8 PNG, written atomically.
fn write_png(path: &Path, w: usize, h: usize, rgb: &[u8]) -> anyhow::Result<()> {
    use image::ImageEncoder as _;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(rgb, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::new(ErrorKind::Io, format!("cannot encode the PNG ({e})")).with_path(path))?;
    ndfit::io::write_bytes_atomic(path, &bytes)?;
    Ok(())
}

/// A float32 H x W array in numpy's `.npy` format 1.0 (the header padded so the data start on 64 bytes).
fn npy_bytes(w: usize, h: usize, values: &[f32]) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({h}, {w}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * values.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    out
}

/// Read a linear RGB image by its extension: `.exr` or `.npy`.
fn read_image(path: &Path) -> anyhow::Result<RgbImage> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let bytes = std::fs::read(path).map_err(|e| Error::io(e).with_path(path))?;
    let img = match ext.as_deref() {
        Some("npy") => read_npy(&bytes),
        Some("exr") => read_exr(&bytes),
        _ => Err(Error::new(ErrorKind::UnknownFormat, "not an image FLIP reads: give a .exr or .npy file (linear RGB)")),
    };
    Ok(img.map_err(|e| e.with_path(path))?)
}

/// An OpenEXR image's first layer with R, G and B channels (A, if any, is ignored), any sample type.
fn read_exr(bytes: &[u8]) -> ndfit::Result<RgbImage> {
    use exr::prelude::{read, ReadChannels as _, ReadLayers as _};
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| Error::corrupt(format!("not a readable OpenEXR file ({e})")))?;
    let header = meta.headers.first().ok_or_else(|| Error::corrupt("OpenEXR file has no layer"))?;
    let (w, h) = (header.layer_size.0, header.layer_size.1);
    // Three f32 a pixel here, and no lossless codec expands beyond 1032:1.
    if (w as u64).saturating_mul(h as u64).saturating_mul(2) > (bytes.len() as u64).saturating_mul(1032) {
        return Err(Error::corrupt(format!("OpenEXR header claims {w} x {h} pixels, more than the file can hold")));
    }
    ndfit::budget::check_bytes((w as u64).saturating_mul(h as u64).saturating_mul(12), "OpenEXR image")?;
    // A panic inside the third-party decoder on hostile bytes is reported as a corrupt file.
    let img = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |size, _| (size.width(), vec![[0f32; 3]; size.area()]),
                |(w, px): &mut (usize, Vec<[f32; 3]>), at, (r, g, b, _a): (f32, f32, f32, f32)| px[at.y() * *w + at.x()] = [r, g, b],
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
    }))
    .map_err(|_| Error::corrupt("OpenEXR decoder failed on this file"))?
    .map_err(|e| match e {
        exr::error::Error::Invalid(m) if m.contains("channel") => {
            Error::new(ErrorKind::Unsupported, format!("OpenEXR image without R, G and B channels ({m})"))
        }
        e => Error::corrupt(format!("OpenEXR decode failed ({e})")),
    })?;
    let layer = img.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let (_, px) = layer.channel_data.pixels;
    RgbImage::new(w, h, px)
}

/// A numpy `.npy` array (format 1.0, 2.0 or 3.0) of shape (H, W, 3) or (H, W, 4) (alpha ignored), dtype
/// `<f4` or `<f8`, C order.
fn read_npy(bytes: &[u8]) -> ndfit::Result<RgbImage> {
    let bad = |m: String| Error::new(ErrorKind::Corrupt, m);
    if !bytes.starts_with(b"\x93NUMPY") || bytes.len() < 10 {
        return Err(Error::new(ErrorKind::UnknownFormat, "not a numpy .npy file (no \\x93NUMPY magic)"));
    }
    let (header_len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(Error::new(ErrorKind::Unsupported, format!(".npy format version {v}.{} is not read", bytes[7]))),
    };
    let header = bytes.get(start..start.saturating_add(header_len)).ok_or_else(|| bad(".npy header is truncated".into()))?;
    let header = std::str::from_utf8(header).map_err(|_| bad(".npy header is not text".into()))?;
    let field = |key: &str| -> ndfit::Result<&str> {
        let at = header.find(&format!("'{key}'")).ok_or_else(|| bad(format!(".npy header has no '{key}'")))?;
        let rest = header[at + key.len() + 2..].trim_start();
        Ok(rest.strip_prefix(':').ok_or_else(|| bad(format!(".npy header: no ':' after '{key}'")))?.trim_start())
    };
    let descr = field("descr")?;
    let descr = descr.get(1..).and_then(|d| d.split(['\'', '"']).next()).unwrap_or("");
    let size = match descr {
        "<f4" => 4,
        "<f8" => 8,
        d => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!(".npy dtype {d:?}: FLIP reads little-endian float32 or float64 (<f4, <f8)"),
            ))
        }
    };
    if field("fortran_order")?.starts_with("True") {
        return Err(Error::new(ErrorKind::Unsupported, ".npy array is in Fortran order: save it with np.ascontiguousarray"));
    }
    let shape = field("shape")?;
    let shape = shape.strip_prefix('(').and_then(|s| s.split(')').next()).ok_or_else(|| bad(".npy header: shape is not a tuple".into()))?;
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad(format!(".npy header: shape ({shape}) is not a tuple of integers")))?;
    let [h, w, c] = dims[..] else {
        return Err(Error::new(ErrorKind::Unsupported, format!(".npy array of shape ({shape}): FLIP reads H x W x 3 (or 4) images")));
    };
    if c != 3 && c != 4 {
        return Err(Error::new(ErrorKind::Unsupported, format!(".npy array has {c} channels: FLIP reads 3 (RGB) or 4 (RGBA)")));
    }
    let data = &bytes[start + header_len..];
    let need = h.checked_mul(w).and_then(|n| n.checked_mul(c)).and_then(|n| n.checked_mul(size));
    if need != Some(data.len()) {
        return Err(bad(format!(
            ".npy data is {} bytes, the header's {h} x {w} x {c} {descr} needs {}",
            data.len(),
            need.map_or("more".into(), |n| n.to_string())
        )));
    }
    let px = data
        .chunks_exact(c * size)
        .map(|p| {
            let v = |i: usize| match size {
                4 => f32::from_le_bytes(p[4 * i..4 * i + 4].try_into().unwrap_or_default()),
                _ => f64::from_le_bytes(p[8 * i..8 * i + 8].try_into().unwrap_or_default()) as f32,
            };
            [v(0), v(1), v(2)]
        })
        .collect();
    RgbImage::new(w, h, px)
}
