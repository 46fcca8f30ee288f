//! The glTF 2.0 importer on small files written here, byte by byte: scene flattening
//! (node transforms, instancing, mirrors), primitive modes, index and attribute
//! encodings, materials' colours, the extensions Tessera reads (`KHR_mesh_quantization`,
//! `EXT_meshopt_compression`, `KHR_texture_transform`; `KHR_draco_mesh_compression` in
//! tests/draco.rs), `.glb`, external buffers, and bad
//! input, which must give a one-line error naming the file (or a counted skip), never a
//! panic.

mod common;

use base64::Engine as _;
use common::{jpeg, png, read_bytes, read_err, read_ok, Collect};
use serde_json::{json, Value};
use tessera_mesh::{ImageSource, MeshError, Wrap, NO_TEXTURE};

const FLOAT: u32 = 5126;
const UBYTE: u32 = 5121;
const USHORT: u32 = 5123;
const UINT: u32 = 5125;
const BYTE: u32 = 5120;

/// A glTF being written: one binary buffer, its views and accessors; the rest of the
/// document (meshes, nodes, ...) is given when it is serialised.
#[derive(Default)]
struct Doc {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

fn f32s(xs: &[[f32; 3]]) -> Vec<u8> {
    xs.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
}

impl Doc {
    /// Append `bytes` as a buffer view (4-byte aligned); its index.
    fn view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// An accessor over `view`, with `extra` fields merged in; its index.
    fn accessor(
        &mut self,
        view: Option<usize>,
        ctype: u32,
        ty: &str,
        count: usize,
        extra: Value,
    ) -> usize {
        let mut a = json!({"componentType": ctype, "type": ty, "count": count});
        if let Some(v) = view {
            a["bufferView"] = json!(v);
        }
        if let Value::Object(m) = extra {
            for (k, v) in m {
                a[k] = v;
            }
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn positions(&mut self, xs: &[[f32; 3]]) -> usize {
        let v = self.view(&f32s(xs), None);
        self.accessor(Some(v), FLOAT, "VEC3", xs.len(), json!({}))
    }

    fn vec3(&mut self, xs: &[[f32; 3]]) -> usize {
        self.positions(xs)
    }

    fn indices_u16(&mut self, xs: &[u16]) -> usize {
        let b: Vec<u8> = xs.iter().flat_map(|x| x.to_le_bytes()).collect();
        let v = self.view(&b, None);
        self.accessor(Some(v), USHORT, "SCALAR", xs.len(), json!({}))
    }

    /// The document with `rest` (meshes, nodes, scenes, ...) and the buffer as `buffer`.
    fn root(&self, rest: Value, buffer: Value) -> Value {
        let mut root = json!({
            "asset": {"version": "2.0"},
            "buffers": [buffer],
            "bufferViews": self.views,
            "accessors": self.accessors,
        });
        if let Value::Object(m) = rest {
            for (k, v) in m {
                root[k] = v;
            }
        }
        root
    }

    /// A `.gltf` with the buffer as a base64 `data:` URI.
    fn gltf(&self, rest: Value) -> Vec<u8> {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        let root = self.root(rest, json!({"byteLength": self.bin.len(), "uri": uri}));
        serde_json::to_vec(&root).unwrap()
    }

    /// A `.glb` with the buffer as its binary chunk.
    fn glb(&self, rest: Value) -> Vec<u8> {
        let root = self.root(rest, json!({"byteLength": self.bin.len()}));
        glb(&serde_json::to_vec(&root).unwrap(), &self.bin)
    }
}

/// A GLB container of `json` and `bin`.
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let pad = |b: &[u8], with: u8| {
        let mut v = b.to_vec();
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let (j, b) = (pad(json, b' '), pad(bin, 0));
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + j.len() + 8 + b.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

/// One node (mesh 0, `node` fields), scene 0.
fn one_node(meshes: Value, node: Value) -> Value {
    let mut n = json!({"mesh": 0});
    if let Value::Object(m) = node {
        for (k, v) in m {
            n[k] = v;
        }
    }
    json!({"meshes": meshes, "nodes": [n], "scenes": [{"nodes": [0]}], "scene": 0})
}

/// A one-triangle document.
fn triangle_doc() -> (Doc, Value) {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let i = d.indices_u16(&[0, 1, 2]);
    let rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p}, "indices": i}]}]),
        json!({}),
    );
    (d, rest)
}

/// The triangle's geometric normal (right hand, counter-clockwise front).
fn face_normal(c: &Collect, t: [u32; 3]) -> [f32; 3] {
    let p = |i: u32| c.vertices[i as usize].position;
    let (a, b, cc) = (p(t[0]), p(t[1]), p(t[2]));
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [cc[0] - a[0], cc[1] - a[1], cc[2] - a[2]];
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn nodes_place_their_meshes_and_a_mirror_flips_winding() {
    // One mesh, three instances: moved, mirrored under a moved parent, and scaled
    // unevenly (its normal must lean as the surface does).
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let s = 0.5f32.sqrt();
    let n = d.vec3(&[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [s, s, 0.0]]);
    let i = d.indices_u16(&[0, 1, 2]);
    let rest = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}, "indices": i}]}],
        "nodes": [
            {"mesh": 0, "translation": [10.0, 0.0, 0.0]},
            {"translation": [0.0, 5.0, 0.0], "children": [2]},
            {"mesh": 0, "scale": [-1.0, 1.0, 1.0]},
            {"mesh": 0, "matrix": [4.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]},
        ],
        "scenes": [{"nodes": [0, 1, 3]}],
        "scene": 0,
    });
    let (r, c) = read_ok("nodes.gltf", &d.gltf(rest));
    assert_eq!((r.vertices, r.triangles), (9, 3));
    assert!(c.headers[0].attributes.normals);
    let pos: Vec<[f32; 3]> = c.vertices.iter().map(|v| v.position).collect();
    assert_eq!(
        &pos[0..3],
        &[[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]
    );
    assert_eq!(
        &pos[3..6],
        &[[0.0, 5.0, 0.0], [-1.0, 5.0, 0.0], [0.0, 6.0, 0.0]]
    );
    assert_eq!(c.triangles[0], [0, 1, 2]);
    assert_eq!(
        c.triangles[1],
        [3, 5, 4],
        "the mirrored instance keeps its front face"
    );
    for (t, tri) in c.triangles.iter().enumerate() {
        let fn_ = face_normal(&c, *tri);
        assert!(
            dot(fn_, c.vertices[tri[0] as usize].normal) > 0.0,
            "triangle {t} faces away from its normals"
        );
    }
    // Under x * 4, the normal (1, 1, 0) / sqrt 2 of a slanted surface becomes (1/4, 1, 0), unit.
    let want = {
        let l = (1.0f32 / 16.0 + 1.0).sqrt();
        [0.25 / l, 1.0 / l, 0.0]
    };
    assert!(
        close(&c.vertices[8].normal, &want, 1e-6),
        "{:?}",
        c.vertices[8].normal
    );
    assert_eq!(pos[7], [4.0, 0.0, 0.0]);
}

#[test]
fn a_mesh_in_several_nodes_is_emitted_per_instance() {
    let (d, _) = triangle_doc();
    let rest = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [0.0, 0.0, 1.0]}, {"children": [0, 1]}],
        "scenes": [{"nodes": [2]}],
    });
    let (r, c) = read_ok("instances.gltf", &d.gltf(rest));
    assert_eq!((r.vertices, r.triangles), (6, 2));
    assert_eq!(c.triangles, [[0, 1, 2], [3, 4, 5]]);
    assert_eq!(c.vertices[3].position, [0.0, 0.0, 1.0]);
}

#[test]
fn without_a_default_scene_every_scene_is_read_and_without_scenes_every_mesh() {
    let (d, _) = triangle_doc();
    let mesh = json!([{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]);
    let two_scenes = json!({
        "meshes": mesh,
        "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [0.0, 0.0, 2.0]}],
        // Node 0 is in both scenes: shown once.
        "scenes": [{"nodes": [0]}, {"nodes": [0, 1]}],
    });
    let (r, _) = read_ok("scenes.gltf", &d.gltf(two_scenes));
    assert_eq!(r.triangles, 2);
    let (r, c) = read_ok("noscene.gltf", &d.gltf(json!({"meshes": mesh})));
    assert_eq!(r.triangles, 1);
    assert_eq!(c.vertices[1].position, [1.0, 0.0, 0.0]);
}

#[test]
fn materials_base_colour_factors_colour_untextured_primitives() {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let i = d.indices_u16(&[0, 1, 2]);
    let prim = |m: Option<u32>| {
        let mut v = json!({"attributes": {"POSITION": p}, "indices": i});
        if let Some(m) = m {
            v["material"] = json!(m);
        }
        v
    };
    let rest = one_node(
        json!([{"primitives": [prim(Some(0)), prim(Some(1)), prim(None)]}]),
        json!({}),
    );
    let mut rest = rest;
    rest["materials"] = json!([
        {"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, 1.0]}},
        {"pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.5, 1.0, 1.0]}},
    ]);
    let (r, c) = read_ok("materials.gltf", &d.gltf(rest));
    assert_eq!(r.triangles, 3);
    assert!(c.headers[0].attributes.colors);
    assert_eq!(c.vertices[0].color, [255, 0, 0, 255]);
    // Linear 0.5 is sRGB 188: glTF factors are linear, Tessera's colours are shown as sRGB.
    assert_eq!(c.vertices[3].color, [0, 188, 255, 255]);
    assert_eq!(
        c.vertices[6].color,
        [255, 255, 255, 255],
        "no material: white"
    );
    assert!(r.textures_not_used.is_empty());
}

#[test]
fn color_0_unorm8_and_float_are_multiplied_by_the_factor() {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let i = d.indices_u16(&[0, 1, 2]);
    // RGBA unorm8, padded to 4 bytes per element already.
    let cv = d.view(&[255, 0, 0, 255, 0, 255, 0, 128, 0, 0, 255, 0], None);
    let c8 = d.accessor(Some(cv), UBYTE, "VEC4", 3, json!({"normalized": true}));
    let cf = d.vec3(&[[1.0, 1.0, 1.0], [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]]);
    let rest = json!({
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": p, "COLOR_0": c8}, "indices": i, "material": 0},
            {"attributes": {"POSITION": p, "COLOR_0": cf}, "indices": i},
        ]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.5]}}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    });
    let (_, c) = read_ok("colors.gltf", &d.gltf(rest));
    let colors: Vec<[u8; 4]> = c.vertices.iter().map(|v| v.color).collect();
    assert_eq!(colors[0], [255, 0, 0, 128]);
    assert_eq!(colors[1], [0, 255, 0, 64]);
    assert_eq!(colors[2], [0, 0, 255, 0]);
    assert_eq!(
        colors[3..],
        [[255, 255, 255, 255], [188, 188, 188, 255], [0, 0, 0, 255]]
    );
}

#[test]
fn strips_fans_and_non_indexed_lists_become_triangles() {
    let mut d = Doc::default();
    let pts: Vec<[f32; 3]> = (0..5)
        .map(|k| [k as f32, (1 - k % 2) as f32, 0.0])
        .collect();
    let p = d.positions(&pts);
    let fan_pts = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [-1.0, 0.5, 0.0],
    ];
    let fp = d.positions(&fan_pts);
    let fv = d.view(&[0, 1, 2, 3, 4], None);
    let fi = d.accessor(Some(fv), UBYTE, "SCALAR", 5, json!({}));
    let lp = d.positions(&[
        TRI[0],
        TRI[1],
        TRI[2],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
    ]);
    let rest = one_node(
        json!([{"primitives": [
            {"attributes": {"POSITION": p}, "mode": 5},
            {"attributes": {"POSITION": fp}, "indices": fi, "mode": 6},
            {"attributes": {"POSITION": lp}},
        ]}]),
        json!({}),
    );
    let (r, c) = read_ok("modes.gltf", &d.gltf(rest));
    assert_eq!(r.triangles, 3 + 3 + 2);
    assert_eq!(&c.triangles[..3], &[[0, 1, 2], [1, 3, 2], [2, 3, 4]]);
    assert_eq!(&c.triangles[3..6], &[[5, 6, 7], [5, 7, 8], [5, 8, 9]]);
    assert_eq!(&c.triangles[6..], &[[10, 11, 12], [13, 14, 15]]);
    // Every strip triangle faces +z, like the first.
    for t in &c.triangles[..6] {
        assert!(face_normal(&c, *t)[2] > 0.0, "{t:?}");
    }
}

#[test]
fn indices_of_every_width_and_byte_strides() {
    let mut d = Doc::default();
    // Positions interleaved with 4 bytes of padding: stride 16.
    let mut inter = Vec::new();
    for p in TRI {
        inter.extend(f32s(&[p]));
        inter.extend([0xAA; 4]);
    }
    let pv = d.view(&inter, Some(16));
    let p = d.accessor(Some(pv), FLOAT, "VEC3", 3, json!({}));
    let v8 = d.view(&[2, 1, 0], None);
    let i8_ = d.accessor(Some(v8), UBYTE, "SCALAR", 3, json!({}));
    let i16_ = d.indices_u16(&[0, 2, 1]);
    let v32 = d.view(&[1u32, 2, 0].map(u32::to_le_bytes).concat(), None);
    let i32_ = d.accessor(Some(v32), UINT, "SCALAR", 3, json!({}));
    let rest = one_node(
        json!([{"primitives": [
            {"attributes": {"POSITION": p}, "indices": i8_},
            {"attributes": {"POSITION": p}, "indices": i16_},
            {"attributes": {"POSITION": p}, "indices": i32_},
        ]}]),
        json!({}),
    );
    let (_, c) = read_ok("widths.gltf", &d.gltf(rest));
    assert_eq!(c.triangles, [[2, 1, 0], [3, 5, 4], [7, 8, 6]]);
    assert_eq!(c.vertices[2].position, [0.0, 1.0, 0.0]);
}

#[test]
fn sparse_accessors_patch_their_base_or_zeros() {
    let mut d = Doc::default();
    let base = d.view(&f32s(&TRI), None);
    let sv = d.view(&1u16.to_le_bytes(), None);
    let vals = d.view(&f32s(&[[5.0, 5.0, 5.0]]), None);
    let sparse = |view: Option<usize>| {
        let mut s = json!({"sparse": {"count": 1,
            "indices": {"bufferView": sv, "componentType": USHORT},
            "values": {"bufferView": vals}}});
        if view.is_none() {
            s["max"] = json!([5.0, 5.0, 5.0]);
        }
        s
    };
    let patched = d.accessor(Some(base), FLOAT, "VEC3", 3, sparse(Some(base)));
    // No bufferView: zeros, then the substitute (vertex 1).
    let zero_based = d.accessor(None, FLOAT, "VEC3", 3, sparse(None));
    let rest = one_node(
        json!([{"primitives": [
            {"attributes": {"POSITION": patched}},
            {"attributes": {"POSITION": zero_based}},
        ]}]),
        json!({}),
    );
    let (r, c) = read_ok("sparse.gltf", &d.gltf(rest));
    assert_eq!(c.vertices[1].position, [5.0, 5.0, 5.0]);
    assert_eq!(c.vertices[0].position, [0.0, 0.0, 0.0]);
    assert_eq!(c.vertices[4].position, [5.0, 5.0, 5.0]);
    assert_eq!(c.vertices[3].position, [0.0, 0.0, 0.0]);
    assert_eq!(c.vertices[5].position, [0.0, 0.0, 0.0]);
    // The all-zero-but-one triangle repeats no index, so it is delivered (zero area is
    // the builder's business), and the report counts it.
    assert_eq!(r.triangles, 2);
}

#[test]
fn khr_mesh_quantization_is_undone_by_the_node_transform() {
    let mut d = Doc::default();
    // u16 positions (not normalised) scaled by the node: 0..1000 -> 0..1 m, moved by 3.
    let qp: Vec<u8> = [[0u16, 0, 0, 0], [1000, 0, 0, 0], [0, 1000, 0, 0]]
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let pv = d.view(&qp, Some(8));
    let p = d.accessor(
        Some(pv),
        USHORT,
        "VEC3",
        3,
        json!({"min": [0, 0, 0], "max": [1000, 1000, 0]}),
    );
    // i8 normalised normals (0, 0, 127), padded to 4 bytes.
    let nv = d.view(&[0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0], Some(4));
    let n = d.accessor(Some(nv), BYTE, "VEC3", 3, json!({"normalized": true}));
    // u16 normalised UVs.
    let tv = d.view(
        &[0u16, 0, 65535, 0, 0, 32768].map(u16::to_le_bytes).concat(),
        None,
    );
    let t = d.accessor(Some(tv), USHORT, "VEC2", 3, json!({"normalized": true}));
    let mut rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p, "NORMAL": n, "TEXCOORD_0": t}}]}]),
        json!({"translation": [3.0, 0.0, 0.0], "scale": [0.001, 0.001, 0.001]}),
    );
    rest["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    rest["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let (r, c) = read_ok("quantized.glb", &d.glb(rest));
    assert_eq!(r.triangles, 1);
    assert!(
        close(&c.vertices[1].position, &[4.0, 0.0, 0.0], 1e-6),
        "{:?}",
        c.vertices[1].position
    );
    assert!(close(&c.vertices[2].position, &[3.0, 1.0, 0.0], 1e-6));
    assert!(
        close(&c.vertices[0].normal, &[0.0, 0.0, 1.0], 1e-6),
        "renormalised after the scale"
    );
    assert!(close(&c.vertices[1].uv, &[1.0, 0.0], 1e-6));
    assert!(close(&c.vertices[2].uv, &[0.0, 0.5], 1e-4));
}

#[test]
fn khr_texture_transform_moves_uvs_and_a_missing_image_is_reported() {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let tv = d.view(
        &[0.25f32, 0.1, 1.0, 0.0, 0.0, 1.0]
            .map(f32::to_le_bytes)
            .concat(),
        None,
    );
    let t = d.accessor(Some(tv), FLOAT, "VEC2", 3, json!({}));
    let mut rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p, "TEXCOORD_0": t}, "material": 0}]}]),
        json!({}),
    );
    rest["materials"] = json!([{"name": "skin", "pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": {
            "offset": [0.5, 0.0], "rotation": std::f32::consts::FRAC_PI_2, "scale": [2.0, 2.0]}}}}}]);
    rest["textures"] = json!([{"source": 0}]);
    rest["images"] = json!([{"uri": "photo.jpg"}]);
    rest["extensionsUsed"] = json!(["KHR_texture_transform"]);
    let (r, c) = read_ok("transform.gltf", &d.gltf(rest));
    assert!(c.headers[0].attributes.uvs);
    // Scale, rotate (u' = u cos + v sin, v' = v cos - u sin), offset:
    // (0.25, 0.1) -> (0.5, 0.2) -> (0.2, -0.5) -> (0.7, -0.5).
    assert!(
        close(&c.vertices[0].uv, &[0.7, -0.5], 1e-6),
        "{:?}",
        c.vertices[0].uv
    );
    assert!(
        close(&c.vertices[1].uv, &[0.5, -2.0], 1e-6),
        "{:?}",
        c.vertices[1].uv
    );
    // The image is missing: a warning naming it, the vertices untextured.
    assert!(r.textures_not_used.is_empty(), "{:?}", r.textures_not_used);
    assert_eq!(r.missing_files.len(), 1);
    assert!(
        r.missing_files[0].ends_with("photo.jpg"),
        "{:?}",
        r.missing_files
    );
    assert!(r.textures.is_empty());
    assert!(!c.headers[0].attributes.textures);
    assert!(c
        .vertices
        .iter()
        .all(|v| v.texture == tessera_mesh::NO_TEXTURE));
    // White factor, no COLOR_0: no colours at all (white, never black).
    assert!(!c.headers[0].attributes.colors);
    assert_eq!(c.vertices[0].color, [255; 4]);
}

#[test]
fn glb_and_gltf_of_one_document_read_alike() {
    let (d, rest) = triangle_doc();
    let (ra, a) = read_ok("a.gltf", &d.gltf(rest.clone()));
    let (rb, b) = read_ok("b.glb", &d.glb(rest.clone()));
    assert_eq!(ra, rb);
    assert_eq!(a.vertices, b.vertices);
    assert_eq!(a.triangles, b.triangles);
    // A GLB is recognised by its magic whatever its name.
    let (rc, _) = read_ok("c.glb", &d.glb(rest));
    assert_eq!(rc.triangles, 1);
}

#[test]
fn glb_without_extension_is_known_by_its_magic() {
    let (d, rest) = triangle_doc();
    for name in ["model", "model.bin3d"] {
        let (r, _) = read_bytes(name, &d.glb(rest.clone()));
        assert_eq!(r.unwrap().triangles, 1, "{name}");
    }
    // A .gltf's JSON has no magic: by its name only.
    let (r, _) = read_bytes("model.json", &d.gltf(rest));
    assert!(matches!(r, Err(MeshError::UnknownFormat { .. })));
}

#[test]
fn a_gzip_compressed_glb_is_refused_clearly() {
    use std::io::Write;
    let (d, rest) = triangle_doc();
    let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(&d.glb(rest)).unwrap();
    let gz = z.finish().unwrap();
    for name in ["scan.glb.gz", "scan"] {
        let e = err_text(name, &gz);
        assert!(
            e.contains("gzip-compressed glTF") && e.contains("decompress it first"),
            "{e}"
        );
    }
}

#[test]
fn external_buffers_with_spaces_in_their_names_are_mapped() {
    let (d, rest) = triangle_doc();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("my scan.bin"), &d.bin).unwrap();
    let root = d.root(
        rest,
        json!({"byteLength": d.bin.len(), "uri": "my%20scan.bin"}),
    );
    let path = dir.path().join("scan.gltf");
    std::fs::write(&path, serde_json::to_vec(&root).unwrap()).unwrap();
    let mut c = Collect::default();
    let r = tessera_mesh::read_mesh(&path, &mut c).unwrap();
    assert_eq!(r.triangles, 1);
    assert_eq!(c.vertices[2].position, [0.0, 1.0, 0.0]);
}

#[test]
fn meshopt_compressed_views_decode_without_their_fallback() {
    // Positions (ATTRIBUTES, no filter), octahedral normals (ATTRIBUTES + OCTAHEDRAL),
    // exponential UVs (EXPONENTIAL), triangles (TRIANGLES) and a second primitive's
    // index sequence (INDICES); the fallback buffer has no data at all.
    let pos: Vec<[f32; 3]> = (0..32)
        .map(|k| [k as f32, (k * k % 7) as f32, 1.0])
        .collect();
    let tris: Vec<u32> = (0..30).flat_map(|k| [k, k + 1, k + 2]).collect();
    let normals: Vec<[f32; 4]> = (0..32).map(|_| [0.0, 0.6, 0.8, 0.0]).collect();
    let uvs: Vec<[f32; 2]> = (0..32).map(|k| [k as f32 / 32.0, 0.5]).collect();
    let oct = meshopt::encode_filter_oct::<i8>(&normals, 8);
    let exp = meshopt::encode_filter_exp::<2>(&uvs, 15, meshopt::EncodeExpMode::Separate);
    let rgba: Vec<[f32; 4]> = (0..32).map(|k| [1.0, k as f32 / 31.0, 0.0, 1.0]).collect();
    let ycocg = meshopt::encode_filter_color::<u8>(&rgba, 8);
    let streams: Vec<(Vec<u8>, usize, usize, &str, &str)> = vec![
        (
            meshopt::encode_vertex_buffer(&pos).unwrap(),
            12,
            32,
            "ATTRIBUTES",
            "NONE",
        ),
        (
            meshopt::encode_vertex_buffer(&oct).unwrap(),
            4,
            32,
            "ATTRIBUTES",
            "OCTAHEDRAL",
        ),
        (
            meshopt::encode_vertex_buffer(&exp).unwrap(),
            8,
            32,
            "ATTRIBUTES",
            "EXPONENTIAL",
        ),
        (
            meshopt::encode_index_buffer(&tris, 32).unwrap(),
            4,
            90,
            "TRIANGLES",
            "NONE",
        ),
        (
            meshopt::encode_index_sequence(&tris[..9], 32).unwrap(),
            2,
            9,
            "INDICES",
            "NONE",
        ),
        (
            meshopt::encode_vertex_buffer(&ycocg).unwrap(),
            4,
            32,
            "ATTRIBUTES",
            "COLOR",
        ),
    ];
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut fallback_at = 0;
    for (bytes, stride, count, mode, filter) in &streams {
        let mut ext = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len(),
            "byteStride": stride, "count": count, "mode": mode});
        if *filter != "NONE" {
            ext["filter"] = json!(filter);
        }
        let mut v = json!({"buffer": 1, "byteOffset": fallback_at, "byteLength": stride * count,
            "extensions": {"EXT_meshopt_compression": ext}});
        if *mode == "ATTRIBUTES" {
            v["byteStride"] = json!(stride);
        }
        views.push(v);
        fallback_at += (stride * count).next_multiple_of(4);
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
    }
    let root = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
        "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
        "buffers": [{"byteLength": bin.len()},
                    {"byteLength": fallback_at, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "type": "VEC3", "count": 32},
            {"bufferView": 1, "componentType": BYTE, "type": "VEC3", "count": 32, "normalized": true},
            {"bufferView": 2, "componentType": FLOAT, "type": "VEC2", "count": 32},
            {"bufferView": 3, "componentType": UINT, "type": "SCALAR", "count": 90},
            {"bufferView": 4, "componentType": USHORT, "type": "SCALAR", "count": 9},
            {"bufferView": 5, "componentType": UBYTE, "type": "VEC4", "count": 32, "normalized": true},
        ],
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 5}, "indices": 3},
            {"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 4},
        ]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    });
    let (r, c) = read_ok(
        "meshopt.glb",
        &glb(&serde_json::to_vec(&root).unwrap(), &bin),
    );
    assert_eq!((r.vertices, r.triangles), (64, 33));
    for k in 0..32 {
        assert_eq!(c.vertices[k].position, pos[k]);
        assert!(
            close(&c.vertices[k].normal, &[0.0, 0.6, 0.8], 0.02),
            "{:?}",
            c.vertices[k].normal
        );
        assert!(
            close(&c.vertices[k].uv, &uvs[k], 1e-4),
            "{:?}",
            c.vertices[k].uv
        );
    }
    // The index codec may rotate a triangle's corners; compare rotation-free.
    let norm = |t: [u32; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    for (k, t) in c.triangles[..30].iter().enumerate() {
        assert_eq!(
            norm(*t),
            norm([tris[3 * k], tris[3 * k + 1], tris[3 * k + 2]])
        );
    }
    assert_eq!(c.triangles[30], [32, 33, 34]);
}

#[test]
fn points_and_lines_are_counted_as_ignored() {
    let (d, _) = triangle_doc();
    let rest = one_node(
        json!([{"primitives": [
            {"attributes": {"POSITION": 0}, "indices": 1},
            {"attributes": {"POSITION": 0}, "mode": 0},
            {"attributes": {"POSITION": 0}, "mode": 1},
            {"attributes": {"POSITION": 0}, "mode": 3},
        ]}]),
        json!({}),
    );
    let (r, _) = read_ok("lines.gltf", &d.gltf(rest));
    assert_eq!(r.triangles, 1);
    assert_eq!(r.ignored_statements, 3);
    assert_eq!(r.ignored_by_name["primitive mode LINES"], 1);
    assert_eq!(r.ignored_by_name["primitive mode POINTS"], 1);
    assert_eq!(r.ignored_by_name["primitive mode LINE_STRIP"], 1);
}

// ---------------------------------------------------------------------------------------
// Bad input: one clear line naming the file, never a panic.
// ---------------------------------------------------------------------------------------

fn err_text(name: &str, bytes: &[u8]) -> String {
    read_err(name, bytes).to_string()
}

#[test]
fn a_buffer_shorter_than_its_views_or_accessors_is_an_error() {
    let (mut d, rest) = triangle_doc();
    d.bin.truncate(20);
    let e = err_text("short.glb", &d.glb(rest.clone()));
    assert!(
        e.contains("bufferView 0 needs bytes 0..36 of buffer 0, which has only 20 bytes"),
        "{e}"
    );
    // A view that fits, an accessor that overruns it.
    let (mut d, _) = triangle_doc();
    d.accessors[0]["count"] = json!(4);
    let e = err_text("overrun.gltf", &d.gltf(rest));
    assert!(
        e.contains("accessor 0 (POSITION of mesh 0 primitive 0): 4 elements of 12 bytes"),
        "{e}"
    );
    assert!(e.contains("need 48 bytes, bufferView 0 has 36"), "{e}");
}

#[test]
fn an_index_out_of_range_is_an_error() {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let i = d.indices_u16(&[0, 1, 7]);
    let rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p}, "indices": i}]}]),
        json!({}),
    );
    let e = err_text("index.gltf", &d.gltf(rest));
    assert!(e.contains("accessor 1 (indices of mesh 0 primitive 0), element 2: vertex index 7 out of range (the mesh has 3 vertices)"), "{e}");
}

#[test]
fn a_missing_external_buffer_file_is_an_error() {
    let (d, rest) = triangle_doc();
    let root = d.root(
        rest,
        json!({"byteLength": d.bin.len(), "uri": "missing.bin"}),
    );
    let e = err_text("external.gltf", &serde_json::to_vec(&root).unwrap());
    assert!(
        e.contains("buffer 0: cannot read its file 'missing.bin'"),
        "{e}"
    );
}

#[test]
fn a_bad_data_uri_is_an_error() {
    let (d, rest) = triangle_doc();
    for (uri, want) in [
        (
            "data:application/octet-stream;base64,@@@@",
            "bad data URI: base64",
        ),
        (
            "data:application/octet-stream;base64",
            "bad data URI: no ','",
        ),
        (
            "http://example.com/x.bin",
            "is a URL, which is never fetched",
        ),
    ] {
        let root = d.root(rest.clone(), json!({"byteLength": d.bin.len(), "uri": uri}));
        let e = err_text("uri.gltf", &serde_json::to_vec(&root).unwrap());
        assert!(e.contains("buffer 0") && e.contains(want), "{e}");
    }
}

#[test]
fn a_nan_position_is_an_error() {
    let mut d = Doc::default();
    let p = d.positions(&[TRI[0], [f32::NAN, 0.0, 0.0], TRI[2]]);
    let rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p}}]}]),
        json!({}),
    );
    let e = err_text("nan.gltf", &d.gltf(rest.clone()));
    assert!(
        e.contains("accessor 0 (POSITION of mesh 0 primitive 0), element 1: position [NaN, 0.0, 0.0] is not finite"),
        "{e}"
    );
    // Finite in the file, infinite once placed.
    let mut rest = rest;
    rest["nodes"][0]["scale"] = json!([3e38, 1.0, 1.0]);
    let mut d = Doc::default();
    d.positions(&[TRI[0], [2.0, 0.0, 0.0], TRI[2]]);
    let e = err_text("huge.gltf", &d.gltf(rest));
    assert!(
        e.contains(
            "element 1: position [2.0, 0.0, 0.0] is finite, but not after its node's transform"
        ),
        "{e}"
    );
}

#[test]
fn json_errors_say_where() {
    let e = err_text(
        "bad.gltf",
        b"{\"asset\": {\"version\": \"2.0\"}, \"meshes\": [}",
    );
    assert!(
        e.contains("JSON line 1 column") && e.contains("not valid JSON"),
        "{e}"
    );
    let e = err_text(
        "schema.gltf",
        br#"{"asset": {"version": "2.0"}, "meshes": 3}"#,
    );
    assert!(e.contains("not a glTF 2.0 document"), "{e}");
    let e = err_text(
        "old.gltf",
        br#"{"asset": {"version": "1.0"}, "meshes": {"m": {}}}"#,
    );
    assert!(
        e.contains("glTF version '1.0'; only glTF 2.x is supported"),
        "{e}"
    );
    let e = err_text("empty.gltf", b"");
    assert!(e.contains("not valid JSON"), "{e}");
}

#[test]
fn broken_glb_containers_are_errors() {
    let (d, rest) = triangle_doc();
    let good = d.glb(rest);
    let e = err_text("cut.glb", &good[..good.len() - 10]);
    assert!(e.contains("GLB: the header says"), "{e}");
    let mut v1 = good.clone();
    v1[4] = 1;
    assert!(err_text("v1.glb", &v1).contains("GLB version 1"));
    let e = err_text("tiny.glb", b"glTF\x02\x00");
    assert!(e.contains("header is cut short"), "{e}");
}

#[test]
fn an_unsupported_required_extension_is_named() {
    let (d, mut rest) = triangle_doc();
    rest["extensionsRequired"] = json!([
        "KHR_mesh_quantization",
        "EXT_mesh_gpu_instancing",
        "KHR_materials_fancy"
    ]);
    let e = err_text("required.gltf", &d.gltf(rest));
    assert!(e.contains("requires the glTF extensions EXT_mesh_gpu_instancing, KHR_materials_fancy, which Tessera does not support"), "{e}");
}

#[test]
fn a_draco_primitive_that_does_not_decode_is_named() {
    // Draco required, the primitive plain: read as it is (tests/draco.rs reads real
    // Draco files).
    let (d, mut rest) = triangle_doc();
    rest["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    rest["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let (r, _) = read_ok("draco.glb", &d.glb(rest));
    assert_eq!(r.triangles, 1);
    // Draco only "used", with no uncompressed fallback and a stream of zeros.
    let mut d2 = Doc::default();
    let p = d2.accessor(None, FLOAT, "VEC3", 3, json!({}));
    let mut rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p},
            "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}}]}]),
        json!({}),
    );
    rest["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    d2.view(&[0; 8], None);
    let e = err_text("draco2.gltf", &d2.gltf(rest));
    assert!(
        e.contains("mesh 0 primitive 0 (KHR_draco_mesh_compression, bufferView 0)")
            && e.contains("the Draco stream does not decode"),
        "{e}"
    );
}

#[test]
fn malformed_scenes_are_errors() {
    let (d, _) = triangle_doc();
    let mesh = json!([{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]);
    let cases = [
        (
            json!({"meshes": mesh, "nodes": [{"mesh": 0, "children": [1]}, {"children": [0]}], "scenes": [{"nodes": [0]}]}),
            "is reached twice",
        ),
        (
            json!({"meshes": mesh, "nodes": [{"mesh": 0, "children": [9]}], "scenes": [{"nodes": [0]}]}),
            "node 9: does not exist",
        ),
        (
            json!({"meshes": mesh, "nodes": [{"mesh": 4}], "scenes": [{"nodes": [0]}]}),
            "mesh 4 does not exist",
        ),
        (
            json!({"meshes": mesh, "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 2}),
            "default scene 2 does not exist",
        ),
        (
            json!({"meshes": [{"primitives": [{"attributes": {"POSITION": 7}}]}]}),
            "accessor 7 (POSITION of mesh 0 primitive 0): does not exist",
        ),
        (
            json!({"meshes": [{"primitives": [{"attributes": {"POSITION": 1}}]}]}),
            "has type SCALAR, POSITION of mesh 0 primitive 0 must be VEC3",
        ),
        (
            json!({"meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 3}]}]}),
            "material 3: does not exist",
        ),
    ];
    for (rest, want) in cases {
        let e = err_text("scene.gltf", &d.gltf(rest));
        assert!(e.contains(want), "want {want:?}: {e}");
    }
}

#[test]
fn a_file_without_triangles_is_empty() {
    let (d, _) = triangle_doc();
    let rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": 0}, "mode": 1}]}]),
        json!({}),
    );
    assert!(matches!(
        read_err("lines_only.gltf", &d.gltf(rest)),
        MeshError::Empty { .. }
    ));
}

#[test]
fn truncating_or_corrupting_a_glb_never_panics() {
    let (d, rest) = triangle_doc();
    let good = d.glb(rest);
    for cut in 0..good.len() {
        let _ = tessera_mesh::fuzzing::fuzz_gltf(&good[..cut]);
    }
    for at in 0..good.len() {
        for x in [0u8, 0xFF, b'9', b'"'] {
            let mut b = good.clone();
            b[at] = x;
            let _ = tessera_mesh::fuzzing::fuzz_gltf(&b);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Base colour textures (issue 11, appearance)
// ---------------------------------------------------------------------------------------

/// A document of `n` one-triangle primitives' data: positions, `TEXCOORD_0` and
/// `TEXCOORD_1` accessors and indices (each shared by every primitive).
fn textured_doc() -> (Doc, usize, usize, usize, usize) {
    let mut d = Doc::default();
    let p = d.positions(&TRI);
    let uv = |d: &mut Doc, xs: [f32; 6]| {
        let v = d.view(&xs.map(f32::to_le_bytes).concat(), None);
        d.accessor(Some(v), FLOAT, "VEC2", 3, json!({}))
    };
    let t0 = uv(&mut d, [0.0, 0.0, 1.0, 0.0, 0.25, 1.5]);
    let t1 = uv(&mut d, [0.5, 0.5, 0.5, 0.5, 0.5, 0.5]);
    let i = d.indices_u16(&[0, 1, 2]);
    (d, p, t0, t1, i)
}

/// Write `bytes` as `name` beside `files` (name, contents) in a temp dir and read it.
fn read_in_dir(
    name: &str,
    bytes: &[u8],
    files: &[(&str, &[u8])],
) -> (tessera_mesh::ImportReport, Collect, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    for (n, b) in files {
        let p = dir.path().join(n);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, b).unwrap();
    }
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    let mut c = Collect::default();
    let r = tessera_mesh::read_mesh(&path, &mut c).unwrap_or_else(|e| panic!("{name}: {e}"));
    (r, c, dir)
}

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// Two materials sample one external PNG (its name percent-encoded, with a space) through
/// two textures, one with a sampler's wrap modes, one with `KHR_texture_transform`; a
/// third material is untextured. The vertices carry their texture's index, their UVs as
/// the file gives them (not flipped, only transformed), their colour the factor.
#[test]
fn base_colour_textures_of_an_external_png_with_samplers() {
    let (d, p, t0, _, i) = textured_doc();
    let prim = |m: u32| json!({"attributes": {"POSITION": p, "TEXCOORD_0": t0}, "indices": i, "material": m});
    let mut rest = one_node(
        json!([{"primitives": [prim(0), prim(1), prim(2)]}]),
        json!({}),
    );
    rest["materials"] = json!([
        {"name": "bark", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.5, 1.0, 1.0],
            "baseColorTexture": {"index": 0}}},
        {"name": "bark moved", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1,
            "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0]}}}}},
        {"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, 1.0]}},
    ]);
    rest["samplers"] = json!([{"wrapS": 33071, "wrapT": 33648}]);
    rest["textures"] = json!([{"source": 0, "sampler": 0}, {"source": 0}]);
    rest["images"] = json!([{"uri": "tex/my%20bark.png"}]);
    rest["extensionsUsed"] = json!(["KHR_texture_transform"]);
    let image = png(6, 10);
    let (r, c, dir) = read_in_dir("bark.gltf", &d.gltf(rest), &[("tex/my bark.png", &image)]);
    assert!(r.textures_not_used.is_empty(), "{:?}", r.textures_not_used);
    assert!(r.missing_files.is_empty() && r.unreadable_images.is_empty());
    let h = c.headers[0].attributes;
    assert!(h.textures && h.uvs && h.colors);
    assert_eq!(r.textures.len(), 2);
    let (a, b) = (&r.textures[0], &r.textures[1]);
    assert_eq!(a.material, "bark");
    assert_eq!(
        a.image,
        ImageSource::File(dir.path().join("tex/my bark.png"))
    );
    assert_eq!(a.image_name, "tex/my%20bark.png");
    assert_eq!(a.size, [6, 10]);
    assert_eq!(a.wrap, [Wrap::ClampToEdge, Wrap::MirroredRepeat]);
    assert!(!a.v_up);
    assert_eq!(a.tint, [255, 188, 255, 255], "the factor, sRGB-encoded");
    assert_eq!(b.material, "bark moved");
    assert_eq!(b.image, a.image, "one image, two textures");
    assert_eq!((b.wrap, b.tint), ([Wrap::Repeat; 2], [255; 4]));
    let textures: Vec<u32> = c.vertices.iter().map(|v| v.texture).collect();
    assert_eq!(
        textures,
        [0, 0, 0, 1, 1, 1, NO_TEXTURE, NO_TEXTURE, NO_TEXTURE]
    );
    let uvs: Vec<[f32; 2]> = c.vertices.iter().map(|v| v.uv).collect();
    assert_eq!(uvs[..3], [[0.0, 0.0], [1.0, 0.0], [0.25, 1.5]]);
    assert_eq!(uvs[3..6], [[0.5, 0.0], [1.5, 0.0], [0.75, 1.5]]);
    assert_eq!(c.vertices[0].color, [255, 188, 255, 255]);
    assert_eq!(c.vertices[6].color, [255, 0, 0, 255]);
}

/// An image in a `data:` URI is held in memory, keyed by its index.
#[test]
fn a_data_uri_image_is_held_in_memory() {
    let (d, p, t0, _, i) = textured_doc();
    let mut rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p, "TEXCOORD_0": t0}, "indices": i, "material": 0}]}]),
        json!({}),
    );
    let image = jpeg(9, 7);
    rest["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    rest["textures"] = json!([{"source": 1}]);
    rest["images"] = json!([
        {"uri": "unused.png"},
        {"uri": format!("data:image/jpeg;base64,{}", b64(&image))},
    ]);
    let (r, c) = read_ok("embedded.gltf", &d.gltf(rest));
    assert_eq!(r.textures.len(), 1);
    let t = &r.textures[0];
    assert_eq!(t.material, "material 0");
    assert_eq!(
        t.image,
        ImageSource::Memory {
            key: "image 1".into(),
            bytes: image.into()
        }
    );
    assert_eq!(t.image_name, "image 1 (embedded)");
    assert_eq!(t.size, [9, 7]);
    assert!(c.vertices.iter().all(|v| v.texture == 0));
    // The unused image is not looked for.
    assert!(r.missing_files.is_empty());
}

/// An image in a buffer view: a byte range of the `.glb`, or of the external `.bin`, read
/// back exactly; in a `data:` buffer, the bytes in memory.
#[test]
fn buffer_view_images_are_ranges_of_their_file() {
    let (mut d, p, t0, _, i) = textured_doc();
    let image = png(5, 3);
    // An odd length before it, so the image starts unaligned within the chunk.
    d.view(&[1, 2, 3], None);
    let v = d.view(&image, None);
    let mut rest = one_node(
        json!([{"primitives": [{"attributes": {"POSITION": p, "TEXCOORD_0": t0}, "indices": i, "material": 0}]}]),
        json!({}),
    );
    rest["materials"] =
        json!([{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    rest["textures"] = json!([{"source": 0}]);
    rest["images"] = json!([{"bufferView": v, "mimeType": "image/png"}]);

    let (r, c, dir) = read_in_dir("model.glb", &d.glb(rest.clone()), &[]);
    assert!(c.headers[0].attributes.textures);
    let t = &r.textures[0];
    assert_eq!(
        (t.size, t.image_name.as_str()),
        ([5, 3], "image 0 (embedded)")
    );
    let ImageSource::FileRange { path, offset, len } = &t.image else {
        panic!("{:?}", t.image);
    };
    assert_eq!(path, &dir.path().join("model.glb"));
    let file = std::fs::read(path).unwrap();
    assert_eq!(&file[*offset as usize..(offset + len) as usize], &image[..]);

    // The same document with its buffer in a .bin beside a .gltf.
    let root = d.root(
        rest.clone(),
        json!({"byteLength": d.bin.len(), "uri": "data%201.bin"}),
    );
    let (r, _, dir) = read_in_dir(
        "model.gltf",
        &serde_json::to_vec(&root).unwrap(),
        &[("data 1.bin", &d.bin)],
    );
    let ImageSource::FileRange { path, offset, len } = &r.textures[0].image else {
        panic!("{:?}", r.textures[0].image);
    };
    assert_eq!(path, &dir.path().join("data 1.bin"));
    let file = std::fs::read(path).unwrap();
    assert_eq!(&file[*offset as usize..(offset + len) as usize], &image[..]);

    // A data: buffer: the view's bytes, in memory.
    let (r, _) = read_ok("inline.gltf", &d.gltf(rest));
    assert_eq!(
        r.textures[0].image,
        ImageSource::Memory {
            key: "image 0".into(),
            bytes: image.into()
        }
    );
}

/// What cannot be used is reported and left untextured: another texture coordinate set,
/// WebP (by MIME type, or only through `EXT_texture_webp`), a missing file, a corrupt
/// PNG, a primitive without `TEXCOORD_0`.
#[test]
fn textures_that_cannot_be_used_are_reported_and_drawn_untextured() {
    let (mut d, p, t0, t1, i) = textured_doc();
    let webp = d.view(b"RIFF\x10\0\0\0WEBPVP8 ", None);
    let mut corrupt = png(4, 4);
    corrupt.truncate(24);
    let prim = |m: u32| json!({"attributes": {"POSITION": p, "TEXCOORD_0": t0, "TEXCOORD_1": t1}, "indices": i, "material": m});
    let mut prims: Vec<Value> = (0..5).map(prim).collect();
    prims.push(json!({"attributes": {"POSITION": p}, "indices": i, "material": 5}));
    let mut rest = one_node(json!([{ "primitives": prims }]), json!({}));
    let mat = |name: &str, t: u32, extra: Value| {
        let mut info = json!({"index": t});
        if let Value::Object(m) = extra {
            for (k, v) in m {
                info[k] = v;
            }
        }
        json!({"name": name, "pbrMetallicRoughness": {"baseColorTexture": info}})
    };
    rest["materials"] = json!([
        mat("second set", 0, json!({"texCoord": 1})),
        mat("webp", 1, json!({})),
        mat("webp only", 2, json!({})),
        mat("gone", 3, json!({})),
        mat("corrupt", 4, json!({})),
        mat("no uvs", 0, json!({})),
    ]);
    rest["textures"] = json!([
        {"source": 0},
        {"source": 1},
        {"extensions": {"EXT_texture_webp": {"source": 1}}},
        {"source": 2},
        {"source": 3},
    ]);
    rest["images"] = json!([
        {"uri": format!("data:image/png;base64,{}", b64(&png(2, 2)))},
        {"bufferView": webp, "mimeType": "image/webp"},
        {"uri": "gone.png"},
        {"uri": format!("data:image/png;base64,{}", b64(&corrupt))},
    ]);
    rest["extensionsUsed"] = json!(["EXT_texture_webp"]);
    let (r, c, dir) = read_in_dir("bad.gltf", &d.gltf(rest.clone()), &[]);
    assert!(r.textures.is_empty(), "{:?}", r.textures);
    assert!(!c.headers[0].attributes.textures);
    assert!(c.vertices.iter().all(|v| v.texture == NO_TEXTURE));
    let not_used = &r.textures_not_used;
    assert_eq!(not_used.len(), 4, "{not_used:?}");
    assert!(
        not_used[0].starts_with("second set (image 0): ") && not_used[0].contains("TEXCOORD_1"),
        "{not_used:?}"
    );
    assert!(
        not_used[1].starts_with("webp (image 1): ") && not_used[1].contains("image/webp"),
        "{not_used:?}"
    );
    assert!(
        not_used[2].starts_with("webp only (no image): ")
            && not_used[2].contains("EXT_texture_webp"),
        "{not_used:?}"
    );
    assert!(
        not_used[3].starts_with("no uvs (image 0): ")
            && not_used[3].contains("mesh 0 primitive 5 has no TEXCOORD_0"),
        "{not_used:?}"
    );
    assert_eq!(
        r.missing_files,
        [dir.path().join("gone.png").display().to_string()]
    );
    assert_eq!(r.unreadable_images, ["image 3 (embedded)"]);
    // The second set's UVs are still those it names.
    assert_eq!(c.vertices[0].uv, [0.5, 0.5]);

    // The fuzz entry point opens no file an image names: it is reported, not read.
    let r = tessera_mesh::fuzzing::fuzz_gltf(&d.gltf(rest)).unwrap();
    assert!(r.missing_files.is_empty());
    assert!(
        r.textures_not_used
            .iter()
            .any(|s| s.starts_with("gone (image 'gone.png'): ") && s.contains("may not open")),
        "{:?}",
        r.textures_not_used
    );
}
