//! The window scene: a square plate seen near grazing by a pinhole camera, under a rectangular area light
//! with sharp edges placed where the plate reflects it toward the camera (a window), the room black. A
//! mirror shows the window's sharp image, a glossy lobe blurs it, a polished surface's haze is a faint glow
//! around it: the scene tells a mirror from a blur, which the sphere scenes cannot. Its geometry is that of
//! `fits/ndfitpy/mirror_scene.py` (Mitsuba 3) without the room; `data_formats/render.md` states it.
//!
//! The plate is `z = 0`, `|x|, |y| <= plate`, its normal `+z` and its tangent `s = +x` (Mitsuba's
//! `rectangle`), so the shading frame is the world frame. The camera sits `view_angle` off the normal on the
//! `-y` side and looks at the plate's centre; the light's centre is the camera's mirror image. Every pixel
//! is a mean over its square by the pixel rule of [`super::Camera`]; the light is integrated at each
//! shading point over the spherical quadrilateral it subtends, by rings about the mirror direction clipped
//! to the quadrilateral's four great circles (module `integrate`), and a BRDF's smooth part
//! ([`super::Brdf::mirror`]) reflects the light's radiance where the mirror direction meets it.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::integrate::{add_mirror, pixels, polygon, Geometry, Grid, Ring};
use super::quadrature::gauss_legendre;
use super::{BrdfSet, Image, PixelRule};
use crate::error::{Error, Result};

/// The window scene: a plate seen near grazing under a sharp-edged rectangular light (geometry and
/// quadrature in `data_formats/render.md`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The camera's angle from the plate's normal (radians).
    pub view_angle: f64,
    /// The camera's distance from the plate's centre (the plate's unit).
    pub camera_distance: f64,
    /// The field of view across the image's width (radians).
    pub fov: f64,
    /// Half the plate's side.
    pub plate: f64,
    /// The light's distance from the plate's centre; it faces the centre.
    pub light_distance: f64,
    /// The light's half-sizes: along `x`, and along its own up (in the plane of the camera and the normal).
    pub light_half: [f64; 2],
    /// The light's radiance (per channel).
    pub radiance: f64,
    /// Gauss-Legendre points per axis of a pixel (or of a sub-pixel cell when refined).
    pub points: usize,
    /// How many times a cell whose points disagree is split into 2 x 2.
    pub refine: usize,
    /// The refinement's relative tolerance ([`super::Camera::tolerance`]).
    pub tolerance: f64,
    /// Where the pixels' points are taken ([`PixelRule`]).
    pub rule: PixelRule,
}

impl Default for Window {
    /// `fits/ndfitpy/mirror_scene.py`'s scene: 65 degrees off the normal, the camera 4 from the centre with
    /// a 32-degree field across 160 x 96 pixels, a plate of side 6.4 that fills the frame, a 2.4 x 1.2
    /// light of radiance 20 at 6 (about 23 x 11 degrees). The centre rule (most of the image is smooth at
    /// the pixel's scale), refined twice where it is not (the window's edges).
    fn default() -> Self {
        Window {
            width: 160,
            height: 96,
            view_angle: 65f64.to_radians(),
            camera_distance: 4.0,
            fov: 32f64.to_radians(),
            plate: 3.2,
            light_distance: 6.0,
            light_half: [1.2, 0.6],
            radiance: 20.0,
            points: 2,
            refine: 2,
            tolerance: 0.1,
            rule: PixelRule::Centre,
        }
    }
}

/// The camera's frame: its position, the direction it looks along, and the image's right and up.
#[derive(Debug, Clone, Copy)]
struct Eye {
    at: Vector3<f64>,
    forward: Vector3<f64>,
    right: Vector3<f64>,
    up: Vector3<f64>,
}

impl Window {
    /// Refuse what cannot be rendered, with the reason in one line.
    pub fn validate(&self) -> Result<()> {
        let positive = [self.camera_distance, self.plate, self.light_distance, self.light_half[0], self.light_half[1], self.tolerance];
        if !positive.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(Error::invalid("the window scene's distances, sizes and tolerance must be positive"));
        }
        if !((0.0..PI / 2.0).contains(&self.view_angle) && self.fov > 0.0 && self.fov < PI) {
            return Err(Error::invalid("the window scene's view angle must be in [0, 90) degrees and its field of view in (0, 180)"));
        }
        if !(1..=4096).contains(&self.width) || !(1..=4096).contains(&self.height) {
            return Err(Error::invalid(format!("the image size {} x {} must be between 1 and 4096", self.width, self.height)));
        }
        if !(1..=16).contains(&self.points) || self.refine > 6 || !(self.radiance.is_finite() && self.radiance >= 0.0) {
            return Err(Error::invalid(
                "the window scene's pixel points (1 to 16), refinements (0 to 6) or radiance (>= 0) are out of range",
            ));
        }
        // The light must lie above the plate's plane, or the plate would hide part of it.
        if self.light_corners().iter().any(|c| c.z <= 0.0) {
            return Err(Error::invalid("the window scene's light reaches below the plate's plane"));
        }
        Ok(())
    }

    fn eye(&self) -> Eye {
        let (s, c) = self.view_angle.sin_cos();
        let at = Vector3::new(0.0, -s, c) * self.camera_distance;
        let forward = -at.normalize();
        // Looking along +y with +z up, the image's right is +x (Mitsuba's `look_at` with up +z).
        let right = Vector3::x();
        Eye { at, forward, right, up: right.cross(&forward) }
    }

    /// The light's corners, in order around it.
    pub fn light_corners(&self) -> [Vector3<f64>; 4] {
        let (s, c) = self.view_angle.sin_cos();
        let centre = Vector3::new(0.0, s, c) * self.light_distance;
        // The light's own up: +z tilted to face the plate's centre (Mitsuba's `look_at`).
        let (ex, ey) = (Vector3::x(), Vector3::new(0.0, -c, s));
        let [a, b] = self.light_half;
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(u, v)| centre + ex * (u * a) + ey * (v * b))
    }

    /// The image plane's half-width and half-height (at unit distance from the camera).
    fn half_extent(&self) -> [f64; 2] {
        let x = (self.fov / 2.0).tan();
        [x, x * self.height as f64 / self.width as f64]
    }

    /// The point of the plate seen at image-plane point `(x, y)` (`y` up), `None` off the plate.
    fn hit(&self, eye: &Eye, x: f64, y: f64) -> Option<Vector3<f64>> {
        let d = eye.forward + eye.right * x + eye.up * y;
        // A ray that does not descend never meets the plate.
        if d.z >= 0.0 {
            return None;
        }
        let p = eye.at - d * (eye.at.z / d.z);
        (p.x.abs() <= self.plate && p.y.abs() <= self.plate).then_some(p)
    }

    /// Whether the centre of each pixel sees the plate, row-major from the top: the object's pixels. With
    /// the default geometry every pixel is the plate's, so the choice's mean over the image is the mean
    /// over the object.
    pub fn mask(&self) -> Vec<bool> {
        let eye = self.eye();
        let [hx, hy] = self.half_extent();
        let side = 2.0 * hx / self.width as f64;
        (0..self.height)
            .flat_map(|j| (0..self.width).map(move |i| (i, j)))
            .map(|(i, j)| self.hit(&eye, -hx + (i as f64 + 0.5) * side, hy - (j as f64 + 0.5) * side).is_some())
            .collect()
    }

    /// The radiance of a white Lambertian plate at its centre: the image's natural scale.
    pub fn white_radiance(&self) -> f64 {
        self.radiance * lambert(&self.light_corners().map(|c| c.normalize())) / PI
    }

    /// Render every BRDF of `set` in one pass over the shading points (as [`super::Scene::render_set`]).
    pub fn render_set<const K: usize>(&self, set: &dyn BrdfSet<K>) -> Result<[Image; K]> {
        self.validate()?;
        let [hx, hy] = self.half_extent();
        let grid = Grid {
            width: self.width,
            height: self.height,
            left: -hx,
            top: hy,
            side: 2.0 * hx / self.width as f64,
            rule: self.rule,
            refine: self.refine,
            tolerance: self.tolerance,
            floor: 1e-3 * self.white_radiance(),
            rough_refine: self.refine,
        };
        let plate = Plate { window: self, eye: self.eye(), corners: self.light_corners(), set, ring: Ring::new() };
        Ok(pixels(&grid, &plate, &gauss_legendre(self.points)))
    }
}

/// `int cos(theta) dw` over the spherical polygon of unit vertices `q` seen from a point with normal `+z`
/// (Lambert's formula: half the sum over the edges of the edge's angle times the `z` of its unit normal),
/// for a polygon above the horizon.
pub(super) fn lambert(q: &[Vector3<f64>]) -> f64 {
    let n = q.len();
    let sum: f64 = (0..n)
        .map(|k| {
            let (a, b) = (q[k], q[(k + 1) % n]);
            let m = a.cross(&b);
            let angle = m.norm().atan2(a.dot(&b));
            angle * m.z / m.norm()
        })
        .sum();
    0.5 * sum.abs()
}

/// The plate of a [`Window`] with the BRDFs it renders.
struct Plate<'a, const K: usize> {
    window: &'a Window,
    eye: Eye,
    corners: [Vector3<f64>; 4],
    set: &'a dyn BrdfSet<K>,
    ring: Ring,
}

impl<const K: usize> Geometry<K> for Plate<'_, K> {
    fn shade(&self, x: f64, y: f64, active: [bool; K]) -> Option<[[f64; 3]; K]> {
        let p = self.window.hit(&self.eye, x, y)?;
        let wi = (self.eye.at - p).normalize();
        let q = self.corners.map(|c| (c - p).normalize());
        let (mut v, inside) = polygon(self.set, wi, &q, &self.ring, active);
        // The mirror direction meets the light: a smooth part reflects its radiance.
        if inside {
            add_mirror(&mut v, self.set.mirror(wi, active), active);
        }
        Some(v.map(|v| v.map(|v| v * self.window.radiance)))
    }

    fn crossed(&self, at: [f64; 2], side: f64) -> bool {
        // The plate's outline crosses the square when its corners disagree on seeing the plate.
        let seen = [(0.0, 0.0), (side, 0.0), (0.0, side), (side, side)]
            .map(|(dx, dy)| self.window.hit(&self.eye, at[0] + dx, at[1] + dy).is_some());
        seen.iter().any(|&s| s != seen[0])
    }
}

#[cfg(test)]
mod tests {
    use super::super::integrate::tests::ggx;
    use super::super::Brdf;
    use super::*;

    /// A smooth conductor with `F = 1`: nothing but its smooth part.
    struct Mirror;
    impl Brdf for Mirror {
        fn eval(&self, _: Vector3<f64>, _: Vector3<f64>) -> [f64; 3] {
            [0.0; 3]
        }
        fn mirror(&self, _: Vector3<f64>) -> [f64; 3] {
            [1.0; 3]
        }
    }

    /// `int f(wi, wo) wo.z dwo` over the light rectangle seen from the origin by brute force: the midpoint
    /// rule on `n x n` cells of its area, `dw = cos_l dA / d^2`.
    fn brute(f: &dyn Brdf, wi: Vector3<f64>, c: &[Vector3<f64>; 4], n: usize) -> f64 {
        let (u, v) = (c[1] - c[0], c[3] - c[0]);
        let normal = u.cross(&v);
        let cell = normal.norm() / (n * n) as f64;
        let normal = normal.normalize();
        let mut acc = 0.0;
        for a in 0..n {
            for b in 0..n {
                let p = c[0] + u * ((a as f64 + 0.5) / n as f64) + v * ((b as f64 + 0.5) / n as f64);
                let d2 = p.norm_squared();
                let wo = p / d2.sqrt();
                acc += f.eval(wi, wo)[0] * wo.z * normal.dot(&wo).abs() / d2 * cell;
            }
        }
        acc
    }

    /// The polygon rule against the brute-force sum for lobes from near-mirror to rough, anisotropic too,
    /// with the mirror direction at the light's centre, near an edge inside and outside, near a corner and
    /// well outside; and against Lambert's closed form for a white Lambertian BRDF.
    #[test]
    fn polygon_rule_matches_brute_force_and_lambert() {
        let w = Window::default();
        let c = w.light_corners();
        let q = c.map(|v| v.normalize());
        let ring = Ring::new();
        let centre = (c[0] + c[2]) / 2.0;
        let (ex, ey) = ((c[1] - c[0]) / 2.0, (c[3] - c[0]) / 2.0);
        let targets = [
            ("centre", centre),
            ("inside an edge", centre + ex * 0.97),
            ("outside an edge", centre + ey * 1.05),
            ("near a corner", centre + ex * 0.98 + ey * 1.02),
            ("outside", centre + ex * 1.6 + ey * 0.3),
        ];
        let lobes: [(f64, f64); 6] = [(0.02, 0.02), (0.05, 0.05), (0.1, 0.1), (0.3, 0.3), (1.0, 1.0), (0.3, 0.08)];
        let mut worst: f64 = 0.0;
        for (name, t) in targets {
            let r = t.normalize();
            let wi = Vector3::new(-r.x, -r.y, r.z);
            let lambertian = |_: Vector3<f64>, _: Vector3<f64>| [1.0 / PI; 3];
            let (l, inside) = polygon(&[&lambertian as &dyn Brdf], wi, &q, &ring, [true]);
            assert_eq!(inside, name == "centre" || name == "inside an edge", "{name}");
            let exact = lambert(&q) / PI;
            eprintln!("{name}: Lambertian rel {:.2e}", (l[0][0] - exact).abs() / exact);
            assert!((l[0][0] - exact).abs() < 1e-3 * exact, "{name}: Lambertian {} vs Lambert's formula {exact}", l[0][0]);
            for (ax, ay) in lobes {
                let f = ggx(ax, ay);
                let (v, _) = polygon(&[&f as &dyn Brdf], wi, &q, &ring, [true]);
                let b = brute(&f, wi, &c, 2000);
                let scale = b.max(1e-3 * brute(&lambertian, wi, &c, 20) * PI);
                let rel = (v[0][0] - b).abs() / scale;
                eprintln!("{name} alpha {ax}/{ay}: rings {:.6} brute {b:.6} rel {rel:.2e}", v[0][0]);
                worst = worst.max(rel);
            }
        }
        assert!(worst < 0.01, "worst relative error {worst}");
    }

    /// A smooth conductor's picture: the light's radiance exactly where the camera sees the light's mirror
    /// image, 0 far from it, and the image's sum the area of that image (the light's corners reflected in
    /// the plate and projected by the camera: a quadrilateral, its area by the shoelace formula) times the
    /// radiance.
    #[test]
    fn a_mirror_shows_the_window_sharp() {
        let w = Window::default();
        let [img] = w.render_set(&[&Mirror as &dyn Brdf]).unwrap();
        let eye = w.eye();
        let [hx, hy] = w.half_extent();
        let side = 2.0 * hx / w.width as f64;
        // Each reflected corner in pixels (column, row from the top).
        let px = w.light_corners().map(|c| {
            let d = Vector3::new(c.x, c.y, -c.z) - eye.at;
            let d = d / d.dot(&eye.forward);
            [(d.dot(&eye.right) + hx) / side, (hy - d.dot(&eye.up)) / side]
        });
        let area: f64 = (0..4).map(|k| px[k][0] * px[(k + 1) % 4][1] - px[(k + 1) % 4][0] * px[k][1]).sum::<f64>().abs() / 2.0;
        let sum: f64 = img.data.iter().map(|p| p[0] as f64).sum();
        eprintln!("mirror image: {:.3} pixels, rendered {:.3}", area, sum / w.radiance);
        assert!((sum / w.radiance - area).abs() < 2e-3 * area, "rendered {} pixels of light, the closed form {area}", sum / w.radiance);
        let centre = img.get(w.width / 2, w.height / 2)[0];
        assert_eq!(centre, w.radiance as f32);
        assert_eq!(img.get(2, 2)[0], 0.0);
        // Every value is the light's, none, or an edge pixel's share of it.
        assert!(img.data.iter().all(|p| p[0] >= 0.0 && p[0] <= w.radiance as f32 && p[0] == p[1]));
    }

    /// The plate fills the frame; a camera looking past the plate's edge sees the outline.
    #[test]
    fn the_plate_fills_the_frame() {
        let w = Window::default();
        assert!(w.mask().iter().all(|&m| m));
        let small = Window { plate: 1.0, ..w };
        let m = small.mask();
        let seen = m.iter().filter(|&&m| m).count();
        assert!(seen > 0 && seen < m.len(), "{seen} of {}", m.len());
        assert!(small.validate().is_ok());
        assert!(Window { light_distance: 0.5, light_half: [1.2, 2.0], ..w }.validate().is_err());
    }

    /// The centre rule against the refined Gauss rule on a glossy lobe: the image agrees within a few
    /// percent of its brightest pixel everywhere and in its mean.
    #[test]
    fn centre_rule_matches_the_fine_render() {
        let f = ggx(0.1, 0.1);
        let coarse = Window { width: 80, height: 48, ..Window::default() };
        let fine = Window { rule: PixelRule::Gauss, points: 3, refine: 2, tolerance: 0.02, ..coarse };
        let [a] = coarse.render_set(&[&f as &dyn Brdf]).unwrap();
        let [b] = fine.render_set(&[&f as &dyn Brdf]).unwrap();
        let peak = b.data.iter().map(|p| p[0]).fold(0.0, f32::max) as f64;
        let worst = a.data.iter().zip(&b.data).map(|(x, y)| (x[0] - y[0]).abs() as f64).fold(0.0, f64::max);
        let (ma, mb) = (a.data.iter().map(|p| p[0] as f64).sum::<f64>(), b.data.iter().map(|p| p[0] as f64).sum::<f64>());
        eprintln!("centre vs fine: worst {:.4} of the peak, means {:.5} vs {:.5}", worst / peak, ma, mb);
        assert!(worst < 0.03 * peak, "worst pixel {worst} against a peak of {peak}");
        assert!((ma - mb).abs() < 2e-3 * mb);
    }
}
