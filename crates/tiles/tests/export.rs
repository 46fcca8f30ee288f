//! `export_tiles` beyond the mapping: a textured model's tiles carry their patch
//! textures as glTF images, and an export stopped half way (Ctrl-C through
//! `Progress::cancelled`) leaves nothing behind.

use std::sync::atomic::{AtomicU64, Ordering};

use tessera_mesh::Progress;
use tessera_testkit::{build_model, shared_data, sphere};
use tessera_tiles::{export_tiles, TilesError, TilesOptions};

#[test]
fn textured_tiles_carry_their_patch_textures() {
    // Why: each patch has its own texture; a tile's primitives must each sample theirs
    // (a PNG in the glb, the BC7 texture decoded) through TEXCOORD_0 inside [0, 1].
    let scissors = shared_data("ycb-scissors/textured_simple_reoriented.obj");
    let model = build_model(
        Some(&scissors),
        &sphere(0),
        &tessera_build::BuildOptions::default(),
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t");
    let s = export_tiles(
        &model.path,
        &out,
        &TilesOptions::default(),
        &tessera_mesh::NoProgress,
    )
    .unwrap();
    assert!(s.textures > 0);
    let mut images = 0;
    for e in std::fs::read_dir(out.join("tiles")).unwrap() {
        let p = e.unwrap().path();
        let g = gltf::Gltf::from_slice(&std::fs::read(&p).unwrap()).unwrap();
        let blob = g.blob.as_deref().unwrap();
        for prim in g.meshes().flat_map(|m| m.primitives()) {
            let info = prim
                .material()
                .pbr_metallic_roughness()
                .base_color_texture()
                .unwrap_or_else(|| panic!("{}: a primitive without its texture", p.display()));
            match info.texture().source().source() {
                gltf::image::Source::View { view, mime_type } => {
                    assert_eq!(mime_type, "image/png");
                    assert!(blob[view.offset()..].starts_with(b"\x89PNG"));
                    images += 1;
                }
                _ => panic!("image not in the glb"),
            }
            let uv = prim.get(&gltf::Semantic::TexCoords(0)).unwrap();
            let v = uv.view().unwrap();
            for c in blob[v.offset()..v.offset() + v.length()].chunks_exact(4) {
                let x = f32::from_le_bytes(c.try_into().unwrap());
                assert!((-1e-3..=1.001).contains(&x), "{}: uv {x}", p.display());
            }
        }
    }
    assert_eq!(images, s.textures);
}

/// Cancels once `after` tiles are done.
struct StopAfter {
    after: u64,
    done: AtomicU64,
}

impl Progress for StopAfter {
    fn stage(&self, _: &str, _: u64) {}
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
    fn finish_stage(&self) {}
    fn cancelled(&self) -> bool {
        self.done.load(Ordering::Relaxed) >= self.after
    }
}

#[test]
fn a_cancelled_export_leaves_nothing() {
    let model = build_model(None, &sphere(20_000), &tessera_testkit::small_options());
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t");
    let stop = StopAfter {
        after: 5,
        done: AtomicU64::new(0),
    };
    let e = export_tiles(&model.path, &out, &TilesOptions::default(), &stop).unwrap_err();
    assert!(matches!(e, TilesError::Interrupted), "{e}");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing left"
    );
}
