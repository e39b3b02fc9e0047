//! Quantized heights: instruments that store heights as integers times a step `q` (or a coarse float)
//! put the central-difference slopes on a lattice of step `q / (2 dx)`, `q / (2 dy)`
//! ([`NormalScheme::slope_step`]). Bins finer than the lattice then alternate between full and empty (a
//! comb) instead of estimating D. This module finds `q` from the data (or takes it from the reader's
//! pass before form removal, [`crate::scan::ScanMeta::height_quantum`]) and the lattice's offset
//! from the slopes. A rigid lattice (a plane removal shifts it, nothing more) gets bins that respect it
//! ([`super::lattice`]); a lattice smeared by a curved form removal caps the automatic grid so that every
//! central bin spans at least two lattice cells. Derivation: `data_formats/objective.md` ("Quantized
//! heights").

use super::normals::NormalScheme;
use super::SlopeFrame;
use crate::scan::bands::{BandSource, HeightRows};

/// Height differences examined to find the quantum (a strided subsample of adjacent pairs).
const QUANTUM_SAMPLE: usize = 1 << 16;
/// Fraction of the examined differences that must lie on the lattice `k q`.
const ON_LATTICE: f64 = 0.99;
/// A difference is on the lattice when `|d / q - round(d / q)|` is below this (covers the rounding of
/// a unit conversion of integer file values, ~1e-12 relative, with a wide margin).
const LATTICE_SLACK: f64 = 1e-3;
/// The 90th percentile of the nonzero differences spanning at least this many steps shows a lattice
/// (a tilted plane's differences are all equal: one "step", no lattice to speak of).
const MIN_STEPS: f64 = 2.0;
/// Or, for the coarsest lattices (a few height levels, where nearly every difference is 0 or one step):
/// at least two multiples `k q` (zero included) each held by this fraction of the examined differences.
/// A tilted plane's differences hold a single multiple.
const MIN_LEVEL_SHARE: f64 = 0.01;
/// The quantum is reported only when the slope lattice step, whitened, is at least this fraction of the
/// slope scale (an f32 file's ulp is a lattice too, but one far too fine to matter).
pub const MATERIAL_STEP: f64 = 1e-3;
/// Resultant length of the slopes' lattice phase (per axis) above which the lattice is rigid: every
/// slope sits on `offset + k step` up to rounding (1), against ~0 for a lattice smeared by a curved form.
pub const RIGID: f64 = 0.9;
/// Largest whitened lattice step at which the scan resolves its NDF. Rounding smooths the slope
/// distribution by the kernel of two height roundings ([`rounding_kernel`]), which the fit models; past
/// half the slope scale a few nodes carry the lobe and the rounding error depends on the slope, so
/// coarser lattices leave a fit the data cannot support (`unresolved`).
pub const MAX_RESOLVED_STEP: f64 = 0.5;
/// Smallest whitened lattice step whose rounding the fit models: below it the rounding widens alpha by
/// under `r^2 / 12` = 1e-4 relative, far inside any scan's counting noise.
pub const MODELLED_STEP: f64 = 0.035;

/// Covariance of the slope error that rounding the heights to the lattice adds, for the lattice
/// `step` of `scheme`: each slope is a difference of two heights, each rounded by an error uniform over
/// one quantum (variance `q^2 / 12`), so each slope axis gets the triangle of half-width `step`
/// (variance `step^2 / 6`). Central differences read four distinct heights (the axes are independent);
/// a triangle's two differences share a corner, whose error enters both with the same sign.
pub fn rounding_kernel(scheme: NormalScheme, step: [f64; 2]) -> [[f64; 2]; 2] {
    let (vx, vy) = (step[0] * step[0] / 6.0, step[1] * step[1] / 6.0);
    let c = match scheme {
        NormalScheme::Central => 0.0,
        NormalScheme::Triangles => step[0] * step[1] / 12.0,
    };
    [[vx, c], [c, vy]]
}

/// The slope lattice of a rigidly quantized scan: every slope is `offset + (i step_x, j step_y)`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlopeLattice {
    /// A node of the lattice (the phase of the slopes; a removed plane's slope moves it).
    pub offset: [f64; 2],
    /// Node spacing along x and y ([`NormalScheme::slope_step`]).
    pub step: [f64; 2],
}

/// Heights found on a lattice `z0 + k q`, and what it does to the binning.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeightQuantum {
    /// The height step `q` (m).
    pub quantum: f64,
    /// Spacing of the slope lattice along x and y ([`NormalScheme::slope_step`]).
    pub slope_step: [f64; 2],
    /// Lengths of the two lattice steps in whitened slope units (`|W e_x| step_x`, `|W e_y| step_y`).
    pub whitened_step: [f64; 2],
    /// Fraction of the examined adjacent height differences that are multiples of `q`.
    pub on_lattice: f64,
    /// Most cells across the Lambert disk for which every central bin spans two lattice cells
    /// (`2 sqrt 2 / (2 (l_x + l_y))`, odd, at least 3): near `p = 0` a bin of side `h` covers `h` of
    /// whitened slope, and a square of side `l_x + l_y` (the lattice's covering diameter) always holds
    /// a lattice node.
    pub max_cells: usize,
    /// Cells across the grid would have had without the cap (`None` when the cap did not bind).
    pub coarsened_from: Option<usize>,
    /// Resultant length of the slopes' phase on the lattice, per axis (1: every slope on a node).
    pub rigidity: [f64; 2],
    /// The rigid slope lattice the bins respect (`None` when the lattice is smeared, and the grid is
    /// capped instead).
    pub lattice: Option<SlopeLattice>,
}

impl HeightQuantum {
    /// Whether the lattice is fine enough against the slope scale to resolve the NDF
    /// (`MAX_RESOLVED_STEP`).
    pub fn resolves_ndf(&self) -> bool {
        self.whitened_step[0].max(self.whitened_step[1]) <= MAX_RESOLVED_STEP
    }

    /// Why the scan cannot resolve its NDF, when the lattice is too coarse (one line).
    pub fn unresolved_reason(&self) -> Option<String> {
        (!self.resolves_ndf()).then(|| {
            format!(
                "heights are quantized in steps of {:.3e} m: the slope lattice ({:.3e} x {:.3e}) is {:.2} of the slope scale, above {}: the scan cannot resolve its NDF",
                self.quantum,
                self.slope_step[0],
                self.slope_step[1],
                self.whitened_step[0].max(self.whitened_step[1]),
                MAX_RESOLVED_STEP
            )
        })
    }
}

/// A height step `q` and the fraction of the examined differences on its lattice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Lattice {
    q: f64,
    on: f64,
}

impl Lattice {
    /// A quantum known from elsewhere (found on the heights before form removal).
    pub(crate) fn known(q: f64) -> Option<Lattice> {
        (q.is_finite() && q > 0.0).then_some(Lattice { q, on: 1.0 })
    }
}

/// The height quantum of the raw heights, if they are on a lattice (as [`lattice`]).
pub fn height_quantum<S: BandSource>(hf: &S) -> Option<f64> {
    lattice(hf).map(|l| l.q)
}

/// The lattice phase of a sample of slopes: per axis, the circular mean of `2 pi s / step` gives the
/// offset of the nodes and its resultant length the rigidity (1 when every slope is on a node).
pub(crate) fn phase(sample: &[[f64; 2]], step: [f64; 2]) -> ([f64; 2], [f64; 2]) {
    let mut offset = [0.0; 2];
    let mut rigidity = [0.0; 2];
    for a in 0..2 {
        let (mut c, mut s) = (0.0, 0.0);
        for v in sample {
            // Reduce first: s / step can be large, and the angle's rounding must stay far below a node.
            let f = v[a] / step[a];
            let t = std::f64::consts::TAU * (f - f.round());
            c += t.cos();
            s += t.sin();
        }
        let n = sample.len().max(1) as f64;
        rigidity[a] = (c.hypot(s) / n).min(1.0);
        offset[a] = s.atan2(c) / std::f64::consts::TAU * step[a];
    }
    (offset, rigidity)
}

/// Find the height quantum of a scan: `q` is the smallest nonzero adjacent height difference (ignoring
/// differences below 1e-6 of the 90th percentile, which are rounding specks) when at least 99% of the
/// examined differences are integer multiples of it and they show more than one step: the 90th
/// percentile of the nonzero ones spans at least two steps, or two multiples (zero included) each hold
/// at least 1% of them (the coarsest lattices, whose differences are mostly 0 and one step).
/// `None` when the heights are not on a lattice, when
/// too few differences are nonzero to tell (fewer than 100), or when the lattice is immaterial
/// ([`MATERIAL_STEP`], judged by [`assess`], the frame half of the rule).
///
/// This is the data half (no frame needed, so it can run beside the frame's estimation).
pub(crate) fn lattice<S: BandSource>(src: &S) -> Option<Lattice> {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    let mut buf = Vec::new();
    if nx < 2 || ny < 1 {
        return None;
    }
    let per_row = nx - 1;
    let row_stride = ((ny * per_row) / QUANTUM_SAMPLE).max(1).min(ny);
    let mut d: Vec<f64> = Vec::with_capacity(QUANTUM_SAMPLE.min(ny * per_row) + nx);
    for i in (0..ny).step_by(row_stride) {
        let band = src.band(i, i + 1, &mut buf);
        let r = band.row(i);
        for j in 0..per_row {
            let v = r[j + 1].into() - r[j].into();
            if v.is_finite() {
                d.push(v.abs());
            }
        }
        if d.len() >= QUANTUM_SAMPLE {
            break;
        }
    }
    let mut nz: Vec<f64> = d.iter().copied().filter(|&v| v > 0.0).collect();
    if nz.len() < 100 {
        return None;
    }
    // Selection reorders `nz`; the minimum below does not care about the order.
    let k90 = (0.9 * (nz.len() - 1) as f64) as usize;
    let p90 = *nz.select_nth_unstable_by(k90, |a, b| a.total_cmp(b)).1;
    let q = nz.iter().copied().filter(|&v| v >= 1e-6 * p90).fold(f64::INFINITY, f64::min);
    if !(q.is_finite() && q > 0.0) {
        return None;
    }
    let on = d.iter().filter(|&&v| (v / q - (v / q).round()).abs() <= LATTICE_SLACK).count() as f64 / d.len() as f64;
    // A lattice needs several steps in the data: a plane (every difference equal) is not quantized.
    if on < ON_LATTICE || !(p90 >= MIN_STEPS * q || two_levels(&d, q)) {
        return None;
    }
    Some(Lattice { q, on })
}

/// Whether at least two multiples `k q` of the differences `d` (zero included) each hold
/// [`MIN_LEVEL_SHARE`] of them.
fn two_levels(d: &[f64], q: f64) -> bool {
    let mut counts = std::collections::HashMap::<u64, usize>::new();
    for &v in d {
        let k = (v / q).round();
        if k.is_finite() && k >= 0.0 {
            *counts.entry(k as u64).or_default() += 1;
        }
    }
    let least = MIN_LEVEL_SHARE * d.len() as f64;
    counts.values().filter(|&&c| c as f64 >= least).count() >= 2
}

/// The frame half of the rule of [`lattice`]: whether the lattice is material in the frame's whitened slopes, and
/// the cap it puts on the grid.
pub(crate) fn assess<H: HeightRows>(lat: Lattice, hf: &H, scheme: NormalScheme, frame: &SlopeFrame) -> Option<HeightQuantum> {
    let Lattice { q, on } = lat;
    let step = scheme.slope_step(q, hf.dx(), hf.dy());
    let w = frame.whiten;
    let lx = w[0][0].hypot(w[1][0]) * step[0];
    let ly = w[0][1].hypot(w[1][1]) * step[1];
    if lx.max(ly) < MATERIAL_STEP {
        return None;
    }
    let cap = (2.0 * super::frame::LAMBERT_RADIUS / (2.0 * (lx + ly))).floor();
    // Odd, at least 3 (a finer lattice than the whole disk still gets the coarsest grid).
    let cap = if cap.is_finite() { (cap as usize).clamp(3, super::grid::MAX_CELLS_ACROSS) } else { 3 };
    let cap = if cap % 2 == 0 { cap - 1 } else { cap };
    Some(HeightQuantum {
        quantum: q,
        slope_step: step,
        whitened_step: [lx, ly],
        on_lattice: on,
        max_cells: cap,
        coarsened_from: None,
        rigidity: [0.0; 2],
        lattice: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::Scan;

    fn scan(nx: usize, ny: usize, z: &[f64]) -> Scan<'_> {
        Scan::from_view(ndarray::ArrayView2::from_shape((ny, nx), z).unwrap(), 1e-6, 1e-6).unwrap()
    }

    /// A smooth surface rounded to a step `q` so coarse that every adjacent difference is 0 or one step
    /// (a handful of levels): the lattice is `q`, counted from the heights here; the rule of the 90th
    /// percentile alone misses it (it spans one step).
    #[test]
    fn the_coarsest_lattice_is_found() {
        let (nx, ny) = (300, 280);
        let q = 5e-7;
        let z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                q * ((4e-6 * (0.05 * j).sin() * (0.04 * i).cos() + 3e-6 * (0.031 * (i + j)).sin()) / q).round()
            })
            .collect();
        let (mut steps, mut zeros, mut levels) = (0, 0, std::collections::BTreeSet::new());
        for i in 0..ny {
            for j in 0..nx - 1 {
                let d = ((z[i * nx + j + 1] - z[i * nx + j]) / q).round().abs() as i64;
                assert!(d <= 1, "a difference of {d} steps");
                steps += usize::from(d == 1);
                zeros += usize::from(d == 0);
            }
        }
        z.iter().for_each(|v| {
            levels.insert((v / q).round() as i64);
        });
        assert!(steps > 1000 && zeros > steps && levels.len() < 60, "{steps} steps, {zeros} zeros, {} levels", levels.len());
        let got = height_quantum(&scan(nx, ny, &z)).expect("the lattice is found");
        assert!((got / q - 1.0).abs() < 1e-9, "quantum {got} against {q}");
    }

    /// A tilted plane's differences are all equal (one "step", exact or up to rounding): no lattice,
    /// even when its heights are exact multiples of that step.
    #[test]
    fn a_tilted_plane_has_no_lattice() {
        let (nx, ny) = (200, 150);
        let exact: Vec<f64> = (0..nx * ny).map(|k| 3e-9 * ((k % nx) as f64 + 2.0 * (k / nx) as f64)).collect();
        assert_eq!(height_quantum(&scan(nx, ny, &exact)), None);
        let plane: Vec<f64> = (0..nx * ny).map(|k| 1e-3 + 0.013 * (k % nx) as f64 * 1e-6 - 0.007 * (k / nx) as f64 * 1e-6).collect();
        assert_eq!(height_quantum(&scan(nx, ny, &plane)), None);
    }
}
