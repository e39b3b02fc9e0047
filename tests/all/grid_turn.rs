//! The bin grid's turn against the sample lattice (`SlopeFrame::grid_turn`): in the frame the NDF builds,
//! the images of the sample rows and columns (the whitened change of the central-difference slope between
//! neighbouring samples, measured on the scan, not predicted from the covariance) sit at 22.5 degrees
//! modulo 45 from the bin grid's axes, whatever the lobe's `theta_z`.

use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

/// Circular mean modulo 45 degrees (of `8 g`) of the whitened lattice steps' angles near the lobe's centre
/// (whitened slope radius below 1), over steps along x and along y, in degrees in (-22.5, 22.5].
fn lattice_image_angle(p: [f64; 5]) -> f64 {
    let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
    let n = 256;
    let (hf, _) = ellipsoid_surface(&SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() }, &ep).expect("synth");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    let f = ndf.frame;
    let z = |i: usize, j: usize| hf.z[i * n + j];
    let slope = |i: usize, j: usize| [(z(i, j + 1) - z(i, j - 1)) / (2.0 * hf.dx), (z(i + 1, j) - z(i - 1, j)) / (2.0 * hf.dy)];
    let (mut c, mut s) = (0.0, 0.0);
    for i in 2..n - 2 {
        for j in 2..n - 2 {
            let a = slope(i, j);
            let wa = f.to_whitened(a[0], a[1]);
            let r = wa[0].hypot(wa[1]);
            if r.is_nan() || r >= 1.0 {
                continue;
            }
            for b in [slope(i, j + 1), slope(i + 1, j)] {
                let wb = f.to_whitened(b[0], b[1]);
                let g = (wb[1] - wa[1]).atan2(wb[0] - wa[0]);
                if g.is_finite() {
                    c += (8.0 * g).cos();
                    s += (8.0 * g).sin();
                }
            }
        }
    }
    (s.atan2(c) / 8.0).to_degrees()
}

#[test]
fn lattice_images_sit_between_the_bin_grids_axes_and_diagonals() {
    for p in [
        [0.2, 0.02, 0.0, 0.4, 0.0],
        [0.2, 0.02, 0.0, 0.0, 22.5f64.to_radians()],
        [0.2, 0.02, 0.0, 0.0, -22.5f64.to_radians()],
        [0.35, 0.05, 0.16, 0.0, 0.3],
        [0.5, 0.05, -0.4, 0.1, 1.0],
        [0.2, 0.1, 0.0, 0.0, 0.7],
        [0.2, 0.2, 0.0, 0.0, 0.0],
    ] {
        let g = lattice_image_angle(p);
        eprintln!("{p:?}: lattice image at {g:.2} deg (mod 45) from the bin grid");
        assert!((g.abs() - 22.5).abs() < 4.0, "{p:?}: {g} deg");
    }
}
