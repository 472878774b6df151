// EPR splatting (eye-based-point-rendering.txt §3.5): every point is scattered into every view
// whose bit its visibility string sets. The host turns the bit strings into a list of
// (point, view) pairs, grouped by view, so that every invocation does real work and the lanes of
// a SIMD group mostly share one view. The point is a world-space square of side `length`
// centred on the point, in its triangle's plane, its edges along and across the triangle's
// longest edge. The square's four corners are projected into the view and the pixels of their
// 2D bounding box receive the point through one 64-bit atomic per pixel on the key
// (depth bits << 32 | point index): the smallest key wins whatever order the invocations run in
// (positive f32 depths order like their bit patterns), so the nearest point, and of equally near
// ones the lowest index. The buffers hold the keys complemented, written with atomicMax, so that
// a zero-filled buffer (clear_buffer, no clearing pass) means empty; the host complements them
// back. With `clip` set, a pixel is written only when its square
// overlaps the projected triangle (a conservative edge-function test at the pixel corner that
// lies farthest inside each edge), which trims the splat's overhang beyond its triangle without
// opening holes at the triangle's edges.
//
// Needs the SHADER_INT64 and SHADER_INT64_ATOMIC_MIN_MAX features; the only 64-bit atomics are
// atomicMax statements (no result used), which is all SHADER_INT64_ATOMIC_MIN_MAX allows.

struct Params {
    // Pairs in this dispatch and the index of the first, so that long pair lists go in chunks.
    count: u32,
    first: u32,
    // Non-zero: keep only pixels overlapping the point's triangle.
    clip: u32,
    _pad: u32,
};

struct View {
    // clip = view_proj * (p - scene_centre, 1), formed in f64 on the host.
    view_proj: mat4x4<f32>,
    // Camera-space depth of p: dot(p - scene_centre, forward) - eye_depth, with
    // forward_depth = (forward.xyz, eye_depth), forward the unit viewing direction.
    forward_depth: vec4<f32>,
    // x: the near plane's depth; points nearer than it are not splatted into this view (a cube
    // map's near plane on its reflector's bounding sphere keeps the reflector out of it).
    near: vec4<f32>,
    // Width, height, and the view's first pixel in `packed` (views may differ in size).
    size_offset: vec4<u32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> views: array<View>;
// Per point: centre relative to the scene centre (xyz) and splat side length (w).
@group(0) @binding(2) var<storage, read> centers: array<vec4<f32>>;
// Per point: its triangle (index into `faces`, as u32 bits).
@group(0) @binding(3) var<storage, read> triangles: array<u32>;
// (point, view within this submission) pairs to splat.
@group(0) @binding(4) var<storage, read> pairs: array<vec2<u32>>;
// Scene vertex positions relative to the scene centre, three floats each, and faces.
@group(0) @binding(5) var<storage, read> positions: array<f32>;
@group(0) @binding(6) var<storage, read> faces: array<u32>;
// The off-screen buffers, view after view (each at its `size_offset`), row-major: complemented
// keys, 0 where empty.
@group(0) @binding(7) var<storage, read_write> packed: array<atomic<u64>>;

fn vertex(i: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
}

// 2D cross product of (b - a) and (p - a): positive when p is left of a->b.
fn edge(a: vec2<f32>, b: vec2<f32>, p: vec2<f32>) -> f32 {
    return (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
}

// Does the unit pixel square with lower corner `px` overlap the triangle (a, b, c), given in
// pixel coordinates with counter-clockwise order? Each edge is tested at the pixel corner
// farthest to its inner side, so a pixel the triangle merely touches is kept.
fn overlaps(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, px: vec2<f32>) -> bool {
    var ok = true;
    for (var k = 0; k < 3; k++) {
        var p = a;
        var q = b;
        if k == 1 {
            p = b;
            q = c;
        } else if k == 2 {
            p = c;
            q = a;
        }
        // The inward normal of edge p->q (left side) is (-(q.y - p.y), q.x - p.x).
        let inward = vec2<f32>(p.y - q.y, q.x - p.x);
        let corner = px + vec2<f32>(select(0.0, 1.0, inward.x > 0.0), select(0.0, 1.0, inward.y > 0.0));
        if edge(p, q, corner) < 0.0 {
            ok = false;
        }
    }
    return ok;
}

@compute @workgroup_size(64)
fn cs_splat(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= params.count {
        return;
    }
    let pair = pairs[params.first + i];
    let point = pair.x;
    let view = views[pair.y];
    let cl = centers[point];
    let centre = cl.xyz;
    let half_side = 0.5 * cl.w;
    let tri = triangles[point];
    let v0 = vertex(faces[3u * tri]);
    let v1 = vertex(faces[3u * tri + 1u]);
    let v2 = vertex(faces[3u * tri + 2u]);

    // The square's axes: along the longest edge, and across it in the triangle's plane.
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    let e2 = v0 - v2;
    var along = e0;
    if dot(e1, e1) > dot(along, along) {
        along = e1;
    }
    if dot(e2, e2) > dot(along, along) {
        along = e2;
    }
    let n = cross(e0, -e2);
    var u = vec3<f32>(1.0, 0.0, 0.0);
    var v = vec3<f32>(0.0, 1.0, 0.0);
    let la = length(along);
    let ln = length(n);
    if la > 0.0 && ln > 0.0 {
        u = along / la;
        v = cross(n / ln, u);
    }

    // Project the corners; a point with a corner behind the camera is skipped in this view.
    var lo = vec2<f32>(3.4e38, 3.4e38);
    var hi = vec2<f32>(-3.4e38, -3.4e38);
    let width = view.size_offset.x;
    let size = vec2<f32>(f32(width), f32(view.size_offset.y));
    for (var k = 0u; k < 4u; k++) {
        let su = select(-half_side, half_side, (k & 1u) != 0u);
        let sv = select(-half_side, half_side, (k & 2u) != 0u);
        let c = view.view_proj * vec4<f32>(centre + su * u + sv * v, 1.0);
        if !(c.w > 0.0) {
            return;
        }
        let ndc = c.xy / c.w;
        // Pixel coordinates: x right, y down, (0, 0) the top-left corner of the image.
        let px = vec2<f32>((ndc.x * 0.5 + 0.5) * size.x, (0.5 - ndc.y * 0.5) * size.y);
        lo = min(lo, px);
        hi = max(hi, px);
    }
    let depth = dot(centre, view.forward_depth.xyz) - view.forward_depth.w;
    if !(depth > 0.0 && depth >= view.near.x) {
        return;
    }
    // Every pixel whose square overlaps the box (a box inside one pixel still covers it).
    let x0 = i32(max(floor(lo.x), 0.0));
    let y0 = i32(max(floor(lo.y), 0.0));
    let x1 = i32(min(ceil(hi.x), size.x)) - 1;
    let y1 = i32(min(ceil(hi.y), size.y)) - 1;
    if x1 < x0 || y1 < y0 {
        return;
    }

    // The triangle in pixel coordinates, counter-clockwise, for the clip test.
    var clip = params.clip != 0u;
    var a = vec2<f32>(0.0);
    var b = vec2<f32>(0.0);
    var c = vec2<f32>(0.0);
    if clip {
        let ca = view.view_proj * vec4<f32>(v0, 1.0);
        let cb = view.view_proj * vec4<f32>(v1, 1.0);
        let cc = view.view_proj * vec4<f32>(v2, 1.0);
        if ca.w > 0.0 && cb.w > 0.0 && cc.w > 0.0 {
            a = vec2<f32>((ca.x / ca.w * 0.5 + 0.5) * size.x, (0.5 - ca.y / ca.w * 0.5) * size.y);
            b = vec2<f32>((cb.x / cb.w * 0.5 + 0.5) * size.x, (0.5 - cb.y / cb.w * 0.5) * size.y);
            c = vec2<f32>((cc.x / cc.w * 0.5 + 0.5) * size.x, (0.5 - cc.y / cc.w * 0.5) * size.y);
            let area = edge(a, b, c);
            if area < 0.0 {
                let t = b;
                b = c;
                c = t;
            } else if area == 0.0 {
                // Seen edge-on: no pixel is inside; keep the box rather than drop the point.
                clip = false;
            }
        } else {
            // A vertex behind the camera: the projected triangle is unbounded; keep the box.
            clip = false;
        }
    }

    let key = ~((u64(bitcast<u32>(depth)) << 32u) | u64(point));
    let base = view.size_offset.z;
    for (var y = y0; y <= y1; y++) {
        for (var x = x0; x <= x1; x++) {
            if clip && !overlaps(a, b, c, vec2<f32>(f32(x), f32(y))) {
                continue;
            }
            atomicMax(&packed[base + u32(y) * width + u32(x)], key);
        }
    }
}
