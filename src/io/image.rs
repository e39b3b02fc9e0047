//! Image containers holding heights: OpenEXR (one float channel) and 16-bit grayscale PNG/TIFF.
//!
//! None carries a length unit: heights need `--z-scale` (metres per stored unit, for 16-bit images
//! metres per grey level) and spacing `--dx`/`--dy`. Row 0 is the image's top row. EXR: the channel
//! named `Z`, else `Y`, else `R`, else the only channel; NaN/infinite samples are invalid. PNG/TIFF:
//! 16-bit grey (`L16`), or grey plus alpha (`LA16`) where alpha 0 marks an invalid point; 8-bit and
//! colour images are refused (too few levels / not a height). Sizes from headers are checked against
//! what the compressed bytes can hold before any pixel is decoded.

use crate::error::{Error, ErrorKind, Result};
use crate::io::raw_opts::{spacing, z_scale};
use crate::io::ReadOptions;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `exr` format ([`crate::io::Reader`]).
pub const EXR_READER: crate::io::Reader =
    crate::io::Reader { id: "exr", extensions: &["exr"], magic: Some(|h| h.starts_with(&[0x76, 0x2f, 0x31, 0x01])), read: read_exr };
/// The registry entry of the `png` format ([`crate::io::Reader`]).
pub const PNG_READER: crate::io::Reader =
    crate::io::Reader { id: "png", extensions: &["png"], magic: Some(|h| h.starts_with(b"\x89PNG\r\n\x1a\n")), read: read_png16 };
/// The registry entry of the `tiff` format ([`crate::io::Reader`]).
pub const TIFF_READER: crate::io::Reader = crate::io::Reader {
    id: "tiff",
    extensions: &["tif", "tiff"],
    magic: Some(|h| h.starts_with(b"II*\0") || h.starts_with(b"MM\0*")),
    read: |b, o| read_image16(b, o, image::ImageFormat::Tiff, "TIFF"),
};

/// No lossless codec here expands more than deflate's 1032:1; more pixels than that is a lie.
const MAX_RATIO: u64 = 1032;

/// Read an OpenEXR file held in memory.
pub fn read_exr(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    use exr::prelude::{read, ReadChannels as _, ReadLayers as _, ReadSpecificChannel as _, Sample};
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| Error::corrupt(format!("not a readable OpenEXR file ({e})")))?;
    let header = meta.headers.first().ok_or_else(|| Error::corrupt("OpenEXR file has no layer"))?;
    let (w, h) = (header.layer_size.0 as u64, header.layer_size.1 as u64);
    let channels = header.channels.list.len() as u64;
    let samples = w.saturating_mul(h).saturating_mul(channels.max(1));
    if samples.saturating_mul(2) > (bytes.len() as u64).saturating_mul(MAX_RATIO) {
        return Err(Error::corrupt(format!("OpenEXR header claims {w} x {h} pixels, more than the file can hold")));
    }
    crate::budget::check_points(w as usize, h as usize, "OpenEXR header")?;
    let (dx, dy) = spacing(opts, "OpenEXR")?;
    let zs = z_scale(opts, "OpenEXR")?;
    // The channel read: `Z`, else `Y`, else `R`, else the only one.
    let names: Vec<String> = header.channels.list.iter().map(|c| c.name.to_string()).collect();
    let pick = ["Z", "Y", "R"]
        .iter()
        .find(|n| names.iter().any(|c| c == *n))
        .map(|n| n.to_string())
        .or(if names.len() == 1 { names.first().cloned() } else { None })
        .ok_or_else(|| {
            Error::new(ErrorKind::Unsupported, format!("OpenEXR channels {names:?}: none is Z, Y or R and there is more than one"))
        })?;
    // Each decoded block's samples go straight into the heights (zeroed pages, resident as written), and
    // the file's pages are given back behind the reader: one copy of the heights. A third-party decoder
    // must not take the process down on hostile bytes: a panic inside it is reported as a corrupt file.
    let img = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .specific_channels()
            .required(pick.as_str())
            .collect_pixels(
                |size, _| (size.width(), crate::scan::heights::zeroed(size.area())),
                move |(w, z): &mut (usize, Vec<f64>), at, (s,): (Sample,)| {
                    let v = match s {
                        Sample::F16(v) => v.to_f32() as f64,
                        Sample::F32(v) => v as f64,
                        Sample::U32(v) => v as f64,
                    };
                    z[at.y() * *w + at.x()] = v * zs;
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(crate::io::mapped::ReleasingCursor::new(bytes))
    }))
    .map_err(|_| Error::corrupt("OpenEXR decoder failed on this file"))?
    .map_err(|e| Error::corrupt(format!("OpenEXR decode failed ({e})")))?;
    let layer = img.layer_data;
    let (nx, ny) = (layer.size.0, layer.size.1);
    let (_, z) = layer.channel_data.pixels;
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: "exr".into(), ..Default::default() };
    hf.meta.instrument.insert("exr.channel".into(), pick);
    Ok(hf)
}

/// A 16-bit grey PNG decoded row by row into the heights (the file's pages given back behind the decoder,
/// `io::mapped`): one copy of the heights, where decoding the whole image first holds its pixels
/// and the heights together. Interlaced images and grey with a transparent level (`tRNS`) go through
/// [`read_image16`], whose expansion they need.
pub fn read_png16(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    let bad = |e: png::DecodingError| Error::corrupt(format!("PNG decode failed ({e})"));
    let max_alloc = (bytes.len() as u64).saturating_mul(MAX_RATIO).clamp(1 << 20, 1 << 34).min(crate::budget::max_memory());
    let limits = png::Limits { bytes: usize::try_from(max_alloc).unwrap_or(usize::MAX) };
    let mut decoder = png::Decoder::new_with_limits(crate::io::mapped::ReleasingCursor::new(bytes), limits);
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(|e| Error::corrupt(format!("PNG header is not readable ({e})")))?;
    let info = reader.info();
    let (nx, ny) = (info.width as usize, info.height as usize);
    if info.interlaced || info.trns.is_some() {
        return read_image16(bytes, opts, image::ImageFormat::Png, "PNG");
    }
    let channels = match (info.color_type, info.bit_depth) {
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => 1,
        (png::ColorType::GrayscaleAlpha, png::BitDepth::Sixteen) => 2,
        (png::ColorType::Grayscale | png::ColorType::GrayscaleAlpha, depth) => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("PNG is {}-bit: {} grey levels are too few for heights; use a 16-bit grey image", depth as u8, 1u32 << depth as u8),
            ))
        }
        (colour, depth) => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("PNG holds {colour:?} {}-bit colour pixels: heights need a 16-bit grey image", depth as u8),
            ))
        }
    };
    crate::budget::check_points(nx, ny, "PNG header")?;
    let (dx, dy) = spacing(opts, "PNG")?;
    let zs = z_scale(opts, "PNG")?;
    let mut z = crate::scan::heights::with_capacity(nx * ny);
    // Big-endian samples; with alpha, alpha 0 marks an invalid point.
    while let Some(row) = reader.next_row().map_err(bad)? {
        z.extend(row.data().chunks_exact(2 * channels).map(|p| match channels == 2 && p[2] == 0 && p[3] == 0 {
            true => f64::NAN,
            false => u16::from_be_bytes([p[0], p[1]]) as f64 * zs,
        }));
    }
    if z.len() != nx * ny {
        return Err(Error::corrupt(format!("PNG holds {} of its {nx} x {ny} pixels", z.len())));
    }
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: "png".into(), ..Default::default() };
    Ok(hf)
}

/// A plain 16-bit grey TIFF decoded strip by strip into the heights, each strip's file pages given back
/// once decoded (`io::mapped`): one copy of the heights. `strips` are the file's strip ranges, checked.
fn read_tiff16_strips(bytes: &[u8], opts: &ReadOptions, strips: &[(usize, usize)]) -> Result<Heightfield> {
    let bad = |e: tiff::TiffError| Error::corrupt(format!("TIFF decode failed ({e})"));
    let mut decoder = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes))
        .map_err(|e| Error::corrupt(format!("TIFF header is not readable ({e})")))?;
    let (w, h) = decoder.dimensions().map_err(bad)?;
    let (nx, ny) = (w as usize, h as usize);
    crate::budget::check_points(nx, ny, "TIFF header")?;
    if decoder.get_chunk_type() != tiff::decoder::ChunkType::Strip || decoder.strip_count().map_err(bad)? as usize != strips.len() {
        return Err(Error::corrupt("TIFF strips do not match its directory"));
    }
    let (dx, dy) = spacing(opts, "TIFF")?;
    let zs = z_scale(opts, "TIFF")?;
    let mut z = crate::scan::heights::with_capacity(nx * ny);
    // Strips in file order (as writers lay them out) are given back by the MiB behind the last one read.
    let in_order = strips.windows(2).all(|p| p[0].0 <= p[1].0);
    let mut release = crate::io::mapped::Release::new(bytes);
    for (k, &(offset, count)) in strips.iter().enumerate() {
        match decoder.read_chunk(k as u32).map_err(bad)? {
            tiff::decoder::DecodingResult::U16(v) if z.len() + v.len() <= nx * ny => z.extend(v.iter().map(|&g| g as f64 * zs)),
            _ => return Err(Error::corrupt(format!("TIFF strip {k} does not hold 16-bit grey rows of {nx} pixels"))),
        }
        match in_order {
            true => release.upto(offset + count),
            false => crate::io::mapped::Release::new(&bytes[offset..offset + count]).upto(count),
        }
    }
    if z.len() != nx * ny {
        return Err(Error::corrupt(format!("TIFF holds {} of its {nx} x {ny} pixels", z.len())));
    }
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: "tiff".into(), ..Default::default() };
    Ok(hf)
}

/// Read a 16-bit grayscale PNG or TIFF held in memory.
pub fn read_image16(bytes: &[u8], opts: &ReadOptions, format: image::ImageFormat, id: &str) -> Result<Heightfield> {
    if format == image::ImageFormat::Tiff {
        let strips = check_tiff_strips(bytes)?;
        if !strips.is_empty() {
            return read_tiff16_strips(bytes, opts, &strips);
        }
    }
    // The header's dimensions against the memory budget before any pixel is decoded.
    let (w, h) = image::ImageReader::with_format(std::io::Cursor::new(bytes), format)
        .into_dimensions()
        .map_err(|e| Error::corrupt(format!("{id} header is not readable ({e})")))?;
    crate::budget::check_points(w as usize, h as usize, &format!("{id} header"))?;
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some((bytes.len() as u64).saturating_mul(MAX_RATIO).clamp(1 << 20, 1 << 34).min(crate::budget::max_memory()));
    reader.limits(limits);
    let (dx, dy) = spacing(opts, id)?;
    let zs = z_scale(opts, id)?;
    // See read_exr: a panic inside the decoder becomes a corrupt-file error.
    let img = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.decode()))
        .map_err(|_| Error::corrupt(format!("{id} decoder failed on this file")))?
        .map_err(|e| Error::corrupt(format!("{id} decode failed ({e})")))?;
    let (nx, ny) = (img.width() as usize, img.height() as usize);
    let z: Vec<f64> = match img {
        image::DynamicImage::ImageLuma16(b) => b.into_raw().into_iter().map(|v| v as f64 * zs).collect(),
        image::DynamicImage::ImageLumaA16(b) => {
            b.into_raw().chunks_exact(2).map(|p| if p[1] == 0 { f64::NAN } else { p[0] as f64 * zs }).collect()
        }
        image::DynamicImage::ImageLuma8(_) | image::DynamicImage::ImageLumaA8(_) => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("{id} is 8-bit: 256 grey levels are too few for heights; use a 16-bit grey image"),
            ))
        }
        other => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("{id} holds {:?} colour pixels: heights need a 16-bit grey image", other.color()),
            ))
        }
    };
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: id.to_ascii_lowercase(), ..Default::default() };
    Ok(hf)
}

/// Check a classic TIFF's first directory: every strip must lie inside the file and, uncompressed, hold
/// the bytes its rows need. The decoder would otherwise fill a short strip from whatever bytes follow it
/// (the directory itself). BigTIFF and tiled images are left to the decoder.
/// Where a TIFF's strips lie, `(offset, bytes)` each, when it is plain 16-bit grey: one sample per pixel
/// (BlackIsZero, chunky), in strips. Empty otherwise: another layout, or a BigTIFF this check does not read.
fn check_tiff_strips(bytes: &[u8]) -> Result<Vec<(usize, usize)>> {
    let le = bytes.starts_with(b"II");
    let u16at = |o: usize| -> Option<u64> {
        let b = bytes.get(o..o + 2)?;
        Some(if le { u16::from_le_bytes([b[0], b[1]]) } else { u16::from_be_bytes([b[0], b[1]]) } as u64)
    };
    let u32at = |o: usize| -> Option<u64> {
        let b: [u8; 4] = bytes.get(o..o + 4)?.try_into().ok()?;
        Some(if le { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) } as u64)
    };
    let short = || Error::corrupt("TIFF directory is truncated");
    if u16at(2) != Some(42) {
        return Ok(Vec::new());
    }
    let ifd = u32at(4).ok_or_else(short)? as usize;
    let n = u16at(ifd).ok_or_else(short)? as usize;
    // (type, count, offset of the value or of the inline value) per tag of interest.
    let mut tags = std::collections::HashMap::new();
    for k in 0..n {
        let e = ifd + 2 + 12 * k;
        let tag = u16at(e).ok_or_else(short)?;
        let typ = u16at(e + 2).ok_or_else(short)?;
        let count = u32at(e + 4).ok_or_else(short)?;
        tags.insert(tag as u16, (typ, count, e + 8));
    }
    // The values of a SHORT or LONG tag.
    let values = |tag: u16| -> Result<Option<Vec<u64>>> {
        let Some(&(typ, count, at)) = tags.get(&tag) else { return Ok(None) };
        let size = match typ {
            3 => 2,
            4 => 4,
            _ => return Ok(None),
        };
        if count > bytes.len() as u64 {
            return Err(Error::corrupt(format!("TIFF tag {tag} declares {count} values, more than the file holds")));
        }
        let start = if count * size <= 4 { at } else { u32at(at).ok_or_else(short)? as usize };
        (0..count as usize)
            .map(|i| if size == 2 { u16at(start + 2 * i) } else { u32at(start + 4 * i) })
            .collect::<Option<Vec<u64>>>()
            .map(Some)
            .ok_or_else(|| Error::corrupt(format!("TIFF tag {tag} runs past the end of the file")))
    };
    let (Some(offsets), Some(counts)) = (values(273)?, values(279)?) else { return Ok(Vec::new()) };
    if offsets.len() != counts.len() {
        return Err(Error::corrupt(format!("TIFF has {} strip offsets but {} strip byte counts", offsets.len(), counts.len())));
    }
    let first = |tag: u16| -> Result<Option<u64>> { Ok(values(tag)?.and_then(|v| v.first().copied())) };
    let (width, height) = (first(256)?.unwrap_or(0), first(257)?.unwrap_or(0));
    let bits: u64 = values(258)?.map_or(1, |v| v.iter().sum());
    let rows_per_strip = first(278)?.unwrap_or(height).clamp(1, height.max(1));
    let uncompressed = first(259)?.unwrap_or(1) == 1;
    let row_bytes = (width.saturating_mul(bits)).div_ceil(8);
    for (k, (&off, &count)) in offsets.iter().zip(&counts).enumerate() {
        if off.saturating_add(count) > bytes.len() as u64 {
            return Err(Error::corrupt(format!(
                "TIFF strip {k} ({count} bytes at offset {off}) runs past the end of the file ({} bytes)",
                bytes.len()
            )));
        }
        if uncompressed {
            let rows = rows_per_strip.min(height.saturating_sub(k as u64 * rows_per_strip));
            let need = rows.saturating_mul(row_bytes);
            if count < need {
                return Err(Error::corrupt(format!("TIFF strip {k} holds {count} bytes, its {rows} rows of {width} pixels need {need}")));
            }
        }
    }
    // Samples per pixel 1, 16 bits, BlackIsZero, chunky (absent tags take the baseline defaults).
    let plain = values(277)?.is_none_or(|v| v == [1])
        && values(258)?.is_some_and(|v| v == [16])
        && values(262)?.is_some_and(|v| v == [1])
        && values(284)?.is_none_or(|v| v == [1]);
    Ok(match plain {
        true => offsets.iter().zip(&counts).map(|(&o, &c)| (o as usize, c as usize)).collect(),
        false => Vec::new(),
    })
}
