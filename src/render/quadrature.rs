//! Gauss-Legendre rules: the nodes and weights of an `n`-point rule on `[0, 1]`, exact for polynomials of
//! degree `2n - 1`.

use std::f64::consts::PI;

/// `(node, weight)` pairs of the `n`-point Gauss-Legendre rule on `[0, 1]` (weights sum to 1).
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            // Newton on P_n from the Chebyshev-like first guess (Abramowitz & Stegun 25.4.29 nodes).
            let mut x = (PI * (k as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (p, d) = legendre(n, x);
                dp = d;
                let dx = p / d;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let (_, d) = legendre(n, x);
            dp = if d.is_finite() { d } else { dp };
            // A&S 25.4.29: w = 2 / ((1 - x^2) P_n'(x)^2) on [-1, 1]; halved for [0, 1].
            ((1.0 - x) / 2.0, 1.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// `P_n(x)` and `P_n'(x)` by the three-term recurrence.
fn legendre(n: usize, x: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, x);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
        p0 = p1;
        p1 = p2;
    }
    (p1, n as f64 * (x * p1 - p0) / (x * x - 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each rule integrates `x^k` exactly up to degree `2n - 1`, and the weights sum to 1.
    #[test]
    fn rules_are_exact_to_degree_2n_minus_1() {
        for n in 1..=12 {
            let rule = gauss_legendre(n);
            for k in 0..2 * n {
                let q: f64 = rule.iter().map(|(x, w)| w * x.powi(k as i32)).sum();
                assert!((q - 1.0 / (k + 1) as f64).abs() < 1e-14, "n {n} degree {k}: {q}");
            }
        }
    }
}
