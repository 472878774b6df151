//! Multiview effects built on the samples (eye-based-point-rendering.txt §4-5): cube-mapped
//! reflections and omnidirectional soft shadows, each by EPR, MVR and iVIR.

pub mod omni_shadows;
pub mod reflections;
