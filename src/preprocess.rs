//! Preprocessing of a heightfield before normals are taken: crop, subsampling, form removal.
//!
//! Each step is explicit and documented; the default removes the least-squares mean plane and nothing
//! else. Holes are never filled: invalid points stay NaN through every step, and the NDF code skips
//! every stencil that touches one.

pub(crate) mod despike;
pub(crate) mod form;
pub(crate) mod prepared;

pub use despike::despike;
pub use despike::Despike;
pub use form::CylinderFit;
pub use form::{remove_cylinder, remove_polynomial};
pub use prepared::{prepare, Prepared};

use crate::error::{Error, Result};
use crate::scan::{Heightfield, Scan};

/// Which preprocessing steps to apply, in the order crop, subsample, form removal.
#[derive(Debug, Clone, PartialEq)]
pub struct Preprocess {
    /// Least-squares form removal; the default removes the mean plane.
    pub form: FormRemoval,
    /// Keep only this window of the grid (applied first).
    pub crop: Option<Crop>,
    /// Keep every `step`-th point along x and y (1 keeps all; applied after the crop).
    pub subsample: usize,
    /// Spike removal after the form removal ([`despike`]).
    pub despike: Despike,
}

/// A window of the grid in samples: columns `x..x+nx`, rows `y..y+ny`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crop {
    /// First column.
    pub x: usize,
    /// First row.
    pub y: usize,
    /// Number of columns.
    pub nx: usize,
    /// Number of rows.
    pub ny: usize,
}

/// The form removed before normals are computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FormRemoval {
    /// Keep the heights as read.
    None,
    /// Least-squares plane (default).
    Plane,
    /// Least-squares polynomial of total degree 2 or 3 in x and y.
    Polynomial(usize),
    /// Least-squares cylinder with its axis in the xy plane (bullet lands, turned parts).
    Cylinder,
}

impl std::str::FromStr for FormRemoval {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "none" => Ok(FormRemoval::None),
            "plane" => Ok(FormRemoval::Plane),
            "poly2" => Ok(FormRemoval::Polynomial(2)),
            "poly3" => Ok(FormRemoval::Polynomial(3)),
            "cylinder" => Ok(FormRemoval::Cylinder),
            other => Err(Error::invalid(format!("unknown form {other:?}: use none, plane, poly2, poly3 or cylinder"))),
        }
    }
}

/// `NXxNY+X+Y`: columns `X..X+NX`, rows `Y..Y+NY`.
impl std::str::FromStr for Crop {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let bad = || Error::invalid(format!("{s:?} is not NXxNY+X+Y (for example 512x512+0+0)"));
        let (size, rest) = s.split_once('+').ok_or_else(bad)?;
        let (x, y) = rest.split_once('+').ok_or_else(bad)?;
        let (nx, ny) = size.split_once('x').ok_or_else(bad)?;
        let p = |t: &str| t.trim().parse::<usize>().map_err(|_| bad());
        Ok(Crop { x: p(x)?, y: p(y)?, nx: p(nx)?, ny: p(ny)? })
    }
}

impl Preprocess {
    /// Refuse out-of-range values ([`crate::ErrorKind::InvalidInput`], the message naming the field): a
    /// `subsample` step of 0, an empty crop window. Whether a crop fits is known only with the scan.
    pub fn validate(&self) -> Result<()> {
        if self.subsample == 0 {
            return Err(Error::invalid("subsample 0 must be at least 1"));
        }
        if let Some(c) = self.crop {
            if c.nx == 0 || c.ny == 0 {
                return Err(Error::invalid(format!("crop {}x{}+{}+{} is empty", c.nx, c.ny, c.x, c.y)));
            }
        }
        Ok(())
    }
}

impl Default for Preprocess {
    fn default() -> Self {
        Preprocess { form: FormRemoval::Plane, crop: None, subsample: 1, despike: Despike::Median }
    }
}

/// Apply `pre` to `hf`: crop, subsample, then remove the form. Never fills an invalid point. The
/// residual heights are a new buffer; [`prepare`] keeps the form and the mask apart instead.
pub fn apply<'a>(hf: Scan<'a>, pre: &Preprocess) -> Result<Scan<'a>> {
    Ok(prepare(hf, pre)?.into_scan())
}

/// The window `c` of `hf` (origin moved so every kept point keeps its position).
pub fn crop(hf: &Scan, c: Crop) -> Result<Heightfield> {
    let fits =
        c.nx > 0 && c.ny > 0 && c.x.checked_add(c.nx).is_some_and(|e| e <= hf.nx) && c.y.checked_add(c.ny).is_some_and(|e| e <= hf.ny);
    if !fits {
        return Err(Error::invalid(format!("crop {}x{}+{}+{} does not fit in the {} x {} grid", c.nx, c.ny, c.x, c.y, hf.nx, hf.ny)));
    }
    let mut z = Vec::with_capacity(c.nx * c.ny);
    for i in c.y..c.y + c.ny {
        z.extend_from_slice(&hf.row(i)[c.x..c.x + c.nx]);
    }
    let mut out = Heightfield::new(c.nx, c.ny, hf.dx, hf.dy, z)?;
    out.x0 = hf.x0 + c.x as f64 * hf.dx;
    out.y0 = hf.y0 + c.y as f64 * hf.dy;
    out.meta = hf.meta.clone();
    Ok(out)
}

/// Every `step`-th point along both axes (point picking, no averaging: averaging would mix invalid
/// points into valid ones or invent values). Spacing grows by `step`.
pub fn subsample(hf: &Scan, step: usize) -> Result<Heightfield> {
    hf.subsample(step)
}
