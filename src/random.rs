//! Seeded, counter-based random numbers, the same on every thread count: SplitMix64's
//! finaliser hashes a seed and a counter, so a sample's number depends only on its index.

/// SplitMix64's finaliser: a well-mixed 64-bit hash of `z`.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
