//! Proof that the running CPU has an instruction set: a token that only its `detect` makes, so a
//! function that takes one may use the instructions (the kernel in `avx2`, the packets in
//! `packet`).

/// Proof that the running CPU supports AVX2.
#[derive(Clone, Copy, Debug)]
pub struct Avx2(());

impl Avx2 {
    pub fn detect() -> Option<Self> {
        is_x86_feature_detected!("avx2").then_some(Self(()))
    }
}
