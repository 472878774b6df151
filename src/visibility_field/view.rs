//! A view from the visibility field (visibility-field.txt §4, Fig. 4), the whole pipeline in
//! order: resample the field along the view's pixel lines to mark the cells they see
//! (`resample`, or the plain `reference`); trace the pixels the field does not answer and mark
//! what they hit (`fallback`); draw the marked cells (`draw`); look along the borders between
//! cells in the image for cells a rasterizer's rounding shows that nothing marked, and draw
//! again if there are any (`fallback::look_across_borders`).

use std::time::Instant;

use super::build::{Slab, SortedScene};
use super::draw::{remap, render_sorted, trace_sorted};
use super::fallback::{look_across_borders, trace_fallback};
use super::resample::{resample, scene_box, Interpolate, Marks, Resampling, Samples};
use crate::camera::Camera;
use crate::error::Result;
use crate::image::pixels::ViewRays;
use crate::types::DepthImages;

/// How a view is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewOptions {
    pub interpolate: Interpolate,
    /// Side of the pixel blocks that share one line (>= 1).
    pub subsample: u32,
    /// Conservative resampling (this package's): answer a pixel only where the field holds
    /// everything it can see, trace the others and look along the cells' borders after
    /// drawing. `false`: the paper's rule alone.
    pub fallback: bool,
    /// The most cells a sample read may have seen (conservative resampling).
    pub trust: u32,
    /// Trace the marked cells on the CPU instead of drawing them on the GPU.
    pub cpu: bool,
    /// Resample pixel by pixel with the plain reference (`reference::resample`) instead of by
    /// blocks: the same marks, slower; for checking.
    pub reference: bool,
}

/// Seconds per stage of a view.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewSeconds {
    pub resample: f64,
    pub fallback: f64,
    /// Drawing, the look along the borders and any second draw.
    pub render: f64,
}

/// What a view made: the image (the scene's triangle ids), the cells marked and how.
#[derive(Debug, Clone)]
pub struct FieldView {
    /// Per cell, whether the view drew it; `pixels`, `outside` and `overflowed` as resampled
    /// (`fallback` emptied: those pixels were traced).
    pub marks: Marks,
    /// Cells the fallback marked that resampling had not.
    pub fallback_cells: usize,
    /// Cells the look along the borders marked.
    pub border_cells: usize,
    pub triangles_drawn: usize,
    pub image: DepthImages,
    pub seconds: ViewSeconds,
}

/// The view of `camera` from the fields (one per slab) of the cell-sorted scene `sorted`.
pub fn view(
    sorted: &SortedScene,
    fields: &[(Slab, Samples)],
    camera: &Camera,
    how: &ViewOptions,
) -> Result<FieldView> {
    let start = Instant::now();
    let resampling = Resampling {
        interpolate: how.interpolate,
        subsample: how.subsample,
        conservative: how.fallback.then(|| scene_box(sorted.scene)),
        trust: how.trust,
    };
    let mut marks = if how.reference {
        super::reference::resample(fields, sorted.cells(), camera, resampling)?
    } else {
        resample(fields, sorted.cells(), camera, resampling)?
    };
    let mut seconds = ViewSeconds {
        resample: start.elapsed().as_secs_f64(),
        ..Default::default()
    };
    let start = Instant::now();
    let rays = ViewRays::of(sorted.scene, camera)?;
    let pixels = std::mem::take(&mut marks.fallback);
    let (fallback_cells, known) = trace_fallback(sorted, camera, &rays, pixels, &mut marks.marked)?;
    seconds.fallback = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let draw = |marked: &[bool]| {
        if how.cpu {
            trace_sorted(sorted, marked, camera, &rays, &known)
        } else {
            render_sorted(sorted, marked, camera)
        }
    };
    let (mut image, mut triangles_drawn) = draw(&marks.marked)?;
    let looking = Instant::now();
    let border_cells = if how.fallback {
        // The fallback looked across the edges near its pixels of the triangles it hit;
        // where the image shows those, that is done.
        let mut looked = vec![false; image.triangle.len()];
        for &(p, t) in &known {
            looked[p] = t >= 0 && image.triangle[p] == t;
        }
        let ids = &image.triangle;
        look_across_borders(sorted, camera, &rays, ids, &looked, &mut marks.marked)?
    } else {
        0
    };
    let border_seconds = looking.elapsed().as_secs_f64();
    if border_cells > 0 {
        (image, triangles_drawn) = draw(&marks.marked)?;
    }
    image.timings.add("borders", border_seconds);
    remap(&mut image, sorted.order);
    seconds.render = start.elapsed().as_secs_f64();
    Ok(FieldView {
        marks,
        fallback_cells,
        border_cells,
        triangles_drawn,
        image,
        seconds,
    })
}
