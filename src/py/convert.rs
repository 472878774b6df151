//! The one numpy boundary: any array-like in, checked for dtype kind and shape (messages name
//! the argument and the shape received), copied into plain Rust values; fresh arrays out.
//! numpy is row-major and glam column-major: `mat4` is the only place that converts.

use glam::DMat4;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::errors::input;

/// `np.ascontiguousarray(obj, dtype)` after checking the dtype kind (`"f"`, `"iu"`, ...).
fn as_array<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    kinds: &str,
    dtype: &str,
    what: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (obj,)).map_err(|e| {
        input(
            py,
            format!("{name} cannot be converted to a numpy array: {e}"),
        )
    })?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    if !kinds.contains(kind.as_str()) {
        let dt = arr.getattr("dtype")?.str()?.to_string();
        return Err(input(
            py,
            format!("{name} must be an array of {what}, got dtype {dt}"),
        ));
    }
    np.call_method1("ascontiguousarray", (arr, dtype))
}

fn shape_str(shape: &[usize]) -> String {
    format!(
        "({})",
        shape
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// An (n, K) array of real numbers (kinds f, i, u, b accepted), converted by numpy to `dtype`
/// (no copy when it already is a C-contiguous array of that dtype) and checked for shape; read
/// its rows with [`borrow_rows`].
pub fn rows_array_of<'py, T: numpy::Element, const K: usize>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    dtype: &str,
) -> PyResult<PyReadonlyArrayDyn<'py, T>> {
    let arr = as_array(obj, name, "fiub", dtype, "real numbers")?;
    let arr: PyReadonlyArrayDyn<T> = arr.extract()?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 || shape[1] != K {
        return Err(input(
            obj.py(),
            format!("{name} must have shape (n, {K}), got {}", shape_str(&shape)),
        ));
    }
    Ok(arr)
}

/// The rows of an array from [`rows_array_of`], borrowed without copying.
pub fn borrow_rows<'a, T: numpy::Element + bytemuck::Pod, const K: usize>(
    arr: &'a PyReadonlyArrayDyn<'_, T>,
    name: &str,
) -> PyResult<&'a [[T; K]]> {
    let flat = arr
        .as_slice()
        .map_err(|e| input(arr.py(), format!("{name}: {e}")))?;
    Ok(bytemuck::cast_slice(flat))
}

/// An (n, K) array of real numbers as rows of `T`, converted by numpy to `dtype` first.
fn rows<T: numpy::Element + bytemuck::Pod, const K: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dtype: &str,
) -> PyResult<Vec<[T; K]>> {
    let arr = rows_array_of::<T, K>(obj, name, dtype)?;
    Ok(borrow_rows::<T, K>(&arr, name)?.to_vec())
}

/// An (n, K) array of real numbers as rows of f64.
pub fn rows_f64<const K: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<[f64; K]>> {
    rows(obj, name, "float64")
}

/// An (n, K) array of real numbers as rows of f32.
pub fn rows_f32<const K: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<[f32; K]>> {
    rows(obj, name, "float32")
}

/// An (m, 3) integer array of vertex indices (any integer dtype), checked to lie in
/// `0..vertex_count`; the message names the face and the offending index.
pub fn faces(obj: &Bound<'_, PyAny>, name: &str, vertex_count: usize) -> PyResult<Vec<[u32; 3]>> {
    let py = obj.py();
    let arr = as_array(obj, name, "iu", "int64", "integers")?;
    let arr: PyReadonlyArrayDyn<i64> = arr.extract()?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(input(
            py,
            format!("{name} must have shape (m, 3), got {}", shape_str(&shape)),
        ));
    }
    let flat = arr
        .as_slice()
        .map_err(|e| input(py, format!("{name}: {e}")))?;
    let mut out = Vec::with_capacity(flat.len() / 3);
    for (i, f) in flat.chunks_exact(3).enumerate() {
        if let Some(&bad) = f
            .iter()
            .find(|&&x| x < 0 || x as u64 >= vertex_count as u64)
        {
            return Err(super::errors::typed(
                py,
                "SceneError",
                format!("{name}[{i}] = {f:?} refers to vertex {bad}, but valid indices are 0..{} ({vertex_count} vertices)", vertex_count as i64 - 1),
            ));
        }
        out.push([f[0] as u32, f[1] as u32, f[2] as u32]);
    }
    Ok(out)
}

/// A 4×4 row-major numpy matrix → glam (column-major).
pub fn mat4(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DMat4> {
    let rows = rows_f64::<4>(obj, name)?;
    let rows: [[f64; 4]; 4] = rows.try_into().map_err(|r: Vec<_>| {
        input(
            obj.py(),
            format!("{name} must have shape (4, 4), got ({}, 4)", r.len()),
        )
    })?;
    // numpy rows become glam columns, then transpose: the one row/column-major conversion.
    Ok(DMat4::from_cols_array_2d(&rows).transpose())
}

/// glam → a fresh (4, 4) row-major float64 array.
pub fn mat4_to_numpy<'py>(py: Python<'py>, m: &DMat4) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = m.transpose().to_cols_array().to_vec();
    Ok(PyArray1::from_vec(py, flat).reshape([4, 4])?.into_any())
}

/// A flat vector as a fresh numpy array of the given shape.
pub fn array<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v)
        .reshape(shape.to_vec())?
        .into_any())
}

/// Rows of K values as a fresh numpy array of `shape` (whose last dimension is K).
pub fn rows_array<'py, T: numpy::Element + Copy, const K: usize>(
    py: Python<'py>,
    v: &[[T; K]],
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    array(py, v.as_flattened().to_vec(), shape)
}

/// A 3-vector argument (any sequence of three real numbers).
pub fn vec3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<glam::DVec3> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let flat = np.call_method1("reshape", (obj, (1, -1)));
    let flat = flat.map_err(|e| input(py, format!("{name} must be 3 numbers: {e}")))?;
    let rows = rows_f64::<3>(&flat, name)?;
    match rows.as_slice() {
        [r] => Ok(glam::DVec3::from_array(*r)),
        _ => Err(input(py, format!("{name} must be 3 numbers"))),
    }
}

/// Any real array, flattened, as f32.
pub fn flat_f32(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f32>> {
    let arr = as_array(obj, name, "iuf", "float32", "numbers")?;
    let arr: PyReadonlyArrayDyn<f32> = arr.extract()?;
    let flat = arr
        .as_slice()
        .map_err(|e| input(obj.py(), format!("{name}: {e}")))?;
    Ok(flat.to_vec())
}

/// Any integer array, flattened, as i32 (values must fit).
pub fn flat_i32(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<i32>> {
    let arr = as_array(obj, name, "iu", "int64", "integers")?;
    let arr: PyReadonlyArrayDyn<i64> = arr.extract()?;
    let flat = arr
        .as_slice()
        .map_err(|e| input(obj.py(), format!("{name}: {e}")))?;
    flat.iter()
        .map(|&x| {
            i32::try_from(x)
                .map_err(|_| input(obj.py(), format!("{name} holds {x}, outside int32")))
        })
        .collect()
}

/// Owned rows of K values as a numpy array of `shape`, without copying the data.
pub fn rows_owned<'py, T: numpy::Element, const K: usize>(
    py: Python<'py>,
    v: Vec<[T; K]>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    array(py, v.into_flattened(), shape)
}

/// A redundancy definition by name ("pixel" or "visibility").
pub fn redundancy(py: Python<'_>, name: &str) -> PyResult<crate::nonredundant::Redundancy> {
    crate::nonredundant::Redundancy::parse(name).ok_or_else(|| {
        input(
            py,
            format!("redundancy must be 'pixel' or 'visibility', got {name:?}"),
        )
    })
}

/// A call's [`Stats`](crate::types::Stats) as a dict, in the order they were recorded.
pub fn stats<'py>(py: Python<'py>, s: &crate::types::Stats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in s.iter() {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// A call's [`Timings`](crate::types::Timings) as a dict of seconds, in stage order.
pub fn timings<'py>(py: Python<'py>, t: &crate::types::Timings) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in t.iter() {
        d.set_item(k, v)?;
    }
    Ok(d)
}
