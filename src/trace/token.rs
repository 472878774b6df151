//! Proof that the running CPU has an instruction set: a token that only its `detect` makes, so a
//! function that takes one may use the instructions (the kernel in `avx2`, the packets in
//! `packet`). The portable kernel can be forced for the whole process ([`force_portable`]):
//! every kernel gives bit-identical answers, so this changes only speed, and lets one machine
//! check the portable code against the vector code it would otherwise never run.

use std::sync::atomic::{AtomicBool, Ordering};

/// Proof that the running CPU supports AVX2.
#[derive(Clone, Copy, Debug)]
pub struct Avx2(());

/// Whether the portable kernel is forced ([`force_portable`]).
static PORTABLE: AtomicBool = AtomicBool::new(false);

impl Avx2 {
    /// The token, where the CPU has AVX2 and the portable kernel is not forced.
    pub fn detect() -> Option<Self> {
        (cpu_has_avx2() && !PORTABLE.load(Ordering::Relaxed)).then_some(Self(()))
    }
}

/// Whether the CPU has AVX2 (whatever kernel is forced).
pub fn cpu_has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Run every later CPU query of this process on the portable kernel (`true`), or on the best the
/// CPU has again (`false`). Queries already running keep the kernel they started with.
pub fn force_portable(on: bool) {
    PORTABLE.store(on, Ordering::Relaxed);
}

/// The kernel the next CPU query runs on: `"avx2"` or `"portable"`.
pub fn kernel_name() -> &'static str {
    if Avx2::detect().is_some() {
        "avx2"
    } else {
        "portable"
    }
}
