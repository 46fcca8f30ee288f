// Copies the viewer's offscreen frame (the same pixels `tessera render` writes) onto
// the window surface: one full-screen triangle, nearest sampling (same size).
@group(0) @binding(0) var frame_tex: texture_2d<f32>;

struct Out {
    @builtin(position) clip: vec4<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> Out {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: Out;
    out.clip = vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
    return out;
}

@fragment
fn fs_main(o: Out) -> @location(0) vec4<f32> {
    return textureLoad(frame_tex, vec2<i32>(o.clip.xy), 0);
}
