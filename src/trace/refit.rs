//! The tree of a posed scene (`scene::pose`), made without a build: each object's subtree is
//! built once over the object as loaded ([`ObjectTrees`]); a pose takes its triangles' corners
//! from the posed scene's vertices, refits its boxes from the leaves up, and puts a small top tree
//! over the objects' boxes, built afresh for every pose. This is the two-level layout of
//! Wald et al., "Ray Tracing Deformable Scenes Using Dynamic Bounding Volume Hierarchies"
//! (ACM TOG 2007, §4: refitting) under an instance level, flattened into one `Bvh8` so that every
//! query runs on it unchanged.

use std::ops::Range;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

use super::build::{self, padded_box, Aabb, BuildParams, Out};
use super::node::{leaf_blocks, node_index, node_ref, Bvh8, Node8, Tri4, EMPTY, LEAF};
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
    /// The objects' nodes grouped by their depth below their object's root, deepest last: a
    /// refit runs level by level from the deepest, each level's nodes in parallel.
    levels: Vec<Vec<u32>>,
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
        let levels = levels_of(&out.nodes, &parts);
        ObjectTrees {
            nodes: out.nodes,
            ids: out.blocks.iter().map(|b| b.id).collect(),
            top_count,
            objects: parts,
            depth: out.depth,
            levels,
            rest_cost: std::sync::OnceLock::new(),
        }
    }

    /// The surface-area cost relative to the root's area and the surface areas
    /// (`Bvh8::area_parts`) of the tree of the scene as loaded (whose rig is `rig`).
    pub fn rest_cost(&self, rig: &Rig) -> (f64, [f64; 3]) {
        *self.rest_cost.get_or_init(|| {
            let (tree, triangles) = self.posed(&rig.vertices, rig.faces());
            (tree.sah(), tree.area_parts(triangles))
        })
    }

    /// The tree of the posed scene whose `vertices` and `faces` are given (`Scene::posed`
    /// moved this tree's scene's rig vertices by their objects' transforms, with the same f64
    /// transform and f32 rounding the blocks' corners need, so they are gathered, not moved
    /// again), and the sum of its triangles' own box areas (`Bvh8::area_parts`' third part,
    /// taken while the corners are at hand).
    pub fn posed(&self, vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> (Bvh8, f64) {
        // Blocks are written once, from the rest tree's ids and the posed corners.
        // Each block's padded box (the union of its triangles' `padded_box`, as a build
        // takes them) and its triangles' own box areas, while the corners are at hand.
        let (mut blocks, mut boxes) = (Vec::new(), Vec::new());
        self.ids
            .par_iter()
            .with_min_len(1 << 12)
            .map(|&id| {
                let mut out = Tri4 { id, ..Tri4::NONE };
                let (mut bx, mut area) = (Aabb::EMPTY, 0.0);
                for lane in (0..4).filter(|&l| id[l] != u32::MAX) {
                    let face = faces[id[lane] as usize];
                    let tri = Tri {
                        v: face.map(|k| Vec3A::from(Vec3::from(vertices[k as usize]))),
                    };
                    for (c, p) in tri.v.iter().enumerate() {
                        for a in 0..3 {
                            out.v[c][a][lane] = p[a];
                        }
                    }
                    let lo = tri.v[0].min(tri.v[1]).min(tri.v[2]);
                    let e = (tri.v[0].max(tri.v[1]).max(tri.v[2]) - lo).as_dvec3();
                    area += 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
                    bx.grow(&padded_box(&tri));
                }
                (out, (bx, area))
            })
            .unzip_into_vecs(&mut blocks, &mut boxes);
        let triangles = boxes.iter().map(|b| b.1).sum();
        let mut nodes = self.nodes.clone();
        // Level by level from the deepest: a node's children are one level deeper, refit
        // already. Each level's nodes in parallel (one object or many).
        for level in self.levels.iter().rev() {
            let refit: Vec<Node8> = level
                .par_iter()
                .with_min_len(64)
                .map(|&i| refit_node(nodes[i as usize], &nodes, &boxes))
                .collect();
            for (&i, n) in level.iter().zip(refit) {
                nodes[i as usize] = n;
            }
        }
        let mut items: Vec<(Aabb, usize)> = self
            .objects
            .iter()
            .enumerate()
            .map(|(k, o)| (Aabb::of_node(&nodes[o.nodes.start]), k))
            .collect();
        let (mut top_nodes, mut patches) = (Vec::with_capacity(self.top_count), Vec::new());
        top(&mut items, &mut top_nodes, &mut patches);
        debug_assert_eq!(top_nodes.len(), self.top_count);
        let top_depth = depth_of(&top_nodes, 0);
        nodes[..self.top_count].copy_from_slice(&top_nodes);
        for (node, slot, k) in patches {
            nodes[node].child[slot] = node_ref(self.objects[k].nodes.start);
        }
        for n in &mut nodes[..self.top_count] {
            n.set_order();
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

/// Nodes of the top tree over `n` objects ([`top`]'s splits depend on the count alone).
fn top_node_count(n: usize) -> usize {
    let mut items: Vec<(Aabb, usize)> = (0..n).map(|k| (Aabb::EMPTY, k)).collect();
    let mut nodes = Vec::new();
    top(&mut items, &mut nodes, &mut Vec::new());
    nodes.len()
}

/// Node `n` with its children's boxes refit: a leaf's from its blocks' posed corners, an inner
/// child's from that child in `nodes` (refit already). The any-hit order is the one built for
/// the object as loaded.
fn refit_node(mut n: Node8, nodes: &[Node8], blocks: &[(Aabb, f64)]) -> Node8 {
    for k in 0..8 {
        let c = n.child[k];
        if c == EMPTY {
            continue;
        }
        let bx = if c & LEAF != 0 {
            let mut bx = Aabb::EMPTY;
            for (b, _) in &blocks[leaf_blocks(c)] {
                bx.grow(b);
            }
            bx
        } else {
            Aabb::of_node(&nodes[node_index(c)])
        };
        bx.set_child(&mut n, k);
    }
    n.set_order();
    n
}

/// The objects' nodes (`nodes`: the whole tree's, references global) by depth below their
/// object's root.
fn levels_of(nodes: &[Node8], objects: &[Object]) -> Vec<Vec<u32>> {
    let mut levels: Vec<Vec<u32>> = Vec::new();
    let mut frontier: Vec<u32> = objects.iter().map(|o| o.nodes.start as u32).collect();
    while !frontier.is_empty() {
        let mut next = Vec::new();
        for &i in &frontier {
            for &c in &nodes[i as usize].child {
                if c != EMPTY && c & LEAF == 0 {
                    next.push(node_index(c) as u32);
                }
            }
        }
        levels.push(std::mem::replace(&mut frontier, next));
    }
    levels
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
