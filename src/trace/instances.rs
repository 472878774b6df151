//! The two-level tree of a rigidly posed scene: each object's tree built once, in the
//! coordinates of the scene as loaded, and shared by every pose; a pose builds only a small top
//! tree over the objects' instances, and rays move into each object's frame as they enter it
//! (as Embree and OptiX instance their geometry).
//!
//! A plain two-level tree traces slowly where the instances' world boxes overlap: a ray enters
//! every instance whose box it crosses. The top tree can be built over *partially re-braided*
//! instances (Benthin, Woop, Wald and Áfra, "Improved Two-Level BVHs using Partial
//! Re-Braiding", HPG 2017, §3): before the top build, the largest instance boxes are opened into
//! their object trees' upper nodes, as world boxes of object-space subtrees, so that the top
//! tree separates what a single instance box would lump together ([`pose_with`]). Its leaves
//! are (instance, subtree) pairs ([`InstRef`]). By default nothing is opened
//! ([`OPEN_PER_INSTANCE`] has the measurements). The top tree is built by the builder's own
//! surface area heuristic over the items' boxes (`build::build_boxes`).
//!
//! Rays keep their parameter up to a shift: a ray `o + t·d` enters an object as
//! `o' + u·d'` with `o'` the image of where it enters the object's box, `d' = M⁻¹d` and
//! `t = s + u` (`Instance::ray_in` in `traverse`, which bounds its rounding), so hits from
//! different objects compare by `t`. Triangle ids are the scene's. Each hit is refined in f64
//! in its object's frame (`rays::Rays::pending`): reported `t` and barycentrics are the exact
//! pose's, of which the posed scene's f32 vertices are the rounding.
//!
//! Watertightness holds within each object (the watertight test runs on the object's own
//! corners). Across objects, a ray through the seam between two objects may find either one,
//! as it may with the flat tree of the posed vertices; a float64 trace of the exact pose agrees
//! with the two-level tree at least as often as with that flat tree (the tests here).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::Arc;

use glam::{DAffine3, DMat3, DMat4, DVec3, Vec3, Vec3A};
use rayon::prelude::*;

use super::build::{self, Aabb, BuildParams, Out};
use super::node::{
    leaf_blocks, leaf_ref, node_index, node_ref, Bvh8, InstRef, Instance, Instanced, Node8, EMPTY,
    LEAF,
};
use super::watertight::Tri;
use crate::scene::pose::Rig;

/// Items the top tree is built over, per instance, by default: the instances' boxes are opened
/// into their subtrees until there are this many items per instance (or nothing is left to
/// open); Benthin et al. open a budget proportional to the instances in the same way. 1 opens
/// none: measured, every opening cost more than it saved here, where a ray that enters one
/// more item pays for moving into that instance's frame again (fast build, 262,144
/// incoherent rays on 100 posed tiles against the same geometry built flat, 1 / 4 / 16 / 64
/// items per instance: `stanford_bunny` 0.78 / 0.70 / 0.73 / 0.69x; `balloon` 0.72 / 0.70x,
/// primary rays 0.77 / 0.73x; 30 overlapping spheres turned and scaled 0.77 / 0.74 / 0.73x;
/// opening only instances that others overlap by a quarter of their box: `balloon` 0.57x).
pub const OPEN_PER_INSTANCE: usize = 1;

/// Most items in a leaf of the top tree.
const TOP_LEAF: usize = 4;

/// Every object's tree over its triangles as loaded, in one [`Bvh8`] (its nodes and blocks;
/// triangle ids are the scene's), built once per scene as loaded and shared by its poses.
#[derive(Debug)]
pub struct ObjectTrees {
    pub tree: Arc<Bvh8>,
    /// Each object that has triangles: its index and its tree's root node.
    roots: Vec<(u32, u32)>,
    triangles: usize,
}

impl ObjectTrees {
    /// The trees of the objects of a scene as loaded (its `rig`: vertices split so that no two
    /// objects share one), over `objects` objects.
    pub fn of(rig: &Rig, object_ids: &[i32], objects: usize, params: BuildParams) -> Self {
        let trees = per_object(rig, object_ids, objects, params);
        let mut out = Out::default();
        let mut roots = Vec::with_capacity(trees.len());
        for (o, tree) in trees {
            let root = out.append(Out {
                nodes: tree.nodes,
                blocks: tree.blocks,
                depth: tree.depth,
            });
            roots.push((o, node_ref(root as usize)));
        }
        if out.nodes.is_empty() {
            out.nodes.push(Node8::EMPTY);
        }
        let tree = Bvh8 {
            nodes: out.nodes,
            blocks: out.blocks,
            depth: out.depth,
            inst: None,
        };
        tree.move_to_huge_pages();
        ObjectTrees {
            triangles: object_ids.len(),
            tree: Arc::new(tree),
            roots,
        }
    }

    /// Objects that have triangles.
    pub fn len(&self) -> usize {
        self.roots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.roots.is_empty()
    }
}

/// Each object's own tree over its triangles as loaded (`rig`'s corners; ids the scene's face
/// indices), for the objects that have triangles, with the object's index; built in parallel.
/// Both the two-level tree (here) and the flat tree of a pose (`refit`) are made of them.
pub(super) fn per_object(
    rig: &Rig,
    object_ids: &[i32],
    objects: usize,
    params: BuildParams,
) -> Vec<(u32, Bvh8)> {
    let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); objects];
    for (i, &o) in object_ids.iter().enumerate() {
        faces_of[o as usize].push(i as u32);
    }
    let v = &rig.vertices;
    let corner = |k: u32| Vec3A::from(Vec3::from(v[k as usize]));
    faces_of
        .into_par_iter()
        .enumerate()
        .filter(|(_, faces)| !faces.is_empty())
        .map(|(o, faces)| {
            let tris: Vec<Tri> = faces
                .iter()
                .map(|&f| Tri {
                    v: rig.faces()[f as usize].map(corner),
                })
                .collect();
            let mut tree = build::build(&tris, params);
            // The builder numbers triangles by their place in `tris`: name them by face.
            for b in &mut tree.blocks {
                for id in b.id.iter_mut().filter(|id| **id != u32::MAX) {
                    *id = faces[*id as usize];
                }
            }
            (o as u32, tree)
        })
        .collect()
}

/// The world box around the object-space box `b` under `to_world` (the box of its eight
/// corners moved), widened by a few ulps so that it holds every world point whose object-space
/// image lies in `b`, after the rounding of both.
fn world_box(to_world: &DMat4, b: &Aabb) -> Aabb {
    {
        if b.lo.x > b.hi.x {
            return Aabb::EMPTY;
        }
        let (lo, hi) = (b.lo.as_dvec3(), b.hi.as_dvec3());
        let c = 0.5 * (lo + hi);
        let e = 0.5 * (hi - lo);
        let l = DMat3::from_mat4(*to_world);
        let abs = DMat3::from_cols(l.x_axis.abs(), l.y_axis.abs(), l.z_axis.abs());
        let wc = to_world.transform_point3(c);
        let we = abs * e;
        let (wlo, whi) = (wc - we, wc + we);
        let mag = wlo.abs().max(whi.abs()).max_element() + (whi - wlo).max_element();
        let pad = DVec3::splat(16.0 * f32::EPSILON as f64 * mag + f32::MIN_POSITIVE as f64);
        Aabb {
            lo: down(wlo - pad),
            hi: up(whi + pad),
        }
    }
}

fn down(v: DVec3) -> Vec3A {
    Vec3A::from_array(v.to_array().map(|x| {
        let f = x as f32;
        if f as f64 > x {
            f.next_down()
        } else {
            f
        }
    }))
}

fn up(v: DVec3) -> Vec3A {
    Vec3A::from_array(v.to_array().map(|x| {
        let f = x as f32;
        if (f as f64) < x {
            f.next_up()
        } else {
            f
        }
    }))
}

/// Whether `m` can place an instance: its inverse exists and is finite, by the test
/// `Scene::posed` puts every user's transform to (a clip may flatten an object to a plane,
/// which only the flat tree can trace).
pub fn invertible(m: &DMat4) -> bool {
    !crate::scene::pose::singular(m) && m.inverse().is_finite()
}

/// An item of the top build: a world box, the subtree it bounds and its instance.
#[derive(Clone, Copy)]
struct Item {
    bounds: Aabb,
    node: u32,
    inst: u32,
}

fn area(b: &Aabb) -> f64 {
    let e = (b.hi - b.lo).max(Vec3A::ZERO).as_dvec3();
    2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
}

/// An inner item waiting to be opened, largest world area first (ties by order of arrival, so
/// the result depends only on the inputs).
struct Open(f64, usize);

impl PartialEq for Open {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> Ordering {
        self.0.total_cmp(&o.0).then(o.1.cmp(&self.1))
    }
}

/// The two-level tree of the objects `trees` moved by `transforms` (one per object of the scene
/// as loaded, each [`invertible`]): the top tree over the instances, in a [`Bvh8`] whose `inst`
/// holds the rest.
pub fn pose(trees: &ObjectTrees, transforms: &[DMat4]) -> Bvh8 {
    pose_with(trees, transforms, OPEN_PER_INSTANCE)
}

/// [`pose`], the instances partially re-braided into `open_per_instance` items each.
pub fn pose_with(trees: &ObjectTrees, transforms: &[DMat4], open_per_instance: usize) -> Bvh8 {
    let objects = &trees.tree;
    let to_world: Vec<DMat4> = trees
        .roots
        .iter()
        .map(|&(o, _)| transforms[o as usize])
        .collect();
    let instances: Vec<Instance> = to_world
        .iter()
        .zip(&trees.roots)
        .map(|(m, &(_, root))| {
            let to_object = DAffine3::from_mat4(m.inverse());
            let b = world_box(m, &node_box(objects, root));
            Instance {
                to_object,
                linear: to_object.matrix3.as_mat3().into(),
                lo: b.lo,
                hi: b.hi,
            }
        })
        .collect();
    let items = rebraid(objects, &trees.roots, &to_world, open_per_instance);
    let (nodes, refs, depth) = top_tree(&items);
    Bvh8 {
        nodes,
        blocks: Vec::new(),
        depth: depth + objects.depth,
        inst: Some(Box::new(Instanced {
            objects: objects.clone(),
            refs,
            instances,
            to_world,
            triangles: trees.triangles,
        })),
    }
}

/// The box of node `r` of `tree`.
fn node_box(tree: &Bvh8, r: u32) -> Aabb {
    Aabb::of_node(&tree.nodes[node_index(r)])
}

/// Partial re-braiding (Benthin et al. 2017, §3): the instances' roots in the world, with the
/// largest inner item opened into its children while the budget (`per_instance` items per
/// instance) lasts. An opened item's place is taken by its first child.
fn rebraid(
    objects: &Bvh8,
    roots: &[(u32, u32)],
    to_world: &[DMat4],
    per_instance: usize,
) -> Vec<Item> {
    let mut items: Vec<Item> = Vec::with_capacity(per_instance * roots.len());
    let mut heap = BinaryHeap::new();
    for (i, &(_, root)) in roots.iter().enumerate() {
        let bounds = world_box(&to_world[i], &node_box(objects, root));
        heap.push(Open(area(&bounds), items.len()));
        items.push(Item {
            bounds,
            node: root,
            inst: i as u32,
        });
    }
    let budget = per_instance * roots.len();
    while let Some(Open(_, k)) = heap.pop() {
        let it = items[k];
        let n = &objects.nodes[node_index(it.node)];
        let children: Vec<usize> = (0..8).filter(|&s| n.child[s] != EMPTY).collect();
        if items.len() + children.len() - 1 > budget {
            break;
        }
        let m = &to_world[it.inst as usize];
        for (j, &s) in children.iter().enumerate() {
            let b = Aabb {
                lo: Vec3A::new(n.b[0][s], n.b[1][s], n.b[2][s]),
                hi: Vec3A::new(n.b[3][s], n.b[4][s], n.b[5][s]),
            };
            let child = Item {
                bounds: world_box(m, &b),
                node: n.child[s],
                inst: it.inst,
            };
            let at = if j == 0 {
                items[k] = child;
                k
            } else {
                items.push(child);
                items.len() - 1
            };
            if child.node & LEAF == 0 {
                heap.push(Open(area(&child.bounds), at));
            }
        }
    }
    items
}

/// The top tree over `items`: the builder's own surface area heuristic over their boxes, on
/// this thread (a few hundred boxes). Each leaf of it becomes one item's: a leaf of one item
/// names it, one of several becomes a node with a slot for each item (so that every item's box
/// is tested before its instance is entered: entering costs a transform of the ray). Its
/// nodes, what its leaves name, and its depth.
fn top_tree(items: &[Item]) -> (Vec<Node8>, Vec<InstRef>, u32) {
    let boxes: Vec<Aabb> = items.iter().map(|it| it.bounds).collect();
    let params = BuildParams {
        max_leaf: TOP_LEAF,
        ..BuildParams::standard()
    }
    .sequential();
    let built = build::build_boxes(&boxes, params);
    let mut nodes = built.nodes;
    let mut refs = Vec::with_capacity(items.len());
    let one = |id: u32, refs: &mut Vec<InstRef>| {
        let it = &items[id as usize];
        refs.push(InstRef {
            node: it.node,
            inst: it.inst,
        });
        leaf_ref(refs.len() as u32 - 1, 1)
    };
    for i in 0..nodes.len() {
        for slot in 0..8 {
            let c = nodes[i].child[slot];
            if c == EMPTY || c & LEAF == 0 {
                continue;
            }
            let ids: Vec<u32> = leaf_blocks(c)
                .flat_map(|b| built.blocks[b].id)
                .filter(|&id| id != u32::MAX)
                .collect();
            nodes[i].child[slot] = if let [id] = ids[..] {
                one(id, &mut refs)
            } else {
                let mut n = Node8::EMPTY;
                for (k, &id) in ids.iter().enumerate() {
                    items[id as usize].bounds.set_child(&mut n, k);
                    n.child[k] = one(id, &mut refs);
                }
                n.set_order();
                nodes.push(n);
                node_ref(nodes.len() - 1)
            };
        }
    }
    for n in &mut nodes {
        // The any-hit order: larger boxes first (likelier to hold what stops a ray).
        let mut slots: [u32; 8] = std::array::from_fn(|k| k as u32);
        slots.sort_by(|&a, &b| {
            n.child_area(b as usize)
                .total_cmp(&n.child_area(a as usize))
                .then(a.cmp(&b))
        });
        n.set_any_order(slots);
    }
    (nodes, refs, built.depth + 1)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{DMat4, DVec3};

    use super::ObjectTrees;
    use crate::scene::Scene;
    use crate::trace::build::BuildParams;
    use crate::trace::refine::moller_trumbore;
    use crate::trace::testdata::{closest_on, posed_and_flat, poses, rays_toward, spheres};
    use crate::trace::{all_hits, cast_rays, count_hits, occluded, Bvh, Query, Threads};

    #[test]
    fn a_rigid_pose_traces_its_objects_trees_through_their_instances() {
        let (base, posed, flat) = posed_and_flat(23);
        let tree = Bvh::of(&posed);
        let inst = tree.tree.inst.as_ref().expect("a two-level tree");
        assert_eq!(inst.instances.len(), 23);
        assert_eq!(tree.stats().triangles, posed.triangle_count());
        // The objects' trees are built once, with the scene as loaded, and shared by every pose.
        let again = base.posed(&poses(23)).unwrap();
        let other = Bvh::of(&again);
        let objects = &other.tree.inst.as_ref().unwrap().objects;
        assert!(Arc::ptr_eq(&inst.objects, objects));
        assert!(base.derived_if_built::<ObjectTrees>().is_some());

        // The pose and its rays need no world vertices: the pose makes them on first use.
        let lazy = base.posed(&poses(23)).unwrap();
        assert!(!lazy.has_vertices());
        let (o, d) = rays_toward(100, 1, posed.vertices());
        let early = cast_rays(&lazy, &o, &d, 0.0, f32::INFINITY).unwrap();
        assert!(!lazy.has_vertices() && Bvh::of(&lazy).tree.inst.is_some());
        assert!(early.triangle.iter().filter(|&&t| t >= 0).count() > 50);
        assert_eq!(lazy.vertices(), posed.vertices());
        assert_eq!(lazy.normals(), posed.normals());
        let (o, d) = rays_toward(20_000, 7, posed.vertices());
        let inf = f32::INFINITY;
        let (a, b) = (
            cast_rays(&posed, &o, &d, 0.0, inf).unwrap(),
            cast_rays(&flat, &o, &d, 0.0, inf).unwrap(),
        );
        let hits = b.triangle.iter().filter(|&&t| t >= 0).count();
        assert!(hits > 10_000, "{hits}");
        let same = a
            .triangle
            .iter()
            .zip(&b.triangle)
            .filter(|(x, y)| x == y)
            .count();
        assert!(same >= o.len() - 4, "{same} of {}", o.len());
        // Refined on the exact pose, the flat tree's on its corners rounded to f32: `t` within
        // a few ulps (the rays are short: 1e-5 of each ray's length).
        let close = (0..o.len())
            .filter(|&i| a.triangle[i] == b.triangle[i] && a.triangle[i] >= 0)
            .filter(|&i| (a.t[i] - b.t[i]).abs() <= 1e-5 * b.t[i].max(1.0))
            .count();
        let hit_same = (0..o.len())
            .filter(|&i| a.triangle[i] == b.triangle[i] && a.triangle[i] >= 0)
            .count();
        assert!(close >= hit_same - 2, "{close} of {hit_same}");
        // The same call, the same result: again, and on one thread.
        let q = Query {
            threads: Threads::One,
            ..Query::new(0.0, inf)
        };
        let c = crate::trace::cast_rays_with(&again, &o, &d, &q).unwrap();
        assert_eq!(
            (&a.triangle, &a.t, &a.barycentric),
            (&c.triangle, &c.t, &c.barycentric)
        );
    }

    /// The nearest triangle along each ray in float64 (Möller–Trumbore on the f32 corners,
    /// edges included), or -1.
    fn reference(scene: &Scene, o: &[[f32; 3]], d: &[[f32; 3]]) -> Vec<i32> {
        let v = scene.vertices();
        let wide = |p: [f32; 3]| p.map(f64::from);
        o.iter()
            .zip(d)
            .map(|(o, d)| {
                let mut best = (f64::INFINITY, -1);
                for (i, f) in scene.faces().iter().enumerate() {
                    let c = f.map(|k| wide(v[k as usize]));
                    let [det, u, w, t] = moller_trumbore(c, wide(*o), wide(*d), 1.0);
                    if det != 0.0 && u >= 0.0 && w >= 0.0 && u + w <= 1.0 && t >= 0.0 && t < best.0
                    {
                        best = (t, i as i32);
                    }
                }
                best.1
            })
            .collect()
    }

    /// [`reference`] on the exact pose: each object's vertices as loaded moved by its
    /// transform in float64, not rounded to f32.
    fn reference_exact(scene: &Scene, o: &[[f32; 3]], d: &[[f32; 3]]) -> Vec<i32> {
        let pose = scene.pose().unwrap();
        let rig = pose.base.rig();
        let wide = |p: [f32; 3]| p.map(f64::from);
        let v: Vec<[f64; 3]> = rig
            .vertices
            .iter()
            .zip(&rig.vertex_object)
            .map(|(p, &ob)| {
                let m = pose
                    .transforms
                    .get(ob as usize)
                    .copied()
                    .unwrap_or(DMat4::IDENTITY);
                m.transform_point3(DVec3::from(wide(*p))).to_array()
            })
            .collect();
        o.iter()
            .zip(d)
            .map(|(o, d)| {
                let mut best = (f64::INFINITY, -1);
                for (i, f) in rig.faces().iter().enumerate() {
                    let c = f.map(|k| v[k as usize]);
                    let [det, u, w, t] = moller_trumbore(c, wide(*o), wide(*d), 1.0);
                    if det != 0.0 && u >= 0.0 && w >= 0.0 && u + w <= 1.0 && t >= 0.0 && t < best.0
                    {
                        best = (t, i as i32);
                    }
                }
                best.1
            })
            .collect()
    }

    #[test]
    fn across_objects_hits_agree_with_float64_as_often_as_a_flat_trees() {
        // Rays aimed at the vertices (where edges meet, and objects overlap) of spheres turned,
        // mirrored and moved: each ray of the two-level tree is rounded into its object's
        // frame, the flat tree's corners into the world.
        let (_, posed, flat) = posed_and_flat(6);
        let (o, d) = rays_toward(1500, 11, posed.vertices());
        let want = reference(&flat, &o, &d);
        let agree = |s: &Scene| {
            let h = cast_rays(s, &o, &d, 0.0, f32::INFINITY).unwrap();
            h.triangle.iter().zip(&want).filter(|(a, b)| a == b).count()
        };
        // Against a float64 trace of the posed vertices (the flat tree's own geometry) and of
        // the exact pose (the two-level tree's): as often in both.
        let (two, one) = (agree(&posed), agree(&flat));
        assert!(Bvh::of(&posed).tree.inst.is_some());
        assert!(two >= one, "two-level {two}, flat {one} of {}", o.len());
        let exact = reference_exact(&posed, &o, &d);
        let agree_exact = |s: &Scene| {
            let h = cast_rays(s, &o, &d, 0.0, f32::INFINITY).unwrap();
            h.triangle
                .iter()
                .zip(&exact)
                .filter(|(a, b)| a == b)
                .count()
        };
        let (two, one) = (agree_exact(&posed), agree_exact(&flat));
        assert!(
            two >= one,
            "exact pose: two-level {two}, flat {one} of {}",
            o.len()
        );
    }

    #[test]
    fn every_ray_query_runs_on_the_two_level_tree() {
        let (_, posed, flat) = posed_and_flat(9);
        let (o, d) = rays_toward(4000, 3, posed.vertices());
        let q = Query::new(0.0, 1.5);
        let (a, b) = (
            occluded(&posed, &o, &d, &q).unwrap().hit,
            occluded(&flat, &o, &d, &q).unwrap().hit,
        );
        let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(differ <= 2, "{differ}");
        assert!(a.iter().filter(|&&h| h).count() > 1000);
        let q = Query::new(0.0, f32::INFINITY);
        let (a, b) = (
            count_hits(&posed, &o, &d, &q).unwrap().count,
            count_hits(&flat, &o, &d, &q).unwrap().count,
        );
        let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(differ <= 2, "{differ}");
        let (a, b) = (
            all_hits(&posed, &o, &d, &q).unwrap(),
            all_hits(&flat, &o, &d, &q).unwrap(),
        );
        assert_eq!(a.triangle.len(), b.triangle.len());
        let k = crate::trace::nearest_hits(&posed, &o, &d, 3, &q).unwrap();
        let j = crate::trace::nearest_hits(&flat, &o, &d, 3, &q).unwrap();
        let differ = k
            .triangle
            .iter()
            .zip(&j.triangle)
            .filter(|(x, y)| x != y)
            .count();
        assert!(differ <= 6, "{differ}");
    }

    #[test]
    fn re_braided_instances_find_what_whole_instances_find() {
        let base = spheres(12);
        let trees = ObjectTrees::of(&base.rig(), base.object_ids(), 12, BuildParams::standard());
        let whole = super::pose_with(&trees, &poses(12), 1);
        let braided = super::pose_with(&trees, &poses(12), 8);
        let refs = |t: &crate::trace::node::Bvh8| t.inst.as_ref().unwrap().refs.len();
        assert_eq!(refs(&whole), 12);
        assert!(refs(&braided) > 48, "{}", refs(&braided));
        let posed = base.posed(&poses(12)).unwrap();
        let (o, d) = rays_toward(5000, 9, posed.vertices());
        let (a, b) = (closest_on(&whole, &o, &d), closest_on(&braided, &o, &d));
        assert!(a.1.iter().filter(|&&t| t >= 0).count() > 2500);
        assert_eq!(a, b);
    }

    #[test]
    fn poses_the_instances_cannot_trace_take_the_flat_tree() {
        let base = spheres(4);
        let mut flat_pose = poses(4);
        // A zero scale (which a clip may give): no inverse.
        flat_pose[2] = DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0));
        let posed = base
            .posed_again(&flat_pose, true, None, None, None)
            .unwrap();
        assert!(Bvh::of(&posed).tree.inst.is_none());
        // Faces wound the other way on a mirrored object (as `Scene::at` winds them).
        let mirrored = base.posed_again(&poses(4), true, None, None, None).unwrap();
        assert!(Bvh::of(&mirrored).tree.inst.is_none());
        let plain = base
            .posed_again(&poses(4), false, None, None, None)
            .unwrap();
        assert!(Bvh::of(&plain).tree.inst.is_some());
        // One object alone: its flat tree.
        let one = spheres(1).posed(&poses(1)).unwrap();
        assert!(Bvh::of(&one).tree.inst.is_none());
    }
}
