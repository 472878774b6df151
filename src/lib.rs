//! scenesample: sample triangle scenes with images, points and rays; rebuild, splat and measure.
//!
//! The algorithms live in plain Rust modules (testable with `cargo test`); the Python module
//! `scenesample._core` is declared in `py/` and compiled only with the `python` feature.

// One room per paper: `nonredundant`, `epr`, `visibility_field`, `impostors`.
pub mod epr;
pub mod impostors;
pub mod nonredundant;
pub mod visibility_field;

// The floors below them, which no paper owns.
pub mod calibration;
pub mod camera;
pub mod counters;
pub mod error;
pub mod gpu;
pub mod image;
pub mod io;
pub mod limits;
pub mod process;
pub mod random;
pub mod scene;
pub mod sets;
pub mod shading;
pub mod shadow_rays;
pub mod trace;
pub mod types;

#[cfg(feature = "python")]
mod py;

pub use camera::Camera;
pub use error::{Error, Result};
pub use scene::Scene;
