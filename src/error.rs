//! One error type for the whole core. `src/py/errors.rs` maps each variant to a typed Python
//! exception, so the message written here is exactly what the user reads.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Scene content that cannot be used: NaN vertices, bad indices, cycles, bad accessors.
    #[error("{0}")]
    Scene(String),
    /// A scene file (or a file it references) that could not be read.
    #[error("{path}: {message}")]
    SceneFile { path: PathBuf, message: String },
    /// Arguments of the wrong shape, dtype or value.
    #[error("{0}")]
    Input(String),
    /// No adapter, or one without the features this crate needs.
    #[error("{0}")]
    GpuUnavailable(String),
    /// A request the device cannot serve (too large for its limits), refused before submission.
    #[error("{0}")]
    GpuLimit(String),
    /// The device reported an error while running work.
    #[error("{0}")]
    Gpu(String),
    /// An EXR file that could not be written or read back.
    #[error("{path}: {message}")]
    Exr { path: PathBuf, message: String },
    /// The call was interrupted (Ctrl-C) before it finished; see `process::interruptible`.
    #[error("interrupted")]
    Interrupted,
    /// The operating system refused a resource the call needs (worker threads).
    #[error("{0}")]
    System(String),
}

pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand for `Err(Error::Input(format!(...)))`.
#[macro_export]
macro_rules! input_err {
    ($($arg:tt)*) => { Err($crate::error::Error::Input(format!($($arg)*))) };
}

/// Shorthand for `Err(Error::Scene(format!(...)))`.
#[macro_export]
macro_rules! scene_err {
    ($($arg:tt)*) => { Err($crate::error::Error::Scene(format!($($arg)*))) };
}
