//! Length unit names as instrument files spell them, to metres.

use crate::error::{Error, ErrorKind, Result};

/// Metres per `unit` (`m`, `mm`, `um`/`µm`/`micron`, `nm`, `A`/`Å`, `pm`, `cm`, `in`, `mil`); the
/// name is trimmed and case-sensitive apart from the micro sign's spellings.
pub fn metres_per(unit: &str) -> Result<f64> {
    let u = unit.trim().trim_end_matches('\0').trim();
    let f = match u {
        "m" => 1.0,
        "cm" => 1e-2,
        "mm" => 1e-3,
        "um" | "µm" | "μm" | "micron" | "microns" | "micrometer" | "micrometre" => 1e-6,
        "nm" => 1e-9,
        "A" | "Å" => 1e-10,
        "pm" => 1e-12,
        "in" | "inch" => 0.0254,
        "mil" => 2.54e-5,
        _ => {
            return Err(Error::new(ErrorKind::Unsupported, format!("unknown length unit {u:?}")));
        }
    };
    Ok(f)
}

/// Decode a unit field that may be Latin-1 (a lone 0xB5 byte is the micro sign in Digital Surf files).
pub fn latin1(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    b[..end].iter().map(|&c| c as char).collect::<String>().trim().to_string()
}
