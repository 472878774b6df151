//! The conventional depth-image mesh (non-redundant-rendering.txt §4): the regular pixel grid
//! connects four neighbouring samples with two triangles unless a depth discontinuity separates
//! them. Two samples are connected when they hold the same triangle or each lies within
//! `CONTINUITY` pixel footprints of the other's tangent plane (so a steep plane stays connected
//! however fast its depth changes, and two surfaces a footprint apart do not). A 2×2 block with
//! all four samples connected around its border gives two triangles, with exactly three
//! mutually connected samples one; a sample connected to nothing is dropped.

use std::time::Instant;

use super::{check, continuous, per_image, push_vertex, ImageView, Mesh};
use crate::error::Result;
use crate::types::{DepthImages, Timings};

/// The conventional mesh of every image. Faces wind counter-clockwise as seen from their
/// image's camera; a face's `sample` is its block's first sample in (top-left, top-right,
/// bottom-left, bottom-right) order that it uses.
pub fn reconstruct_mesh(images: &DepthImages) -> Result<Mesh> {
    check(images)?;
    let start = Instant::now();
    let mut m = per_image(images.n, |i| image_mesh(&ImageView::of(images, i)));
    m.timings = Timings::from([("mesh", start.elapsed().as_secs_f64())]);
    Ok(m)
}

fn image_mesh(img: &ImageView<'_>) -> Mesh {
    let (w, h) = (img.width, img.height);
    let mut m = Mesh::default();
    let mut vertex = vec![u32::MAX; w * h];
    let mut vid = |m: &mut Mesh, k: usize| {
        if vertex[k] == u32::MAX {
            vertex[k] = push_vertex(m, img.point(k));
        }
        vertex[k]
    };
    for y in 0..h.saturating_sub(1) {
        for x in 0..w - 1 {
            // a b
            // c d
            let (a, b, c, d) = (
                y * w + x,
                y * w + x + 1,
                (y + 1) * w + x,
                (y + 1) * w + x + 1,
            );
            let ok = [a, b, c, d].map(|k| img.valid(k));
            let link = |p: usize, q: usize, op: bool, oq: bool| {
                op && oq && continuous(&img.surfel(p), &img.surfel(q))
            };
            let ab = link(a, b, ok[0], ok[1]);
            let ac = link(a, c, ok[0], ok[2]);
            let bd = link(b, d, ok[1], ok[3]);
            let cd = link(c, d, ok[2], ok[3]);
            let ad = link(a, d, ok[0], ok[3]);
            let bc = link(b, c, ok[1], ok[2]);
            // Counter-clockwise as seen from the camera: rows grow downward in the image.
            let mut tri = |m: &mut Mesh, p: usize, q: usize, r: usize| {
                let f = [vid(m, p), vid(m, q), vid(m, r)];
                m.faces.push(f);
                m.sample.push(img.base + p.min(q).min(r) as i64);
            };
            if ab && ac && bd && cd && (ad || bc) {
                if ad {
                    tri(&mut m, a, c, d);
                    tri(&mut m, a, d, b);
                } else {
                    tri(&mut m, a, c, b);
                    tri(&mut m, b, c, d);
                }
            } else if ac && cd && ad {
                tri(&mut m, a, c, d);
            } else if ab && bd && ad {
                tri(&mut m, a, d, b);
            } else if ab && ac && bc {
                tri(&mut m, a, c, b);
            } else if bc && cd && bd {
                tri(&mut m, b, c, d);
            }
        }
    }
    m
}
