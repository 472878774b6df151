//! CPU ray queries (`trace`): closest and k nearest hits, any hit, and the BVH's statistics.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::convert::{array, borrow_rows, rows_array_of, rows_owned};
use super::errors::IntoPy;
use super::scene::PyScene;
use crate::trace::{self, Query, Threads};

/// Borrowed, not copied: numpy's float32 rows are read in place while the GIL is released.
macro_rules! rays {
    ($o:ident, $d:ident) => {
        let $o = rows_array_of::<f32, 3>($o, "origins", "float32")?;
        let $d = rows_array_of::<f32, 3>($d, "directions", "float32")?;
        let ($o, $d) = (
            borrow_rows::<f32, 3>(&$o, "origins")?,
            borrow_rows::<f32, 3>(&$d, "directions")?,
        );
    };
}

fn query(py: Python<'_>, t_min: f32, t_max: f32, threads: Option<usize>) -> PyResult<Query> {
    Ok(Query {
        t_min,
        t_max,
        threads: Threads::from_count(threads).py_err(py)?,
        report: true,
    })
}

/// Run a ray or point query where `threads` says: `threads=1` on the calling thread, else on
/// the pool; `progress(done, total)` hears the rays or points done.
pub(crate) fn on_threads<T: Send>(
    py: Python<'_>,
    threads: Threads,
    progress: Option<Py<PyAny>>,
    work: impl Fn() -> crate::error::Result<T> + Sync,
) -> PyResult<T> {
    if threads == Threads::One {
        super::run_here(py, progress, work)
    } else {
        super::run_with(py, progress, work)
    }
}

fn timings<'py>(py: Python<'py>, build: f64, trace: f64) -> PyResult<Bound<'py, PyDict>> {
    let t = PyDict::new(py);
    t.set_item("bvh_build", build)?;
    t.set_item("trace", trace)?;
    Ok(t)
}

/// One ray query's binding, written once: `scene, origins, directions, t_min=0.0,
/// t_max=inf`, the query's own arguments, `threads=None, progress=None`; the rays borrowed in
/// place, the core call (`|scene, origins, directions, query| ...`) on the threads asked for,
/// and the result's arrays (`|py, result, dict| ...`) followed by its `timings`. The stubs in
/// `_core.pyi` declare the same signature once (`_RayQuery`).
macro_rules! ray_query {
    (
        $(#[$doc:meta])*
        fn $name:ident($($extra:ident: $ty:ty = $default:tt),*)
        |$s:ident, $o:ident, $d:ident, $q:ident| $call:expr;
        |$py:ident, $r:ident, $out:ident| $fill:block
    ) => {
        $(#[$doc])*
        #[pyfunction]
        #[pyo3(signature = (
            scene, origins, directions, t_min=0.0, t_max=f32::INFINITY,
            $($extra=$default,)* threads=None, progress=None
        ))]
        #[allow(clippy::too_many_arguments)]
        pub fn $name<'py>(
            $py: Python<'py>,
            scene: &PyScene,
            origins: &Bound<'py, PyAny>,
            directions: &Bound<'py, PyAny>,
            t_min: f32,
            t_max: f32,
            $($extra: $ty,)*
            threads: Option<usize>,
            progress: Option<Py<PyAny>>,
        ) -> PyResult<Bound<'py, PyDict>> {
            rays!(origins, directions);
            let ($o, $d) = (origins, directions);
            let $q = query($py, t_min, t_max, threads)?;
            let $s = scene.inner.clone();
            let $r = on_threads($py, $q.threads, progress, || $call)?;
            let $out = PyDict::new($py);
            $fill;
            let t = timings($py, $r.bvh_build_seconds, $r.trace_seconds)?;
            $out.set_item("timings", t)?;
            Ok($out)
        }
    };
}

ray_query! {
    /// The closest hit of each ray, or its `max_hits` nearest: `t`, `triangle`, `barycentric`
    /// ((N,) and (N, 2), or (N, k) and (N, k, 2)).
    fn cast_rays(max_hits: usize = 1)
    |s, o, d, q| trace::nearest_hits(&s, o, d, max_hits, &q);
    |py, hits, out| {
        let n = o.len();
        // One hit per ray keeps the flat shapes (N,), (N, 2); k hits add an axis.
        let (shape, bary): (Vec<usize>, Vec<usize>) = if max_hits == 1 {
            (vec![n], vec![n, 2])
        } else {
            (vec![n, max_hits], vec![n, max_hits, 2])
        };
        out.set_item("t", array(py, hits.t, &shape)?)?;
        out.set_item("triangle", array(py, hits.triangle, &shape)?)?;
        out.set_item("barycentric", rows_owned(py, hits.barycentric, &bary)?)?;
    }
}

ray_query! {
    /// Whether anything lies on each ray: `hit` (N,) bool.
    fn occluded()
    |s, o, d, q| trace::occluded(&s, o, d, &q);
    |py, r, out| {
        let n = r.hit.len();
        out.set_item("hit", array(py, r.hit, &[n])?)?;
    }
}

ray_query! {
    /// Every hit of each ray, ragged: `ray_splits` (N + 1,) offsets into `t`, `triangle`,
    /// `barycentric`.
    fn all_hits()
    |s, o, d, q| trace::all_hits(&s, o, d, &q);
    |py, r, out| {
        let (n, h) = (r.splits.len(), r.t.len());
        let splits: Vec<i64> = r.splits.into_iter().map(|x| x as i64).collect();
        out.set_item("ray_splits", array(py, splits, &[n])?)?;
        out.set_item("t", array(py, r.t, &[h])?)?;
        out.set_item("triangle", array(py, r.triangle, &[h])?)?;
        out.set_item("barycentric", rows_owned(py, r.barycentric, &[h, 2])?)?;
    }
}

ray_query! {
    /// How many distinct hits each ray has: `count` (N,) int64.
    fn count_hits()
    |s, o, d, q| trace::count_hits(&s, o, d, &q);
    |py, r, out| {
        let n = r.count.len();
        let count: Vec<i64> = r.count.into_iter().map(i64::from).collect();
        out.set_item("count", array(py, count, &[n])?)?;
    }
}

#[pyfunction]
pub fn bvh_stats<'py>(py: Python<'py>, scene: &PyScene) -> PyResult<Bound<'py, PyDict>> {
    let s = scene.inner.clone();
    let st = super::run(py, || Ok(trace::Bvh::of(&s).stats()))?;
    let d = PyDict::new(py);
    d.set_item("triangles", st.triangles)?;
    d.set_item("nodes", st.nodes)?;
    d.set_item("blocks", st.blocks)?;
    d.set_item("bytes", st.bytes)?;
    d.set_item("depth", st.depth)?;
    d.set_item("instances", st.instances)?;
    d.set_item("sah", st.sah)?;
    d.set_item("build_seconds", st.build_seconds)?;
    d.set_item("winding_bytes", trace::winding::winding_bytes(&s))?;
    Ok(d)
}

/// The kernel CPU queries run on (`"avx512"`, `"avx2"` or `"portable"`), after allowing none
/// wider than `widest` where asked (`"best"`: the widest the CPU has).
#[pyfunction]
#[pyo3(signature = (widest=None))]
pub fn ray_kernel(py: Python<'_>, widest: Option<&str>) -> PyResult<&'static str> {
    use trace::token::{force, kernel, Level};
    if let Some(name) = widest {
        let level = match name {
            "best" => Level::Avx512,
            _ => Level::named(name).ok_or_else(|| {
                super::errors::input(
                    py,
                    format!("ray_kernel: widest must be 'best', 'avx512', 'avx2' or 'portable', not {name:?}"),
                )
            })?,
        };
        force(level);
    }
    Ok(kernel().name())
}
