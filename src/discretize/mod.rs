//! Discretizations of a scene into samples (non-redundant-rendering.txt): `conventional` depth
//! images (one per camera, the baseline of §3), `nonredundant` images (§3.2, Algorithm 1 with
//! pixel or visibility redundancy) and depth `peeling` layers, and the `redundancy` tests
//! (§3.1) they and the sampling metrics share; eye-based points for many off-screen views
//! (`epr`, eye-based-point-rendering.txt §3). The visibility field has a room of its own
//! (`crate::visibility_field`).

pub mod backend;
pub mod conventional;
pub mod epr;
pub mod impostors;
pub mod nonredundant;
pub(crate) mod pixels;
pub(crate) mod raster_rule;
pub mod redundancy;

pub use conventional::{
    discretize_conventional, discretize_ranges, discretize_sided, discretize_traced, push_range,
};
pub use nonredundant::{centroid_camera, discretize_nonredundant, discretize_peeling};
pub use redundancy::Redundancy;
