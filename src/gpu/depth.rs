//! Raster pass of `shaders/depth.wgsl`: per camera, the nearest triangle's id at every pixel
//! centre (no multisampling).

use std::time::Instant;

use bytemuck::{Pod, Zeroable};

use super::raster::{
    align, check_image_size, copy, draw_ids, id_pipeline, id_pipeline_with, submit_readback,
    texture_2d, uniform_window, wait, IdPass, Timestamps, DEPTH_FORMAT, TRI_FORMAT,
};
use super::{GpuContext, SceneBuffers};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::scene::Scene;

const SHADER: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/depth.wgsl"));
/// Upper bound on readback memory held at once; larger requests are split into chunks.
const READBACK_BUDGET: u64 = 256 << 20;

/// Host copy of `View` in depth.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
}
const _: () = assert!(std::mem::size_of::<ViewUniform>() == 64);

pub struct DepthPipeline {
    layout: wgpu::BindGroupLayout,
    /// Index 0: no culling; 1: back faces (counter-clockwise front) culled.
    pipelines: [wgpu::RenderPipeline; 2],
    /// The same for drawing face ranges (`vs_ranged` / `fs_ranged`).
    ranged: [wgpu::RenderPipeline; 2],
}

impl DepthPipeline {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth.wgsl bindings"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    // One camera per dynamic offset into a shared uniform buffer.
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(64),
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("depth.wgsl layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let make = |cull| id_pipeline(device, &module, &pipeline_layout, "fs_main", cull, &[]);
        let ranged = |cull| {
            let l = &pipeline_layout;
            id_pipeline_with(device, &module, l, "vs_ranged", "fs_ranged", cull, &[])
        };
        Self {
            layout,
            pipelines: [make(None), make(Some(wgpu::Face::Back))],
            ranged: [ranged(None), ranged(Some(wgpu::Face::Back))],
        }
    }
}

/// What rasterising cost. The ids themselves go to the caller's `on_chunk` as they arrive.
#[derive(Debug, Default)]
pub struct RasterStats {
    /// Scene upload time (0 when the buffers were cached).
    pub upload_seconds: f64,
    /// CPU time spent encoding, submitting and waiting for the raster passes.
    pub raster_seconds: f64,
    /// GPU time of the raster passes from timestamp queries, when the adapter has them.
    pub gpu_seconds: Option<f64>,
    pub readback_seconds: f64,
    /// Time inside the caller's `on_chunk` (it overlaps the GPU's work on the next chunk).
    pub consumer_seconds: f64,
}

/// Images per submission: about a million pixels each, so that the caller's processing of one
/// chunk overlaps the GPU's work on the next, and never more than the readback budget.
const PIXELS_PER_CHUNK: u64 = 1 << 20;

/// Rasterise `scene` from every camera (all of one resolution). Images are rendered in chunks;
/// `on_chunk(first, ids)` receives the triangle ids of images `first..first + k` (row-major,
/// −1 where empty) while the GPU already renders the next chunk. With `ranges`, only the
/// triangles in those ranges `[a, b)` are drawn (ids stay the scene's).
pub fn rasterize(
    ctx: &GpuContext,
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
    ranges: Option<&[(u32, u32)]>,
    mut on_chunk: impl FnMut(usize, &[i32]),
) -> Result<RasterStats> {
    let (w, h) = (cameras[0].width, cameras[0].height);
    check_image_size(ctx, w, h)?;
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let cached = SceneBuffers::cached(ctx, scene);
    let buffers = SceneBuffers::of(ctx, scene)?;

    let row_tri = align(w as u64 * 4, wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64);
    let per_image = row_tri * h as u64;
    let max_buffer = ctx.limits.max_buffer_size;
    if per_image > max_buffer {
        return Err(Error::GpuLimit(format!(
            "one {w}x{h} image needs a {per_image} byte readback buffer, more than this \
             device's limit of {max_buffer} bytes"
        )));
    }
    let by_budget = READBACK_BUDGET.min(max_buffer) / per_image;
    let by_pixels = PIXELS_PER_CHUNK / (w as u64 * h as u64);
    let chunk = (by_budget.min(by_pixels).max(1) as usize).min(cameras.len());

    let mut stats = RasterStats {
        upload_seconds: if cached { 0.0 } else { buffers.upload_seconds },
        gpu_seconds: ctx.timestamps.then_some(0.0),
        ..Default::default()
    };
    let targets = Targets::new(&ctx.device, w, h);
    let pipeline = ctx.depth_pipeline();
    let mut in_flight: Option<Pending> = None;
    for (c, cams) in cameras.chunks(chunk).enumerate() {
        let start = Instant::now();
        let next = submit_chunk(
            ctx,
            scene,
            &buffers,
            pipeline,
            &targets,
            cams,
            cull_backfaces,
            ranges,
            row_tri,
            c * chunk,
        );
        stats.raster_seconds += start.elapsed().as_secs_f64();
        // Finish the previous chunk while the GPU works on this one.
        if let Some(done) = in_flight.replace(next) {
            finish_chunk(ctx, done, &mut stats, &mut on_chunk)?;
        }
    }
    if let Some(done) = in_flight {
        finish_chunk(ctx, done, &mut stats, &mut on_chunk)?;
    }
    Ok(stats)
}

/// A submitted chunk whose readback is not yet consumed: images `first..first + n` of w×h ids,
/// rows `row_tri` bytes apart in `readback`.
pub(super) struct Pending {
    pub readback: wgpu::Buffer,
    pub queries: Option<Timestamps>,
    pub submission: wgpu::SubmissionIndex,
    pub first: usize,
    pub n: usize,
    pub w: u32,
    pub h: u32,
    pub row_tri: u64,
}

struct Targets {
    tri: wgpu::Texture,
    tri_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    w: u32,
    h: u32,
}

impl Targets {
    fn new(device: &wgpu::Device, w: u32, h: u32) -> Self {
        let tex = |label, format, usage| texture_2d(device, label, (w, h), format, usage);
        let color = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let tri = tex("triangle ids", TRI_FORMAT, color);
        let depth = tex(
            "depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        Self {
            tri_view: tri.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            tri,
            w,
            h,
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn submit_chunk(
    ctx: &GpuContext,
    scene: &Scene,
    buffers: &SceneBuffers,
    pipeline: &DepthPipeline,
    targets: &Targets,
    cameras: &[Camera],
    cull_backfaces: bool,
    ranges: Option<&[(u32, u32)]>,
    row_tri: u64,
    first: usize,
) -> Pending {
    use wgpu::util::DeviceExt;
    let device = &ctx.device;
    let (w, h) = (targets.w, targets.h);
    let n = cameras.len() as u64;
    let stride = align(64, ctx.limits.min_uniform_buffer_offset_alignment as u64);
    let centre = scene.center();
    let bounds = scene.bounds();
    let mut uniforms = vec![0u8; (stride * n) as usize];
    for (i, cam) in cameras.iter().enumerate() {
        let (near, far) = cam.clip_range(bounds);
        let m = cam.projection_matrix(near, far) * cam.view_matrix_relative(centre);
        let u = ViewUniform {
            view_proj: m.as_mat4().to_cols_array_2d(),
        };
        let at = i * stride as usize;
        uniforms[at..at + 64].copy_from_slice(bytemuck::bytes_of(&u));
    }
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("view uniforms"),
        contents: &uniforms,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("depth.wgsl bindings"),
        layout: &pipeline.layout,
        entries: &[uniform_window(0, &uniform_buf, 64)],
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: row_tri * h as u64 * n,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let queries = Timestamps::new(ctx, n as u32);

    let mut encoder = device.create_command_encoder(&Default::default());
    let image_bytes = row_tri * h as u64;
    for i in 0..n {
        let pass = IdPass {
            faces: None,
            ranges,
            tri_view: &targets.tri_view,
            depth_view: &targets.depth_view,
            store_depth: false,
            pipeline: if ranges.is_some() {
                &pipeline.ranged[cull_backfaces as usize]
            } else {
                &pipeline.pipelines[cull_backfaces as usize]
            },
            bind: &bind,
            offsets: &[(i * stride) as u32],
        };
        draw_ids(&mut encoder, buffers, &pass, queries.as_ref(), i as u32);
        let base = i * image_bytes;
        copy(&mut encoder, &targets.tri, &readback, base, row_tri, w, h);
    }
    let submission = submit_readback(ctx, encoder, &readback, queries.as_ref());
    Pending {
        readback,
        queries,
        submission,
        first,
        n: n as usize,
        w,
        h,
        row_tri,
    }
}

/// Wait for a chunk, hand its ids to `on_chunk`, and add its GPU time.
pub(super) fn finish_chunk(
    ctx: &GpuContext,
    p: Pending,
    stats: &mut RasterStats,
    on_chunk: &mut impl FnMut(usize, &[i32]),
) -> Result<()> {
    let start = Instant::now();
    wait(ctx, p.submission)?;
    stats.raster_seconds += start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (w, h) = (p.w as usize, p.h as usize);
    let mut ids = vec![0i32; p.n * w * h];
    {
        let data = p
            .readback
            .slice(..)
            .get_mapped_range()
            .map_err(|e| Error::Gpu(format!("mapping the readback buffer failed: {e}")))?;
        for (row, dst) in ids.chunks_exact_mut(w).enumerate() {
            let src = &data[row * p.row_tri as usize..][..w * 4];
            dst.copy_from_slice(bytemuck::cast_slice(src));
        }
    }
    p.readback.unmap();
    if let Some(q) = &p.queries {
        let gpu = q.seconds(ctx)?;
        if let Some(total) = stats.gpu_seconds.as_mut() {
            *total += gpu;
        }
    }
    stats.readback_seconds += start.elapsed().as_secs_f64();
    let start = Instant::now();
    on_chunk(p.first, &ids);
    stats.consumer_seconds += start.elapsed().as_secs_f64();
    Ok(())
}
