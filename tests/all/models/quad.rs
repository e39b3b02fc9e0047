//! An adaptive 2D Gauss-Kronrod integrator (tensor 7/15-point rule, global subdivision of the worst cell)
//! and slope-space helpers, written for the tests and independent of the model code.
//!
//! Error estimate per cell: |K15 x K15 - G7 x G7|, pessimistic for smooth integrands (the real error of the
//! 15-point rule is far smaller), so a tolerance met here is met by the value.

// The QUADPACK constants are kept verbatim.
#![allow(clippy::excessive_precision)]

use std::collections::BinaryHeap;

use nalgebra::{Matrix2, Matrix3, Rotation3, Vector2, Vector3};

const XGK: [f64; 8] = [
    0.991455371120812639206854697526329,
    0.949107912342758524526189684047851,
    0.864864423359769072789712788640926,
    0.741531185599394439863864773280788,
    0.586087235467691130294144845693013,
    0.405845151377397166906606412076961,
    0.207784955007898467600689403773245,
    0.0,
];
const WGK: [f64; 8] = [
    0.022935322010529224963732008058970,
    0.063092092629978553290700663189204,
    0.104790010322250183839876322541518,
    0.140653259715525918745189590510238,
    0.169004726639267902826583426598550,
    0.190350578064785409913256402421014,
    0.204432940075298892414161999234649,
    0.209482141084727828012999174891714,
];
/// Gauss weights of the 7-point rule, on the Kronrod nodes XGK[1], XGK[3], XGK[5], XGK[7].
const WG: [f64; 4] = [
    0.129484966168869693270611432679082,
    0.279705391489276667901467771423780,
    0.381830050505118944950369775488975,
    0.417959183673469387755102040816327,
];

/// The 15 nodes on [-1, 1] with Kronrod weight and Gauss weight (0 when not a Gauss node).
fn nodes() -> [(f64, f64, f64); 15] {
    let mut out = [(0.0, 0.0, 0.0); 15];
    for i in 0..8 {
        let wg = if i % 2 == 1 { WG[i / 2] } else { 0.0 };
        out[i] = (-XGK[i], WGK[i], wg);
        out[14 - i] = (XGK[i], WGK[i], wg);
    }
    out
}

struct Cell {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    val: f64,
    err: f64,
}
impl PartialEq for Cell {
    fn eq(&self, o: &Self) -> bool {
        self.err == o.err
    }
}
impl Eq for Cell {}
impl PartialOrd for Cell {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Cell {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.err.total_cmp(&o.err)
    }
}

fn rule<F: Fn(f64, f64) -> f64>(f: &F, x0: f64, x1: f64, y0: f64, y1: f64) -> Cell {
    let nd = nodes();
    let (cx, hx) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
    let (cy, hy) = (0.5 * (y0 + y1), 0.5 * (y1 - y0));
    let (mut k, mut g) = (0.0, 0.0);
    for &(u, wku, wgu) in &nd {
        for &(v, wkv, wgv) in &nd {
            let fv = f(cx + hx * u, cy + hy * v);
            k += wku * wkv * fv;
            g += wgu * wgv * fv;
        }
    }
    let area = hx * hy;
    Cell { x0, x1, y0, y1, val: k * area, err: ((k - g) * area).abs() }
}

/// Integrate `f` over `[x0,x1] x [y0,y1]`, starting from an `init x init` grid, until the estimated error
/// is below `max(abs_tol, rel_tol |I|)` or `max_cells` cells exist. Returns (value, error estimate).
pub fn integrate_2d<F: Fn(f64, f64) -> f64>(
    f: F,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    init: usize,
    abs_tol: f64,
    rel_tol: f64,
    max_cells: usize,
) -> (f64, f64) {
    let mut heap = BinaryHeap::new();
    for i in 0..init {
        for j in 0..init {
            let xa = x0 + (x1 - x0) * i as f64 / init as f64;
            let xb = x0 + (x1 - x0) * (i + 1) as f64 / init as f64;
            let ya = y0 + (y1 - y0) * j as f64 / init as f64;
            let yb = y0 + (y1 - y0) * (j + 1) as f64 / init as f64;
            heap.push(rule(&f, xa, xb, ya, yb));
        }
    }
    let mut val: f64 = heap.iter().map(|c| c.val).sum();
    let mut err: f64 = heap.iter().map(|c| c.err).sum();
    loop {
        if err <= abs_tol.max(rel_tol * val.abs()) || heap.len() >= max_cells {
            // Exact sums (the running ones drift by rounding).
            let val: f64 = heap.iter().map(|c| c.val).sum();
            let err: f64 = heap.iter().map(|c| c.err).sum();
            return (val, err);
        }
        // Split the worst cell into four.
        let c = heap.pop().expect("the heap is never empty");
        val -= c.val;
        err -= c.err;
        let (xm, ym) = (0.5 * (c.x0 + c.x1), 0.5 * (c.y0 + c.y1));
        for (xa, xb) in [(c.x0, xm), (xm, c.x1)] {
            for (ya, yb) in [(c.y0, ym), (ym, c.y1)] {
                let n = rule(&f, xa, xb, ya, yb);
                val += n.val;
                err += n.err;
                heap.push(n);
            }
        }
    }
}

/// `g(t) = t / (1 - t^2)`: maps (-1, 1) onto the real line.
pub fn g(t: f64) -> f64 {
    t / (1.0 - t * t)
}
/// `g'(t)`.
pub fn dg(t: f64) -> f64 {
    (1.0 + t * t) / (1.0 - t * t).powi(2)
}

/// Heitz eq. 62: the normal of slope `w`.
pub fn normal_of_slope(w: Vector2<f64>) -> Vector3<f64> {
    Vector3::new(-w.x, -w.y, 1.0).normalize()
}

/// `R = Rx Ry Rz` built with nalgebra's axis-angle rotations (not the library's `rotation_xyz`).
pub fn rotation(tx: f64, ty: f64, tz: f64) -> Matrix3<f64> {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), tx);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), ty);
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), tz);
    (rx * ry * rz).into_inner()
}

/// Centre and scale of an ellipsoid-shaped lobe in slope space, from the test's own algebra: with
/// `v = (-w, 1)`, `||S^-1 R v||^2 = w^T M2 w - 2 w.b + c` (M = R^T S^-2 R), minimal at `w0 = M2^-1 b` with
/// value `qmin`; `w = w0 + sqrt(qmin) M2^(-1/2) xi` makes the quadratic `qmin (1 + |xi|^2)`.
/// Returns `(w0, L)` with `w = w0 + L xi`. Used for GGX and Beckmann too (tilts 0).
pub fn slope_frame(ax: f64, ay: f64, tx: f64, ty: f64, tz: f64) -> (Vector2<f64>, Matrix2<f64>) {
    let r = rotation(tx, ty, tz);
    let s_inv2 = Matrix3::from_diagonal(&Vector3::new(1.0 / (ax * ax), 1.0 / (ay * ay), 1.0));
    let m = r.transpose() * s_inv2 * r;
    let m2 = Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
    let b = Vector2::new(m[(0, 2)], m[(1, 2)]);
    let m2_inv = m2.try_inverse().expect("M2 is positive definite");
    let w0 = m2_inv * b;
    let qmin = m[(2, 2)] - b.dot(&w0);
    let eig = nalgebra::SymmetricEigen::new(m2);
    let inv_sqrt = eig.eigenvectors * Matrix2::from_diagonal(&eig.eigenvalues.map(|l| 1.0 / l.sqrt())) * eig.eigenvectors.transpose();
    (w0, inv_sqrt * qmin.sqrt())
}

/// `integral over the hemisphere of f(m) D(m) (m.n) dm` written in slope space (`D cos^4 = P22`, Heitz eq. 64;
/// `dm = cos^3 dw`), with `w = w0 + L (g(t1), g(t2))`, over `t` in `(-1, 1)^2`. `f` receives `m`.
pub fn hemisphere_integral<D: Fn(Vector3<f64>) -> f64, F: Fn(Vector3<f64>) -> f64>(
    d: D,
    f: F,
    w0: Vector2<f64>,
    l: Matrix2<f64>,
    rel_tol: f64,
) -> (f64, f64) {
    let det = l.determinant().abs();
    let integrand = |t1: f64, t2: f64| {
        let w = w0 + l * Vector2::new(g(t1), g(t2));
        let r2 = w.norm_squared();
        if !r2.is_finite() {
            return 0.0;
        }
        let m = normal_of_slope(w);
        let c = 1.0 / (1.0 + r2).sqrt();
        let val = d(m) * c.powi(4) * f(m) * det * dg(t1) * dg(t2);
        if val.is_finite() {
            val
        } else {
            0.0
        }
    };
    integrate_2d(integrand, (-1.0, 1.0), (-1.0, 1.0), 4, 1e-300, rel_tol, 40_000)
}
