// EPR splatting (eye-based-point-rendering.txt §3.5): every point is scattered into every view
// whose bit its visibility string sets. The host turns the bit strings into one list of points
// per view and runs one dispatch per view (and per chunk of points) with that view's camera in a
// uniform, so every invocation does real work and no lane gathers per-view data. The point is a
// world-space square of side 2·half_side centred on the point, in its triangle's plane, its
// edges along (u) and across (v) the triangle's longest edge; the host computes u, v and the
// triangle's vertices in (u, v) coordinates once per point, so that a pair reads four texels and
// projects three vectors: the corners are pc ± h·pu ± h·pv and the vertices pc + a·pu + b·pv.
// The pixels of the corners' 2D bounding box receive the point through one 64-bit atomic per
// pixel on the key (depth bits << 32 | point index): the smallest key wins whatever order the
// invocations run in (positive f32 depths order like their bit patterns), so the nearest point,
// and of equally near ones the lowest index. The buffers hold the keys complemented, written
// with atomicMax, so that a zero-filled buffer (clear_buffer, no clearing pass) means empty; the
// host complements them back. With the clip flag set, a pixel is written only when its square
// overlaps the projected triangle (a conservative edge-function test at the pixel corner that
// lies farthest inside each edge), which trims the splat's overhang beyond its triangle without
// opening holes at the triangle's edges.
//
// Needs the SHADER_INT64 and SHADER_INT64_ATOMIC_MIN_MAX features; the only 64-bit atomics are
// atomicMax statements (no result used), which is all SHADER_INT64_ATOMIC_MIN_MAX allows.

struct View {
    // clip = view_proj * (p - scene_centre, 1), formed in f64 on the host.
    view_proj: mat4x4<f32>,
    // Camera-space depth of p: dot(p - scene_centre, forward) - eye_depth, with
    // forward_depth = (forward.xyz, eye_depth), forward the unit viewing direction.
    forward_depth: vec4<f32>,
    // x: the near plane's depth; points nearer than it are not splatted into this view (a cube
    // map's near plane on its reflector's bounding sphere keeps the reflector out of it).
    near: vec4<f32>,
    // Width, height, the view's first pixel in `packed` (views may differ in size), and
    // non-zero to keep only pixels overlapping the point's triangle.
    size: vec4<u32>,
    // Points in this dispatch, the first of them in `list`, and the index of the first point
    // of the bound `geometry` chunk (list entries are global point indices).
    range: vec4<u32>,
};

@group(0) @binding(0) var<uniform> view: View;
// Per point of the bound chunk, four texels (16 floats): the centre relative to the scene
// centre (xyz) and half the side (w); the unit axes u (floats 4..7) and v (7..10); the
// triangle's vertices relative to the centre in (u, v) coordinates (10..16), all zero for a
// degenerate triangle. Point p of the chunk is texel 4p, row-major with ROW texels per row.
// Textures rather than storage buffers: llvmpipe fetches texels for all lanes at once, where it
// loads from a storage buffer one lane at a time.
@group(0) @binding(1) var geometry: texture_2d<f32>;
// The points to splat into this view (and its neighbours in the same submission), entry i at
// texel i, row-major with ROW texels per row.
@group(0) @binding(2) var list: texture_2d<u32>;
// The off-screen buffers, view after view (each at its `size.z`), row-major: complemented
// keys, 0 where empty.
@group(0) @binding(3) var<storage, read_write> packed: array<atomic<u64>>;

// Texels per row of both textures (gpu::splat::TEXTURE_ROW): 2^ROW_SHIFT.
const ROW_SHIFT: u32 = 12u;

fn texel(i: u32) -> vec2<u32> {
    return vec2<u32>(i & ((1u << ROW_SHIFT) - 1u), i >> ROW_SHIFT);
}

fn to_pixels(c: vec4<f32>, size: vec2<f32>) -> vec2<f32> {
    // Pixel coordinates: x right, y down, (0, 0) the top-left corner of the image.
    let ndc = c.xy / c.w;
    return vec2<f32>((ndc.x * 0.5 + 0.5) * size.x, (0.5 - ndc.y * 0.5) * size.y);
}

// One edge p->q of a counter-clockwise triangle as a test of lower pixel corners x:
// a·(x + d) >= 0 with a = the edge's inward normal and d = the offset from x to the pixel
// corner farthest inside the edge, minus p. A pixel the triangle merely touches passes.
fn edge_test(p: vec2<f32>, q: vec2<f32>) -> vec4<f32> {
    let inward = vec2<f32>(p.y - q.y, q.x - p.x);
    let corner = vec2<f32>(select(0.0, 1.0, inward.x > 0.0), select(0.0, 1.0, inward.y > 0.0));
    return vec4<f32>(inward, corner - p);
}

fn inside(e: vec4<f32>, x: vec2<f32>) -> bool {
    return !(e.x * (x.x + e.z) + e.y * (x.y + e.w) < 0.0);
}

@compute @workgroup_size(64)
fn cs_splat(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= view.range.x {
        return;
    }
    let point = textureLoad(list, texel(view.range.y + i), 0).x;
    let at = texel(4u * (point - view.range.z));
    let g0 = textureLoad(geometry, at, 0);
    let centre = g0.xyz;
    let depth = dot(centre, view.forward_depth.xyz) - view.forward_depth.w;
    if !(depth > 0.0 && depth >= view.near.x) {
        return;
    }
    let h = g0.w;
    let g1 = textureLoad(geometry, at + vec2<u32>(1u, 0u), 0);
    let g2 = textureLoad(geometry, at + vec2<u32>(2u, 0u), 0);
    let u = g1.xyz;
    let v = vec3<f32>(g1.w, g2.xy);
    let pc = view.view_proj * vec4<f32>(centre, 1.0);
    let pu = view.view_proj * vec4<f32>(u, 0.0);
    let pv = view.view_proj * vec4<f32>(v, 0.0);

    // Project the corners; a point with a corner behind the camera is skipped in this view.
    let size = vec2<f32>(f32(view.size.x), f32(view.size.y));
    let hu = h * pu;
    let hv = h * pv;
    let c0 = pc - hu - hv;
    let c1 = pc + hu - hv;
    let c2 = pc - hu + hv;
    let c3 = pc + hu + hv;
    if !(min(min(c0.w, c1.w), min(c2.w, c3.w)) > 0.0) {
        return;
    }
    let p0 = to_pixels(c0, size);
    let p1 = to_pixels(c1, size);
    let p2 = to_pixels(c2, size);
    let p3 = to_pixels(c3, size);
    let lo = min(min(p0, p1), min(p2, p3));
    let hi = max(max(p0, p1), max(p2, p3));
    // Every pixel whose square overlaps the box (a box inside one pixel still covers it).
    let x0 = i32(max(floor(lo.x), 0.0));
    let y0 = i32(max(floor(lo.y), 0.0));
    let x1 = i32(min(ceil(hi.x), size.x)) - 1;
    let y1 = i32(min(ceil(hi.y), size.y)) - 1;
    if x1 < x0 || y1 < y0 {
        return;
    }

    // The triangle in pixel coordinates, counter-clockwise, as three edge tests.
    var clip = view.size.w != 0u;
    var ea = vec4<f32>(0.0);
    var eb = vec4<f32>(0.0);
    var ec = vec4<f32>(0.0);
    if clip {
        let g3 = textureLoad(geometry, at + vec2<u32>(3u, 0u), 0);
        let ta = pc + g2.z * pu + g2.w * pv;
        let tb = pc + g3.x * pu + g3.y * pv;
        let tc = pc + g3.z * pu + g3.w * pv;
        if ta.w > 0.0 && tb.w > 0.0 && tc.w > 0.0 {
            let a = to_pixels(ta, size);
            var b = to_pixels(tb, size);
            var c = to_pixels(tc, size);
            let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
            if area < 0.0 {
                let t = b;
                b = c;
                c = t;
            }
            // Seen edge-on (or degenerate): no pixel is inside; keep the box rather than drop
            // the point.
            clip = area != 0.0;
            ea = edge_test(a, b);
            eb = edge_test(b, c);
            ec = edge_test(c, a);
        } else {
            // A vertex behind the camera: the projected triangle is unbounded; keep the box.
            clip = false;
        }
    }

    let key = ~((u64(bitcast<u32>(depth)) << 32u) | u64(point));
    let width = view.size.x;
    let base = view.size.z;
    for (var y = y0; y <= y1; y++) {
        for (var x = x0; x <= x1; x++) {
            let px = vec2<f32>(f32(x), f32(y));
            if clip && !(inside(ea, px) && inside(eb, px) && inside(ec, px)) {
                continue;
            }
            atomicMax(&packed[base + u32(y) * width + u32(x)], key);
        }
    }
}
