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
mod rays;
mod reconstruct;
mod render;
mod scene;
mod shadows;
mod splat;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<scene::PyScene>()?;
    m.add_class::<camera::PyCamera>()?;
    m.add_function(wrap_pyfunction!(render::discretize_conventional, m)?)?;
    m.add_function(wrap_pyfunction!(render::discretize_nonredundant, m)?)?;
    m.add_function(wrap_pyfunction!(render::discretize_peeling, m)?)?;
    m.add_function(wrap_pyfunction!(rays::cast_rays, m)?)?;
    m.add_function(wrap_pyfunction!(rays::occluded, m)?)?;
    m.add_function(wrap_pyfunction!(rays::bvh_stats, m)?)?;
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
    m.add_function(wrap_pyfunction!(field::field_view, m)?)?;
    m.add_function(wrap_pyfunction!(field::render_cells, m)?)?;
    m.add_class::<impostors::PyImpostors>()?;
    m.add_function(wrap_pyfunction!(impostors::impostors, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::impostor_view, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::render_lit, m)?)?;
    m.add_function(wrap_pyfunction!(impostors::impostor_directions, m)?)?;
    m.add_function(wrap_pyfunction!(render::device_info, m)?)?;
    m.add_function(wrap_pyfunction!(render::counters, m)?)?;
    m.add_function(wrap_pyfunction!(render::write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(render::read_exr, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
