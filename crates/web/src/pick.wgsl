@group(0) @binding(0) var depth_tex: texture_2d<f32>;
@group(0) @binding(1) var nearest: sampler;
// The pixel's centre in texture coordinates (0..1, top-left origin).
@group(0) @binding(2) var<uniform> at: vec4<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the (one-pixel) target.
    let x = f32((i << 1u) & 2u);
    let y = f32(i & 2u);
    return vec4<f32>(x * 2.0 - 1.0, y * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_main() -> @location(0) vec4<f32> {
    let d = textureSampleLevel(depth_tex, nearest, at.xy, 0.0).x;
    let b = bitcast<u32>(d);
    let bytes = vec4<u32>(b, b >> 8u, b >> 16u, b >> 24u) & vec4<u32>(255u);
    return vec4<f32>(bytes) / 255.0;
}
