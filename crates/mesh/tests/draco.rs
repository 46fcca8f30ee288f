//! `KHR_draco_mesh_compression` (issue 11): Draco files written by Google's encoder
//! (gltf-pipeline, `tests/data/draco/`, rebuilt by its `make.sh`) read like their
//! uncompressed source (same triangles and winding through node transforms and a mirror,
//! positions, normals, UVs and colours within the encoder's quantisation, the texture
//! used); an EdgeBreaker valence stream with integer colours (written here by
//! `draco-core`'s encoder: gltf-pipeline's encoder never writes valence); an uncompressed
//! fallback preferred to the stream; attributes outside the stream read from their
//! accessors; and bad streams: one clear error naming the primitive, never a panic,
//! checked by flipping bytes of the real streams.

mod common;

use std::ops::Range;
use std::path::PathBuf;

use base64::Engine as _;
use common::{read_err, read_ok, Collect};
use serde_json::{json, Value};
use tessera_mesh::fuzzing::fuzz_gltf;
use tessera_mesh::{ImportReport, NO_TEXTURE};

fn data(name: &str) -> Vec<u8> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/draco")).join(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn doc(name: &str) -> Value {
    serde_json::from_slice(&data(name)).unwrap()
}

fn b64(bytes: &[u8]) -> String {
    format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bytes)
    )
}

/// The bytes of buffer `b` of `d` (a `data:` URI).
fn buffer(d: &Value, b: usize) -> Vec<u8> {
    let uri = d["buffers"][b]["uri"].as_str().unwrap();
    base64::engine::general_purpose::STANDARD
        .decode(uri.split_once(',').unwrap().1)
        .unwrap()
}

/// The `.glb` of `d` with buffer 0 as its binary chunk, and where (in the `.glb`) the
/// Draco streams of its primitives lie (those in buffer 0).
fn to_glb(d: &Value) -> (Vec<u8>, Vec<Range<usize>>) {
    let bin = buffer(d, 0);
    let mut d = d.clone();
    d["buffers"][0] = json!({"byteLength": bin.len()});
    let mut json = serde_json::to_vec(&d).unwrap();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut padded = bin.clone();
    while !padded.len().is_multiple_of(4) {
        padded.push(0);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((28 + json.len() + padded.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(padded.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    let bin_at = out.len();
    out.extend_from_slice(&padded);
    let mut streams = Vec::new();
    for m in d["meshes"].as_array().unwrap() {
        for p in m["primitives"].as_array().unwrap() {
            let Some(v) = p["extensions"]["KHR_draco_mesh_compression"]["bufferView"].as_u64()
            else {
                continue;
            };
            let view = &d["bufferViews"][v as usize];
            if view["buffer"].as_u64() != Some(0) {
                continue;
            }
            let at = bin_at + view["byteOffset"].as_u64().unwrap_or(0) as usize;
            streams.push(at..at + view["byteLength"].as_u64().unwrap() as usize);
        }
    }
    (out, streams)
}

fn read_doc(name: &str, d: &Value) -> (ImportReport, Collect) {
    read_ok(name, &serde_json::to_vec(d).unwrap())
}

fn err_doc(name: &str, d: &Value) -> String {
    read_err(name, &serde_json::to_vec(d).unwrap()).to_string()
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max)
}

/// `c`'s triangles in vertex numbers of `to` through `map`, each rotated to start at its
/// smallest corner (rotation keeps the winding), sorted.
fn triangles(c: &Collect, map: &[usize]) -> Vec<[usize; 3]> {
    let mut t: Vec<[usize; 3]> = c
        .triangles
        .iter()
        .map(|t| {
            let t = t.map(|i| map[i as usize]);
            let r = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
        })
        .collect();
    t.sort_unstable();
    t
}

/// Compare what `draco` delivered with what `source` delivered: every vertex matches
/// one of the source's within the quantisation of gltf-pipeline's defaults (positions 11
/// bits of the largest extent, times the instance's scale of 2; normals 8 bits; UVs 10
/// bits; colours 8 bits), and the triangles, mapped through that match, are the
/// source's with the same winding.
fn assert_like_source(
    name: &str,
    source: &(ImportReport, Collect),
    draco: &(ImportReport, Collect),
) {
    let (sr, s) = source;
    let (dr, d) = draco;
    assert_eq!(d.headers, s.headers, "{name}: header");
    assert_eq!(dr.triangles, sr.triangles, "{name}: triangles");
    assert_eq!(d.vertices.len(), s.vertices.len(), "{name}: vertices");
    assert_eq!(dr.textures.len(), sr.textures.len(), "{name}: textures");
    for (a, b) in dr.textures.iter().zip(&sr.textures) {
        assert_eq!((a.size, a.wrap, a.tint), (b.size, b.wrap, b.tint), "{name}");
    }
    let tol = 2.0 / 2047.0;
    let map: Vec<usize> = d
        .vertices
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let (j, e) = s
                .vertices
                .iter()
                .map(|w| dist(v.position, w.position))
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert!(
                e <= tol,
                "{name}: vertex {i} at {:?} is {e} from the nearest source vertex",
                v.position
            );
            let w = &s.vertices[j];
            let dot: f32 = (0..3).map(|k| v.normal[k] * w.normal[k]).sum();
            assert!(
                v.normal == [0.0; 3] && w.normal == [0.0; 3] || dot > 0.995,
                "{name}: vertex {i}: normal {:?}, source {:?}",
                v.normal,
                w.normal
            );
            assert!(
                (0..2).all(|k| (v.uv[k] - w.uv[k]).abs() <= 2.0 / 1023.0),
                "{name}: vertex {i}: uv {:?}, source {:?}",
                v.uv,
                w.uv
            );
            assert!(
                (0..4).all(|k| v.color[k].abs_diff(w.color[k]) <= 2),
                "{name}: vertex {i}: colour {:?}, source {:?}",
                v.color,
                w.color
            );
            assert_eq!(v.texture, w.texture, "{name}: vertex {i}: texture");
            j
        })
        .collect();
    let identity: Vec<usize> = (0..s.vertices.len()).collect();
    assert_eq!(
        triangles(d, &map),
        triangles(s, &identity),
        "{name}: triangles or their winding differ from the source's"
    );
}

#[test]
fn draco_files_read_like_their_source() {
    let source = read_ok("grid.gltf", &data("grid.gltf"));
    // Two instances (one mirrored) of a 1058-triangle textured grid and a 2-triangle quad.
    assert_eq!(source.0.triangles, 2120);
    assert_eq!(source.0.textures.len(), 1);
    let textured = source.1.vertices.iter().filter(|v| v.texture != NO_TEXTURE);
    assert_eq!(textured.count(), 1152);
    for name in [
        "grid-draco-cl0.gltf",
        "grid-draco-cl5.gltf",
        "grid-draco-cl7.gltf",
        "grid-draco-fallback.gltf",
    ] {
        let draco = read_ok(name, &data(name));
        assert_like_source(name, &source, &draco);
        // The same as a .glb.
        if name != "grid-draco-fallback.gltf" {
            let (glb, streams) = to_glb(&doc(name));
            assert_eq!(streams.len(), 2, "{name}");
            let glb_name = name.replace(".gltf", ".glb");
            assert_like_source(&glb_name, &source, &read_ok(&glb_name, &glb));
        }
    }
}

#[test]
fn draco_primitive_without_normals_gets_none_and_uses_its_material() {
    // The quad (primitive 1) alone: POSITION only, a plain colour material.
    let mut d = doc("grid-draco-cl7.gltf");
    let quad = d["meshes"][0]["primitives"][1].clone();
    d["meshes"][0]["primitives"] = json!([quad]);
    d["scenes"][0]["nodes"] = json!([1]);
    let (r, c) = read_doc("quad.gltf", &d);
    assert_eq!((r.triangles, c.vertices.len()), (2, 4));
    let h = &c.headers[0].attributes;
    assert!(!h.normals && !h.uvs && h.colors && !h.textures, "{h:?}");
    // baseColorFactor [0.2, 0.4, 0.6] in sRGB.
    assert!(
        c.vertices.iter().all(|v| v.color == [124, 170, 203, 255]),
        "{:?}",
        c.vertices[0].color
    );
    // Mirrored in x: x in -1..0.
    assert!(c
        .vertices
        .iter()
        .all(|v| (-1.001..=0.001).contains(&v.position[0])));
}

#[test]
fn a_fallback_is_read_without_decoding_the_stream() {
    let mut d = doc("grid-draco-fallback.gltf");
    // Ruin the streams (buffer 0 holds only them): the fallback still reads.
    let zeros = vec![0u8; buffer(&d, 0).len()];
    d["buffers"][0]["uri"] = json!(b64(&zeros));
    let (r, _) = read_doc("fallback.gltf", &d);
    assert_eq!(r.triangles, 2120);
    // Without the fallback's accessors' views, the ruined stream is read and refused.
    for a in d["accessors"].as_array_mut().unwrap() {
        a.as_object_mut().unwrap().remove("bufferView");
        a.as_object_mut().unwrap().remove("byteOffset");
    }
    let e = err_doc("fallback.gltf", &d);
    assert!(
        e.contains("mesh 0 primitive 0 (KHR_draco_mesh_compression, bufferView 0)")
            && e.contains("the Draco stream does not decode"),
        "{e}"
    );
}

#[test]
fn attributes_outside_the_stream_come_from_their_accessors() {
    let mut d = doc("grid-draco-cl7.gltf");
    let prim = &mut d["meshes"][0]["primitives"][0];
    prim["extensions"]["KHR_draco_mesh_compression"]["attributes"]
        .as_object_mut()
        .unwrap()
        .remove("COLOR_0");
    let color = prim["attributes"]["COLOR_0"].as_u64().unwrap() as usize;
    // 576 opaque reds in a buffer of their own.
    let red: Vec<u8> = (0..576)
        .flat_map(|_| [1f32, 0.0, 0.0, 1.0])
        .flat_map(f32::to_le_bytes)
        .collect();
    d["buffers"]
        .as_array_mut()
        .unwrap()
        .push(json!({"byteLength": red.len(), "uri": b64(&red)}));
    let b = d["buffers"].as_array().unwrap().len() - 1;
    d["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({"buffer": b, "byteLength": red.len()}));
    let v = d["bufferViews"].as_array().unwrap().len() - 1;
    d["accessors"][color]["bufferView"] = json!(v);
    let (r, c) = read_doc("mixed.gltf", &d);
    assert_eq!(r.triangles, 2120);
    // Red times the base colour factor [1, 0.5, 1]: the grid's vertices are red.
    let red = c
        .vertices
        .iter()
        .filter(|v| v.color == [255, 0, 0, 255])
        .count();
    assert_eq!(red, 1152);
}

#[test]
fn bad_draco_primitives_are_one_error_naming_them() {
    let at = "mesh 0 primitive 0 (KHR_draco_mesh_compression, bufferView 0)";
    let base = doc("grid-draco-cl7.gltf");
    // A stream of zeros.
    let mut d = base.clone();
    let mut bin = buffer(&d, 0);
    let len = d["bufferViews"][0]["byteLength"].as_u64().unwrap() as usize;
    bin[..len].fill(0);
    d["buffers"][0]["uri"] = json!(b64(&bin));
    let e = err_doc("zeros.gltf", &d);
    assert!(
        e.contains(at) && e.contains("the Draco stream does not decode"),
        "{e}"
    );
    // The stream cut short.
    let mut d = base.clone();
    d["bufferViews"][0]["byteLength"] = json!(600);
    let e = err_doc("short.gltf", &d);
    assert!(e.contains(at) && e.contains("does not decode"), "{e}");
    // The POSITION accessor's count is not the decoded point count.
    let mut d = base.clone();
    d["accessors"][1]["count"] = json!(575);
    let e = err_doc("count.gltf", &d);
    assert!(
        e.contains(at) && e.contains("decodes 576 points, its POSITION accessor 1 says 575"),
        "{e}"
    );
    // An attribute id the stream does not have.
    let mut d = base.clone();
    d["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["attributes"]
        ["NORMAL"] = json!(9);
    let e = err_doc("id.gltf", &d);
    assert!(
        e.contains(at) && e.contains("no attribute with id 9 (mapped to NORMAL)"),
        "{e}"
    );
    // An accessor type that is not the Draco attribute's.
    let mut d = base.clone();
    d["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["attributes"]
        ["COLOR_0"] = json!(1);
    d["accessors"][4]["type"] = json!("VEC4");
    let e = err_doc("type.gltf", &d);
    assert!(
        e.contains("accessor 4 (COLOR_0 of mesh 0 primitive 0, from KHR_draco_mesh_compression)")
            && e.contains("has type VEC4, its Draco attribute has 3 components"),
        "{e}"
    );
    // A malformed extension.
    let mut d = base.clone();
    d["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]
        .as_object_mut()
        .unwrap()
        .remove("bufferView");
    let e = err_doc("ext.gltf", &d);
    assert!(
        e.contains("mesh 0 primitive 0: KHR_draco_mesh_compression: 'bufferView' is missing"),
        "{e}"
    );
    // A buffer view that does not exist.
    let mut d = base;
    d["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"] =
        json!(99);
    let e = err_doc("view.gltf", &d);
    assert!(
        e.contains("bufferView 99") && e.contains("does not exist"),
        "{e}"
    );
}

/// Flip bits and overwrite bytes of the Draco streams of `glb` (in `streams`), `n`
/// times, through the fuzz target: never a panic (the target checks the visitor contract
/// and that errors are one line), and every error names a Draco primitive.
fn flip_streams(glb: &[u8], streams: &[Range<usize>], n: usize, seed: u64) -> (usize, usize) {
    // testkit's xorshift64*: the same flips on every run.
    let mut rng = tessera_testkit::Rng(seed | 1);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..n {
        let mut g = glb.to_vec();
        let s = &streams[rng.next_u64() as usize % streams.len()];
        for _ in 0..1 + rng.next_u64() % 8 {
            let r = rng.next_u64();
            // Half of the changes in the first 64 bytes: headers and counts.
            let span = if r & 1 == 0 { s.len().min(64) } else { s.len() };
            let i = s.start + (r >> 8) as usize % span;
            if r & 2 == 0 {
                g[i] ^= 1 << ((r >> 4) & 7);
            } else {
                g[i] = (r >> 32) as u8;
            }
        }
        match fuzz_gltf(&g) {
            Ok(_) => ok += 1,
            Err(e) => {
                let e = e.to_string();
                assert!(
                    e.contains("mesh 0 primitive") && e.contains("KHR_draco_mesh_compression"),
                    "a damaged stream's error does not name its primitive: {e}"
                );
                err += 1;
            }
        }
    }
    (ok, err)
}

#[test]
fn flipped_bytes_of_draco_streams_are_errors_not_panics() {
    for (name, seed) in [("grid-draco-cl0.gltf", 3), ("grid-draco-cl7.gltf", 5)] {
        let (glb, streams) = to_glb(&doc(name));
        assert!(fuzz_gltf(&glb).is_ok(), "{name}");
        let (ok, err) = flip_streams(&glb, &streams, 1500, seed);
        eprintln!("{name}: 1500 flipped streams: {ok} read, {err} refused");
        assert!(err > 0, "{name}: no flipped stream was refused");
    }
}

/// A Draco stream written by `draco-core`'s encoder: a grid with `Uint8` normalised
/// colours, coded with EdgeBreaker's valence traversal.
fn valence_stream() -> (Vec<u8>, Vec<[f32; 3]>, Vec<[u8; 4]>) {
    use draco_core::{
        DataType, EncoderBuffer, EncoderOptions, FaceIndex, GeometryAttributeType, Mesh,
        MeshEncoder, PointAttribute,
    };
    // Over the 1000 faces below which Draco's encoders never use the valence traversal.
    const SIDE: usize = 24;
    let n = SIDE * SIDE;
    let mut pos = PointAttribute::new();
    pos.init(
        GeometryAttributeType::Position,
        3,
        DataType::Float32,
        false,
        n,
    );
    let mut col = PointAttribute::new();
    col.init(GeometryAttributeType::Color, 4, DataType::Uint8, true, n);
    let (mut ps, mut cs) = (Vec::new(), Vec::new());
    for i in 0..n {
        let (x, y) = ((i % SIDE) as f32, (i / SIDE) as f32);
        let p = [x, y, (x * 0.7).sin() * (y * 0.4).cos()];
        let c = [if x < 12.0 { 255 } else { 0 }, 0, 255, 128];
        let bytes: Vec<u8> = p.iter().flat_map(|v| v.to_le_bytes()).collect();
        pos.buffer_mut().write(i * 12, &bytes);
        col.buffer_mut().write(i * 4, &c);
        ps.push(p);
        cs.push(c);
    }
    let mut mesh = Mesh::new();
    mesh.add_attribute(pos);
    mesh.add_attribute(col);
    let s = SIDE as u32;
    mesh.set_num_faces((SIDE - 1) * (SIDE - 1) * 2);
    let mut f = 0;
    for y in 0..s - 1 {
        for x in 0..s - 1 {
            let a = y * s + x;
            mesh.set_face(FaceIndex(f), [a.into(), (a + 1).into(), (a + s + 1).into()]);
            mesh.set_face(
                FaceIndex(f + 1),
                [a.into(), (a + s + 1).into(), (a + s).into()],
            );
            f += 2;
        }
    }
    let mut options = EncoderOptions::new();
    options.set_compression_level(7);
    options.set_attribute_quantization(0, 14);
    let mut encoder = MeshEncoder::new();
    encoder.set_mesh(mesh);
    let mut out = EncoderBuffer::new();
    encoder.encode(&options, &mut out).unwrap();
    (out.data().to_vec(), ps, cs)
}

#[test]
fn a_valence_stream_with_integer_colours_reads() {
    let (stream, ps, cs) = valence_stream();
    // "DRACO", version, mesh, EdgeBreaker, flags, then the traversal: 2 is valence.
    assert_eq!((&stream[..5], stream[8], stream[11]), (&b"DRACO"[..], 1, 2));
    let d = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_draco_mesh_compression"],
        "extensionsRequired": ["KHR_draco_mesh_compression"],
        "buffers": [{"byteLength": stream.len(), "uri": b64(&stream)}],
        "bufferViews": [{"buffer": 0, "byteLength": stream.len()}],
        "accessors": [
            {"componentType": 5126, "type": "VEC3", "count": ps.len()},
            {"componentType": 5121, "normalized": true, "type": "VEC4", "count": ps.len()},
            {"componentType": 5125, "type": "SCALAR", "count": 1058 * 3},
        ],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "COLOR_0": 1}, "indices": 2,
            "extensions": {"KHR_draco_mesh_compression": {
                "bufferView": 0, "attributes": {"POSITION": 0, "COLOR_0": 1}}}}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    });
    let (r, c) = read_doc("valence.gltf", &d);
    assert_eq!((r.triangles, c.vertices.len()), (1058, 576));
    for v in &c.vertices {
        let (k, e) = ps
            .iter()
            .map(|p| dist(*p, v.position))
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert!(e < 12.0 / 16383.0, "{:?}", v.position);
        // Normalised bytes, encoded to sRGB: 0 and 255 stay, alpha is linear.
        assert_eq!(v.color, cs[k], "at {:?}", v.position);
    }
}

#[test]
fn draco_required_without_draco_primitives_reads() {
    // `extensionsRequired` may name Draco while a primitive is plain.
    let mut d = doc("grid.gltf");
    d["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    d["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let (r, _) = read_doc("plain.gltf", &d);
    assert_eq!(r.triangles, 2120);
}
