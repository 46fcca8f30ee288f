//! Issue 11, "texture error is not part of the LOD error": on a smooth textured terrain
//! (geometric errors of about a texel) the coarse patches' textures must not keep
//! near-full-resolution crops. Each coarse patch's texture fits a texel budget, and its
//! stored (saturated) error is raised to the texel size its texture has in model space,
//! so the runtime refines it before its texels show: the tree of patch textures stays
//! a small multiple of the leaves' texels, every coarse patch's texel is within its
//! error, and the model still verifies (saturated errors, diamond mates equal).

use tessera_build::{build, verify::verify_model, BuildOptions, NoProgress};
use tessera_format::{Grid, Model, NODE_FLAG_LEAF};
use tessera_gen::{write_textured_terrain, ImageFormat, TexturedOptions};

/// The builder's `TEXEL_PER_ERROR` (texture.rs): a coarse patch's texel, in units of
/// its model-space error.
const TEXEL_PER_ERROR: f64 = 1.0;
/// Side of the generated tile images.
const SOURCE: u32 = 1024;

#[test]
fn coarse_textures_fit_their_budget_and_their_texels_are_within_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("terrain.obj");
    // 2 tiles of 1024^2 over ~40k triangles (~52 texels a triangle): a smooth terrain
    // whose geometric errors stay about a texel for several levels.
    write_textured_terrain(
        &obj,
        &TexturedOptions {
            triangles: 40_000,
            columns: 2,
            rows: 1,
            image_size: SOURCE,
            image_format: ImageFormat::Png,
            seed: 3,
        },
        &NoProgress,
    )
    .unwrap();
    let out = dir.path().join("t.tsr");
    let opts = BuildOptions {
        leaf_triangles: 1000,
        node_triangles: 500,
        ..Default::default()
    };
    let r = build(&obj, &out, &opts, &NoProgress).unwrap();
    let t = r.textures.clone().expect("a textured build");
    assert_eq!(t.source_images, 2, "{t:?}");
    assert_eq!(t.downsampled_to_fit, 0, "{t:?}");
    let model = Model::open(&out).unwrap();
    let v = verify_model(&model);
    assert!(v.is_valid(), "{:?}", v.problems);
    let step = Grid::of_header(model.header()).step();
    assert!(
        model.header().level_count >= 4,
        "{} levels",
        model.header().level_count
    );

    let (mut coarse, mut worst) = (0u64, 0.0f64);
    for (i, n) in model.nodes().iter().enumerate() {
        if n.flags & NODE_FLAG_LEAF != 0 || n.triangle_count == 0 {
            continue;
        }
        let p = model.decode_patch(i).unwrap();
        let tex = p.texture.as_ref().expect("every patch has a texture");
        let (tw, th) = (tex.width as f64, tex.height as f64);
        // Per chart of the stored patch: model area and area in patch-texture texels of
        // the triangles whose corners all sample it.
        let mut area = vec![(0.0f64, 0.0f64); p.charts.len()];
        // Charts cut from the source texels themselves (level 0): none finer exists, so
        // their texel may exceed a small error (refining would not sharpen them).
        let source = |c: usize| (p.charts[c].scale[0] as f64 * tw).abs() > SOURCE as f64 - 0.5;
        for f in p.indices.chunks_exact(3) {
            let c = p.chart_ids[f[0] as usize];
            if p.chart_ids[f[1] as usize] != c
                || p.chart_ids[f[2] as usize] != c
                || p.charts[c as usize].image == u32::MAX
            {
                continue;
            }
            let q = [0, 1, 2].map(|k| p.positions[f[k] as usize].map(|x| x as f64 * step));
            let e1: [f64; 3] = std::array::from_fn(|a| q[1][a] - q[0][a]);
            let e2: [f64; 3] = std::array::from_fn(|a| q[2][a] - q[0][a]);
            let cr = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            let m = [0, 1, 2].map(|k| {
                let uv = p.charts[c as usize].map(p.uvs[f[k] as usize]);
                [uv[0] as f64 * tw, uv[1] as f64 * th]
            });
            let texels = 0.5
                * ((m[1][0] - m[0][0]) * (m[2][1] - m[0][1])
                    - (m[2][0] - m[0][0]) * (m[1][1] - m[0][1]))
                    .abs();
            let a = &mut area[c as usize];
            a.0 += 0.5 * (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
            a.1 += texels;
        }
        for (c, (model_area, texel_area)) in area.into_iter().enumerate() {
            if model_area <= 0.0 || texel_area <= 0.0 || source(c) {
                continue;
            }
            // Model-space size of one texel of the patch texture.
            let texel = (model_area / texel_area).sqrt();
            let allowed = n.error as f64 * TEXEL_PER_ERROR;
            assert!(
                texel <= allowed * (1.0 + 1e-3),
                "node {i} (level {}): texel {texel:e} over its error {:e}",
                n.level,
                n.error
            );
            worst = worst.max(texel / allowed);
            coarse += 1;
        }
    }
    assert!(coarse > 20, "{coarse} downsampled coarse charts checked");
    // The tree of textures is a pyramid over the leaves, not a stack of near-full
    // crops: each level at most half the one below (`TEXEL_REDUCTION`), so at most
    // about twice the leaves in all; 1.63x here (2.76x before issue 11).
    let ratio = t.texels as f64 / t.leaf_texels as f64;
    eprintln!(
        "{t:?}: tree {ratio:.3}x the leaves' texels, {:.3}x the source's; \
         {coarse} coarse charts, largest texel {worst:.3} of the error",
        t.texels as f64 / t.source_texels as f64
    );
    assert!(ratio < 1.75, "texture tree {ratio:.3}x the leaves' texels");
}
