//! Reconstruction from the arrays of a `DepthImages` result.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, flat_i32, rows_f32, rows_owned};
use super::errors::input;
use crate::nonredundant::reconstruct::{
    reconstruct_hybrid, reconstruct_mesh, reconstruct_points, Mesh,
};
use crate::types::DepthImages;

/// A `DepthImages` (any object with its fields) as the Rust struct, checked for size.
pub fn depth_images(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DepthImages> {
    let py = obj.py();
    let cameras: Vec<PyCamera> = obj.getattr("cameras")?.extract()?;
    let cameras: Vec<_> = cameras.into_iter().map(|c| c.inner).collect();
    let Some(first) = cameras.first() else {
        return Err(input(py, format!("{name} has no images")));
    };
    let (width, height) = (first.width, first.height);
    let field = |f: &str| obj.getattr(f);
    let depth: Vec<f32> = rows_f32::<1>(
        &field("depth")?.call_method1("reshape", ((-1, 1),))?,
        &format!("{name}.depth"),
    )?
    .into_iter()
    .map(|[d]| d)
    .collect();
    let img = DepthImages {
        n: cameras.len(),
        width,
        height,
        depth,
        triangle: flat_i32(&field("triangle")?, &format!("{name}.triangle"))?,
        normal: rows_f32::<3>(
            &field("normal")?.call_method1("reshape", ((-1, 3),))?,
            &format!("{name}.normal"),
        )?,
        position: rows_f32::<3>(
            &field("position")?.call_method1("reshape", ((-1, 3),))?,
            &format!("{name}.position"),
        )?,
        cameras,
        method: field("method")?.extract().unwrap_or_default(),
        ..Default::default()
    };
    Ok(img)
}

/// A `Mesh` as a dict of numpy arrays.
pub fn mesh_dict<'py>(py: Python<'py>, m: Mesh) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let (nv, nf) = (m.vertices.len(), m.faces.len());
    d.set_item("vertices", rows_owned(py, m.vertices, &[nv, 3])?)?;
    d.set_item("faces", rows_owned(py, m.faces, &[nf, 3])?)?;
    d.set_item("sample", array(py, m.sample, &[nf])?)?;
    d.set_item("timings", super::convert::timings(py, &m.timings)?)?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (images, method, offset=None))]
pub fn reconstruct<'py>(
    py: Python<'py>,
    images: &Bound<'py, PyAny>,
    method: &str,
    offset: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let img = depth_images(images, "images")?;
    let m = match (method, offset) {
        ("mesh", _) => super::run(py, || reconstruct_mesh(&img)),
        ("points", _) => super::run(py, || reconstruct_points(&img)),
        ("hybrid", Some(off)) => {
            let off = depth_images(off, "offset")?;
            super::run(py, || reconstruct_hybrid(&img, &off))
        }
        ("hybrid", None) => {
            return Err(input(
                py,
                "hybrid reconstruction needs the offset images".into(),
            ))
        }
        _ => {
            return Err(input(
                py,
                format!("method must be 'mesh', 'hybrid' or 'points', got {method:?}"),
            ))
        }
    }?;
    mesh_dict(py, m)
}
