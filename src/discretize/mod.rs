//! Discretizations of a scene into samples. `conventional`: one depth image per camera
//! (the baseline of non-redundant-rendering.txt §3).

pub mod conventional;

pub use conventional::{discretize_conventional, DepthImages};
