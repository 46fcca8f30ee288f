//! The draw path of devices without `base_vertex` (WebGL2: the browser client binds the
//! vertex buffer at each patch's first vertex instead) gives the same pixels as the
//! native one, on lavapipe. A missing adapter is a failure, not a skip.

use tessera_format::PatchData;
use tessera_render::{FrameParams, Gpu, GpuCache, Image, Renderer};
use tessera_select::Camera;

/// A quad of grid size `s` at grid offset `(x, y)` in the z = 0 plane, facing +z.
fn quad(x: u32, y: u32, s: u32) -> PatchData {
    PatchData {
        positions: vec![[x, y, 0], [x + s, y, 0], [x + s, y + s, 0], [x, y + s, 0]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Default::default()
    }
}

fn draw(gpu: &Gpu, base_vertex: bool) -> Image {
    let mut r = Renderer::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
    r.set_base_vertex(base_vertex);
    r.ensure_offscreen(&gpu.device, 96, 64);
    let mut cache = GpuCache::new(&gpu.device, 4 << 20);
    let step = 1.0 / 64.0;
    // Three patches, so two of them start past vertex 0 of the shared buffer.
    for (node, (x, y)) in [(0u32, (0u32, 0u32)), (1, (80, 0)), (2, (40, 60))] {
        cache
            .upload(&gpu.device, &gpu.queue, node, &quad(x, y, 40), step)
            .expect("upload");
    }
    let cam = Camera {
        position: [1.0, 0.8, 1.5],
        target: [1.0, 0.8, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 50.0,
        width: 96,
        height: 64,
    };
    r.set_frame(
        &gpu.queue,
        &FrameParams::new(&cam, [0.0; 3], [1.0, 0.8, 0.0, 2.0]),
    );
    let (color, depth) = r.offscreen_views().expect("targets");
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    let slots: Vec<_> = (0..3).filter_map(|n| cache.slot(n).cloned()).collect();
    // Ratio 0.5: the targets of the test patches (if any) are drawn halfway, the same
    // way on both paths.
    let slots = slots.iter().map(|s| (s, 0.5));
    r.encode_pass(&gpu.device, &mut enc, color, depth, &cache, slots, true);
    gpu.queue.submit([enc.finish()]);
    r.read_offscreen(&gpu.device, &gpu.queue).expect("readback")
}

#[test]
fn draws_without_base_vertex_equal_draws_with_it() {
    let gpu = Gpu::headless().expect("adapter (apt-get install mesa-vulkan-drivers)");
    let with = draw(&gpu, true);
    let without = draw(&gpu, false);
    let bg = with.rgba[..4].to_vec();
    let lit = with.rgba.chunks(4).filter(|p| *p != bg.as_slice()).count();
    // The three quads cover a good part of the frame.
    assert!(lit > 96 * 64 / 8, "only {lit} pixels drawn");
    assert!(with.rgba == without.rgba, "the two draw paths differ");
}
