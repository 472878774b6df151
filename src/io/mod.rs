//! File formats: EXR for depth images.

pub mod exr;
