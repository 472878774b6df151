//! Pieces shared by the raster passes (`depth`, `layered`, `shadow`): the pipeline state,
//! one pass per image, per-pass GPU timestamps, and texture-to-buffer copies.

use super::{GpuContext, SceneBuffers};
use crate::error::{Error, Result};

/// Triangle id per pixel (−1 where empty).
pub const TRI_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Sint;
/// Reversed depth: larger is nearer (see `Camera::projection_matrix`).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Images of w×h must fit in one of the device's textures.
pub fn check_image_size(ctx: &GpuContext, w: u32, h: u32) -> Result<()> {
    let max_dim = ctx.limits.max_texture_dimension_2d;
    if w > max_dim || h > max_dim {
        return Err(Error::GpuLimit(format!(
            "images of {w}x{h} exceed this device's largest texture ({max_dim}x{max_dim}); \
             use a smaller resolution"
        )));
    }
    Ok(())
}

/// The vertex input of every scene raster pass: one float3 position per vertex.
const POSITION_ATTRIBUTES: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
pub const POSITIONS: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
    array_stride: 12,
    step_mode: wgpu::VertexStepMode::Vertex,
    attributes: &POSITION_ATTRIBUTES,
};

/// The depth test of every scene raster pass: reversed depth (larger is nearer), written.
pub fn reversed_depth() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Greater),
        stencil: Default::default(),
        bias: Default::default(),
    }
}

/// A single-sampled w×h 2D texture without mip levels.
pub fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    (w, h): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&texture_2d_descriptor(label, (w, h, 1), format, usage))
}

/// The descriptor of a single-sampled w×h 2D texture (an array of `layers` of them) without mip
/// levels.
pub fn texture_2d_descriptor(
    label: &str,
    (w, h, layers): (u32, u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureDescriptor<'_> {
    wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    }
}

pub fn align(x: u64, a: u64) -> u64 {
    x.div_ceil(a) * a
}

/// Bind group entry `binding`: a `size`-byte window at the start of `buffer`, moved by the
/// dynamic offset of each draw or dispatch (one uniform block per image, view or light).
pub fn uniform_window(binding: u32, buffer: &wgpu::Buffer, size: u64) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer,
            offset: 0,
            size: wgpu::BufferSize::new(size),
        }),
    }
}

/// A pipeline drawing the scene's indexed triangles (positions relative to the scene centre,
/// `vs_main`) into a `TRI_FORMAT` target with a reversed depth test, fragment stage `fs_entry`,
/// counter-clockwise fronts, culling `cull`, and the fragment stage's pipeline-overridable
/// `constants`.
pub fn id_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    fs_entry: &str,
    cull: Option<wgpu::Face>,
    constants: &[(&str, f64)],
) -> wgpu::RenderPipeline {
    id_pipeline_with(device, module, layout, "vs_main", fs_entry, cull, constants)
}

/// `id_pipeline` with a vertex entry point other than `vs_main`.
pub fn id_pipeline_with(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    vs_entry: &str,
    fs_entry: &str,
    cull: Option<wgpu::Face>,
    constants: &[(&str, f64)],
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(fs_entry),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs_entry),
            compilation_options: Default::default(),
            buffers: &[Some(POSITIONS)],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: cull,
            ..Default::default()
        },
        depth_stencil: Some(reversed_depth()),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs_entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants,
                ..Default::default()
            },
            targets: &[Some(TRI_FORMAT.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Where one image's pass draws and what it binds.
pub struct IdPass<'a> {
    pub tri_view: &'a wgpu::TextureView,
    pub depth_view: &'a wgpu::TextureView,
    /// Keep the depth buffer after the pass (peeling reads it in the next one).
    pub store_depth: bool,
    pub pipeline: &'a wgpu::RenderPipeline,
    pub bind: &'a wgpu::BindGroup,
    /// Dynamic offsets of this image's uniforms, in binding order.
    pub offsets: &'a [u32],
    /// Draw only these triangle ranges `[a, b)` (the shader must add the instance index to its
    /// primitive index, as depth.wgsl does); `None`: every triangle in one draw.
    pub ranges: Option<&'a [(u32, u32)]>,
    /// Draw this index buffer of `n` triangles instead of the scene's faces (`ranges` unused):
    /// the scene without its duplicated faces ([`super::Distinct`]).
    pub faces: Option<(&'a wgpu::Buffer, u32)>,
}

/// Record pass `i`: clear ids to −1 and depth to far, draw every triangle of the scene.
pub fn draw_ids(
    encoder: &mut wgpu::CommandEncoder,
    buffers: &SceneBuffers,
    pass: &IdPass<'_>,
    timestamps: Option<&Timestamps>,
    i: u32,
) {
    let mut rp = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("triangle ids"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: pass.tri_view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color {
                    r: -1.0,
                    g: 0.0,
                    b: 0.0,
                    a: 0.0,
                }),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: pass.depth_view,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(0.0),
                store: if pass.store_depth {
                    wgpu::StoreOp::Store
                } else {
                    wgpu::StoreOp::Discard
                },
            }),
            stencil_ops: None,
        }),
        timestamp_writes: timestamps.map(|t| t.writes(i)),
        occlusion_query_set: None,
        multiview_mask: None,
    });
    rp.set_pipeline(pass.pipeline);
    rp.set_bind_group(0, pass.bind, pass.offsets);
    rp.set_vertex_buffer(0, buffers.positions.slice(..));
    if let Some((faces, n)) = pass.faces {
        rp.set_index_buffer(faces.slice(..), wgpu::IndexFormat::Uint32);
        rp.draw_indexed(0..3 * n, 0, 0..1);
        return;
    }
    rp.set_index_buffer(buffers.faces.slice(..), wgpu::IndexFormat::Uint32);
    match pass.ranges {
        None => rp.draw_indexed(0..3 * buffers.triangle_count, 0, 0..1),
        // One draw per range; its first triangle rides in the instance index, which the shader
        // adds to the primitive index (which restarts at 0 in every draw).
        Some(ranges) => {
            for &(a, b) in ranges {
                rp.draw_indexed(3 * a..3 * b, 0, a..a + 1);
            }
        }
    }
}

/// Begin and end timestamps of `n` passes, resolved into a mappable buffer.
pub struct Timestamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    read: wgpu::Buffer,
    n: u32,
}

impl Timestamps {
    /// The begin and end writes of render pass `i`.
    pub fn writes(&self, i: u32) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(2 * i),
            end_of_pass_write_index: Some(2 * i + 1),
        }
    }

    /// Queries for `n` passes, when the adapter has timestamps.
    pub fn new(ctx: &GpuContext, n: u32) -> Option<Self> {
        ctx.timestamps.then(|| {
            let device = &ctx.device;
            let buffer = |label, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: 16 * n as u64,
                    usage,
                    mapped_at_creation: false,
                })
            };
            Self {
                set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("raster timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * n,
                }),
                resolved: buffer(
                    "timestamp resolve",
                    wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                ),
                read: buffer(
                    "timestamp readback",
                    wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                ),
                n,
            }
        })
    }

    /// Record the resolve and copy after the passes.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..2 * self.n, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.read, 0, 16 * self.n as u64);
    }

    /// Request the mapping, after the submission.
    pub fn map(&self) {
        self.read.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    }

    /// Total GPU seconds of the passes, once the submission is done.
    pub fn seconds(&self, ctx: &GpuContext) -> Result<f64> {
        let period = ctx.queue.get_timestamp_period() as f64 * 1e-9;
        let data = self
            .read
            .slice(..)
            .get_mapped_range()
            .map_err(|e| Error::Gpu(format!("mapping the timestamps failed: {e}")))?;
        let ts: &[u64] = bytemuck::cast_slice(&data);
        Ok(ts
            .chunks(2)
            .map(|t| t[1].saturating_sub(t[0]) as f64 * period)
            .sum())
    }
}

/// Copy a w×h id texture into `buf` at `offset`, rows `row` bytes apart.
pub fn copy(
    encoder: &mut wgpu::CommandEncoder,
    tex: &wgpu::Texture,
    buf: &wgpu::Buffer,
    offset: u64,
    row: u64,
    w: u32,
    h: u32,
) {
    encoder.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset,
                bytes_per_row: Some(row as u32),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
}

/// Resolve the timestamps, submit `encoder`, and start mapping `readback` (and the
/// timestamps) for reading once the GPU is done.
pub fn submit_readback(
    ctx: &GpuContext,
    mut encoder: wgpu::CommandEncoder,
    readback: &wgpu::Buffer,
    queries: Option<&Timestamps>,
) -> wgpu::SubmissionIndex {
    if let Some(q) = queries {
        q.resolve(&mut encoder);
    }
    let submission = ctx.queue.submit([encoder.finish()]);
    readback.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    if let Some(q) = queries {
        q.map();
    }
    submission
}

/// Wait for `submission` and raise any error wgpu reported meanwhile.
pub fn wait(ctx: &GpuContext, submission: wgpu::SubmissionIndex) -> Result<()> {
    ctx.device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(submission),
            timeout: None,
        })
        .map_err(|e| Error::Gpu(format!("waiting for the GPU failed: {e}")))?;
    ctx.check_errors()
}
