//! Tests of `trace::build`.

use super::*;
use crate::trace::node::{leaf_blocks, node_at, NODE_UNITS};
use crate::trace::testdata::{icosphere, Rng};

fn tris(v: &[[f32; 3]], f: &[[u32; 3]]) -> Vec<Tri> {
    f.iter()
        .map(|t| Tri {
            v: t.map(|k| Vec3A::from(v[k as usize])),
        })
        .collect()
}

/// Walk the tree checking its invariants; returns each triangle's number of appearances.
fn check(bvh: &Bvh8, n: usize) -> Vec<u32> {
    let mut seen = vec![0u32; n];
    let mut stack = vec![(0u32, 1u32)];
    while let Some((r, depth)) = stack.pop() {
        assert!(depth <= bvh.depth && depth <= MAX_DEPTH);
        let node = node_at(&bvh.nodes, r);
        for k in 0..8 {
            let c = node.child[k];
            if c == EMPTY {
                assert!(
                    node.b[0][k] > node.b[3][k],
                    "an empty slot has an empty box"
                );
                continue;
            }
            if c & LEAF == 0 {
                assert!(
                    (c as usize).is_multiple_of(NODE_UNITS)
                        && (c as usize) < bvh.nodes.len() * NODE_UNITS
                );
                stack.push((c, depth + 1));
                continue;
            }
            for b in leaf_blocks(c) {
                for lane in 0..4 {
                    let id = bvh.blocks[b].id[lane];
                    if id == u32::MAX {
                        continue;
                    }
                    seen[id as usize] += 1;
                    // The triangle lies inside its box.
                    for p in bvh.blocks[b].corners(lane) {
                        for (a, x) in p.iter().enumerate() {
                            assert!(node.b[a][k] <= *x && *x <= node.b[a + 3][k]);
                        }
                    }
                }
            }
        }
    }
    seen
}

#[test]
fn every_triangle_lands_in_exactly_one_leaf() {
    let (v, f) = icosphere(4);
    for params in [
        BuildParams::standard(),
        BuildParams::standard().sequential(),
    ] {
        let bvh = build(&tris(&v, &f), params);
        assert!(check(&bvh, f.len()).iter().all(|&c| c == 1));
    }
}

/// Parallel and sequential builds make the same tree.
#[test]
fn parallel_build_is_the_sequential_one() {
    let mut r = Rng(5);
    let v: Vec<[f32; 3]> = (0..60_000).map(|_| r.point(-10.0, 10.0)).collect();
    let f: Vec<[u32; 3]> = (0..20_000).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let t = tris(&v, &f);
    let (a, b) = (
        build(&t, BuildParams::standard()),
        build(&t, BuildParams::standard().sequential()),
    );
    assert_eq!(a.nodes.len(), b.nodes.len());
    assert!(a.blocks.iter().zip(&b.blocks).all(|(x, y)| x.id == y.id));
}

/// Each node's any-hit order is a permutation of its slots, children before empty slots, by
/// non-increasing worth (chance of stopping a ray per unit cost), recomputed here from the
/// finished tree by recursion.
#[test]
fn any_hit_order_ranks_children_by_worth() {
    // (triangle area, expected cost) of the subtree at an inner reference.
    fn subtree(bvh: &Bvh8, r: u32) -> (f64, f64) {
        let n = node_at(&bvh.nodes, r);
        let (lo, hi) = n.bounds();
        let e: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) as f64);
        let surface = 2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]);
        let (mut area, mut cost) = (0.0, 1.0);
        for k in (0..8).filter(|&k| n.child[k] != EMPTY) {
            let (a, c) = child(bvh, n, k);
            area += a;
            cost += (n.child_area(k) / surface).min(1.0) * c;
        }
        (area, cost)
    }
    fn child(bvh: &Bvh8, n: &Node8, k: usize) -> (f64, f64) {
        let c = n.child[k];
        if c & LEAF == 0 {
            return subtree(bvh, c);
        }
        let r = leaf_blocks(c);
        (
            r.clone().map(|b| block_area(&bvh.blocks[b])).sum(),
            r.len() as f64,
        )
    }
    let (mut v, mut f) = icosphere(3);
    // A few large, lone triangles beside the dense sphere.
    let mut r = Rng(9);
    for _ in 0..40 {
        let base = v.len() as u32;
        let c = r.point(-6.0, 6.0);
        for _ in 0..3 {
            let d = r.point(-1.5, 1.5);
            v.push([c[0] + d[0], c[1] + d[1], c[2] + d[2]]);
        }
        f.push([base, base + 1, base + 2]);
    }
    let bvh = build(&tris(&v, &f), BuildParams::standard());
    let mut orders_differ = false;
    for (i, n) in bvh.nodes.iter().enumerate() {
        let slots: Vec<usize> = (0..8).map(|r| n.any_slot(r)).collect();
        let mut sorted = slots.clone();
        sorted.sort_unstable();
        assert_eq!(
            sorted,
            (0..8).collect::<Vec<_>>(),
            "node {i}: not a permutation"
        );
        for (rank, &k) in slots.iter().enumerate() {
            assert_eq!(
                n.any_rank(k),
                rank as u32,
                "node {i}: rank and slot disagree"
            );
        }
        let valid = (0..8).filter(|&k| n.child[k] != EMPTY).count();
        assert!(slots[..valid].iter().all(|&k| n.child[k] != EMPTY));
        let worth: Vec<f64> = slots[..valid]
            .iter()
            .map(|&k| {
                let (a, c) = child(&bvh, n, k);
                -(-2.0 * a / n.child_area(k)).exp_m1() / c
            })
            .collect();
        for w in worth.windows(2) {
            assert!(w[0] >= w[1] * (1.0 - 1e-9), "node {i}: worth {worth:?}");
        }
        orders_differ |= slots[..valid].windows(2).any(|w| w[0] > w[1]);
    }
    assert!(
        orders_differ,
        "the order should not be slot order everywhere"
    );
}

/// Degenerate inputs: every centroid in one point (the builder must split by count, not
/// loop), and far more triangles than a leaf holds.
#[test]
fn coincident_centroids_still_build() {
    let v = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let f = vec![[0, 1, 2]; 5000];
    let bvh = build(&tris(&v, &f), BuildParams::standard());
    assert!(check(&bvh, f.len()).iter().all(|&c| c == 1));
    assert!(bvh.depth <= MAX_DEPTH);
}
