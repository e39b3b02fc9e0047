//! A profile: a scan under three samples across one axis (a profilometer's trace, or two), whose slopes
//! are measured along the other axis only. Its NDF is the Gauss map of the profiles extruded across them
//! (every normal in the plane of the profile and `z`): what the instrument measured, no more. The report
//! says so, and what one isotropic Beckmann lobe would be were the surface isotropic.

use crate::error::Result;
use crate::fit::{FitReport, Verdict};
use crate::ndf::{EmpiricalNdf, NdfOptions};
use crate::scan::{BandSource, GridShape, Heightfield};

/// The profiles of a scan under three samples across one axis, or of a grid whose valid points form lines.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// `'x'`: the rows are the profiles; `'y'`: the columns.
    pub along: char,
    /// Profiles (rows or columns) with at least one slope.
    pub count: usize,
    /// Samples per profile.
    pub samples: usize,
    /// RMS of the central-difference slopes along the profiles (ISO 4287's `R_dq`).
    pub rdq: f64,
    /// The rows or columns that are the profiles.
    lines: Vec<usize>,
}

impl Profile {
    /// The profiles of `scan` (residual heights) when it is under three samples across one axis and at least
    /// three along the other; `None` otherwise (an areal scan, or one without a slope).
    pub fn of<S: BandSource<T = f64>>(scan: &S) -> Option<Profile> {
        let g = scan.shape();
        let along = match (g.nx >= 3, g.ny >= 3) {
            (true, false) => 'x',
            (false, true) => 'y',
            _ => return None,
        };
        let mut buf = Vec::new();
        let band = scan.band(0, g.ny, &mut buf);
        Self::along(band.values(), g, along).map(|c| c.profile)
    }

    /// The profiles of a grid whose valid points form lines and no areal stencil (a trace stored in an areal
    /// format): its rows or columns, whichever hold more slopes; `None` without a slope.
    pub fn in_lines<S: BandSource<T = f64>>(scan: &S) -> Option<Profile> {
        let g = scan.shape();
        let mut buf = Vec::new();
        let band = scan.band(0, g.ny, &mut buf);
        let slopes = |p: &Option<Counted>| p.as_ref().map_or(0, |p| p.slopes);
        let (x, y) = (Self::along(band.values(), g, 'x'), Self::along(band.values(), g, 'y'));
        if slopes(&x) >= slopes(&y) { x } else { y }.map(|p| p.profile)
    }

    /// The rows (`'x'`) or columns (`'y'`) of the heights `z` (shape `g`) with a valid central slope, and those
    /// slopes' count.
    fn along(z: &[f64], g: GridShape, along: char) -> Option<Counted> {
        let (count, samples, step) = if along == 'x' { (g.ny, g.nx, g.dx) } else { (g.nx, g.ny, g.dy) };
        let at = |p: usize, k: usize| if along == 'x' { z[p * g.nx + k] } else { z[k * g.nx + p] };
        let (mut sum, mut n, mut lines) = (0.0, 0usize, Vec::new());
        for p in 0..count {
            let before = n;
            for k in 1..samples.saturating_sub(1) {
                let s = (at(p, k + 1) - at(p, k - 1)) / (2.0 * step);
                if s.is_finite() && at(p, k).is_finite() {
                    sum += s * s;
                    n += 1;
                }
            }
            if n > before {
                lines.push(p);
            }
        }
        (n > 0).then(|| Counted { profile: Profile { along, count: lines.len(), samples, rdq: (sum / n as f64).sqrt(), lines }, slopes: n })
    }

    /// Beckmann's `alpha` of an isotropic surface whose profiles these are: its slope along any axis has the
    /// variance `alpha^2 / 2` (Heitz 2014, section 5, footnote 3: Beckmann's slopes are Gaussian of covariance
    /// `alpha^2 / 2` per axis), so `alpha = sqrt(2) R_dq`.
    pub fn isotropic_alpha(&self) -> f64 {
        std::f64::consts::SQRT_2 * self.rdq
    }

    /// What the report says of a profile, in one sentence.
    pub fn sentence(&self) -> String {
        let (axis, across) = match (self.along, self.count) {
            ('x', 1) => ("row", "y"),
            ('x', _) => ("rows", "y"),
            (_, 1) => ("column", "x"),
            _ => ("columns", "x"),
        };
        format!(
            "a profile ({} {axis} of {} samples): its slopes along {across} are not measured, and its NDF is that of the profiles extruded along {across}; were the surface isotropic, one Beckmann lobe of alpha sqrt(2) R_dq = {:.4} would stand for it",
            self.count,
            self.samples,
            self.isotropic_alpha()
        )
    }

    /// The empirical NDF of the profiles of `scan` extruded across them: each profile three times (the
    /// central stencil of the middle copy and the triangles between the copies see no slope across), the
    /// profiles apart by a row of invalid points; no resolution test. The warning says what it is.
    pub fn extruded_ndf<S: BandSource<T = f64>>(&self, scan: &S, opts: &NdfOptions) -> Result<EmpiricalNdf> {
        let g = scan.shape();
        let mut buf = Vec::new();
        let band = scan.band(0, g.ny, &mut buf);
        let z = band.values();
        let width = 4 * self.count - 1;
        let (nx, ny) = if self.along == 'x' { (g.nx, width) } else { (width, g.ny) };
        let mut out = vec![f64::NAN; nx * ny];
        for (q, &p) in self.lines.iter().enumerate() {
            for k in 0..self.samples {
                let h = if self.along == 'x' { z[p * g.nx + k] } else { z[k * g.nx + p] };
                for c in 4 * q..4 * q + 3 {
                    let at = if self.along == 'x' { c * nx + k } else { k * nx + c };
                    out[at] = h;
                }
            }
        }
        let hf = Heightfield::new(nx, ny, g.dx, g.dy, out)?;
        // The resolution test takes slopes over twice the step across the profile too, where there is none:
        // a profile's tail is not tested (as `--tail all`).
        let mut ndf = crate::ndf::empirical_ndf(&hf, &NdfOptions { resolution: Some(false), ..opts.clone() })?;
        ndf.warnings.insert(0, format!("profile: {}", self.sentence()));
        Ok(ndf)
    }

    /// Say in `report` that its scan is a profile: the sentence among the reasons; where the answer rests on
    /// the slopes (no mirror answer), a verdict `ok` becomes `unresolved`, with the reason in the warnings.
    pub fn mark(&self, report: &mut FitReport) {
        let sentence = self.sentence();
        let mirror = report.selection.as_ref().and_then(|s| s.answer.as_deref()).is_some_and(|a| a.contains("mirror"));
        let q = &mut report.quality;
        if !mirror && q.verdict == Verdict::Ok {
            q.verdict = Verdict::Unresolved;
            q.reasons.insert(0, sentence.clone());
            report.warnings.push(format!("unresolved: {sentence}"));
        } else {
            q.reasons.push(sentence);
        }
    }
}

/// A profile and the count of its slopes.
struct Counted {
    profile: Profile,
    slopes: usize,
}
