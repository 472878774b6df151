//! `scenesample._core.Camera`: immutable; camera math in float64.

use glam::{DVec2, DVec3};
use pyo3::prelude::*;

use super::convert::{array, mat4, mat4_to_numpy, rows_f64, vec3};
use super::errors::{input, IntoPy};
use crate::camera::{Camera, Projection};

/// A pinhole (perspective) or orthographic camera, immutable, its math in float64.
///
/// Conventions follow OpenGL, pyrender and glTF: ``pose`` is the 4x4 camera-to-world matrix,
/// the camera looks along its -Z with +Y up; ``yfov`` is the vertical field of view in
/// radians; images have ``height`` rows of ``width`` pixels, row 0 at the top, pixel centres
/// at +0.5; depth is camera-space z. ``znear``/``zfar`` are None for "from the scene's bounds".
/// Make one with :meth:`look_at`, :meth:`from_pose`, :meth:`orthographic` or :meth:`cube`.
#[pyclass(
    name = "Camera",
    module = "scenesample._core",
    frozen,
    eq,
    from_py_object
)]
#[derive(Clone, PartialEq)]
pub struct PyCamera {
    pub inner: Camera,
}

impl From<Camera> for PyCamera {
    fn from(inner: Camera) -> Self {
        Self { inner }
    }
}

/// What a pickled camera holds: pose (16 float64s, column-major), projection kind and its two
/// parameters, width, height, znear, zfar, name.
type CameraState = (
    Vec<f64>,
    String,
    [f64; 2],
    u32,
    u32,
    Option<f64>,
    Option<f64>,
    Option<String>,
);

#[pymethods]
impl PyCamera {
    /// A perspective camera at ``eye`` (3 floats) looking at ``target``, with ``up`` (default
    /// +Y) kept upward; ``yfov`` radians, ``width`` x ``height`` pixels, optional
    /// ``znear``/``zfar``. Raises InputError when eye and target coincide or up is parallel
    /// to the view.
    #[staticmethod]
    #[pyo3(signature = (eye, target, up=None, *, yfov, width, height, znear=None, zfar=None))]
    #[allow(clippy::too_many_arguments)]
    fn look_at(
        py: Python<'_>,
        eye: &Bound<'_, PyAny>,
        target: &Bound<'_, PyAny>,
        up: Option<&Bound<'_, PyAny>>,
        yfov: f64,
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> PyResult<Self> {
        let up = up.map(|u| vec3(u, "up")).transpose()?.unwrap_or(DVec3::Y);
        Camera::look_at(
            vec3(eye, "eye")?,
            vec3(target, "target")?,
            up,
            yfov,
            width,
            height,
            znear,
            zfar,
        )
        .py_err(py)
        .map(Self::from)
    }

    /// A camera between ``cameras`` (of one resolution and projection): positions and
    /// fields of view averaged with ``weights`` (default equal), orientations blended as
    /// quaternions; the in-between views of ``evaluate``'s intermediate frames.
    #[staticmethod]
    #[pyo3(signature = (cameras, weights=None))]
    fn blend(py: Python<'_>, cameras: Vec<PyCamera>, weights: Option<Vec<f64>>) -> PyResult<Self> {
        let cams: Vec<Camera> = cameras.into_iter().map(|c| c.inner).collect();
        let weights = weights.unwrap_or_else(|| vec![1.0; cams.len()]);
        Camera::blend(&cams, &weights).map(Self::from).py_err(py)
    }

    /// A perspective camera with the 4x4 camera-to-world ``pose`` (rigid: rotation and
    /// translation), ``yfov`` radians, ``width`` x ``height`` pixels.
    #[staticmethod]
    #[pyo3(signature = (pose, *, yfov, width, height, znear=None, zfar=None))]
    fn from_pose(
        py: Python<'_>,
        pose: &Bound<'_, PyAny>,
        yfov: f64,
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> PyResult<Self> {
        Camera::new(
            mat4(pose, "pose")?,
            Projection::Perspective { yfov },
            width,
            height,
            znear,
            zfar,
        )
        .py_err(py)
        .map(Self::from)
    }

    /// An orthographic camera with the 4x4 camera-to-world ``pose``: it sees ``[-xmag,
    /// xmag] x [-ymag, ymag]`` (glTF's half extents) over ``width`` x ``height`` pixels.
    #[staticmethod]
    #[pyo3(signature = (pose, *, xmag, ymag, width, height, znear=None, zfar=None))]
    #[allow(clippy::too_many_arguments)]
    fn orthographic(
        py: Python<'_>,
        pose: &Bound<'_, PyAny>,
        xmag: f64,
        ymag: f64,
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> PyResult<Self> {
        Camera::new(
            mat4(pose, "pose")?,
            Projection::Orthographic { xmag, ymag },
            width,
            height,
            znear,
            zfar,
        )
        .py_err(py)
        .map(Self::from)
    }

    /// The six 90-degree faces of a cube map at ``center``, ``resolution`` pixels square, in
    /// OpenGL's order +X, -X, +Y, -Y, +Z, -Z with OpenGL's up vectors.
    #[staticmethod]
    #[pyo3(signature = (center, resolution, *, znear=None, zfar=None))]
    fn cube(
        py: Python<'_>,
        center: &Bound<'_, PyAny>,
        resolution: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
    ) -> PyResult<Vec<Self>> {
        let c = Camera::cube(vec3(center, "center")?, resolution, znear, zfar).py_err(py)?;
        Ok(c.into_iter().map(Self::from).collect())
    }

    /// Pickling (process pools, dask): the pose's sixteen float64s and the other fields, which
    /// `_restore` turns back into the same camera, bit for bit.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, CameraState)> {
        let c = &slf.get().inner;
        let (kind, params) = match c.projection {
            Projection::Perspective { yfov } => ("perspective", [yfov, 0.0]),
            Projection::Orthographic { xmag, ymag } => ("orthographic", [xmag, ymag]),
        };
        let state = (
            c.pose.to_cols_array().to_vec(),
            kind.to_string(),
            params,
            c.width,
            c.height,
            c.znear,
            c.zfar,
            c.name.clone(),
        );
        Ok((slf.get_type().getattr("_restore")?, state))
    }

    /// The camera `__reduce__` describes.
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    fn _restore(
        py: Python<'_>,
        pose: Vec<f64>,
        kind: &str,
        params: [f64; 2],
        width: u32,
        height: u32,
        znear: Option<f64>,
        zfar: Option<f64>,
        name: Option<String>,
    ) -> PyResult<Self> {
        let Ok(cols) = <[f64; 16]>::try_from(pose.as_slice()) else {
            return Err(input(
                py,
                format!("a pickled camera's pose has {} values, not 16", pose.len()),
            ));
        };
        let projection = match kind {
            "perspective" => Projection::Perspective { yfov: params[0] },
            "orthographic" => Projection::Orthographic {
                xmag: params[0],
                ymag: params[1],
            },
            _ => return Err(input(py, format!("unknown pickled projection {kind:?}"))),
        };
        let mut c = Camera::new(
            glam::DMat4::from_cols_array(&cols),
            projection,
            width,
            height,
            znear,
            zfar,
        )
        .py_err(py)?;
        c.name = name;
        Ok(Self::from(c))
    }

    /// The same camera with ``width`` x ``height`` pixels (the same field of view vertically).
    fn with_resolution(&self, py: Python<'_>, width: u32, height: u32) -> PyResult<Self> {
        self.inner
            .with_resolution(width, height)
            .py_err(py)
            .map(Self::from)
    }

    /// (4, 4) float64 camera-to-world matrix.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        mat4_to_numpy(py, &self.inner.pose)
    }
    /// ``"perspective"`` or ``"orthographic"``.
    #[getter]
    fn projection(&self) -> &'static str {
        match self.inner.projection {
            Projection::Perspective { .. } => "perspective",
            Projection::Orthographic { .. } => "orthographic",
        }
    }
    /// Vertical field of view in radians (None for an orthographic camera).
    #[getter]
    fn yfov(&self) -> Option<f64> {
        match self.inner.projection {
            Projection::Perspective { yfov } => Some(yfov),
            _ => None,
        }
    }
    /// Half the horizontal extent of an orthographic view (None for a perspective one).
    #[getter]
    fn xmag(&self) -> Option<f64> {
        match self.inner.projection {
            Projection::Orthographic { xmag, .. } => Some(xmag),
            _ => None,
        }
    }
    /// Half the vertical extent of an orthographic view (None for a perspective one).
    #[getter]
    fn ymag(&self) -> Option<f64> {
        match self.inner.projection {
            Projection::Orthographic { ymag, .. } => Some(ymag),
            _ => None,
        }
    }
    /// Image width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }
    /// Image height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }
    /// Near plane depth, or None (from the scene's bounds).
    #[getter]
    fn znear(&self) -> Option<f64> {
        self.inner.znear
    }
    /// Far plane depth, or None (from the scene's bounds).
    #[getter]
    fn zfar(&self) -> Option<f64> {
        self.inner.zfar
    }
    /// The glTF camera's name, or None.
    #[getter]
    fn name(&self) -> Option<String> {
        self.inner.name.clone()
    }
    /// The camera's position in world space.
    #[getter]
    fn eye(&self) -> [f64; 3] {
        self.inner.eye().to_array()
    }
    /// The unit direction it looks along (its -Z in world space).
    #[getter]
    fn forward(&self) -> [f64; 3] {
        self.inner.forward().to_array()
    }

    /// (n, 3) world points → ((n, 2) pixel x/y, (n,) camera-space depth), float64.
    fn project<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let p = rows_f64::<3>(points, "points")?;
        let (mut px, mut d) = (Vec::with_capacity(2 * p.len()), Vec::with_capacity(p.len()));
        for q in &p {
            let (xy, depth) = self.inner.project(DVec3::from_array(*q));
            px.extend([xy.x, xy.y]);
            d.push(depth);
        }
        Ok((array(py, px, &[p.len(), 2])?, array(py, d, &[p.len()])?))
    }

    /// (n, 2) pixel x/y and (n,) depth → (n, 3) world points, float64.
    fn unproject<'py>(
        &self,
        py: Python<'py>,
        pixels: &Bound<'py, PyAny>,
        depth: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let px = rows_f64::<2>(pixels, "pixels")?;
        let np = py.import("numpy")?;
        let d = rows_f64::<1>(&np.call_method1("reshape", (depth, (-1, 1)))?, "depth")?;
        if d.len() != px.len() {
            return Err(input(
                py,
                format!("pixels has {} rows but depth has {}", px.len(), d.len()),
            ));
        }
        let out: Vec<f64> = px
            .iter()
            .zip(&d)
            .flat_map(|(p, z)| self.inner.unproject(DVec2::from_array(*p), z[0]).to_array())
            .collect();
        array(py, out, &[px.len(), 3])
    }

    /// Rays through every pixel centre: origins and directions, each (H, W, 3) float32.
    /// Unit directions by default; with `normalize=False` each direction's camera-space z
    /// is −1, so a hit's `t` equals its depth.
    #[pyo3(signature = (*, normalize=true))]
    fn pixel_rays<'py>(
        &self,
        py: Python<'py>,
        normalize: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (w, h) = (self.inner.width as usize, self.inner.height as usize);
        crate::limits::check(
            || format!("the pixel rays of a {w}x{h} camera"),
            crate::limits::product(&[w as u64, h as u64]),
            24,
        )
        .py_err(py)?;
        let mut o = Vec::with_capacity(w * h * 3);
        let mut d = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let (orig, dir) = self
                    .inner
                    .ray_z1(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                let dir = if normalize { dir.normalize() } else { dir };
                o.extend(orig.as_vec3().to_array());
                d.extend(dir.as_vec3().to_array());
            }
        }
        Ok((array(py, o, &[h, w, 3])?, array(py, d, &[h, w, 3])?))
    }

    /// The camera offset by half a pixel in both directions (hybrid reconstruction's H): same
    /// pose and pixel size, (width+1)x(height+1) pixels whose centres are this camera's pixel
    /// corners.
    fn corner_camera(&self, py: Python<'_>) -> PyResult<Self> {
        self.inner.corner_camera().map(Self::from).py_err(py)
    }

    /// World size of one pixel at camera depth ``depth`` (perspective: depth * 2 tan(yfov/2) /
    /// height; orthographic: 2 ymag / height).
    fn pixel_footprint(&self, depth: f64) -> f64 {
        self.inner.pixel_footprint(depth)
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        let proj = match c.projection {
            Projection::Perspective { yfov } => format!("yfov={yfov:.6}"),
            Projection::Orthographic { xmag, ymag } => format!("xmag={xmag}, ymag={ymag}"),
        };
        format!(
            "Camera({}, eye={:?}, forward={:?}, {proj}, {}x{})",
            self.projection(),
            c.eye().to_array(),
            c.forward().to_array(),
            c.width,
            c.height
        )
    }
}
