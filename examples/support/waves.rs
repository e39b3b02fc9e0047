//! A random-phase sum of plane waves, `h = sum_k a_k cos(k_k . x + phi_k)` on a unit-spaced grid: a
//! Gaussian-like random surface (many independent phases) whose gradient is known in closed form,
//! `grad h = -sum_k a_k k_k sin(k_k . x + phi_k)`.

use ndfit::Heightfield;

/// The waves: wave vectors `k` (radians per sample), amplitudes and phases.
pub struct Waves {
    k: Vec<[f64; 2]>,
    a: Vec<f64>,
    phi: Vec<f64>,
}

impl Waves {
    /// 64 waves of wavelengths from `lambda` to `4 lambda` samples in random directions, scaled so that
    /// the RMS slope is `rms_slope`; `seed` drives a small LCG (reproducible, no dependency).
    pub fn new(lambda: f64, rms_slope: f64, seed: u64) -> Waves {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut u = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut k, mut a, mut phi) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..64 {
            let len = std::f64::consts::TAU / (lambda * (1.0 + 3.0 * u()));
            let dir = std::f64::consts::TAU * u();
            k.push([len * dir.cos(), len * dir.sin()]);
            a.push(1.0 / len);
            phi.push(std::f64::consts::TAU * u());
        }
        // RMS slope of the sum: sqrt(sum a^2 |k|^2 / 2).
        let rms = (a.iter().zip(&k).map(|(a, k)| a * a * (k[0] * k[0] + k[1] * k[1])).sum::<f64>() / 2.0).sqrt();
        a.iter_mut().for_each(|v| *v *= rms_slope / rms);
        Waves { k, a, phi }
    }

    /// The height at column `x`, row `y` (in samples).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        self.k.iter().zip(&self.a).zip(&self.phi).map(|((k, a), p)| a * (k[0] * x + k[1] * y + p).cos()).sum()
    }

    /// The exact gradient (per sample).
    pub fn gradient(&self, x: f64, y: f64) -> [f64; 2] {
        self.k.iter().zip(&self.a).zip(&self.phi).fold([0.0, 0.0], |g, ((k, a), p)| {
            let s = -a * (k[0] * x + k[1] * y + p).sin();
            [g[0] + s * k[0], g[1] + s * k[1]]
        })
    }

    /// The surface on an `nx` x `ny` grid of unit spacing.
    pub fn surface(&self, nx: usize, ny: usize) -> Heightfield {
        let z = (0..nx * ny).map(|i| self.height((i % nx) as f64, (i / nx) as f64)).collect();
        Heightfield::new(nx, ny, 1.0, 1.0, z).expect("grid")
    }
}
