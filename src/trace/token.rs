//! Proof that the running CPU has an instruction set: a token that only its `detect` makes, so a
//! function that takes one may use the instructions (the kernels in `avx2` and `avx512`, the
//! packets in `packet`). A narrower kernel can be forced for the whole process ([`force`]):
//! every kernel gives bit-identical answers, so this changes only speed, and lets one machine
//! check the narrower kernels' code against the wide code it would otherwise run.

use std::sync::atomic::{AtomicU8, Ordering};

/// The CPU kernels, widest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    Avx512 = 0,
    Avx2 = 1,
    Portable = 2,
}

impl Level {
    pub fn name(self) -> &'static str {
        match self {
            Level::Avx512 => "avx512",
            Level::Avx2 => "avx2",
            Level::Portable => "portable",
        }
    }

    /// The level of a kernel's name ([`Level::name`]).
    pub fn named(name: &str) -> Option<Self> {
        [Level::Avx512, Level::Avx2, Level::Portable]
            .into_iter()
            .find(|l| l.name() == name)
    }
}

/// The widest kernel queries may use ([`force`]); [`Level::Avx512`]: the best the CPU has.
static CEILING: AtomicU8 = AtomicU8::new(Level::Avx512 as u8);

fn allowed(level: Level) -> bool {
    CEILING.load(Ordering::Relaxed) <= level as u8
}

/// Proof that the running CPU supports AVX2.
#[derive(Clone, Copy, Debug)]
pub struct Avx2(());

impl Avx2 {
    /// The token, where the CPU has AVX2 and no narrower kernel is forced.
    pub fn detect() -> Option<Self> {
        (allowed(Level::Avx2) && cpu_has(Level::Avx2)).then_some(Self(()))
    }
}

/// Proof that the running CPU supports AVX-512 (F, VL, BW, DQ and CD) and AVX2.
#[derive(Clone, Copy, Debug)]
pub struct Avx512(Avx2);

impl Avx512 {
    /// The token, where the CPU has AVX-512 and no narrower kernel is forced.
    pub fn detect() -> Option<Self> {
        (allowed(Level::Avx512) && cpu_has(Level::Avx512)).then_some(Self(Avx2(())))
    }

    /// AVX-512 implies AVX2.
    pub fn avx2(self) -> Avx2 {
        self.0
    }
}

/// Whether the CPU has the instructions of `level` (whatever kernel is forced).
pub fn cpu_has(level: Level) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt");
        match level {
            Level::Portable => true,
            Level::Avx2 => avx2,
            Level::Avx512 => {
                avx2 && is_x86_feature_detected!("avx512f")
                    && is_x86_feature_detected!("avx512vl")
                    && is_x86_feature_detected!("avx512bw")
                    && is_x86_feature_detected!("avx512dq")
                    && is_x86_feature_detected!("avx512cd")
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        level == Level::Portable
    }
}

/// Run every later CPU query of this process on a kernel no wider than `widest` (the portable
/// one: [`Level::Portable`]; the best the CPU has again: [`Level::Avx512`]). Queries already
/// running keep the kernel they started with.
pub fn force(widest: Level) {
    CEILING.store(widest as u8, Ordering::Relaxed);
}

/// The kernel the next CPU query runs on.
pub fn kernel() -> Level {
    if Avx512::detect().is_some() {
        Level::Avx512
    } else if Avx2::detect().is_some() {
        Level::Avx2
    } else {
        Level::Portable
    }
}
