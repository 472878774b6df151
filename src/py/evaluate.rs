//! The sampling metrics, from the arrays of a `DepthImages` result.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, flat_i32, rows_f32};
use super::errors::input;
use super::scene::PyScene;
use crate::types::DepthImages;

#[pyfunction]
#[pyo3(signature = (scene, triangle, position, depth, cameras, method, reference, frames, redundancy, cull_backfaces))]
#[allow(clippy::too_many_arguments)]
pub fn sampling_metrics<'py>(
    py: Python<'py>,
    scene: &PyScene,
    triangle: &Bound<'py, PyAny>,
    position: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    cameras: Vec<PyCamera>,
    method: String,
    reference: Vec<PyCamera>,
    frames: Vec<PyCamera>,
    redundancy: &str,
    cull_backfaces: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let mode = super::convert::redundancy(py, redundancy)?;
    let cameras: Vec<_> = cameras.into_iter().map(|c| c.inner).collect();
    let Some(first) = cameras.first() else {
        return Err(input(py, "the images have no cameras".into()));
    };
    let (width, height) = (first.width, first.height);
    let npx = width as usize * height as usize * cameras.len();
    let img = DepthImages {
        n: cameras.len(),
        width,
        height,
        triangle: flat_i32(triangle, "triangle")?,
        position: rows_f32::<3>(position, "position")?,
        depth: rows_f32::<1>(depth, "depth")?
            .into_iter()
            .map(|[d]| d)
            .collect(),
        cameras,
        method,
        ..Default::default()
    };
    if img.triangle.len() != npx || img.position.len() != npx || img.depth.len() != npx {
        return Err(input(
            py,
            format!(
                "triangle, position and depth must hold {npx} pixels ({} images of \
                 {width}x{height}), got {}, {} and {}",
                img.n,
                img.triangle.len(),
                img.position.len(),
                img.depth.len()
            ),
        ));
    }
    let reference: Vec<_> = reference.into_iter().map(|c| c.inner).collect();
    let frames: Vec<_> = frames.into_iter().map(|c| c.inner).collect();
    let s = scene.inner.clone();
    let m = super::run(py, || {
        crate::nonredundant::sampling_metrics(&s, &img, &reference, &frames, mode, cull_backfaces)
    })?;
    let n = m.samples.len();
    let d = PyDict::new(py);
    d.set_item("samples", array(py, m.samples, &[n])?)?;
    d.set_item("redundant", array(py, m.redundant, &[n])?)?;
    d.set_item("disoccluded", array(py, m.disoccluded, &[n])?)?;
    d.set_item("useful", array(py, m.useful, &[n])?)?;
    d.set_item("available_avg", array(py, m.available_avg, &[n])?)?;
    d.set_item("available_min", array(py, m.available_min, &[n])?)?;
    d.set_item("frames", m.frames)?;
    let shape = [n, height as usize, width as usize];
    d.set_item("disoccluded_mask", array(py, m.disoccluded_mask, &shape)?)?;
    d.set_item("useful_mask", array(py, m.useful_mask, &shape)?)?;
    d.set_item("timings", super::convert::timings(py, &m.timings)?)?;
    Ok(d)
}
