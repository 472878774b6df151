//! scenesample: sample triangle scenes with images, points and rays; rebuild, splat and measure.
//!
//! The algorithms live in plain Rust modules (testable with `cargo test`); the Python module
//! `scenesample._core` is declared in `py/` and compiled only with the `python` feature.

pub mod camera;
pub mod counters;
pub mod discretize;
pub mod effects;
pub mod error;
pub mod evaluate;
pub mod gpu;
pub mod io;
pub mod limits;
pub mod process;
pub mod reconstruct;
pub mod scene;
pub mod sets;
pub mod shading;
pub mod shadows;
pub mod splat;
pub mod trace;
pub mod types;
pub mod visibility_field;

#[cfg(feature = "python")]
mod py;

pub use camera::Camera;
pub use error::{Error, Result};
pub use scene::Scene;
