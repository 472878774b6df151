//! The image floor, shared by every room: pixel rays and the trace frame (`pixels`), the
//! raster's rule for samples on an edge (`raster_rule`), and conventional depth images, drawn
//! or traced (`conventional`, the baseline of non-redundant-rendering.txt §3), with the
//! front-to-back pixel walk that non-redundant images and the coincident-triangle fix-up use.

pub mod conventional;
pub(crate) mod pixels;
pub(crate) mod raster_rule;

use glam::DVec3;

use crate::scene::Scene;

pub use conventional::{
    discretize_conventional, discretize_ranges, discretize_sided, discretize_traced, push_range,
};

/// A sample: the triangle it lies on and its world point.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub triangle: i32,
    pub point: DVec3,
}

/// The distance within which another surface counts as the sample itself in the visibility
/// test, to which `visible_from` adds 1e-5 of the sample's distance from the viewpoint: well
/// above f32 rounding of positions and hits, well below any feature a depth image resolves.
pub fn tolerance(scene: &Scene) -> f64 {
    1e-5 * scene.diagonal()
}
