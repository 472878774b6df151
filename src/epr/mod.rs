//! Eye-based point rendering (eye-based-point-rendering.txt): EPR and iVIR points for many
//! off-screen views (`points`: §3.1-3.4), their splatting into those views at once (`splat`:
//! §3.4-3.5), cube-mapped reflections (`reflections`: §4) and omnidirectional soft shadows
//! (`omni_shadows`: §5), each beside MVR and iVIR.

pub mod omni_shadows;
pub mod points;
pub mod reflections;
pub mod splat;
