//! Multiview effects built on the samples (eye-based-point-rendering.txt §4-5): cube-mapped
//! reflections by EPR, MVR and iVIR, and the shading model they share.

pub mod reflections;
pub mod shading;
