//! Raster passes of `shaders/layered.wgsl`: images rendered one after another, each pass testing
//! its fragments against the images before it — non-redundant rendering with pixel redundancy
//! (non-redundant-rendering.txt Algorithm 1 with Algorithm 3) or depth peeling. Each pass is its
//! own submission: after it, its triangle ids are copied into a storage buffer that the later
//! passes read and into a readback buffer that the caller consumes while the GPU renders the next
//! image. Peeling alternates two depth textures, one the target and the other the previous
//! layer. A non-redundant pass maps each
//! fragment's window position and depth straight into the earlier images with matrices formed
//! here in f64, and its pipeline is compiled for its count of earlier images (see
//! `LayeredPipeline::nonredundant`).

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::DMat4;

use super::depth::{finish_chunk, Pending, RasterStats};
use super::raster::{
    align, check_image_size, copy, draw_ids, id_pipeline, submit_readback, texture_2d,
    uniform_window, IdPass, Timestamps, DEPTH_FORMAT, TRI_FORMAT,
};
use super::{GpuContext, SceneBuffers};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::scene::Scene;

const SHADER: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/layered.wgsl"));

/// Which test a pass applies to its fragments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerTest {
    /// Discard a fragment whose triangle an earlier image holds at the pixel it reprojects to.
    PixelRedundancy,
    /// Discard a fragment not strictly beyond the previous image's depth at its pixel.
    Peel,
}

/// Host copy of `View` in layered.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    image: u32,
    width: u32,
    height: u32,
    stride: u32,
}
const VIEW_SIZE: u64 = std::mem::size_of::<ViewUniform>() as u64;
const _: () = assert!(VIEW_SIZE == 80);

/// How many earlier images a non-redundant pass can test against (`MAX_EARLIER` in
/// layered.wgsl): the reprojection matrices of one pass are one uniform binding.
pub const MAX_EARLIER: usize = 255;
const REPROJECT_SIZE: u64 = 64 * MAX_EARLIER as u64;

pub struct LayeredPipeline {
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    module: wgpu::ShaderModule,
    /// [test][cull]: test 0 = peel, 1 = none (image 0, early depth test); cull 0 = none,
    /// 1 = back faces.
    fixed: [[wgpu::RenderPipeline; 2]; 2],
    /// `fs_nonredundant` compiled for one count of earlier images (the override
    /// `earlier_count`), by (count, cull), made on first use. With the count a constant the
    /// shader compiler unrolls the loop over earlier images and loads each reprojection matrix
    /// from a constant address; on lavapipe that halves the cost of the test.
    nonredundant: Mutex<HashMap<(u32, bool), wgpu::RenderPipeline>>,
}

impl LayeredPipeline {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("layered.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let storage = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("layered.wgsl bindings"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: wgpu::BufferSize::new(VIEW_SIZE),
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: wgpu::BufferSize::new(REPROJECT_SIZE),
                    },
                    count: None,
                },
                storage(2),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("layered.wgsl layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let make = |entry, cull| id_pipeline(device, &module, &pipeline_layout, entry, cull, &[]);
        let pair = |entry| [make(entry, None), make(entry, Some(wgpu::Face::Back))];
        let fixed = [pair("fs_peel"), pair("fs_first")];
        Self {
            layout,
            pipeline_layout,
            module,
            fixed,
            nonredundant: Mutex::new(HashMap::new()),
        }
    }

    /// The pipeline of image `image` (> 0) of a non-redundant call.
    fn nonredundant(&self, device: &wgpu::Device, image: u32, cull: bool) -> wgpu::RenderPipeline {
        let mut cache = self.nonredundant.lock().unwrap_or_else(|e| e.into_inner());
        cache
            .entry((image, cull))
            .or_insert_with(|| {
                id_pipeline(
                    device,
                    &self.module,
                    &self.pipeline_layout,
                    "fs_nonredundant",
                    cull.then_some(wgpu::Face::Back),
                    &[("earlier_count", image as f64)],
                )
            })
            .clone()
    }
}

/// Render one image per camera (all of one resolution), image i tested against images 0..i.
/// `on_image(i, ids)` receives image i's triangle ids (row-major, −1 where empty) while the GPU
/// already renders image i + 1.
pub fn render(
    ctx: &GpuContext,
    scene: &Scene,
    cameras: &[Camera],
    test: LayerTest,
    cull_backfaces: bool,
    mut on_image: impl FnMut(usize, &[i32]),
) -> Result<RasterStats> {
    let (w, h) = (cameras[0].width, cameras[0].height);
    let n = cameras.len() as u64;
    check_image_size(ctx, w, h)?;
    if test == LayerTest::PixelRedundancy && cameras.len() > MAX_EARLIER + 1 {
        return Err(Error::GpuLimit(format!(
            "non-redundant rendering tests each image against the ones before it, at most \
             {MAX_EARLIER} of them; got {n} cameras, split them into calls of at most {}",
            MAX_EARLIER + 1
        )));
    }
    let row = align(w as u64 * 4, wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64);
    let image_bytes = row * h as u64;
    let history_bytes = image_bytes * n;
    let limit = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    if history_bytes > limit {
        return Err(Error::GpuLimit(format!(
            "{n} layered images of {w}x{h} need {history_bytes} bytes of triangle ids on the GPU, \
             more than this device's storage limit of {limit} bytes; use fewer or smaller images"
        )));
    }
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let cached = scene.gpu.lock().map(|s| s.is_some()).unwrap_or(false);
    let buffers = SceneBuffers::of(ctx, scene)?;
    let mut stats = RasterStats {
        upload_seconds: if cached { 0.0 } else { buffers.upload_seconds },
        gpu_seconds: ctx.timestamps.then_some(0.0),
        ..Default::default()
    };
    let start = Instant::now();
    let device = &ctx.device;
    let pipeline = ctx.layered_pipeline();
    let centre = scene.center();
    let bounds = scene.bounds();

    use wgpu::util::DeviceExt;
    let stride = align(
        VIEW_SIZE,
        ctx.limits.min_uniform_buffer_offset_alignment as u64,
    );
    let mut uniforms = vec![0u8; (stride * n) as usize];
    let mut clip = Vec::with_capacity(cameras.len());
    for (i, cam) in cameras.iter().enumerate() {
        let (near, far) = cam.clip_range(bounds);
        let m = cam.projection_matrix(near, far) * cam.view_matrix_relative(centre);
        let u = ViewUniform {
            view_proj: m.as_mat4().to_cols_array_2d(),
            image: i as u32,
            width: w,
            height: h,
            stride: (row / 4) as u32,
        };
        let at = i * stride as usize;
        uniforms[at..at + VIEW_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&u));
        clip.push(m);
    }
    // Image i's i reprojection matrices, each image's block at an aligned offset.
    let mut reproject = Vec::new();
    let mut reproject_at = Vec::with_capacity(cameras.len());
    for block in reprojections(cameras, &clip, centre, w, h) {
        reproject_at.push(reproject.len() as u32);
        reproject.extend_from_slice(bytemuck::cast_slice(&block));
        let end = align(
            reproject.len() as u64,
            ctx.limits.min_uniform_buffer_offset_alignment as u64,
        );
        reproject.resize(end as usize, 0u8);
    }
    reproject.resize(reproject.len() + REPROJECT_SIZE as usize, 0u8);
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("layered view uniforms"),
        contents: &uniforms,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let reproject_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("reprojections"),
        contents: &reproject,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let history = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("earlier triangle ids"),
        size: history_bytes,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let texture = |label, format, usage| texture_2d(device, label, (w, h), format, usage);
    let tri = texture(
        "layered triangle ids",
        TRI_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let tri_view = tri.create_view(&Default::default());
    // Two depth textures: pass i renders into depths[i % 2] and reads the other.
    let depth_usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    let depths = [
        texture("layered depth a", DEPTH_FORMAT, depth_usage),
        texture("layered depth b", DEPTH_FORMAT, depth_usage),
    ];
    let depth_views = depths
        .each_ref()
        .map(|d| d.create_view(&Default::default()));
    let binds = [1, 0].map(|other: usize| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("layered.wgsl bindings"),
            layout: &pipeline.layout,
            entries: &[
                uniform_window(0, &uniform_buf, VIEW_SIZE),
                uniform_window(1, &reproject_buf, REPROJECT_SIZE),
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: history.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&depth_views[other]),
                },
            ],
        })
    });
    let cull = cull_backfaces as usize;
    let passes: Vec<wgpu::RenderPipeline> = (0..n as u32)
        .map(|i| match (i, test) {
            (0, _) => pipeline.fixed[1][cull].clone(),
            (_, LayerTest::Peel) => pipeline.fixed[0][cull].clone(),
            (_, LayerTest::PixelRedundancy) => pipeline.nonredundant(device, i, cull_backfaces),
        })
        .collect();
    stats.raster_seconds = start.elapsed().as_secs_f64();
    // One submission per image, so that the caller consumes image i while the GPU renders
    // image i + 1 (as `depth::rasterize` does with its chunks); the passes still see each other's
    // ids through `history`, in submission order.
    let mut in_flight: Option<Pending> = None;
    for i in 0..n {
        let start = Instant::now();
        let queries = Timestamps::new(ctx, 1);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("layered readback"),
            size: image_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        let pass = IdPass {
            ranges: None,
            tri_view: &tri_view,
            depth_view: &depth_views[i as usize % 2],
            store_depth: true,
            pipeline: &passes[i as usize],
            bind: &binds[i as usize % 2],
            offsets: &[(i * stride) as u32, reproject_at[i as usize]],
        };
        draw_ids(&mut encoder, &buffers, &pass, queries.as_ref(), 0);
        copy(&mut encoder, &tri, &history, i * image_bytes, row, w, h);
        encoder.copy_buffer_to_buffer(&history, i * image_bytes, &readback, 0, image_bytes);
        let submission = submit_readback(ctx, encoder, &readback, queries.as_ref());
        let next = Pending {
            readback,
            queries,
            submission,
            first: i as usize,
            n: 1,
            w,
            h,
            row_tri: row,
        };
        stats.raster_seconds += start.elapsed().as_secs_f64();
        if let Some(done) = in_flight.replace(next) {
            finish_chunk(ctx, done, &mut stats, &mut on_image)?;
        }
    }
    if let Some(done) = in_flight {
        finish_chunk(ctx, done, &mut stats, &mut on_image)?;
    }
    Ok(stats)
}

/// The matrices `reproject` of layered.wgsl, a block per image: for image i and each earlier
/// image j < i, the map from i's homogeneous window coordinates (x, y, depth, 1) to
/// (x·w, y·w, w, f) in image j — pixel position, clip w and signed distance in front of j's image
/// plane, all scaled by the same positive weight. Formed in f64 from the clip matrices `clip`
/// (relative to `centre`) and rounded once to f32. Image 0's block is empty.
fn reprojections(
    cameras: &[Camera],
    clip: &[DMat4],
    centre: glam::DVec3,
    w: u32,
    h: u32,
) -> Vec<Vec<[[f32; 4]; 4]>> {
    let (wf, hf) = (w as f64, h as f64);
    let rows = |r: [[f64; 4]; 4]| DMat4::from_cols_array_2d(&r).transpose();
    // Window (x right, y down, depth) to normalized device coordinates.
    let window_to_ndc = rows([
        [2.0 / wf, 0.0, 0.0, -1.0],
        [0.0, -2.0 / hf, 0.0, 1.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);
    // Clip coordinates to (x·w, y·w, w) in pixels.
    let clip_to_pixel = rows([
        [wf / 2.0, 0.0, 0.0, wf / 2.0],
        [0.0, -hf / 2.0, 0.0, hf / 2.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0, 0.0],
    ]);
    let mut out = vec![Vec::new()];
    for i in 1..cameras.len() {
        let back = clip[i].inverse() * window_to_ndc;
        let mut block = Vec::with_capacity(i);
        for j in 0..i {
            let fwd = cameras[j].forward();
            // In front: (p_rel + centre − eye)·forward > 0.
            let front = fwd.extend((centre - cameras[j].eye()).dot(fwd));
            let mut r = clip_to_pixel * clip[j] * back;
            r = r.transpose();
            r.w_axis = back.transpose() * front;
            block.push(r.transpose().as_mat4().to_cols_array_2d());
        }
        out.push(block);
    }
    out
}
