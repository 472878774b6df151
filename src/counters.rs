//! Process-wide counts of the expensive operations, so that a caller (the effect planner's
//! tests) can prove which ones ran: cube maps built, splat passes, shadow-map views, rays cast.

use std::sync::atomic::{AtomicU64, Ordering};

pub static CUBE_MAPS: AtomicU64 = AtomicU64::new(0);
pub static SPLAT_PASSES: AtomicU64 = AtomicU64::new(0);
pub static SHADOW_VIEWS: AtomicU64 = AtomicU64::new(0);
pub static RAYS_CAST: AtomicU64 = AtomicU64::new(0);

pub fn add(counter: &AtomicU64, n: u64) {
    counter.fetch_add(n, Ordering::Relaxed);
}

/// (name, count) of every counter.
pub fn snapshot() -> Vec<(&'static str, u64)> {
    [
        ("cube_maps", &CUBE_MAPS),
        ("splat_passes", &SPLAT_PASSES),
        ("shadow_views", &SHADOW_VIEWS),
        ("rays_cast", &RAYS_CAST),
    ]
    .into_iter()
    .map(|(k, c)| (k, c.load(Ordering::Relaxed)))
    .collect()
}
