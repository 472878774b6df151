//! The compute pass of `shaders/splat.wgsl` (eye-based-point-rendering.txt §3.5): points
//! scattered into many off-screen views at once with 64-bit atomics. The host turns the
//! visibility bits into one point list per view; each view is one dispatch (or several: per
//! chunk of points, at most `MAX_GROUPS · 64` each) with its camera in a uniform at a dynamic
//! offset. The points' square geometry and the lists are textures, which lavapipe fetches for
//! all SIMD lanes at once (a storage buffer it reads lane by lane). Views go in chunks whose
//! buffers and lists fit the device's limits; each view chunk is one submission, read back
//! while the next one runs.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use bytemuck::{Pod, Zeroable};

use super::raster::{align, texture_2d, uniform_window};
use super::GpuContext;
use crate::camera::Camera;
use crate::error::{Error, Result};

const SHADER: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/splat.wgsl"));

/// Host copy of `View` in splat.wgsl: one per dispatch, at a dynamic offset.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    forward_depth: [f32; 4],
    near: [f32; 4],
    size: [u32; 4],
    range: [u32; 4],
}
const VIEW_SIZE: u64 = std::mem::size_of::<ViewUniform>() as u64;

/// Floats per point in the `geometry` texture (four RGBA32F texels).
pub const GEOMETRY_FLOATS: usize = 16;
const GEOMETRY_BYTES: u64 = GEOMETRY_FLOATS as u64 * 4;
/// Texels per row of the `geometry` and `list` textures: `1 << ROW_SHIFT` in splat.wgsl.
const TEXTURE_ROW: u32 = 4096;

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
        let texture = |binding, sample_type| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let entries = [
            entry(0, wgpu::BufferBindingType::Uniform),
            texture(1, wgpu::TextureSampleType::Float { filterable: false }),
            texture(2, wgpu::TextureSampleType::Uint),
            entry(3, wgpu::BufferBindingType::Storage { read_only: false }),
        ];
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
    /// `GEOMETRY_FLOATS` per point, as the `geometry` binding of splat.wgsl describes them
    /// (positions relative to the scene centre).
    pub geometry: &'a [[f32; GEOMETRY_FLOATS]],
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

/// The device features and limits splatting needs: 64-bit atomics, and one view's buffer within
/// a storage binding. Returns the binding size and each view's buffer bytes.
fn check_limits(ctx: &GpuContext, cameras: &[Camera]) -> Result<(u64, Vec<u64>)> {
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
    Ok((binding, view_bytes))
}

/// The `n` points in chunks of at most one binding's worth of geometry bytes that each fit one
/// texture of `rows` rows.
fn point_chunks(n: usize, binding: u64, rows: u64) -> Vec<std::ops::Range<usize>> {
    let per_chunk = ((binding / GEOMETRY_BYTES).min(rows * TEXTURE_ROW as u64 / 4) as usize).max(1);
    (0..n.max(1))
        .step_by(per_chunk)
        .map(|s| s..(s + per_chunk).min(n))
        .collect()
}

/// One texture of the points' geometry per chunk of [`point_chunks`].
fn geometry_textures(
    ctx: &GpuContext,
    points: &PointBuffersIn,
    point_chunks: &[std::ops::Range<usize>],
) -> Result<Vec<wgpu::TextureView>> {
    point_chunks
        .iter()
        .map(|r| {
            row_texture(
                ctx,
                "splat geometry",
                wgpu::TextureFormat::Rgba32Float,
                4 * r.len(),
                |mut view| {
                    let bytes: &[u8] = bytemuck::cast_slice(&points.geometry[r.clone()]);
                    view.slice(..bytes.len()).copy_from_slice(bytes);
                },
            )
        })
        .collect::<Result<_>>()
}

/// Each camera's splat uniform. The clip range only shapes the projection's depth row, unused
/// here (a splat's depth comes from `forward_depth`).
fn view_uniforms(
    cameras: &[Camera],
    centre: DVec3,
    bounds: [[f32; 3]; 2],
    clip_to_triangle: bool,
) -> Vec<ViewUniform> {
    cameras
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
                size: [cam.width, cam.height, 0, clip_to_triangle as u32],
                range: [0; 4],
            }
        })
        .collect()
}

/// Chunks of consecutive views whose buffers (at most `binding` bytes together), and whose point
/// lists (at most `list_limit`), each fit one binding.
fn view_chunks(
    view_bytes: &[u64],
    counts: &[usize],
    binding: u64,
    list_limit: u64,
) -> Result<Vec<std::ops::Range<usize>>> {
    let mut chunks: Vec<std::ops::Range<usize>> = Vec::new();
    let mut start_view = 0;
    let (mut bytes, mut list_bytes) = (0, 0);
    for (i, (&b, &count)) in view_bytes.iter().zip(counts).enumerate() {
        let lb = count as u64 * 4;
        if lb > list_limit {
            return Err(Error::GpuLimit(format!(
                "view {i} alone receives {} points, whose list takes {lb} bytes, more than this \
                 device's limit of {list_limit} bytes; splat fewer points",
                count
            )));
        }
        if i > start_view && (bytes + b > binding || list_bytes + lb > list_limit) {
            chunks.push(start_view..i);
            start_view = i;
            (bytes, list_bytes) = (0, 0);
        }
        bytes += b;
        list_bytes += lb;
    }
    chunks.push(start_view..view_bytes.len());
    Ok(chunks)
}

/// Splat the points into one buffer per camera (each at its own resolution); returns the keys
/// (depth bits << 32 | point index, `u64::MAX` empty), view after view, row-major. `centre` is
/// the origin the points' geometry is given relative to.
pub fn splat(
    ctx: &GpuContext,
    points: &PointBuffersIn,
    cameras: &[Camera],
    centre: DVec3,
    bounds: [[f32; 3]; 2],
    clip_to_triangle: bool,
) -> Result<(Vec<u64>, SplatStats)> {
    crate::counters::add(crate::counters::Op::SplatPasses, 1);
    let (binding, view_bytes) = check_limits(ctx, cameras)?;
    let n = points.geometry.len();
    if n > u32::MAX as usize {
        return Err(Error::GpuLimit(format!(
            "{n} points: at most 2^32 - 1 fit the 32-bit point index of a splat key"
        )));
    }
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let mut stats = SplatStats::default();
    let start = Instant::now();
    if ctx.limits.max_texture_dimension_2d < TEXTURE_ROW {
        return Err(Error::GpuLimit(format!(
            "splatting reads points from {TEXTURE_ROW}-texel-wide textures; this device allows \
             {}",
            ctx.limits.max_texture_dimension_2d
        )));
    }
    let rows = ctx.limits.max_texture_dimension_2d as u64;
    let point_chunks = point_chunks(n, binding, rows);
    let geometry = geometry_textures(ctx, points, &point_chunks)?;
    let view_data = view_uniforms(cameras, centre, bounds, clip_to_triangle);
    stats.upload_seconds = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let lists = points_per_view(points, cameras, centre);
    stats.pairs_seconds = start.elapsed().as_secs_f64();

    // A chunk's lists go in one texture: at most a binding's worth of bytes, and its rows.
    let list_limit = binding.min(rows * TEXTURE_ROW as u64 * 4);
    let chunks = view_chunks(&view_bytes, &lists.counts, binding, list_limit)?;
    let total_pixels: u64 = view_bytes.iter().sum::<u64>() / 8;
    let mut out = vec![0u64; total_pixels as usize];
    let mut pending: Option<Pending> = None;
    let mut at_pixel = 0usize;
    let inputs = SplatInputs {
        cameras,
        view_data: &view_data,
        point_chunks: &point_chunks,
        geometry: &geometry,
        lists: &lists,
    };
    for range in chunks {
        // Ctrl-C between chunks of views (the previous chunk's readback is dropped).
        crate::process::check()?;
        let start = Instant::now();
        let next = submit_views(ctx, &inputs, range, at_pixel)?;
        stats.splat_seconds += start.elapsed().as_secs_f64();
        at_pixel += next.pixels;
        if let Some(done) = pending.replace(next) {
            finish(ctx, done, &mut out, &mut stats)?;
        }
    }
    if let Some(done) = pending {
        finish(ctx, done, &mut out, &mut stats)?;
    }
    Ok((out, stats))
}

/// What every chunk of views reads: the cameras, their uniforms, the point textures and the
/// per-view point lists.
struct SplatInputs<'a> {
    cameras: &'a [Camera],
    view_data: &'a [ViewUniform],
    point_chunks: &'a [std::ops::Range<usize>],
    geometry: &'a [wgpu::TextureView],
    lists: &'a PairLists,
}

/// The splat pass's key buffer of `bytes` (zeroed before each pass) and its readback.
fn key_buffers(device: &wgpu::Device, bytes: u64) -> (wgpu::Buffer, wgpu::Buffer) {
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
    (target, readback)
}

/// The splat pass's bindings for one geometry texture.
fn splat_bind(
    ctx: &GpuContext,
    uniforms: &wgpu::Buffer,
    geometry: &wgpu::TextureView,
    lists: &wgpu::TextureView,
    target: &wgpu::Buffer,
) -> wgpu::BindGroup {
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("splat.wgsl bindings"),
        layout: &ctx.splat_pipeline().layout,
        entries: &[
            uniform_window(0, uniforms, VIEW_SIZE),
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(geometry),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::TextureView(lists),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: target.as_entire_binding(),
            },
        ],
    })
}

/// Encodes and submits one chunk of views (§4.1's splat pass over the points each view lists),
/// and starts the readback of its key buffers; `at` is the chunk's first pixel in the output.
fn submit_views(
    ctx: &GpuContext,
    inputs: &SplatInputs,
    range: std::ops::Range<usize>,
    at: usize,
) -> Result<Pending> {
    use wgpu::util::DeviceExt;
    let device = &ctx.device;
    let SplatInputs {
        cameras,
        view_data,
        point_chunks,
        geometry,
        lists,
    } = inputs;
    let stride = align(
        VIEW_SIZE,
        ctx.limits.min_uniform_buffer_offset_alignment as u64,
    );
    let per_dispatch = (MAX_GROUPS * GROUP) as usize;
    let (dispatches, offset, first) = dispatches(
        range.clone(),
        cameras,
        view_data,
        point_chunks,
        lists,
        per_dispatch,
    );
    let mut uniforms = vec![0u8; stride as usize * dispatches.len().max(1)];
    for (d, (_, u)) in dispatches.iter().enumerate() {
        let at = d * stride as usize;
        uniforms[at..at + VIEW_SIZE as usize].copy_from_slice(bytemuck::bytes_of(u));
    }
    let list_view = row_texture(
        ctx,
        "splat lists",
        wgpu::TextureFormat::R32Uint,
        first,
        |mut view| {
            let mut at = 0;
            for part in range.clone().flat_map(|v| lists.view(v)) {
                let bytes: &[u8] = bytemuck::cast_slice(part);
                view.slice(at..at + bytes.len()).copy_from_slice(bytes);
                at += bytes.len();
            }
        },
    )?;
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("splat views"),
        contents: &uniforms,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let bytes = offset as u64 * 8;
    let (target, readback) = key_buffers(device, bytes);
    let binds: Vec<wgpu::BindGroup> = geometry
        .iter()
        .map(|g| splat_bind(ctx, &uniform_buf, g, &list_view, &target))
        .collect();
    let mut encoder = device.create_command_encoder(&Default::default());
    // Zero is "empty": the shader stores complemented keys with atomicMax.
    encoder.clear_buffer(&target, 0, None);
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&ctx.splat_pipeline().pipeline);
        for (d, (k, u)) in dispatches.iter().enumerate() {
            pass.set_bind_group(0, &binds[*k], &[(d as u64 * stride) as u32]);
            pass.dispatch_workgroups(u.range[0].div_ceil(GROUP), 1, 1);
        }
    }
    encoder.copy_buffer_to_buffer(&target, 0, &readback, 0, bytes);
    let submission = ctx.queue.submit([encoder.finish()]);
    readback.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    Ok(Pending {
        at,
        pixels: offset as usize,
        readback,
        submission,
    })
}

/// A 2D texture of `format` with `texels` texels, `TEXTURE_ROW` per row (at least one row),
/// whose bytes `fill` writes into a mapped staging buffer (the shader never reads past
/// `texels`); uploaded by its own submission, which the queue runs before any later one. The
/// caller has checked that the rows fit.
fn row_texture(
    ctx: &GpuContext,
    label: &str,
    format: wgpu::TextureFormat,
    texels: usize,
    fill: impl FnOnce(wgpu::BufferViewMut),
) -> Result<wgpu::TextureView> {
    let device = &ctx.device;
    let row = TEXTURE_ROW * format.block_copy_size(None).unwrap_or(4);
    let rows = texels.div_ceil(TEXTURE_ROW as usize).max(1) as u32;
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: row as u64 * rows as u64,
        usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: true,
    });
    let view = staging
        .slice(..)
        .get_mapped_range_mut()
        .map_err(|e| Error::Gpu(format!("mapping the {label} staging buffer failed: {e}")))?;
    fill(view);
    staging.unmap();
    let size = wgpu::Extent3d {
        width: TEXTURE_ROW,
        height: rows,
        depth_or_array_layers: 1,
    };
    let texture = texture_2d(
        device,
        label,
        (TEXTURE_ROW, rows),
        format,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_texture(
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(rows),
            },
        },
        texture.as_image_copy(),
        size,
    );
    ctx.queue.submit([encoder.finish()]);
    Ok(texture.create_view(&Default::default()))
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
/// no pixel, so the output is the same and the GPU does only pairs that matter. A view's list is
/// the concatenation of its parts in `blocks` (consecutive blocks of points), so in point order.
struct PairLists {
    /// Per block of points, per view, the block's points for the view.
    blocks: Vec<Vec<Vec<u32>>>,
    /// Per view, the length of its list.
    counts: Vec<usize>,
}

impl PairLists {
    fn view(&self, v: usize) -> impl Iterator<Item = &[u32]> + '_ {
        self.blocks.iter().map(move |b| b[v].as_slice())
    }

    /// How many entries of view `v`'s list are below point `end`.
    fn below(&self, v: usize, end: usize) -> usize {
        self.view(v)
            .map(|part| part.partition_point(|&p| (p as usize) < end))
            .sum()
    }
}

/// The dispatches of the views in `range`: their lists one after another, and one dispatch per
/// (view, point chunk, run of at most `per_dispatch` points), as (point chunk, uniform). Also
/// the chunk's pixels and list length.
fn dispatches(
    range: std::ops::Range<usize>,
    cameras: &[Camera],
    view_data: &[ViewUniform],
    point_chunks: &[std::ops::Range<usize>],
    lists: &PairLists,
    per_dispatch: usize,
) -> (Vec<(usize, ViewUniform)>, u32, usize) {
    let mut out: Vec<(usize, ViewUniform)> = Vec::new();
    let mut offset = 0u32;
    let mut first = 0;
    for v in range {
        // The list is in point order: each point chunk is one run of it.
        let mut from = 0;
        for (k, r) in point_chunks.iter().enumerate() {
            let to = lists.below(v, r.end);
            for s in (from..to).step_by(per_dispatch) {
                let count = (to - s).min(per_dispatch);
                let mut u = view_data[v];
                u.size[2] = offset;
                u.range = [count as u32, (first + s) as u32, r.start as u32, 0];
                out.push((k, u));
            }
            from = to;
        }
        first += lists.counts[v];
        offset += cameras[v].width * cameras[v].height;
    }
    (out, offset, first)
}

fn points_per_view(points: &PointBuffersIn, cameras: &[Camera], centre: DVec3) -> PairLists {
    // Blocks of points in parallel, each walking its points' set bits twice: to size its lists
    // (the bits bound them), then to fill them.
    const BLOCK: usize = 1 << 15;
    let words = points.words;
    let n = points.geometry.len();
    let planes: Vec<Vec<(DVec3, f64)>> = cameras
        .iter()
        .map(|cam| cam.frustum_planes(1.0, cam.znear.unwrap_or(0.0), centre))
        .collect();
    let views = cameras.len();
    let bits_of = |p: usize| &points.bits[p * words..(p + 1) * words];
    let blocks: Vec<Vec<Vec<u32>>> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let block = b * BLOCK..((b + 1) * BLOCK).min(n);
            let mut bound = vec![0usize; cameras.len()];
            for p in block.clone() {
                for_each_view(bits_of(p), views, |v| bound[v] += 1);
            }
            let mut lists: Vec<Vec<u32>> = bound.iter().map(|&c| Vec::with_capacity(c)).collect();
            for p in block {
                let g = &points.geometry[p];
                let at = DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64);
                // The square's circumradius: half its diagonal.
                let r = g[3] as f64 * std::f64::consts::SQRT_2;
                for_each_view(bits_of(p), views, |v| {
                    if planes[v].iter().all(|&(nrm, d)| nrm.dot(at) + d >= -r) {
                        lists[v].push(p as u32);
                    }
                });
            }
            lists
        })
        .collect();
    let counts = (0..cameras.len())
        .map(|v| blocks.iter().map(|b| b[v].len()).sum())
        .collect();
    PairLists { blocks, counts }
}

/// Call `each` with every view below `views` whose bit is set in `bits`, in increasing order.
fn for_each_view(bits: &[u64], views: usize, mut each: impl FnMut(usize)) {
    for (w, &word) in bits.iter().enumerate() {
        let mut rest = word;
        while rest != 0 {
            let v = w * 64 + rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if v >= views {
                return;
            }
            each(v);
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shader_and_host_agree_on_the_texture_row() {
        assert!(TEXTURE_ROW.is_power_of_two());
        let line = format!("const ROW_SHIFT: u32 = {}u;", TEXTURE_ROW.trailing_zeros());
        assert!(SHADER.contains(&line), "splat.wgsl lacks `{line}`");
        assert_eq!(
            std::mem::size_of::<[f32; GEOMETRY_FLOATS]>(),
            4 * wgpu::TextureFormat::Rgba32Float
                .block_copy_size(None)
                .unwrap_or(0) as usize
        );
    }

    #[test]
    fn each_set_bit_below_the_view_count_is_visited_in_order() {
        let mut seen = Vec::new();
        for_each_view(&[0b1010_0001, 1 << 63, 0b11], 129, |v| seen.push(v));
        assert_eq!(seen, vec![0, 5, 7, 127, 128]);
    }
}
