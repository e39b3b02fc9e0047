//! A small deterministic renderer: a unit sphere with any BRDF under a distant point light or a broad
//! spherical-cap light, seen by an orthographic camera, every pixel integrated by a fixed quadrature
//! (no random numbers, so two renders of the same BRDF are the same bits). It is what ndfit's model
//! choice compares: the render of a fitted lobe against the render of the scan's measured table.
//!
//! The world frame is the sphere's object frame (`z` its pole), as Mitsuba 3's `sphere` with the
//! identity transform: at a point with normal `n` the shading frame is `s = normalize(-n_y, n_x, 0)`
//! (`dp/du` with `u` the azimuth about `+z`, Gram-Schmidt against `n`), `t = n x s`, `z = n`. A BRDF is
//! evaluated in that local frame. The scenes, their defaults and the quadrature's measured accuracy are
//! in `data_formats/render.md`.

#[cfg(test)]
pub(crate) mod before;
mod image;
mod integrate;
mod quadrature;
mod scene;
mod window;

use nalgebra::Vector3;

pub use image::Image;
pub use scene::{Camera, Light, PixelRule, Scene};
pub use window::Window;

/// What is rendered: a BRDF in the local shading frame (`z` the normal, `x` the tangent `s`).
pub trait Brdf: Sync {
    /// The RGB value `f(wi, wo)` (1/sr, not multiplied by a cosine) for the direction `wi` toward the
    /// camera and `wo` toward the light, both unit vectors pointing away from the surface (Mitsuba's
    /// `si.wi` and `wo`).
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3];

    /// `f(wi, wo)` for every `wo` of `wos` into `out` (the light points of one shading point), each the
    /// same value as [`Brdf::eval`] gives; a BRDF may do the work on `wi` alone once for all of them.
    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], out: &mut [[f64; 3]]) {
        for (o, &wo) in out.iter_mut().zip(wos) {
            *o = self.eval(wi, wo);
        }
    }

    /// The smooth part: the RGB share of the light from the mirror direction `r = (-wi.x, -wi.y, wi.z)`
    /// that is reflected toward `wi` (`f = m delta(wo - r) / cos theta_o`), a smooth conductor's Fresnel
    /// term for instance. Zero for a BRDF without one; [`Brdf::eval`] never includes it.
    fn mirror(&self, _wi: Vector3<f64>) -> [f64; 3] {
        [0.0; 3]
    }
}

/// `K` BRDFs rendered together at the same shading points ([`Scene::render_set`]): each value is what
/// the BRDF's own [`Brdf::eval`] gives, and work the BRDFs share at one pair of directions (a Fresnel
/// term of one conductor) may be done once. `active[k]` says which of them a point needs; the values of
/// the others are not read.
pub trait BrdfSet<const K: usize>: Sync {
    /// `f_k(wi, wo)` into `out[k]` for every `k` with `active[k]`.
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>, active: [bool; K], out: &mut [[f64; 3]; K]);

    /// `f_k(wi, wo)` for every `wo` of `wos` into `out[k]` (as long as `wos`) for every `k` with
    /// `active[k]`, as [`Brdf::eval_many`].
    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], active: [bool; K], out: &mut [Vec<[f64; 3]>; K]);

    /// Each BRDF's smooth part ([`Brdf::mirror`]) for every `k` with `active[k]` (zero for the others).
    fn mirror(&self, wi: Vector3<f64>, active: [bool; K]) -> [[f64; 3]; K];
}

/// BRDFs rendered together that share nothing but the geometry.
impl<const K: usize> BrdfSet<K> for [&dyn Brdf; K] {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>, active: [bool; K], out: &mut [[f64; 3]; K]) {
        for k in (0..K).filter(|&k| active[k]) {
            out[k] = self[k].eval(wi, wo);
        }
    }

    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], active: [bool; K], out: &mut [Vec<[f64; 3]>; K]) {
        for k in (0..K).filter(|&k| active[k]) {
            self[k].eval_many(wi, wos, &mut out[k]);
        }
    }

    fn mirror(&self, wi: Vector3<f64>, active: [bool; K]) -> [[f64; 3]; K] {
        std::array::from_fn(|k| if active[k] { self[k].mirror(wi) } else { [0.0; 3] })
    }
}

impl<F: Fn(Vector3<f64>, Vector3<f64>) -> [f64; 3] + Sync> Brdf for F {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        self(wi, wo)
    }
}

/// The shading frame `(s, t, n)` of the unit sphere at the point with normal `n` (Mitsuba 3's `sphere`):
/// `s` along `dp/du = (-y, x, 0)`; at a pole, where `dp/du` vanishes, `s = +x`.
pub fn sphere_frame(n: Vector3<f64>) -> [Vector3<f64>; 3] {
    let du = Vector3::new(-n.y, n.x, 0.0);
    let s = if du.norm_squared() > 0.0 { du.normalize() } else { Vector3::x() };
    [s, n.cross(&s), n]
}

/// `w` (world) in the local frame `(s, t, n)`.
pub fn to_local(frame: &[Vector3<f64>; 3], w: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(frame[0].dot(&w), frame[1].dot(&w), frame[2].dot(&w))
}

/// The unit vector at polar angle `theta` from `+z` and azimuth `phi` from `+x` (radians).
pub fn direction(theta: f64, phi: f64) -> Vector3<f64> {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vector3::new(st * cp, st * sp, ct)
}

/// A scene of either kind: the sphere under a distant light ([`Scene`]) or the plate under a window
/// ([`Window`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stage {
    /// The unit sphere.
    Sphere(Scene),
    /// The plate under a window.
    Window(Window),
}

impl Stage {
    /// Refuse what cannot be rendered, with the reason in one line.
    pub fn validate(&self) -> crate::Result<()> {
        match self {
            Stage::Sphere(s) => s.validate(),
            Stage::Window(w) => w.validate(),
        }
    }

    /// Render `brdf`: linear RGB radiance per pixel, rows from the top.
    pub fn render(&self, brdf: &dyn Brdf) -> crate::Result<Image> {
        let [image] = self.render_set(&[brdf])?;
        Ok(image)
    }

    /// Render every BRDF of `set` in one pass over the shading points.
    pub fn render_set<const K: usize>(&self, set: &dyn BrdfSet<K>) -> crate::Result<[Image; K]> {
        match self {
            Stage::Sphere(s) => s.render_set(set),
            Stage::Window(w) => w.render_set(set),
        }
    }
}

impl From<Scene> for Stage {
    fn from(s: Scene) -> Stage {
        Stage::Sphere(s)
    }
}
