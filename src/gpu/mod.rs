//! The GPU: one wgpu device per process, created lazily and reused; scene buffers uploaded once
//! per scene; pipelines compiled once. Headless (no window or surface).

pub mod depth;
pub mod layered;
pub mod raster;
pub mod shadow;
pub mod splat;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use crate::error::{Error, Result};
use crate::scene::Scene;

/// Features the raster passes need; `PRIMITIVE_INDEX` gives the triangle id of each fragment.
const REQUIRED: wgpu::Features = wgpu::Features::PRIMITIVE_INDEX;

/// The process-wide device, its queue and what it can do.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    pub timestamps: bool,
    /// Which context of this process's lineage this is: buffers made for another (a parent's,
    /// before a fork) are not used with it.
    pub serial: u64,
    /// Errors wgpu reports asynchronously (validation, out of memory, device loss); drained
    /// after each submission and turned into `Error::Gpu`, so none of them panics.
    errors: Arc<Mutex<Vec<String>>>,
    /// Serialises submissions from several Python threads.
    pub(crate) lock: Mutex<()>,
    depth_pipeline: OnceLock<depth::DepthPipeline>,
    layered_pipeline: OnceLock<layered::LayeredPipeline>,
    shadow_pipeline: OnceLock<shadow::ShadowPipeline>,
    splat_pipeline: OnceLock<splat::SplatPipeline>,
}

/// The context (or why there is none) and the process that made it.
struct Made {
    pid: u32,
    context: std::result::Result<Arc<GpuContext>, String>,
}

static CONTEXT: Mutex<Option<Made>> = Mutex::new(None);

/// Contexts made so far in this process's lineage; each gets the next number.
static SERIAL: AtomicU64 = AtomicU64::new(0);

/// The shared GPU context, created on first call. Fails with `GpuUnavailable` when no adapter
/// with the required features exists. A child forked after the parent made its context makes
/// its own: the driver's threads and the device's state stayed in the parent.
pub fn context() -> Result<Arc<GpuContext>> {
    let pid = std::process::id();
    let mut slot = CONTEXT.lock().unwrap_or_else(|e| e.into_inner());
    if slot.as_ref().is_some_and(|m| m.pid != pid) {
        // Dropping the parent's device would call into a driver whose threads are gone.
        std::mem::forget(slot.take());
    }
    slot.get_or_insert_with(|| Made {
        pid,
        context: create().map(Arc::new),
    })
    .context
    .clone()
    .map_err(Error::GpuUnavailable)
}

const NO_ADAPTER_HELP: &str = "On a machine without a GPU, Mesa's software Vulkan driver \
provides one: install the Debian/Ubuntu package `mesa-vulkan-drivers` \
(apt-get install -y mesa-vulkan-drivers).";

fn create() -> std::result::Result<GpuContext, String> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::VULKAN;
    let instance = wgpu::Instance::new(desc);
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        apply_limit_buckets: false,
    }))
    .map_err(|e| format!("no Vulkan adapter found ({e}). {NO_ADAPTER_HELP}"))?;
    let info = adapter.get_info();
    let features = adapter.features();
    if !features.contains(REQUIRED) {
        return Err(format!(
            "the adapter '{}' ({:?}) lacks the feature PRIMITIVE_INDEX needed for triangle ids. \
             {NO_ADAPTER_HELP}",
            info.name, info.backend
        ));
    }
    let timestamps = features.contains(wgpu::Features::TIMESTAMP_QUERY);
    let mut wanted = REQUIRED;
    if timestamps {
        wanted |= wgpu::Features::TIMESTAMP_QUERY;
    }
    for f in [
        wgpu::Features::SHADER_INT64,
        wgpu::Features::SHADER_INT64_ATOMIC_MIN_MAX,
    ] {
        if features.contains(f) {
            wanted |= f;
        }
    }
    let limits = adapter.limits();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("scenesample"),
        required_features: wanted,
        required_limits: limits.clone(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| {
        format!(
            "could not open the adapter '{}': {e}. {NO_ADAPTER_HELP}",
            info.name
        )
    })?;
    let errors = Arc::new(Mutex::new(Vec::new()));
    let sink = errors.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        if let Ok(mut v) = sink.lock() {
            v.push(e.to_string());
        }
    }));
    Ok(GpuContext {
        device,
        queue,
        info,
        limits,
        timestamps,
        serial: SERIAL.fetch_add(1, Ordering::Relaxed) + 1,
        errors,
        lock: Mutex::new(()),
        depth_pipeline: OnceLock::new(),
        layered_pipeline: OnceLock::new(),
        shadow_pipeline: OnceLock::new(),
        splat_pipeline: OnceLock::new(),
    })
}

impl GpuContext {
    /// Raise any error wgpu reported since the last check.
    pub fn check_errors(&self) -> Result<()> {
        let mut errs = self
            .errors
            .lock()
            .map_err(|_| Error::Gpu("GPU error log poisoned".into()))?;
        if errs.is_empty() {
            return Ok(());
        }
        let msg = errs.join("; ");
        errs.clear();
        Err(Error::Gpu(format!("the GPU reported: {msg}")))
    }

    pub fn depth_pipeline(&self) -> &depth::DepthPipeline {
        self.depth_pipeline
            .get_or_init(|| depth::DepthPipeline::new(&self.device))
    }

    pub fn layered_pipeline(&self) -> &layered::LayeredPipeline {
        self.layered_pipeline
            .get_or_init(|| layered::LayeredPipeline::new(&self.device))
    }

    pub fn shadow_pipeline(&self) -> &shadow::ShadowPipeline {
        self.shadow_pipeline
            .get_or_init(|| shadow::ShadowPipeline::new(&self.device))
    }

    pub fn splat_pipeline(&self) -> &splat::SplatPipeline {
        self.splat_pipeline
            .get_or_init(|| splat::SplatPipeline::new(&self.device))
    }
}

/// What `scenesample.device_info()` reports.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    pub timestamps: bool,
    pub max_texture_dimension_2d: u32,
    pub max_storage_buffer_binding_size: u64,
}

pub fn device_info() -> Result<DeviceInfo> {
    let ctx = context()?;
    Ok(DeviceInfo {
        name: ctx.info.name.clone(),
        backend: format!("{:?}", ctx.info.backend),
        device_type: format!("{:?}", ctx.info.device_type),
        driver: format!("{} {}", ctx.info.driver, ctx.info.driver_info),
        timestamps: ctx.timestamps,
        max_texture_dimension_2d: ctx.limits.max_texture_dimension_2d,
        max_storage_buffer_binding_size: ctx.limits.max_storage_buffer_binding_size as u64,
    })
}

/// A scene's geometry on the GPU: vertex positions relative to the scene centre (vertex buffer)
/// and the faces (index buffer), both also readable as storage (the splat pass reads triangles).
#[derive(Debug)]
pub struct SceneBuffers {
    pub positions: wgpu::Buffer,
    pub faces: wgpu::Buffer,
    pub triangle_count: u32,
    pub upload_seconds: f64,
    /// The `GpuContext::serial` of the device they live on.
    pub serial: u64,
    /// The faces without their duplicates, made on first use by the layered passes.
    distinct: OnceLock<Option<Distinct>>,
}

/// A scene's faces with every duplicate removed (a face with the same three vertex positions
/// as an earlier one, in any order or winding), as an index buffer, and the triangle id of
/// each face it keeps. Duplicated faces are one surface: drawn once, a non-redundant pass's
/// "same triangle at that pixel" test sees them as the same triangle, and a peeling pass
/// never peels one from under the other.
#[derive(Debug)]
pub struct Distinct {
    pub faces: wgpu::Buffer,
    /// Triangle id of each kept face (index into the scene's faces).
    pub triangles: Vec<u32>,
    /// The kept face that stands for each triangle (itself or the first of its duplicates).
    pub slot_of: Vec<u32>,
}

impl Distinct {
    /// Maps the kept faces' indices an id pass wrote back to triangle ids (negatives, "no
    /// triangle", stay as they are).
    pub fn triangle_ids(&self, ids: &[i32]) -> Vec<i32> {
        ids.iter()
            .map(|&t| {
                if t < 0 {
                    t
                } else {
                    self.triangles[t as usize] as i32
                }
            })
            .collect()
    }

    /// The inverse: triangle ids (an image made elsewhere: the CPU backend's) to the kept
    /// faces an id pass would have written for them.
    pub fn slots(&self, ids: &[i32]) -> Vec<i32> {
        ids.iter()
            .map(|&t| {
                if t < 0 {
                    t
                } else {
                    self.slot_of[t as usize] as i32
                }
            })
            .collect()
    }
}

/// A scene's buffers on the current device, cached on the scene; a Mutex because the upload can
/// fail, and a forked child replaces its parent's.
#[derive(Default)]
pub struct SceneGpu(Mutex<Option<Arc<SceneBuffers>>>);

impl SceneBuffers {
    /// Whether the scene's buffers are on `ctx`'s device already.
    pub fn cached(ctx: &GpuContext, scene: &Scene) -> bool {
        scene.derived_if_built::<SceneGpu>().is_some_and(|c| {
            c.0.lock()
                .map(|s| s.as_ref().is_some_and(|b| b.serial == ctx.serial))
                .unwrap_or(false)
        })
    }

    /// The scene's buffers, uploaded on first use and cached on the scene.
    pub fn of(ctx: &GpuContext, scene: &Scene) -> Result<Arc<SceneBuffers>> {
        let cache = scene.derived(SceneGpu::default);
        let mut slot = cache
            .0
            .lock()
            .map_err(|_| Error::Gpu("scene GPU cache poisoned".into()))?;
        match slot.as_ref() {
            Some(b) if b.serial == ctx.serial => return Ok(b.clone()),
            // Made on the parent's device before a fork: leave them be (dropping them would
            // call into the parent's driver) and upload to this one.
            Some(_) => std::mem::forget(slot.take()),
            None => {}
        }
        let b = Arc::new(Self::upload(ctx, scene)?);
        *slot = Some(b.clone());
        Ok(b)
    }

    /// The scene's faces without duplicates; `None` when it has none.
    pub fn distinct(&self, ctx: &GpuContext, scene: &Scene) -> Option<&Distinct> {
        self.distinct
            .get_or_init(|| {
                use wgpu::util::DeviceExt;
                let (keep, slot_of) = distinct_faces(scene.vertices(), scene.faces())?;
                let faces: Vec<u32> = keep
                    .iter()
                    .flat_map(|&t| scene.faces()[t as usize])
                    .collect();
                let faces = ctx
                    .device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("distinct faces"),
                        contents: bytemuck::cast_slice(&faces),
                        usage: wgpu::BufferUsages::INDEX,
                    });
                Some(Distinct {
                    faces,
                    triangles: keep,
                    slot_of,
                })
            })
            .as_ref()
    }

    fn upload(ctx: &GpuContext, scene: &Scene) -> Result<Self> {
        Self::from_triangles(ctx, scene.vertices(), scene.faces(), scene.center())
    }

    /// Upload any triangles, positions relative to `centre` (formed in f64, rounded to f32).
    pub fn from_triangles(
        ctx: &GpuContext,
        vertices: &[[f32; 3]],
        faces: &[[u32; 3]],
        centre: glam::DVec3,
    ) -> Result<Self> {
        use wgpu::util::DeviceExt;
        let start = std::time::Instant::now();
        let c = centre;
        let rel: Vec<f32> = vertices
            .iter()
            .flat_map(|v| [0, 1, 2].map(|k| (v[k] as f64 - c[k]) as f32))
            .collect();
        let faces: Vec<u32> = faces.iter().flatten().copied().collect();
        let limit = ctx.limits.max_buffer_size;
        for (name, bytes) in [
            ("vertex positions", rel.len() * 4),
            ("faces", faces.len() * 4),
        ] {
            if bytes as u64 > limit {
                return Err(Error::GpuLimit(format!(
                    "the {name} take {bytes} bytes, more than this device's buffer limit of \
                     {limit} bytes; split the geometry"
                )));
            }
        }
        // wgpu rejects empty buffers' bindings; keep one degenerate triangle's worth.
        let pad = |mut v: Vec<u8>| {
            if v.is_empty() {
                v.resize(12, 0);
            }
            v
        };
        let positions = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("positions"),
                contents: &pad(bytemuck::cast_slice(&rel).to_vec()),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE,
            });
        let faces_buf = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("faces"),
                contents: &pad(bytemuck::cast_slice(&faces).to_vec()),
                usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::STORAGE,
            });
        ctx.check_errors()?;
        Ok(Self {
            positions,
            faces: faces_buf,
            triangle_count: (faces.len() / 3) as u32,
            upload_seconds: start.elapsed().as_secs_f64(),
            serial: ctx.serial,
            distinct: OnceLock::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    /// Every shader in shaders/ must parse and validate; needs no GPU.
    #[test]
    fn every_shader_validates_with_naga() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().and_then(|e| e.to_str()) != Some("wgsl") {
                continue;
            }
            let src = std::fs::read_to_string(&path).unwrap();
            let module = naga::front::wgsl::parse_str(&src)
                .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&src)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::all(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {}", path.display(), e.emit_to_string(&src)));
            count += 1;
        }
        assert!(count > 0, "no shaders found in {}", dir.display());
    }
}

/// The ids of the faces that are not duplicates of an earlier face (same three vertex
/// positions, bit for bit, in any order), and for every face the index among those of the one
/// it duplicates (or of itself); `None` when no face is a duplicate.
pub fn distinct_faces(vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Option<(Vec<u32>, Vec<u32>)> {
    let key = |f: &[u32; 3]| {
        let mut c = f.map(|i| vertices[i as usize].map(f32::to_bits));
        c.sort_unstable();
        c
    };
    let mut first = std::collections::HashMap::with_capacity(faces.len());
    let mut keep = Vec::new();
    let slot_of: Vec<u32> = (0..faces.len() as u32)
        .map(|t| {
            *first.entry(key(&faces[t as usize])).or_insert_with(|| {
                keep.push(t);
                keep.len() as u32 - 1
            })
        })
        .collect();
    (keep.len() < faces.len()).then_some((keep, slot_of))
}

#[cfg(test)]
mod distinct_tests {
    use super::distinct_faces;

    #[test]
    fn duplicates_in_any_order_or_winding_are_dropped() {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        // Face 1 repeats face 0 reversed; face 2 names the same corner through vertex 3.
        let f = [[0, 1, 2], [2, 1, 0], [0, 3, 2], [0, 1, 4]];
        assert_eq!(distinct_faces(&v, &f), Some((vec![0, 3], vec![0, 0, 0, 1])));
        assert_eq!(distinct_faces(&v, &[[0, 1, 2], [0, 1, 4]]), None);
    }
}
