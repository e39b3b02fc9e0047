//! The synthetic set: the visible half of a skewed, anisotropic ellipsoid (its NDF is exactly the
//! ellipsoid NDF of Walter et al. eq. 1, see `ellipsoid`), written once per size as a
//! float64 NPY file so that every point of the sweep times the real reader.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::models::Model;
use crate::scan::Heightfield;
use crate::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

/// Grid spacing of every synthetic scan (m). The ellipsoid is sized to the grid, so the NDF does not
/// depend on it; readers need one.
pub const DX: f64 = 1e-6;

/// The truth of the synthetic set: skewed (`theta_x`, `theta_y` != 0), anisotropic and rotated, so every
/// one of the five ellipsoid parameters is exercised.
pub fn truth_params() -> EllipsoidParams {
    EllipsoidParams { alpha_x: 0.35, alpha_y: 0.18, theta_x: 0.15, theta_y: -0.10, theta_z: 0.6, fill: 0.96 }
}

/// One synthetic scan on disk with its truth.
#[derive(Debug)]
pub struct Scene {
    /// Side of the square grid.
    pub size: usize,
    /// The NPY file.
    pub path: PathBuf,
    /// The true NDF.
    pub truth: Model,
    /// Valid points of the scan (0 when opened rather than created).
    pub valid: usize,
}

impl Scene {
    /// Generate the `size x size` scan and write it as `dir/ellipsoid_<size>.npy`.
    pub fn create(dir: &Path, size: usize) -> Result<Scene> {
        let s = SynthSettings { nx: size, ny: size, dx: DX, dy: DX, seed: 1, ..SynthSettings::default() };
        let (hf, truth) = ellipsoid_surface(&s, &truth_params())?;
        let path = dir.join(format!("ellipsoid_{size}.npy"));
        write_npy_f64(&path, &hf)?;
        Ok(Scene { size, path, truth: truth.to_model()?, valid: hf.valid_count() })
    }

    /// A scene already on disk (written by [`Scene::create`] with the same size); the truth is
    /// [`truth_params`].
    pub fn open(path: &Path, size: usize) -> Result<Scene> {
        let s = SynthSettings { nx: size, ny: size, dx: DX, dy: DX, seed: 1, ..SynthSettings::default() };
        let g = crate::synth::ellipsoid::EllipsoidGeometry::new(&truth_params(), &s)?;
        Ok(Scene { size, path: path.to_path_buf(), truth: Model::Ellipsoid(g.model), valid: 0 })
    }

    /// The read options of the scene's NPY file (spacing and unit are not in the file).
    pub fn read_options(&self) -> crate::io::ReadOptions {
        crate::io::ReadOptions { dx: Some(DX), dy: Some(DX), z_scale: Some(1.0), format: None }
    }
}

/// Write `hf` as a C-ordered little-endian float64 NPY (format 1.0), NaN at invalid points.
pub fn write_npy_f64(path: &Path, hf: &Heightfield) -> Result<()> {
    let dict = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, {}), }}", hf.ny, hf.nx);
    // The header (magic 6 + version 2 + length 2 + dict + '\n') is padded with spaces to a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let pad = unpadded.div_ceil(64) * 64 - unpadded;
    let header = format!("{dict}{}\n", " ".repeat(pad));
    let hlen = u16::try_from(header.len()).map_err(|_| Error::invalid("NPY header too long"))?;
    crate::io::write_atomic(path, |w| {
        w.write_all(b"\x93NUMPY\x01\x00")?;
        w.write_all(&hlen.to_le_bytes())?;
        w.write_all(header.as_bytes())?;
        for row in hf.z.chunks(hf.nx.max(1)) {
            let mut buf = Vec::with_capacity(row.len() * 8);
            for v in row {
                buf.extend_from_slice(&v.to_le_bytes());
            }
            w.write_all(&buf)?;
        }
        Ok(())
    })
}
