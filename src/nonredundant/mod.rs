//! Non-redundant rendering (non-redundant-rendering.txt): images that sample each surface once
//! (`render`: §3.2, Algorithm 1 with pixel or visibility redundancy, and depth peeling), the
//! redundancy tests (§3.1) they and the sampling metrics share (`redundancy`), the surfaces
//! rebuilt from depth images (`reconstruct`: §4, Algorithm 4), soft shadows from them
//! (`shadows`: §5, Algorithm 5) and the sampling-quality metrics (`sampling`: §6.1.2).
//! Conventional images, the baseline, are the image floor's (`crate::image`).

pub mod reconstruct;
pub mod redundancy;
pub mod render;
pub mod sampling;
pub mod shadows;

pub use redundancy::Redundancy;
pub use render::{centroid_camera, discretize_nonredundant, discretize_peeling};
pub use sampling::{sampling_metrics, SamplingMetrics};
