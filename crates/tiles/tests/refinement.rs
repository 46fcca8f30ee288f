//! The exported tileset, judged as a 3D Tiles client would read it.
//!
//! - `clients_refinement_only_picks_crack_free_cuts`: the refinement rule of the 3D
//!   Tiles 1.1 specification (section "Geometric error": a tile is refined when its
//!   screen-space error `geometricError * height / (2 * distance * tan(fov_y / 2))`
//!   exceeds the maximum screen-space error, `distance` from the eye to the bounding
//!   volume, 0 inside; `REPLACE`: the children are drawn instead of the tile), written
//!   here in Rust over the parsed `tileset.json`, for hundreds of random cameras and
//!   thresholds on the Bunny (built with small nodes for a deep tree) and a closed
//!   sphere: the contents it picks, merged, have no boundary edge the full-resolution
//!   mesh lacks and no non-manifold edge, and (measured: all 300 of each) it is the
//!   very cut `tessera_select::select_cut` picks for the view. Negative control: the
//!   same tileset with each tile's bounding sphere replaced by its patch's tight sphere
//!   (mates then disagree) does show cracks.
//! - `the_tileset_is_structurally_valid_and_in_model_coordinates`: the structural rules
//!   of the specification that `3d-tiles-tools` 0.5.4 has no validator for (it has no
//!   `validate` command): asset version, `REPLACE`, geometric errors never above the
//!   parent's, children's spheres inside their parent's, every content URI a file that
//!   the `gltf` crate parses and validates; and every content vertex, put through the
//!   glTF node's translation, the Y-up to Z-up rotation clients apply to glTF content
//!   and `root.transform`, lands on its model position.

use std::collections::HashSet;
use std::path::Path;

use serde_json::Value;
use tessera_format::{Model, PatchData, NODE_FLAG_LEAF};
use tessera_select::{
    boundary_edges, edge_report, merge_patches, select_cut, Camera, Criterion, PatchRef,
};
use tessera_testkit::{build_model, shared_data, small_options, sphere, TestModel};
use tessera_tiles::{export_tiles, frame, TilesOptions};

/// splitmix64: random cameras, reproducible.
struct Rng(u64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn direction(&mut self) -> [f64; 3] {
        loop {
            let v = [
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            ];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.1 && l <= 1.0 {
                return v.map(|x| x / l);
            }
        }
    }
}

/// A client's view: eye (world coordinates), vertical field of view, image height.
struct View {
    eye: [f64; 3],
    fov_y_rad: f64,
    height_px: f64,
}

/// The specification's selection with `REPLACE` and no culling: from the root, a tile
/// whose screen-space error exceeds `max_sse` and that has children is replaced by
/// them; otherwise it is drawn. Returns the drawn tiles. Only `root.transform` places
/// tiles here (the exporter writes no other transform; a child transform is refused).
fn client_cut<'a>(tileset: &'a Value, view: &View, max_sse: f64) -> Vec<&'a Value> {
    let root = &tileset["root"];
    let m: Vec<f64> = match root.get("transform") {
        Some(t) => t
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect(),
        None => frame::IDENTITY.to_vec(),
    };
    let m: [f64; 16] = m.try_into().unwrap();
    // The largest axis scale of the transform scales radii.
    let scale = (0..3)
        .map(|c| (0..3).map(|r| m[c * 4 + r].powi(2)).sum::<f64>().sqrt())
        .fold(0.0f64, f64::max);
    let mut drawn = Vec::new();
    let mut stack = vec![root];
    while let Some(tile) = stack.pop() {
        if !std::ptr::eq(tile, root) {
            assert!(
                tile.get("transform").is_none(),
                "child transforms are not modelled here"
            );
        }
        let s: Vec<f64> = tile["boundingVolume"]["sphere"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let c = frame::apply(&m, [s[0], s[1], s[2]]);
        let d = ((0..3)
            .map(|k| (c[k] - view.eye[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            - s[3] * scale)
            .max(0.0);
        let error = tile["geometricError"].as_f64().unwrap();
        let sse = if d == 0.0 {
            if error > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        } else {
            error * view.height_px / (2.0 * d * (view.fov_y_rad / 2.0).tan())
        };
        match tile.get("children").and_then(|c| c.as_array()) {
            Some(children) if sse > max_sse && !children.is_empty() => {
                stack.extend(children.iter().rev());
            }
            _ => drawn.push(tile),
        }
    }
    drawn
}

fn tile_nodes(tile: &Value) -> Vec<u32> {
    tile["extras"]["tessera_nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap() as u32)
        .collect()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// Boundary edges of the merged patches of `nodes` and the count of non-manifold edges.
fn open_edges(patches: &[PatchData], nodes: &[u32]) -> (HashSet<[[u32; 3]; 2]>, u64) {
    let mesh = merge_patches(nodes.iter().map(|&n| PatchRef::from(&patches[n as usize])));
    let r = edge_report(&mesh.indices, &mesh.positions);
    let boundary: HashSet<_> = boundary_edges(&mesh.indices, &mesh.positions)
        .into_iter()
        .collect();
    (boundary, r.nonmanifold_edges)
}

struct Exported {
    model: TestModel,
    dir: tempfile::TempDir,
}

fn export(model: TestModel) -> Exported {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tiles");
    let opts = TilesOptions {
        threads: Some(2),
        ..TilesOptions::default()
    };
    let s = export_tiles(&model.path, &out, &opts, &tessera_mesh::NoProgress).unwrap();
    eprintln!(
        "exported {}: {} tiles, {} files, {} bytes ({:.2} per input triangle), {:.2} s",
        model.input.display(),
        s.tiles,
        s.files,
        s.bytes,
        s.bytes as f64 / s.input_triangles as f64,
        s.seconds
    );
    Exported { model, dir }
}

/// What [`check_cuts`] saw.
struct Checked {
    cuts: usize,
    cracked: usize,
    /// Cuts over more than one level.
    multi_level: usize,
    /// Cuts that are exactly `tessera_select::select_cut`'s (the same camera and
    /// tolerance, no culling): Tessera's own renderer's choice.
    as_tessera: usize,
}

/// Random cameras around, near and inside the model and thresholds from 0.5 to 50 px;
/// every client cut of `tileset` checked for cracks and compared with Tessera's own.
fn check_cuts(m: &Model, patches: &[PatchData], tileset: &Value, cameras: usize) -> Checked {
    let h = m.header();
    let leaves: Vec<u32> = (0..m.nodes().len() as u32)
        .filter(|&i| m.nodes()[i as usize].flags & NODE_FLAG_LEAF != 0)
        .collect();
    let (border, nonmanifold) = open_edges(patches, &leaves);
    assert_eq!(nonmanifold, 0, "the full-resolution mesh is manifold");
    let c = &h.bounding_sphere;
    let radius = c[3];
    let mut rng = Rng(0x7e55_e7a0 ^ m.nodes().len() as u64);
    let (mut cracked, mut multi_level, mut as_tessera) = (0, 0, 0);
    for k in 0..cameras {
        let dir = rng.direction();
        let dist = match k % 4 {
            0 => rng.range(2.0, 10.0),
            1 => rng.range(1.1, 2.0),
            2 => rng.range(0.9, 1.1),
            _ => rng.range(0.1, 0.9),
        } * radius;
        let view = View {
            eye: [0, 1, 2].map(|i| c[i] + dir[i] * dist),
            fov_y_rad: rng.range(20.0, 90.0).to_radians(),
            height_px: rng.range(300.0, 1200.0).round(),
        };
        let max_sse = 0.5 * 100f64.powf(rng.unit());
        let cut = client_cut(tileset, &view, max_sse);
        let nodes: Vec<u32> = cut.iter().flat_map(|t| tile_nodes(t)).collect();
        // Tessera's selection for the same view (the direction does not matter
        // without culling: look at the centre, any up not along the view).
        let camera = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]
            .into_iter()
            .find_map(|up| {
                let h_px = view.height_px as u32;
                Camera::new(
                    view.eye,
                    [c[0], c[1], c[2]],
                    up,
                    view.fov_y_rad.to_degrees(),
                    h_px,
                    h_px,
                )
                .ok()
            })
            .unwrap();
        let criterion = Criterion::View {
            camera,
            tolerance_px: max_sse as f32,
            cull: false,
        };
        let mut own = select_cut(h, m.nodes(), &criterion).nodes;
        let mut mine = nodes.clone();
        own.sort_unstable();
        mine.sort_unstable();
        as_tessera += usize::from(own == mine);
        let levels: HashSet<u8> = nodes.iter().map(|&n| m.nodes()[n as usize].level).collect();
        multi_level += usize::from(levels.len() > 1);
        let (open, nonmanifold) = open_edges(patches, &nodes);
        let new_holes = open.difference(&border).count();
        if new_holes > 0 || nonmanifold > 0 {
            cracked += 1;
        }
    }
    Checked {
        cuts: cameras,
        cracked,
        multi_level,
        as_tessera,
    }
}

fn decode_all(m: &Model) -> Vec<PatchData> {
    (0..m.nodes().len())
        .map(|i| m.decode_patch(i).unwrap())
        .collect()
}

/// The same tileset with every tile's bounding sphere its patch's tight sphere (the
/// root tile: its first root's): mates no longer share a bounding volume.
fn with_tight_spheres(tileset: &Value, m: &Model) -> Value {
    let mut t = tileset.clone();
    let h = *m.header();
    let origin = [
        h.bounding_sphere[0],
        h.bounding_sphere[1],
        h.bounding_sphere[2],
    ];
    let mut stack = vec![&mut t["root"]];
    while let Some(tile) = stack.pop() {
        let n = tile_nodes(tile)[0] as usize;
        let s = tessera_tiles::plan::model_sphere(&h, m.nodes()[n].tight_sphere);
        tile["boundingVolume"]["sphere"] =
            serde_json::json!([s[0] - origin[0], s[1] - origin[1], s[2] - origin[2], s[3]]);
        if let Some(children) = tile.get_mut("children").and_then(|c| c.as_array_mut()) {
            stack.extend(children.iter_mut());
        }
    }
    t
}

#[test]
fn clients_refinement_only_picks_crack_free_cuts() {
    let opts = small_options();
    let models = [
        (
            "bunny",
            build_model(Some(&shared_data("bunny.obj")), &sphere(0), &opts),
        ),
        ("sphere", build_model(None, &sphere(20_000), &opts)),
    ];
    let mut control_cracks = 0;
    for (name, model) in models {
        let e = export(model);
        let m = Model::open(&e.model.path).unwrap();
        let patches = decode_all(&m);
        let tileset = read_json(&e.dir.path().join("tiles/tileset.json"));
        let ok = check_cuts(&m, &patches, &tileset, 300);
        let tight = with_tight_spheres(&tileset, &m);
        let control = check_cuts(&m, &patches, &tight, 300).cracked;
        eprintln!(
            "{name}: {} levels; {} client cuts, {} of them over several levels, {} cracked, {} exactly Tessera's own cut; negative control (tight spheres): {control} cracked",
            m.header().level_count,
            ok.cuts,
            ok.multi_level,
            ok.cracked,
            ok.as_tessera
        );
        assert_eq!(ok.cracked, 0, "{name}: a client picked a cut with cracks");
        assert!(
            ok.multi_level * 3 >= ok.cuts,
            "{name}: too few cuts mix levels ({} of {})",
            ok.multi_level,
            ok.cuts
        );
        // The same rule on the same numbers: only rounding at the threshold (f64 here,
        // f32 in tessera-select) may tell them apart.
        assert!(
            ok.as_tessera * 100 >= ok.cuts * 95,
            "{name}: only {} of {} client cuts are Tessera's own",
            ok.as_tessera,
            ok.cuts
        );
        control_cracks += control;
    }
    assert!(
        control_cracks > 0,
        "the crack check never fails: it would not see a bad mapping"
    );
}

#[test]
fn the_tileset_is_structurally_valid_and_in_model_coordinates() {
    let e = export(build_model(
        Some(&shared_data("bunny.obj")),
        &sphere(0),
        &small_options(),
    ));
    let m = Model::open(&e.model.path).unwrap();
    let grid = m.index().grid();
    let dir = e.dir.path().join("tiles");
    let tileset = read_json(&dir.join("tileset.json"));
    assert_eq!(tileset["asset"]["version"], "1.1");
    let root = &tileset["root"];
    assert_eq!(root["refine"], "REPLACE");
    assert!(
        tileset["geometricError"].as_f64().unwrap() >= root["geometricError"].as_f64().unwrap()
    );
    let m4: [f64; 16] = root["transform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect::<Vec<_>>()
        .try_into()
        .unwrap();
    let sphere_of = |t: &Value| -> Vec<f64> {
        t["boundingVolume"]["sphere"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (mut tiles, mut contents, mut vertices) = (0, 0, 0usize);
    let mut worst = 0.0f64;
    let mut seen = HashSet::new();
    let mut stack: Vec<(&Value, Option<&Value>)> = vec![(root, None)];
    while let Some((tile, parent)) = stack.pop() {
        tiles += 1;
        let s = sphere_of(tile);
        let e = tile["geometricError"].as_f64().unwrap();
        assert!(e >= 0.0 && s[3] >= 0.0);
        if let Some(p) = parent {
            let ps = sphere_of(p);
            let pe = p["geometricError"].as_f64().unwrap();
            // Strictly below a non-zero parent's (3DTilesRendererJS refines
            // unconditionally otherwise).
            assert!(
                e < pe || (e == 0.0 && pe == 0.0),
                "error {e} not below the parent's {pe}"
            );
            let d = ((0..3).map(|k| (s[k] - ps[k]).powi(2)).sum::<f64>()).sqrt();
            assert!(
                d + s[3] <= ps[3] * (1.0 + 1e-6) + 1e-9,
                "child sphere {s:?} not inside {ps:?}"
            );
        }
        let nodes = tile_nodes(tile);
        for &n in &nodes {
            assert!(seen.insert(n), "node {n} in two tiles");
        }
        if let Some(uri) = tile.get("content").map(|c| c["uri"].as_str().unwrap()) {
            contents += 1;
            let bytes = std::fs::read(dir.join(uri)).unwrap_or_else(|e| panic!("{uri}: {e}"));
            let g = gltf::Gltf::from_slice(&bytes).unwrap_or_else(|e| panic!("{uri}: {e}"));
            let blob = g.blob.as_deref().unwrap();
            let node = g.nodes().next().unwrap();
            let t = node.transform().decomposed().0.map(f64::from);
            // Every model vertex of the tile's patches, in order, against the content's.
            let want: Vec<[f64; 3]> = nodes
                .iter()
                .flat_map(|&n| m.decode_patch(n as usize).unwrap().positions)
                .map(|q| grid.position(q))
                .collect();
            let mut got = Vec::new();
            for prim in g.meshes().next().unwrap().primitives() {
                let a = prim.get(&gltf::Semantic::Positions).unwrap();
                let v = a.view().unwrap();
                let raw = &blob[v.offset()..v.offset() + v.length()];
                for p in raw.chunks_exact(12) {
                    let f = |k: usize| {
                        f64::from(f32::from_le_bytes(p[4 * k..4 * k + 4].try_into().unwrap()))
                    };
                    let y_up = [f(0) + t[0], f(1) + t[1], f(2) + t[2]];
                    // glTF +Y up to 3D Tiles +Z up: (x, y, z) -> (x, -z, y).
                    let z_up = [y_up[0], -y_up[2], y_up[1]];
                    got.push(frame::apply(&m4, z_up));
                }
            }
            let mut want_set: Vec<[f64; 3]> = want.clone();
            want_set.sort_by(|a, b| a.partial_cmp(b).unwrap());
            want_set.dedup();
            assert!(
                got.len() <= want.len() && got.len() >= want_set.len(),
                "{uri}: {} vertices, patches hold {}",
                got.len(),
                want.len()
            );
            for p in &got {
                // The nearest model vertex (contents weld duplicates, so compare as sets).
                let d = want_set
                    .iter()
                    .map(|w| (0..3).map(|k| (w[k] - p[k]).powi(2)).sum::<f64>())
                    .fold(f64::INFINITY, f64::min)
                    .sqrt();
                worst = worst.max(d);
            }
            vertices += got.len();
        }
        if let Some(children) = tile.get("children").and_then(|c| c.as_array()) {
            stack.extend(children.iter().map(|c| (c, Some(tile))));
        }
    }
    assert_eq!(seen.len(), m.nodes().len(), "every node in one tile");
    // f32 positions relative to each tile's centre: within a few ulps of the tile size.
    let limit = m.header().bounding_sphere[3] * 1e-6;
    eprintln!("{tiles} tiles, {contents} contents, {vertices} vertices; farthest from its model position {worst:.3e} (limit {limit:.3e})");
    assert!(
        worst <= limit,
        "a vertex is {worst} from its model position"
    );
}
