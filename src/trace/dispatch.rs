//! CPU dispatch: a query's work on a chunk of rays ([`Job`]) is compiled once per kernel and
//! run with the widest one this CPU has, chosen at run time: AVX-512 on the Intel Xeon and AMD
//! Zen 5 machines, AVX2 on the AMD machines with AVX2 only, else the portable kernel. Every
//! kernel gives bit-identical hits (`token::force` narrows the choice, for tests).

use super::portable::Portable;
use super::traverse::Kernel;

/// A query's work on one chunk of rays, for any kernel.
pub trait Job: Sync {
    type Out<'o>;
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: Self::Out<'_>);
}

/// Run `job` with the best kernel this CPU has.
#[inline(always)]
pub fn dispatch<J: Job>(job: &J, base: usize, out: J::Out<'_>) {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(k) = super::avx512::Avx512::detect() {
            // SAFETY: the CPU has AVX-512 and AVX2 (the token proves it).
            return unsafe { chunk_avx512(job, k, base, out) };
        }
        if let Some(k) = super::avx2::Avx2::detect() {
            // SAFETY: the CPU has AVX2 (the token proves it).
            return unsafe { chunk_avx2(job, k, base, out) };
        }
    }
    job.chunk(Portable, base, out)
}

/// [`Job::chunk`] compiled for AVX2 (and the VEX encodings, bit scans and popcount that come
/// with it), so the kernel's intrinsics inline.
///
/// # Safety
/// The CPU must support AVX2, BMI1, BMI2, LZCNT and POPCNT (`token::cpu_has`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn chunk_avx2<J: Job>(job: &J, k: super::avx2::Avx2, base: usize, out: J::Out<'_>) {
    job.chunk(k, base, out)
}

/// [`Job::chunk`] compiled for AVX-512 (EVEX encodings: 32 vector registers, mask registers,
/// the compress), so the kernel's intrinsics inline.
///
/// # Safety
/// The CPU must support what `chunk_avx2` needs and AVX-512 F, VL, BW, DQ and CD
/// (`token::cpu_has`).
#[cfg(target_arch = "x86_64")]
#[target_feature(
    enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt,avx512f,avx512vl,avx512bw,avx512dq,avx512cd"
)]
unsafe fn chunk_avx512<J: Job>(job: &J, k: super::avx512::Avx512, base: usize, out: J::Out<'_>) {
    job.chunk(k, base, out)
}
