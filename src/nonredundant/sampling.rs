//! The sampling-quality metrics of non-redundant-rendering.txt §6.1.2, per image of a set:
//!
//! 1. redundant — samples of image i redundant with an earlier image j < i of the same set;
//! 2. disoccluded — samples not captured by the conventional reference images: for a
//!    non-redundant image, by the conventional image from its own camera; for a peeling layer, by
//!    any conventional reference image; none for a conventional image;
//! 3. useful — disoccluded samples needed by at least one intermediate output frame (redundant
//!    with that frame), as a fraction of the disoccluded ones;
//! 4. available (Table 2) — for each intermediate frame, the fraction of its samples captured by
//!    (redundant with) at least one image; reported per prefix of the set (images 0..=i), as the
//!    average and minimum over frames.
//!
//! A sample is a pixel that sees a surface. Both redundancy definitions of §3.1 are supported
//! (`super::redundancy`). The conventional reference images and the frames
//! are rendered here; frames go through the GPU in chunks, each consumed as it arrives.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::image::discretize_conventional;
use crate::image::pixels::resolve_ids;
use crate::input_err;
use crate::nonredundant::redundancy::{self, pixel_redundant, Redundancy, Sample};
use crate::scene::Scene;
use crate::types::{DepthImages, Timings};

/// The metrics, one entry per image (fractions in [0, 1]).
#[derive(Debug, Default, Clone)]
pub struct SamplingMetrics {
    /// Samples (covered pixels) per image.
    pub samples: Vec<u64>,
    pub redundant: Vec<f64>,
    pub disoccluded: Vec<f64>,
    /// Fraction of the disoccluded samples that are useful; 0 where none are disoccluded.
    pub useful: Vec<f64>,
    /// Over frames, of the fraction of a frame's samples available in images 0..=i.
    pub available_avg: Vec<f64>,
    pub available_min: Vec<f64>,
    pub frames: usize,
    /// Per pixel of every image (row-major, image after image): disoccluded, and useful.
    pub disoccluded_mask: Vec<bool>,
    pub useful_mask: Vec<bool>,
    pub timings: Timings,
}

/// The pixels (within image i) that hold samples, in the order of `samples_of`.
fn sample_pixels(img: &DepthImages, i: usize) -> Vec<usize> {
    let npx = img.width as usize * img.height as usize;
    (0..npx)
        .filter(|&p| img.triangle[i * npx + p] >= 0)
        .collect()
}

/// An image's samples, in pixel order. A sample's point is rebuilt in f64 from its camera and
/// depth when the images carry depth (the float32 world position is quantized far from the
/// origin: 1 unit at 1e7), else read from the position.
fn samples_of(img: &DepthImages, i: usize) -> Vec<Sample> {
    let w = img.width as usize;
    let npx = w * img.height as usize;
    let range = i * npx..(i + 1) * npx;
    let cam = &img.cameras[i];
    img.triangle[range.clone()]
        .iter()
        .zip(&img.position[range.clone()])
        .enumerate()
        .filter(|(_, (&t, _))| t >= 0)
        .map(|(k, (&t, p))| {
            let d = img.depth.get(i * npx + k).map_or(f64::NAN, |&d| d as f64);
            let point = if d.is_finite() {
                let px = glam::DVec2::new((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
                cam.unproject(px, d)
            } else {
                DVec3::from_array(p.map(f64::from))
            };
            Sample { triangle: t, point }
        })
        .collect()
}

fn ids_of(img: &DepthImages, i: usize) -> &[i32] {
    let npx = img.width as usize * img.height as usize;
    &img.triangle[i * npx..(i + 1) * npx]
}

/// For each sample, whether the image `k` of `set` captures it under `mode`.
fn captured(
    scene: &Scene,
    samples: &[Sample],
    set: &DepthImages,
    k: usize,
    mode: Redundancy,
) -> Result<Vec<bool>> {
    let cam = &set.cameras[k];
    match mode {
        Redundancy::Pixel => {
            let ids = ids_of(set, k);
            Ok(samples
                .par_iter()
                .map(|s| pixel_redundant(s, cam, ids))
                .collect())
        }
        Redundancy::Visibility => {
            redundancy::visible_from(scene, samples, cam, redundancy::tolerance(scene))
        }
    }
}

/// The samples, among those `open`, that image `k` of `set` captures (indices into `samples`).
fn newly_captured(
    scene: &Scene,
    samples: &[Sample],
    open: impl Fn(usize) -> bool,
    set: &DepthImages,
    k: usize,
    mode: Redundancy,
) -> Result<Vec<usize>> {
    let open: Vec<usize> = (0..samples.len()).filter(|&s| open(s)).collect();
    if open.is_empty() {
        return Ok(open);
    }
    let sub: Vec<Sample> = open.iter().map(|&s| samples[s]).collect();
    let got = captured(scene, &sub, set, k, mode)?;
    Ok(open
        .into_iter()
        .zip(got)
        .filter_map(|(s, c)| c.then_some(s))
        .collect())
}

/// OR of `captured` over images `ks` of `set`, testing each sample only until captured.
fn captured_by_any(
    scene: &Scene,
    samples: &[Sample],
    set: &DepthImages,
    ks: impl IntoIterator<Item = usize>,
    mode: Redundancy,
) -> Result<Vec<bool>> {
    let mut hit = vec![false; samples.len()];
    for k in ks {
        if hit.iter().all(|&h| h) {
            break;
        }
        for s in newly_captured(scene, samples, |s| !hit[s], set, k, mode)? {
            hit[s] = true;
        }
    }
    Ok(hit)
}

fn fraction(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// Evaluate `images` (made by `images.method` for the `reference` viewpoints) against frames
/// rendered from `frames` (the intermediate views). The conventional reference images and the
/// frames cull back faces when the images did.
pub fn sampling_metrics(
    scene: &Scene,
    images: &DepthImages,
    reference: &[Camera],
    frames: &[Camera],
    mode: Redundancy,
    cull_backfaces: bool,
) -> Result<SamplingMetrics> {
    let total = Instant::now();
    let n = images.n;
    check_sets(images, reference)?;
    let mut out = SamplingMetrics {
        frames: frames.len(),
        ..Default::default()
    };
    let start = Instant::now();
    let conventional = discretize_conventional(scene, reference, cull_backfaces)?;
    out.timings
        .add("conventional", start.elapsed().as_secs_f64());

    // View-independent metrics 1 and 2.
    let start = Instant::now();
    let samples: Vec<Vec<Sample>> = (0..n).map(|i| samples_of(images, i)).collect();
    let mut disoccluded: Vec<Vec<Sample>> = Vec::with_capacity(n);
    let mut disoccluded_px: Vec<Vec<usize>> = Vec::with_capacity(n);
    for (i, s) in samples.iter().enumerate() {
        out.samples.push(s.len() as u64);
        let red = captured_by_any(scene, s, images, 0..i, mode)?;
        out.redundant
            .push(fraction(red.iter().filter(|&&r| r).count(), s.len()));
        let held = match images.method.as_str() {
            "conventional" => vec![true; s.len()],
            "nonredundant" => captured_by_any(scene, s, &conventional, [i], mode)?,
            _ => captured_by_any(scene, s, &conventional, 0..reference.len(), mode)?,
        };
        let dis: Vec<Sample> = s
            .iter()
            .zip(&held)
            .filter(|(_, &h)| !h)
            .map(|(s, _)| *s)
            .collect();
        out.disoccluded.push(fraction(dis.len(), s.len()));
        disoccluded.push(dis);
        let px = sample_pixels(images, i);
        disoccluded_px.push(
            px.iter()
                .zip(&held)
                .filter(|(_, &h)| !h)
                .map(|(&p, _)| p)
                .collect(),
        );
    }
    out.timings
        .add("view_independent", start.elapsed().as_secs_f64());

    // Metrics 3 and 4, frame by frame.
    let start = Instant::now();
    let (useful, available) =
        frame_metrics(scene, images, frames, &disoccluded, mode, cull_backfaces)?;
    let npx = images.width as usize * images.height as usize;
    out.disoccluded_mask = vec![false; n * npx];
    out.useful_mask = vec![false; n * npx];
    for i in 0..n {
        for (k, &p) in disoccluded_px[i].iter().enumerate() {
            out.disoccluded_mask[i * npx + p] = true;
            out.useful_mask[i * npx + p] = useful[i][k];
        }
        let u = useful[i].iter().filter(|&&u| u).count();
        out.useful.push(fraction(u, disoccluded[i].len()));
        let a = &available[i];
        out.available_avg.push(if a.is_empty() {
            f64::NAN
        } else {
            a.iter().sum::<f64>() / a.len() as f64
        });
        out.available_min
            .push(a.iter().copied().fold(f64::NAN, f64::min));
    }
    out.timings.add("frames", start.elapsed().as_secs_f64());
    out.timings.add("total", total.elapsed().as_secs_f64());
    Ok(out)
}

/// Refuses a set without its reference cameras, a one-image-per-camera set whose counts
/// differ, and a method the metrics do not know.
fn check_sets(images: &DepthImages, reference: &[Camera]) -> Result<()> {
    let n = images.n;
    if reference.is_empty() {
        return input_err!(
            "the sampling metrics need the reference cameras the images were made for"
        );
    }
    if images.method == "nonredundant" || images.method == "conventional" {
        if reference.len() != n {
            return input_err!(
                "{} images but {} reference cameras; a {} set has one image per reference camera",
                n,
                reference.len(),
                images.method
            );
        }
    } else if images.method != "peeling" {
        return input_err!(
            "unknown method {:?}: expected 'conventional', 'nonredundant' or 'peeling'",
            images.method
        );
    }
    Ok(())
}

/// Per image: which disoccluded samples some frame sees, and each frame's fraction of them.
type FrameMetrics = (Vec<Vec<bool>>, Vec<Vec<f64>>);

/// Metrics 3 and 4 (§6.1.2): renders the frames and, per image, marks the disoccluded samples
/// some frame sees (`useful`) and records each frame's fraction of them (`available`).
fn frame_metrics(
    scene: &Scene,
    images: &DepthImages,
    frames: &[Camera],
    disoccluded: &[Vec<Sample>],
    mode: Redundancy,
    cull_backfaces: bool,
) -> Result<FrameMetrics> {
    let n = images.n;
    let mut useful: Vec<Vec<bool>> = disoccluded.iter().map(|d| vec![false; d.len()]).collect();
    let mut available: Vec<Vec<f64>> = vec![Vec::with_capacity(frames.len()); n];
    if !frames.is_empty() {
        let ctx = gpu::context()?;
        let mut failure = None;
        gpu::depth::rasterize(&ctx, scene, frames, cull_backfaces, None, |first, ids| {
            if failure.is_some() {
                return;
            }
            let npx = frames[0].width as usize * frames[0].height as usize;
            let cams = &frames[first..first + ids.len() / npx];
            let chunk = match resolve_ids(scene, cams, ids.to_vec()) {
                Ok((chunk, _)) => chunk,
                Err(e) => {
                    failure = Some(e);
                    return;
                }
            };
            for f in 0..cams.len() {
                let r = consume_frame(scene, images, &chunk, f, disoccluded, &mut useful, mode)
                    .map(|avail| {
                        for (k, a) in avail.into_iter().enumerate() {
                            available[k].push(a);
                        }
                    });
                if let Err(e) = r {
                    failure = Some(e);
                    return;
                }
            }
        })?;
        if let Some(e) = failure {
            return Err(e);
        }
    }
    Ok((useful, available))
}

/// One intermediate frame (image `f` of `chunk`): marks the disoccluded samples it needs as
/// useful and returns, per prefix 0..=k of the set, the fraction of its samples available.
fn consume_frame(
    scene: &Scene,
    images: &DepthImages,
    chunk: &DepthImages,
    f: usize,
    disoccluded: &[Vec<Sample>],
    useful: &mut [Vec<bool>],
    mode: Redundancy,
) -> Result<Vec<f64>> {
    for (dis, use_) in disoccluded.iter().zip(useful.iter_mut()) {
        for s in newly_captured(scene, dis, |s| !use_[s], chunk, f, mode)? {
            use_[s] = true;
        }
    }
    // Available: the first image of the set that captures each frame sample.
    let frame = samples_of(chunk, f);
    let mut first_holder = vec![usize::MAX; frame.len()];
    for k in 0..images.n {
        let open = |s: usize| first_holder[s] == usize::MAX;
        let got = newly_captured(scene, &frame, open, images, k, mode)?;
        for s in got {
            first_holder[s] = k;
        }
    }
    Ok((0..images.n)
        .map(|k| {
            let held = first_holder.iter().filter(|&&h| h <= k).count();
            if frame.is_empty() {
                1.0
            } else {
                fraction(held, frame.len())
            }
        })
        .collect())
}
