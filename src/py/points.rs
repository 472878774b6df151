//! Point queries (`trace::points`): closest surface points and generalized winding numbers.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::convert::{array, borrow_rows, rows_array_of, rows_owned};
use super::errors::IntoPy;
use super::scene::PyScene;
use crate::trace::{points, winding, Threads};

/// The closest surface point of each point (rows (N, 3), read in place when float32).
#[pyfunction]
#[pyo3(signature = (scene, points, max_distance=f32::INFINITY, threads=None, progress=None))]
pub fn closest_points<'py>(
    py: Python<'py>,
    scene: &PyScene,
    points: &Bound<'py, PyAny>,
    max_distance: f32,
    threads: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = rows_array_of::<f32, 3>(points, "points", "float32")?;
    let p = borrow_rows::<f32, 3>(&p, "points")?;
    let threads = Threads::from_count(threads).py_err(py)?;
    let s = scene.inner.clone();
    let r = super::rays::on_threads(py, threads, progress, || {
        points::closest_points(&s, p, max_distance, threads)
    })?;
    let n = r.distance.len();
    let d = PyDict::new(py);
    d.set_item("point", rows_owned(py, r.point, &[n, 3])?)?;
    d.set_item("distance", array(py, r.distance, &[n])?)?;
    d.set_item("triangle", array(py, r.triangle, &[n])?)?;
    d.set_item("barycentric", rows_owned(py, r.barycentric, &[n, 2])?)?;
    let t = PyDict::new(py);
    t.set_item("bvh_build", r.bvh_build_seconds)?;
    t.set_item("query", r.query_seconds)?;
    d.set_item("timings", t)?;
    Ok(d)
}

/// The generalized winding number of the scene's surface at each point (rows (N, 3)).
#[pyfunction]
#[pyo3(signature = (scene, points, threads=None, progress=None))]
pub fn winding_numbers<'py>(
    py: Python<'py>,
    scene: &PyScene,
    points: &Bound<'py, PyAny>,
    threads: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let p = rows_array_of::<f32, 3>(points, "points", "float32")?;
    let p = borrow_rows::<f32, 3>(&p, "points")?;
    let threads = Threads::from_count(threads).py_err(py)?;
    let s = scene.inner.clone();
    let w = super::rays::on_threads(py, threads, progress, || {
        winding::winding_numbers(&s, p, threads)
    })?;
    let n = w.len();
    array(py, w, &[n])
}
