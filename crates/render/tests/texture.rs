//! Per-patch textures (models with `ATTR_TEXTURE`) on real pixels (lavapipe; a missing
//! adapter is a failure, not a skip): patches built by hand, uploaded into a
//! [`GpuCache`] and drawn by the [`Renderer`] as the viewer and the browser client do.

use tessera_format::{PatchData, PatchTexture, TextureChart};
use tessera_render::{
    texture_gpu_bytes, ColorMode, FrameParams, Gpu, GpuCache, GpuStore, Image, Renderer, Shading,
    Slot,
};
use tessera_select::Camera;
use tessera_stream::ResidentStore;

/// Image size of the renders.
const SIZE: u32 = 128;
/// Grid units of the quads' side (local size 1 at `STEP`).
const S: u32 = 64;
const STEP: f64 = 1.0 / 64.0;

fn gpu() -> Gpu {
    Gpu::headless().expect("adapter (apt-get install mesa-vulkan-drivers)")
}

/// Looking at the unit quad (z = 0, facing +z) from +z, y up: it covers the middle
/// ~80% of the image.
fn camera() -> Camera {
    Camera {
        position: [0.5, 0.5, 1.35],
        target: [0.5, 0.5, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 50.0,
        width: SIZE,
        height: SIZE,
    }
}

fn params(shading: Shading) -> FrameParams {
    let cam = camera();
    let planes = tessera_render::clip_planes_along(
        glam::DVec3::from(cam.position),
        cam.basis().forward,
        [(glam::DVec3::new(0.5, 0.5, 0.0), 1.0)],
    );
    FrameParams::with_planes(&cam, [0.0; 3], planes, shading)
}

/// The pixel (column, row from the top) local point `p` projects to.
fn pixel_of(p: [f32; 3]) -> (u32, u32) {
    let vp = params(Shading::default()).view_proj;
    let c = vp * glam::Vec4::new(p[0], p[1], p[2], 1.0);
    let (x, y) = (c.x / c.w, c.y / c.w);
    (
        ((x + 1.0) * 0.5 * SIZE as f32) as u32,
        ((1.0 - y) * 0.5 * SIZE as f32) as u32,
    )
}

/// RGBA8 texels from a function of the texel (column, row from the top).
fn texels(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 4]) -> Vec<u8> {
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .flat_map(|(x, y)| f(x, y))
        .collect()
}

fn texture(w: u32, h: u32, rgba: Vec<u8>) -> Option<PatchTexture> {
    Some(PatchTexture {
        width: w,
        height: h,
        rgba,
        ..Default::default()
    })
}

/// The unit quad (two triangles), source uvs `uv_of(x, y)` (x, y in 0..1, y up), one
/// chart `chart`, the texture `tex`.
fn textured_quad(
    uv_of: impl Fn(f32, f32) -> [f32; 2],
    chart: TextureChart,
    tex: Option<PatchTexture>,
) -> PatchData {
    let corners = [[0, 0], [S, 0], [S, S], [0, S]];
    PatchData {
        positions: corners.iter().map(|c| [c[0], c[1], 0]).collect(),
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: corners
            .iter()
            .map(|c| uv_of(c[0] as f32 / S as f32, c[1] as f32 / S as f32))
            .collect(),
        indices: vec![0, 1, 2, 0, 2, 3],
        charts: vec![chart],
        chart_ids: vec![0; 4],
        texture: tex,
        ..Default::default()
    }
}

/// Draws `slots` (with their morph ratios) of `cache`.
fn draw(
    gpu: &Gpu,
    cache: &GpuCache,
    slots: &[(Slot, f32)],
    shading: Shading,
    has_colors: bool,
) -> Image {
    draw_with(gpu, cache, slots, shading, has_colors, gpu.base_vertex())
}

/// [`draw`] with or without `base_vertex` (WebGL2 has none).
fn draw_with(
    gpu: &Gpu,
    cache: &GpuCache,
    slots: &[(Slot, f32)],
    shading: Shading,
    has_colors: bool,
    base_vertex: bool,
) -> Image {
    let mut r = Renderer::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
    r.background = [1.0, 0.0, 1.0, 1.0];
    r.has_colors = has_colors;
    r.set_base_vertex(base_vertex);
    r.ensure_offscreen(&gpu.device, SIZE, SIZE);
    r.set_frame(&gpu.queue, &params(shading));
    let (color, depth) = r.offscreen_views().expect("targets");
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    let slots = slots.iter().map(|(s, ratio)| (s, *ratio));
    r.encode_pass(&gpu.device, &mut enc, color, depth, cache, slots, true);
    gpu.queue.submit([enc.finish()]);
    r.read_offscreen(&gpu.device, &gpu.queue).expect("readback")
}

fn px(img: &Image, (x, y): (u32, u32)) -> [u8; 3] {
    let i = 4 * (y * img.width + x) as usize;
    [img.rgba[i], img.rgba[i + 1], img.rgba[i + 2]]
}

fn max_diff(a: [u8; 3], b: [u8; 3]) -> i32 {
    (0..3)
        .map(|c| (i32::from(a[c]) - i32::from(b[c])).abs())
        .max()
        .unwrap()
}

const RED: [u8; 3] = [230, 30, 20];
const GREEN: [u8; 3] = [40, 200, 60];
const BLUE: [u8; 3] = [30, 50, 220];
const YELLOW: [u8; 3] = [240, 220, 40];

/// A 64x64 texture of four quadrants (top left red, top right green, bottom left blue,
/// bottom right yellow).
fn quadrants() -> Vec<u8> {
    texels(64, 64, |x, y| {
        let c = match (x < 32, y < 32) {
            (true, true) => RED,
            (false, true) => GREEN,
            (true, false) => BLUE,
            (false, false) => YELLOW,
        };
        [c[0], c[1], c[2], 255]
    })
}

/// A textured quad shows its texture's quadrants where they belong, through a chart
/// that is not the identity (source uvs 0..2 scaled by one half onto the texture; v
/// down, so the texture's top row is at the quad's top).
///
/// Unlit, so a pixel is the sampled texel itself. Tolerance: 1 level per channel. Each
/// sample lies inside a quadrant, at least 8 texels from its edges at the magnification
/// drawn (~100 pixels for 64 texels: mip 0), so the bilinear filter mixes texels of one
/// colour only and returns it up to float rounding, which the 8-bit target rounds to
/// the same level or the next.
#[test]
fn textured_quad_shows_its_quadrants() {
    let gpu = gpu();
    let mut cache = GpuCache::new(&gpu.device, 4 << 20);
    let chart = TextureChart {
        image: 0,
        scale: [0.5, 0.5],
        offset: [0.0, 0.0],
    };
    let quad = textured_quad(
        |x, y| [2.0 * x, 2.0 * (1.0 - y)],
        chart,
        texture(64, 64, quadrants()),
    );
    cache
        .upload(&gpu.device, &gpu.queue, 0, &quad, STEP)
        .expect("upload");
    let slot = cache.slot(0).cloned().expect("resident");
    assert!(
        slot.texture.is_some(),
        "a textured patch's slot has its texture"
    );
    let unlit = Shading {
        unlit: true,
        ..Default::default()
    };
    let img = draw(&gpu, &cache, &[(slot.clone(), 0.0)], unlit, false);
    if let Some(dir) = std::env::var_os("TESSERA_TEST_IMAGES") {
        img.save_png(&std::path::Path::new(&dir).join("texture_quadrants.png"))
            .unwrap();
    }
    for (x, y, want) in [
        (0.25, 0.75, RED),
        (0.75, 0.75, GREEN),
        (0.25, 0.25, BLUE),
        (0.75, 0.25, YELLOW),
    ] {
        // A 5x5 block around the quadrant's centre.
        let (cx, cy) = pixel_of([x, y, 0.0]);
        for dy in 0..5 {
            for dx in 0..5 {
                let p = (cx + dx - 2, cy + dy - 2);
                let got = px(&img, p);
                assert!(
                    max_diff(got, want) <= 1,
                    "quadrant at ({x}, {y}), pixel {p:?}: {got:?}, want {want:?}"
                );
            }
        }
    }
    // The whole quad is drawn: no background inside its corners.
    let (x0, y1) = pixel_of([0.05, 0.05, 0.0]);
    let (x1, y0) = pixel_of([0.95, 0.95, 0.0]);
    for y in y0..=y1 {
        for x in x0..=x1 {
            assert_ne!(px(&img, (x, y)), [255, 0, 255], "hole at ({x}, {y})");
        }
    }
    // Lit, the same quadrants shaded: darker than unlit, the same hue.
    let lit = draw(&gpu, &cache, &[(slot, 0.0)], Shading::default(), false);
    let (cx, cy) = pixel_of([0.25, 0.75, 0.0]);
    let p = px(&lit, (cx, cy));
    assert!(p[0] < RED[0] && p[0] > 3 * p[1] && p[0] > 3 * p[2], "{p:?}");
}

/// A textured patch and an untextured one with the same colours per vertex look the
/// same: lit, in every colour mode. Tolerance: 1 level per channel (both paths light the
/// same colour with the same function; the texel and the vertex colour are the same
/// 8-bit value read as unorm, and interpolation of a constant may differ by rounding).
/// An sRGB texture format would fail this (its texels would be linearised: 200 -> 147).
#[test]
fn textured_and_vertex_colours_look_the_same() {
    let gpu = gpu();
    let colour = [200u8, 120, 60, 255];
    // Node 0 in both caches: the same tag, so by-node and by-level colours agree too.
    let mut tex_cache = GpuCache::new(&gpu.device, 4 << 20);
    let solid = texture(8, 8, texels(8, 8, |_, _| colour));
    let chart = TextureChart {
        image: 0,
        scale: [1.0, 1.0],
        offset: [0.0, 0.0],
    };
    let quad = textured_quad(|x, y| [x, 1.0 - y], chart, solid);
    tex_cache
        .upload(&gpu.device, &gpu.queue, 0, &quad, STEP)
        .expect("upload");
    let mut plain_cache = GpuCache::new(&gpu.device, 4 << 20);
    let plain = PatchData {
        colors: vec![colour; 4],
        uvs: vec![],
        charts: vec![],
        chart_ids: vec![],
        texture: None,
        ..quad.clone()
    };
    plain_cache
        .upload(&gpu.device, &gpu.queue, 0, &plain, STEP)
        .expect("upload");
    let ts = tex_cache.slot(0).cloned().unwrap();
    let ps = plain_cache.slot(0).cloned().unwrap();
    assert!(ts.texture.is_some() && ps.texture.is_none());
    for mode in [ColorMode::Natural, ColorMode::ByNode, ColorMode::ByLevel] {
        for unlit in [false, true] {
            let shading = Shading {
                color_mode: mode,
                unlit,
                ..Default::default()
            };
            let a = draw(&gpu, &tex_cache, &[(ts.clone(), 0.0)], shading, false);
            let b = draw(&gpu, &plain_cache, &[(ps.clone(), 0.0)], shading, true);
            let worst = a
                .rgba
                .chunks_exact(4)
                .zip(b.rgba.chunks_exact(4))
                .map(|(p, q)| max_diff([p[0], p[1], p[2]], [q[0], q[1], q[2]]))
                .max()
                .unwrap();
            let drawn = b.rgba.chunks_exact(4).filter(|p| p[..3] != [255, 0, 255]);
            assert!(drawn.count() > (SIZE * SIZE / 2) as usize);
            assert!(
                worst <= 1,
                "{mode:?}, unlit {unlit}: textured and vertex colours differ by {worst}"
            );
        }
    }
}

/// Geomorphing carries the texture coordinate: a fan whose centre vertex moves onto a
/// corner shows, at ratio 0.5, the texel halfway between the centre's uv and the
/// corner's (from the corner's survivor on the same image: a decoy vertex at the
/// corner on another image is passed over).
///
/// The texture is a ramp (red = u, green = v), so the texel at a uv is known: at the
/// morphed centre, uv (0.25, 0.75) gives about (64, 191); without the uv's morph it
/// would stay (0.5, 0.5): about (128, 128). Tolerance: 6 levels, for the pixel centre
/// lying up to 0.7 pixel from the vertex, over which the uv moves ~0.01 (2.5 levels).
#[test]
fn morph_interpolates_the_texture_coordinate() {
    let gpu = gpu();
    let ramp = texels(64, 64, |x, y| {
        let q = |t: u32| ((t as f32 + 0.5) / 64.0 * 255.0).round() as u8;
        [q(x), q(y), 0, 255]
    });
    let h = S / 2;
    // A B C D corners (y up), M the centre, E a decoy at A's position on another
    // image (first in the patch, so the first vertex at A's position is E).
    let pos = [
        [0, 0, 0],
        [0, 0, 0],
        [S, 0, 0],
        [S, S, 0],
        [0, S, 0],
        [h, h, 0],
    ];
    let (e, a, b, c, d, m) = (0u32, 1, 2, 3, 4, 5);
    let uv_of = |p: [u32; 3]| [p[0] as f32 / S as f32, 1.0 - p[1] as f32 / S as f32];
    let mut uvs: Vec<[f32; 2]> = pos.iter().map(|&p| uv_of(p)).collect();
    uvs[e as usize] = [1.0, 0.0];
    let mut targets = pos.to_vec();
    targets[m as usize] = pos[a as usize];
    let fan = PatchData {
        positions: pos.to_vec(),
        normals: vec![[0.0, 0.0, 1.0]; 6],
        uvs,
        morph_targets: targets,
        indices: vec![a, b, m, b, c, m, c, d, m, d, a, m],
        charts: vec![
            TextureChart {
                image: 0,
                scale: [1.0, 1.0],
                offset: [0.0, 0.0],
            },
            TextureChart {
                image: 9,
                scale: [1.0, 1.0],
                offset: [0.0, 0.0],
            },
        ],
        chart_ids: vec![1, 0, 0, 0, 0, 0],
        texture: texture(64, 64, ramp),
        ..Default::default()
    };
    let mut cache = GpuCache::new(&gpu.device, 4 << 20);
    cache
        .upload(&gpu.device, &gpu.queue, 0, &fan, STEP)
        .expect("upload");
    let slot = cache.slot(0).cloned().unwrap();
    let unlit = Shading {
        unlit: true,
        ..Default::default()
    };
    let expect = |uv: [f32; 2]| [uv[0] * 255.0, uv[1] * 255.0];
    for (ratio, at, uv) in [
        (0.0f32, [0.5f32, 0.5], [0.5f32, 0.5]),
        (0.5, [0.25, 0.25], [0.25, 0.75]),
    ] {
        let img = draw(&gpu, &cache, &[(slot.clone(), ratio)], unlit, false);
        let got = px(&img, pixel_of([at[0], at[1], 0.0]));
        let want = expect(uv);
        let off = (f32::from(got[0]) - want[0])
            .abs()
            .max((f32::from(got[1]) - want[1]).abs());
        assert!(
            off <= 6.0 && got[2] == 0,
            "ratio {ratio}: {got:?} at the centre, want about {want:?}"
        );
    }
}

/// The cache counts a texture's bytes (mips included) in the slot, the resident bytes
/// and the store's estimates, frees them with the patch, and keeps textures within its
/// budget: uploads answer `Full` when the textures would exceed it, and a patch without
/// its texture is drawn grey at no cost.
#[test]
fn cache_counts_and_evicts_texture_bytes() {
    let gpu = gpu();
    let chart = TextureChart {
        image: 0,
        scale: [1.0, 1.0],
        offset: [0.0, 0.0],
    };
    let quad = textured_quad(|x, y| [x, 1.0 - y], chart, texture(64, 64, quadrants()));
    let tex_bytes = 4 * (64 * 64 + 32 * 32 + 16 * 16 + 8 * 8 + 4 * 4 + 2 * 2 + 1);
    assert_eq!(texture_gpu_bytes(64, 64, 4096), tex_bytes);
    let geometry = 4 * 40 + 6 * 4;

    let mut cache = GpuCache::new(&gpu.device, 4 << 20);
    {
        let store = GpuStore {
            cache: &mut cache,
            device: &gpu.device,
            queue: &gpu.queue,
            quant_step: STEP,
            model: 0,
        };
        assert_eq!(store.bytes_for(&quad), geometry + tex_bytes);
        assert_eq!(store.estimate_texture_bytes([64, 64]), tex_bytes);
        assert_eq!(store.estimate_texture_bytes([0, 0]), 0);
    }
    for node in 0..5 {
        let b = cache
            .upload(&gpu.device, &gpu.queue, node, &quad, STEP)
            .expect("upload");
        assert_eq!(b, geometry + tex_bytes);
        assert_eq!(cache.slot(node).unwrap().bytes(), b);
    }
    let st = cache.stats();
    assert_eq!(st.resident_bytes, 5 * (geometry + tex_bytes));
    assert_eq!(st.texture_bytes, 5 * tex_bytes);
    assert_eq!(cache.model_stats(0).texture_bytes, 5 * tex_bytes);
    // A textured patch that came without its texture: the grey stand-in, 0 bytes.
    let bare = PatchData {
        texture: None,
        ..quad.clone()
    };
    let b = cache
        .upload(&gpu.device, &gpu.queue, 9, &bare, STEP)
        .expect("upload");
    assert_eq!(b, geometry);
    let grey = cache.slot(9).cloned().unwrap();
    assert_eq!(grey.texture.as_ref().map(|t| t.bytes), Some(0));
    let unlit = Shading {
        unlit: true,
        ..Default::default()
    };
    let img = draw(&gpu, &cache, &[(grey, 0.0)], unlit, false);
    let g = px(&img, (SIZE / 2, SIZE / 2));
    assert!(max_diff(g, [128, 128, 128]) <= 1, "{g:?}");
    for node in (0..5).chain([9]) {
        cache.evict(node);
    }
    let st = cache.stats();
    assert_eq!(
        (st.resident_bytes, st.texture_bytes, st.resident_patches),
        (0, 0, 0)
    );
    assert_eq!(cache.model_stats(0).resident_bytes, 0);
    wait(&gpu);

    // A 1 MiB budget: textures of 341 KiB (256x256 with mips) fit twice beside the
    // buffers, never beyond the budget; evicting one makes room for the next.
    let big = textured_quad(
        |x, y| [x, 1.0 - y],
        chart,
        texture(256, 256, texels(256, 256, |x, _| [x as u8, 0, 0, 255])),
    );
    let mut small = GpuCache::new(&gpu.device, 1 << 20);
    let budget = small.max_bytes();
    assert!(budget <= 1 << 20);
    let mut held = Vec::new();
    for node in 0..8 {
        match small.upload(&gpu.device, &gpu.queue, node, &big, STEP) {
            Ok(_) => held.push(node),
            Err(tessera_stream::StoreError::Full) => break,
            Err(e) => panic!("{e:?}"),
        }
        assert!(small.stats().resident_bytes <= budget);
    }
    assert!(held.len() >= 2, "only {} textures fit 1 MiB", held.len());
    assert!(held.len() < 8, "8 textures of 341 KiB in 1 MiB");
    assert!(!small.has_room_for(4, 6, texture_gpu_bytes(256, 256, 4096)));
    small.evict(held[0]);
    assert!(small.has_room_for(4, 6, texture_gpu_bytes(256, 256, 4096)));
    small
        .upload(&gpu.device, &gpu.queue, 100, &big, STEP)
        .expect("room after an eviction");
    let usable = small.usable_bytes();
    assert!(
        usable <= budget && usable >= small.stats().resident_bytes,
        "usable {usable}, budget {budget}, {:?}",
        small.stats()
    );
}

/// Textured patches past vertex 0 of the shared buffer, drawn the WebGL2 way (the
/// vertex buffer bound at each patch's first vertex, no base vertex), beside an
/// untextured one (the pipeline switches per patch): the same pixels as the native
/// path.
#[test]
fn textured_draws_without_base_vertex_equal_draws_with_it() {
    let gpu = gpu();
    let mut cache = GpuCache::new(&gpu.device, 4 << 20);
    let chart = TextureChart {
        image: 0,
        scale: [1.0, 1.0],
        offset: [0.0, 0.0],
    };
    let shifted = |p: &PatchData, dx: u32, dy: u32| PatchData {
        positions: p
            .positions
            .iter()
            .map(|q| [q[0] / 2 + dx, q[1] / 2 + dy, q[2]])
            .collect(),
        ..p.clone()
    };
    let quad = textured_quad(|x, y| [x, 1.0 - y], chart, texture(64, 64, quadrants()));
    let plain = PatchData {
        colors: vec![[90, 160, 200, 255]; 4],
        uvs: vec![],
        charts: vec![],
        chart_ids: vec![],
        texture: None,
        ..quad.clone()
    };
    for (node, p) in [
        shifted(&plain, 0, 0),
        shifted(&quad, S / 2, 0),
        shifted(&quad, 0, S / 2),
        shifted(&plain, S / 2, S / 2),
    ]
    .iter()
    .enumerate()
    {
        cache
            .upload(&gpu.device, &gpu.queue, node as u32, p, STEP)
            .expect("upload");
    }
    let slots: Vec<(Slot, f32)> = (0..4)
        .map(|n| (cache.slot(n).cloned().unwrap(), 0.0))
        .collect();
    assert!(slots[1].0.vertices.start > 0 && slots[1].0.texture.is_some());
    let with = draw_with(&gpu, &cache, &slots, Shading::default(), true, true);
    let without = draw_with(&gpu, &cache, &slots, Shading::default(), true, false);
    let drawn = with
        .rgba
        .chunks_exact(4)
        .filter(|p| p[..3] != [255, 0, 255]);
    assert!(drawn.count() > (SIZE * SIZE / 2) as usize);
    assert!(with.rgba == without.rgba, "the two draw paths differ");
}

fn wait(gpu: &Gpu) {
    gpu.wait_idle().expect("idle");
}

fn scissors() -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ycb-scissors/textured_simple_reoriented.obj");
    p.exists().then_some(p)
}

/// The real textured scan (YCB scissors: OBJ + MTL + PNG) through the builder and the
/// viewer: complete frames show the texture (not the clay colour, not the grey
/// stand-in), and progressive frames over a small GPU budget stay within it, textures
/// counted, while the orbit turns.
#[test]
fn textured_scan_draws_its_texture_within_budget() {
    use std::sync::Arc;
    use tessera_render::{Mode, Viewer, ViewerOptions};
    use tessera_select::Orbit;
    let Some(obj) = scissors() else {
        eprintln!("skipped: ../shared/data/ycb-scissors is not there");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.tsr");
    let opts = tessera_build::BuildOptions {
        leaf_triangles: 1000,
        node_triangles: 500,
        ..Default::default()
    };
    tessera_build::build(&obj, &out, &opts, &tessera_build::NoProgress).expect("build");
    let model = Arc::new(tessera_format::Model::open(&out).expect("open"));
    assert_ne!(
        model.header().attributes & tessera_format::ATTR_TEXTURE,
        0,
        "the scan builds textured"
    );
    let b = model.header().bounding_sphere;
    let cam = |az: f64, w: u32| {
        Camera::orbit(&Orbit {
            center: [b[0], b[1], b[2]],
            radius: b[3] * 2.0,
            azimuth_deg: az,
            elevation_deg: 30.0,
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 45.0,
            width: w,
            height: w,
        })
        .expect("camera")
    };
    let mut v = Viewer::new(
        model.clone(),
        ViewerOptions {
            mode: Mode::Complete,
            background: [1.0, 0.0, 1.0, 1.0],
            ..Default::default()
        },
    )
    .expect("viewer");
    v.render(&cam(30.0, 240)).expect("render");
    let img = v.read_image().expect("read");
    if let Some(dir) = std::env::var_os("TESSERA_TEST_IMAGES") {
        img.save_png(&std::path::Path::new(&dir).join("texture_scissors.png"))
            .unwrap();
    }
    // Lit pixels off the clay colour's ratios and off grey: the texture's colours.
    let clay = [0.78f32, 0.74, 0.68];
    let (mut lit, mut coloured) = (0, 0);
    for p in img.rgba.chunks_exact(4) {
        if p[..3] == [255, 0, 255] || p[0].max(p[1]).max(p[2]) < 40 {
            continue;
        }
        lit += 1;
        let k = f32::from(p[0]) / clay[0];
        let off_clay = (f32::from(p[1]) - k * clay[1])
            .abs()
            .max((f32::from(p[2]) - k * clay[2]).abs());
        let spread = i32::from(p[0].max(p[1]).max(p[2])) - i32::from(p[0].min(p[1]).min(p[2]));
        if off_clay > 12.0 && spread > 12 {
            coloured += 1;
        }
    }
    assert!(lit > 1500, "the scan is barely visible ({lit} lit pixels)");
    assert!(
        coloured * 4 > lit,
        "only {coloured} of {lit} lit pixels show colour: texture not drawn?"
    );

    // All nodes' bytes as the GPU cache counts them, textures with their mips.
    let all: u64 = model
        .nodes()
        .iter()
        .map(|n| {
            u64::from(n.vertex_count) * 40
                + u64::from(n.triangle_count) * 12
                + texture_gpu_bytes(
                    u32::from(n.texture_size[0]),
                    u32::from(n.texture_size[1]),
                    4096,
                )
        })
        .sum();
    let textures: u64 = model
        .nodes()
        .iter()
        .map(|n| {
            texture_gpu_bytes(
                u32::from(n.texture_size[0]),
                u32::from(n.texture_size[1]),
                4096,
            )
        })
        .sum();
    eprintln!(
        "{} nodes, {all} GPU bytes, {textures} of them textures",
        model.nodes().len()
    );
    let budget = all / 4;
    let mut v = Viewer::new(
        model,
        ViewerOptions {
            mode: Mode::Progressive,
            gpu_budget_bytes: budget,
            tolerance_px: 0.5,
            ..Default::default()
        },
    )
    .expect("viewer");
    // Progressive frames never wait for reads (PNG decoding at the loader): give them
    // time, turning a little each frame.
    let (mut most, mut evictions) = (0, 0);
    for i in 0..150 {
        let s = v.render(&cam(3.0 * i as f64, 320)).expect("frame");
        assert!(s.gpu_resident_bytes <= budget, "frame {i}: {s:?}");
        most = most.max(s.gpu_resident_bytes);
        evictions = s.gpu_evictions;
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    eprintln!("most {most} of {budget} bytes, {evictions} evictions");
    assert!(
        most > budget / 2,
        "the budget was hardly used ({most} bytes)"
    );
}

/// No texture pop at a switch: a patch drawn at morph ratio 1 (its parent's shape) with
/// its `texel_lod` shows its parent's texel detail, and at ratio 0 exactly its own.
/// The child's texture is a fine checker (2-texel squares, 256 x 256, minified here);
/// its parent's is that texture's mip 2 (64 x 64: the same box filter, so uniform grey),
/// as the builder's coarser crop of the same source. Without the texel blend the
/// child at ratio 1 still shows the checker; with it, the parent's grey.
#[test]
fn a_patch_morphing_in_shows_its_parents_texel_detail() {
    let gpu = gpu();
    let chart = TextureChart {
        image: 0,
        scale: [1.0, 1.0],
        offset: [0.0, 0.0],
    };
    let fine = texels(256, 256, |x, y| {
        let c = if (x / 2 + y / 2) % 2 == 0 { 230 } else { 25 };
        [c, c, c, 255]
    });
    let mips = tessera_render::mip_chain(&fine, 256, 256);
    let child = textured_quad(|x, y| [x, 1.0 - y], chart, texture(256, 256, fine));
    let parent = textured_quad(|x, y| [x, 1.0 - y], chart, texture(64, 64, mips[1].clone()));
    // The texel size of a patch: its model side (1) over its texels.
    assert!((tessera_render::patch_texel_size(&child, 256, 256, STEP) - 1.0 / 256.0).abs() < 1e-6);
    assert!((tessera_render::patch_texel_size(&parent, 64, 64, STEP) - 1.0 / 64.0).abs() < 1e-6);
    let mut cache = GpuCache::new(&gpu.device, 8 << 20);
    cache
        .upload(&gpu.device, &gpu.queue, 0, &parent, STEP)
        .expect("upload");
    cache
        .upload(&gpu.device, &gpu.queue, 1, &child, STEP)
        .expect("upload");
    let p = cache.slot(0).cloned().unwrap();
    let c = cache.slot(1).cloned().unwrap();
    // Without the node table the cache knows no parent: no texel detail to morph from.
    assert_eq!(c.texel_lod, 0.0);
    assert!(
        (c.texel_size - 1.0 / 256.0).abs() < 1e-6,
        "{}",
        c.texel_size
    );
    let blended = Slot {
        texel_lod: (p.texel_size / c.texel_size).log2(),
        ..c.clone()
    };
    assert!((blended.texel_lod - 2.0).abs() < 1e-4);
    let unlit = Shading {
        unlit: true,
        ..Default::default()
    };
    let image = |s: &Slot, r: f32| draw(&gpu, &cache, &[(s.clone(), r)], unlit, false);
    let parent_img = image(&p, 0.0);
    let psnr = |a: &Image, b: &Image| tessera_render::psnr(a, b).unwrap_or(f64::INFINITY);
    let (with, without) = (image(&blended, 1.0), image(&c, 1.0));
    let (p_with, p_without) = (psnr(&with, &parent_img), psnr(&without, &parent_img));
    eprintln!("child at ratio 1 against its parent: {p_with:.2} dB with the texel blend, {p_without:.2} dB without");
    assert!(
        p_with >= 40.0,
        "with the blend the child differs from its parent: {p_with:.2} dB"
    );
    assert!(
        p_without < p_with - 10.0,
        "the checker should show without the blend: {p_without:.2} dB"
    );
    // At its own shape the blend changes nothing.
    assert_eq!(image(&blended, 0.0).rgba, image(&c, 0.0).rgba);
}
