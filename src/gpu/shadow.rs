//! Shadow mapping for soft shadows (non-redundant-rendering.txt Algorithm 5, steps 4-9), with
//! `shaders/shadow.wgsl`: per light sample, one depth-only raster pass of the occluders into a
//! square shadow map, then one compute pass testing every output point against it and writing
//! 32 visibility bits per word. All samples go into one submission; the shadow map is reused.

use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::raster::{
    align, reversed_depth, submit_readback, texture_2d, uniform_window, wait, Timestamps,
    DEPTH_FORMAT, POSITIONS,
};
use super::{GpuContext, SceneBuffers};
use crate::camera::Camera;
use crate::error::{Error, Result};

const SHADER: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/shadow.wgsl"));

/// The shadow-map bias: a point is lit when it lies no more than
/// `1.5 · texel(d) · (1 + min(tan θ, 8)) + ABS_BIAS · diagonal` beyond the stored occluder depth,
/// with texel(d) the shadow-map texel size at the point's depth d from the light sample and θ
/// the angle between the point's normal and the direction to the sample. (The constant 1.5 and
/// the cap are in `shadow.wgsl`.)
pub const ABS_BIAS: f64 = 1e-4;

/// Host copy of `Light` in shadow.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct LightUniform {
    view_proj: [[f32; 4]; 4],
    position: [f32; 4],
    params: [f32; 4],
    sizes: [u32; 4],
}
const LIGHT_SIZE: u64 = std::mem::size_of::<LightUniform>() as u64;
const _: () = assert!(LIGHT_SIZE == 112);

pub struct ShadowPipeline {
    /// Everything the test reads (the shadow map included).
    layout: wgpu::BindGroupLayout,
    /// The raster pass's own: the light uniform only, since the map is its attachment.
    raster_layout: wgpu::BindGroupLayout,
    depth: wgpu::RenderPipeline,
    test: wgpu::ComputePipeline,
}

impl ShadowPipeline {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shadow.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let (layout, raster_layout) = Self::layouts(device);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("shadow.wgsl layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let raster_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("shadow.wgsl raster layout"),
                bind_group_layouts: &[Some(&raster_layout)],
                immediate_size: 0,
            });
        let depth = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("shadow map"),
            layout: Some(&raster_pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_depth"),
                compilation_options: Default::default(),
                buffers: &[Some(POSITIONS)],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(reversed_depth()),
            multisample: Default::default(),
            fragment: None,
            multiview_mask: None,
            cache: None,
        });
        let test = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("shadow test"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("cs_test"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self {
            layout,
            raster_layout,
            depth,
            test,
        }
    }

    /// The test's bindings (light uniform, points, normals, shadow map, bits) and the raster
    /// pass's (the light uniform only, since the map is its attachment).
    fn layouts(device: &wgpu::Device) -> (wgpu::BindGroupLayout, wgpu::BindGroupLayout) {
        let buffer =
            |binding, visibility, ty, dynamic, min: Option<u64>| wgpu::BindGroupLayoutEntry {
                binding,
                visibility,
                ty: wgpu::BindingType::Buffer {
                    ty,
                    has_dynamic_offset: dynamic,
                    min_binding_size: min.and_then(wgpu::BufferSize::new),
                },
                count: None,
            };
        let compute = wgpu::ShaderStages::COMPUTE;
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shadow.wgsl bindings"),
            entries: &[
                buffer(
                    0,
                    wgpu::ShaderStages::VERTEX | compute,
                    wgpu::BufferBindingType::Uniform,
                    true,
                    Some(LIGHT_SIZE),
                ),
                buffer(1, compute, read, false, None),
                buffer(2, compute, read, false, None),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: compute,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                buffer(
                    4,
                    compute,
                    wgpu::BufferBindingType::Storage { read_only: false },
                    false,
                    None,
                ),
            ],
        });
        let raster_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shadow.wgsl raster bindings"),
            entries: &[buffer(
                0,
                wgpu::ShaderStages::VERTEX | compute,
                wgpu::BufferBindingType::Uniform,
                true,
                Some(LIGHT_SIZE),
            )],
        });
        (layout, raster_layout)
    }
}

/// What `visibility` measured.
#[derive(Clone, Debug, Default)]
pub struct ShadowStats {
    /// CPU time encoding, submitting and waiting.
    pub seconds: f64,
    /// GPU timestamps of the raster passes, when the adapter has them.
    pub gpu_seconds: Option<f64>,
    pub upload_seconds: f64,
}

/// The sizes of a visibility pass over `points` points from `lights` light samples, each
/// checked against the device: (32-bit words per light, output bytes, workgroups).
fn check_sizes(ctx: &GpuContext, points: usize, lights: usize) -> Result<(u64, u64, u64)> {
    let words = points.div_ceil(32).max(1) as u64;
    let out_bytes = words * 4 * lights as u64;
    let limit = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    let point_bytes = points.max(1) as u64 * 16;
    if out_bytes > limit || point_bytes > limit {
        return Err(Error::GpuLimit(format!(
            "{} points seen from {} light samples need {out_bytes} bytes of visibility bits on \
             the GPU, more than this device's storage limit of {limit} bytes; use fewer light \
             samples or a smaller output image",
            points, lights
        )));
    }
    let groups = words.div_ceil(64);
    if groups > ctx.limits.max_compute_workgroups_per_dimension as u64 {
        return Err(Error::GpuLimit(format!(
            "{} output points exceed one compute dispatch on this device",
            points
        )));
    }
    Ok((words, out_bytes, groups))
}

/// Every light sample's uniform, `stride` bytes apart: its clip matrix relative to `centre`,
/// its position, its reversed-depth constants and the test's biases.
fn light_uniforms(
    lights: &[Camera],
    centre: DVec3,
    bounds: [[f32; 3]; 2],
    stride: u64,
    points: usize,
    words: u64,
    diagonal: f64,
) -> Result<Vec<u8>> {
    let res = lights[0].width;
    let mut uniforms = vec![0u8; (stride * lights.len() as u64) as usize];
    for (s, cam) in lights.iter().enumerate() {
        if (cam.width, cam.height) != (res, res) {
            return Err(Error::Input(
                "light-sample cameras must share one square resolution".into(),
            ));
        }
        let (near, far) = cam.clip_range(bounds);
        let m = cam.projection_matrix(near, far) * cam.view_matrix_relative(centre);
        // Reversed depth with these planes: ndc z = b/d − a (see Camera::projection_matrix).
        let (a, b) = if far.is_finite() {
            (near / (far - near), near * far / (far - near))
        } else {
            (0.0, near)
        };
        let u = LightUniform {
            view_proj: m.as_mat4().to_cols_array_2d(),
            position: (cam.eye() - centre).as_vec3().extend(1.0).to_array(),
            params: [
                a as f32,
                b as f32,
                cam.pixel_footprint(1.0) as f32,
                (ABS_BIAS * diagonal) as f32,
            ],
            sizes: [res, points as u32, (s as u64 * words) as u32, 0],
        };
        let at = s * stride as usize;
        uniforms[at..at + LIGHT_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&u));
    }
    Ok(uniforms)
}

/// What each light sample's two passes (its shadow map, then the test of every point against
/// it) bind.
struct Passes<'a> {
    map_view: &'a wgpu::TextureView,
    raster_bind: &'a wgpu::BindGroup,
    bind: &'a wgpu::BindGroup,
    buffers: &'a SceneBuffers,
    stride: u64,
    groups: u32,
}

impl Passes<'_> {
    /// Encode light sample `s`'s shadow map and test.
    fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        s: usize,
        queries: Option<&Timestamps>,
    ) {
        let pipeline = ctx.shadow_pipeline();
        let offset = (s as u64 * self.stride) as u32;
        {
            let mut rp = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow map"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: self.map_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: queries.map(|t| t.writes(s as u32)),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            rp.set_pipeline(&pipeline.depth);
            rp.set_bind_group(0, self.raster_bind, &[offset]);
            rp.set_vertex_buffer(0, self.buffers.positions.slice(..));
            rp.set_index_buffer(self.buffers.faces.slice(..), wgpu::IndexFormat::Uint32);
            rp.draw_indexed(0..3 * self.buffers.triangle_count, 0, 0..1);
        }
        let mut cp = encoder.begin_compute_pass(&Default::default());
        cp.set_pipeline(&pipeline.test);
        cp.set_bind_group(0, self.bind, &[offset]);
        cp.dispatch_workgroups(self.groups, 1, 1);
    }
}

/// The test pass's bindings (`shadow.wgsl`): the light uniforms, the points and normals
/// relative to the scene centre, the shadow map and the visibility bits.
fn test_bindings(
    ctx: &GpuContext,
    uniform_buf: &wgpu::Buffer,
    map_view: &wgpu::TextureView,
    out: &wgpu::Buffer,
    (points, normals): (&[DVec3], &[DVec3]),
    centre: DVec3,
) -> wgpu::BindGroup {
    use wgpu::util::DeviceExt;
    let device = &ctx.device;
    let rel = |v: &[DVec3], shift: DVec3| -> Vec<[f32; 4]> {
        let mut out: Vec<[f32; 4]> = v
            .iter()
            .map(|p| (*p - shift).as_vec3().extend(0.0).to_array())
            .collect();
        if out.is_empty() {
            out.push([0.0; 4]);
        }
        out
    };
    let points_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("shadow points"),
        contents: bytemuck::cast_slice(&rel(points, centre)),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let normals_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("shadow normals"),
        contents: bytemuck::cast_slice(&rel(normals, DVec3::ZERO)),
        usage: wgpu::BufferUsages::STORAGE,
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("shadow.wgsl bindings"),
        layout: &ctx.shadow_pipeline().layout,
        entries: &[
            uniform_window(0, uniform_buf, LIGHT_SIZE),
            wgpu::BindGroupEntry {
                binding: 1,
                resource: points_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: normals_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(map_view),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: out.as_entire_binding(),
            },
        ],
    })
}

/// The light samples' uniforms, the visibility bits (`out_bytes`) and their readback buffer.
fn visibility_buffers(
    device: &wgpu::Device,
    uniforms: &[u8],
    out_bytes: u64,
) -> (wgpu::Buffer, wgpu::Buffer, wgpu::Buffer) {
    use wgpu::util::DeviceExt;
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("light samples"),
        contents: uniforms,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("visibility bits"),
        size: out_bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("visibility readback"),
        size: out_bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    (uniform_buf, out, readback)
}

/// Visibility bits of every point from every light sample: `lights[s]` is the shadow camera of
/// sample s (all of one square resolution, positioned at the sample); occluders are
/// `vertices`/`faces`; `points` and `normals` (unit, facing the viewer; zero where there is no
/// point) are world space. Returns, per sample, `ceil(P / 32)` words whose bit k of word w is
/// point 32w + k, and the time taken. `diagonal` scales the absolute bias.
#[allow(clippy::too_many_arguments)]
pub fn visibility(
    ctx: &GpuContext,
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    centre: DVec3,
    bounds: [[f32; 3]; 2],
    lights: &[Camera],
    points: &[DVec3],
    normals: &[DVec3],
    diagonal: f64,
) -> Result<(Vec<u32>, ShadowStats)> {
    crate::counters::add(crate::counters::Op::ShadowViews, lights.len() as u64);
    let Some(first) = lights.first() else {
        return Ok((Vec::new(), ShadowStats::default()));
    };
    let res = first.width;
    super::raster::check_image_size(ctx, res, res)?;
    let (words, out_bytes, groups) = check_sizes(ctx, points.len(), lights.len())?;
    let _guard = ctx
        .lock
        .lock()
        .map_err(|_| Error::Gpu("GPU lock poisoned".into()))?;
    let buffers = SceneBuffers::from_triangles(ctx, vertices, faces, centre)?;
    let start = Instant::now();
    let device = &ctx.device;
    let pipeline = ctx.shadow_pipeline();
    let stride = align(
        LIGHT_SIZE,
        ctx.limits.min_uniform_buffer_offset_alignment as u64,
    );
    let uniforms = light_uniforms(
        lights,
        centre,
        bounds,
        stride,
        points.len(),
        words,
        diagonal,
    )?;
    let (uniform_buf, out, readback) = visibility_buffers(device, &uniforms, out_bytes);
    let map = texture_2d(
        device,
        "shadow map",
        (res, res),
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let map_view = map.create_view(&Default::default());
    let bind = test_bindings(
        ctx,
        &uniform_buf,
        &map_view,
        &out,
        (points, normals),
        centre,
    );
    let raster_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("shadow.wgsl raster bindings"),
        layout: &pipeline.raster_layout,
        entries: &[uniform_window(0, &uniform_buf, LIGHT_SIZE)],
    });
    let queries = Timestamps::new(ctx, lights.len() as u32);
    let mut encoder = device.create_command_encoder(&Default::default());
    let passes = Passes {
        map_view: &map_view,
        raster_bind: &raster_bind,
        bind: &bind,
        buffers: &buffers,
        stride,
        groups: groups as u32,
    };
    for s in 0..lights.len() {
        passes.encode(ctx, &mut encoder, s, queries.as_ref());
    }
    encoder.copy_buffer_to_buffer(&out, 0, &readback, 0, out_bytes);
    let submission = submit_readback(ctx, encoder, &readback, queries.as_ref());
    wait(ctx, submission)?;
    let bits: Vec<u32> = {
        let data = readback
            .slice(..)
            .get_mapped_range()
            .map_err(|e| Error::Gpu(format!("mapping the readback buffer failed: {e}")))?;
        bytemuck::cast_slice(&data).to_vec()
    };
    readback.unmap();
    let gpu_seconds = match &queries {
        Some(q) => Some(q.seconds(ctx)?),
        None => None,
    };
    Ok((
        bits,
        ShadowStats {
            seconds: start.elapsed().as_secs_f64(),
            gpu_seconds,
            upload_seconds: buffers.upload_seconds,
        },
    ))
}
