//! Depth images, ray casts, device info and EXR, returned as dicts of fresh numpy arrays that
//! the Python façade wraps in result objects.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::camera::PyCamera;
use super::convert::{array, flat_i32, rows_f32, rows_owned};
use super::errors::input;
use super::scene::PyScene;
use crate::calibration::{BackendChoice, CostModel, Workload};
use crate::types::DepthImages;

pub(super) fn images_dict<'py>(py: Python<'py>, img: DepthImages) -> PyResult<Bound<'py, PyDict>> {
    let (n, h, w) = (img.n, img.height as usize, img.width as usize);
    let d = PyDict::new(py);
    d.set_item("depth", array(py, img.depth, &[n, h, w])?)?;
    d.set_item("triangle", array(py, img.triangle, &[n, h, w])?)?;
    d.set_item("normal", rows_owned(py, img.normal, &[n, h, w, 3])?)?;
    d.set_item(
        "shading_normal",
        rows_owned(py, img.shading_normal, &[n, h, w, 3])?,
    )?;
    d.set_item("position", rows_owned(py, img.position, &[n, h, w, 3])?)?;
    d.set_item("color", rows_owned(py, img.color, &[n, h, w, 3])?)?;
    let cams: Vec<PyCamera> = img.cameras.into_iter().map(PyCamera::from).collect();
    d.set_item("cameras", cams)?;
    d.set_item("method", img.method)?;
    d.set_item("timings", super::convert::timings(py, &img.timings)?)?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (scene, cameras, cull_backfaces=false, backend="auto"))]
pub fn discretize_conventional<'py>(
    py: Python<'py>,
    scene: &PyScene,
    cameras: Vec<PyCamera>,
    cull_backfaces: bool,
    backend: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let choice: BackendChoice = backend
        .parse()
        .map_err(|e| super::errors::to_pyerr(py, e))?;
    let cams: Vec<_> = cameras.into_iter().map(|c| c.inner).collect();
    let s = scene.inner.clone();
    let (img, decision) = super::run(py, || {
        crate::calibration::discretize_with(&s, &cams, cull_backfaces, choice)
    })?;
    let d = images_dict(py, img)?;
    d.set_item("backend", decision.backend.name())?;
    d.set_item("backend_reason", decision.reason)?;
    Ok(d)
}

/// What `backend="auto"` would choose for a request of this size (see
/// `calibration`; `auto` itself weighs every request prepared, as the defaults do),
/// where `box_fraction` of the pixels see the scene's bounding box (0.75 by default: an
/// orbiting view of an object); calibrates the cost model on first use.
#[pyfunction]
#[pyo3(signature = (triangles, pixels, images=1, bvh_built=true, uploaded=true, box_fraction=0.75))]
pub fn choose_backend<'py>(
    py: Python<'py>,
    triangles: u64,
    pixels: u64,
    images: u64,
    bvh_built: bool,
    uploaded: bool,
    box_fraction: f64,
) -> PyResult<Bound<'py, PyDict>> {
    if !(0.0..=1.0).contains(&box_fraction) {
        return Err(super::errors::input(
            py,
            format!("box_fraction must be in [0, 1], got {box_fraction}"),
        ));
    }
    let w = Workload {
        triangles,
        pixels,
        images,
        bvh_built,
        uploaded,
        // Only the pixel count is given: the image's sides are not known here.
        fits_gpu: true,
        box_fraction,
    };
    let (decision, model) = super::run(py, || {
        let model = CostModel::get()?;
        Ok((model.decide(&w), model))
    })?;
    let d = PyDict::new(py);
    d.set_item("backend", decision.backend.name())?;
    d.set_item("reason", decision.reason)?;
    d.set_item("gpu_seconds", decision.gpu_seconds)?;
    d.set_item("cpu_seconds", decision.cpu_seconds)?;
    d.set_item("calibration_seconds", model.calibration_seconds)?;
    d.set_item("calibration", &model.source)?;
    let coefficients = PyDict::new(py);
    let c = &model.cpu;
    coefficients.set_item("cpu_per_call", c.per_call)?;
    coefficients.set_item("cpu_per_image_triangle", c.per_image_triangle)?;
    coefficients.set_item("cpu_per_pixel", c.per_pixel)?;
    coefficients.set_item("cpu_per_box_ray", c.per_box_ray)?;
    coefficients.set_item("cpu_per_box_ray_log2", c.per_box_ray_log2)?;
    coefficients.set_item("cpu_build_per_triangle", c.build_per_triangle)?;
    if let Ok(g) = &model.gpu {
        coefficients.set_item("gpu_per_call", g.per_call)?;
        coefficients.set_item("gpu_per_triangle", g.per_triangle)?;
        coefficients.set_item("gpu_per_pixel", g.per_pixel)?;
        coefficients.set_item("gpu_per_box_pixel", g.per_box_pixel)?;
        coefficients.set_item("gpu_upload_per_triangle", g.upload_per_triangle)?;
    }
    d.set_item("coefficients", coefficients)?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (scene, cameras, redundancy="pixel", cull_backfaces=false, backend="auto"))]
pub fn discretize_nonredundant<'py>(
    py: Python<'py>,
    scene: &PyScene,
    cameras: Vec<PyCamera>,
    redundancy: &str,
    cull_backfaces: bool,
    backend: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let r = super::convert::redundancy(py, redundancy)?;
    let choice: BackendChoice = backend
        .parse()
        .map_err(|e| super::errors::to_pyerr(py, e))?;
    let cams: Vec<_> = cameras.into_iter().map(|c| c.inner).collect();
    let s = scene.inner.clone();
    let (img, decision) = super::run(py, || {
        crate::nonredundant::discretize_nonredundant(&s, &cams, r, cull_backfaces, choice)
    })?;
    let rest = match r {
        crate::nonredundant::Redundancy::Pixel => "rendered on the gpu",
        crate::nonredundant::Redundancy::Visibility => "traced on the cpu",
    };
    let d = images_dict(py, img)?;
    d.set_item("backend", decision.backend.name())?;
    d.set_item(
        "backend_reason",
        format!(
            "image 0 on the {} ({}); the later images {rest}",
            decision.backend.name(),
            decision.reason
        ),
    )?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (scene, camera, layers, cull_backfaces=false, backend="auto"))]
pub fn discretize_peeling<'py>(
    py: Python<'py>,
    scene: &PyScene,
    camera: PyCamera,
    layers: usize,
    cull_backfaces: bool,
    backend: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let choice: BackendChoice = backend
        .parse()
        .map_err(|e| super::errors::to_pyerr(py, e))?;
    let s = scene.inner.clone();
    let (img, decision) = super::run(py, || {
        crate::nonredundant::render::peeling_with(&s, &camera.inner, layers, cull_backfaces, choice)
    })?;
    let d = images_dict(py, img)?;
    d.set_item("backend", decision.backend.name())?;
    d.set_item("backend_reason", decision.reason)?;
    Ok(d)
}

#[pyfunction]
pub fn device_info<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let info = super::run(py, crate::gpu::device_info)?;
    let d = PyDict::new(py);
    d.set_item("name", info.name)?;
    d.set_item("backend", info.backend)?;
    d.set_item("device_type", info.device_type)?;
    d.set_item("driver", info.driver)?;
    d.set_item("timestamps", info.timestamps)?;
    d.set_item("max_texture_dimension_2d", info.max_texture_dimension_2d)?;
    d.set_item(
        "max_storage_buffer_binding_size",
        info.max_storage_buffer_binding_size,
    )?;
    Ok(d)
}

/// Write flattened image fields (the façade flattens and checks shapes) to an EXR file.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn write_exr(
    py: Python<'_>,
    path: PathBuf,
    width: u32,
    height: u32,
    depth: &Bound<'_, PyAny>,
    triangle: &Bound<'_, PyAny>,
    normal: &Bound<'_, PyAny>,
    shading_normal: &Bound<'_, PyAny>,
    position: &Bound<'_, PyAny>,
    color: &Bound<'_, PyAny>,
    cameras: Vec<PyCamera>,
    method: String,
) -> PyResult<()> {
    let npx = width as usize * height as usize;
    let n = cameras.len();
    let depth: Vec<f32> = rows_f32::<1>(depth, "depth")?
        .into_iter()
        .map(|d| d[0])
        .collect();
    let img = DepthImages {
        n,
        width,
        height,
        depth,
        triangle: flat_i32(triangle, "triangle")?,
        normal: rows_f32::<3>(normal, "normal")?,
        shading_normal: rows_f32::<3>(shading_normal, "shading_normal")?,
        position: rows_f32::<3>(position, "position")?,
        color: rows_f32::<3>(color, "color")?,
        cameras: cameras.into_iter().map(|c| c.inner).collect(),
        method,
        timings: crate::types::Timings::new(),
    };
    for (name, len) in [
        ("depth", img.depth.len()),
        ("triangle", img.triangle.len()),
        ("normal", img.normal.len()),
        ("shading_normal", img.shading_normal.len()),
        ("position", img.position.len()),
        ("color", img.color.len()),
    ] {
        if len != n * npx {
            return Err(input(
                py,
                format!("{name} has {len} pixels, expected {n} images of {width}x{height}"),
            ));
        }
    }
    super::run(py, || crate::io::exr::write_depth_images(&path, &img))
}

#[pyfunction]
pub fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let img = super::run(py, || crate::io::exr::read_depth_images(&path))?;
    images_dict(py, img)
}

/// A lit frame from a one-image G-buffer (`gbuffer`: its triangle ids (H, W), positions and base
/// colours (H·W, 3); `shading::frame`): the scene's punctual lights in
/// order, each scaled by its entry of `light_visibility` ((H, W) float32, or None for fully
/// visible), then one area light per `(center, visibility or None)` of `areas`; the default
/// light joins them when there are none, or when they leave the view dark. Returns (H, W, 3)
/// float32 linear RGB, and whether the default light was added.
#[pyfunction]
pub fn shade_frame<'py>(
    py: Python<'py>,
    scene: &PyScene,
    camera: &PyCamera,
    gbuffer: (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>),
    light_visibility: Vec<Option<Bound<'py, PyAny>>>,
    areas: Vec<(Bound<'py, PyAny>, Option<Bound<'py, PyAny>>)>,
) -> PyResult<(Bound<'py, PyAny>, bool)> {
    use crate::shading::{self, ShadeLight};
    let s = scene.inner.clone();
    let cam = camera.inner.clone();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let vis = |v: &Option<Bound<'py, PyAny>>| -> PyResult<Option<Vec<f32>>> {
        v.as_ref()
            .map(|a| super::convert::flat_f32(a, "visibility"))
            .transpose()
    };
    let mut lights = shading::punctual(&s);
    if light_visibility.len() != lights.len() {
        return Err(input(
            py,
            format!(
                "the scene has {} lights, light_visibility {} entries",
                lights.len(),
                light_visibility.len()
            ),
        ));
    }
    let mut visibility = light_visibility
        .iter()
        .map(vis)
        .collect::<PyResult<Vec<_>>>()?;
    for (center, v) in &areas {
        lights.push(ShadeLight::area(super::convert::vec3(
            center,
            "area light centre",
        )?));
        visibility.push(vis(v)?);
    }
    let gbuffer = DepthImages {
        n: 1,
        width: cam.width,
        height: cam.height,
        triangle: flat_i32(&gbuffer.0, "triangle")?,
        position: rows_f32(&gbuffer.1, "position")?,
        color: rows_f32(&gbuffer.2, "color")?,
        ..Default::default()
    };
    let (image, rig) = super::run(py, || {
        shading::frame(&s, &cam, &gbuffer, &lights, &visibility)
    })?;
    Ok((rows_owned(py, image, &[h, w, 3])?.into_any(), rig))
}
