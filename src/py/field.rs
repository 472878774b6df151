//! The visibility field (visibility-field.txt §3-4) from Python arguments.

use numpy::{PyReadonlyArray1, PyReadonlyArrayDyn, PyUntypedArrayMethods};
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

fn slab_array<'py>(py: Python<'py>, s: &Slab) -> PyResult<Bound<'py, PyAny>> {
    let rows: Vec<f64> = [s.uv.origin, s.uv.u, s.uv.v, s.st.origin, s.st.u, s.st.v]
        .iter()
        .flat_map(|p| p.to_array())
        .collect();
    array(py, rows, &[2, 3, 3])
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
    slab_array(py, &s)
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
    let rows: Vec<f64> = slabs
        .iter()
        .flat_map(|s| [s.uv.origin, s.uv.u, s.uv.v, s.st.origin, s.st.u, s.st.v])
        .flat_map(|p| p.to_array())
        .collect();
    array(py, rows, &[slabs.len(), 2, 3, 3])
}

/// Cells and one sampled field per slab.
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
) -> PyResult<Bound<'py, PyDict>> {
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
    let c = cells.table.len();
    d.set_item("cell_of", array(py, cells.cell_of, &[s.triangle_count()])?)?;
    d.set_item("cells", array(py, cells.table.into_flattened(), &[c, 4])?)?;
    let bounds: Vec<f32> = cells.bounds.iter().flatten().flatten().copied().collect();
    d.set_item("cell_bounds", array(py, bounds, &[c, 2, 3])?)?;
    d.set_item("offsets", array(py, cells.offsets, &[c + 1])?)?;
    let nt = cells.triangles.len();
    d.set_item("triangles", array(py, cells.triangles, &[nt])?)?;
    d.set_item("groups", cells.groups)?;
    d.set_item(
        "sorted_scene",
        PyScene {
            inner: std::sync::Arc::new(sorted),
        },
    )?;
    d.set_item("cell_seconds", cell_seconds)?;
    d.set_item("bvh_seconds", bvh_seconds)?;
    // All slabs share their dimensions: one (K, U, V, S, T, n) array of ids, one (K, U, V, S,
    // T) of the cells each sample's rays hit.
    let k = fields.len();
    let dims = [uv[0], uv[1], st[0], st[1]].map(|x| x as usize);
    let rays: u64 = fields.iter().map(|f| f.rays).sum();
    let mut timings = crate::types::Timings::new();
    for f in &fields {
        timings.merge(&f.timings);
    }
    let (ids, hits): (Vec<Vec<i32>>, Vec<Vec<u16>>) =
        fields.into_iter().map(|f| (f.ids, f.hits)).unzip();
    let n = ids_per_sample as usize;
    let shape = [k, dims[0], dims[1], dims[2], dims[3], n];
    d.set_item("ids", array(py, ids.concat(), &shape)?)?;
    d.set_item("cells_hit", array(py, hits.concat(), &shape[..5])?)?;
    d.set_item("rays", rays)?;
    d.set_item("timings", super::convert::timings(py, &timings)?)?;
    Ok(d)
}

/// Resample the fields from a camera, trace the pixels they cannot answer (with `fallback`),
/// and render the marked cells.
#[pyfunction]
#[pyo3(signature = (sorted_scene, triangles, offsets, slabs, ids, cells_hit, camera, interpolate, subsample, fallback, trust, backend, reference=false))]
#[allow(clippy::too_many_arguments)]
pub fn field_view<'py>(
    py: Python<'py>,
    sorted_scene: &PyScene,
    triangles: PyReadonlyArray1<'py, u32>,
    offsets: PyReadonlyArray1<'py, u32>,
    slabs: Vec<Bound<'py, PyAny>>,
    ids: PyReadonlyArrayDyn<'py, i32>,
    cells_hit: PyReadonlyArrayDyn<'py, u16>,
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
    let fields = fields(py, &slabs, &ids, &cells_hit)?;
    let (order, offsets) = (triangles.as_array().to_vec(), offsets.as_array().to_vec());
    let how = vf::ViewOptions {
        interpolate: interp,
        subsample,
        fallback,
        trust,
        cpu: traced,
        reference,
    };
    let (scene, cam) = (&sorted_scene.inner, &camera.inner);
    let v = super::run(py, || {
        let sorted = vf::SortedScene::new(scene, &order, &offsets)?;
        vf::view(&sorted, &fields, cam, &how)
    })?;
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

/// The fields of a (K, U, V, S, T, n) id array and its (K, U, V, S, T) counts of cells hit,
/// one per slab, read in place (both C-contiguous).
fn fields<'a>(
    py: Python<'_>,
    slabs: &[Bound<'_, PyAny>],
    ids: &'a PyReadonlyArrayDyn<'_, i32>,
    hits: &'a PyReadonlyArrayDyn<'_, u16>,
) -> PyResult<Vec<(Slab, vf::Samples<'a>)>> {
    let shape = ids.shape().to_vec();
    if shape.len() != 6 || shape[0] != slabs.len() || hits.shape() != &shape[..5] {
        return Err(input(
            py,
            format!(
                "field ids must be (K, U, V, S, T, n) and cells_hit (K, U, V, S, T) for K = {} \
                 slabs, got {shape:?} and {:?}",
                slabs.len(),
                hits.shape()
            ),
        ));
    }
    let (Ok(all_ids), Ok(all_hits)) = (ids.as_slice(), hits.as_slice()) else {
        return Err(input(
            py,
            "field ids and cells_hit must be C-contiguous".into(),
        ));
    };
    let per = shape[1..5].iter().product::<usize>();
    let mut out = Vec::with_capacity(slabs.len());
    for (k, s) in slabs.iter().enumerate() {
        let f = vf::Samples {
            dims: [shape[1], shape[2], shape[3], shape[4]].map(|d| d as u32),
            n: shape[5] as u32,
            ids: &all_ids[k * per * shape[5]..(k + 1) * per * shape[5]],
            hits: &all_hits[k * per..(k + 1) * per],
        };
        out.push((slab(py, s)?, f));
    }
    Ok(out)
}

/// Render only the marked cells (of the cell-sorted scene) from a camera: the depth image's
/// dict, triangle ids of the original scene, and the triangles drawn.
#[pyfunction]
#[pyo3(signature = (sorted_scene, triangles, offsets, marked, camera))]
pub fn render_cells<'py>(
    py: Python<'py>,
    sorted_scene: &PyScene,
    triangles: PyReadonlyArray1<'py, u32>,
    offsets: PyReadonlyArray1<'py, u32>,
    marked: PyReadonlyArray1<'py, bool>,
    camera: &PyCamera,
) -> PyResult<(Bound<'py, PyDict>, usize)> {
    let (order, offsets) = (triangles.as_array().to_vec(), offsets.as_array().to_vec());
    let marked = marked.as_array().to_vec();
    let (scene, cam) = (&sorted_scene.inner, &camera.inner);
    let (img, drawn) = super::run(py, || {
        vf::render_marked(
            &vf::SortedScene::new(scene, &order, &offsets)?,
            &marked,
            cam,
        )
    })?;
    Ok((super::render::images_dict(py, img)?, drawn))
}
