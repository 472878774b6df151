//! Raster passes of `shaders/layered.wgsl`: images rendered one after another, each pass testing
//! its fragments against the images before it — non-redundant rendering with pixel redundancy
//! (non-redundant-rendering.txt Algorithm 1 with Algorithm 3) or depth peeling. Each pass is its
//! own submission: after it, its triangle ids are copied into a layer of a texture array that the
//! later passes read and into a readback buffer that the caller consumes while the GPU renders
//! the next image. Peeling alternates two depth textures, one the target and the other the
//! previous layer. A non-redundant pass reaches its first `VARYING_IMAGES` earlier images through
//! positions the vertex stage projects into them and the rasteriser interpolates, and any further
//! ones by mapping the fragment's window position and depth with a matrix read from a texture;
//! the projections are formed here in f64, and each pass's pipeline is compiled for its count of
//! earlier images (see `LayeredPipeline::nonredundant`).

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{DMat4, DVec3};

use super::depth::{finish_chunk, Pending, RasterStats};
use super::raster::{
    align, check_image_size, copy, draw_ids, id_pipeline_with, submit_readback, texture_2d,
    texture_2d_descriptor, uniform_window, IdPass, Timestamps, DEPTH_FORMAT, TRI_FORMAT,
};
use super::{Distinct, GpuContext, SceneBuffers};
use crate::camera::{Camera, Projection};
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
    /// `fs_peel`'s (k, c, 0, 0); see layered.wgsl.
    peel: [f32; 4],
}
const VIEW_SIZE: u64 = std::mem::size_of::<ViewUniform>() as u64;
const _: () = assert!(VIEW_SIZE == 80);

/// How many earlier images a non-redundant pass can test against: the earlier images are the
/// layers of one texture array, and WebGPU guarantees 256 layers.
pub const MAX_EARLIER: usize = 255;
/// How many earlier images a pass reaches through interpolated positions (`VARYING_IMAGES` in
/// layered.wgsl); the rest through matrices read per fragment.
const VARYING_IMAGES: u32 = 4;
const PROJECT_INTO_SIZE: u64 = 64 * VARYING_IMAGES as u64;

pub struct LayeredPipeline {
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    module: wgpu::ShaderModule,
    /// [test][cull]: test 0 = peel, 1 = none (image 0, early depth test); cull 0 = none,
    /// 1 = back faces.
    fixed: [[wgpu::RenderPipeline; 2]; 2],
    /// The non-redundant pipeline for one count of earlier images, by (count, cull), made on
    /// first use: `vs_earlierK`/`fs_earlierK` with K = min(count, VARYING_IMAGES) interpolated
    /// earlier images, and the count as the override `earlier_count`, so that the loop over the
    /// remaining ones unrolls.
    nonredundant: Mutex<HashMap<(u32, bool), wgpu::RenderPipeline>>,
}

impl LayeredPipeline {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("layered.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let texture = |binding, sample_type, view_dimension| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension,
                multisampled: false,
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
                texture(
                    1,
                    wgpu::TextureSampleType::Float { filterable: false },
                    wgpu::TextureViewDimension::D2,
                ),
                texture(
                    2,
                    wgpu::TextureSampleType::Sint,
                    wgpu::TextureViewDimension::D2Array,
                ),
                texture(
                    3,
                    wgpu::TextureSampleType::Depth,
                    wgpu::TextureViewDimension::D2,
                ),
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(PROJECT_INTO_SIZE),
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
        let make =
            |vs, fs, cull| id_pipeline_with(device, &module, &pipeline_layout, vs, fs, cull, &[]);
        let pair = |vs, fs| [make(vs, fs, None), make(vs, fs, Some(wgpu::Face::Back))];
        let fixed = [pair("vs_peel", "fs_peel"), pair("vs_main", "fs_first")];
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
                let k = image.min(VARYING_IMAGES);
                id_pipeline_with(
                    device,
                    &self.module,
                    &self.pipeline_layout,
                    &format!("vs_earlier{k}"),
                    &format!("fs_earlier{k}"),
                    cull.then_some(wgpu::Face::Back),
                    &[("earlier_count", image as f64)],
                )
            })
            .clone()
    }
}

/// Render one image per camera (all of one resolution), image i tested against images 0..i.
/// `on_image(i, ids)` receives image i's triangle ids (row-major, −1 where empty) while the GPU
/// already renders image i + 1. A non-redundant render may be given image 0's ids (`first`,
/// made by the CPU backend): they are not drawn again, and the later passes test against them.
pub fn render(
    ctx: &GpuContext,
    scene: &Scene,
    cameras: &[Camera],
    test: LayerTest,
    cull_backfaces: bool,
    first: Option<&[i32]>,
    mut on_image: impl FnMut(usize, &[i32]),
) -> Result<RasterStats> {
    let (w, h) = (cameras[0].width, cameras[0].height);
    let n = cameras.len() as u64;
    check_image_size(ctx, w, h)?;
    let nonredundant = test == LayerTest::PixelRedundancy;
    debug_assert!(
        first.is_none() || nonredundant,
        "peeling draws its own first layer"
    );
    debug_assert!(first.is_none_or(|ids| ids.len() == w as usize * h as usize));
    let layers = earlier_layers(ctx, n, nonredundant)?;
    let row = align(w as u64 * 4, wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64);
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let cached = SceneBuffers::cached(ctx, scene);
    let buffers = SceneBuffers::of(ctx, scene)?;
    // Duplicated faces are drawn once; the passes see kept faces' indices, which are mapped
    // back to triangle ids as each image comes back.
    let distinct = buffers.distinct(ctx, scene);
    let mut stats = RasterStats {
        upload_seconds: if cached { 0.0 } else { buffers.upload_seconds },
        gpu_seconds: ctx.timestamps.then_some(0.0),
        ..Default::default()
    };
    let start = Instant::now();
    let centre = scene.center();
    let bounds = scene.bounds();

    let stride = align(
        VIEW_SIZE,
        ctx.limits.min_uniform_buffer_offset_alignment as u64,
    );
    let (uniforms, clip) = view_uniforms(cameras, centre, bounds, stride);
    let res = Resources::new(
        ctx,
        cameras,
        &clip,
        centre,
        &uniforms,
        test,
        layers,
        cull_backfaces,
    );
    // Image 0 made elsewhere: the later passes read it, as the kept faces a pass would write.
    let drawn_from = match first {
        Some(ids) => {
            let slots = distinct.map(|d| d.slots(ids));
            res.write_earlier(ctx, 0, slots.as_deref().unwrap_or(ids));
            on_image(0, ids);
            1
        }
        None => 0,
    };
    let mut on_drawn = |i: usize, ids: &[i32]| match distinct {
        Some(d) => on_image(i, &d.triangle_ids(ids)),
        None => on_image(i, ids),
    };
    stats.raster_seconds = start.elapsed().as_secs_f64();
    // One submission per image, so that the caller consumes image i while the GPU renders
    // image i + 1 (as `depth::rasterize` does with its chunks); the passes still see each other's
    // ids through `earlier`, in submission order.
    let mut in_flight: Option<Pending> = None;
    for i in drawn_from..n {
        let start = Instant::now();
        let next = res.submit(
            ctx,
            &buffers,
            distinct,
            ImageStep {
                i,
                stride,
                copy_earlier: nonredundant && (i as u32) < layers,
                row,
            },
        );
        stats.raster_seconds += start.elapsed().as_secs_f64();
        if let Some(done) = in_flight.replace(next) {
            finish_chunk(ctx, done, &mut stats, &mut on_drawn)?;
        }
    }
    if let Some(done) = in_flight {
        finish_chunk(ctx, done, &mut stats, &mut on_drawn)?;
    }
    Ok(stats)
}

/// The GPU resources of one layered render: view uniforms, the reprojection matrices, the
/// earlier images' ids (non-redundant passes), the id target, two depth textures the passes
/// alternate between (each reads the other), their bind groups and one pipeline per pass.
struct Resources {
    /// Bound, never touched again: held for the render's lifetime.
    _held: (
        wgpu::Texture,
        [wgpu::Texture; 2],
        wgpu::Buffer,
        wgpu::Buffer,
    ),
    tri: wgpu::Texture,
    tri_view: wgpu::TextureView,
    earlier: wgpu::Texture,
    depth_views: [wgpu::TextureView; 2],
    binds: [wgpu::BindGroup; 2],
    passes: Vec<wgpu::RenderPipeline>,
}

/// The projections of world space into each earlier image's pixels (`projection_into`), as a
/// uniform buffer.
fn projections_into(
    device: &wgpu::Device,
    cameras: &[Camera],
    clip: &[DMat4],
    centre: DVec3,
) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let (w, h) = (cameras[0].width, cameras[0].height);
    let mut project_into = [[[0f32; 4]; 4]; VARYING_IMAGES as usize];
    for (m, (cam, clip)) in project_into.iter_mut().zip(cameras.iter().zip(clip)) {
        *m = projection_into(cam, clip, centre, w, h)
            .as_mat4()
            .to_cols_array_2d();
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("projections into earlier images"),
        contents: bytemuck::cast_slice(&project_into),
        usage: wgpu::BufferUsages::UNIFORM,
    })
}

impl Resources {
    #[allow(clippy::too_many_arguments)]
    fn new(
        ctx: &GpuContext,
        cameras: &[Camera],
        clip: &[DMat4],
        centre: DVec3,
        uniforms: &[u8],
        test: LayerTest,
        layers: u32,
        cull_backfaces: bool,
    ) -> Resources {
        use wgpu::util::DeviceExt;
        let device = &ctx.device;
        let pipeline = ctx.layered_pipeline();
        let (w, h) = (cameras[0].width, cameras[0].height);
        let n = cameras.len() as u64;
        let nonredundant = test == LayerTest::PixelRedundancy;
        let clip = clip.to_vec();
        let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("layered view uniforms"),
            contents: uniforms,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let reproject = reprojection_texture(ctx, cameras, &clip, centre, nonredundant);
        // Peeling never reads earlier ids: a 1x1 stand-in fills the binding.
        let earlier_size = if nonredundant {
            (w, h, layers)
        } else {
            (1, 1, 1)
        };
        let earlier = device.create_texture(&texture_2d_descriptor(
            "earlier triangle ids",
            earlier_size,
            TRI_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        ));
        let tri = texture_2d(
            device,
            "layered triangle ids",
            (w, h),
            TRI_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let tri_view = tri.create_view(&Default::default());
        // Two depth textures: pass i renders into depths[i % 2] and reads the other.
        let depth_usage =
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let depths = ["layered depth a", "layered depth b"]
            .map(|label| texture_2d(device, label, (w, h), DEPTH_FORMAT, depth_usage));
        let depth_views = depths
            .each_ref()
            .map(|d| d.create_view(&Default::default()));
        let reproject_view = reproject.create_view(&Default::default());
        let earlier_view = earlier.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let project_into_buf = projections_into(device, cameras, &clip, centre);
        let binds = [1, 0].map(|other: usize| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("layered.wgsl bindings"),
                layout: &pipeline.layout,
                entries: &[
                    uniform_window(0, &uniform_buf, VIEW_SIZE),
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&reproject_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(&earlier_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&depth_views[other]),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: project_into_buf.as_entire_binding(),
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

        Resources {
            _held: (reproject, depths, uniform_buf, project_into_buf),
            tri,
            tri_view,
            earlier,
            depth_views,
            binds,
            passes,
        }
    }
}

/// One image of `render`'s loop: its index, the uniform stride, whether its ids are kept for
/// later images, and the readback's row pitch.
struct ImageStep {
    i: u64,
    stride: u64,
    copy_earlier: bool,
    row: u64,
}

impl Resources {
    /// Put image `i`'s ids (row-major, as a pass writes them) into the earlier images' layer
    /// `i`, where the passes after it read them.
    fn write_earlier(&self, ctx: &GpuContext, i: u32, ids: &[i32]) {
        let (w, h) = (self.tri.width(), self.tri.height());
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.earlier,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: 0, z: i },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(ids),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Encodes and submits image `step.i`'s pass and the readback of its ids.
    fn submit(
        &self,
        ctx: &GpuContext,
        buffers: &SceneBuffers,
        distinct: Option<&Distinct>,
        step: ImageStep,
    ) -> Pending {
        let ImageStep { i, stride, row, .. } = step;
        let device = &ctx.device;
        let (w, h) = (self.tri.width(), self.tri.height());
        let image_bytes = row * h as u64;
        let queries = Timestamps::new(ctx, 1);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("layered readback"),
            size: image_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        let pass = IdPass {
            faces: distinct.map(|d| (&d.faces, d.triangles.len() as u32)),
            ranges: None,
            tri_view: &self.tri_view,
            depth_view: &self.depth_views[i as usize % 2],
            store_depth: true,
            pipeline: &self.passes[i as usize],
            bind: &self.binds[i as usize % 2],
            offsets: &[(i * stride) as u32],
        };
        draw_ids(&mut encoder, buffers, &pass, queries.as_ref(), 0);
        if step.copy_earlier {
            encoder.copy_texture_to_texture(
                self.tri.as_image_copy(),
                wgpu::TexelCopyTextureInfo {
                    texture: &self.earlier,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: i as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
        }
        copy(&mut encoder, &self.tri, &readback, 0, row, w, h);
        let submission = submit_readback(ctx, encoder, &readback, queries.as_ref());
        Pending {
            readback,
            queries,
            submission,
            first: i as usize,
            n: 1,
            w,
            h,
            row_tri: row,
        }
    }
}

/// Row i, texels 4(j − VARYING_IMAGES) + 0..4: the columns of image i's matrix into earlier
/// image j >= VARYING_IMAGES (a 4x1 stand-in when no pass has such an image; §3.2's
/// reprojection of a fragment into the images before it).
fn reprojection_texture(
    ctx: &GpuContext,
    cameras: &[Camera],
    clip: &[DMat4],
    centre: DVec3,
    nonredundant: bool,
) -> wgpu::Texture {
    use wgpu::util::DeviceExt;
    let (w, h) = (cameras[0].width, cameras[0].height);
    let n = cameras.len();
    let later = n.saturating_sub(1 + VARYING_IMAGES as usize);
    let columns = 4 * later.max(1);
    let mut texels = vec![[0f32; 4]; columns * n];
    if nonredundant && later > 0 {
        for (i, block) in reprojections(cameras, clip, centre, w, h)
            .into_iter()
            .enumerate()
        {
            let dst = &mut texels[i * columns..];
            for (k, m) in block.iter().skip(VARYING_IMAGES as usize).enumerate() {
                dst[4 * k..4 * k + 4].copy_from_slice(m);
            }
        }
    }
    ctx.device.create_texture_with_data(
        &ctx.queue,
        &texture_2d_descriptor(
            "reprojections",
            (columns as u32, n as u32, 1),
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING,
        ),
        wgpu::util::TextureDataOrder::LayerMajor,
        bytemuck::cast_slice(&texels),
    )
}

/// How many earlier images a non-redundant pass reads (every image but the last, as layers of
/// one texture array); a device limit error when there are more than the device holds.
fn earlier_layers(ctx: &GpuContext, n: u64, nonredundant: bool) -> Result<u32> {
    let layers = (n as u32).saturating_sub(1).max(1);
    if nonredundant && layers > ctx.limits.max_texture_array_layers.min(MAX_EARLIER as u32) {
        let most = ctx.limits.max_texture_array_layers.min(MAX_EARLIER as u32) + 1;
        return Err(Error::GpuLimit(format!(
            "non-redundant rendering tests each image against the ones before it, at most \
             {} of them on this device; got {n} cameras, split them into calls of at most \
             {most}",
            most - 1
        )));
    }
    Ok(layers)
}

/// `fs_peel`'s tie constants for a camera with clip range `near..far`: it keeps fragments below
/// k·previous + c, the window depth of camera z d (1 + m) for the previous layer's d, m the
/// relative tie [`SAME_HIT`](crate::types::SAME_HIT). Perspective (z = b / d - a): k = 1 / (1 +
/// m), c = -a m / (1 + m). Orthographic (z = f / (f - n) - d / (f - n)): k = 1 + m,
/// c = -m f / (f - n).
fn peel_tie(cam: &Camera, near: f64, far: f64) -> (f64, f64) {
    let m_tie = crate::types::SAME_HIT as f64;
    match cam.projection {
        Projection::Orthographic { .. } => (1.0 + m_tie, -m_tie * far / (far - near)),
        Projection::Perspective { .. } => {
            let a = if far.is_finite() {
                near / (far - near)
            } else {
                0.0
            };
            (1.0 / (1.0 + m_tie), -a * m_tie / (1.0 + m_tie))
        }
    }
}

/// Every camera's view uniform (its clip matrix relative to `centre` and its peel constants),
/// `stride` bytes apart, and the clip matrices.
fn view_uniforms(
    cameras: &[Camera],
    centre: DVec3,
    bounds: [[f32; 3]; 2],
    stride: u64,
) -> (Vec<u8>, Vec<DMat4>) {
    let mut uniforms = vec![0u8; stride as usize * cameras.len()];
    let mut clip = Vec::with_capacity(cameras.len());
    for (i, cam) in cameras.iter().enumerate() {
        let (near, far) = cam.clip_range(bounds);
        let m = cam.projection_matrix(near, far) * cam.view_matrix_relative(centre);
        let (k, c) = peel_tie(cam, near, far);
        let u = ViewUniform {
            view_proj: m.as_mat4().to_cols_array_2d(),
            peel: [k as f32, c as f32, 0.0, 0.0],
        };
        let at = i * stride as usize;
        uniforms[at..at + VIEW_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&u));
        clip.push(m);
    }
    (uniforms, clip)
}

/// `project_into` of layered.wgsl for camera `cam` with clip matrix `clip` (relative to
/// `centre`): the map from a position relative to the scene centre to (x·w, y·w, w, f) in its
/// w×h image — pixel position (x right, y down from the top-left corner), clip w, and the signed
/// distance in front of the camera's image plane, (p_rel + centre − eye)·forward. In f64.
fn projection_into(cam: &Camera, clip: &DMat4, centre: glam::DVec3, w: u32, h: u32) -> DMat4 {
    let (wf, hf) = (w as f64, h as f64);
    // Clip coordinates to (x·w, y·w, w) in pixels; the last row is replaced below.
    let clip_to_pixel = DMat4::from_cols_array_2d(&[
        [wf / 2.0, 0.0, 0.0, wf / 2.0],
        [0.0, -hf / 2.0, 0.0, hf / 2.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0, 0.0],
    ])
    .transpose();
    let fwd = cam.forward();
    let mut rows = (clip_to_pixel * *clip).transpose();
    rows.w_axis = fwd.extend((centre - cam.eye()).dot(fwd));
    rows.transpose()
}

/// The matrices of `reproject` in layered.wgsl, a block per image: for image i and each earlier
/// image j < i, the map from i's homogeneous window coordinates (x, y, depth, 1) to
/// (x·w, y·w, w, f) in image j (see `projection_into`), all scaled by the same positive weight.
/// Formed in f64 from the clip matrices `clip` (relative to `centre`) and rounded once to f32.
/// Image 0's block is empty.
fn reprojections(
    cameras: &[Camera],
    clip: &[DMat4],
    centre: glam::DVec3,
    w: u32,
    h: u32,
) -> Vec<Vec<[[f32; 4]; 4]>> {
    let (wf, hf) = (w as f64, h as f64);
    // Window (x right, y down, depth) to normalized device coordinates.
    let window_to_ndc = DMat4::from_cols_array_2d(&[
        [2.0 / wf, 0.0, 0.0, -1.0],
        [0.0, -2.0 / hf, 0.0, 1.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ])
    .transpose();
    let into: Vec<DMat4> = cameras
        .iter()
        .zip(clip)
        .map(|(cam, m)| projection_into(cam, m, centre, w, h))
        .collect();
    let mut out = vec![Vec::new()];
    for i in 1..cameras.len() {
        let back = clip[i].inverse() * window_to_ndc;
        let block = into[..i]
            .iter()
            .map(|m| (*m * back).as_mat4().to_cols_array_2d())
            .collect();
        out.push(block);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{look_at_pose, Projection};
    use glam::{DVec3, DVec4};

    #[test]
    fn shader_and_host_agree_on_the_interpolated_images() {
        let line = format!("const VARYING_IMAGES: u32 = {VARYING_IMAGES}u;");
        assert!(SHADER.contains(&line), "layered.wgsl lacks `{line}`");
        for k in 1..=VARYING_IMAGES {
            for entry in [format!("fn vs_earlier{k}("), format!("fn fs_earlier{k}(")] {
                assert!(SHADER.contains(&entry), "layered.wgsl lacks `{entry}`");
            }
        }
    }

    /// Both ways into an earlier image — a vertex's projection (interpolated) and a fragment's
    /// window position and depth through its matrix — land where `Camera::project` puts the
    /// point, with a perspective and an orthographic camera.
    #[test]
    fn both_reprojections_agree_with_camera_project() {
        let (w, h) = (320, 200);
        let centre = DVec3::new(10.0, -4.0, 3.0);
        let up = DVec3::Z;
        let pose = |eye: DVec3| look_at_pose(centre + eye, centre, up).unwrap();
        let cameras = [
            Camera::new(
                pose(DVec3::new(0.0, -8.0, 2.0)),
                Projection::Perspective { yfov: 0.9 },
                w,
                h,
                None,
                None,
            )
            .unwrap(),
            Camera::new(
                pose(DVec3::new(6.0, -5.0, 4.0)),
                Projection::Orthographic {
                    xmag: 3.0,
                    ymag: 2.0,
                },
                w,
                h,
                None,
                Some(40.0),
            )
            .unwrap(),
            Camera::new(
                pose(DVec3::new(-5.0, -6.0, 1.0)),
                Projection::Perspective { yfov: 0.7 },
                w,
                h,
                None,
                None,
            )
            .unwrap(),
        ];
        let bounds = [[5.0, -9.0, -2.0], [15.0, 1.0, 8.0]];
        let clip: Vec<DMat4> = cameras
            .iter()
            .map(|c| {
                let (near, far) = c.clip_range(bounds);
                c.projection_matrix(near, far) * c.view_matrix_relative(centre)
            })
            .collect();
        let blocks = reprojections(&cameras, &clip, centre, w, h);
        let pixel = |c: DVec4| (c.x / c.z, c.y / c.z);
        for p in [
            DVec3::new(10.3, -4.2, 3.5),
            DVec3::new(11.0, -3.0, 2.0),
            DVec3::new(9.2, -4.9, 3.9),
        ] {
            let rel = (p - centre).extend(1.0);
            // Image 2's window coordinates of p, as the rasteriser gives them to a fragment.
            let ndc = clip[2] * rel;
            let ndc = ndc.truncate() / ndc.w;
            let window = DVec4::new(
                (ndc.x + 1.0) * 0.5 * w as f64,
                (1.0 - ndc.y) * 0.5 * h as f64,
                ndc.z,
                1.0,
            );
            for (j, cam) in cameras[..2].iter().enumerate() {
                let (want, depth) = cam.project(p);
                let direct = projection_into(cam, &clip[j], centre, w, h) * rel;
                let via = glam::Mat4::from_cols_array_2d(&blocks[2][j]).as_dmat4() * window;
                for c in [direct, via] {
                    let (x, y) = pixel(c);
                    assert!((x - want.x).abs() < 1e-3 && (y - want.y).abs() < 1e-3);
                    // In front of camera j: w and f positive (f is the depth along forward).
                    assert!(c.z > 0.0 && c.w > 0.0);
                }
                assert!((direct.w - depth).abs() < 1e-9 * depth.max(1.0));
            }
        }
    }
}
