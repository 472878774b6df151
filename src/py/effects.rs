//! Reflections (eye-based-point-rendering.txt §4) from Python arguments.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, flat_i32, rows_f64, rows_owned, stats};
use super::errors::input;
use super::scene::PyScene;
use crate::epr::points::Reflector;
use crate::epr::reflections::{Method, ReflectionOptions};

/// Reflectors from parallel lists: centres (R, 3), radii, triangle ids per reflector.
pub fn reflectors(
    py: Python<'_>,
    scene: &PyScene,
    centers: &Bound<'_, PyAny>,
    radii: &[f64],
    triangles: &[Bound<'_, PyAny>],
) -> PyResult<Vec<Reflector>> {
    let centers = rows_f64::<3>(centers, "reflector centres")?;
    if centers.len() != radii.len() || centers.len() != triangles.len() {
        return Err(input(
            py,
            format!(
                "{} reflector centres, {} radii and {} triangle lists: one of each per reflector",
                centers.len(),
                radii.len(),
                triangles.len()
            ),
        ));
    }
    let n = scene.inner.triangle_count();
    let mut out = Vec::with_capacity(centers.len());
    for (k, ((c, r), t)) in centers.iter().zip(radii).zip(triangles).enumerate() {
        let ids = flat_i32(t, &format!("reflector {k}'s triangles"))?;
        if let Some(bad) = ids.iter().find(|&&i| i < 0 || i as usize >= n) {
            return Err(input(
                py,
                format!("reflector {k} names triangle {bad}, but the scene has {n} triangles"),
            ));
        }
        out.push(Reflector {
            center: glam::DVec3::from_array(*c),
            radius: *r,
            triangles: ids.into_iter().map(|i| i as u32).collect(),
        });
    }
    Ok(out)
}

#[pyfunction]
#[pyo3(signature = (scene, eye, centers, radii, triangles, resolutions, method, bounces, supersample, rho_scale, seed))]
#[allow(clippy::too_many_arguments)]
pub fn reflections<'py>(
    py: Python<'py>,
    scene: &PyScene,
    eye: &PyCamera,
    centers: &Bound<'py, PyAny>,
    radii: Vec<f64>,
    triangles: Vec<Bound<'py, PyAny>>,
    resolutions: Vec<u32>,
    method: &str,
    bounces: u32,
    supersample: usize,
    rho_scale: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let refl = reflectors(py, scene, centers, &radii, &triangles)?;
    let Some(method) = Method::parse(method) else {
        return Err(input(
            py,
            format!("method must be 'epr', 'mvr' or 'ivir', got {method:?}"),
        ));
    };
    let opts = ReflectionOptions {
        method,
        bounces,
        supersample,
        rho_scale,
        seed,
        resolutions,
    };
    let s = scene.inner.clone();
    let cam = eye.inner.clone();
    let (r, ops) = super::run_counted(py, || {
        crate::epr::reflections::reflections(&s, &cam, &refl, &opts)
    })?;
    let (h, w) = (r.height as usize, r.width as usize);
    let d = PyDict::new(py);
    d.set_item("image", rows_owned(py, r.image, &[h, w, 3])?)?;
    d.set_item("reflective", array(py, r.reflective, &[h, w])?)?;
    d.set_item("stats", stats(py, &r.stats)?)?;
    d.set_item("timings", super::convert::timings(py, &r.timings)?)?;
    super::set_ops(&d, ops)?;
    Ok(d)
}
