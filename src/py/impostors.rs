//! Multi-cell impostors (multi-cell-orthographic-impostors.txt) from Python arguments.

use std::sync::Arc;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, stats};
use super::errors::input;
use super::scene::PyScene;
use crate::impostors::build::{self as di, ImpostorOptions, ImpostorProjection, Impostors};
use crate::impostors::view as ri;

/// The built impostors, kept on the Rust side for `impostor_view`.
#[pyclass(name = "Impostors", module = "scenesample._core", frozen)]
pub struct PyImpostors {
    inner: Arc<Impostors>,
    projection: ImpostorProjection,
    /// The scene with its faces in cell order (for drawing cells as triangles).
    sorted: Arc<crate::scene::Scene>,
}

fn projection(py: Python<'_>, name: &str, fov: Option<f64>) -> PyResult<ImpostorProjection> {
    match (name, fov) {
        ("orthographic", None) => Ok(ImpostorProjection::Orthographic),
        ("orthographic", Some(_)) => Err(input(
            py,
            "fov applies to projection='perspective'".to_string(),
        )),
        ("perspective", Some(f)) => Ok(ImpostorProjection::Perspective(f)),
        ("perspective", None) => Err(input(
            py,
            "projection='perspective' needs fov= (radians)".to_string(),
        )),
        (other, _) => Err(input(
            py,
            format!("projection must be 'orthographic' or 'perspective', got {other:?}"),
        )),
    }
}

/// Build the impostors: the handle and the arrays.
#[pyfunction]
#[pyo3(signature = (scene, depth, subdivisions, resolution, projection_name, fov, grow, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn impostors<'py>(
    py: Python<'py>,
    scene: &PyScene,
    depth: u32,
    subdivisions: u32,
    resolution: u32,
    projection_name: &str,
    fov: Option<f64>,
    grow: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PyImpostors, Bound<'py, PyDict>)> {
    let proj = projection(py, projection_name, fov)?;
    let opts = ImpostorOptions {
        depth,
        subdivisions,
        resolution,
        projection: proj,
        grow,
    };
    let s = scene.inner.clone();
    let (imp, sorted) = super::run_with(py, progress, || -> crate::error::Result<_> {
        let imp = di::build(&s, &opts)?;
        let sorted = s.permuted(&imp.triangles)?;
        Ok((imp, sorted))
    })?;
    let (c, d, h, w) = (imp.cells.len(), imp.directions.len(), imp.height, imp.width);
    let out = PyDict::new(py);
    let lo: Vec<f64> = imp.cells.iter().flat_map(|x| x.lo.to_array()).collect();
    out.set_item("lo", array(py, lo, &[c, 3])?)?;
    let size: Vec<f64> = imp.cells.iter().map(|x| x.size).collect();
    out.set_item("size", array(py, size, &[c])?)?;
    let index: Vec<u32> = imp.cells.iter().flat_map(|x| x.index).collect();
    out.set_item("index", array(py, index, &[c, 3])?)?;
    let dirs: Vec<f64> = imp.directions.iter().flat_map(|v| v.to_array()).collect();
    out.set_item("directions", array(py, dirs, &[d, 3])?)?;
    let color: Vec<u8> = imp.color.iter().flatten().copied().collect();
    out.set_item("color", array(py, color, &[c, d, h, w, 4])?)?;
    out.set_item("depth", array(py, imp.depth.clone(), &[c, d, h, w])?)?;
    let crops: Vec<u32> = imp.crops.iter().flatten().copied().collect();
    out.set_item("crops", array(py, crops, &[c, d, 4])?)?;
    out.set_item(
        "triangle_counts",
        array(py, imp.triangle_counts.clone(), &[c])?,
    )?;
    out.set_item("offsets", array(py, imp.offsets.clone(), &[c + 1])?)?;
    let n = imp.triangles.len();
    out.set_item("triangles", array(py, imp.triangles.clone(), &[n])?)?;
    out.set_item("rays", imp.rays)?;
    out.set_item("timings", super::convert::timings(py, &imp.timings)?)?;
    let handle = PyImpostors {
        inner: Arc::new(imp),
        projection: proj,
        sorted: Arc::new(sorted),
    };
    Ok((handle, out))
}

fn view_dict<'py>(py: Python<'py>, v: ri::ImpostorView) -> PyResult<Bound<'py, PyDict>> {
    let (h, w) = (v.height as usize, v.width as usize);
    let d = PyDict::new(py);
    d.set_item(
        "color",
        super::convert::rows_owned(py, v.color, &[h, w, 3])?,
    )?;
    d.set_item("depth", array(py, v.depth, &[h, w])?)?;
    let c = v.used.len();
    d.set_item("used", array(py, v.used, &[c])?)?;
    d.set_item("stats", stats(py, &v.stats)?)?;
    d.set_item("timings", super::convert::timings(py, &v.timings)?)?;
    Ok(d)
}

/// The view of `camera` from the impostors; `triangle_budget` None: no limit.
#[pyfunction]
#[pyo3(signature = (handle, camera, triangle_budget, use_scene, screen_threshold))]
pub fn impostor_view<'py>(
    py: Python<'py>,
    handle: &PyImpostors,
    camera: &PyCamera,
    triangle_budget: Option<u64>,
    use_scene: bool,
    screen_threshold: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let imp = handle.inner.clone();
    let sorted = handle.sorted.clone();
    let proj = handle.projection;
    let cam = camera.inner.clone();
    let v = super::run(py, || {
        let s = use_scene.then_some(&*sorted);
        ri::reconstruct(&imp, proj, s, &cam, triangle_budget, screen_threshold)
    })?;
    view_dict(py, v)
}

/// Every triangle of the scene from `camera`, lit as the impostors are (the reference).
#[pyfunction]
#[pyo3(signature = (scene, camera))]
pub fn render_lit<'py>(
    py: Python<'py>,
    scene: &PyScene,
    camera: &PyCamera,
) -> PyResult<Bound<'py, PyDict>> {
    let s = scene.inner.clone();
    let cam = camera.inner.clone();
    let (color, depth, seconds) = super::run(py, || ri::render_lit(&s, &cam))?;
    let (h, w) = (cam.height as usize, cam.width as usize);
    let d = PyDict::new(py);
    d.set_item("color", super::convert::rows_owned(py, color, &[h, w, 3])?)?;
    d.set_item("depth", array(py, depth, &[h, w])?)?;
    d.set_item("seconds", seconds)?;
    Ok(d)
}

/// The direction index each cell would use from `camera` (smallest angle).
#[pyfunction]
pub fn impostor_directions(handle: &PyImpostors, camera: &PyCamera) -> Vec<usize> {
    (0..handle.inner.cells.len())
        .map(|c| ri::best_direction(&handle.inner, c, &camera.inner))
        .collect()
}
