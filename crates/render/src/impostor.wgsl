// Texture impostors (tessera_stream::impostor): a model far away drawn as its texture on
// a quad facing the eye it was sampled from. Quad corners come in the frame's
// eye-relative world coordinates (f32 near the eye); the texture is the model drawn by
// the patch shader from the sampling eye over a transparent background, so its alpha
// says where the model is. A quad in a dissolve keeps only the pixels whose dither
// threshold is in its [keep.x, keep.y), the model's geometry (fs_*_dissolve in
// patch.wgsl, the same dither) the others.

struct Quads {
    view_proj: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> quads: Quads;
@group(1) @binding(0) var impostor_texture: texture_2d<f32>;
@group(1) @binding(1) var impostor_sampler: sampler;

struct QuadIn {
    @location(0) position: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) keep: vec2<f32>,
}

struct QuadOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) keep: vec2<f32>,
}

@vertex
fn vs_quad(v: QuadIn) -> QuadOut {
    var out: QuadOut;
    out.clip = quads.view_proj * vec4<f32>(v.position, 1.0);
    out.uv = v.uv;
    out.keep = v.keep;
    return out;
}

// Interleaved gradient noise (Jimenez 2014), as patch.wgsl's `dither`.
fn dither(frag: vec2<f32>) -> f32 {
    return fract(52.9829189 * fract(dot(floor(frag), vec2<f32>(0.06711056, 0.00583715))));
}

@fragment
fn fs_quad(f: QuadOut) -> @location(0) vec4<f32> {
    let c = textureSample(impostor_texture, impostor_sampler, f.uv);
    let h = dither(f.clip.xy);
    // Texels the model covered (alpha from the sample's coverage, filtered at the
    // silhouette: kept above one half).
    if c.a < 0.5 || h < f.keep.x || h >= f.keep.y {
        discard;
    }
    return vec4<f32>(c.rgb / c.a, 1.0);
}
