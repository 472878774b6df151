//! The visibility field (visibility-field.txt): which grid cells of a scene are first hit along
//! the lines of two-plane slabs, precomputed (§3), and the views drawn from it (§4).
//!
//! - `build`: slabs, cells and the sampled field (§3).
//! - A view (`view::view`) runs, in order: `resample` (the fast resampler, by blocks; its plain
//!   twin is `reference`) marks the cells the pixel lines' samples saw; `fallback` traces the
//!   pixels the field does not answer and marks what they hit; `draw` draws the marked cells
//!   (GPU) or traces them (CPU); `fallback::look_across_borders` marks the cells a
//!   rasterizer's rounding shows at the borders between cells, and `draw` runs again if it
//!   found any.

pub mod build;
pub mod cells;
pub mod draw;
pub mod fallback;
pub mod lines;
pub mod reference;
pub mod resample;
pub mod slab;
pub mod view;

pub use build::{
    build, cells, prepare_views, sample, Built, Cells, Field, Grid, Grouping, Rect, Slab,
    SortedScene, Supersample,
};
pub use draw::render_marked;
pub use resample::{Interpolate, Marks, Resampling, Samples};
pub use view::{view, FieldView, ViewOptions, ViewSeconds};
