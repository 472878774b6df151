// Conventional depth images (non-redundant-rendering.txt §3, the "conventional" baseline):
// rasterise every triangle once per camera and keep, per pixel, the index of the nearest
// triangle at the pixel centre. Depth, world position, normal and colour are resolved from that
// index on the CPU in f64 by intersecting the pixel-centre ray with the triangle
// (src/image/conventional.rs): nothing is read back from the hardware depth buffer, and no
// attribute is interpolated in f32.
//
// An indexed draw of the scene's faces: the rasteriser's primitive index is the face index, and
// shared vertices are transformed once (post-transform vertex cache).
enable primitive_index;

struct View {
    // clip = proj * view * (p - scene_centre): the translation is formed in f64 on the host,
    // so a scene far from the world origin keeps full f32 precision here.
    view_proj: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

// Vertex positions relative to the scene centre.
@vertex
fn vs_main(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view.view_proj * vec4<f32>(p, 1.0);
}

@fragment
fn fs_main(@builtin(primitive_index) prim: u32) -> @location(0) i32 {
    return i32(prim);
}

// Drawing ranges of faces only (the visibility field's marked cells, the impostors' nearest
// cells): each draw passes its first triangle as its first instance, since the primitive index
// counts from 0 in every draw. A separate entry pair, so that full draws carry no varying.
struct RangedOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) first: u32,
};

@vertex
fn vs_ranged(@location(0) p: vec3<f32>, @builtin(instance_index) first: u32) -> RangedOut {
    return RangedOut(view.view_proj * vec4<f32>(p, 1.0), first);
}

@fragment
fn fs_ranged(@builtin(primitive_index) prim: u32, @location(0) @interpolate(flat) first: u32) -> @location(0) i32 {
    return i32(prim + first);
}
