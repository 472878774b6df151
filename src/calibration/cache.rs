//! The calibration file: the model of each machine key, in `$SCENESAMPLE_CACHE_DIR` (set it
//! empty to switch the file off), else `$XDG_CACHE_HOME/scenesample`, else
//! `~/.cache/scenesample`. A machine key the file does not hold (another package version, CPU,
//! thread count or adapter), or a file that does not parse, is measured anew and added.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::{CostModel, CpuCosts, GpuCosts};

const FILE: &str = "cost-model.json";
/// Machine keys one file keeps.
const KEEP: usize = 8;
/// Bumped when the model's formulas or probes change, so that older files are not used (2:
/// the CPU backend settles edge pixels by the raster's rule; 3: its per-triangle cost is
/// per image, and the probes see their scene as orbiting views see theirs).
const FORMAT: u32 = 3;

pub fn path() -> Option<PathBuf> {
    let dir = match std::env::var_os("SCENESAMPLE_CACHE_DIR") {
        Some(d) if d.is_empty() => return None,
        Some(d) => PathBuf::from(d),
        None => match std::env::var_os("XDG_CACHE_HOME").filter(|d| !d.is_empty()) {
            Some(d) => PathBuf::from(d).join("scenesample"),
            None => PathBuf::from(std::env::var_os("HOME")?).join(".cache/scenesample"),
        },
    };
    Some(dir.join(FILE))
}

pub fn display(p: &Path) -> String {
    p.display().to_string()
}

/// How long a process waits for another's probes before it gives up on the file.
const LOCK_WAIT: Duration = Duration::from_secs(60);

/// Run `f` holding an exclusive lock on `<file>.lock` beside the calibration file, waiting
/// (and polling for Ctrl-C) while another process holds it. `Ok(Err(why))` when no lock
/// can be had: no directory or lock file can be made, or another process held it for
/// [`LOCK_WAIT`]. The operating system releases the lock of a process that dies.
pub fn locked<T>(
    path: &Path,
    f: impl FnOnce() -> crate::error::Result<T>,
) -> crate::error::Result<std::result::Result<T, String>> {
    let lock = path.with_extension("lock");
    let opened = path
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|()| {
            std::fs::OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&lock)
        });
    let file = match opened {
        Ok(f) => f,
        Err(e) => return Ok(Err(format!("no lock file {}: {e}", lock.display()))),
    };
    let start = Instant::now();
    loop {
        match file.try_lock() {
            Ok(()) => break,
            Err(std::fs::TryLockError::WouldBlock) if start.elapsed() < LOCK_WAIT => {
                crate::process::check()?;
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(e) => return Ok(Err(format!("{} not locked: {e}", lock.display()))),
        }
    }
    let r = f();
    let _ = file.unlock();
    r.map(Ok)
}

/// What the coefficients depend on: the package and the hash of the sources it was built
/// from (`build.rs`: a rebuilt engine may be faster), the CPU model, the worker threads, and
/// the adapter (its name and driver; "none" without one).
pub fn machine(adapter: Option<&wgpu::AdapterInfo>) -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let gpu = adapter.map_or_else(
        || "none".to_string(),
        |a| format!("{} ({} {})", a.name, a.driver, a.driver_info),
    );
    format!(
        "{}; cpu {cpu}; {} threads; gpu {gpu}",
        build(),
        rayon::current_num_threads()
    )
}

/// The part of a machine key that names this build: the package, its sources' hash and the
/// file's format.
pub fn build() -> String {
    format!(
        "scenesample {} ({}) format {FORMAT}",
        env!("CARGO_PKG_VERSION"),
        env!("SCENESAMPLE_SOURCE_HASH")
    )
}

pub fn to_json(model: &CostModel, machine: &str) -> Value {
    let c = &model.cpu;
    let gpu = model.gpu.as_ref().ok().map(|g| {
        json!({
            "per_call": g.per_call,
            "per_triangle": g.per_triangle,
            "per_pixel": g.per_pixel,
            "per_box_pixel": g.per_box_pixel,
            "upload_per_triangle": g.upload_per_triangle,
        })
    });
    json!({
        "machine": machine,
        "probe_seconds": model.calibration_seconds,
        "cpu": {
            "per_call": c.per_call,
            "per_image_triangle": c.per_image_triangle,
            "per_pixel": c.per_pixel,
            "per_box_ray": c.per_box_ray,
            "per_box_ray_log2": c.per_box_ray_log2,
            "build_per_triangle": c.build_per_triangle,
        },
        "gpu": gpu,
    })
}

/// The CPU and (with an adapter) GPU coefficients of `v`, if it was made for `machine` and
/// every coefficient is a finite number.
pub fn from_json(v: &Value, machine: &str) -> Option<(CpuCosts, Option<GpuCosts>)> {
    if v.get("machine")?.as_str()? != machine {
        return None;
    }
    let num = |o: &Value, k: &str| o.get(k)?.as_f64().filter(|x| x.is_finite());
    let c = v.get("cpu")?;
    let cpu = CpuCosts {
        per_call: num(c, "per_call")?,
        per_image_triangle: num(c, "per_image_triangle")?,
        per_pixel: num(c, "per_pixel")?,
        per_box_ray: num(c, "per_box_ray")?,
        per_box_ray_log2: num(c, "per_box_ray_log2")?,
        build_per_triangle: num(c, "build_per_triangle")?,
    };
    let gpu = match v.get("gpu")? {
        Value::Null => None,
        g => Some(GpuCosts {
            per_call: num(g, "per_call")?,
            per_triangle: num(g, "per_triangle")?,
            per_pixel: num(g, "per_pixel")?,
            per_box_pixel: num(g, "per_box_pixel")?,
            upload_per_triangle: num(g, "upload_per_triangle")?,
        }),
    };
    Some((cpu, gpu))
}

/// The models in the file, by machine key (a file that does not parse holds none).
fn models(path: &Path) -> serde_json::Map<String, Value> {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .and_then(|v| v.get("models")?.as_object().cloned())
        .unwrap_or_default()
}

pub fn read(path: &Path, machine: &str) -> Option<(CpuCosts, Option<GpuCosts>)> {
    from_json(models(path).get(machine)?, machine)
}

/// Add (or replace) `machine`'s model in the file, keeping the other machines' (a home
/// shared by several hosts, or runs with Vulkan hidden), at most [`KEEP`] of them. Written
/// through a temporary file renamed into place, so that a process reading it meanwhile sees
/// the old file or the new one, never half of one.
pub fn write(path: &Path, machine: &str, model: &CostModel) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let mut all = models(path);
    all.remove(machine);
    // Other builds' models go first (an older build's can never be read again by this one),
    // so that a full file never loses a model this build's processes are reading: one that
    // another process then measured again would decide differently (same call, same result).
    let ours = format!("{}; ", build());
    while all.len() >= KEEP {
        let victim = all.keys().find(|k| !k.starts_with(&ours));
        let Some(victim) = victim.or_else(|| all.keys().next()).cloned() else {
            break;
        };
        all.remove(&victim);
    }
    all.insert(machine.to_string(), to_json(model, machine));
    let tmp = path.with_extension(format!("json.{}", std::process::id()));
    std::fs::write(&tmp, json!({ "models": all }).to_string())?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}
