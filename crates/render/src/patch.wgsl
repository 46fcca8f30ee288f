// Tessera patch shader: one draw per patch from the shared vertex/index buffers of the
// GPU cache. Positions are in the model's local frame (model coordinates minus the
// cube origin, so f32 keeps the quantisation grid exact); the camera matrices are built
// in the same frame on the CPU in f64 and rounded once.
//
// Lighting: a head light (a directional light from just above and left of the eye) plus
// a hemispheric ambient term, on the per-vertex colour (or a neutral clay colour when
// the model has none). Kept simple on purpose: it must look the same on lavapipe and a
// real GPU, and be cheap.

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: unit direction TOWARD the light, view-independent (local frame); w unused.
    light_dir: vec4<f32>,
    // xyz: up direction of the camera for the hemispheric ambient; w: 1 when the model
    // has per-vertex colours, 0 to use the clay colour.
    sky_up_has_color: vec4<f32>,
    clay: vec4<f32>,
    // x: colour mode (0 natural, 1 by node, 2 by level); y: 1 = unlit.
    mode: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;

// Geomorphing (GoLD): every vertex carries its morph target (the position, normal and
// colour it takes in its parent's shape) and each draw its node's ratio r, as instance
// data: r = 0 draws the node's own shape, r = 1 its parent's. `a + (b - a) * r` keeps a
// vertex whose target is itself (locked borders, survivors) bit-exact at every ratio,
// so neighbours morphing at different ratios meet exactly there.
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) target_pos: vec3<f32>,
    // Octahedral unit normals (snorm16 x 2), own and target.
    @location(2) normal: vec2<f32>,
    @location(3) target_normal: vec2<f32>,
    @location(4) color: vec4<f32>,
    @location(5) target_color: vec4<f32>,
    // Per draw: the morph ratio, and the node's tag (`vertex_tag`: level in the top 6
    // bits, a hash of the node in the low 10).
    @location(6) ratio: f32,
    @location(7) tag: u32,
}

fn oct_decode(e: vec2<f32>) -> vec3<f32> {
    let z = 1.0 - abs(e.x) - abs(e.y);
    let t = max(-z, 0.0);
    let s = select(vec2<f32>(1.0), vec2<f32>(-1.0), e < vec2<f32>(0.0));
    return normalize(vec3<f32>(e - s * t, z));
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec3<f32>,
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let r = v.ratio;
    let p = v.position + (v.target_pos - v.position) * r;
    out.clip = frame.view_proj * vec4<f32>(p, 1.0);
    let n0 = oct_decode(v.normal);
    out.normal = n0 + (oct_decode(v.target_normal) - n0) * r;
    let tag = v.tag & 0xFFFFu;
    let c = v.color + (v.target_color - v.color) * r;
    // No branches: with a branch on the uniform around per-vertex work, lavapipe
    // (Mesa 22.3) keeps ~260 KB a frame (RSS grew 116 -> 392 MB over 1,200 frames of
    // a fixed camera); computing all three colours and selecting leaks nothing.
    let natural = select(frame.clay.rgb, c.rgb, frame.sky_up_has_color.w > 0.5);
    // By level: hue from blue (coarse) to red (fine) over 12 levels, then again (a view
    // shows a few adjacent levels; they must look different).
    let by_level = hue(0.66 - f32((tag >> 10u) % 12u) / 11.0 * 0.66);
    // By node: a hashed hue per node, pastel so the shading still reads.
    let by_node = mix(hue(f32(tag & 1023u) / 1023.0), vec3<f32>(1.0), 0.25);
    let color = select(select(natural, by_node, frame.mode.x > 0.5), by_level, frame.mode.x > 1.5);
    out.color = color;
    return out;
}

fn hue(h: f32) -> vec3<f32> {
    let k = fract(vec3<f32>(h) + vec3<f32>(0.0, 2.0 / 3.0, 1.0 / 3.0)) * 6.0;
    return clamp(abs(k - 3.0) - 1.0, vec3<f32>(0.0), vec3<f32>(1.0));
}

@fragment
fn fs_main(f: VertexOut) -> @location(0) vec4<f32> {
    let len = length(f.normal);
    let n = select(vec3<f32>(0.0, 0.0, 0.0), f.normal / len, len > 1e-6);
    let diffuse = max(dot(n, frame.light_dir.xyz), 0.0);
    let hemi = 0.5 + 0.5 * dot(n, frame.sky_up_has_color.xyz);
    let ambient = mix(0.12, 0.28, hemi);
    let lit = select(f.color * (ambient + 0.75 * diffuse), f.color, frame.mode.y > 0.5);
    return vec4<f32>(clamp(lit, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

// Wireframe overlay: dark, half transparent edges.
@fragment
fn fs_wire(f: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(0.05, 0.06, 0.08, 0.55);
}
