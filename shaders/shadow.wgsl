// Shadow maps for soft shadows from a discretized scene (non-redundant-rendering.txt §5,
// Algorithm 5, steps 4-9): for each light sample, render the occluders' depth from the sample
// (vs_depth, no fragment stage), then test every output point against it (cs_test), one
// invocation per 32 points writing one word of visibility bits.

struct Light {
    // clip = proj * view * (p - scene_centre) of the light sample's camera, formed in f64.
    view_proj: mat4x4<f32>,
    // The light sample, relative to the scene centre.
    position: vec4<f32>,
    // Reversed-depth linearization: camera depth = b / (ndc_z + a); x = a, y = b.
    // z: shadow-map texel size at camera depth 1; w: absolute bias (world units).
    params: vec4<f32>,
    // x: shadow-map resolution (square); y: number of points; z: first output word.
    sizes: vec4<u32>,
};

@group(0) @binding(0) var<uniform> light: Light;
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
// Unit normals facing the eye; zero for a point without a surface.
@group(0) @binding(2) var<storage, read> normals: array<vec4<f32>>;
@group(0) @binding(3) var shadow_map: texture_depth_2d;
@group(0) @binding(4) var<storage, read_write> visible: array<u32>;

@vertex
fn vs_depth(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    return light.view_proj * vec4<f32>(p, 1.0);
}

// Is the light sample visible from point i? Facing away from the sample: no. Outside the
// shadow map's view, or where it holds nothing: yes. Otherwise yes when the point is no more
// than the bias beyond the occluder depth stored at its texel; the bias grows with the texel's
// footprint and the slope of the surface as seen from the light (tangent capped at 8).
fn lit(i: u32) -> bool {
    let n = normals[i].xyz;
    let p = points[i].xyz;
    let to_light = light.position.xyz - p;
    let dist = length(to_light);
    let c = dot(n, to_light) / max(dist, 1e-30);
    if !(c > 0.0) {
        return false;
    }
    let clip = light.view_proj * vec4<f32>(p, 1.0);
    if !(clip.w > 0.0) {
        return true;
    }
    let ndc = clip.xyz / clip.w;
    let res = f32(light.sizes.x);
    let px = vec2<f32>((ndc.x + 1.0) * 0.5 * res, (1.0 - ndc.y) * 0.5 * res);
    if !(px.x >= 0.0 && px.y >= 0.0 && px.x < res && px.y < res) {
        return true;
    }
    let stored = textureLoad(shadow_map, vec2<i32>(px), 0);
    if stored <= 0.0 {
        return true;
    }
    let occluder = light.params.y / (stored + light.params.x);
    let tan_slope = min(sqrt(max(1.0 - c * c, 0.0)) / c, 8.0);
    let bias = 1.5 * light.params.z * clip.w * (1.0 + tan_slope) + light.params.w;
    return clip.w <= occluder + bias;
}

@compute @workgroup_size(64)
fn cs_test(@builtin(global_invocation_id) id: vec3<u32>) {
    let word = id.x;
    let count = light.sizes.y;
    if word * 32u >= count {
        return;
    }
    var bits = 0u;
    for (var k = 0u; k < 32u; k++) {
        let i = word * 32u + k;
        if i < count && lit(i) {
            bits |= 1u << k;
        }
    }
    visible[light.sizes.z + word] = bits;
}
