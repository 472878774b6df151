//! How a query's rays are spread over threads: chunks of [`CHUNK`] rays, on the calling thread,
//! rayon's pool of every core, or a pool of a given size; each chunk checks for an interruption
//! and reports its progress.

use std::mem::MaybeUninit;

use rayon::prelude::*;

use super::query::{Query, Threads};
use crate::error::Result;

/// Rays per parallel task.
pub const CHUNK: usize = 1024;

/// Output slices that split into matching chunks of `k` entries per ray.
pub trait Chunks: Send + Sized {
    fn rays(&self, k: usize) -> usize;
    fn split(self, at: usize) -> (Self, Self);
}

impl<T: Send> Chunks for &mut [T] {
    fn rays(&self, k: usize) -> usize {
        self.len() / k
    }
    fn split(self, at: usize) -> (Self, Self) {
        self.split_at_mut(at)
    }
}

/// `t`, triangle and barycentric per hit.
pub type HitSlices<'o> = (&'o mut [f32], &'o mut [i32], &'o mut [[f32; 2]]);

/// The memory of [`HitSlices`] not yet written: a fresh output, which each chunk's job fills
/// (`jobs::no_hits`) on the thread that runs it.
pub type FreshHits<'o> = (
    &'o mut [MaybeUninit<f32>],
    &'o mut [MaybeUninit<i32>],
    &'o mut [MaybeUninit<[f32; 2]>],
);

impl<A: Send, B: Send, C: Send> Chunks for (&mut [A], &mut [B], &mut [C]) {
    fn rays(&self, k: usize) -> usize {
        self.0.len() / k
    }
    fn split(self, at: usize) -> (Self, Self) {
        let (t0, t1) = self.0.split_at_mut(at);
        let (i0, i1) = self.1.split_at_mut(at);
        let (b0, b1) = self.2.split_at_mut(at);
        ((t0, i0, b0), (t1, i1, b1))
    }
}

/// Run `f(first ray, its chunk of out)` over `out` in chunks of [`CHUNK`] rays, on `q.threads`;
/// every chunk first checks for an interruption (`process::check`), and with `q.report` counts
/// its rays as the call's progress once done.
pub fn run<O: Chunks>(q: &Query, out: O, k: usize, f: impl Fn(usize, O) + Sync) -> Result<()> {
    let rays = out.rays(k);
    let mut chunks = Vec::with_capacity(rays.div_ceil(CHUNK));
    let mut rest = out;
    while rest.rays(k) > CHUNK {
        let (a, b) = rest.split(CHUNK * k);
        chunks.push(a);
        rest = b;
    }
    chunks.push(rest);
    each_chunk(q, rays, chunks, |c, o: O| {
        f(c * CHUNK, o);
        Ok(())
    })?;
    Ok(())
}

/// `f(chunk index, its ray count)` for each chunk of [`CHUNK`] of `n` rays, on `q.threads`, as
/// [`run`] does; the results in chunk order (for queries whose output per ray is ragged).
pub fn collect<T: Send>(
    q: &Query,
    n: usize,
    f: impl Fn(usize, usize) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let lens: Vec<usize> = (0..n.div_ceil(CHUNK))
        .map(|c| CHUNK.min(n - c * CHUNK))
        .collect();
    each_chunk(q, n, lens, f)
}

/// The shared loop of [`run`] and [`collect`]: `f(index, item)` for each item, with the
/// interruption check before and the progress after, in order on one thread or in parallel.
fn each_chunk<I: Send, T: Send>(
    q: &Query,
    rays: usize,
    items: Vec<I>,
    f: impl Fn(usize, I) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let progress = q.report.then(crate::process::counter).flatten();
    if let Some(p) = &progress {
        p.add_total(rays as u64);
    }
    let each = |(c, item): (usize, I)| {
        crate::process::check()?;
        let len = CHUNK.min(rays.saturating_sub(c * CHUNK)) as u64;
        let out = f(c, item)?;
        if let Some(p) = &progress {
            p.advance(len);
        }
        Ok(out)
    };
    if q.threads == Threads::One {
        items.into_iter().enumerate().map(each).collect()
    } else {
        items.into_par_iter().enumerate().map(each).collect()
    }
}

/// Run `f` where `threads` says: on the calling thread, or inside this process's pool of all
/// cores or of `n` threads (so every parallel step of `f` stays on those).
pub fn on_threads<R: Send>(threads: Threads, f: impl FnOnce() -> R + Send) -> Result<R> {
    match threads {
        Threads::One => Ok(f()),
        Threads::All => crate::process::install(None, f),
        Threads::Count(n) => crate::process::install(Some(n.get()), f),
    }
}
