//! The 2D discrete Fourier transform for spectral synthesis of Gaussian surfaces, on rustfft (the
//! well-kept FFT crate of the Rust ecosystem) with rayon over rows and columns.

use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{FftDirection, FftPlanner};

/// 2D transform of a row-major `ny x nx` array: rows, then columns (unnormalized both ways).
pub fn fft2(re: &mut [f64], im: &mut [f64], nx: usize, ny: usize, inverse: bool) {
    debug_assert!(re.len() == nx * ny && im.len() == nx * ny);
    let mut data: Vec<Complex<f64>> = re.iter().zip(im.iter()).map(|(&r, &i)| Complex::new(r, i)).collect();
    let row_fft = planner_fft(nx, inverse);
    data.par_chunks_mut(nx).for_each(|row| row_fft.process(row));
    // Columns: transpose into rows of length ny, transform, transpose back.
    let mut cols = vec![Complex::new(0.0, 0.0); nx * ny];
    cols.par_chunks_mut(ny).enumerate().for_each(|(j, col)| {
        for (i, c) in col.iter_mut().enumerate() {
            *c = data[i * nx + j];
        }
    });
    let col_fft = planner_fft(ny, inverse);
    cols.par_chunks_mut(ny).for_each(|col| col_fft.process(col));
    re.par_chunks_mut(nx).zip(im.par_chunks_mut(nx)).enumerate().for_each(|(i, (r, m))| {
        for j in 0..nx {
            let c = cols[j * ny + i];
            r[j] = c.re;
            m[j] = c.im;
        }
    });
}

/// A planned transform of length `n` in the requested direction.
fn planner_fft(n: usize, inverse: bool) -> std::sync::Arc<dyn rustfft::Fft<f64>> {
    let dir = if inverse { FftDirection::Inverse } else { FftDirection::Forward };
    FftPlanner::new().plan_fft(n, dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The O(n^2) definition of the 2D DFT, the independent reference.
    fn naive_dft2(x: &[f64], nx: usize, ny: usize) -> Vec<(f64, f64)> {
        let mut out = vec![(0.0, 0.0); nx * ny];
        for ky in 0..ny {
            for kx in 0..nx {
                let (mut sr, mut si) = (0.0, 0.0);
                for y in 0..ny {
                    for xx in 0..nx {
                        let a = -2.0 * std::f64::consts::PI * ((kx * xx) as f64 / nx as f64 + (ky * y) as f64 / ny as f64);
                        sr += x[y * nx + xx] * a.cos();
                        si += x[y * nx + xx] * a.sin();
                    }
                }
                out[ky * nx + kx] = (sr, si);
            }
        }
        out
    }

    /// Against the definition of the DFT on a non-square grid, and inverse(forward(x)) = n x.
    #[test]
    fn fft2_matches_naive_dft_and_inverts() {
        let (nx, ny) = (16, 8);
        let x: Vec<f64> = (0..nx * ny).map(|i| ((i * 7 % 13) as f64).sin() + 0.01 * i as f64).collect();
        let (mut re, mut im) = (x.clone(), vec![0.0; nx * ny]);
        fft2(&mut re, &mut im, nx, ny, false);
        for (k, (sr, si)) in naive_dft2(&x, nx, ny).into_iter().enumerate() {
            assert!((re[k] - sr).abs() < 1e-10 && (im[k] - si).abs() < 1e-10, "bin {k}");
        }
        fft2(&mut re, &mut im, nx, ny, true);
        let n = (nx * ny) as f64;
        for t in 0..nx * ny {
            assert!((re[t] / n - x[t]).abs() < 1e-12 && im[t].abs() < 1e-10);
        }
    }
}
