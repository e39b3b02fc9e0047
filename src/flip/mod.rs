//! The FLIP image-difference evaluator: LDR-FLIP (Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström
//! and Fairchild, "FLIP: A Difference Evaluator for Alternating Images", HPG 2020) and HDR-FLIP (Andersson,
//! Nilsson, Shirley and Akenine-Möller, "Visualizing Errors in Rendered High Dynamic Range Images",
//! Eurographics 2021), to score renders of fitted lobes against renders of the measured table.
//!
//! A per-pixel error in `[0, 1]` that approximates the difference a viewer sees when flipping between a
//! reference and a test image at a given number of pixels per degree of visual angle. It follows the
//! reference implementation (NVlabs/flip, `FLIP.h`, as in the `flip-evaluator` 1.7 wheel) in every
//! choice that changes a value: separated CSF filters and their radius, the colour spaces, the Hunt
//! adjustment, HyAB, the remapping constants, the edge and point detectors, the ACES tone mapper and the
//! automatic exposure range. Arithmetic is in `f64` (the reference uses `f32`), except for the few integer
//! decisions (filter radii, the number of exposures) which are taken in `f32` as the reference takes them.
//! data_formats/flip.md has the measured agreement with the reference.
//!
//! Inputs are linear RGB (sRGB primaries), `[f32; 3]` per pixel, row-major: LDR values in `[0, 1]`
//! (clamped), HDR values non-negative radiances.

use rayon::prelude::*;

use crate::error::{Error, ErrorKind, Result};

mod color;
mod magma;

pub use magma::magma;

/// Exponent of the colour difference before remapping, `q_c` (HPG 2020, section 4.1).
pub const QC: f64 = 0.7;
/// Fraction of `c_max` where the colour remapping changes slope, `p_c` (HPG 2020, section 4.1).
pub const PC: f64 = 0.4;
/// The remapped value at `p_c c_max`, `p_t` (HPG 2020, section 4.1).
pub const PT: f64 = 0.95;
/// Width of the edge and point detectors in degrees of visual angle, `w` (HPG 2020, section 4.2).
pub const GW: f64 = 0.082;
/// Exponent of the feature difference, `q_f` (HPG 2020, section 4.2).
pub const QF: f64 = 0.5;

/// Pixels per degree of visual angle for a monitor `monitor_width_m` wide showing `resolution_x`
/// pixels across, seen from `distance_m`: `d (r / w) (pi / 180)`, FLIP's small-angle formula.
pub fn pixels_per_degree(distance_m: f64, resolution_x: f64, monitor_width_m: f64) -> f64 {
    distance_m * (resolution_x / monitor_width_m) * (std::f64::consts::PI / 180.0)
}

/// FLIP's default viewing condition: a 0.7 m wide 3840-pixel monitor seen from 0.7 m, 67.0206... pixels
/// per degree.
pub const DEFAULT_PPD: f64 = 0.7 * (3840.0 / 0.7) * (std::f64::consts::PI / 180.0);

/// An image of linear RGB pixels, row-major, `width * height` of them.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 3]>,
}

impl RgbImage {
    /// An image from its pixels, row by row; an error if `pixels` does not hold `width * height` of them,
    /// if the image is empty or if a value is not finite.
    pub fn new(width: usize, height: usize, pixels: Vec<[f32; 3]>) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(Error::invalid(format!("image is empty ({width} x {height})")));
        }
        if width.checked_mul(height) != Some(pixels.len()) {
            return Err(Error::invalid(format!("{} pixels for a {width} x {height} image", pixels.len())));
        }
        if let Some(i) = pixels.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
            let n = pixels.iter().filter(|p| !p.iter().all(|v| v.is_finite())).count();
            return Err(Error::new(
                ErrorKind::BadData,
                format!("{n} pixel(s) are not finite, the first at x = {}, y = {}: {:?}", i % width, i / width, pixels[i]),
            ));
        }
        Ok(RgbImage { width, height, pixels })
    }

    /// An image from an `(height, width, 3)` array (a numpy image's layout).
    pub fn from_array(a: ndarray::ArrayView3<'_, f32>) -> Result<Self> {
        let (h, w, c) = a.dim();
        if c != 3 {
            return Err(Error::invalid(format!("image array has {c} channels, not 3 (shape {h} x {w} x {c})")));
        }
        let pixels = a.outer_iter().flat_map(|row| row.outer_iter().map(|p| [p[0], p[1], p[2]]).collect::<Vec<_>>()).collect();
        Self::new(w, h, pixels)
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixels, row by row.
    pub fn pixels(&self) -> &[[f32; 3]] {
        &self.pixels
    }
}

/// Which FLIP produced a map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// LDR-FLIP: inputs in `[0, 1]`, compared as shown.
    Ldr,
    /// HDR-FLIP: inputs tone-mapped at several exposures, the largest LDR-FLIP kept per pixel.
    Hdr,
}

impl Mode {
    /// `"ldr"` or `"hdr"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Ldr => "ldr",
            Mode::Hdr => "hdr",
        }
    }
}

/// The exposure range of HDR-FLIP; a `None` is computed from the reference image as the reference
/// implementation does ([`auto_exposures`], and `max(2, ceil(stop - start))` exposures).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HdrOptions {
    /// The first exposure `c_start`, in stops (the image is scaled by `2^c`).
    pub start_exposure: Option<f64>,
    /// The last exposure `c_stop`, in stops, at least `c_start`.
    pub stop_exposure: Option<f64>,
    /// How many exposures, evenly spaced from `c_start` to `c_stop` (1: `c_start` alone).
    pub num_exposures: Option<usize>,
}

/// The exposures HDR-FLIP evaluated.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Exposures {
    /// The first exposure, in stops.
    pub start: f64,
    /// The last exposure, in stops.
    pub stop: f64,
    /// How many, evenly spaced from `start` to `stop`.
    pub count: usize,
}

impl Exposures {
    /// The exposure of step `i` (in stops), computed in `f32` as the reference does.
    pub fn exposure(&self, i: usize) -> f64 {
        if self.count < 2 {
            return self.start;
        }
        let (start, stop) = (self.start as f32, self.stop as f32);
        let step = (stop - start) / (self.count - 1) as f32;
        (start + i as f32 * step) as f64
    }
}

/// A FLIP error map: one value in `[0, 1]` per pixel, and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct FlipMap {
    width: usize,
    height: usize,
    values: Vec<f32>,
    mode: Mode,
    ppd: f64,
    exposures: Option<Exposures>,
    exposure_map: Option<Vec<f32>>,
}

impl FlipMap {
    /// The mean error over all pixels (FLIP's single-number summary), summed in `f64`.
    pub fn mean(&self) -> f64 {
        self.values.iter().map(|&v| v as f64).sum::<f64>() / self.values.len() as f64
    }

    /// The per-pixel errors, row by row.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// The error at pixel `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.values[y * self.width + x]
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// LDR-FLIP or HDR-FLIP.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The pixels per degree the map was computed for.
    pub fn ppd(&self) -> f64 {
        self.ppd
    }

    /// HDR-FLIP's exposures (`None` for LDR-FLIP).
    pub fn exposures(&self) -> Option<Exposures> {
        self.exposures
    }

    /// HDR-FLIP only: per pixel, the exposure (in stops) whose LDR-FLIP error was the largest (the first
    /// exposure where all were 0).
    pub fn exposure_map(&self) -> Option<&[f32]> {
        self.exposure_map.as_deref()
    }

    /// The map in FLIP's magma colour map, 8-bit sRGB, row by row (3 bytes a pixel), for a PNG.
    pub fn magma_rgb8(&self) -> Vec<u8> {
        self.values.iter().flat_map(|&v| magma(v)).collect()
    }
}

/// LDR-FLIP of `test` against `reference` (both linear RGB, clamped to `[0, 1]` first as the reference
/// does), viewed at `ppd` pixels per degree ([`DEFAULT_PPD`] is FLIP's default).
pub fn ldr(reference: &RgbImage, test: &RgbImage, ppd: f64) -> Result<FlipMap> {
    check_pair(reference, test, ppd)?;
    let to_ycc = |img: &RgbImage| -> Vec<[f32; 3]> {
        img.pixels.par_iter().map(|p| narrow(color::linear_rgb_to_ycxcz(p.map(|v| (v as f64).clamp(0.0, 1.0))))).collect()
    };
    let kernels = Kernels::new(ppd);
    let (w, h) = (reference.width, reference.height);
    let values = errors(&filter(&to_ycc(reference), w, h, &kernels), &filter(&to_ycc(test), w, h, &kernels));
    Ok(FlipMap { width: reference.width, height: reference.height, values, mode: Mode::Ldr, ppd, exposures: None, exposure_map: None })
}

/// HDR-FLIP of `test` against `reference` (linear RGB radiances) at `ppd` pixels per degree (EG 2021,
/// section 3): both are exposed by `2^c` for each exposure `c` from `c_start` to `c_stop`, tone-mapped
/// with the ACES fit and clamped to `[0, 1]`; each pixel keeps its largest LDR-FLIP over the exposures.
pub fn hdr(reference: &RgbImage, test: &RgbImage, ppd: f64, options: &HdrOptions) -> Result<FlipMap> {
    check_pair(reference, test, ppd)?;
    HdrReference::new(reference, ppd, options)?.map(test)
}

/// HDR-FLIP against one reference, prepared once for many test images: per exposure, the reference's
/// filtered colours (as Hunt-adjusted L*a*b*) and its edge and point magnitudes, which is everything
/// of the reference that a test's error depends on. [`HdrReference::map`] equals [`hdr`] with the same
/// reference, `ppd` and options, and costs about half as much.
#[derive(Debug, Clone)]
pub struct HdrReference {
    width: usize,
    height: usize,
    ppd: f64,
    exposures: Exposures,
    kernels: Kernels,
    /// Per exposure, the reference's filtered pixels.
    filtered: Vec<Vec<Filtered>>,
}

impl HdrReference {
    /// Prepare `reference` (linear RGB radiances) at `ppd` pixels per degree, its exposures resolved from
    /// `options` as [`hdr`] resolves them.
    pub fn new(reference: &RgbImage, ppd: f64, options: &HdrOptions) -> Result<Self> {
        check_ppd(ppd)?;
        let exposures = resolve_exposures(reference, options)?;
        let kernels = Kernels::new(ppd);
        let (w, h) = (reference.width, reference.height);
        let filtered = (0..exposures.count).map(|i| filter(&tone_mapped(reference, exposures.exposure(i)), w, h, &kernels)).collect();
        Ok(HdrReference { width: w, height: h, ppd, exposures, kernels, filtered })
    }

    /// The exposures evaluated.
    pub fn exposures(&self) -> Exposures {
        self.exposures
    }

    /// HDR-FLIP's map of `test` against the reference; an error if `test` is not the reference's size.
    pub fn map(&self, test: &RgbImage) -> Result<FlipMap> {
        if (self.width, self.height) != (test.width, test.height) {
            return Err(Error::invalid(format!(
                "the reference is {} x {} pixels and the test {} x {}: FLIP compares images of one size",
                self.width, self.height, test.width, test.height
            )));
        }
        let (w, h, exposures) = (self.width, self.height, self.exposures);
        let mut values = vec![0.0f32; w * h];
        let mut exposure_map = vec![exposures.exposure(0) as f32; w * h];
        for (i, reference) in self.filtered.iter().enumerate() {
            let c = exposures.exposure(i);
            let map = errors(reference, &filter(&tone_mapped(test, c), w, h, &self.kernels));
            // Strictly larger, as the reference: ties keep the earlier exposure.
            for ((v, e), m) in values.iter_mut().zip(exposure_map.iter_mut()).zip(map) {
                if m > *v {
                    *v = m;
                    *e = c as f32;
                }
            }
        }
        Ok(FlipMap {
            width: w,
            height: h,
            values,
            mode: Mode::Hdr,
            ppd: self.ppd,
            exposures: Some(exposures),
            exposure_map: Some(exposure_map),
        })
    }

    /// The mean of [`HdrReference::map`] (FLIP's single-number summary).
    pub fn mean(&self, test: &RgbImage) -> Result<f64> {
        Ok(self.map(test)?.mean())
    }
}

/// `img` exposed by `2^c`, tone-mapped by [`aces`], clamped to `[0, 1]`, in YCxCz (f32, as the reference
/// stores it).
fn tone_mapped(img: &RgbImage, c: f64) -> Vec<[f32; 3]> {
    let scale = 2f64.powf(c);
    img.pixels.par_iter().map(|p| narrow(color::linear_rgb_to_ycxcz(p.map(|v| aces(v as f64 * scale).clamp(0.0, 1.0))))).collect()
}

/// The ACES filmic tone-mapping fit (Narkowicz 2016) HDR-FLIP uses (EG 2021, section 3), with the 0.6
/// pre-exposure of the fit cancelled: `(a x^2 + b x) / (c x^2 + d x + e)` per channel.
pub fn aces(x: f64) -> f64 {
    let [a, b, c, d, e] = ACES;
    (a * x * x + b * x) / (c * x * x + d * x + e)
}

/// The ACES coefficients `a, b, c, d, e` of [`aces`], the 0.6 folded in as the reference folds it.
const ACES: [f64; 5] = [0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14];

/// HDR-FLIP's automatic exposure range for a reference image (EG 2021, section 3): `c_start` maps its
/// largest luminance and `c_stop` its median luminance to 0.85 after the tone mapper,
/// `c = log2(x_0.85 / Y)` with `x_0.85` the tone mapper's input for 0.85. Computed in `f32` as the
/// reference computes it (the median is the element at index `n / 2`, and is raised to `f32::EPSILON`
/// as `flip-evaluator` 1.7 does, so a mostly black image still has a finite `c_stop`). An error for an
/// all-black reference, whose range has no start.
pub fn auto_exposures(reference: &RgbImage) -> Result<(f64, f64)> {
    let a = ACES.map(|v| v as f32);
    // Solve tm(x) = t: (a0 - t a2) x^2 + (a1 - t a3) x - t a4 = 0, the larger root.
    let t = 0.85f32;
    let (qa, qb, qc) = (a[0] - t * a[2], a[1] - t * a[3], -t * a[4]);
    let d1 = -0.5 * (qb / qa);
    let x_max = d1 + (d1 * d1 - qc / qa).sqrt();
    let mut lum: Vec<f32> = reference.pixels.iter().map(|p| 0.2126f32 * p[0] + 0.7152f32 * p[1] + 0.0722f32 * p[2]).collect();
    let y_max = lum.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if !(y_max > 0.0) {
        return Err(Error::new(
            ErrorKind::BadData,
            "the reference image has no positive luminance: HDR-FLIP cannot choose its exposures (give the start and stop exposures)",
        ));
    }
    let mid = lum.len() / 2;
    let (_, &mut median, _) = lum.select_nth_unstable_by(mid, f32::total_cmp);
    let start = (x_max / y_max).log2();
    let stop = (x_max / median.max(f32::EPSILON)).log2();
    Ok((start as f64, stop as f64))
}

/// The exposures to evaluate: the given ones, the rest from [`auto_exposures`].
fn resolve_exposures(reference: &RgbImage, o: &HdrOptions) -> Result<Exposures> {
    for (name, v) in [("start exposure", o.start_exposure), ("stop exposure", o.stop_exposure)] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("the {name} must be finite, got {v}")));
        }
    }
    let (start, stop) = match (o.start_exposure, o.stop_exposure) {
        (Some(a), Some(b)) => (a, b),
        (a, b) => {
            let (sa, sb) = auto_exposures(reference)?;
            (a.unwrap_or(sa), b.unwrap_or(sb))
        }
    };
    if start > stop {
        return Err(Error::invalid(format!("the start exposure {start} is above the stop exposure {stop}")));
    }
    let count = match o.num_exposures {
        Some(0) => return Err(Error::invalid("the number of exposures must be at least 1")),
        Some(n) => n,
        None => (stop as f32 - start as f32).ceil().max(2.0) as usize,
    };
    Ok(Exposures { start, stop, count })
}

fn check_pair(reference: &RgbImage, test: &RgbImage, ppd: f64) -> Result<()> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(Error::invalid(format!(
            "the reference is {} x {} pixels and the test {} x {}: FLIP compares images of one size",
            reference.width, reference.height, test.width, test.height
        )));
    }
    check_ppd(ppd)
}

fn check_ppd(ppd: f64) -> Result<()> {
    // The filters' radii grow with ppd: beyond 1e4 they would dwarf any image.
    if !(ppd.is_finite() && ppd > 0.0 && ppd <= 1e4) {
        return Err(Error::invalid(format!("pixels per degree must be in (0, 10000], got {ppd}")));
    }
    Ok(())
}

fn narrow(c: [f64; 3]) -> [f32; 3] {
    c.map(|v| v as f32)
}

/// The separated filters of one viewing condition.
#[derive(Debug, Clone)]
struct Kernels {
    /// Per tap: the achromatic and red-green CSF weights, and the two Gaussians of the blue-yellow CSF.
    spatial: Vec<[f64; 4]>,
    /// Per tap: the Gaussian, its first and its second derivative (the edge and point detectors).
    feature: Vec<[f64; 3]>,
}

impl Kernels {
    fn new(ppd: f64) -> Self {
        Kernels { spatial: spatial_kernel(ppd), feature: feature_kernel(ppd) }
    }
}

/// The CSF parameters `(a, b)` of HPG 2020, section 4.1: the achromatic and red-green CSFs are one
/// Gaussian each, the blue-yellow CSF a sum of two; in the spatial domain each term is
/// `a sqrt(pi / b) exp(-pi^2 x^2 / b)` (x in degrees).
const CSF_Y: (f64, f64) = (1.0, 0.0047);
const CSF_CX: (f64, f64) = (1.0, 0.0053);
const CSF_CZ1: (f64, f64) = (34.1, 0.04);
const CSF_CZ2: (f64, f64) = (13.5, 0.025);

/// The 1D taps of the CSF filters (HPG 2020, section 4.1), radius `ceil(3 sqrt(b_max / (2 pi^2)) ppd)`
/// pixels (three standard deviations of the widest Gaussian). The achromatic and red-green filters are
/// separable Gaussians, normalised to sum 1; the blue-yellow one is the sum of two separable 2D
/// Gaussians, so each 1D factor carries the square root of its amplitude and both are scaled by
/// `1 / sqrt(S1^2 + S2^2)` (S the 1D sums), which makes the 2D filter sum to 1 (NVlabs/flip,
/// misc/separatedConvolutions.pdf). A constant image passes unchanged.
fn spatial_kernel(ppd: f64) -> Vec<[f64; 4]> {
    let pi = std::f64::consts::PI;
    let b_max = [CSF_Y.1, CSF_CX.1, CSF_CZ1.1, CSF_CZ2.1].into_iter().fold(0.0, f64::max);
    // The radius in f32, as the reference takes it.
    let pi32 = std::f32::consts::PI;
    let radius = (3.0 * (b_max as f32 / (2.0 * pi32 * pi32)).sqrt() * ppd as f32).ceil() as i64;
    let g = |x2: f64, (a, b): (f64, f64)| a * (pi / b).sqrt() * (-pi * pi * x2 / b).exp();
    let g_sqrt = |x2: f64, (a, b): (f64, f64)| (a * (pi / b).sqrt()).sqrt() * (-pi * pi * x2 / b).exp();
    let mut taps: Vec<[f64; 4]> = (-radius..=radius)
        .map(|i| {
            let x = i as f64 / ppd;
            let x2 = x * x;
            [g(x2, CSF_Y), g(x2, CSF_CX), g_sqrt(x2, CSF_CZ1), g_sqrt(x2, CSF_CZ2)]
        })
        .collect();
    let sum = |k: usize| taps.iter().map(|t| t[k]).sum::<f64>();
    let (sy, scx) = (sum(0), sum(1));
    let scz = sum(2).hypot(sum(3));
    for t in &mut taps {
        *t = [t[0] / sy, t[1] / scx, t[2] / scz, t[3] / scz];
    }
    taps
}

/// The 1D taps of the edge and point detectors (HPG 2020, section 4.2): a Gaussian of standard deviation
/// `sigma = 0.5 w ppd` pixels over radius `ceil(3 sigma)`, its first derivative `-x g` and its second
/// `(x^2 / sigma^2 - 1) g`. The Gaussian is normalised to sum 1; each derivative's positive and negative
/// taps are normalised to sum +1 and -1 separately, so a constant image has no edge and no point.
fn feature_kernel(ppd: f64) -> Vec<[f64; 3]> {
    let sigma = 0.5 * GW * ppd;
    let radius = (3.0 * (0.5 * GW as f32 * ppd as f32)).ceil() as i64;
    let mut taps: Vec<[f64; 3]> = (-radius..=radius)
        .map(|i| {
            let x = i as f64;
            let g = (-(x * x) / (2.0 * sigma * sigma)).exp();
            [g, -x * g, (x * x / (sigma * sigma) - 1.0) * g]
        })
        .collect();
    let g_sum: f64 = taps.iter().map(|t| t[0]).sum();
    let pos = |k: usize| taps.iter().map(|t| t[k].max(0.0)).sum::<f64>();
    let neg = |k: usize| taps.iter().map(|t| (-t[k]).max(0.0)).sum::<f64>();
    let (dp, dn, ddp, ddn) = (pos(1), neg(1), pos(2), neg(2));
    for t in &mut taps {
        let d = t[1] / if t[1] > 0.0 { dp } else { dn };
        let dd = t[2] / if t[2] > 0.0 { ddp } else { ddn };
        *t = [t[0] / g_sum, d, dd];
    }
    taps
}

/// The colour remapping of HPG 2020, section 4.1: `d = HyAB^q_c` is mapped linearly from `[0, p_c c_max)`
/// to `[0, p_t)` and from `[p_c c_max, c_max]` to `[p_t, 1]`, so that the many small differences get most
/// of the range.
fn remap_color(d: f64, cmax: f64) -> f64 {
    let pccmax = PC * cmax;
    if d < pccmax {
        d * PT / pccmax
    } else {
        PT + (d - pccmax) / (cmax - pccmax) * (1.0 - PT)
    }
}

#[cfg(test)]
/// The feature difference of HPG 2020, section 4.2, from the filtered `[dx, ddx, dy, ddy]` of the two
/// images: `((1 / sqrt 2) max(| |edge_r| - |edge_t| |, | |point_r| - |point_t| |))^q_f`.
fn feature_difference(r: [f64; 4], t: [f64; 4]) -> f64 {
    let edge = |f: [f64; 4]| f[0].hypot(f[2]);
    let point = |f: [f64; 4]| f[1].hypot(f[3]);
    let d = (edge(r) - edge(t)).abs().max((point(r) - point(t)).abs());
    (std::f64::consts::FRAC_1_SQRT_2 * d).powf(QF)
}

#[cfg(test)]
/// The colour error of one pixel from the two CSF-filtered YCxCz values (HPG 2020, section 4.1): back to
/// linear RGB, clamped to `[0, 1]`, to L*a*b*, Hunt-adjusted, HyAB, `^q_c`, remapped.
fn color_difference(r: [f64; 3], t: [f64; 3], cmax: f64) -> f64 {
    let lab = |c: [f64; 3]| color::hunt(color::linear_rgb_to_lab(color::ycxcz_to_linear_rgb(c).map(|v| v.clamp(0.0, 1.0))));
    remap_color(color::hyab(lab(r), lab(t)).powf(QC), cmax)
}

/// The final FLIP error of a pixel (HPG 2020, section 4.3): `colour^(1 - feature)`, the feature difference
/// raising a small colour error where edges or points differ.
fn combine(color: f64, feature: f64) -> f64 {
    color.powf(1.0 - feature)
}

/// One image's pixel after FLIP's filters: the CSF-filtered colour as Hunt-adjusted L*a*b* (HPG 2020,
/// section 4.1: back to linear RGB, clamped to `[0, 1]`) and the magnitudes of the edge and point
/// detectors' responses (section 4.2). A pixel's error depends on the two images only through these.
#[derive(Debug, Clone, Copy)]
struct Filtered {
    lab: [f64; 3],
    edge: f64,
    point: f64,
}

/// FLIP's filters on one YCxCz image (from linear RGB in `[0, 1]`): separated filtering, the horizontal
/// pass into an intermediate image (`f32`, as the reference stores it), the vertical pass accumulated row
/// by row (cache-friendly). Rows run in parallel.
fn filter(img: &[[f32; 3]], w: usize, h: usize, k: &Kernels) -> Vec<Filtered> {
    let avx2 = has_avx2();
    let mut mid = vec![[0f32; 7]; w * h];
    mid.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let s = &img[y * w..(y + 1) * w];
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: the CPU has AVX2 (`has_avx2`).
            return unsafe { horizontal_avx2(s, row, k) };
        }
        horizontal(s, row, k)
    });
    let mut out = vec![Filtered { lab: [0.0; 3], edge: 0.0, point: 0.0 }; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: the CPU has AVX2 (`has_avx2`).
            return unsafe { vertical_avx2(&mid, y, h, orow, k) };
        }
        vertical(&mid, y, h, orow, k)
    });
    out
}

/// Whether the filters may run with AVX2: the same operations in the same order, twice as wide (no
/// fused multiply-add, so the values are the same bits).
fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn horizontal_avx2(s: &[[f32; 3]], row: &mut [[f32; 7]], k: &Kernels) {
    horizontal(s, row, k)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn vertical_avx2(mid: &[[f32; 7]], y: usize, h: usize, orow: &mut [Filtered], k: &Kernels) {
    vertical(mid, y, h, orow, k)
}

/// The horizontal pass of one row `s` into `row`. Per pixel: Y, Cx, Cz*g1, Cz*g2 (CSF), then on the
/// normalised luminance (Y + 16) / 116: d/dx, d2/dx2 and the Gaussian (features).
#[inline(always)]
fn horizontal(s: &[[f32; 3]], row: &mut [[f32; 7]], k: &Kernels) {
    let w = s.len();
    let rs = (k.spatial.len() / 2) as isize;
    let rf = (k.feature.len() / 2) as isize;
    let clamp_x = |x: isize| x.clamp(0, w as isize - 1) as usize;
    let yn: Vec<f64> = s.iter().map(|p| (p[0] as f64 + 16.0) / 116.0).collect();
    for (x, o) in row.iter_mut().enumerate() {
        let mut a = [0f64; 7];
        for (i, kw) in k.spatial.iter().enumerate() {
            let p = s[clamp_x(x as isize + i as isize - rs)];
            a[0] += kw[0] * p[0] as f64;
            a[1] += kw[1] * p[1] as f64;
            a[2] += kw[2] * p[2] as f64;
            a[3] += kw[3] * p[2] as f64;
        }
        for (i, kf) in k.feature.iter().enumerate() {
            let v = yn[clamp_x(x as isize + i as isize - rf)];
            a[4] += kf[1] * v;
            a[5] += kf[2] * v;
            a[6] += kf[0] * v;
        }
        *o = a.map(|v| v as f32);
    }
}

/// The vertical pass of output row `y` from the horizontal pass `mid` (`h` rows of `orow.len()`),
/// accumulated row by row (cache-friendly), then the colours to Hunt-adjusted L*a*b* and the feature
/// magnitudes.
#[inline(always)]
fn vertical(mid: &[[f32; 7]], y: usize, h: usize, orow: &mut [Filtered], k: &Kernels) {
    let w = orow.len();
    let rs = (k.spatial.len() / 2) as isize;
    let rf = (k.feature.len() / 2) as isize;
    let reach = rs.max(rf);
    // Per pixel: Y, Cx, Cz (CSF-filtered), dx, ddx, dy, ddy.
    let mut acc = vec![[0f64; 7]; w];
    for d in -reach..=reach {
        let yy = (y as isize + d).clamp(0, h as isize - 1) as usize;
        let ks = (d.abs() <= rs).then(|| k.spatial[(d + rs) as usize]);
        let kf = (d.abs() <= rf).then(|| k.feature[(d + rf) as usize]);
        for (a, m) in acc.iter_mut().zip(&mid[yy * w..(yy + 1) * w]) {
            let m = m.map(|v| v as f64);
            if let Some(ks) = ks {
                a[0] += ks[0] * m[0];
                a[1] += ks[1] * m[1];
                a[2] += ks[2] * m[2] + ks[3] * m[3];
            }
            if let Some(kf) = kf {
                a[3] += kf[0] * m[4];
                a[4] += kf[0] * m[5];
                a[5] += kf[1] * m[6];
                a[6] += kf[2] * m[6];
            }
        }
    }
    for (o, a) in orow.iter_mut().zip(&acc) {
        let lab = color::hunt(color::linear_rgb_to_lab(color::ycxcz_to_linear_rgb([a[0], a[1], a[2]]).map(|v| v.clamp(0.0, 1.0))));
        *o = Filtered { lab, edge: a[3].hypot(a[5]), point: a[4].hypot(a[6]) };
    }
}

/// The FLIP error per pixel of two filtered images of one size: the colour error (HyAB, `^q_c`,
/// remapped) raised to `1 -` the feature difference.
fn errors(r: &[Filtered], t: &[Filtered]) -> Vec<f32> {
    let cmax = color::max_distance(QC);
    r.par_iter()
        .zip(t)
        .map(|(r, t)| {
            let color = remap_color(color::hyab(r.lab, t.lab).powf(QC), cmax);
            let d = (r.edge - t.edge).abs().max((r.point - t.point).abs());
            let feature = (std::f64::consts::FRAC_1_SQRT_2 * d).powf(QF);
            combine(color, feature) as f32
        })
        .collect()
}

/// The two-image LDR-FLIP pass as it was before the filters were split per image: the tests' check that
/// [`filter`] and [`errors`] change no value.
#[cfg(test)]
fn ldr_core(r: &[[f32; 3]], t: &[[f32; 3]], w: usize, h: usize, k: &Kernels) -> Vec<f32> {
    let rs = (k.spatial.len() / 2) as isize;
    let rf = (k.feature.len() / 2) as isize;
    let clamp_x = |x: isize| x.clamp(0, w as isize - 1) as usize;
    // Horizontal pass. Per pixel and image: Y, Cx, Cz*g1, Cz*g2 (CSF), then on the normalised
    // luminance (Y + 16) / 116: d/dx, d2/dx2 and the Gaussian (features).
    let mut mid = vec![[[0f32; 7]; 2]; w * h];
    mid.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let src = [&r[y * w..(y + 1) * w], &t[y * w..(y + 1) * w]];
        for (x, out) in row.iter_mut().enumerate() {
            for (s, o) in src.iter().zip(out.iter_mut()) {
                let mut a = [0f64; 7];
                for (i, kw) in k.spatial.iter().enumerate() {
                    let p = s[clamp_x(x as isize + i as isize - rs)];
                    a[0] += kw[0] * p[0] as f64;
                    a[1] += kw[1] * p[1] as f64;
                    a[2] += kw[2] * p[2] as f64;
                    a[3] += kw[3] * p[2] as f64;
                }
                for (i, kf) in k.feature.iter().enumerate() {
                    let yn = (s[clamp_x(x as isize + i as isize - rf)][0] as f64 + 16.0) / 116.0;
                    a[4] += kf[1] * yn;
                    a[5] += kf[2] * yn;
                    a[6] += kf[0] * yn;
                }
                *o = a.map(|v| v as f32);
            }
        }
    });
    let cmax = color::max_distance(QC);
    let reach = rs.max(rf);
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        // Per pixel and image: Y, Cx, Cz (CSF-filtered), dx, ddx, dy, ddy.
        let mut acc = vec![[[0f64; 7]; 2]; w];
        for d in -reach..=reach {
            let yy = (y as isize + d).clamp(0, h as isize - 1) as usize;
            let ks = (d.abs() <= rs).then(|| k.spatial[(d + rs) as usize]);
            let kf = (d.abs() <= rf).then(|| k.feature[(d + rf) as usize]);
            for (a2, m2) in acc.iter_mut().zip(&mid[yy * w..(yy + 1) * w]) {
                for (a, m) in a2.iter_mut().zip(m2) {
                    let m = m.map(|v| v as f64);
                    if let Some(ks) = ks {
                        a[0] += ks[0] * m[0];
                        a[1] += ks[1] * m[1];
                        a[2] += ks[2] * m[2] + ks[3] * m[3];
                    }
                    if let Some(kf) = kf {
                        a[3] += kf[0] * m[4];
                        a[4] += kf[0] * m[5];
                        a[5] += kf[1] * m[6];
                        a[6] += kf[2] * m[6];
                    }
                }
            }
        }
        for (o, [ar, at]) in orow.iter_mut().zip(&acc) {
            let color = color_difference([ar[0], ar[1], ar[2]], [at[0], at[1], at[2]], cmax);
            let feature = feature_difference([ar[3], ar[4], ar[5], ar[6]], [at[3], at[4], at[5], at[6]]);
            *o = combine(color, feature) as f32;
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(w: usize, h: usize, c: [f32; 3]) -> RgbImage {
        RgbImage::new(w, h, vec![c; w * h]).unwrap()
    }

    /// A deterministic textured HDR image (a highlight on a gradient, with a hash for noise).
    fn textured(w: usize, h: usize, gain: f32, seed: u32) -> RgbImage {
        let mut px = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 / w as f32 - 0.4, y as f32 / h as f32 - 0.45);
                let hl = 20.0 * (-(u * u + v * v) / 0.01).exp();
                let mut s = (x as u32).wrapping_mul(73_856_093) ^ (y as u32).wrapping_mul(19_349_663) ^ seed.wrapping_mul(83_492_791);
                s ^= s >> 13;
                s = s.wrapping_mul(0x5bd1_e995);
                let n = (s >> 8) as f32 / (1u32 << 24) as f32;
                let base = 0.05 + 0.3 * x as f32 / w as f32;
                px.push([gain * (hl + base + 0.05 * n), gain * (0.8 * hl + base), gain * (0.6 * hl + 0.5 * base + 0.02 * n)]);
            }
        }
        RgbImage::new(w, h, px).unwrap()
    }

    /// The colour error of two flat colours worked from the paper's formulas alone, independently of the
    /// module's colour code: linear sRGB -> XYZ with the sRGB matrix to four digits' tolerance (D65),
    /// CIE L*a*b*, Hunt, HyAB, `^0.7`, remapped; the feature term of a flat image is 0, so FLIP is this.
    fn flat_pair_by_hand(c1: [f64; 3], c2: [f64; 3]) -> f64 {
        // sRGB (IEC 61966-2-1) linear RGB -> XYZ, D65, the usual published four-digit matrix.
        let m = [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]];
        let white = [0.95047, 1.0, 1.08883];
        let lab = |c: [f64; 3]| {
            let xyz: Vec<f64> = (0..3).map(|i| (m[i][0] * c[0] + m[i][1] * c[1] + m[i][2] * c[2]) / white[i]).collect();
            let f = |t: f64| if t > 216.0 / 24389.0 { t.powf(1.0 / 3.0) } else { (24389.0 / 27.0 * t + 16.0) / 116.0 };
            let (fx, fy, fz) = (f(xyz[0]), f(xyz[1]), f(xyz[2]));
            let l = 116.0 * fy - 16.0;
            // Hunt: chroma times L / 100.
            [l, l / 100.0 * 500.0 * (fx - fy), l / 100.0 * 200.0 * (fy - fz)]
        };
        let hyab = |p: [f64; 3], q: [f64; 3]| (p[0] - q[0]).abs() + ((p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        let cmax = hyab(lab([0.0, 1.0, 0.0]), lab([0.0, 0.0, 1.0])).powf(0.7);
        let d = hyab(lab(c1), lab(c2)).powf(0.7);
        if d < 0.4 * cmax {
            d * 0.95 / (0.4 * cmax)
        } else {
            0.95 + (d - 0.4 * cmax) / (0.6 * cmax) * 0.05
        }
    }

    #[test]
    fn identical_images_give_exactly_zero() {
        let a = textured(48, 40, 1.0, 1);
        let m = hdr(&a, &a, DEFAULT_PPD, &HdrOptions::default()).unwrap();
        assert!(m.values().iter().all(|&v| v == 0.0));
        assert_eq!(m.mean(), 0.0);
        let l = textured(48, 40, 0.03, 2);
        let m = ldr(&l, &l, DEFAULT_PPD).unwrap();
        assert!(m.values().iter().all(|&v| v == 0.0));
    }

    #[test]
    fn flat_colour_difference_matches_the_formulas_by_hand() {
        // Below and above the knee at p_c c_max, grey and chromatic.
        let pairs = [
            ([0.2, 0.2, 0.2], [0.25, 0.2, 0.2]),
            ([0.5, 0.4, 0.3], [0.45, 0.42, 0.36]),
            ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
            ([1.0, 1.0, 1.0], [0.0, 0.0, 0.0]),
            ([0.9, 0.1, 0.1], [0.1, 0.1, 0.9]),
        ];
        for (c1, c2) in pairs {
            let (a, b) = (flat(24, 20, c1.map(|v| v as f32)), flat(24, 20, c2.map(|v| v as f32)));
            let m = ldr(&a, &b, DEFAULT_PPD).unwrap();
            let want = flat_pair_by_hand(c1, c2);
            for &v in m.values() {
                // The four-digit matrix of the hand computation differs from the reference's exact one
                // in the fifth digit.
                assert!((v as f64 - want).abs() < 2e-4, "{c1:?} vs {c2:?}: {v} by hand {want}");
            }
        }
        // Pure green against pure blue is c_max itself: exactly 1.
        let m = ldr(&flat(8, 8, [0.0, 1.0, 0.0]), &flat(8, 8, [0.0, 0.0, 1.0]), DEFAULT_PPD).unwrap();
        assert!(m.values().iter().all(|&v| (v - 1.0).abs() < 1e-6), "{}", m.get(0, 0));
    }

    #[test]
    fn filters_pass_a_constant_and_detect_no_feature() {
        for ppd in [10.0, DEFAULT_PPD, 150.0] {
            let s = spatial_kernel(ppd);
            let sum = |k: usize| s.iter().map(|t| t[k]).sum::<f64>();
            assert!((sum(0) - 1.0).abs() < 1e-12 && (sum(1) - 1.0).abs() < 1e-12);
            // The blue-yellow 2D filter sum(g1) sum(g1) + sum(g2) sum(g2) is 1.
            assert!((sum(2).powi(2) + sum(3).powi(2) - 1.0).abs() < 1e-12);
            let f = feature_kernel(ppd);
            let fs = |k: usize| f.iter().map(|t| t[k]).sum::<f64>();
            assert!((fs(0) - 1.0).abs() < 1e-12 && fs(1).abs() < 1e-12 && fs(2).abs() < 1e-12);
        }
        // Radii as the reference's at its default 67.02 ppd: 10 (CSF) and 9 (features).
        assert_eq!(spatial_kernel(DEFAULT_PPD).len(), 21);
        assert_eq!(feature_kernel(DEFAULT_PPD).len(), 19);
    }

    #[test]
    fn symmetric_in_reference_and_test() {
        // Every term is a distance (HyAB, absolute differences of feature magnitudes), so LDR-FLIP is
        // symmetric (HPG 2020 names FLIP a difference evaluator, not a one-sided metric).
        let (a, b) = (textured(40, 36, 0.04, 3), textured(40, 36, 0.035, 4));
        let (ab, ba) = (ldr(&a, &b, DEFAULT_PPD).unwrap(), ldr(&b, &a, DEFAULT_PPD).unwrap());
        assert_eq!(ab.values(), ba.values());
        // HDR-FLIP with the exposures fixed is symmetric too (the automatic ones come from the reference).
        let o = HdrOptions { start_exposure: Some(-2.0), stop_exposure: Some(3.0), num_exposures: None };
        let (ab, ba) = (hdr(&a, &b, DEFAULT_PPD, &o).unwrap(), hdr(&b, &a, DEFAULT_PPD, &o).unwrap());
        assert_eq!(ab.values(), ba.values());
        assert_eq!(ab.exposures().unwrap().count, 5);
    }

    #[test]
    fn hdr_is_the_max_of_ldr_over_the_exposures() {
        let (a, b) = (textured(32, 30, 1.0, 5), textured(32, 30, 1.2, 6));
        let m = hdr(&a, &b, DEFAULT_PPD, &HdrOptions::default()).unwrap();
        let e = m.exposures().unwrap();
        assert!(e.count >= 2 && e.start < e.stop);
        let mut max = vec![0f32; 32 * 30];
        for i in 0..e.count {
            let s = 2f64.powf(e.exposure(i));
            let tm = |img: &RgbImage| {
                RgbImage::new(32, 30, img.pixels().iter().map(|p| p.map(|v| aces(v as f64 * s).clamp(0.0, 1.0) as f32)).collect()).unwrap()
            };
            // Through f32 pixels: LDR-FLIP of the tone-mapped images, within f32 rounding.
            let l = ldr(&tm(&a), &tm(&b), DEFAULT_PPD).unwrap();
            for (m, v) in max.iter_mut().zip(l.values()) {
                *m = m.max(*v);
            }
        }
        for (x, y) in m.values().iter().zip(&max) {
            assert!((x - y).abs() < 1e-4, "{x} {y}");
        }
        // Every value is an error in [0, 1], and a brighter test differs somewhere.
        assert!(m.values().iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(m.mean() > 0.01);
    }

    /// One prepared reference scores several tests exactly as the two-image pass of the unsplit filters
    /// does per exposure (the maximum over the exposures, ties to the earlier one), and as [`hdr`].
    #[test]
    fn a_prepared_reference_equals_the_two_image_pass() {
        let reference = textured(37, 29, 1.0, 7);
        let o = HdrOptions { start_exposure: None, stop_exposure: None, num_exposures: Some(6) };
        let prepared = HdrReference::new(&reference, DEFAULT_PPD, &o).unwrap();
        let e = prepared.exposures();
        for (gain, seed) in [(1.3, 8), (0.9, 9), (1.0, 7)] {
            let test = textured(37, 29, gain, seed);
            let mut want = vec![0f32; 37 * 29];
            for i in 0..e.count {
                let k = Kernels::new(DEFAULT_PPD);
                let pair = ldr_core(&tone_mapped(&reference, e.exposure(i)), &tone_mapped(&test, e.exposure(i)), 37, 29, &k);
                want.iter_mut().zip(pair).for_each(|(m, v)| *m = m.max(v));
            }
            let got = prepared.map(&test).unwrap();
            let direct = hdr(&reference, &test, DEFAULT_PPD, &o).unwrap();
            for ((g, w), d) in got.values().iter().zip(&want).zip(direct.values()) {
                assert!((g - w).abs() as f64 <= 1e-12 && g == d, "{g} {w} {d}");
            }
            let mean = want.iter().map(|&v| v as f64).sum::<f64>() / want.len() as f64;
            assert!((prepared.mean(&test).unwrap() - mean).abs() <= 1e-12);
            assert_eq!(got.exposure_map(), direct.exposure_map());
        }
        assert_eq!(prepared.mean(&textured(36, 29, 1.0, 7)).unwrap_err().kind(), ErrorKind::InvalidInput);
    }

    #[test]
    fn automatic_exposures_follow_the_reference() {
        // Max luminance 1 maps to 0.85 at start = log2(x_0.85) = 1.0833 (the reference prints 1.0832973);
        // the median 0.25 (index n / 2 of 225) gives stop = start + 2.
        let mut px = vec![[0.5f32; 3]; 225];
        px[1..114].fill([0.25; 3]);
        px[0] = [1.0; 3];
        let img = RgbImage::new(15, 15, px).unwrap();
        let (start, stop) = auto_exposures(&img).unwrap();
        assert!((start - 1.0832973).abs() < 1e-6, "{start}");
        assert!((stop - (start + 2.0)).abs() < 1e-6, "{stop}");
        // A mostly black image: the median is raised to f32::EPSILON (stop = log2(x_0.85) + 23).
        let mut px = vec![[0.0f32; 3]; 100];
        px[0] = [1.0; 3];
        let (_, stop) = auto_exposures(&RgbImage::new(10, 10, px).unwrap()).unwrap();
        assert!((stop - 24.0832973).abs() < 1e-5, "{stop}");
        // An all-black reference has no range.
        let black = flat(4, 4, [0.0; 3]);
        assert_eq!(hdr(&black, &black, DEFAULT_PPD, &HdrOptions::default()).unwrap_err().kind(), ErrorKind::BadData);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = flat(4, 4, [0.1; 3]);
        assert_eq!(ldr(&a, &flat(4, 5, [0.1; 3]), DEFAULT_PPD).unwrap_err().kind(), ErrorKind::InvalidInput);
        assert_eq!(ldr(&a, &a, 0.0).unwrap_err().kind(), ErrorKind::InvalidInput);
        assert_eq!(RgbImage::new(2, 2, vec![[0.0; 3]; 3]).unwrap_err().kind(), ErrorKind::InvalidInput);
        assert_eq!(RgbImage::new(1, 1, vec![[f32::NAN, 0.0, 0.0]]).unwrap_err().kind(), ErrorKind::BadData);
        let o = HdrOptions { start_exposure: Some(2.0), stop_exposure: Some(1.0), num_exposures: None };
        assert_eq!(hdr(&a, &a, DEFAULT_PPD, &o).unwrap_err().kind(), ErrorKind::InvalidInput);
        // A single-pixel image is valid (edge clamping everywhere).
        let one = flat(1, 1, [0.3; 3]);
        assert_eq!(ldr(&one, &flat(1, 1, [0.3; 3]), DEFAULT_PPD).unwrap().mean(), 0.0);
    }

    #[test]
    fn default_ppd_and_magma() {
        assert!((DEFAULT_PPD - 67.020643).abs() < 1e-5);
        assert!((pixels_per_degree(0.7, 3840.0, 0.7) - DEFAULT_PPD).abs() < 1e-12);
        assert_eq!(magma(0.0), [0, 0, 4]);
        assert_eq!(magma(1.0), [252, 253, 191]);
        assert_eq!(magma(f32::NAN), magma(0.0));
    }
}
