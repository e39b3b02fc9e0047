//! Image containers holding heights: OpenEXR (one float channel) and 16-bit grayscale PNG/TIFF.
//!
//! None carries a length unit: heights need `--z-scale` (metres per stored unit, for 16-bit images
//! metres per grey level) and spacing `--dx`/`--dy`. Row 0 is the image's top row. EXR: the channel
//! named `Z`, else `Y`, else `R`, else the only channel; NaN/infinite samples are invalid. PNG/TIFF:
//! 16-bit grey (`L16`), or grey plus alpha (`LA16`) where alpha 0 marks an invalid point; 8-bit and
//! colour images are refused (too few levels / not a height). Sizes from headers are checked against
//! what the compressed bytes can hold before any pixel is decoded.

use crate::error::{Error, ErrorKind, Result};
use crate::heightfield::{Heightfield, ScanMeta};
use crate::io::raw_opts::{spacing, z_scale};
use crate::io::ReadOptions;

/// No lossless codec here expands more than deflate's 1032:1; more pixels than that is a lie.
const MAX_RATIO: u64 = 1032;

/// Read an OpenEXR file held in memory.
pub fn read_exr(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    use exr::prelude::{read, FlatSamples, ReadChannels as _, ReadLayers as _};
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
    // A third-party decoder must not take the process down on hostile bytes: a panic inside it is
    // reported as a corrupt file.
    let img = std::panic::catch_unwind(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
    })
    .map_err(|_| Error::corrupt("OpenEXR decoder failed on this file"))?
    .map_err(|e| Error::corrupt(format!("OpenEXR decode failed ({e})")))?;
    let layer = img.layer_data;
    let (nx, ny) = (layer.size.0, layer.size.1);
    let list = &layer.channel_data.list;
    let pick = ["Z", "Y", "R"]
        .iter()
        .find_map(|n| list.iter().find(|c| c.name.to_string() == *n))
        .or(if list.len() == 1 { list.first() } else { None })
        .ok_or_else(|| {
            Error::new(
                ErrorKind::Unsupported,
                format!(
                    "OpenEXR channels {:?}: none is Z, Y or R and there is more than one",
                    list.iter().map(|c| c.name.to_string()).collect::<Vec<_>>()
                ),
            )
        })?;
    let z: Vec<f64> = match &pick.sample_data {
        FlatSamples::F16(v) => v.iter().map(|s| s.to_f32() as f64 * zs).collect(),
        FlatSamples::F32(v) => v.iter().map(|s| *s as f64 * zs).collect(),
        FlatSamples::U32(v) => v.iter().map(|s| *s as f64 * zs).collect(),
    };
    let mut hf = Heightfield::new(nx, ny, dx, dy, z)?;
    hf.meta = ScanMeta { format: "exr".into(), ..Default::default() };
    hf.meta.instrument.insert("exr.channel".into(), pick.name.to_string());
    Ok(hf)
}

/// Read a 16-bit grayscale PNG or TIFF held in memory.
pub fn read_image16(bytes: &[u8], opts: &ReadOptions, format: image::ImageFormat, id: &str) -> Result<Heightfield> {
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
