// Conventional depth images (non-redundant-rendering.txt §3, the "conventional" baseline):
// rasterise every triangle once per camera and keep, per pixel, the nearest triangle's index and
// perspective-correct barycentrics. Depth, world position, normal and colour are resolved from
// these on the CPU in f64 (src/gpu/depth.rs), never read back from the hardware depth buffer.
//
// Vertex pulling: a non-indexed draw of 3·M vertices; vertex k belongs to triangle k / 3, so the
// rasteriser's primitive index is the scene's face index.
enable primitive_index;

struct View {
    // clip = proj * view * (p - scene_centre): the translation is formed in f64 on the host,
    // so a scene far from the world origin keeps full f32 precision here.
    view_proj: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
// Vertex positions relative to the scene centre, xyz packed.
@group(0) @binding(1) var<storage, read> positions: array<f32>;
// Face vertex indices, three per triangle.
@group(0) @binding(2) var<storage, read> faces: array<u32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // (b1, b2): weights of the triangle's second and third corners.
    @location(0) bary: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) k: u32) -> VertexOut {
    let corner = k % 3u;
    let i = faces[k];
    let p = vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
    var out: VertexOut;
    out.clip = view.view_proj * vec4<f32>(p, 1.0);
    out.bary = vec2<f32>(f32(corner == 1u), f32(corner == 2u));
    return out;
}

struct FragmentOut {
    @location(0) bary: vec2<f32>,
    @location(1) triangle: i32,
};

@fragment
fn fs_main(in: VertexOut, @builtin(primitive_index) prim: u32) -> FragmentOut {
    var out: FragmentOut;
    out.bary = in.bary;
    out.triangle = i32(prim);
    return out;
}
