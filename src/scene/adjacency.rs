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
        let weld = weld(scene);
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

/// One id per distinct vertex position (-0.0 and 0.0 are one), per vertex: ids count the
/// positions in sorted order from 0.
pub fn weld(scene: &Scene) -> Vec<u32> {
    let verts = scene.vertices();
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
    weld
}

/// Whether the surface is closed: with vertices welded by position, every edge is walked as
/// often from one end as from the other by the triangles that have it (corners taken in their
/// counter-clockwise order; a triangle two of whose corners weld into one has no area and is
/// left out). The triangles then form a cycle, with no border, so their generalized winding
/// number is an integer everywhere off the surface: the signed count of the triangles any ray
/// from the point to infinity crosses (+1 leaving through a triangle's front, −1 entering),
/// 1 inside a closed mesh wound counter-clockwise seen from outside, 0 outside, −1 inside one
/// wound the other way, 2 where two overlap. A triangle soup (an STL file: every triangle with
/// corners of its own) is closed when its welded edges are.
///
/// An open surface gets a cap: triangles that close it. Each edge walked more often one way
/// than the other is walked back as often by a cap triangle to the apex of its border (the
/// mean of the border's vertices; a border is a connected set of such edges), so the surface
/// and its cap together form a cycle. The winding number of the surface is then that of the
/// two together, an integer found by one ray, less the cap's own (Jacobson et al. 2013 note
/// that any surface spanning the holes closes them; the cap is one).
pub struct Closure {
    pub closed: bool,
    /// The triangles that close an open surface (none for a closed one).
    pub cap: Option<Scene>,
}

impl Closure {
    /// The scene's closure, found once and kept on the scene.
    pub fn of(scene: &Scene) -> Arc<Closure> {
        scene.derived(|| Self::build(scene))
    }

    fn build(scene: &Scene) -> Self {
        let weld = weld(scene);
        // Every directed edge as its two welded ends, low first, with its direction in the
        // lowest bit: sorted, the edges of one pair of ends lie side by side.
        let mut edges: Vec<u64> = scene
            .faces()
            .par_iter()
            .flat_map_iter(|f| {
                let c = f.map(|i| weld[i as usize]);
                let collapsed = c[0] == c[1] || c[1] == c[2] || c[2] == c[0];
                (0..3).filter(move |_| !collapsed).map(move |k| {
                    let (a, b) = (c[k], c[(k + 1) % 3]);
                    (u64::from(a.min(b)) << 33) | (u64::from(a.max(b)) << 1) | u64::from(a > b)
                })
            })
            .collect();
        edges.par_sort_unstable();
        // The cap's edges: each unmatched walk of an edge, walked back.
        let mut border: Vec<[u32; 2]> = Vec::new();
        for run in edges.chunk_by(|x, y| x >> 1 == y >> 1) {
            let backward = run.iter().filter(|&&e| e & 1 == 1).count() as i64;
            let net = run.len() as i64 - 2 * backward;
            let (lo, hi) = ((run[0] >> 33) as u32, (run[0] >> 1) as u32);
            let back = if net > 0 { [hi, lo] } else { [lo, hi] };
            border.extend(std::iter::repeat_n(back, net.unsigned_abs() as usize));
        }
        if border.is_empty() {
            return Closure {
                closed: true,
                cap: None,
            };
        }
        Closure {
            closed: false,
            cap: cap(scene, &weld, &border),
        }
    }
}

/// The cap of a surface whose unmatched edges, walked back, are `border` (welded ids). The edges
/// are walked into cycles (each vertex has as many cap edges in as out), and each cycle is
/// triangulated by thirds: a triangle on its first vertex and those a third and two thirds of
/// the way round, then each of the three arcs between them the same way. The triangles are
/// small along the border and few across it, so the cap's tree separates them (a fan from one
/// apex gave every triangle the border's size, and every point near the cap had to open them
/// all). `None` if the triangles make no valid scene.
fn cap(scene: &Scene, weld: &[u32], border: &[[u32; 2]]) -> Option<Scene> {
    let mut at = vec![[0.0f32; 3]; weld.iter().max().map_or(0, |&m| m as usize + 1)];
    for (v, &w) in scene.vertices().iter().zip(weld) {
        at[w as usize] = *v;
    }
    // The cap edges by their start, in order (border is sorted by ends: a deterministic walk).
    let mut out: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for &[a, b] in border {
        out.entry(a).or_default().push(b);
    }
    for ends in out.values_mut() {
        ends.reverse(); // popped from the back: the lowest end first
    }
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(border.len());
    let starts: Vec<u32> = out.keys().copied().collect();
    for start in starts {
        while let Some(cycle) = walk(&mut out, start) {
            thirds(&cycle, &mut faces);
        }
    }
    // Compact the vertices to those the cap uses.
    let mut index: std::collections::HashMap<u32, u32> = Default::default();
    let mut vertices = Vec::new();
    for f in faces.iter_mut() {
        for v in f.iter_mut() {
            *v = *index.entry(*v).or_insert_with(|| {
                vertices.push(at[*v as usize]);
                vertices.len() as u32 - 1
            });
        }
    }
    Scene::from_arrays(vertices, faces, None, None).ok()
}

/// One cycle of the edges left in `out` from `start`, taking them as it goes (a closed walk:
/// each vertex has as many edges in as out, so a walk from `start` returns to it); `None` when
/// no edge leaves `start`.
fn walk(out: &mut std::collections::BTreeMap<u32, Vec<u32>>, start: u32) -> Option<Vec<u32>> {
    let mut cycle = vec![start];
    let mut at = start;
    loop {
        let next = out.get_mut(&at)?.pop()?;
        if next == start {
            return Some(cycle);
        }
        cycle.push(next);
        at = next;
    }
}

/// Triangles whose boundary is the closed polygon `p` (p[0] → p[1] → ... → p[0]), by thirds.
fn thirds(p: &[u32], faces: &mut Vec<[u32; 3]>) {
    let n = p.len();
    if n < 3 {
        return;
    }
    let (b, c) = (n / 3, 2 * n / 3);
    let (b, c) = (b.max(1), c.max(b.max(1) + 1));
    faces.push([p[0], p[b], p[c]]);
    thirds(&p[..=b], faces);
    thirds(&p[b..=c], faces);
    let mut last = p[c..].to_vec();
    last.push(p[0]);
    thirds(&last, faces);
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

    /// A tetrahedron wound counter-clockwise seen from outside, its vertices split per face (a
    /// triangle soup), and the same with one face reversed, with a face missing, with a face
    /// doubled (an open sheet inside), and two tetrahedra sharing a vertex and an edge.
    #[test]
    fn closure_counts_each_welded_edge_both_ways() {
        let p = [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let faces = [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let soup = |faces: &[[u32; 3]]| {
            let v: Vec<[f32; 3]> = faces
                .iter()
                .flat_map(|f| f.map(|i| p[i as usize]))
                .collect();
            let f: Vec<[u32; 3]> = (0..faces.len() as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect();
            Closure::build(&Scene::from_arrays(v, f, None, None).unwrap()).closed
        };
        assert!(soup(&faces));
        let mut flipped = faces;
        flipped[3] = [1, 3, 2];
        assert!(!soup(&flipped));
        assert!(!soup(&faces[..3]));
        assert!(!soup(&[faces.as_slice(), &faces[..1]].concat()));
        // The whole tetrahedron reversed is closed (inside out); a collapsed triangle counts
        // for nothing.
        let reversed: Vec<[u32; 3]> = faces.iter().map(|f| [f[0], f[2], f[1]]).collect();
        assert!(soup(&reversed));
        assert!(soup(&[faces.as_slice(), &[[0, 1, 0]]].concat()));
        // Two copies of the tetrahedron, one shifted to touch the other at a corner: a cycle.
        let mut v: Vec<[f32; 3]> = p.to_vec();
        v.extend(p.iter().map(|q| [q[0], q[1], q[2] - 1.0]));
        let mut f: Vec<[u32; 3]> = faces.to_vec();
        f.extend(faces.iter().map(|t| t.map(|i| i + 4)));
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        assert!(Closure::build(&s).closed);
    }

    /// An open surface and its cap together are closed: a tetrahedron missing a face (one
    /// border of three edges: the cap is that face), a quad strip (one border of ten edges: a
    /// polygon of ten corners, eight triangles), two disjoint triangles (two borders).
    #[test]
    fn an_open_surface_and_its_cap_are_closed() {
        let closes = |v: Vec<[f32; 3]>, f: Vec<[u32; 3]>| {
            let s = Scene::from_arrays(v.clone(), f.clone(), None, None).unwrap();
            let c = Closure::build(&s);
            assert!(!c.closed);
            let cap = c.cap.expect("a cap");
            let n = v.len() as u32;
            let mut verts = v;
            verts.extend_from_slice(cap.vertices());
            let mut faces = f;
            faces.extend(cap.faces().iter().map(|t| t.map(|i| i + n)));
            let both = Scene::from_arrays(verts, faces, None, None).unwrap();
            assert!(Closure::build(&both).closed);
            cap.faces().len()
        };
        let p = vec![
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        assert_eq!(closes(p.clone(), vec![[0, 2, 1], [0, 1, 3], [0, 3, 2]]), 1);
        let strip: Vec<[f32; 3]> = (0..10)
            .map(|i| [(i / 2) as f32, (i % 2) as f32, 0.1 * i as f32])
            .collect();
        let faces: Vec<[u32; 3]> = (0..8u32)
            .map(|i| {
                if i % 2 == 0 {
                    [i, i + 1, i + 2]
                } else {
                    [i + 1, i, i + 2]
                }
            })
            .collect();
        assert_eq!(closes(strip, faces), 8);
        let mut two = p.clone();
        two.extend(p.iter().map(|q| [q[0] + 3.0, q[1], q[2]]));
        assert_eq!(closes(two, vec![[0, 1, 2], [4, 5, 7]]), 2);
        // A border polygon of many corners: n - 2 triangles.
        for n in [3usize, 4, 5, 7, 64, 1000] {
            let mut faces = Vec::new();
            let cycle: Vec<u32> = (0..n as u32).collect();
            thirds(&cycle, &mut faces);
            assert_eq!(faces.len(), n - 2, "{n}");
        }
    }
}
