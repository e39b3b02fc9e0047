//! Microfacet normals of a heightfield, as slopes `s = grad h` (Heitz eq. 61), by two schemes.
//!
//! On a regular grid every sample of either scheme has the same projected area (`dx dy` per central
//! stencil, `dx dy / 2` per triangle), so a count of samples is a projected-area measure and the
//! empirical NDF is `D_k = count_k / (N W_k)` (Heitz eq. 9; Walter et al. eq. 9).

use crate::scan::bands::HeightRows;

/// How normals are taken from the heights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalScheme {
    /// Central differences at every interior point whose 4 neighbours and itself are valid:
    /// `s = ((h[i][j+1] - h[i][j-1]) / 2dx, (h[i+1][j] - h[i-1][j]) / 2dy)`. Exact on quadratics.
    #[default]
    Central,
    /// The exact Gauss map of the triangulated surface: every grid cell split along its
    /// `(i, j+1)-(i+1, j)` diagonal into two triangles, each a plane facet of projected area `dx dy / 2`
    /// (forward differences). A triangle with an invalid corner is skipped.
    Triangles,
}

impl NormalScheme {
    /// The name used on the command line and in output files.
    pub fn as_str(self) -> &'static str {
        match self {
            NormalScheme::Central => "central",
            NormalScheme::Triangles => "triangles",
        }
    }

    /// Rows `i` whose samples [`NormalScheme::row_slopes`] visits.
    pub fn rows(self, hf: &impl HeightRows) -> std::ops::Range<usize> {
        let (nx, ny) = (hf.nx(), hf.ny());
        match self {
            NormalScheme::Central if ny >= 3 && nx >= 3 => 1..ny - 1,
            NormalScheme::Triangles if ny >= 2 && nx >= 2 => 0..ny - 1,
            _ => 0..0,
        }
    }

    /// The rows `lo..hi` the stencils of row `i` (one of [`NormalScheme::rows`]) read, within `0..ny`.
    pub fn stencil_rows(self, i: usize, ny: usize) -> (usize, usize) {
        match self {
            NormalScheme::Central => (i.saturating_sub(1), (i + 2).min(ny)),
            NormalScheme::Triangles => (i, (i + 2).min(ny)),
        }
    }

    /// Number of stencils (valid or not) in one row.
    pub fn per_row(self, hf: &impl HeightRows) -> usize {
        match self {
            NormalScheme::Central => hf.nx().saturating_sub(2),
            NormalScheme::Triangles => 2 * hf.nx().saturating_sub(1),
        }
    }

    /// Projected area of one sample in m^2.
    pub fn sample_area(self, hf: &impl HeightRows) -> f64 {
        match self {
            NormalScheme::Central => hf.dx() * hf.dy(),
            NormalScheme::Triangles => 0.5 * hf.dx() * hf.dy(),
        }
    }

    /// Spacing of the slope lattice of heights quantized in steps `q` (m): central differences give
    /// slopes in steps `q / (2 dx)`, `q / (2 dy)`; triangle facets (forward differences) `q / dx`, `q / dy`.
    pub fn slope_step(self, q: f64, dx: f64, dy: f64) -> [f64; 2] {
        match self {
            NormalScheme::Central => [q / (2.0 * dx), q / (2.0 * dy)],
            NormalScheme::Triangles => [q / dx, q / dy],
        }
    }

    /// Call `f(sx, sy)` for every valid sample of row `i` (one of [`NormalScheme::rows`]) with its
    /// slope `grad h`; return how many were valid. Stencils that touch a NaN are skipped (NaN propagates
    /// through the differences, so one test per sample suffices).
    #[inline(always)]
    pub fn row_slopes<H: HeightRows>(self, hf: &H, i: usize, stride: usize, mut f: impl FnMut(f64, f64)) -> u64 {
        let nx = hf.nx();
        let w = |v: H::T| -> f64 { v.into() };
        let mut valid = 0u64;
        match self {
            NormalScheme::Central => {
                let (r0, r1, r2) = (hf.row(i - 1), hf.row(i), hf.row(i + 1));
                let (kx, ky) = (0.5 / hf.dx(), 0.5 / hf.dy());
                let mut j = 1;
                while j + 1 < nx {
                    let sx = (w(r1[j + 1]) - w(r1[j - 1])) * kx;
                    let sy = (w(r2[j]) - w(r0[j])) * ky;
                    // The centre point is not in the differences but must be valid: a masked point is
                    // not surface, and its projected area must not count.
                    if !(sx + sy + w(r1[j])).is_nan() {
                        valid += 1;
                        f(sx, sy);
                    }
                    j += stride;
                }
            }
            NormalScheme::Triangles => {
                let (r0, r1) = (hf.row(i), hf.row(i + 1));
                let (kx, ky) = (1.0 / hf.dx(), 1.0 / hf.dy());
                let mut j = 0;
                while j + 1 < nx {
                    let (h00, h01, h10, h11) = (w(r0[j]), w(r0[j + 1]), w(r1[j]), w(r1[j + 1]));
                    // Lower triangle (i,j), (i,j+1), (i+1,j).
                    let (sx, sy) = ((h01 - h00) * kx, (h10 - h00) * ky);
                    if !(sx + sy).is_nan() {
                        valid += 1;
                        f(sx, sy);
                    }
                    // Upper triangle (i+1,j+1), (i+1,j), (i,j+1).
                    let (sx, sy) = ((h11 - h10) * kx, (h11 - h01) * ky);
                    if !(sx + sy).is_nan() {
                        valid += 1;
                        f(sx, sy);
                    }
                    j += stride;
                }
            }
        }
        valid
    }
}

impl std::str::FromStr for NormalScheme {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s {
            "central" => Ok(NormalScheme::Central),
            "triangles" => Ok(NormalScheme::Triangles),
            _ => Err(crate::Error::invalid(format!("unknown normal scheme '{s}' (expected central or triangles)"))),
        }
    }
}
