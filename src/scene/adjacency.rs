//! Which triangles share each edge of a triangle, by vertex position (vertices split for
//! flat shading or UV seams still join their triangles).

use std::sync::Arc;

use rayon::prelude::*;

use super::Scene;

/// No single other triangle shares the edge: a border, a non-manifold edge (three or more
/// triangles), or a collapsed one.
pub const NONE: u32 = u32::MAX;

/// Per triangle `t`, per edge `k` (from corner `k` to corner `k + 1`), the one other triangle
/// sharing that edge, or [`NONE`].
pub struct EdgeNeighbours(pub Vec<[u32; 3]>);

impl EdgeNeighbours {
    /// The scene's edge neighbours, built once and kept on the scene.
    pub fn of(scene: &Scene) -> Arc<EdgeNeighbours> {
        scene.derived(|| Self::build(scene))
    }

    fn build(scene: &Scene) -> Self {
        let verts = scene.vertices();
        // Weld: one id per distinct position (-0.0 and 0.0 are one).
        let key = |i: u32| verts[i as usize].map(|x| (x + 0.0).to_bits());
        let mut order: Vec<u32> = (0..verts.len() as u32).collect();
        order.par_sort_unstable_by_key(|&i| key(i));
        let mut weld = vec![0u32; verts.len()];
        let mut id = 0u32;
        for (k, &i) in order.iter().enumerate() {
            if k > 0 && key(i) != key(order[k - 1]) {
                id += 1;
            }
            weld[i as usize] = id;
        }
        // Every edge as (its two welded ends, low first; triangle * 3 + edge), sorted so that
        // the edges two triangles share lie side by side.
        let faces = scene.faces();
        let mut edges: Vec<(u64, u32)> = faces
            .par_iter()
            .enumerate()
            .flat_map_iter(|(t, f)| {
                let weld = &weld;
                (0..3).filter_map(move |k| {
                    let (a, b) = (weld[f[k] as usize], weld[f[(k + 1) % 3] as usize]);
                    let ends = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
                    (a != b).then_some((ends, (t * 3 + k) as u32))
                })
            })
            .collect();
        edges.par_sort_unstable();
        let mut out = vec![[NONE; 3]; faces.len()];
        for run in edges.chunk_by(|x, y| x.0 == y.0) {
            if let [(_, x), (_, y)] = run {
                let (x, y) = (*x as usize, *y as usize);
                if x / 3 != y / 3 {
                    out[x / 3][x % 3] = (y / 3) as u32;
                    out[y / 3][y % 3] = (x / 3) as u32;
                }
            }
        }
        EdgeNeighbours(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_edges_join_by_position() {
        // Two triangles of a quad with split (duplicated) vertices, a third across another
        // of the first's edges, and two more on its first edge (which three then share).
        let v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [2.0, 0.5, 0.0],
            [0.5, -1.0, 0.0],
            [0.5, -1.0, 1.0],
        ];
        let f = vec![[0, 1, 2], [3, 4, 5], [1, 6, 2], [0, 7, 1], [1, 8, 0]];
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let n = EdgeNeighbours::of(&s);
        // Triangle 0: edge 0-1 is shared with 3 and 4 as well (non-manifold), edge 1-2 with
        // 2, edge 2-0 with 1 (split vertices).
        assert_eq!(n.0[0], [NONE, 2, 1]);
        assert_eq!(n.0[1], [0, NONE, NONE]);
        assert_eq!(n.0[2], [NONE, NONE, 0]);
        assert_eq!(n.0[3], [NONE, NONE, NONE]);
    }
}
