//! Hybrid reconstruction (non-redundant-rendering.txt §4, Algorithm 4). Each sample of image I
//! becomes a quad over its pixel. Its four corners come from the offset image H — the same
//! discretization from cameras offset by half a pixel, whose pixel centres are I's pixel
//! corners (`Camera::corner_camera`) — where H's sample at the corner belongs to the same surface
//! as I's sample (see `continuous`); otherwise the corner is where the corner ray meets the
//! sample's tangent plane (`on_tangent_plane`). No corner, from H or not, lies farther than
//! `MAX_STRETCH` footprints from its sample. Corners
//! taken from H are shared by every quad that takes them, so a continuous surface is tiled
//! without cracks or overlap; an isolated sample still gives a quad of four plane corners.

use std::time::Instant;

use glam::DVec2;

use super::{
    check, continuous, on_tangent_plane, per_image, push_vertex, ImageView, Mesh, MAX_STRETCH,
};
use crate::error::Result;
use crate::input_err;
use crate::types::{DepthImages, Timings};

/// The hybrid reconstruction of `images` with the offset images `offset` (image i of `offset`
/// made from `images.cameras[i].corner_camera()`). Two triangles per sample, counter-clockwise
/// as seen from the camera, both with that sample's index.
pub fn reconstruct_hybrid(images: &DepthImages, offset: &DepthImages) -> Result<Mesh> {
    check(images)?;
    check(offset)?;
    if offset.n != images.n
        || (offset.width, offset.height) != (images.width + 1, images.height + 1)
    {
        return input_err!(
            "the offset images must be {} images of {}x{} (one pixel larger than the images, \
             from Camera.corner_camera()), got {} of {}x{}",
            images.n,
            images.width + 1,
            images.height + 1,
            offset.n,
            offset.width,
            offset.height
        );
    }
    let start = Instant::now();
    let mut m = per_image(images.n, |i| {
        image_hybrid(&ImageView::of(images, i), &ImageView::of(offset, i))
    });
    m.timings = Timings::from([("hybrid", start.elapsed().as_secs_f64())]);
    Ok(m)
}

fn image_hybrid(img: &ImageView<'_>, off: &ImageView<'_>) -> Mesh {
    let (w, h) = (img.width, img.height);
    let ow = off.width;
    let mut m = Mesh::default();
    // Vertex of each offset sample once some quad has taken it.
    let mut shared = vec![u32::MAX; off.width * off.height];
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            if !img.valid(k) {
                continue;
            }
            let s = img.surfel(k);
            // Corners c0..c3: top-left, top-right, bottom-right, bottom-left.
            let corners = [(x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1)];
            let ids = corners.map(|(cx, cy)| {
                let q = cy * ow + cx;
                let h = off.surfel(q);
                let near = (h.point - s.point).length() <= MAX_STRETCH * s.footprint;
                if off.valid(q) && near && continuous(&s, &h) {
                    if shared[q] == u32::MAX {
                        shared[q] = push_vertex(&mut m, off.point(q));
                    }
                    shared[q]
                } else {
                    let p = on_tangent_plane(img, k, DVec2::new(cx as f64, cy as f64));
                    push_vertex(&mut m, p)
                }
            });
            // Counter-clockwise as seen from the camera (image rows grow downward).
            m.faces.push([ids[0], ids[3], ids[2]]);
            m.faces.push([ids[2], ids[1], ids[0]]);
            let flat = img.base + k as i64;
            m.sample.extend([flat, flat]);
        }
    }
    m
}
