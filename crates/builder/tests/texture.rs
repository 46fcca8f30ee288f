//! The texture stage on the real textured scan (YCB scissors, OBJ + MTL + PNG): every
//! patch gets a texture within the size limit whose charts hold its vertices, and at the
//! leaves a vertex's texel is the source image's texel at its UV, exactly (PNG is
//! lossless and leaves are cut at the source resolution).

use std::path::{Path, PathBuf};

use tessera_build::{build, texture::PATCH_TEXELS, BuildOptions, NoProgress};
use tessera_format::{Model, ATTR_TEXTURE, MAX_TEXTURE_DIM, NODE_FLAG_LEAF};

fn scissors() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/ycb-scissors/textured_simple_reoriented.obj");
    p.exists().then_some(p)
}

#[test]
fn leaf_textures_hold_the_source_texels_and_every_patch_fits() {
    let Some(obj) = scissors() else {
        eprintln!("skipped: ../shared/data/ycb-scissors is not there");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.tsr");
    // Small leaves, so the scan has several levels and coarse patches downsample.
    let opts = BuildOptions {
        leaf_triangles: 1000,
        node_triangles: 500,
        ..Default::default()
    };
    let r = build(&obj, &out, &opts, &NoProgress).unwrap();
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

    let (mut checked, mut exact) = (0u64, 0u64);
    let (mut coarse, mut over, mut coarse_max) = (0u64, 0u64, 0u64);
    for (i, n) in model.nodes().iter().enumerate() {
        let p = model.decode_patch(i).unwrap();
        let tex = p.texture.as_ref().expect("every patch has a texture");
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
            if tex.rgba[o..o + 4] == s.0 {
                exact += 1;
            } else if checked - exact < 5 {
                eprintln!("vertex {v}: {:?} vs source {:?}", &tex.rgba[o..o + 4], s.0);
            }
        }
    }
    assert!(checked > 1000, "checked {checked} leaf vertices");
    assert_eq!(exact, checked, "leaf texels equal the source's");
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
}
