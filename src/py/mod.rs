//! The only code that touches PyO3: the `scenesample._core` module, numpy conversion, error
//! mapping and GIL release. Every function here converts, calls a plain-Rust algorithm, and
//! converts back.

mod camera;
mod convert;
mod effects;
mod errors;
mod evaluate;
mod field;
mod impostors;
mod points;
mod rays;
mod reconstruct;
mod render;
mod scene;
mod shadows;
mod splat;

use std::sync::Arc;

use pyo3::prelude::*;

use errors::IntoPy;

/// Release the GIL and run `work` on this process's worker pool (`process::interruptible`),
/// while the calling thread checks for signals every `process::POLL`: Ctrl-C stops the work
/// within a fraction of a second and raises `KeyboardInterrupt` here (or whatever the signal's
/// Python handler raises). Calls from threads other than the main one are not interrupted.
/// `work` may run again if another thread's call was interrupted meanwhile, so it must be free
/// of side effects.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    work: impl Fn() -> crate::error::Result<T> + Sync,
) -> PyResult<T> {
    run_with(py, None, work)
}

/// [`run`], also returning what the work did (`counters::tally`): cube maps, splat passes,
/// shadow views and rays of this call only, whatever other calls run meanwhile.
pub(crate) fn run_counted<T: Send>(
    py: Python<'_>,
    work: impl Fn() -> crate::error::Result<T> + Sync,
) -> PyResult<(T, crate::counters::Ops)> {
    run(py, || {
        let (r, ops) = crate::counters::tally(&work);
        r.map(|v| (v, ops))
    })
}

/// `d["ops"]`: a call's operation counts (see [`run_counted`]).
pub(crate) fn set_ops(
    d: &Bound<'_, pyo3::types::PyDict>,
    ops: crate::counters::Ops,
) -> PyResult<()> {
    let o = pyo3::types::PyDict::new(d.py());
    for (k, v) in ops.named() {
        o.set_item(k, v)?;
    }
    d.set_item("ops", o)
}

/// [`run`], reporting the work's progress (`process::advance`) to `progress(done, total)`,
/// a Python callable, from the calling thread at each poll and once at the end, also when the
/// work was interrupted (so a bar, or a test, sees where it stopped).
pub(crate) fn run_with<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    work: impl Fn() -> crate::error::Result<T> + Sync,
) -> PyResult<T> {
    let watch = Watch::new(progress);
    let mut poll = watch.poller(py);
    let r = py.detach(|| crate::process::interruptible(&work, &mut poll, watch.counter.as_ref()));
    watch.finish(py, r.map(|r| r.py_err(py)), poll)
}

/// [`run`] for single-threaded work that stays on the calling thread (`threads=1`): it checks
/// for signals itself, from its loops (`process::interruptible_here`).
pub(crate) fn run_here<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    work: impl Fn() -> crate::error::Result<T> + Sync,
) -> PyResult<T> {
    let watch = Watch::new(progress);
    let poll = watch.poller(py);
    let r = py.detach(|| crate::process::interruptible_here(&work, poll, watch.counter.as_ref()));
    let poll = watch.poller(py);
    watch.finish(py, r.map(|r| r.py_err(py)), poll)
}

/// A call's progress callback and the counter its work advances.
struct Watch {
    progress: Option<Py<PyAny>>,
    counter: Option<Arc<crate::process::Progress>>,
}

impl Watch {
    fn new(progress: Option<Py<PyAny>>) -> Self {
        let counter = progress
            .is_some()
            .then(|| Arc::new(crate::process::Progress::default()));
        Self { progress, counter }
    }

    /// What the calling thread does at each poll: check for signals, then report progress
    /// when it moved.
    fn poller(&self, py: Python<'_>) -> impl FnMut() -> PyResult<()> + Send + 'static {
        let progress = self.progress.as_ref().map(|p| p.clone_ref(py));
        let counter = self.counter.clone();
        let mut shown = (u64::MAX, u64::MAX);
        move || {
            Python::attach(|py| {
                py.check_signals()?;
                if let (Some(f), Some(c)) = (&progress, &counter) {
                    let now = c.now();
                    if now != shown {
                        shown = now;
                        f.call1(py, now)?;
                    }
                }
                Ok(())
            })
        }
    }

    /// The work's result, after a last report: the final count, so a bar ends full; or, when
    /// the work was interrupted, where it stopped (the report's own errors then give way to
    /// the interruption's).
    fn finish<T>(
        &self,
        py: Python<'_>,
        r: PyResult<PyResult<T>>,
        mut poll: impl FnMut() -> PyResult<()>,
    ) -> PyResult<T> {
        match r {
            Ok(r) => {
                let r = r?;
                poll()?;
                Ok(r)
            }
            Err(e) => {
                if let (Some(f), Some(c)) = (&self.progress, &self.counter) {
                    if let Err(late) = f.call1(py, c.now()) {
                        late.write_unraisable(py, None);
                    }
                }
                Err(e)
            }
        }
    }
}

/// `InputError` when `count` items of `each` bytes (`what`: the request in the caller's terms)
/// would exceed the memory limit (`limits::check`, for checks made on the Python side); the
/// limit in bytes otherwise.
#[pyfunction]
fn check_memory(py: Python<'_>, what: &str, count: u128, each: u64) -> PyResult<u64> {
    crate::limits::check(|| what.to_string(), count, each).py_err(py)?;
    Ok(crate::limits::memory_limit())
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<scene::PyScene>()?;
    m.add_class::<camera::PyCamera>()?;
    m.add_function(wrap_pyfunction!(render::shade_frame, m)?)?;
    m.add_function(wrap_pyfunction!(render::discretize_conventional, m)?)?;
    m.add_function(wrap_pyfunction!(render::discretize_nonredundant, m)?)?;
    m.add_function(wrap_pyfunction!(render::discretize_peeling, m)?)?;
    m.add_function(wrap_pyfunction!(rays::cast_rays, m)?)?;
    m.add_function(wrap_pyfunction!(rays::occluded, m)?)?;
    m.add_function(wrap_pyfunction!(rays::bvh_stats, m)?)?;
    m.add_function(wrap_pyfunction!(rays::ray_kernel, m)?)?;
    m.add_function(wrap_pyfunction!(rays::all_hits, m)?)?;
    m.add_function(wrap_pyfunction!(rays::count_hits, m)?)?;
    m.add_function(wrap_pyfunction!(points::closest_points, m)?)?;
    m.add_function(wrap_pyfunction!(scene::surface_attributes, m)?)?;
    m.add_function(wrap_pyfunction!(points::winding_numbers, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::sampling_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(shadows::soft_shadows, m)?)?;
    m.add_function(wrap_pyfunction!(splat::epr_points, m)?)?;
    m.add_function(wrap_pyfunction!(splat::epr_shadow_points, m)?)?;
    m.add_function(wrap_pyfunction!(splat::splat, m)?)?;
    m.add_function(wrap_pyfunction!(shadows::omni_shadows, m)?)?;
    m.add_function(wrap_pyfunction!(effects::reflections, m)?)?;
    m.add_function(wrap_pyfunction!(field::default_slab, m)?)?;
    m.add_function(wrap_pyfunction!(field::visibility_field, m)?)?;
    m.add_function(wrap_pyfunction!(field::six_slabs, m)?)?;
    m.add_function(wrap_pyfunction!(field::field_view, m)?)?;
    m.add_function(wrap_pyfunction!(field::render_cells, m)?)?;
    m.add_class::<impostors::PyImpostors>()?;
    m.add_class::<field::PyField>()?;
    m.add_function(wrap_pyfunction!(impostors::impostors, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::impostor_view, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::render_lit, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::impostor_directions, m)?)?;
    m.add_function(wrap_pyfunction!(render::device_info, m)?)?;
    m.add_function(wrap_pyfunction!(render::choose_backend, m)?)?;
    m.add_function(wrap_pyfunction!(check_memory, m)?)?;
    m.add_function(wrap_pyfunction!(render::write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(render::read_exr, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
