//! The compute pass of `shaders/splat.wgsl` (eye-based-point-rendering.txt §3.5): points
//! scattered into many off-screen views at once with 64-bit atomics. Views go in chunks whose
//! buffers fit the device's storage-binding limit, points in dispatches of at most
//! `MAX_GROUPS · 64`; each view chunk is one submission, read back while the next one runs.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use bytemuck::{Pod, Zeroable};

use super::raster::align;
use super::{GpuContext, SceneBuffers};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::scene::Scene;

const SHADER: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/splat.wgsl"));

/// Host copy of `Params` in splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Params {
    count: u32,
    first: u32,
    clip: u32,
    _pad: u32,
}
const PARAMS_SIZE: u64 = std::mem::size_of::<Params>() as u64;

/// Host copy of `View` in splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    forward_depth: [f32; 4],
    near: [f32; 4],
    size_offset: [u32; 4],
}

/// Workgroups per dispatch dimension (wgpu's default limit) and threads per workgroup.
const MAX_GROUPS: u32 = 65535;
const GROUP: u32 = 64;

pub struct SplatPipeline {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl SplatPipeline {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("splat.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: binding == 0,
                min_binding_size: None,
            },
            count: None,
        };
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let mut entries = vec![entry(0, wgpu::BufferBindingType::Uniform)];
        entries.extend((1..7).map(|b| entry(b, read)));
        entries.push(entry(
            7,
            wgpu::BufferBindingType::Storage { read_only: false },
        ));
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat.wgsl bindings"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat.wgsl layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("cs_splat"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("cs_splat"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }
}

/// The points to splat, in the layout splat.wgsl reads.
pub struct PointBuffersIn<'a> {
    /// Centres relative to the scene centre (xyz) and side length (w).
    pub centers: &'a [[f32; 4]],
    /// Triangle index per point.
    pub triangles: &'a [u32],
    /// `words` visibility words per point.
    pub bits: &'a [u64],
    pub words: usize,
}

/// Wall-clock seconds of the steps of one `splat` call.
#[derive(Debug, Default, Clone)]
pub struct SplatStats {
    /// Host time turning the bit strings into per-view point lists.
    pub pairs_seconds: f64,
    pub upload_seconds: f64,
    pub splat_seconds: f64,
    pub readback_seconds: f64,
}

/// Splat the points into one buffer per camera (each at its own resolution); returns the keys
/// (depth bits << 32 | point index, `u64::MAX` empty), view after view, row-major.
pub fn splat(
    ctx: &GpuContext,
    scene: &Scene,
    points: &PointBuffersIn,
    cameras: &[Camera],
    clip_to_triangle: bool,
) -> Result<(Vec<u64>, SplatStats)> {
    crate::counters::add(&crate::counters::SPLAT_PASSES, 1);
    let needed = wgpu::Features::SHADER_INT64 | wgpu::Features::SHADER_INT64_ATOMIC_MIN_MAX;
    if !ctx.device.features().contains(needed) {
        return Err(Error::GpuUnavailable(format!(
            "splatting needs 64-bit atomics (SHADER_INT64 and SHADER_INT64_ATOMIC_MIN_MAX), \
             which the adapter '{}' lacks",
            ctx.info.name
        )));
    }
    let binding = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    let view_bytes: Vec<u64> = cameras
        .iter()
        .map(|c| c.width as u64 * c.height as u64 * 8)
        .collect();
    if let Some((i, b)) = view_bytes.iter().enumerate().find(|(_, &b)| b > binding) {
        let c = &cameras[i];
        return Err(Error::GpuLimit(format!(
            "one {}x{} splat buffer takes {b} bytes, more than this device's storage limit of \
             {binding} bytes; use smaller views",
            c.width, c.height
        )));
    }
    let n = points.triangles.len();
    // The visibility strings stay on the host (they become the pair lists); the centres and
    // triangles go up whole.
    if n as u64 * 16 > binding {
        return Err(Error::GpuLimit(format!(
            "{n} points' centres take {} bytes, more than this device's storage limit of \
             {binding} bytes; splat fewer points per call",
            n as u64 * 16
        )));
    }
    if n > u32::MAX as usize {
        return Err(Error::GpuLimit(format!(
            "{n} points: at most 2^32 - 1 fit the 32-bit point index of a splat key"
        )));
    }
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let device = &ctx.device;
    let mut stats = SplatStats::default();

    use wgpu::util::DeviceExt;
    let start = Instant::now();
    let buffers = SceneBuffers::of(ctx, scene)?;
    let centre = scene.center();
    // wgpu rejects empty bindings: pad each array to at least one element.
    let storage = |label, bytes: &[u8]| {
        let mut v = bytes.to_vec();
        if v.len() < 16 {
            v.resize(16, 0);
        }
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &v,
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    let centers = storage("splat centres", bytemuck::cast_slice(points.centers));
    let triangles = storage("splat triangles", bytemuck::cast_slice(points.triangles));
    // The clip range only shapes the projection's depth row, unused here (a splat's depth comes
    // from `forward_depth`).
    let bounds = scene.bounds();
    let view_data: Vec<ViewUniform> = cameras
        .iter()
        .map(|cam| {
            let (near, far) = cam.clip_range(bounds);
            let m = cam.projection_matrix(near, far) * cam.view_matrix_relative(centre);
            let f = cam.forward();
            let eye = cam.eye() - centre;
            ViewUniform {
                view_proj: m.as_mat4().to_cols_array_2d(),
                forward_depth: [f.x as f32, f.y as f32, f.z as f32, eye.dot(f) as f32],
                near: [cam.znear.unwrap_or(0.0) as f32, 0.0, 0.0, 0.0],
                size_offset: [0; 4],
            }
        })
        .collect();
    stats.upload_seconds = start.elapsed().as_secs_f64();

    // Chunks of consecutive views whose buffers, and whose (point, view) pairs, each fit one
    // binding together.
    let start = Instant::now();
    let lists = points_per_view(points, cameras, centre);
    stats.pairs_seconds = start.elapsed().as_secs_f64();
    let pair_counts: Vec<usize> = lists.iter().map(Vec::len).collect();
    let mut chunks: Vec<std::ops::Range<usize>> = Vec::new();
    let mut start_view = 0;
    let (mut bytes, mut pair_bytes) = (0, 0);
    for (i, (&b, &c)) in view_bytes.iter().zip(&pair_counts).enumerate() {
        let pb = c as u64 * 8;
        if pb > binding {
            return Err(Error::GpuLimit(format!(
                "view {i} alone receives {c} points, whose (point, view) pairs take {pb} bytes, \
                 more than this device's storage limit of {binding} bytes; splat fewer points"
            )));
        }
        let full = bytes + b > binding || pair_bytes + pb > binding;
        if i > start_view && (full || i - start_view == MAX_GROUPS as usize) {
            chunks.push(start_view..i);
            start_view = i;
            (bytes, pair_bytes) = (0, 0);
        }
        bytes += b;
        pair_bytes += pb;
    }
    chunks.push(start_view..cameras.len());
    let param_stride = align(
        PARAMS_SIZE,
        ctx.limits.min_uniform_buffer_offset_alignment as u64,
    );
    let total_pixels: u64 = view_bytes.iter().sum::<u64>() / 8;
    let mut out = vec![0u64; total_pixels as usize];
    let mut pending: Option<Pending> = None;
    let mut at_pixel = 0usize;
    for range in chunks {
        let start = Instant::now();
        let mut cams = view_data[range.clone()].to_vec();
        let mut offset = 0u32;
        for (v, cam) in cams.iter_mut().zip(&cameras[range.clone()]) {
            v.size_offset = [cam.width, cam.height, offset, 0];
            offset += cam.width * cam.height;
        }
        // The chunk's (point, view) pairs, grouped by view.
        let pairs: Vec<[u32; 2]> = lists[range.clone()]
            .iter()
            .enumerate()
            .flat_map(|(v, ps)| ps.iter().map(move |&p| [p, v as u32]))
            .collect();
        let per_dispatch = (MAX_GROUPS * GROUP) as usize;
        let dispatches = pairs.len().div_ceil(per_dispatch).max(1);
        let mut params = vec![0u8; param_stride as usize * dispatches];
        for d in 0..dispatches {
            let first = d * per_dispatch;
            let p = Params {
                count: (pairs.len() - first.min(pairs.len())).min(per_dispatch) as u32,
                first: first as u32,
                clip: clip_to_triangle as u32,
                _pad: 0,
            };
            let at = d * param_stride as usize;
            params[at..at + PARAMS_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&p));
        }
        let pairs_buf = storage("splat pairs", bytemuck::cast_slice(&pairs));
        let params_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("splat params"),
            contents: &params,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let views_buf = storage("splat views", bytemuck::cast_slice(&cams));
        let bytes = offset as u64 * 8;
        let target = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat buffers"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat.wgsl bindings"),
            layout: &ctx.splat_pipeline().layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &params_buf,
                        offset: 0,
                        size: wgpu::BufferSize::new(PARAMS_SIZE),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: views_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: centers.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: triangles.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: pairs_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: buffers.positions.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: buffers.faces.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: target.as_entire_binding(),
                },
            ],
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        // Zero is "empty": the shader stores complemented keys with atomicMax.
        encoder.clear_buffer(&target, 0, None);
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&ctx.splat_pipeline().pipeline);
            for d in 0..dispatches {
                let first = d * per_dispatch;
                let count = (pairs.len() - first.min(pairs.len())).min(per_dispatch) as u32;
                if count == 0 {
                    continue;
                }
                pass.set_bind_group(0, &bind, &[(d as u64 * param_stride) as u32]);
                pass.dispatch_workgroups(count.div_ceil(GROUP), 1, 1);
            }
        }
        encoder.copy_buffer_to_buffer(&target, 0, &readback, 0, bytes);
        let submission = ctx.queue.submit([encoder.finish()]);
        readback.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        stats.splat_seconds += start.elapsed().as_secs_f64();
        let next = Pending {
            at: at_pixel,
            pixels: offset as usize,
            readback,
            submission,
        };
        at_pixel += offset as usize;
        if let Some(done) = pending.replace(next) {
            finish(ctx, done, &mut out, &mut stats)?;
        }
    }
    if let Some(done) = pending {
        finish(ctx, done, &mut out, &mut stats)?;
    }
    Ok((out, stats))
}

/// A submitted chunk of views whose readback is not yet consumed.
struct Pending {
    /// Its first pixel in the output, and its pixel count.
    at: usize,
    pixels: usize,
    readback: wgpu::Buffer,
    submission: wgpu::SubmissionIndex,
}

/// For each view, the points to splat into it: those whose bit for the view is set and whose
/// square (its circumscribed sphere) reaches into the view's frustum. The bits are the paper's
/// conservative per-triangle test (§3.1); this per-point test drops the pairs that would write
/// no pixel, so the output is the same and the GPU does only pairs that matter.
fn points_per_view(points: &PointBuffersIn, cameras: &[Camera], centre: DVec3) -> Vec<Vec<u32>> {
    let words = points.words;
    let n = points.triangles.len();
    cameras
        .par_iter()
        .enumerate()
        .map(|(v, cam)| {
            let planes = cam.frustum_planes(1.0, cam.znear.unwrap_or(0.0), centre);
            let (w, bit) = (v / 64, 1u64 << (v % 64));
            (0..n)
                .filter(|&p| {
                    if points.bits[p * words + w] & bit == 0 {
                        return false;
                    }
                    let c = points.centers[p];
                    let at = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                    let r = c[3] as f64 * std::f64::consts::FRAC_1_SQRT_2;
                    planes.iter().all(|&(nrm, d)| nrm.dot(at) + d >= -r)
                })
                .map(|p| p as u32)
                .collect()
        })
        .collect()
}

/// Wait for one chunk of views and copy its keys, un-complemented, into `out`.
fn finish(ctx: &GpuContext, p: Pending, out: &mut [u64], stats: &mut SplatStats) -> Result<()> {
    let Pending {
        at,
        pixels,
        readback,
        submission,
    } = p;
    let start = Instant::now();
    super::raster::wait(ctx, submission)?;
    stats.splat_seconds += start.elapsed().as_secs_f64();
    let start = Instant::now();
    {
        let data = readback
            .slice(..)
            .get_mapped_range()
            .map_err(|e| Error::Gpu(format!("mapping the splat readback failed: {e}")))?;
        let keys: &[u64] = bytemuck::cast_slice(&data);
        let dst = &mut out[at..at + pixels];
        for (d, k) in dst.iter_mut().zip(keys) {
            *d = !*k;
        }
    }
    readback.unmap();
    stats.readback_seconds += start.elapsed().as_secs_f64();
    Ok(())
}
