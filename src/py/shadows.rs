//! Soft shadows (non-redundant-rendering.txt Algorithm 5) and omnidirectional soft shadows
//! (eye-based-point-rendering.txt §5) from Python arguments.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, stats, vec3};
use super::errors::{input, IntoPy};
use super::scene::PyScene;
use crate::epr::omni_shadows::{OmniMethod, OmniOptions};
use crate::nonredundant::shadows::{
    self, AreaLight, Discretization, Reconstruction, ShadowOptions,
};

#[pyfunction]
#[pyo3(signature = (scene, camera, center, u, v, samples, discretization, resolution, corners, reconstruction, shadow_resolution, layers))]
#[allow(clippy::too_many_arguments)]
pub fn soft_shadows<'py>(
    py: Python<'py>,
    scene: &PyScene,
    camera: &PyCamera,
    center: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    samples: (u32, u32),
    discretization: &str,
    resolution: u32,
    corners: bool,
    reconstruction: &str,
    shadow_resolution: u32,
    layers: u32,
) -> PyResult<Bound<'py, PyDict>> {
    let light = AreaLight::new(vec3(center, "center")?, vec3(u, "u")?, vec3(v, "v")?).py_err(py)?;
    let Some(d) = Discretization::parse(discretization) else {
        return Err(input(
            py,
            format!(
                "discretization must be one of 'nonredundant', 'conventional', 'peeling', \
                 'geometry', 'raytraced', got {discretization:?}"
            ),
        ));
    };
    let reconstruction = match reconstruction {
        "hybrid" => Reconstruction::Hybrid,
        "mesh" => Reconstruction::Mesh,
        "points" => Reconstruction::Points,
        other => {
            return Err(input(
                py,
                format!("reconstruction must be 'hybrid', 'mesh' or 'points', got {other:?}"),
            ))
        }
    };
    let opts = ShadowOptions {
        samples,
        discretization: d,
        resolution,
        corners,
        reconstruction,
        shadow_resolution,
        layers,
    };
    let s = scene.inner.clone();
    let cam = camera.inner.clone();
    let (r, ops) = super::run_counted(py, || shadows::soft_shadows(&s, &cam, &light, &opts))?;
    let (h, w) = (r.height as usize, r.width as usize);
    let count = (samples.0 * samples.1) as usize;
    let d = PyDict::new(py);
    d.set_item("visibility", array(py, r.visibility, &[h, w])?)?;
    d.set_item("visible", array(py, r.visible, &[h, w, count])?)?;
    d.set_item("mask", array(py, r.mask, &[h, w])?)?;
    d.set_item("occluder_triangles", r.occluder_triangles)?;
    d.set_item("timings", super::convert::timings(py, &r.timings)?)?;
    super::set_ops(&d, ops)?;
    Ok(d)
}

/// Omnidirectional soft shadows of a spherical light; `resolution` 0 picks Eq. 6's.
#[pyfunction]
#[pyo3(signature = (scene, eye, center, radius, samples, method, rho_scale, resolution, max_resolution, seed))]
#[allow(clippy::too_many_arguments)]
pub fn omni_shadows<'py>(
    py: Python<'py>,
    scene: &PyScene,
    eye: &PyCamera,
    center: &Bound<'py, PyAny>,
    radius: f64,
    samples: u32,
    method: &str,
    rho_scale: f64,
    resolution: u32,
    max_resolution: u32,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let Some(m) = OmniMethod::parse(method) else {
        return Err(input(
            py,
            format!("method must be 'epr', 'mvr', 'ivir' or 'raytraced', got {method:?}"),
        ));
    };
    let opts = OmniOptions {
        samples,
        method: m,
        rho_scale,
        resolution: (resolution > 0).then_some(resolution),
        max_resolution,
        seed,
    };
    let center = vec3(center, "light_center")?;
    let s = scene.inner.clone();
    let cam = eye.inner.clone();
    let (r, ops) = super::run_counted(py, || {
        crate::epr::omni_shadows::omni_shadows(&s, &cam, center, radius, &opts)
    })?;
    let (h, w) = (r.height as usize, r.width as usize);
    let count = r.samples.len();
    let d = PyDict::new(py);
    d.set_item("visibility", array(py, r.visibility, &[h, w])?)?;
    d.set_item("visible", array(py, r.visible, &[h, w, count])?)?;
    d.set_item("mask", array(py, r.mask, &[h, w])?)?;
    let pts: Vec<[f64; 3]> = r.samples.iter().map(|p| p.to_array()).collect();
    d.set_item(
        "light_samples",
        super::convert::rows_owned(py, pts, &[count, 3])?,
    )?;
    d.set_item("resolution", r.resolution)?;
    d.set_item("stats", stats(py, &r.stats)?)?;
    d.set_item("timings", super::convert::timings(py, &r.timings)?)?;
    super::set_ops(&d, ops)?;
    Ok(d)
}
