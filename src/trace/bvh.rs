//! A scene's BVH: built once on first use (every core, or the calling thread), cached with the
//! scene, and for a posed scene refit from its base's object trees (`refit`).

use std::sync::Arc;
use std::time::Instant;

use glam::{DMat4, Vec3, Vec3A};

use super::node::{self, Bvh8};
use super::query::Threads;
use super::watertight::Tri;
use super::{build, instances, refit};
use crate::error::Result;
use crate::input_err;
use crate::scene::pose::Pose;
use crate::scene::Scene;

pub const MAX_TRIANGLES: u32 = node::MAX_BLOCKS;

/// A scene's BVH.
#[derive(Debug)]
pub struct Bvh {
    pub(crate) tree: Bvh8,
    pub build_seconds: f64,
    /// The tree's surface-area cost ([`Bvh8::sah`]), taken once (a refit takes it to decide).
    sah: std::sync::OnceLock<f64>,
}

/// What a BVH holds and what it cost.
#[derive(Clone, Copy, Debug)]
pub struct BvhStats {
    pub triangles: usize,
    pub nodes: usize,
    pub blocks: usize,
    /// Bytes of nodes and triangle blocks: everything the queries read besides the rays.
    pub bytes: usize,
    pub depth: u32,
    /// The instances of a two-level tree (`instances`: a rigidly posed scene's), 0 for a flat
    /// tree.
    pub instances: usize,
    pub build_seconds: f64,
    /// Surface area heuristic cost, Embree's measure: inner nodes' areas plus leaves' areas
    /// times their blocks, relative to the root's area.
    pub sah: f64,
}

/// How much a deformed scene's refit tree may have lost against its rest pose before the
/// scene's BVH is built afresh instead (`Scene::deformed`, and a clip's skins and morph
/// targets; measured in `bench scenes`): see [`refit_keeps`].
pub const REFIT_LIMIT: f64 = 1.3;

/// Whether a refit tree stays tight enough against its rest pose: its surface-area cost
/// relative to its root's area (`sah`) within [`REFIT_LIMIT`] times the rest pose's
/// (`rest_sah`), and its surface areas (`Bvh8::area_parts`: inner nodes, leaves times their
/// blocks, triangles; `now` against `rest`) grown no more than REFIT_LIMIT times beyond what
/// they hold: the leaves against the triangles' own boxes, the inner nodes against the leaves.
/// The first catches vertices scattered over the scene; the second a bend that widens the
/// root's box, which lowers a fresh tree's relative cost much more than the refit one's (a
/// skinned tube bent by its joints: 2.5x a fresh tree's cost, 1.28x its rest pose's).
pub fn refit_keeps(sah: f64, rest_sah: f64, now: [f64; 3], rest: [f64; 3]) -> bool {
    let grew = |k: usize| now[k] / rest[k].max(f64::MIN_POSITIVE);
    sah <= REFIT_LIMIT * rest_sah
        && grew(1) <= REFIT_LIMIT * grew(2)
        && grew(0) <= REFIT_LIMIT * grew(1)
}

impl Bvh {
    pub fn build(scene: &Scene) -> Self {
        Self::build_with(scene, build::BuildParams::standard())
    }

    pub fn build_with(scene: &Scene, params: build::BuildParams) -> Self {
        let start = Instant::now();
        if let Some(pose) = two_level(scene) {
            let base = &pose.base;
            let trees = base.derived(|| {
                let objects = base.objects().len();
                instances::ObjectTrees::of(&base.rig(), base.object_ids(), objects, params)
            });
            let tree = instances::pose(&trees, &pose.transforms);
            return Self::made(tree, start, None);
        }
        Self::build_flat(scene, params, start)
    }

    /// The flat tree: built, or for a posed or deformed scene refit from its base's.
    fn build_flat(scene: &Scene, params: build::BuildParams, start: Instant) -> Self {
        // A posed scene refits its base's object trees, a deformed one its source's; where
        // vertices moved other than rigidly (a deformation, a clip's skins or morph targets),
        // the scene is built afresh instead when the refit tree has lost its tightness
        // (`refit_keeps`: a deformation that scatters what the tree keeps together).
        let source = match (scene.pose(), scene.refit_from()) {
            (Some(pose), _) => Some((&pose.base, pose.deforms)),
            (None, Some(source)) => Some((source, true)),
            (None, None) => None,
        };
        if let Some((source, deforms)) = source {
            let trees = source.derived(|| {
                let objects = source.objects().len();
                refit::ObjectTrees::of(&source.rig(), source.object_ids(), objects, params)
            });
            // The blocks' corners as vertex indices, kept on the source for the faces of its
            // rig (poses) and its own (deformations); a pose that rewinds faces makes its own.
            let rig = source.rig();
            let corners = if scene.shares_faces(&rig.shared) {
                source
                    .derived(|| RigCorners(Arc::new(trees.corners(rig.faces()))))
                    .0
                    .clone()
            } else if scene.shares_faces(source.shared()) {
                source
                    .derived(|| OwnCorners(Arc::new(trees.corners(source.faces()))))
                    .0
                    .clone()
            } else {
                Arc::new(trees.corners(scene.faces()))
            };
            let (tree, triangles) = trees.posed(scene.vertices(), &corners);
            if !deforms {
                return Self::made(tree, start, None);
            }
            let (rest_sah, rest) = trees.rest_cost(&source.rig());
            let sah = tree.sah();
            if refit_keeps(sah, rest_sah, tree.area_parts(triangles), rest) {
                return Self::made(tree, start, Some(sah));
            }
        }
        let v = scene.vertices();
        let tris: Vec<Tri> = scene
            .faces()
            .iter()
            .map(|f| Tri {
                v: f.map(|k| Vec3A::from(Vec3::from(v[k as usize]))),
            })
            .collect();
        // A refit writes into huge pages already, a two-level tree's objects are moved there
        // once (`instances::ObjectTrees`); a fresh build is moved now.
        let tree = build::build(&tris, params);
        tree.move_to_huge_pages();
        Self::made(tree, start, None)
    }

    /// The BVH of `tree`, made since `start`, with its surface-area cost where known.
    fn made(tree: Bvh8, start: Instant, sah: Option<f64>) -> Self {
        Self {
            tree,
            build_seconds: start.elapsed().as_secs_f64(),
            sah: sah.map_or_else(std::sync::OnceLock::new, std::sync::OnceLock::from),
        }
    }

    /// The scene's BVH, built on first use (by every core) and cached for the scene's lifetime.
    pub fn of(scene: &Scene) -> Arc<Bvh> {
        Self::of_with(scene, Threads::All)
    }

    /// [`Bvh::of`], building on `threads` when the BVH is not cached yet.
    pub fn of_with(scene: &Scene, threads: Threads) -> Arc<Bvh> {
        let params = build::BuildParams::standard();
        scene.derived(|| {
            // `Count` threads: the caller runs this inside that pool already.
            match threads {
                Threads::One => Bvh::build_with(scene, params.sequential()),
                _ => Bvh::build_with(scene, params),
            }
        })
    }

    pub fn stats(&self) -> BvhStats {
        let t = &self.tree;
        let (blocks, nodes) = match &t.inst {
            None => (&t.blocks, t.nodes.len()),
            Some(i) => (&i.objects.blocks, t.nodes.len() + i.objects.nodes.len()),
        };
        let triangles = match &t.inst {
            None => blocks
                .iter()
                .flat_map(|b| b.id)
                .filter(|&i| i != u32::MAX)
                .count(),
            // Counted once, when the objects' trees were built (a pose's stats stay O(objects)).
            Some(i) => i.triangles,
        };
        BvhStats {
            triangles,
            nodes,
            blocks: blocks.len(),
            bytes: t.bytes(),
            depth: t.depth,
            instances: t.inst.as_ref().map_or(0, |i| i.instances.len()),
            build_seconds: self.build_seconds,
            sah: *self.sah.get_or_init(|| t.sah()),
        }
    }
}

/// A refit tree's corners for the faces of its source's rig, and for the source's own faces
/// (`refit::ObjectTrees::corners`).
struct RigCorners(Arc<refit::Corners>);
struct OwnCorners(Arc<refit::Corners>);

/// Whether the scene's ray queries run on a two-level tree (`instances`), and its pose if so:
/// a pose that moves two or more objects rigidly, each by an invertible transform, and winds
/// no face the other way (`Scene::at` rewinds mirrored objects' faces, which the objects'
/// trees do not).
pub fn two_level(scene: &Scene) -> Option<&Pose> {
    let pose = scene.pose()?;
    if pose.deforms || pose.base.objects().len() < 2 {
        return None;
    }
    let mirrors = |m: &DMat4| pose.rewinds && m.determinant() < 0.0;
    if pose
        .transforms
        .iter()
        .any(|m| !instances::invertible(m) || mirrors(m))
    {
        return None;
    }
    Some(pose)
}

/// The flat tree of a scene whose ray queries run on a two-level tree, for the queries that
/// walk a flat tree (points, winding numbers, crossings).
struct Flat(Arc<Bvh>);

/// The scene's BVH (built on `threads` if not cached yet) and the seconds spent building it now
/// (0 when it was cached). `flat`: a flat tree even where the ray queries take a two-level one.
pub(crate) fn bvh_for_with(scene: &Scene, threads: Threads, flat: bool) -> Result<(Arc<Bvh>, f64)> {
    if flat && two_level(scene).is_some() {
        check_size(scene)?;
        let had = scene.derived_if_built::<Flat>().is_some();
        let bvh = scene
            .derived(|| {
                let params = build::BuildParams::standard();
                let params = match threads {
                    Threads::One => params.sequential(),
                    _ => params,
                };
                Flat(Arc::new(Bvh::build_flat(scene, params, Instant::now())))
            })
            .0
            .clone();
        let built = if had { 0.0 } else { bvh.build_seconds };
        return Ok((bvh, built));
    }
    bvh_for(scene, threads)
}

fn check_size(scene: &Scene) -> Result<()> {
    if scene.triangle_count() >= MAX_TRIANGLES as usize {
        return input_err!(
            "the ray and point queries handle scenes of fewer than {MAX_TRIANGLES} triangles; \
             this one has {}",
            scene.triangle_count()
        );
    }
    Ok(())
}

/// The scene's BVH (built on `threads` if not cached yet) and the seconds spent building it now
/// (0 when it was cached).
pub(crate) fn bvh_for(scene: &Scene, threads: Threads) -> Result<(Arc<Bvh>, f64)> {
    check_size(scene)?;
    let had = scene.derived_if_built::<Bvh>().is_some();
    let bvh = Bvh::of_with(scene, threads);
    let built = if had { 0.0 } else { bvh.build_seconds };
    Ok((bvh, built))
}
