// Tessera patch shader: one draw per patch from the shared vertex/index buffers of the
// GPU cache. Positions are in the model's local frame (model coordinates minus the
// cube origin, so f32 keeps the quantisation grid exact); the camera matrices are built
// in the same frame on the CPU in f64 and rounded once.
//
// Lighting: a head light (a directional light from just above and left of the eye) plus
// a hemispheric ambient term, on the per-vertex colour (or a neutral clay colour when
// the model has none). Kept simple on purpose: it must look the same on lavapipe and a
// real GPU, and be cheap.
//
// Textured models (a texture per patch) draw through `vs_textured` / `fs_textured`, a
// second pipeline: the colour slots of the vertex hold the texture coordinate and its
// morph target (unorm16 x 2 each), the fragment samples the patch texture (group 1), and
// the colour modes and the lighting are the same functions as the untextured path's.

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: unit direction TOWARD the light, view-independent (local frame); w unused.
    light_dir: vec4<f32>,
    // xyz: up direction of the camera for the hemispheric ambient; w: 1 when the model
    // has per-vertex colours, 0 to use the clay colour.
    sky_up_has_color: vec4<f32>,
    clay: vec4<f32>,
    // x: colour mode (0 natural, 1 by node, 2 by level); y: 1 = unlit; zw: the dither
    // thresholds a dissolving model keeps ([z, w); the `_dissolve` entry points only).
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

// The morphed vertex in clip space, and its morphed (unnormalised) normal: shared by
// both vertex entry points.
fn morph_clip(position: vec3<f32>, target_pos: vec3<f32>, r: f32) -> vec4<f32> {
    let p = position + (target_pos - position) * r;
    return frame.view_proj * vec4<f32>(p, 1.0);
}

fn morph_normal(normal: vec2<f32>, target_normal: vec2<f32>, r: f32) -> vec3<f32> {
    let n0 = oct_decode(normal);
    return n0 + (oct_decode(target_normal) - n0) * r;
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
    out.clip = morph_clip(v.position, v.target_pos, r);
    out.normal = morph_normal(v.normal, v.target_normal, r);
    let c = v.color + (v.target_color - v.color) * r;
    let natural = select(frame.clay.rgb, c.rgb, frame.sky_up_has_color.w > 0.5);
    out.color = mode_color(natural, v.tag);
    return out;
}

// The colour of the frame's colour mode: `natural` (mode 0), by node or by level.
// No branches: with a branch on the uniform around per-vertex work, lavapipe
// (Mesa 22.3) keeps ~260 KB a frame (RSS grew 116 -> 392 MB over 1,200 frames of
// a fixed camera); computing all three colours and selecting leaks nothing.
fn mode_color(natural: vec3<f32>, draw_tag: u32) -> vec3<f32> {
    let tag = draw_tag & 0xFFFFu;
    // By level: hue from blue (coarse) to red (fine) over 12 levels, then again (a view
    // shows a few adjacent levels; they must look different).
    let by_level = hue(0.66 - f32((tag >> 10u) % 12u) / 11.0 * 0.66);
    // By node: a hashed hue per node, pastel so the shading still reads.
    let by_node = mix(hue(f32(tag & 1023u) / 1023.0), vec3<f32>(1.0), 0.25);
    return select(select(natural, by_node, frame.mode.x > 0.5), by_level, frame.mode.x > 1.5);
}

fn hue(h: f32) -> vec3<f32> {
    let k = fract(vec3<f32>(h) + vec3<f32>(0.0, 2.0 / 3.0, 1.0 / 3.0)) * 6.0;
    return clamp(abs(k - 3.0) - 1.0, vec3<f32>(0.0), vec3<f32>(1.0));
}

@fragment
fn fs_main(f: VertexOut) -> @location(0) vec4<f32> {
    return shade(f.normal, f.color);
}

// Head light + hemispheric ambient on `color` (or `color` as it is, unlit mode), for the
// interpolated `normal`.
fn shade(normal: vec3<f32>, color: vec3<f32>) -> vec4<f32> {
    let len = length(normal);
    let n = select(vec3<f32>(0.0, 0.0, 0.0), normal / len, len > 1e-6);
    let diffuse = max(dot(n, frame.light_dir.xyz), 0.0);
    let hemi = 0.5 + 0.5 * dot(n, frame.sky_up_has_color.xyz);
    let ambient = mix(0.12, 0.28, hemi);
    let lit = select(color * (ambient + 0.75 * diffuse), color, frame.mode.y > 0.5);
    return vec4<f32>(clamp(lit, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

// Textured models: the patch's texture and the sampler (linear, trilinear mips, clamped).
@group(1) @binding(0) var patch_texture: texture_2d<f32>;
@group(1) @binding(1) var patch_sampler: sampler;

// The vertex of a textured model: `VertexIn` with texture coordinates (own and target,
// unorm16 x 2: 0..1, origin top left, v down) in the colour slots.
struct TexturedIn {
    @location(0) position: vec3<f32>,
    @location(1) target_pos: vec3<f32>,
    @location(2) normal: vec2<f32>,
    @location(3) target_normal: vec2<f32>,
    @location(4) uv: vec2<f32>,
    @location(5) target_uv: vec2<f32>,
    @location(6) ratio: f32,
    @location(7) tag: u32,
    // Per draw: mip levels between the patch's texels and its parent's.
    @location(8) texel_lod: f32,
}

struct TexturedOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    // The colour by node or by level (unused in the natural mode: the texel is).
    @location(1) color: vec3<f32>,
    @location(2) uv: vec2<f32>,
    // The finest mip level to sample: ratio * texel_lod (0 for a patch at its own
    // shape), so a patch morphing in from its parent shows its parent's texel detail.
    @location(3) @interpolate(flat) min_lod: f32,
}

@vertex
fn vs_textured(v: TexturedIn) -> TexturedOut {
    var out: TexturedOut;
    let r = v.ratio;
    out.clip = morph_clip(v.position, v.target_pos, r);
    out.normal = morph_normal(v.normal, v.target_normal, r);
    out.uv = v.uv + (v.target_uv - v.uv) * r;
    out.color = mode_color(frame.clay.rgb, v.tag);
    out.min_lod = r * v.texel_lod;
    return out;
}

@fragment
fn fs_textured(f: TexturedOut) -> @location(0) vec4<f32> {
    return textured_color(f);
}

fn textured_color(f: TexturedOut) -> vec4<f32> {
    // Sampled in uniform control flow; the mode picks by selection, as `mode_color`.
    // The texture's own level of detail, from the uv's screen derivatives in texels,
    // raised to `min_lod` by scaling the derivatives (a patch at its own shape samples
    // with the true derivatives: exactly `textureSample`).
    let size = vec2<f32>(textureDimensions(patch_texture, 0));
    let dx = dpdx(f.uv);
    let dy = dpdy(f.uv);
    let rho = max(length(dx * size), length(dy * size));
    let floor_rho = exp2(f.min_lod);
    let k = select(1.0, floor_rho / max(rho, 1e-8), f.min_lod > 0.0 && rho < floor_rho);
    let texel = textureSampleGrad(patch_texture, patch_sampler, f.uv, dx * k, dy * k).rgb;
    return shade(f.normal, select(texel, f.color, frame.mode.x > 0.5));
}

// A model dissolving into or out of its impostor (tessera_stream::impostor): each pixel
// shows it where its dither threshold is in [mode.z, mode.w), the impostor elsewhere.
// Separate entry points (and pipelines), so the plain ones keep no discard.
fn dissolved(frag: vec2<f32>) -> bool {
    let h = dither(frag);
    return h < frame.mode.z || h >= frame.mode.w;
}

// Interleaved gradient noise (Jimenez 2014): a threshold in [0, 1) per pixel, evenly
// spread over every small block of pixels; `impostor.wgsl` has the same.
fn dither(frag: vec2<f32>) -> f32 {
    return fract(52.9829189 * fract(dot(floor(frag), vec2<f32>(0.06711056, 0.00583715))));
}

@fragment
fn fs_main_dissolve(f: VertexOut) -> @location(0) vec4<f32> {
    if dissolved(f.clip.xy) {
        discard;
    }
    return shade(f.normal, f.color);
}

@fragment
fn fs_textured_dissolve(f: TexturedOut) -> @location(0) vec4<f32> {
    let c = textured_color(f);
    if dissolved(f.clip.xy) {
        discard;
    }
    return c;
}

// Wireframe overlay: dark, half transparent edges.
@fragment
fn fs_wire(f: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(0.05, 0.06, 0.08, 0.55);
}
