//! Test data that the tests of several `trace` files share: an icosphere and a seeded generator.

use glam::Vec3;

/// An icosphere subdivided `n` times: a closed mesh with shared edges and vertices.
pub(crate) fn icosphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let (v0, f0) = crate::scene::shapes::icosahedron();
    let mut v: Vec<Vec3> = v0.iter().map(|p| p.as_vec3()).collect();
    let mut f: Vec<[u32; 3]> = f0.to_vec();
    for _ in 0..n {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for tri in &f {
            let m: Vec<u32> = (0..3)
                .map(|k| {
                    let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                    *mid.entry((a, b)).or_insert_with(|| {
                        v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                        v.len() as u32 - 1
                    })
                })
                .collect();
            next.push([tri[0], m[0], m[2]]);
            next.push([tri[1], m[1], m[0]]);
            next.push([tri[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    (v.iter().map(|p| p.to_array()).collect(), f)
}

/// A deterministic generator (SplitMix64) for test data.
pub(crate) struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn point(&mut self, lo: f32, hi: f32) -> [f32; 3] {
        [0; 3].map(|_| lo + (hi - lo) * self.next())
    }
}
