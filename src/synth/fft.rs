//! A small in-place radix-2 complex FFT (iterative Cooley-Tukey), enough for spectral synthesis of
//! Gaussian surfaces on power-of-two grids. No dependency is added for it: the crate needs one
//! transform, once per synthetic scan.

/// In-place forward (`inverse = false`, `exp(-i k n)`) or unnormalized inverse (`exp(+i k n)`) DFT of
/// `re + i im`; the length must be a power of two.
pub fn fft(re: &mut [f64], im: &mut [f64], inverse: bool) {
    let n = re.len();
    debug_assert!(n.is_power_of_two() && im.len() == n);
    if n < 2 {
        return;
    }
    // Bit-reversal permutation.
    let bits = n.trailing_zeros();
    for i in 0..n {
        let j = i.reverse_bits() >> (usize::BITS - bits);
        if j > i {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let sign = if inverse { 1.0 } else { -1.0 };
    let mut len = 2;
    while len <= n {
        let ang = sign * 2.0 * std::f64::consts::PI / len as f64;
        let half = len / 2;
        // Twiddles computed directly per index (not by recurrence) to keep the error at O(eps log n).
        let tw: Vec<(f64, f64)> = (0..half).map(|k| (ang * k as f64).sin_cos()).map(|(s, c)| (c, s)).collect();
        for start in (0..n).step_by(len) {
            for k in 0..half {
                let (wr, wi) = tw[k];
                let (a, b) = (start + k, start + k + half);
                let (xr, xi) = (re[b] * wr - im[b] * wi, re[b] * wi + im[b] * wr);
                re[b] = re[a] - xr;
                im[b] = im[a] - xi;
                re[a] += xr;
                im[a] += xi;
            }
        }
        len *= 2;
    }
}

/// 2D transform of a row-major `ny x nx` array (both powers of two): rows, then columns.
pub fn fft2(re: &mut [f64], im: &mut [f64], nx: usize, ny: usize, inverse: bool) {
    use rayon::prelude::*;
    re.par_chunks_mut(nx).zip(im.par_chunks_mut(nx)).for_each(|(r, i)| fft(r, i, inverse));
    // Columns: transpose through a buffer per column (simple and cache-tolerable at these sizes).
    let cols: Vec<(Vec<f64>, Vec<f64>)> = (0..nx)
        .into_par_iter()
        .map(|j| {
            let mut cr: Vec<f64> = (0..ny).map(|i| re[i * nx + j]).collect();
            let mut ci: Vec<f64> = (0..ny).map(|i| im[i * nx + j]).collect();
            fft(&mut cr, &mut ci, inverse);
            (cr, ci)
        })
        .collect();
    for (j, (cr, ci)) in cols.into_iter().enumerate() {
        for i in 0..ny {
            re[i * nx + j] = cr[i];
            im[i * nx + j] = ci[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the O(n^2) definition of the DFT, and inverse(forward(x)) = n x.
    #[test]
    fn matches_naive_dft() {
        let n = 64;
        let x: Vec<f64> = (0..n).map(|i| ((i * 7 % 13) as f64).sin() + 0.1 * i as f64).collect();
        let (mut re, mut im) = (x.clone(), vec![0.0; n]);
        fft(&mut re, &mut im, false);
        for k in 0..n {
            let (mut sr, mut si) = (0.0, 0.0);
            for (t, v) in x.iter().enumerate() {
                let a = -2.0 * std::f64::consts::PI * (k * t) as f64 / n as f64;
                sr += v * a.cos();
                si += v * a.sin();
            }
            assert!((re[k] - sr).abs() < 1e-10 && (im[k] - si).abs() < 1e-10);
        }
        fft(&mut re, &mut im, true);
        for t in 0..n {
            assert!((re[t] / n as f64 - x[t]).abs() < 1e-12 && im[t].abs() < 1e-10);
        }
    }
}
