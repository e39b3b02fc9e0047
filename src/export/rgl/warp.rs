//! The sample warp of a tabulated density, as Mitsuba 3's `Marginal2D` (continuous variant) and pbrt-v4's
//! `PiecewiseLinear2D` define it: `p(x, y)` bilinear between nodes at `x_i = i / (w - 1)`,
//! `y_j = j / (h - 1)` of the unit square; a uniform `(s_x, s_y)` maps through the inverse marginal CDF of
//! `y` and then the inverse conditional CDF of `x` given `y` (Dupuy & Jakob 2018, section 4). The writer
//! needs the forward map to place the spectra on the nodes of the sample space.

/// A density on the unit square, bilinear between `w x h` node values (row-major, `x` fastest).
pub struct Bilinear<'a> {
    data: &'a [f64],
    w: usize,
    h: usize,
    /// Integral of each node row over `x` (`h` values).
    row: Vec<f64>,
    /// Cumulative integral over `y` at each node row (`h` values, from 0).
    marginal: Vec<f64>,
    /// Cumulative integral over `x` along each node row, at each node (`w x h` values, from 0).
    cond: Vec<f64>,
}

impl<'a> Bilinear<'a> {
    /// The density of `data` (`w x h`, both at least 2, values `>= 0`).
    pub fn new(data: &'a [f64], w: usize, h: usize) -> Bilinear<'a> {
        let dx = 1.0 / (w - 1) as f64;
        let dy = 1.0 / (h - 1) as f64;
        let row: Vec<f64> = (0..h).map(|j| trapezoid(&data[j * w..(j + 1) * w], dx)).collect();
        let mut marginal = vec![0.0; h];
        for j in 1..h {
            marginal[j] = marginal[j - 1] + 0.5 * dy * (row[j - 1] + row[j]);
        }
        let mut cond = vec![0.0; w * h];
        for j in 0..h {
            for i in 1..w {
                cond[j * w + i] = cond[j * w + i - 1] + 0.5 * dx * (data[j * w + i - 1] + data[j * w + i]);
            }
        }
        Bilinear { data, w, h, row, marginal, cond }
    }

    /// The normalized density at `u` (clamped into the unit square): the bilinear value over the total.
    pub fn density(&self, u: [f64; 2]) -> f64 {
        let t = self.total();
        if t > 0.0 {
            super::bilinear(self.data, self.w, u) / t
        } else {
            0.0
        }
    }

    /// The uniform sample that [`Bilinear::sample`] maps to `u` (clamped into the unit square): the
    /// marginal CDF of `y`, then the conditional CDF of `x` at that `y`.
    pub fn invert(&self, u: [f64; 2]) -> [f64; 2] {
        let (w, h) = (self.w, self.h);
        let (dx, dy) = (1.0 / (w - 1) as f64, 1.0 / (h - 1) as f64);
        let cell = |t: f64, n: usize| {
            let p = t.clamp(0.0, 1.0) * (n - 1) as f64;
            let i = (p as usize).min(n - 2);
            (i, p - i as f64)
        };
        let ((i, tx), (j, ty)) = (cell(u[0], w), cell(u[1], h));
        let total = self.total();
        if !(total > 0.0) {
            return [u[0].clamp(0.0, 1.0), u[1].clamp(0.0, 1.0)];
        }
        let (r0, r1) = (self.row[j], self.row[j + 1]);
        let sy = (self.marginal[j] + dy * ty * (r0 + 0.5 * (r1 - r0) * ty)) / total;
        // The conditional at y: the rows' values and cumulative sums interpolated linearly between rows.
        let lerp = |a: f64, b: f64| a + (b - a) * ty;
        let line_total = lerp(r0, r1);
        if !(line_total > 0.0) {
            return [u[0].clamp(0.0, 1.0), sy.clamp(0.0, 1.0)];
        }
        let (v0, v1) =
            (lerp(self.data[j * w + i], self.data[(j + 1) * w + i]), lerp(self.data[j * w + i + 1], self.data[(j + 1) * w + i + 1]));
        let before = lerp(self.cond[j * w + i], self.cond[(j + 1) * w + i]);
        let sx = (before + dx * tx * (v0 + 0.5 * (v1 - v0) * tx)) / line_total;
        [sx.clamp(0.0, 1.0), sy.clamp(0.0, 1.0)]
    }

    /// The total integral over the unit square.
    pub fn total(&self) -> f64 {
        self.marginal[self.h - 1]
    }

    /// The point of the unit square that the uniform sample `s` maps to (`s` clamped into `[0, 1]`).
    pub fn sample(&self, s: [f64; 2]) -> [f64; 2] {
        let (w, h) = (self.w, self.h);
        let (dx, dy) = (1.0 / (w - 1) as f64, 1.0 / (h - 1) as f64);
        // A density that vanishes everywhere has no inverse CDF; the identity stands in for it.
        if !(self.total() > 0.0) {
            return [s[0].clamp(0.0, 1.0), s[1].clamp(0.0, 1.0)];
        }
        // Marginal in y: the row integral is linear between node rows.
        let target = s[1].clamp(0.0, 1.0) * self.total();
        let j = self.marginal[1..h - 1].partition_point(|&c| c < target);
        let ty = segment(target - self.marginal[j], dy, self.row[j], self.row[j + 1]);
        let y = (j as f64 + ty) * dy;
        // Conditional in x at that y: the rows interpolated, then linear within each column.
        let (r0, r1) = (&self.data[j * w..(j + 1) * w], &self.data[(j + 1) * w..(j + 2) * w]);
        let line: Vec<f64> = r0.iter().zip(r1).map(|(a, b)| a + (b - a) * ty).collect();
        let mut cdf = vec![0.0; w];
        for i in 1..w {
            cdf[i] = cdf[i - 1] + 0.5 * dx * (line[i - 1] + line[i]);
        }
        let total = cdf[w - 1];
        if !(total > 0.0) {
            return [s[0].clamp(0.0, 1.0), y];
        }
        let target = s[0].clamp(0.0, 1.0) * total;
        let i = cdf[1..w - 1].partition_point(|&c| c < target);
        let tx = segment(target - cdf[i], dx, line[i], line[i + 1]);
        [(i as f64 + tx) * dx, y]
    }
}

/// Integral of a piecewise-linear function with node spacing `d`.
fn trapezoid(v: &[f64], d: f64) -> f64 {
    v.windows(2).map(|p| 0.5 * d * (p[0] + p[1])).sum()
}

/// The fraction `t` of a segment of width `d` with a density linear from `v0` to `v1` at which the mass
/// `d (v0 t + (v1 - v0) t^2 / 2)` reaches `mass`; clamped into `[0, 1]`.
fn segment(mass: f64, d: f64, v0: f64, v1: f64) -> f64 {
    let m = (mass / d).max(0.0);
    let a = v1 - v0;
    let t = if a.abs() <= 1e-12 * (v0.abs() + v1.abs()) {
        if v0 > 0.0 {
            m / v0
        } else {
            0.5
        }
    } else {
        // The root of a t^2 / 2 + v0 t - m = 0 in [0, 1], in the form that does not cancel.
        let disc = (v0 * v0 + 2.0 * a * m).max(0.0);
        2.0 * m / (v0 + disc.sqrt())
    };
    if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `invert` undoes `sample` wherever the density is positive.
    #[test]
    fn invert_undoes_sample() {
        let (w, h) = (6, 5);
        let data: Vec<f64> = (0..w * h).map(|k| 0.1 + ((k * 7919) % 11) as f64 / 11.0).collect();
        let b = Bilinear::new(&data, w, h);
        for a in 0..37 {
            for c in 0..29 {
                let s = [(a as f64 + 0.3) / 37.0, (c as f64 + 0.6) / 29.0];
                let back = b.invert(b.sample(s));
                assert!((back[0] - s[0]).abs() < 1e-9 && (back[1] - s[1]).abs() < 1e-9, "{s:?} -> {back:?}");
            }
        }
    }

    /// The map sends the uniform measure to the density: the mass of `[0, x] x [0, y]` under the density
    /// equals the measure of the samples' preimage, checked by a midpoint sum over a fine grid of `s`.
    #[test]
    fn sample_follows_the_density() {
        let (w, h) = (5, 4);
        let data: Vec<f64> = (0..w * h).map(|k| 0.2 + ((k * 7919) % 13) as f64 / 13.0).collect();
        let b = Bilinear::new(&data, w, h);
        let n = 400;
        let (qx, qy) = (0.37, 0.61);
        let mut inside = 0usize;
        for a in 0..n {
            for c in 0..n {
                let p = b.sample([(a as f64 + 0.5) / n as f64, (c as f64 + 0.5) / n as f64]);
                inside += usize::from(p[0] <= qx && p[1] <= qy);
            }
        }
        // The mass of the same rectangle by a fine midpoint rule over the bilinear density.
        let m = 2000;
        let mut mass = 0.0;
        for a in 0..m {
            for c in 0..m {
                let (x, y) = ((a as f64 + 0.5) / m as f64 * qx, (c as f64 + 0.5) / m as f64 * qy);
                let (fx, fy) = (x * (w - 1) as f64, y * (h - 1) as f64);
                let (i, j) = ((fx as usize).min(w - 2), (fy as usize).min(h - 2));
                let (tx, ty) = (fx - i as f64, fy - j as f64);
                let v = |i: usize, j: usize| data[j * w + i];
                let d = (1.0 - tx) * (1.0 - ty) * v(i, j)
                    + tx * (1.0 - ty) * v(i + 1, j)
                    + (1.0 - tx) * ty * v(i, j + 1)
                    + tx * ty * v(i + 1, j + 1);
                mass += d * qx * qy / (m * m) as f64;
            }
        }
        let frac = inside as f64 / (n * n) as f64;
        assert!((frac - mass / b.total()).abs() < 3e-3, "{frac} vs {}", mass / b.total());
    }
}
