//! EPR points (§3.1-3.4) and splatting (§3.5) from Python arguments.

use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, flat_i32, rows_f32, rows_owned, stats, vec3};
use super::errors::{input, IntoPy};
use super::scene::PyScene;
use crate::epr::omni_shadows::{eye_resolution, light_samples, NEAR};
use crate::epr::points::{self as epr, Density};
use crate::types::Points;

/// Points for the cube maps of the reflectors (centres (R, 3), radii, triangle ids per
/// reflector, cube-map resolution per reflector); `density` is "eye" (EPR) or "offscreen"
/// (iVIR).
#[pyfunction]
#[pyo3(signature = (scene, eye, centers, radii, triangles, resolutions, density, rho_scale, seed, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn epr_points<'py>(
    py: Python<'py>,
    scene: &PyScene,
    eye: &PyCamera,
    centers: &Bound<'py, PyAny>,
    radii: Vec<f64>,
    triangles: Vec<Bound<'py, PyAny>>,
    resolutions: Vec<u32>,
    density: &str,
    rho_scale: f64,
    seed: u64,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let reflectors = super::effects::reflectors(py, scene, centers, &radii, &triangles)?;
    let density = parse_density(py, density, rho_scale)?;
    let s = scene.inner.clone();
    let cam = eye.inner.clone();
    let p = super::run_with(py, progress, || {
        epr::generate(&s, &cam, &reflectors, &resolutions, density, seed)
    })?;
    let views = epr::cube_views(&reflectors, &resolutions).py_err(py)?;
    points_dict(py, p, views)
}

/// Points for the shadow cube maps of a spherical light's samples (§5.1, Eq. 5), all faces at
/// `resolution` (0: Eq. 6 for what the eye sees, at most `max_resolution`); `density` as for
/// `epr_points`.
#[pyfunction]
#[pyo3(signature = (scene, eye, center, radius, samples, resolution, max_resolution, density, rho_scale, seed))]
#[allow(clippy::too_many_arguments)]
pub fn epr_shadow_points<'py>(
    py: Python<'py>,
    scene: &PyScene,
    eye: &PyCamera,
    center: &Bound<'py, PyAny>,
    radius: f64,
    samples: u32,
    resolution: u32,
    max_resolution: u32,
    density: &str,
    rho_scale: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let density = parse_density(py, density, rho_scale)?;
    let center = vec3(center, "center")?;
    if !(center.is_finite() && radius.is_finite() && radius >= 0.0) || samples == 0 {
        return Err(input(
            py,
            format!(
                "the light needs a finite centre, a finite radius >= 0 and at least one sample; \
                 got {center:?}, {radius}, {samples}"
            ),
        ));
    }
    let lights = light_samples(center, radius, samples).py_err(py)?;
    let near = NEAR * scene.inner.diagonal();
    let s = scene.inner.clone();
    let cam = eye.inner.clone();
    let (p, resolution) = super::run(py, || {
        let res = match resolution {
            0 => eye_resolution(&s, &cam, center, radius, max_resolution)?,
            r => r,
        };
        epr::generate_shadow(&s, &cam, &lights, res, near, density, seed).map(|p| (p, res))
    })?;
    let views = epr::shadow_views(&lights, resolution, near).py_err(py)?;
    points_dict(py, p, views)
}

fn parse_density(py: Python<'_>, density: &str, rho_scale: f64) -> PyResult<Density> {
    match density {
        "eye" => Ok(Density::Eye { rho_scale }),
        "offscreen" => Ok(Density::OffScreen),
        other => Err(input(
            py,
            format!("density must be 'eye' or 'offscreen', got {other:?}"),
        )),
    }
}

/// The point arrays, the views they were made for, timings and stats.
fn points_dict<'py>(
    py: Python<'py>,
    p: Points,
    views: Vec<crate::camera::Camera>,
) -> PyResult<Bound<'py, PyDict>> {
    let n = p.len();
    let words = p.words();
    let d = PyDict::new(py);
    d.set_item("center", rows_owned(py, p.center, &[n, 3])?)?;
    d.set_item("length", array(py, p.length, &[n])?)?;
    d.set_item("triangle", array(py, p.triangle, &[n])?)?;
    d.set_item("normal", rows_owned(py, p.normal, &[n, 3])?)?;
    d.set_item("shading_normal", rows_owned(py, p.shading_normal, &[n, 3])?)?;
    d.set_item("color", rows_owned(py, p.color, &[n, 3])?)?;
    d.set_item("material", array(py, p.material, &[n])?)?;
    d.set_item("views", array(py, p.views, &[n, words])?)?;
    let cams: Vec<PyCamera> = views.into_iter().map(PyCamera::from).collect();
    d.set_item("cameras", cams)?;
    d.set_item("timings", super::convert::timings(py, &p.timings)?)?;
    d.set_item("stats", stats(py, &p.stats)?)?;
    Ok(d)
}

/// Splat points (centres (P, 3), lengths (P,), triangles (P,), visibility words (P, W) uint64)
/// into one buffer per camera.
#[pyfunction]
#[pyo3(signature = (scene, center, length, triangle, views, cameras, clip_to_triangle))]
#[allow(clippy::too_many_arguments)]
pub fn splat<'py>(
    py: Python<'py>,
    scene: &PyScene,
    center: &Bound<'py, PyAny>,
    length: &Bound<'py, PyAny>,
    triangle: &Bound<'py, PyAny>,
    views: &Bound<'py, PyAny>,
    cameras: Vec<PyCamera>,
    clip_to_triangle: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let center = rows_f32::<3>(center, "center")?;
    let length = rows_f32::<1>(&length.call_method1("reshape", ((-1i64, 1i64),))?, "length")?;
    let triangle = flat_i32(triangle, "triangle")?;
    let bits: PyReadonlyArray2<u64> = views.extract().map_err(|_| {
        input(
            py,
            "views must be a 2-D uint64 array of visibility words (P, ceil(V / 64))".to_string(),
        )
    })?;
    let words = bits.shape()[1];
    let view_count = cameras.len();
    if words != view_count.div_ceil(64).max(1) {
        return Err(input(
            py,
            format!(
                "{view_count} views need {} visibility words per point, got {words}",
                view_count.div_ceil(64).max(1)
            ),
        ));
    }
    let points = Points {
        center,
        length: length.into_iter().map(|[l]| l).collect(),
        triangle,
        views: bits.as_array().iter().copied().collect(),
        view_count,
        ..Default::default()
    };
    let cams: Vec<_> = cameras.into_iter().map(|c| c.inner).collect();
    let s = scene.inner.clone();
    let (b, ops) = super::run_counted(py, || {
        crate::epr::splat::splat(&s, &points, &cams, clip_to_triangle)
    })?;
    let shape = [b.views, b.height as usize, b.width as usize];
    let d = PyDict::new(py);
    d.set_item("depth", array(py, b.depth(), &shape)?)?;
    d.set_item("index", array(py, b.index(), &shape)?)?;
    d.set_item("packed", array(py, b.packed, &shape)?)?;
    d.set_item("timings", super::convert::timings(py, &b.timings)?)?;
    super::set_ops(&d, ops)?;
    Ok(d)
}
