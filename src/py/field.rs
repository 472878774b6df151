//! The visibility field (visibility-field.txt §3-4) from Python arguments. A built field stays
//! on the Rust side ([`PyField`]): Python reads its arrays as read-only numpy views, and a view
//! sends only the camera and its options across.

use std::sync::Arc;

use numpy::ndarray::{Array, ArrayD, IxDyn};
use numpy::{PyArray, PyReadonlyArray1, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, rows_f64};
use super::errors::{input, IntoPy};
use super::scene::PyScene;
use crate::visibility_field::{self as vf, Grouping, Interpolate, Rect, Slab};

/// A slab from a (2, 3, 3) array: uv then st, each (origin, u edge, v edge).
fn slab(py: Python<'_>, obj: &Bound<'_, PyAny>) -> PyResult<Slab> {
    let rows = rows_f64::<3>(obj, "slab")?;
    if rows.len() != 6 {
        return Err(input(
            py,
            "a slab is (2, 3, 3): uv then st, each (origin, u, v)".to_string(),
        ));
    }
    let v = |i: usize| glam::DVec3::from_array(rows[i]);
    let uv = Rect::new(v(0), v(1), v(2)).py_err(py)?;
    let st = Rect::new(v(3), v(4), v(5)).py_err(py)?;
    Ok(Slab { uv, st })
}

/// Slabs as a (K, 2, 3, 3) array: each one's uv then st, each (origin, u edge, v edge).
fn slab_arrays<'py>(py: Python<'py>, slabs: &[Slab]) -> PyResult<Bound<'py, PyAny>> {
    let rows: Vec<f64> = (slabs.iter())
        .flat_map(|s| [s.uv.origin, s.uv.u, s.uv.v, s.st.origin, s.st.u, s.st.v])
        .flat_map(|p| p.to_array())
        .collect();
    array(py, rows, &[slabs.len(), 2, 3, 3])
}

/// The paper's single slab around a scene (`Slab::around`), as a (2, 3, 3) array.
#[pyfunction]
#[pyo3(signature = (scene, axis, margin, widen))]
pub fn default_slab<'py>(
    py: Python<'py>,
    scene: &PyScene,
    axis: Option<usize>,
    margin: f64,
    widen: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let s = Slab::around(&scene.inner, axis, margin, widen).py_err(py)?;
    slab_arrays(py, &[s])?.call_method1("reshape", ((2, 3, 3),))
}

/// The six slabs around a scene (both directions along each axis), as a (6, 2, 3, 3) array.
#[pyfunction]
#[pyo3(signature = (scene, margin))]
pub fn six_slabs<'py>(
    py: Python<'py>,
    scene: &PyScene,
    margin: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let slabs = Slab::six(&scene.inner, margin).py_err(py)?;
    slab_arrays(py, &slabs)
}

/// A built visibility field (visibility-field.txt §3), owned here: the cell-sorted scene its
/// views draw and trace, its slabs, the sampled ids and counts, and the cells. Python holds
/// this handle and read-only numpy views of its arrays (nothing can change them, so what a view
/// reads is what was built); `field_view` and `render_cells` take it whole. Every array is in
/// C order (made by [`owned`] or [`taken`]), so each reads as one flat slice.
#[pyclass(name = "Field", module = "scenesample._core", frozen)]
pub struct PyField {
    /// The scene with its faces in cell order: sorted face `i` is the scene's `order[i]`.
    sorted: Arc<crate::scene::Scene>,
    slabs: Vec<Slab>,
    /// (K, U, V, S, T, n) cell ids, -1 where fewer cells were hit.
    ids: ArrayD<i32>,
    /// (K, U, V, S, T): how many distinct cells each sample's rays hit.
    hits: ArrayD<u16>,
    /// (F,): the scene's faces in cell order (sorted face `i` is the scene's `order[i]`).
    order: ArrayD<u32>,
    /// (C + 1,): cell c holds sorted faces `offsets[c]..offsets[c + 1]`.
    offsets: ArrayD<u32>,
    /// (C, 4): group, x, y, z.
    cells: ArrayD<i32>,
    /// (C, 2, 3): each cell's grid box.
    cell_bounds: ArrayD<f32>,
    /// (F,): each triangle's cell.
    cell_of: ArrayD<u32>,
}

fn owned<T: Clone>(v: Vec<T>, shape: &[usize]) -> PyResult<ArrayD<T>> {
    Array::from_shape_vec(IxDyn(shape), v)
        .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))
}

/// A read-only numpy view of an array the handle owns; the view keeps the handle alive.
fn view<'py, T: numpy::Element>(
    this: &Bound<'py, PyField>,
    array: &ArrayD<T>,
) -> PyResult<Bound<'py, PyAny>> {
    // SAFETY: the handle is frozen and never changes or moves its arrays' buffers, and the view
    // holds a reference to the handle (its numpy base), so the memory outlives the view.
    let a = unsafe { PyArray::borrow_from_array(array, this.clone().into_any()) };
    a.getattr("flags")?.setattr("writeable", false)?;
    Ok(a.into_any())
}

/// A (..) array argument's values and shape, checked against `expect` (`None`: any length).
fn taken<T: numpy::Element + Clone>(
    py: Python<'_>,
    a: &PyReadonlyArrayDyn<'_, T>,
    name: &str,
    expect: &[Option<usize>],
) -> PyResult<ArrayD<T>> {
    let shape = a.shape();
    let fits = shape.len() == expect.len()
        && shape
            .iter()
            .zip(expect)
            .all(|(&s, e)| e.is_none_or(|e| e == s));
    if !fits {
        let want: Vec<String> = expect
            .iter()
            .map(|e| e.map_or("_".into(), |e| e.to_string()))
            .collect();
        return Err(input(
            py,
            format!("field {name} must be ({}), got {shape:?}", want.join(", ")),
        ));
    }
    // In C order whatever the argument's strides: the views and `samples` read it flat.
    Ok(a.as_array().as_standard_layout().into_owned())
}

impl PyField {
    /// The fields, one per slab, read in place.
    fn samples(&self) -> Vec<(Slab, vf::Samples<'_>)> {
        let shape = self.ids.shape();
        let per = shape[1..5].iter().product::<usize>();
        let n = shape[5];
        let (ids, hits) = (self.ids.as_slice(), self.hits.as_slice());
        let (ids, hits) = (ids.unwrap_or(&[]), hits.unwrap_or(&[]));
        (self.slabs.iter().enumerate())
            .map(|(k, s)| {
                let f = vf::Samples {
                    dims: [shape[1], shape[2], shape[3], shape[4]].map(|d| d as u32),
                    n: n as u32,
                    ids: &ids[k * per * n..(k + 1) * per * n],
                    hits: &hits[k * per..(k + 1) * per],
                };
                (*s, f)
            })
            .collect()
    }

    fn sorted(&self) -> crate::error::Result<vf::SortedScene<'_>> {
        let order = self.order.as_slice().unwrap_or(&[]);
        let offsets = self.offsets.as_slice().unwrap_or(&[]);
        vf::SortedScene::new(&self.sorted, order, offsets)
    }
}

#[pymethods]
impl PyField {
    /// A field from its arrays (what `VisibilityField` pickles): the scene it was built for,
    /// then what the getters below return. Every shape is checked, the face order must be a
    /// permutation and the offsets must rise from 0 to the face count; the cell-sorted scene,
    /// its BVH and its edge neighbours are rebuilt, as the build made them.
    #[staticmethod]
    #[pyo3(signature = (scene, slabs, ids, cells_hit, triangles, offsets, cells, cell_bounds, cell_of))]
    #[allow(clippy::too_many_arguments)]
    fn restore(
        py: Python<'_>,
        scene: &PyScene,
        slabs: Vec<Bound<'_, PyAny>>,
        ids: PyReadonlyArrayDyn<'_, i32>,
        cells_hit: PyReadonlyArrayDyn<'_, u16>,
        triangles: PyReadonlyArrayDyn<'_, u32>,
        offsets: PyReadonlyArrayDyn<'_, u32>,
        cells: PyReadonlyArrayDyn<'_, i32>,
        cell_bounds: PyReadonlyArrayDyn<'_, f32>,
        cell_of: PyReadonlyArrayDyn<'_, u32>,
    ) -> PyResult<Self> {
        let slabs = slabs
            .iter()
            .map(|s| slab(py, s))
            .collect::<PyResult<Vec<_>>>()?;
        let faces = scene.inner.triangle_count();
        let k = Some(slabs.len());
        let ids = taken(py, &ids, "ids", &[k, None, None, None, None, None])?;
        let dims: Vec<Option<usize>> = ids.shape()[..5].iter().map(|&d| Some(d)).collect();
        let hits = taken(py, &cells_hit, "cells_hit", &dims)?;
        let order = taken(py, &triangles, "triangles", &[Some(faces)])?;
        let offsets = taken(py, &offsets, "offsets", &[None])?;
        let c = Some(offsets.len().saturating_sub(1));
        let cells = taken(py, &cells, "cells", &[c, Some(4)])?;
        let cell_bounds = taken(py, &cell_bounds, "cell_bounds", &[c, Some(2), Some(3)])?;
        let cell_of = taken(py, &cell_of, "cell_of", &[Some(faces)])?;
        let s = scene.inner.clone();
        let order_v = order.as_slice().unwrap_or(&[]);
        let sorted = super::run(py, || {
            let sorted = s.permuted(order_v)?;
            vf::SortedScene::new(&sorted, order_v, offsets.as_slice().unwrap_or(&[]))?;
            vf::prepare_views(&sorted)?;
            Ok(sorted)
        })?;
        Ok(PyField {
            sorted: Arc::new(sorted),
            slabs,
            ids,
            hits,
            order,
            offsets,
            cells,
            cell_bounds,
            cell_of,
        })
    }

    /// (K, U, V, S, T, n) int32, read-only.
    #[getter]
    fn ids<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().ids)
    }

    /// (K, U, V, S, T) uint16, read-only.
    #[getter]
    fn cells_hit<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().hits)
    }

    /// (F,) uint32, read-only: the triangles in cell order.
    #[getter]
    fn triangles<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().order)
    }

    /// (C + 1,) uint32, read-only.
    #[getter]
    fn offsets<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().offsets)
    }

    /// (C, 4) int32, read-only: group, x, y, z.
    #[getter]
    fn cells<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().cells)
    }

    /// (C, 2, 3) float32, read-only.
    #[getter]
    fn cell_bounds<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().cell_bounds)
    }

    /// (F,) uint32, read-only.
    #[getter]
    fn cell_of<'py>(this: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        view(this, &this.get().cell_of)
    }

    /// (K, 2, 3, 3) float64, a fresh array: each slab's uv then st (origin, u edge, v edge).
    #[getter]
    fn slabs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        slab_arrays(py, &self.slabs)
    }

    fn __repr__(&self) -> String {
        let s = self.ids.shape();
        format!(
            "Field({} slabs, {:?} samples, {} cells)",
            s[0],
            &s[1..],
            self.cells.shape()[0]
        )
    }
}

/// Cells and one sampled field per slab: the handle and what the build measured.
#[pyfunction]
#[pyo3(signature = (scene, slabs, uv, st, grid, cell_size, grouping, ids_per_sample, supersample, jitter, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn visibility_field<'py>(
    py: Python<'py>,
    scene: &PyScene,
    slabs: Vec<Bound<'py, PyAny>>,
    uv: (u32, u32),
    st: (u32, u32),
    grid: (u32, u32, u32),
    cell_size: Option<f64>,
    grouping: &str,
    ids_per_sample: u32,
    supersample: u32,
    jitter: Option<u64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PyField, Bound<'py, PyDict>)> {
    let supersample = vf::Supersample {
        per_axis: supersample,
        jitter,
    };
    let grouping = match grouping {
        "objects" => Grouping::Objects,
        "scene" => Grouping::Scene,
        other => {
            return Err(input(
                py,
                format!("grouping must be 'objects' or 'scene', got {other:?}"),
            ))
        }
    };
    let slabs = slabs
        .iter()
        .map(|s| slab(py, s))
        .collect::<PyResult<Vec<_>>>()?;
    let grid = match cell_size {
        // `grid` bounds the cells per axis when they are sized.
        Some(size) => vf::Grid::Size {
            size,
            max: grid.0.max(grid.1).max(grid.2),
        },
        None => vf::Grid::Cells([grid.0, grid.1, grid.2]),
    };
    let s = scene.inner.clone();
    let (uv, st) = ([uv.0, uv.1], [st.0, st.1]);
    let built = super::run_with(py, progress, || {
        vf::build(
            &s,
            &slabs,
            uv,
            st,
            grid,
            grouping,
            ids_per_sample,
            supersample,
        )
    })?;
    let vf::Built {
        cells,
        sorted,
        fields,
        cell_seconds,
        bvh_seconds,
    } = built;
    let d = PyDict::new(py);
    d.set_item("groups", cells.groups)?;
    d.set_item("cell_seconds", cell_seconds)?;
    d.set_item("bvh_seconds", bvh_seconds)?;
    let rays: u64 = fields.iter().map(|f| f.rays).sum();
    let mut timings = crate::types::Timings::new();
    for f in &fields {
        timings.merge(&f.timings);
    }
    d.set_item("rays", rays)?;
    d.set_item("timings", super::convert::timings(py, &timings)?)?;
    // All slabs share their dimensions: one (K, U, V, S, T, n) array of ids, one (K, U, V, S,
    // T) of the cells each sample's rays hit.
    let k = fields.len();
    let dims = [uv[0], uv[1], st[0], st[1]].map(|x| x as usize);
    let (ids, hits): (Vec<Vec<i32>>, Vec<Vec<u16>>) =
        fields.into_iter().map(|f| (f.ids, f.hits)).unzip();
    let shape = [
        k,
        dims[0],
        dims[1],
        dims[2],
        dims[3],
        ids_per_sample as usize,
    ];
    let c = cells.table.len();
    let bounds: Vec<f32> = cells.bounds.iter().flatten().flatten().copied().collect();
    let nt = cells.triangles.len();
    let field = PyField {
        sorted: Arc::new(sorted),
        slabs,
        ids: owned(ids.concat(), &shape)?,
        hits: owned(hits.concat(), &shape[..5])?,
        order: owned(cells.triangles, &[nt])?,
        offsets: owned(cells.offsets, &[c + 1])?,
        cells: owned(cells.table.into_flattened(), &[c, 4])?,
        cell_bounds: owned(bounds, &[c, 2, 3])?,
        cell_of: owned(cells.cell_of, &[s.triangle_count()])?,
    };
    Ok((field, d))
}

/// Resample the field from a camera, trace the pixels it cannot answer (with `fallback`), and
/// render the marked cells.
#[pyfunction]
#[pyo3(signature = (field, camera, interpolate, subsample, fallback, trust, backend, reference=false))]
#[allow(clippy::too_many_arguments)]
pub fn field_view<'py>(
    py: Python<'py>,
    field: &PyField,
    camera: &PyCamera,
    interpolate: &str,
    subsample: u32,
    fallback: bool,
    trust: u32,
    backend: &str,
    reference: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let traced = match backend {
        "gpu" => false,
        "cpu" => true,
        _ => {
            return Err(input(
                py,
                format!("backend must be 'gpu' or 'cpu', got {backend:?}"),
            ))
        }
    };
    let Some(interp) = Interpolate::parse(interpolate) else {
        return Err(input(
            py,
            format!("interpolate must be 'none', 'uv', 'st' or 'uv+st', got {interpolate:?}"),
        ));
    };
    let how = vf::ViewOptions {
        interpolate: interp,
        subsample,
        fallback,
        trust,
        cpu: traced,
        reference,
    };
    let (fields, cam) = (field.samples(), &camera.inner);
    let v = super::run(py, || vf::view(&field.sorted()?, &fields, cam, &how))?;
    let d = PyDict::new(py);
    let cells = v.marks.marked.len();
    d.set_item("marked", array(py, v.marks.marked, &[cells])?)?;
    d.set_item("pixels", v.marks.pixels)?;
    d.set_item("outside", v.marks.outside)?;
    d.set_item("overflowed", v.marks.overflowed)?;
    d.set_item("fallback_cells", v.fallback_cells)?;
    d.set_item("border_cells", v.border_cells)?;
    d.set_item("triangles_drawn", v.triangles_drawn)?;
    d.set_item("resample_seconds", v.seconds.resample)?;
    d.set_item("fallback_seconds", v.seconds.fallback)?;
    d.set_item("render_seconds", v.seconds.render)?;
    d.set_item("image", super::render::images_dict(py, v.image)?)?;
    Ok(d)
}

/// Render only the marked cells of a field's cell-sorted scene from a camera: the depth
/// image's dict (triangle ids of the original scene) and the triangles drawn.
#[pyfunction]
#[pyo3(signature = (field, marked, camera))]
pub fn render_cells<'py>(
    py: Python<'py>,
    field: &PyField,
    marked: PyReadonlyArray1<'py, bool>,
    camera: &PyCamera,
) -> PyResult<(Bound<'py, PyDict>, usize)> {
    let marked = marked.as_array().to_vec();
    let cam = &camera.inner;
    let (img, drawn) = super::run(py, || vf::render_marked(&field.sorted()?, &marked, cam))?;
    Ok((super::render::images_dict(py, img)?, drawn))
}
