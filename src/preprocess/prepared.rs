//! A preprocessed scan whose heights are never copied: the heights as read (owned, or a view of the
//! memory-mapped file), the fitted form, and the despiking mask, kept apart.
//!
//! [`crate::preprocess::apply`] subtracts the form from every height and writes NaN over spikes, which
//! costs a second buffer the size of the scan (and its page zeroing). A [`Prepared`] scan instead hands
//! its heights out in row bands ([`BandSource`]): each band's residual rows are computed into a small
//! buffer with [`FormModel::residual_row`], the arithmetic of the whole-grid removal, and the masked
//! points set to NaN there. Every pass after reading (despiking, the frame, the height lattice, the
//! histogram, the resolution test) reads bands, so it sees exactly the heights `apply` would have made,
//! bit for bit, and the working memory is a few bands per thread. Removing the form from the heights
//! band by band is the same as folding it into the slopes: each central difference is taken of the
//! residual rows, in cache, just before it is binned. The counting pass goes further for a plane: it
//! reads the heights as stored ([`RawMasked`]) and subtracts the plane's constant slope
//! ([`BandSource::plane_folded`]), so no band is remade there; slopes then agree with the residual's
//! to rounding (a normal on a cell edge may change cell). The spike test screens the heights as read
//! too (a plane cancels in its screen, [`despike::RawPlane`]) and makes residuals only around the
//! points it must test, with the same arithmetic, so it finds the same spikes. A cylinder form is
//! removed into a residual buffer as before (its fit holds every point anyway).

use crate::error::Result;
use crate::scan::bands::{bands_of, masked_band, Band, BandSource, GridShape, RawMasked};
use crate::scan::{InputInfo, Scan, ScanMeta};

use super::form::FormModel;
use super::{despike, FormRemoval, Preprocess};

/// A preprocessed scan: the heights as read, the form to subtract and the points to mask, kept apart
/// and handed out in row bands ([`BandSource`]) so that no second copy of the heights is made. Every
/// pass sees the residual heights the whole-grid form removal would make, bit for bit.
#[derive(Debug, Clone)]
pub struct Prepared<'a> {
    /// The heights after crop and subsampling, before form removal (a mapped file stays mapped).
    raw: Scan<'a>,
    /// The fitted form, subtracted band by band (`None`: the heights are used as they are).
    form: Option<FormModel>,
    /// Flat indices `i * nx + j` of the points despiking masked, sorted.
    masked: Vec<usize>,
    /// The points the form was fitted without (the spikes of an earlier search; valid as read).
    form_without: Vec<usize>,
}

/// Crop, subsample, fit the form and find the spikes of `hf` as [`super::apply`] does, without making
/// the residual heights.
pub fn prepare<'a>(hf: Scan<'a>, pre: &Preprocess) -> Result<Prepared<'a>> {
    let mut hf = hf;
    if let Some(c) = pre.crop {
        hf = super::crop(&hf, c)?;
    }
    if pre.subsample != 1 {
        hf = super::subsample(&hf, pre.subsample)?;
    }
    // The lattice is found on the heights as stored (a form removal shifts every height off `k q`), so
    // its serial search runs beside the form's fit (within its phase), which reads the same heights and
    // not the quantum.
    let find_quantum = pre.form != FormRemoval::None && hf.meta.height_quantum.is_none();
    let quantum = || find_quantum.then(|| crate::ndf::quantum::height_quantum(&hf)).flatten();
    let polynomial = |order| {
        let (q, form) = rayon::join(quantum, || super::form::fit_polynomial(&hf, order));
        (q, form.map(Some))
    };
    let phase = crate::phases::phase("form");
    let (q, form) = match pre.form {
        FormRemoval::None => (None, Ok(None)),
        FormRemoval::Plane => polynomial(1),
        FormRemoval::Polynomial(k) => polynomial(k),
        FormRemoval::Cylinder => {
            let q = quantum();
            hf.z = super::form::remove_cylinder(&hf)?.residual.into();
            (q, Ok(None))
        }
    };
    let form = form?;
    drop(phase);
    if find_quantum {
        hf.meta.height_quantum = q;
    }
    let _p = crate::phases::phase("despike");
    let mut p = Prepared { raw: hf, form, masked: Vec::new(), form_without: Vec::new() };
    let order = match pre.form {
        FormRemoval::Plane => Some(1),
        FormRemoval::Polynomial(k) => Some(k),
        FormRemoval::None | FormRemoval::Cylinder => None,
    };
    // The form is fitted again without the spikes it was first fitted with (a few tall spikes tilt a
    // least-squares plane across the whole scan), and the spikes sought again under it, until they no
    // longer change.
    for _ in 0..MAX_FORM_PASSES {
        // Each search reads every point under the current form (a masked point would read as NaN).
        p.masked.clear();
        let raw = p.form.as_ref().map(|form| despike::RawPlane { raw: &p.raw, form });
        let Some((masked, report)) = despike::find_spikes_over(&p, raw, pre.despike, p.raw.meta.height_quantum) else { break };
        p.masked = masked;
        p.raw.meta.despike = Some(report);
        let Some(k) = order.filter(|_| p.masked != p.form_without) else { break };
        p.form = Some(super::form::fit_polynomial(&RawMasked::new(&p.raw, &p.masked), k)?);
        p.form_without = p.masked.clone();
    }
    Ok(p)
}

/// The most fits of the form between spike searches ([`prepare`]): the second search finds the spikes
/// the first plane's tilt hid, and a third rarely changes them.
const MAX_FORM_PASSES: usize = 3;

impl<'a> Prepared<'a> {
    /// The metadata of the scan (with the height quantum and the despiking report).
    pub fn meta(&self) -> &ScanMeta {
        &self.raw.meta
    }

    /// The heights as read (before form removal and masking).
    pub fn raw(&self) -> &Scan<'a> {
        &self.raw
    }

    /// Flat indices of the masked spikes, sorted.
    pub fn masked(&self) -> &[usize] {
        &self.masked
    }

    /// Number of invalid points after masking (NaN as read, plus the masked spikes): from the form's fit,
    /// or bands counted on every thread.
    pub fn invalid_count(&self) -> usize {
        use rayon::prelude::*;
        if let Some(f) = &self.form {
            // The form's fit counted the valid heights already (the same grid: crop and subsampling come first),
            // less those it was fitted without.
            return self.raw.nx * self.raw.ny - (f.valid() + self.form_without.len()) + self.masked.len();
        }
        let step = self.raw.band_rows();
        let bands: Vec<std::ops::Range<usize>> = bands_of(0..self.raw.ny, step).collect();
        let nan: usize = bands
            .into_par_iter()
            .map_init(Vec::new, |buf, b| self.raw.band(b.start, b.end, buf).values().iter().filter(|h| h.is_nan()).count())
            .sum();
        nan + self.masked.len()
    }

    /// The scan [`super::apply`] makes: the residual heights with the spikes masked. Heights used as
    /// read with nothing masked stay as they are (a mapped file stays mapped).
    pub fn into_scan(self) -> Scan<'a> {
        let Prepared { mut raw, form, masked, .. } = self;
        if let Some(form) = form {
            raw.z = form.residual(&raw).into();
        }
        for k in masked {
            raw.z[k] = f64::NAN;
        }
        raw
    }
}

impl BandSource for Prepared<'_> {
    type T = f64;
    fn shape(&self) -> GridShape {
        self.raw.shape()
    }
    fn band<'b>(&'b self, lo: usize, hi: usize, buf: &'b mut Vec<f64>) -> Band<'b, f64> {
        masked_band(
            &self.raw,
            self.form.as_ref().map(|f| move |i, row: &[f64], buf: &mut Vec<f64>| f.residual_row(i, row, buf)),
            &self.masked,
            lo,
            hi,
            buf,
        )
    }
    fn plane_folded(&self) -> Option<(RawMasked<'_>, [f64; 2])> {
        let g = self.form.as_ref()?.plane_slope(self.raw.dx, self.raw.dy)?;
        Some((RawMasked::new(&self.raw, &self.masked), g))
    }
}

impl Prepared<'_> {
    /// The fit report's description of this scan read from `path` (as [`InputInfo::new`] gives for the
    /// scan [`Prepared::into_scan`] makes).
    pub fn input_info(&self, path: &std::path::Path) -> InputInfo {
        InputInfo::with_invalid(path, &self.raw, self.invalid_count())
    }
}
