// Layered depth images, rendered one image at a time, each pass testing its fragments against
// the images already rendered (non-redundant-rendering.txt):
//
// - fs_nonredundant: Algorithm 1 with the pixel redundancy test of Algorithm 3 (§3.2, §6.1.1).
//   A fragment of triangle t is reprojected into every earlier image j; when image j holds t at
//   that pixel, the fragment is redundant and discarded here, before the depth test can let it
//   occlude a non-redundant fragment behind it. The reprojection starts from the fragment's own
//   window position and depth (@builtin(position)), through one matrix per earlier image formed
//   in f64 on the host, so the vertex stage stays as light as a conventional pass's (on a
//   software rasterizer, per-vertex outputs cost as much as the test itself).
// - fs_peel: depth peeling (§2, §6.1.1): a fragment survives only strictly beyond the previous
//   layer's depth at its pixel, so each pass keeps the next surface along every pixel ray.
//
// Like depth.wgsl, the output is the triangle id at each pixel centre; depth, position, normal and
// colour are resolved from it in f64 on the host. Fragments run at pixel centres (no
// multisampling), so the fragment's window position and depth are the sample's point.
enable primitive_index;

struct View {
    // clip = proj * view * (p - scene_centre), formed in f64 on the host.
    view_proj: mat4x4<f32>,
    // Index of this image among the images of the call; earlier images are 0..image.
    image: u32,
    width: u32,
    height: u32,
    // Row stride of the id images in `earlier_ids`, in i32 elements.
    stride: u32,
};

@group(0) @binding(0) var<uniform> view: View;
// The number of earlier images (= view.image) for fs_nonredundant, fixed when its pipeline is
// made, so that the loop over them unrolls and each matrix load has a constant address.
override earlier_count: u32 = 0u;
// For this image i and each earlier image j < i: the map from a fragment's homogeneous window
// coordinates (x, y, depth, 1) in image i to (x·w, y·w, w, f) in image j, where (x, y) is the
// pixel position in image j and f > 0 when the point lies in front of camera j's image plane.
// w and f keep their signs: the point's homogeneous weight is 1/w_i > 0 for any rasterized
// fragment. A uniform rather than a storage buffer: on lavapipe a storage load costs a gather
// per lane, a uniform load at a constant address a single load.
const MAX_EARLIER: u32 = 255u;
@group(0) @binding(1) var<uniform> reproject: array<mat4x4<f32>, MAX_EARLIER>;
// Triangle ids of the earlier images, image after image, rows `stride` apart; -1 where empty.
@group(0) @binding(2) var<storage, read> earlier_ids: array<i32>;
// The previous peeling layer's depth (reversed: larger is nearer); unused by fs_nonredundant.
@group(0) @binding(3) var previous_depth: texture_depth_2d;

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view.view_proj * vec4<f32>(p, 1.0);
}

// Algorithm 3: is the sample at window position `frag` of triangle `prim` held by earlier image
// j at the pixel it projects to?
fn held_by(j: u32, frag: vec4<f32>, prim: i32) -> bool {
    let c = reproject[j] * vec4<f32>(frag.xyz, 1.0);
    let px = c.xy * (1.0 / c.z);
    let size = vec2<f32>(f32(view.width), f32(view.height));
    // Branch-free: llvmpipe runs both sides of a branch under a lane mask anyway. The pixel is
    // clamped so that the load stays in image j even where the test already failed.
    let inside = c.w > 0.0 && c.z > 0.0 && all(px >= vec2<f32>(0.0)) && all(px < size);
    let pixel = vec2<u32>(clamp(px, vec2<f32>(0.0), size - 1.0));
    let at = j * view.stride * view.height + pixel.y * view.stride + pixel.x;
    return inside && earlier_ids[at] == prim;
}

@fragment
fn fs_nonredundant(
    @builtin(position) frag: vec4<f32>,
    @builtin(primitive_index) prim: u32,
) -> @location(0) i32 {
    for (var j = 0u; j < earlier_count; j++) {
        if held_by(j, frag, i32(prim)) {
            discard;
        }
    }
    return i32(prim);
}

// Image 0 of either method has nothing to test against: no discard, so the depth test can run
// before the fragment stage (early z), as in a conventional pass.
@fragment
fn fs_first(@builtin(primitive_index) prim: u32) -> @location(0) i32 {
    return i32(prim);
}

@fragment
fn fs_peel(
    @builtin(position) frag: vec4<f32>,
    @builtin(primitive_index) prim: u32,
) -> @location(0) i32 {
    if view.image > 0u {
        let previous = textureLoad(previous_depth, vec2<i32>(frag.xy), 0);
        // Reversed depth: strictly beyond the previous layer means strictly smaller.
        if !(frag.z < previous) {
            discard;
        }
    }
    return i32(prim);
}
