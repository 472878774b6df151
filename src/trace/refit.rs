//! The tree of a posed scene (`scene::pose`), made without a build: each object's subtree is
//! built once over the object as loaded ([`ObjectTrees`]); a pose takes its triangles' corners
//! from the posed scene's vertices, refits its boxes from the leaves up, and puts a small top tree
//! over the objects' boxes, built afresh for every pose. This is the two-level layout of
//! Wald et al., "Ray Tracing Deformable Scenes Using Dynamic Bounding Volume Hierarchies"
//! (ACM TOG 2007, §4: refitting) under an instance level, flattened into one `Bvh8` so that every
//! query runs on it unchanged.

use std::mem::MaybeUninit;
use std::ops::Range;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

use super::build::{self, padded_box, Aabb, BuildParams, Out};
use super::node::{leaf_blocks, node_index, node_ref, Bvh8, Node8, Tri4, EMPTY, LEAF};
use super::traverse::prefetch_line;
use super::watertight::Tri;
use crate::scene::pose::Rig;

/// The tree of a scene as loaded, laid out for posing: room for the top tree's nodes first,
/// then each object's subtree over its triangles as loaded (its nodes and blocks contiguous,
/// references already shifted to their place), so that a pose copies it once and refits
/// each object's part in place.
#[derive(Debug)]
pub struct ObjectTrees {
    nodes: Vec<Node8>,
    /// The triangle ids of each block (its corners are the pose's, gathered per pose).
    ids: Vec<[u32; 4]>,
    /// The top tree's node count (it depends only on the number of objects).
    top_count: usize,
    objects: Vec<Object>,
    depth: u32,
    /// Each node's subtree's extent (the top tree's entries unused).
    ext: Vec<Extent>,
    /// The surface-area cost ([`Bvh8::sah`]) and surface areas ([`Bvh8::area_parts`]) of the
    /// tree of the scene as loaded, made on the first deformation (poses do not need them).
    rest_cost: std::sync::OnceLock<(f64, [f64; 3])>,
}

/// An object's part of [`ObjectTrees`]: its nodes (the root first), and its root's triangle
/// area and expected cost (for the any-hit order of the top tree above it).
#[derive(Debug)]
struct Object {
    nodes: Range<usize>,
    stats: (f64, f64),
}

impl ObjectTrees {
    /// The subtrees of the objects of a scene as loaded (its `rig`), over `objects` objects.
    pub fn of(rig: &Rig, object_ids: &[i32], objects: usize, params: BuildParams) -> Self {
        let trees: Vec<(Bvh8, (f64, f64))> =
            super::instances::per_object(rig, object_ids, objects, params)
                .into_par_iter()
                .map(|(_, mut tree)| {
                    let stats = build::rank_for_any_hit(&mut tree.nodes, &tree.blocks);
                    (tree, stats)
                })
                .collect();
        let top_count = top_node_count(trees.len());
        let mut out = Out {
            nodes: vec![Node8::EMPTY; top_count],
            ..Default::default()
        };
        let mut parts = Vec::with_capacity(trees.len());
        for (tree, stats) in trees {
            let n0 = out.nodes.len();
            let sub = Out {
                nodes: tree.nodes,
                blocks: tree.blocks,
                depth: tree.depth,
            };
            out.append(sub);
            parts.push(Object {
                nodes: n0..out.nodes.len(),
                stats,
            });
        }
        // `posed` writes into unfilled memory: the objects must tile the nodes after the top
        // tree's, and each object's subtrees its own nodes and blocks.
        let mut ext = vec![Extent::default(); out.nodes.len()];
        let mut next_block = 0;
        let mut next_node = top_count;
        for o in &parts {
            assert_eq!(o.nodes.start, next_node, "objects' nodes out of order");
            next_node = o.nodes.end;
            let e = extents(&out.nodes, o.nodes.start, next_block, &mut ext);
            assert_eq!(
                e.nodes_end as usize, o.nodes.end,
                "an object's nodes out of order"
            );
            next_block = e.blocks_end;
        }
        assert_eq!(next_node, out.nodes.len(), "nodes no object holds");
        assert_eq!(
            next_block as usize,
            out.blocks.len(),
            "blocks no object holds"
        );
        ObjectTrees {
            nodes: out.nodes,
            ids: out.blocks.iter().map(|b| b.id).collect(),
            top_count,
            objects: parts,
            depth: out.depth,
            ext,
            rest_cost: std::sync::OnceLock::new(),
        }
    }

    /// The surface-area cost relative to the root's area and the surface areas
    /// (`Bvh8::area_parts`) of the tree of the scene as loaded (whose rig is `rig`).
    pub fn rest_cost(&self, rig: &Rig) -> (f64, [f64; 3]) {
        *self.rest_cost.get_or_init(|| {
            let (tree, triangles) = self.posed(&rig.vertices, &self.corners(rig.faces()));
            (tree.sah(), tree.area_parts(triangles))
        })
    }

    /// Each block's corners as vertex indices into a scene whose faces are `faces` (a lane
    /// without a triangle names vertex 0): what a refit reads in the order it writes the
    /// blocks, in place of a triangle id and then its face.
    pub fn corners(&self, faces: &[[u32; 3]]) -> Corners {
        Corners(
            self.ids
                .par_iter()
                .with_min_len(1 << 12)
                .map(|id| {
                    id.map(|i| {
                        if i == u32::MAX {
                            [0; 3]
                        } else {
                            faces[i as usize]
                        }
                    })
                })
                .collect(),
        )
    }

    /// The tree of the posed scene whose `vertices` are given, with its blocks' `corners`
    /// ([`ObjectTrees::corners`] of its faces; `Scene::posed` moved this tree's scene's rig
    /// vertices by their objects' transforms, with the same f64 transform and f32 rounding the
    /// blocks' corners need, so they are gathered, not moved again), and the sum of its
    /// triangles' own box areas (`Bvh8::area_parts`' third part, taken while the corners are at
    /// hand).
    ///
    /// One pass per object (Wald et al. 2007 §4): each subtree's nodes and blocks are stored
    /// together after its root, so a node is refit after its children, its leaves' blocks are
    /// written from the posed corners as it reaches them, and large subtrees go in parallel;
    /// every node and block is written once, into memory not filled before.
    pub fn posed(&self, vertices: &[[f32; 3]], corners: &Corners) -> (Bvh8, f64) {
        assert_eq!(corners.0.len(), self.ids.len(), "corners of another tree");
        let (n, nb) = (self.nodes.len(), self.ids.len());
        let mut nodes: Vec<Node8> = Vec::with_capacity(n);
        let mut blocks: Vec<Tri4> = Vec::with_capacity(nb);
        crate::limits::huge_pages(nodes.spare_capacity_mut());
        crate::limits::huge_pages(blocks.spare_capacity_mut());
        let refit = Refit {
            rest: &self.nodes,
            ext: &self.ext,
            ids: &self.ids,
            corners: &corners.0,
            vertices,
        };
        // Each object's nodes and blocks, carved in order out of the unfilled memory.
        let mut jobs = Vec::with_capacity(self.objects.len());
        {
            let (_, mut ns) = nodes.spare_capacity_mut()[..n].split_at_mut(self.top_count);
            let mut bs = &mut blocks.spare_capacity_mut()[..nb];
            for o in &self.objects {
                let (mine, rest) = ns.split_at_mut(o.nodes.len());
                let e = self.ext[o.nodes.start];
                let (bmine, brest) = std::mem::take(&mut bs).split_at_mut(e.blocks());
                jobs.push((o.nodes.start, mine, bmine));
                (ns, bs) = (rest, brest);
            }
            debug_assert!(ns.is_empty() && bs.is_empty());
        }
        let roots: Vec<(Aabb, f64)> = jobs
            .into_par_iter()
            .with_max_len(1)
            .map(|(i, ns, bs)| refit.subtree(i, ns, bs))
            .collect();
        let triangles = roots.iter().map(|r| r.1).sum();
        let mut items: Vec<(Aabb, usize)> =
            roots.iter().enumerate().map(|(k, r)| (r.0, k)).collect();
        let (mut top_nodes, mut patches) = (Vec::with_capacity(self.top_count), Vec::new());
        top(&mut items, &mut top_nodes, &mut patches);
        assert_eq!(top_nodes.len(), self.top_count);
        // The top tree's own depth, before its leaves name the objects' roots.
        let top_depth = depth_of(&top_nodes, 0);
        for (node, slot, k) in patches {
            top_nodes[node].child[slot] = node_ref(self.objects[k].nodes.start);
        }
        for n in &mut top_nodes {
            n.set_order();
        }
        for (slot, node) in nodes.spare_capacity_mut().iter_mut().zip(top_nodes) {
            slot.write(node);
        }
        // SAFETY: the top tree's nodes were written just now, and every object's nodes and
        // blocks by `Refit::subtree`, which writes each node and block of the subtree it is
        // given once (`ObjectTrees::of` checked that each object's subtrees tile its nodes and
        // blocks, `Extent`); the objects tile the rest.
        unsafe {
            nodes.set_len(n);
            blocks.set_len(nb);
        }
        let mut subtree = vec![(0.0, 0.0); nodes.len()];
        for o in &self.objects {
            subtree[o.nodes.start] = o.stats;
        }
        build::rank_first_nodes(&mut nodes, &blocks, self.top_count, &mut subtree);
        let tree = Bvh8 {
            nodes,
            blocks,
            depth: top_depth + self.depth,
            inst: None,
        };
        (tree, triangles)
    }
}

/// Each block's three corners per lane, as vertex indices ([`ObjectTrees::corners`]).
#[derive(Debug)]
pub struct Corners(Vec<[[u32; 3]; 4]>);

/// Where a node's subtree lies: its nodes from the node itself to `nodes_end`, its blocks
/// `blocks_start..blocks_end` (the builder writes a node, then its children's subtrees and
/// leaves in slot order, so each subtree's nodes and blocks are contiguous).
#[derive(Clone, Copy, Debug, Default)]
struct Extent {
    nodes_end: u32,
    blocks_start: u32,
    blocks_end: u32,
}

impl Extent {
    fn blocks(&self) -> usize {
        (self.blocks_end - self.blocks_start) as usize
    }
}

/// The extents of node `i`'s subtree and of every node below it, written into `ext`; panics
/// unless the subtree's children follow it in slot order, each subtree and leaf contiguous
/// (what [`Refit::subtree`] relies on to write every node and block once).
fn extents(nodes: &[Node8], i: usize, blocks_start: u32, ext: &mut [Extent]) -> Extent {
    let (mut next_node, mut next_block) = (i + 1, blocks_start);
    for &c in nodes[i].child.iter().filter(|&&c| c != EMPTY) {
        if c & LEAF != 0 {
            let r = leaf_blocks(c);
            assert_eq!(r.start, next_block as usize, "a leaf out of order");
            next_block = r.end as u32;
        } else {
            assert_eq!(node_index(c), next_node, "a subtree out of order");
            let e = extents(nodes, next_node, next_block, ext);
            (next_node, next_block) = (e.nodes_end as usize, e.blocks_end);
        }
    }
    ext[i] = Extent {
        nodes_end: next_node as u32,
        blocks_start,
        blocks_end: next_block,
    };
    ext[i]
}

/// What a refit reads: the tree as built, its extents, the blocks' triangle ids and corners,
/// and the posed vertices.
struct Refit<'a> {
    rest: &'a [Node8],
    ext: &'a [Extent],
    ids: &'a [[u32; 4]],
    corners: &'a [[[u32; 3]; 4]],
    vertices: &'a [[f32; 3]],
}

/// How many blocks ahead a refit asks for the vertices it will gather.
const PREFETCH_BLOCKS: usize = 4;

/// Subtrees of at least this many blocks refit their inner children in parallel.
const PARALLEL_BLOCKS: usize = 1 << 11;

impl Refit<'_> {
    /// Refit node `i`'s subtree into `nodes` (its nodes, `i` first) and `blocks` (its
    /// blocks); returns its box and its triangles' box areas.
    fn subtree(
        &self,
        i: usize,
        nodes: &mut [MaybeUninit<Node8>],
        blocks: &mut [MaybeUninit<Tri4>],
    ) -> (Aabb, f64) {
        let e = self.ext[i];
        debug_assert_eq!(nodes.len(), e.nodes_end as usize - i);
        debug_assert_eq!(blocks.len(), e.blocks());
        let mut n = self.rest[i];
        let (me, mut ns) = nodes.split_first_mut().expect("a subtree has its root");
        let mut bs = blocks;
        let mut boxes = [(Aabb::EMPTY, 0.0); 8];
        // Each child's part, carved in slot order; inner children run after, in parallel when
        // the subtree is large.
        let mut inner = Vec::new();
        for (k, &c) in n.child.iter().enumerate().filter(|(_, &c)| c != EMPTY) {
            if c & LEAF != 0 {
                let r = leaf_blocks(c);
                let (mine, rest) = std::mem::take(&mut bs).split_at_mut(r.len());
                boxes[k] = self.leaf(r.start, mine);
                bs = rest;
            } else {
                let j = node_index(c);
                let ce = self.ext[j];
                let (nmine, nrest) =
                    std::mem::take(&mut ns).split_at_mut(ce.nodes_end as usize - j);
                let (bmine, brest) = std::mem::take(&mut bs).split_at_mut(ce.blocks());
                inner.push((k, j, nmine, bmine));
                (ns, bs) = (nrest, brest);
            }
        }
        if e.blocks() >= PARALLEL_BLOCKS && inner.len() > 1 {
            let done: Vec<(usize, (Aabb, f64))> = inner
                .into_par_iter()
                .with_max_len(1)
                .map(|(k, j, ns, bs)| (k, self.subtree(j, ns, bs)))
                .collect();
            for (k, b) in done {
                boxes[k] = b;
            }
        } else {
            for (k, j, ns, bs) in inner {
                boxes[k] = self.subtree(j, ns, bs);
            }
        }
        let (mut bx, mut area) = (Aabb::EMPTY, 0.0);
        let child = n.child;
        for (k, (b, a)) in boxes.iter().enumerate().filter(|(k, _)| child[*k] != EMPTY) {
            b.set_child(&mut n, k);
            bx.grow(b);
            area += a;
        }
        n.set_order();
        me.write(n);
        (bx, area)
    }

    /// Write the blocks from `first` on (`out`'s length of them) from the posed corners;
    /// returns the union of their triangles' padded boxes (as a build takes them,
    /// `padded_box`) and the triangles' own box areas.
    fn leaf(&self, first: usize, out: &mut [MaybeUninit<Tri4>]) -> (Aabb, f64) {
        let (mut bx, mut area) = (Aabb::EMPTY, 0.0);
        let v = self.vertices;
        for (b, slot) in out.iter_mut().enumerate() {
            // Blocks are refit in the order they are stored: ask for the vertices of a block
            // a few ahead (in this leaf or the next) while this one's are read.
            if let Some(ahead) = self.corners.get(first + b + PREFETCH_BLOCKS) {
                for k in ahead.as_flattened() {
                    prefetch_line(v.as_ptr().wrapping_add(*k as usize));
                }
            }
            let (id, corners) = (self.ids[first + b], &self.corners[first + b]);
            let mut block = Tri4 { id, ..Tri4::NONE };
            for lane in (0..4).filter(|&l| id[l] != u32::MAX) {
                let tri = Tri {
                    v: corners[lane].map(|k| Vec3A::from(Vec3::from(v[k as usize]))),
                };
                block.set(lane, &tri, id[lane]);
                let lo = tri.v[0].min(tri.v[1]).min(tri.v[2]);
                let e = (tri.v[0].max(tri.v[1]).max(tri.v[2]) - lo).as_dvec3();
                area += 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
                bx.grow(&padded_box(&tri));
            }
            slot.write(block);
        }
        (bx, area)
    }
}

/// Nodes of the top tree over `n` objects ([`top`]'s splits depend on the count alone).
fn top_node_count(n: usize) -> usize {
    let mut items: Vec<(Aabb, usize)> = (0..n).map(|k| (Aabb::EMPTY, k)).collect();
    let mut nodes = Vec::new();
    top(&mut items, &mut nodes, &mut Vec::new());
    nodes.len()
}

/// Nodes on the longest path down from `i` through the top tree's own nodes.
pub(super) fn depth_of(nodes: &[Node8], i: usize) -> u32 {
    let n = &nodes[i];
    1 + n
        .child
        .iter()
        .filter(|&&c| c != EMPTY && c & LEAF == 0)
        .map(|&c| depth_of(nodes, node_index(c)))
        .max()
        .unwrap_or(0)
}

/// A top tree over `items` (boxes and their objects): up to eight per node, split by the median
/// of their centres along the widest axis. Its slots that hold one object are left empty and
/// listed in `patches` as (node, slot, object), and the nodes' orders are left to the caller,
/// once those are filled; returns the root's index.
pub(super) fn top(
    items: &mut [(Aabb, usize)],
    nodes: &mut Vec<Node8>,
    patches: &mut Vec<(usize, usize, usize)>,
) -> usize {
    let me = nodes.len();
    nodes.push(Node8::EMPTY);
    let mut groups = vec![(0, items.len())];
    while groups.len() < 8 {
        // The largest group (the first of equals) with more than one object.
        let Some((g, _)) = groups
            .iter()
            .enumerate()
            .filter(|(_, (a, b))| b - a > 1)
            .max_by_key(|(i, (a, b))| (b - a, usize::MAX - i))
        else {
            break;
        };
        let (a, b) = groups[g];
        split_at_median(&mut items[a..b]);
        let mid = a + (b - a) / 2;
        groups[g] = (a, mid);
        groups.insert(g + 1, (mid, b));
    }
    for (slot, &(a, b)) in groups.iter().enumerate() {
        let bx = items[a..b]
            .iter()
            .fold(Aabb::EMPTY, |acc, (bx, _)| acc.union(bx));
        if b - a == 1 {
            patches.push((me, slot, items[a].1));
        } else {
            let child = top(&mut items[a..b], nodes, patches);
            nodes[me].child[slot] = node_ref(child);
        }
        bx.set_child(&mut nodes[me], slot);
    }
    me
}

/// Order `items` by their centres along the axis where the centres spread widest (ties by
/// object, so the tree depends only on the boxes).
fn split_at_median(items: &mut [(Aabb, usize)]) {
    let centre = |b: &Aabb| b.lo + b.hi;
    let (lo, hi) = items.iter().fold(
        (Vec3A::INFINITY, Vec3A::NEG_INFINITY),
        |(lo, hi), (b, _)| (lo.min(centre(b)), hi.max(centre(b))),
    );
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    items.sort_by(|(a, i), (b, j)| centre(a)[axis].total_cmp(&centre(b)[axis]).then(i.cmp(j)));
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::scene::{Scene, SceneParts};
    use crate::trace::testdata::{icosphere, spheres};

    /// The refit of a scene as loaded, at its own vertices.
    fn at_rest(scene: &Arc<Scene>) -> (ObjectTrees, Bvh8) {
        let rig = scene.rig();
        let trees = ObjectTrees::of(
            &rig,
            scene.object_ids(),
            scene.objects().len(),
            BuildParams::standard(),
        );
        let (tree, _) = trees.posed(&rig.vertices, &trees.corners(rig.faces()));
        (trees, tree)
    }

    #[test]
    fn a_refit_at_rest_is_the_built_tree_node_for_node() {
        // Many objects (one subtree each), and one object large enough that its subtrees refit
        // in parallel: every node's boxes, children and orders as the builder made them.
        let (v, f) = icosphere(5);
        assert!(f.len() > 4 * PARALLEL_BLOCKS);
        let one = Arc::new(
            Scene::new(SceneParts {
                object_ids: vec![0; f.len()],
                material_ids: vec![-1; f.len()],
                objects: vec!["sphere".into()],
                vertices: v,
                faces: f,
                ..Default::default()
            })
            .unwrap(),
        );
        for scene in [spheres(30), one] {
            let (trees, tree) = at_rest(&scene);
            let rest = &trees.nodes[trees.top_count..];
            let refit = &tree.nodes[trees.top_count..];
            assert_eq!(rest.len(), refit.len());
            for (a, b) in rest.iter().zip(refit) {
                assert_eq!(a.child, b.child);
                assert_eq!(a.order, b.order);
                let bits = |n: &Node8| n.b.map(|row| row.map(f32::to_bits));
                assert_eq!(bits(a), bits(b));
            }
            // Every block holds its triangles' corners as the scene has them.
            let rig = scene.rig();
            for block in &tree.blocks {
                for lane in (0..4).filter(|&l| block.id[l] != u32::MAX) {
                    let face = rig.faces()[block.id[lane] as usize];
                    assert_eq!(block.corners(lane), face.map(|k| rig.vertices[k as usize]));
                }
            }
        }
    }

    #[test]
    fn extents_refuse_a_tree_out_of_order() {
        let scene = spheres(2);
        let (trees, _) = at_rest(&scene);
        let mut nodes = trees.nodes.clone();
        let root = trees.objects[0].nodes.start;
        let inner: Vec<usize> = (0..8)
            .filter(|&k| nodes[root].child[k] != EMPTY && nodes[root].child[k] & LEAF == 0)
            .collect();
        assert!(inner.len() >= 2, "the test needs two inner children");
        nodes[root].child.swap(inner[0], inner[1]);
        let mut ext = vec![Extent::default(); nodes.len()];
        let walk = std::panic::catch_unwind(move || extents(&nodes, root, 0, &mut ext));
        assert!(walk.is_err());
    }
}
