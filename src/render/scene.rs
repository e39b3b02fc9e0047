//! The scenes: the unit sphere at the origin (its pole `+z`), an orthographic camera, one distant light
//! and a black background. There is no other geometry, so the only occluder is the sphere itself: a
//! light direction below a point's horizon is hidden.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::{direction, Brdf, BrdfSet, Image};
use crate::error::{Error, Result};

/// The orthographic camera and the pixel quadrature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Unit direction from the sphere toward the camera (world frame). The image's up is `+z` projected
    /// onto the image plane (`+y` when looking along the pole), its right `up x view`.
    pub view: Vector3<f64>,
    /// Pixels per side (the image is square).
    pub size: usize,
    /// Half the image's side in sphere radii (1: the sphere touches the edges).
    pub extent: f64,
    /// Gauss-Legendre points per axis of a pixel (or of a sub-pixel cell when refined).
    pub points: usize,
    /// How many times a cell is split into 2 x 2 where its points disagree (the silhouette, a sharp
    /// highlight).
    pub refine: usize,
    /// A cell is split when the spread of its points' values exceeds `tolerance` times their mean plus
    /// `1e-3` of a white Lambertian surface's radiance under the light.
    pub tolerance: f64,
    /// Where the pixels' points are taken (with `refine` 0 every pixel takes its Gauss rule, unrefined).
    pub rule: PixelRule,
}

/// How a pixel's mean over its square is taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelRule {
    /// `points x points` Gauss-Legendre in every pixel, refined where the points disagree.
    Gauss,
    /// One point at each pixel's centre, plus a twenty-fourth of the sum of the central second
    /// differences of the neighbouring centres (the box mean of a smooth image, exact for cubics); a
    /// pixel where that correction exceeds a tenth of `tolerance` of its value, or that the silhouette
    /// crosses or borders, takes the refined Gauss rule. For images smooth at the pixel's scale (a broad
    /// light), where each point is costly.
    Centre,
}

impl Default for Camera {
    /// From the equator (`-y`), pole up: at the image's centre `s` points right and `t` up.
    fn default() -> Self {
        Camera { view: -Vector3::y(), size: 128, extent: 1.05, points: 2, refine: 2, tolerance: 0.1, rule: PixelRule::Gauss }
    }
}

/// The light: distant, so the same at every point of the sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// A directional light (a point at infinity): `irradiance` (W/m^2 per channel) on a surface facing
    /// the unit direction `dir` (toward the light).
    Point {
        /// Unit direction toward the light (world frame).
        dir: Vector3<f64>,
        /// Irradiance at normal incidence.
        irradiance: f64,
    },
    /// A spherical cap of uniform `radiance` over the cone of `half_angle` (radians) about `dir`; the
    /// irradiance of a surface facing it wholly is `radiance pi sin^2(half_angle)`.
    Cap {
        /// Unit direction of the cap's centre (world frame).
        dir: Vector3<f64>,
        /// Half-angle of the cone (radians, in `(0, pi/2]`).
        half_angle: f64,
        /// Radiance inside the cone.
        radiance: f64,
    },
}

impl Light {
    /// The radiance of a white Lambertian surface facing the light: the image's natural scale.
    pub fn white_radiance(&self) -> f64 {
        match *self {
            Light::Point { irradiance, .. } => irradiance / PI,
            Light::Cap { half_angle, radiance, .. } => radiance * half_angle.sin().powi(2),
        }
    }
}

/// What is rendered: a camera and a light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scene {
    /// The camera and pixel quadrature.
    pub camera: Camera,
    /// The light.
    pub light: Light,
}

/// The default light direction: 30 degrees above the default view, toward the pole (`theta = 60`,
/// `phi = -90` degrees), so the highlight sits above the image's centre.
fn default_light() -> Vector3<f64> {
    direction(PI / 3.0, -PI / 2.0)
}

impl Scene {
    /// The point-light scene: a directional light of irradiance `pi` (a white Lambertian sphere's
    /// brightest pixel is 1).
    pub fn point() -> Scene {
        Scene { camera: Camera::default(), light: Light::Point { dir: default_light(), irradiance: PI } }
    }

    /// The broad-light scene: a 25-degree spherical cap of radiance `1 / sin^2(25 deg)` (again 1 for a
    /// white Lambertian surface facing it), on a 64-pixel image by the centre rule, refined once (each
    /// point integrates the light, and the image is smooth at the pixel's scale).
    pub fn broad() -> Scene {
        let half_angle = 25f64.to_radians();
        Scene {
            camera: Camera { size: 64, refine: 1, rule: PixelRule::Centre, ..Camera::default() },
            light: Light::Cap { dir: default_light(), half_angle, radiance: 1.0 / half_angle.sin().powi(2) },
        }
    }

    /// Refuse what cannot be rendered, with the reason in one line.
    pub fn validate(&self) -> Result<()> {
        let c = &self.camera;
        let unit = |v: Vector3<f64>| v.iter().all(|x| x.is_finite()) && (v.norm() - 1.0).abs() < 1e-9;
        if !unit(c.view) {
            return Err(Error::invalid(format!("the view direction {:?} is not a unit vector", c.view.as_slice())));
        }
        if !(1..=4096).contains(&c.size) {
            return Err(Error::invalid(format!("the image size {} must be between 1 and 4096", c.size)));
        }
        if !(c.extent.is_finite() && c.extent > 0.0) {
            return Err(Error::invalid(format!("the image extent {} must be positive", c.extent)));
        }
        if !(1..=16).contains(&c.points) || c.refine > 6 || !(c.tolerance.is_finite() && c.tolerance > 0.0) {
            return Err(Error::invalid(format!(
                "pixel quadrature: points {} (1 to 16), refine {} (0 to 6), tolerance {} (> 0)",
                c.points, c.refine, c.tolerance
            )));
        }
        let (dir, strength) = match self.light {
            Light::Point { dir, irradiance } => (dir, irradiance),
            Light::Cap { dir, half_angle, radiance } => {
                if !(half_angle > 0.0 && half_angle <= PI / 2.0) {
                    return Err(Error::invalid(format!("the light's half-angle {:.4} deg must be in (0, 90]", half_angle.to_degrees())));
                }
                (dir, radiance)
            }
        };
        if !unit(dir) {
            return Err(Error::invalid(format!("the light direction {:?} is not a unit vector", dir.as_slice())));
        }
        if !(strength.is_finite() && strength >= 0.0) {
            return Err(Error::invalid(format!("the light's strength {strength} must be finite and >= 0")));
        }
        Ok(())
    }

    /// The image's right and up axes (world frame).
    pub fn image_axes(&self) -> [Vector3<f64>; 2] {
        let v = self.camera.view;
        let z = Vector3::z();
        // Looking along the pole, the projection of +z vanishes: +y is up instead.
        let up0 = if (z - v * v.z).norm() > 1e-9 { z } else { Vector3::y() };
        let up = (up0 - v * v.dot(&up0)).normalize();
        [up.cross(&v), up]
    }

    /// The normal of the sphere seen at image-plane point `(x, y)` (sphere radii from the centre, `y`
    /// up), or `None` off the sphere.
    pub fn normal_at(&self, x: f64, y: f64) -> Option<Vector3<f64>> {
        let r2 = x * x + y * y;
        if r2 >= 1.0 {
            return None;
        }
        let [right, up] = self.image_axes();
        Some(right * x + up * y + self.camera.view * (1.0 - r2).sqrt())
    }

    /// Render `brdf`: linear RGB radiance per pixel, rows from the top.
    pub fn render(&self, brdf: &dyn Brdf) -> Result<Image> {
        let [image] = self.render_set(&[brdf])?;
        Ok(image)
    }

    /// Render every BRDF of `set` in one pass over the shading points: image `k` is, bit for bit,
    /// [`Scene::render`] of BRDF `k` alone.
    pub fn render_set<const K: usize>(&self, set: &dyn BrdfSet<K>) -> Result<[Image; K]> {
        self.validate()?;
        Ok(super::integrate::render(self, set))
    }
}
