// Conventional depth images (non-redundant-rendering.txt §3, the "conventional" baseline):
// rasterise every triangle once per camera and keep, per pixel, the index of the nearest
// triangle at the pixel centre. Depth, world position, normal and colour are resolved from that
// index on the CPU in f64 by intersecting the pixel-centre ray with the triangle
// (src/discretize/conventional.rs): nothing is read back from the hardware depth buffer, and no
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

struct VsOut {
    @builtin(position) position: vec4<f32>,
    // The index of the draw's first triangle: a draw of a range of faces (the visibility
    // field's marked cells) passes it as its first instance, since the primitive index counts
    // from 0 in every draw.
    @location(0) @interpolate(flat) first: u32,
};

// Vertex positions relative to the scene centre.
@vertex
fn vs_main(@location(0) p: vec3<f32>, @builtin(instance_index) first: u32) -> VsOut {
    return VsOut(view.view_proj * vec4<f32>(p, 1.0), first);
}

@fragment
fn fs_main(@builtin(primitive_index) prim: u32, @location(0) @interpolate(flat) first: u32) -> @location(0) i32 {
    return i32(prim + first);
}
