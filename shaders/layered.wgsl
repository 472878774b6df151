// Layered depth images, rendered one image at a time, each pass testing its fragments against
// the images already rendered (non-redundant-rendering.txt):
//
// - Non-redundant rendering: Algorithm 1 with the pixel redundancy test of Algorithm 3 (§3.2,
//   §6.1.1). A fragment of triangle t is reprojected into every earlier image j; when image j
//   holds t at that pixel, the fragment is redundant and discarded here, before the depth test can
//   let it occlude a non-redundant fragment behind it.
// - fs_peel: depth peeling (§2, §6.1.1): a fragment survives only strictly beyond the previous
//   layer's depth at its pixel, so each pass keeps the next surface along every pixel ray.
//
// Like depth.wgsl, the output is the triangle id at each pixel centre; depth, position, normal and
// colour are resolved from it in f64 on the host. Fragments run at pixel centres (no
// multisampling), so the fragment's window position and depth are the sample's point.
//
// Where the reprojection comes from. A fragment's position in earlier image j, in homogeneous
// form (x·w, y·w, w, f) — pixel position (x, y), camera j's clip w, and f > 0 when the point lies
// in front of camera j's image plane — is a linear function of the point. So for the first
// VARYING_IMAGES earlier images the vertex stage projects each vertex into image j and the
// rasteriser interpolates the result (perspective-correct, hence the projection of the
// fragment's own point, up to rounding; clipping keeps it so). Further earlier images are
// reached from the fragment's window position and depth, through one matrix per earlier image
// read in the fragment stage. The first way is the fast one on llvmpipe: it cannot assume that a
// fragment invocation is active in lane 0, so it loads every uniform, even at a constant address,
// one lane at a time, and a texel fetch costs about as much; sixteen such loads per matrix made
// the matrices the costliest part of the test, while an interpolated vec4 costs a few
// multiply-adds per fragment and its setup is shared by the triangle's fragments.
enable primitive_index;

struct View {
    // clip = proj * view * (p - scene_centre), formed in f64 on the host.
    view_proj: mat4x4<f32>,
    // For fs_peel, (k, c, 0, 0): a fragment is beyond the previous layer's window depth z by
    // the tie margin when its own depth is below k·z + c (see fs_peel).
    peel: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
// The index of this image among the images of the call, and so its number of earlier images,
// fixed when a non-redundant pipeline is made: loops over earlier images unroll and every texel
// coordinate below is a constant.
override earlier_count: u32 = 0u;
// Row i, texels 4k..4k+3 for earlier image j = VARYING_IMAGES + k: the columns of the matrix
// that maps a fragment's homogeneous window coordinates (x, y, depth, 1) in image i to
// (x·w, y·w, w, f) in earlier image j, scaled by the point's homogeneous weight 1/w_i > 0.
// Formed in f64 on the host and rounded once.
@group(0) @binding(1) var reproject: texture_2d<f32>;
// Triangle ids of the earlier images, one layer each; -1 where empty.
@group(0) @binding(2) var earlier_ids: texture_2d_array<i32>;
// The previous peeling layer's depth (reversed: larger is nearer); unused by the other passes.
@group(0) @binding(3) var previous_depth: texture_depth_2d;
// For camera j < VARYING_IMAGES: the map from a position relative to the scene centre to
// (x·w, y·w, w, f) in image j. Read in the vertex stage, where uniform loads are plain loads.
const VARYING_IMAGES: u32 = 4u;
@group(0) @binding(4) var<uniform> project_into: array<mat4x4<f32>, VARYING_IMAGES>;

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view.view_proj * vec4<f32>(p, 1.0);
}

// Algorithm 3: does earlier image j hold triangle `prim` at the pixel where a sample lands, given
// the sample's homogeneous position c = (x·w, y·w, w, f) in image j, up to a positive scale?
fn held_at(j: u32, c: vec4<f32>, prim: i32) -> bool {
    let px = c.xy * (1.0 / c.z);
    let size = vec2<f32>(textureDimensions(earlier_ids));
    // Branch-free: llvmpipe runs both sides of a branch under a lane mask anyway. The pixel is
    // clamped so that the fetch stays in image j even where the test already failed.
    let inside = c.w > 0.0 && c.z > 0.0 && all(px >= vec2<f32>(0.0)) && all(px < size);
    let pixel = vec2<i32>(clamp(px, vec2<f32>(0.0), size - 1.0));
    return inside && textureLoad(earlier_ids, pixel, j, 0).x == prim;
}

// The same test for the earlier images from VARYING_IMAGES on, reprojected from the fragment's
// window position and depth `frag`.
fn held_by_later(frag: vec4<f32>, prim: i32) -> bool {
    var held = false;
    let row = i32(earlier_count);
    for (var j = VARYING_IMAGES; j < earlier_count; j++) {
        let col = 4 * i32(j - VARYING_IMAGES);
        let m = mat4x4<f32>(
            textureLoad(reproject, vec2<i32>(col, row), 0),
            textureLoad(reproject, vec2<i32>(col + 1, row), 0),
            textureLoad(reproject, vec2<i32>(col + 2, row), 0),
            textureLoad(reproject, vec2<i32>(col + 3, row), 0),
        );
        held = held | held_at(j, m * vec4<f32>(frag.xyz, 1.0), prim);
    }
    return held;
}

// One vertex/fragment entry pair per count of interpolated earlier images (1 to VARYING_IMAGES),
// so that a pass interpolates only the positions it tests.
struct Earlier1 {
    @builtin(position) position: vec4<f32>,
    @location(0) c0: vec4<f32>,
};
struct Earlier2 {
    @builtin(position) position: vec4<f32>,
    @location(0) c0: vec4<f32>,
    @location(1) c1: vec4<f32>,
};
struct Earlier3 {
    @builtin(position) position: vec4<f32>,
    @location(0) c0: vec4<f32>,
    @location(1) c1: vec4<f32>,
    @location(2) c2: vec4<f32>,
};
struct Earlier4 {
    @builtin(position) position: vec4<f32>,
    @location(0) c0: vec4<f32>,
    @location(1) c1: vec4<f32>,
    @location(2) c2: vec4<f32>,
    @location(3) c3: vec4<f32>,
};

@vertex
fn vs_earlier1(@location(0) p: vec3<f32>) -> Earlier1 {
    let q = vec4<f32>(p, 1.0);
    return Earlier1(view.view_proj * q, project_into[0] * q);
}

@vertex
fn vs_earlier2(@location(0) p: vec3<f32>) -> Earlier2 {
    let q = vec4<f32>(p, 1.0);
    return Earlier2(view.view_proj * q, project_into[0] * q, project_into[1] * q);
}

@vertex
fn vs_earlier3(@location(0) p: vec3<f32>) -> Earlier3 {
    let q = vec4<f32>(p, 1.0);
    return Earlier3(
        view.view_proj * q,
        project_into[0] * q,
        project_into[1] * q,
        project_into[2] * q,
    );
}

@vertex
fn vs_earlier4(@location(0) p: vec3<f32>) -> Earlier4 {
    let q = vec4<f32>(p, 1.0);
    return Earlier4(
        view.view_proj * q,
        project_into[0] * q,
        project_into[1] * q,
        project_into[2] * q,
        project_into[3] * q,
    );
}

@fragment
fn fs_earlier1(v: Earlier1, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    let t = i32(prim);
    if held_at(0u, v.c0, t) {
        discard;
    }
    return t;
}

@fragment
fn fs_earlier2(v: Earlier2, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    let t = i32(prim);
    if held_at(0u, v.c0, t) | held_at(1u, v.c1, t) {
        discard;
    }
    return t;
}

@fragment
fn fs_earlier3(v: Earlier3, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    let t = i32(prim);
    if held_at(0u, v.c0, t) | held_at(1u, v.c1, t) | held_at(2u, v.c2, t) {
        discard;
    }
    return t;
}

// Four interpolated earlier images, and the rest (earlier_count > 4) through `reproject`.
@fragment
fn fs_earlier4(v: Earlier4, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    let t = i32(prim);
    let near = held_at(0u, v.c0, t) | held_at(1u, v.c1, t) | held_at(2u, v.c2, t)
        | held_at(3u, v.c3, t);
    if near | held_by_later(v.position, t) {
        discard;
    }
    return t;
}

// Image 0 of either method has nothing to test against: no discard, so the depth test can run
// before the fragment stage (early z), as in a conventional pass.
@fragment
fn fs_first(@builtin(primitive_index) prim: u32) -> @location(0) i32 {
    return i32(prim);
}

// Peeling passes carry fs_peel's two constants as a flat varying: the vertex stage loads the
// uniform once per vertex, where llvmpipe would load it lane by lane in every fragment.
struct Peel {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) kc: vec2<f32>,
};

@vertex
fn vs_peel(@location(0) p: vec3<f32>) -> Peel {
    return Peel(view.view_proj * vec4<f32>(p, 1.0), view.peel.xy);
}

@fragment
fn fs_peel(v: Peel, @builtin(primitive_index) prim: u32) -> @location(0) i32 {
    // Only images after the first use this entry point.
    let previous = textureLoad(previous_depth, vec2<i32>(v.position.xy), 0);
    // A surface within a relative margin m (`trace::SAME_HIT`) of the previous layer's camera z
    // d is that layer met again (a duplicated or coplanar face), not the next one: keep only
    // fragments beyond d (1 + m). Window depth is reversed and, for camera z d, b / d - a in
    // perspective and c - d / (far - near) in orthographic, so z(d (1 + m)) is linear in the
    // previous depth: k·previous + c, with k and c formed on the host. The host then checks
    // the same rule on the exact f64 depths (`nonredundant::render`) and removes what
    // float32 depth misjudged.
    if !(v.position.z < v.kc.x * previous + v.kc.y) {
        discard;
    }
    return i32(prim);
}
