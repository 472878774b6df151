// Layered depth images, rendered one image at a time, each pass testing its fragments against
// the images already rendered (non-redundant-rendering.txt):
//
// - fs_nonredundant: Algorithm 1 with the pixel redundancy test of Algorithm 3 (§3.2, §6.1.1).
//   A fragment of triangle t is reprojected into every earlier image j; when image j holds t at
//   that pixel, the fragment is redundant and discarded here, before the depth test can let it
//   occlude a non-redundant fragment behind it.
// - fs_peel: depth peeling (§2, §6.1.1): a fragment survives only strictly beyond the previous
//   layer's depth at its pixel, so each pass keeps the next surface along every pixel ray.
//
// Like depth.wgsl, the output is the triangle id at each pixel centre; depth, position, normal and
// colour are resolved from it in f64 on the host. Fragments run at pixel centres (no
// multisampling), so the interpolated `rel` is the sample's point (relative to the scene centre).
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

// An earlier image's camera: where a point lands in it and whether it lies in front.
struct Earlier {
    view_proj: mat4x4<f32>,
    // dot(front.xyz, p) + front.w > 0 for a point in front of the camera's image plane.
    front: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> earlier: array<Earlier>;
// Triangle ids of the earlier images, image after image, rows `stride` apart; -1 where empty.
@group(0) @binding(2) var<storage, read> earlier_ids: array<i32>;
// The previous peeling layer's depth (reversed: larger is nearer); unused by fs_nonredundant.
@group(0) @binding(3) var previous_depth: texture_depth_2d;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
};

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = view.view_proj * vec4<f32>(p, 1.0);
    out.rel = p;
    return out;
}

// Algorithm 3: is the sample at `rel` of triangle `prim` held by earlier image j at the pixel it
// projects to?
fn held_by(j: u32, rel: vec3<f32>, prim: i32) -> bool {
    let e = earlier[j];
    if dot(e.front.xyz, rel) + e.front.w <= 0.0 {
        return false;
    }
    let clip = e.view_proj * vec4<f32>(rel, 1.0);
    let ndc = clip.xy / clip.w;
    let px = vec2<f32>((ndc.x + 1.0) * 0.5 * f32(view.width), (1.0 - ndc.y) * 0.5 * f32(view.height));
    if !(px.x >= 0.0 && px.y >= 0.0 && px.x < f32(view.width) && px.y < f32(view.height)) {
        return false;
    }
    let pixel = vec2<u32>(px);
    let at = j * view.stride * view.height + pixel.y * view.stride + pixel.x;
    return earlier_ids[at] == prim;
}

@fragment
fn fs_nonredundant(in: VertexOut, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    for (var j = 0u; j < view.image; j++) {
        if held_by(j, in.rel, i32(prim)) {
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
fn fs_peel(in: VertexOut, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    if view.image > 0u {
        let previous = textureLoad(previous_depth, vec2<i32>(in.clip.xy), 0);
        // Reversed depth: strictly beyond the previous layer means strictly smaller.
        if !(in.clip.z < previous) {
            discard;
        }
    }
    return i32(prim);
}
