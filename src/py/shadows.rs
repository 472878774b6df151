//! Soft shadows (Algorithm 5) from Python arguments.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, named, vec3};
use super::errors::{input, IntoPy};
use super::scene::PyScene;
use crate::shadows::{self, AreaLight, Discretization, Reconstruction, ShadowOptions};

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
    let r = py
        .detach(|| shadows::soft_shadows(&s, &cam, &light, &opts))
        .py_err(py)?;
    let (h, w) = (r.height as usize, r.width as usize);
    let count = (samples.0 * samples.1) as usize;
    let d = PyDict::new(py);
    d.set_item("visibility", array(py, r.visibility, &[h, w])?)?;
    d.set_item("visible", array(py, r.visible, &[h, w, count])?)?;
    d.set_item("mask", array(py, r.mask, &[h, w])?)?;
    d.set_item("occluder_triangles", r.occluder_triangles)?;
    d.set_item("timings", named(py, r.timings)?)?;
    Ok(d)
}
