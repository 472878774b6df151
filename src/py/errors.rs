//! Core errors → the typed exceptions of `scenesample.errors` (defined in Python so they can
//! inherit from both `ValueError` and `OSError` where both apply).

use pyo3::prelude::*;
use pyo3::types::PyType;

use crate::error::Error;

/// Instantiate `scenesample.errors.<class_name>(message)`.
pub fn typed(py: Python<'_>, class_name: &str, message: String) -> PyErr {
    let cls = py
        .import("scenesample.errors")
        .and_then(|m| m.getattr(class_name))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
    match cls {
        Ok(cls) => PyErr::from_type(cls, message),
        // The façade is always importable beside _core; this keeps the message if it is not.
        Err(_) => pyo3::exceptions::PyValueError::new_err(message),
    }
}

pub fn to_pyerr(py: Python<'_>, e: Error) -> PyErr {
    let class = match &e {
        Error::Interrupted => {
            return pyo3::exceptions::PyKeyboardInterrupt::new_err("interrupted");
        }
        Error::System(_) => "ScenesampleError",
        Error::Scene(_) => "SceneError",
        Error::SceneFile { .. } => "SceneFileError",
        Error::Input(_) => "InputError",
        Error::GpuUnavailable(_) => "GpuUnavailableError",
        Error::GpuLimit(_) => "GpuLimitError",
        Error::Gpu(_) => "GpuError",
        Error::Exr { .. } => "ExrError",
    };
    typed(py, class, e.to_string())
}

/// `Result<T, Error>` → `PyResult<T>`.
pub trait IntoPy<T> {
    fn py_err(self, py: Python<'_>) -> PyResult<T>;
}

impl<T> IntoPy<T> for crate::error::Result<T> {
    fn py_err(self, py: Python<'_>) -> PyResult<T> {
        self.map_err(|e| to_pyerr(py, e))
    }
}

pub fn input(py: Python<'_>, message: String) -> PyErr {
    typed(py, "InputError", message)
}
