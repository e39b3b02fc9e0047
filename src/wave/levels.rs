//! The levels of `v_z` at which the patches' spectra are computed, and the cubic interpolation between
//! them in `ln v_z`.
//!
//! A patch's diffracted field depends on the outgoing direction through `v_t` (the FFT's frequency) and
//! `v_z = k (cos t_i + cos t_o)` (the phase `v_z h`). Each FFT bin has its own `v_z`, so the spectra are
//! computed at a ladder of `v_z` values covering every bin that a queried wavelength and incidence reaches,
//! and each bin reads its intensity between the two levels around its own `v_z`. The patch-averaged
//! intensity is a smooth function of `v_z` (the characteristic functions of height differences), which a
//! cubic in `ln v_z` with neighbours `ratio` apart follows to well below the speckle noise
//! (docs/WAVE.md, "Levels").

/// The sorted ladder of `v_z` values (rad/m) and their logarithms.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Levels {
    pub vz: Vec<f64>,
    t: Vec<f64>,
    /// Largest step in `ln v_z` between neighbours of one covered interval.
    step: f64,
}

impl Levels {
    /// Levels covering every interval `[lo, hi]` (rad/m, `0 < lo <= hi`) with neighbours at most
    /// `ratio` apart; intervals that overlap or touch share their levels.
    pub fn covering(intervals: &[(f64, f64)], ratio: f64) -> Levels {
        let step = ratio.ln();
        let mut sorted: Vec<(f64, f64)> = intervals.iter().map(|&(a, b)| (a.ln(), b.ln())).collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Merge intervals closer than one step: one ladder across both.
        let mut merged: Vec<(f64, f64)> = Vec::new();
        for (a, b) in sorted {
            match merged.last_mut() {
                Some(last) if a <= last.1 + step => last.1 = last.1.max(b),
                _ => merged.push((a, b)),
            }
        }
        let mut t = Vec::new();
        for (a, b) in merged {
            let n = ((b - a) / step).ceil().max(0.0) as usize;
            if n == 0 {
                t.push(a);
            } else {
                t.extend((0..=n).map(|j| a + (b - a) * j as f64 / n as f64));
            }
        }
        Levels { vz: t.iter().map(|x| x.exp()).collect(), t, step }
    }

    /// Number of levels.
    pub fn len(&self) -> usize {
        self.vz.len()
    }

    /// The interpolation weights of `v_z` over the levels: up to four `(level, weight)` pairs (a cubic
    /// Hermite in `ln v_z` whose slopes are three-point differences; one-sided at the ends of a covered
    /// interval). Outside the ladder the nearest level's value is held.
    pub fn weights(&self, vz: f64) -> [(usize, f64); 4] {
        let n = self.t.len();
        let t = vz.ln();
        if n == 1 || !(t > self.t[0]) {
            return [(0, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)];
        }
        if t >= self.t[n - 1] {
            return [(n - 1, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)];
        }
        let j = self.t.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.t[j], self.t[j + 1]);
        let h = t1 - t0;
        let s = (t - t0) / h;
        // Hermite basis on [t0, t1].
        let (h00, h10, h01, h11) =
            (2.0 * s * s * s - 3.0 * s * s + 1.0, s * s * s - 2.0 * s * s + s, -2.0 * s * s * s + 3.0 * s * s, s * s * s - s * s);
        // A gap wider than the covering step is the edge of an interval: no neighbour across it.
        let joined = |a: usize, b: usize| self.t[b] - self.t[a] <= self.step * 1.0001;
        if !joined(j, j + 1) {
            // Queries never fall in a gap between intervals; hold the nearer level if one does.
            return if s < 0.5 { [(j, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)] } else { [(j + 1, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)] };
        }
        // Slope at a node as weights on the values: three-point where both neighbours are joined.
        let slope = |i: usize| -> [(usize, f64); 3] {
            let left = i > 0 && joined(i - 1, i);
            let right = i + 1 < n && joined(i, i + 1);
            match (left, right) {
                (true, true) => {
                    let (hl, hr) = (self.t[i] - self.t[i - 1], self.t[i + 1] - self.t[i]);
                    let d = hl + hr;
                    // d/dt of the parabola through the three nodes at the middle one.
                    [(i - 1, -hr / (hl * d)), (i, (hr - hl) / (hl * hr)), (i + 1, hl / (hr * d))]
                }
                (true, false) => {
                    let hl = self.t[i] - self.t[i - 1];
                    [(i - 1, -1.0 / hl), (i, 1.0 / hl), (i, 0.0)]
                }
                (false, true) => {
                    let hr = self.t[i + 1] - self.t[i];
                    [(i, -1.0 / hr), (i + 1, 1.0 / hr), (i, 0.0)]
                }
                (false, false) => [(i, 0.0), (i, 0.0), (i, 0.0)],
            }
        };
        let mut acc = [(j.saturating_sub(1), 0.0), (j, h00), (j + 1, h01), ((j + 2).min(n - 1), 0.0)];
        let mut add = |i: usize, w: f64| {
            for slot in acc.iter_mut() {
                if slot.0 == i {
                    slot.1 += w;
                    return;
                }
            }
        };
        for (i, w) in slope(j) {
            add(i, w * h10 * h);
        }
        for (i, w) in slope(j + 1) {
            add(i, w * h11 * h);
        }
        acc
    }

    /// The interpolated value of `values` (one per level) at `v_z`.
    pub fn interpolate(&self, values: &[f64], vz: f64) -> f64 {
        self.weights(vz).iter().map(|&(i, w)| if w == 0.0 { 0.0 } else { w * values[i] }).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cubic_follows_smooth_functions_of_vz_and_reproduces_the_nodes() {
        let lv = Levels::covering(&[(2.0, 3.0), (2.5, 8.0)], 1.1);
        assert!(lv.vz.windows(2).all(|w| w[1] / w[0] <= 1.1 * 1.0001), "{:?}", lv.vz);
        // A rough surface's tail, exp(-a / vz^2) / vz^2, and a smooth one's coherent share, exp(-vz^2 s^2).
        for f in [|v: f64| (-30.0 / (v * v)).exp() / (v * v), |v: f64| (-(v * 0.3) * (v * 0.3)).exp()] {
            let values: Vec<f64> = lv.vz.iter().map(|&v| f(v)).collect();
            for (i, &v) in lv.vz.iter().enumerate() {
                assert!((lv.interpolate(&values, v) - values[i]).abs() < 1e-12);
            }
            let peak = values.iter().cloned().fold(0.0, f64::max);
            for k in 0..200 {
                let v = 2.0 * (4.0f64).powf(k as f64 / 199.0);
                let err = (lv.interpolate(&values, v) - f(v)).abs();
                assert!(err < 2e-3 * peak, "vz {v}: {} against {}", lv.interpolate(&values, v), f(v));
            }
        }
    }

    #[test]
    fn disjoint_intervals_keep_their_own_ladders() {
        let lv = Levels::covering(&[(1.0, 1.2), (5.0, 5.5)], 1.05);
        assert!(lv.vz.iter().all(|&v| (1.0..=1.2 + 1e-12).contains(&v) || (5.0 - 1e-12..=5.5 + 1e-12).contains(&v)));
        // Each ladder has three or five levels: one-sided slopes at its ends, so the cubic is good to about
        // `h^2 f'' / 8` there (1e-3 relative with h = 0.048), not to the three-point order inside.
        let values: Vec<f64> = lv.vz.iter().map(|&v| v * v).collect();
        for (v, want) in [(5.2, 27.04), (5.45, 29.7025), (1.1, 1.21), (1.03, 1.0609)] {
            let got = lv.interpolate(&values, v);
            assert!((got / want - 1.0).abs() < 1e-3, "{v}: {got} against {want}");
        }
    }
}
