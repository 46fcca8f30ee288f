//! The texture stage on the real textured scan (YCB scissors, OBJ + MTL + PNG): every
//! patch gets a texture within the size limit whose charts hold its vertices, and at the
//! leaves a vertex's texel is the source image's texel at its UV, exactly with PNG
//! (lossless, and leaves are cut at the source resolution) and within BC7's error with
//! BC7.

use std::path::{Path, PathBuf};

use tessera_build::texture::TextureOptions;
use tessera_build::{build, texture::PATCH_TEXELS, BuildOptions, NoProgress};
use tessera_format::texels::mip_level_count;
use tessera_format::{Model, TextureCodec, ATTR_TEXTURE, MAX_TEXTURE_DIM, NODE_FLAG_LEAF};

fn scissors() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ycb-scissors/textured_simple_reoriented.obj");
    p.exists().then_some(p)
}

/// What [`build_and_check`] saw at the leaves: vertices checked, and for each the
/// largest channel difference between its patch texel and the source's.
struct LeafTexels {
    checked: u64,
    diffs: Vec<u8>,
}

#[test]
fn leaf_textures_hold_the_source_texels_and_every_patch_fits() {
    let Some(obj) = scissors() else {
        eprintln!("skipped: ../shared/data/ycb-scissors is not there");
        return;
    };
    let l = build_and_check(&obj, TextureCodec::Png);
    let exact = l.diffs.iter().filter(|&&d| d == 0).count() as u64;
    assert_eq!(exact, l.checked, "leaf texels equal the source's");
}

/// BC7 (the ISPC "ultra fast" profile) keeps a leaf's texels within its block error:
/// on the scissors the texel under a vertex is within 16 levels of the source in every
/// channel for 99% of vertices, at 42 dB or better as a whole (measured: every one
/// within 5 levels, 48.5 dB; the thresholds leave room for a sharper photo, whose
/// edges inside a block cost more).
#[test]
fn bc7_leaf_textures_hold_the_source_texels_within_the_codec_error() {
    let Some(obj) = scissors() else {
        eprintln!("skipped: ../shared/data/ycb-scissors is not there");
        return;
    };
    let l = build_and_check(&obj, TextureCodec::Bc7);
    let within = l.diffs.iter().filter(|&&d| d <= 16).count() as f64 / l.checked as f64;
    let mse = l.diffs.iter().map(|&d| f64::from(d).powi(2)).sum::<f64>() / l.checked as f64;
    let psnr = 10.0 * (255.0f64.powi(2) / mse.max(1e-9)).log10();
    let worst = l.diffs.iter().max().copied().unwrap_or(0);
    eprintln!(
        "BC7 leaves: {:.2}% of {} vertex texels within 16 levels, {psnr:.1} dB (largest \
         channel difference), worst {worst}",
        100.0 * within,
        l.checked
    );
    assert!(within >= 0.99, "{within}");
    assert!(psnr >= 42.0, "{psnr} dB");
}

/// Builds the scissors with `codec` and checks every patch texture; returns the leaves'
/// texels against the source.
fn build_and_check(obj: &Path, codec: TextureCodec) -> LeafTexels {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.tsr");
    // Small leaves, so the scan has several levels and coarse patches downsample.
    let opts = BuildOptions {
        leaf_triangles: 1000,
        node_triangles: 500,
        texture: TextureOptions {
            codec,
            ..Default::default()
        },
        ..Default::default()
    };
    let r = build(obj, &out, &opts, &NoProgress).unwrap();
    let t = r
        .textures
        .clone()
        .expect("a textured build reports its textures");
    assert_eq!(t.source_images, 1, "{t:?}");
    assert!(t.unreadable_images.is_empty(), "{t:?}");
    let model = Model::open(&out).unwrap();
    assert_ne!(model.header().attributes & ATTR_TEXTURE, 0);
    let src = image::open(obj.with_file_name("texture_map.png"))
        .unwrap()
        .into_rgba8();
    let (sw, sh) = (src.width() as f64, src.height() as f64);

    let (mut checked, mut diffs) = (0u64, Vec::new());
    let (mut coarse, mut over, mut coarse_max) = (0u64, 0u64, 0u64);
    for (i, n) in model.nodes().iter().enumerate() {
        let p = model.decode_patch(i).unwrap();
        let mut tex = p.texture.clone().expect("every patch has a texture");
        assert_eq!(tex.codec, Some(codec));
        if codec == TextureCodec::Bc7 {
            // Whole blocks, every level stored.
            assert!(
                tex.width % 4 == 0 && tex.height % 4 == 0,
                "{}x{}",
                tex.width,
                tex.height
            );
            assert_eq!(
                tex.blocks.len() as u32,
                mip_level_count(tex.width, tex.height)
            );
            tex.decode_rgba().unwrap();
        }
        assert_eq!([tex.width as u16, tex.height as u16], n.texture_size);
        assert!(tex.width <= MAX_TEXTURE_DIM && tex.height <= MAX_TEXTURE_DIM);
        assert_eq!(tex.rgba.len(), (4 * tex.width * tex.height) as usize);
        // Every vertex (and its morph target) maps inside the texture.
        for (v, uv) in p.uvs.iter().enumerate() {
            let c = p.charts[p.chart_ids[v] as usize];
            let m = c.map(*uv);
            assert!(
                (0.0..=1.0).contains(&m[0]) && (0.0..=1.0).contains(&m[1]),
                "node {i} vertex {v}: uv {uv:?} maps to {m:?}"
            );
        }
        if n.flags & NODE_FLAG_LEAF == 0 {
            // Coarse patches fit the texel budget, as planned when they are made: the
            // morph targets' UVs their parent gives them widen their rectangles a
            // little, or across the atlas where a target lies on another chart.
            let texels = tex.width as u64 * tex.height as u64;
            coarse += 1;
            over += (texels * 4 > PATCH_TEXELS * 5) as u64;
            coarse_max = coarse_max.max(texels);
            continue;
        }
        for (v, uv) in p.uvs.iter().enumerate() {
            let c = p.charts[p.chart_ids[v] as usize];
            assert_eq!(c.image, 0, "leaf vertices sample the scan's one image");
            // OBJ: v = 0 is the bottom row.
            let (x, y) = (uv[0] as f64 * sw, (1.0 - uv[1] as f64) * sh);
            let m = c.map(*uv);
            let (ax, ay) = (
                m[0] as f64 * tex.width as f64,
                m[1] as f64 * tex.height as f64,
            );
            // Skip points within 1e-2 texel of a texel edge (f32 rounding of the map).
            let near_edge = |z: f64| (z - z.round()).abs() < 1e-2;
            if near_edge(x) || near_edge(y) || near_edge(ax) || near_edge(ay) {
                continue;
            }
            let s = src.get_pixel(
                (x.floor() as i64).rem_euclid(src.width() as i64) as u32,
                (y.floor() as i64).rem_euclid(src.height() as i64) as u32,
            );
            let o = 4 * (ay.floor() as usize * tex.width as usize + ax.floor() as usize);
            checked += 1;
            let d = (0..4)
                .map(|k| tex.rgba[o + k].abs_diff(s.0[k]))
                .max()
                .unwrap_or(0);
            if d > 0 && diffs.iter().filter(|&&d| d > 0).count() < 5 && codec == TextureCodec::Png {
                eprintln!("vertex {v}: {:?} vs source {:?}", &tex.rgba[o..o + 4], s.0);
            }
            diffs.push(d);
        }
    }
    assert!(checked > 1000, "checked {checked} leaf vertices");
    eprintln!(
        "{t:?}; {checked} leaf vertices checked; {over} of {coarse} coarse textures over \
         1.25x the budget, the largest {coarse_max} texels"
    );
    assert!(
        over * 10 <= coarse,
        "{over} of {coarse} coarse textures over the budget"
    );
    // A texture tree: more texels in all than in the leaves, but not wildly more.
    assert!(t.texels > t.leaf_texels);
    LeafTexels { checked, diffs }
}
