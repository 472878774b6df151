//! Sizes computed from a caller's numbers (rays × `max_hits`, cameras × pixels, views ×
//! resolution², ...) are checked here before anything is allocated: Rust aborts the process
//! when an allocation fails, and with it the Python interpreter and every unsaved result. A
//! request over the limit is an [`Error::Input`] naming its size and the limit instead.

use crate::error::{Error, Result};

/// Bytes per pixel of a depth image: depth, triangle, normal, position and colour.
pub const IMAGE_BYTES: u64 = 4 + 4 + 12 + 12 + 12;

/// What `SCENESAMPLE_MEMORY_LIMIT` (bytes) says, else half of this machine's physical memory
/// (`MemTotal` of /proc/meminfo; 8 GiB where that cannot be read).
pub fn memory_limit() -> u64 {
    if let Some(bytes) = std::env::var("SCENESAMPLE_MEMORY_LIMIT")
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .filter(|&b| b > 0)
    {
        return bytes;
    }
    physical_memory().map_or(8 << 30, |b| b / 2)
}

fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// `Err(Input)` when `count` items of `each` bytes (`what`: the request in the caller's terms,
/// e.g. "1000000 rays x max_hits=100000") exceed the memory limit.
pub fn check(what: impl FnOnce() -> String, count: u128, each: u64) -> Result<()> {
    let need = count.saturating_mul(each as u128);
    let limit = memory_limit();
    if need <= limit as u128 {
        return Ok(());
    }
    Err(Error::Input(format!(
        "{} would take {}, over scenesample's memory limit of {} (half this machine's memory; \
         set SCENESAMPLE_MEMORY_LIMIT, in bytes, to change it)",
        what(),
        gib(need),
        gib(limit as u128)
    )))
}

/// `bytes` in GiB, or in bytes when small.
fn gib(bytes: u128) -> String {
    if bytes < 1 << 20 {
        format!("{bytes} bytes")
    } else {
        format!("{:.2} GiB", bytes as f64 / (1u64 << 30) as f64)
    }
}

/// [`check`] for images of `bytes_per_pixel` bytes per pixel, one per camera ("{what}: N views
/// of WxH pixels"; views of several sizes are summed).
pub fn check_views(what: &str, cameras: &[crate::Camera], bytes_per_pixel: u64) -> Result<()> {
    let pixels: u128 = cameras
        .iter()
        .map(|c| c.width as u128 * c.height as u128)
        .sum();
    check(
        || match cameras.first() {
            Some(c)
                if cameras
                    .iter()
                    .all(|d| (d.width, d.height) == (c.width, c.height)) =>
            {
                format!(
                    "{what}: {} views of {}x{} pixels",
                    cameras.len(),
                    c.width,
                    c.height
                )
            }
            _ => format!("{what}: {} views, {pixels} pixels in all", cameras.len()),
        },
        pixels,
        bytes_per_pixel,
    )
}

/// The product of `factors`, without overflow (sizes past u128 saturate, and fail any check).
pub fn product(factors: &[u64]) -> u128 {
    factors
        .iter()
        .fold(1u128, |p, &f| p.saturating_mul(f as u128))
}

/// Ask the kernel to back `v`'s memory with transparent huge pages where it can (Linux's
/// `MADV_HUGEPAGE`; a hint, ignored elsewhere or when refused). For large arrays written once
/// into freshly mapped memory (images, a refit tree's nodes and blocks): one fault per 2 MiB
/// instead of one per 4 KiB takes most of what the first write cost. What the memory holds is
/// the same either way.
pub fn huge_pages<T>(v: &[T]) {
    advise(v, false);
}

/// Move `v`'s memory, already written, onto transparent huge pages in place where the kernel
/// can (Linux 6.1's `MADV_COLLAPSE`; nothing happens elsewhere, or where it refuses): for large
/// arrays read at random for a long time after (a tree that rays visit all over misses the TLB
/// on most visits with 4 KiB pages). No copy is made, so the peak memory does not grow; what
/// the memory holds is the same either way.
pub fn collapse_to_huge_pages<T>(v: &[T]) {
    advise(v, true);
}

fn advise<T>(v: &[T], collapse: bool) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let (start, len) = (v.as_ptr() as usize, std::mem::size_of_val(v));
        let first = start.next_multiple_of(HUGE);
        let last = (start + len) / HUGE * HUGE;
        if last > first {
            let range = (first as *mut libc::c_void, last - first);
            // SAFETY: the range lies inside `v`'s allocation, and neither advice changes what
            // it holds, only how the kernel backs it.
            unsafe {
                libc::madvise(range.0, range.1, libc::MADV_HUGEPAGE);
                if collapse {
                    libc::madvise(range.0, range.1, libc::MADV_COLLAPSE);
                }
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (v, collapse);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_size_over_the_limit_names_itself_and_the_limit() {
        assert!(check(|| "small".into(), 1000, 4).is_ok());
        let e = check(
            || "1000000 rays x max_hits=100000".into(),
            product(&[1_000_000, 100_000]),
            16,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("1000000 rays x max_hits=100000 would take 1490.12 GiB"),
            "{e}"
        );
        assert!(
            e.contains("memory limit of") && e.contains("SCENESAMPLE_MEMORY_LIMIT"),
            "{e}"
        );
        assert!(check(|| "huge".into(), product(&[u64::MAX, u64::MAX, 7]), 8).is_err());
        assert!(memory_limit() > 0);
    }
}
