//! CPU dispatch: a query's work on a chunk of rays ([`Job`]) is compiled once per kernel and
//! run with the best one this CPU has, chosen at run time: AVX2 where the CPU has it (on the
//! AMD machines with AVX2 only and the Intel ones with AVX-512 alike), else the portable kernel.
//! Both give bit-identical hits.

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
    if let Some(k) = super::avx2::Avx2::detect() {
        // SAFETY: the CPU has AVX2 (the token proves it).
        return unsafe { chunk_avx2(job, k, base, out) };
    }
    job.chunk(Portable, base, out)
}

/// [`Job::chunk`] compiled for AVX2 (and the VEX encodings, bit scans and popcount that come
/// with it), so the kernel's intrinsics inline.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn chunk_avx2<J: Job>(job: &J, k: super::avx2::Avx2, base: usize, out: J::Out<'_>) {
    job.chunk(k, base, out)
}
