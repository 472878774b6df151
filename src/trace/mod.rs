//! CPU ray and point queries on our own 8-wide BVH, built once per scene and shared by every
//! query.
//!
//! The folder by concern:
//! - the API: [`api`] (the ray queries and their results), [`query`] (range and threads),
//!   `points` and `winding` (point queries), `crossings`;
//! - one driver every ray query goes through ([`driver`]), which checks the rays, gets the
//!   scene's BVH ([`bvh`]) and runs the query's job on its threads;
//! - scheduling: [`schedule`] (chunks of rays over threads, interruption, progress);
//! - CPU dispatch: [`dispatch`] picks the widest kernel the CPU has at run time (`avx512`,
//!   else `avx2`, both with the packets of `packet`, else `portable`; `token` proves the
//!   instruction set);
//! - the query jobs: [`jobs`] (closest hit, any hit, the k nearest, every hit, counts) over the
//!   shared ray loop of [`rays`] (packets, single rays, rays in turns: `interleave`), with
//!   their sinks ([`sinks`]) and the f64 refinement of each reported hit (`refine`);
//! - the node layout and the kernels: [`node`] (nodes, blocks, references), [`traverse`] (the
//!   kernels' interface and the traversal loop), the watertight triangle test (`watertight`);
//!   `build` makes the tree, `refit` moves it with a posed scene.

pub mod api;
pub mod avx2;
#[cfg(target_arch = "x86_64")]
pub mod avx512;
pub mod build;
pub mod bvh;
pub mod crossings;
pub mod dispatch;
pub mod driver;
pub mod instances;
pub mod interleave;
pub mod jobs;
pub mod node;
#[cfg(target_arch = "x86_64")]
mod packet;
pub mod points;
pub mod portable;
pub mod query;
pub mod rays;
pub mod refine;
pub mod refit;
pub mod schedule;
pub mod sinks;
#[cfg(test)]
pub(crate) mod testdata;
#[cfg(test)]
mod tests;
pub mod token;
pub mod traverse;
pub mod watertight;
pub mod winding;

pub use crate::types::SAME_HIT;
pub use api::{
    all_hits, cast_rays, cast_rays_kept, cast_rays_with, count_hits, nearest_hits,
    nearest_hits_facing, occluded, AllHits, HitCounts, Occlusion, RayHits,
};
pub use bvh::{Bvh, BvhStats, MAX_TRIANGLES, REFIT_LIMIT};
pub use query::{Query, Threads};
pub use rays::INTERLEAVE_BYTES;
