//! PLY importer and writer tests: every encoding, every attribute, every error.

mod common;

use common::*;
use proptest::prelude::*;
use tessera_mesh::{
    read_mesh, Attributes, MeshError, MeshHeader, MeshVisitor, PlyWriter, PlyWriterOptions, Vertex,
};

const ASCII_QUAD: &str = "ply
format ascii 1.0
comment a unit square and a triangle
element vertex 5
property float x
property float y
property float z
element face 2
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
4 0 1 2 3
3 0 1 4
";

#[test]
fn ascii_quad_is_fan_triangulated() {
    let (r, c) = read_ok("q.ply", ASCII_QUAD.as_bytes());
    assert_eq!(c.headers.len(), 1);
    assert_eq!(
        c.headers[0],
        MeshHeader {
            attributes: Attributes::default(),
            vertex_count: Some(5),
            face_count: Some(2)
        }
    );
    assert_eq!(c.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    assert_eq!(r.vertices, 5);
    assert_eq!(r.triangles, 3);
    assert_eq!(r.polygons_triangulated, 1);
    assert_eq!(pos(&c)[2], [1.0, 1.0, 0.0]);
    assert_eq!(c.vertices[0].color, [255; 4]);
}

#[test]
fn crlf_header_and_vertex_index_name() {
    let text = ASCII_QUAD
        .replace('\n', "\r\n")
        .replace("vertex_indices", "vertex_index");
    let (r, _) = read_ok("crlf.ply", text.as_bytes());
    assert_eq!(r.triangles, 3);
}

#[test]
fn ascii_attributes_float_colors_and_uv_aliases() {
    let text = "ply
format ascii 1.0
element vertex 3
property double x
property double y
property double z
property float nx
property float ny
property float nz
property float diffuse_red
property float diffuse_green
property float diffuse_blue
property float s
property float t
element face 1
property list uchar uint vertex_indices
end_header
0 0 0 0 0 1 1 0.5 0 0.25 0.75
1 0 0 0 0 1 0 1 0 1 0
0 1 0 0 0 1 2 -1 0 0 1
3 0 1 2
";
    let (_, c) = read_ok("attr.ply", text.as_bytes());
    let a = c.headers[0].attributes;
    assert_eq!(
        a,
        Attributes {
            normals: true,
            colors: true,
            uvs: true,
            textures: false,
        }
    );
    assert_eq!(c.vertices[0].color, [255, 128, 0, 255]);
    assert_eq!(c.vertices[2].color, [255, 0, 0, 255], "clamped");
    assert_eq!(c.vertices[0].uv, [0.25, 0.75]);
    assert_eq!(c.vertices[1].normal, [0.0, 0.0, 1.0]);
}

#[test]
fn incomplete_attribute_groups_are_ignored() {
    let text = "ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
property float nx
property float ny
property uchar red
property float u
element face 1
property list uchar uint vertex_indices
end_header
0 0 0 1 1 9 1
1 0 0 1 1 9 1
0 1 0 1 1 9 1
3 0 1 2
";
    let (_, c) = read_ok("partial.ply", text.as_bytes());
    assert_eq!(c.headers[0].attributes, Attributes::default());
    assert_eq!(
        c.vertices[0],
        Vertex {
            position: [0.0; 3],
            ..Vertex::default()
        }
    );
}

/// Binary header + body helper.
fn binary(format: &str, header_rest: &str, body: &[u8]) -> Vec<u8> {
    let mut out = format!("ply\nformat {format} 1.0\n{header_rest}end_header\n").into_bytes();
    out.extend_from_slice(body);
    out
}

const LE_RGBA_HEADER: &str = "element vertex 3
property float x
property float y
property float z
property float nx
property float ny
property float nz
property uchar red
property uchar green
property uchar blue
property uchar alpha
element face 1
property list uchar int vertex_indices
";

fn le_rgba_body() -> Vec<u8> {
    let mut b = Vec::new();
    for (i, p) in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        .iter()
        .enumerate()
    {
        f32le(&mut b, p);
        f32le(&mut b, &[0.0, 0.0, 1.0]);
        b.extend_from_slice(&[10 * i as u8, 20, 30, 40]);
    }
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

#[test]
fn binary_le_normals_and_rgba() {
    let (r, c) = read_ok(
        "le.ply",
        &binary("binary_little_endian", LE_RGBA_HEADER, &le_rgba_body()),
    );
    assert_eq!(
        c.headers[0].attributes,
        Attributes {
            normals: true,
            colors: true,
            uvs: false,
            textures: false,
        }
    );
    assert_eq!(c.vertices[1].color, [10, 20, 30, 40]);
    assert_eq!(c.vertices[2].position, [0.0, 1.0, 0.0]);
    assert_eq!(c.vertices[2].normal, [0.0, 0.0, 1.0]);
    assert_eq!(c.triangles, vec![[0, 1, 2]]);
    assert_eq!(r.triangles, 1);
}

#[test]
fn binary_truncated_in_vertices_and_faces() {
    let file = binary("binary_little_endian", LE_RGBA_HEADER, &le_rgba_body());
    let body_start = file.len() - le_rgba_body().len();
    let e = read_err("tv.ply", &file[..body_start + 30]);
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
    assert!(e.to_string().contains("vertex 1 of 3"), "{e}");
    let e = read_err("tf.ply", &file[..file.len() - 2]);
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
    assert!(e.to_string().contains("face 0 of 1"), "{e}");
    let e = read_err("th.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n");
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
}

#[test]
fn ascii_truncated() {
    let cut = ASCII_QUAD.rsplit_once("3 0 1 4").unwrap().0;
    let e = read_err("ta.ply", cut.as_bytes());
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
}

#[test]
fn big_endian_with_doubles_short_counts_and_skipped_stuff() {
    // Vertex has a list property in the middle, faces carry an extra scalar and list,
    // and two unknown elements sit between and after.
    let header = "element vertex 3
property double x
property list uchar float junk
property double y
property double z
element edge 2
property int vertex1
property int vertex2
element face 2
property uchar flags
property list ushort short vertex_indices
property list uchar float texcoord
element material 1
property list uchar uchar name
";
    let mut b = Vec::new();
    for p in [[0.0f64, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]] {
        b.extend_from_slice(&p[0].to_be_bytes());
        b.push(2);
        f32be(&mut b, &[7.0, 8.0]);
        b.extend_from_slice(&p[1].to_be_bytes());
        b.extend_from_slice(&p[2].to_be_bytes());
    }
    for v in [0i32, 1, 1, 2] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    for face in [[0i16, 1, 2], [2, 1, 0]] {
        b.push(9);
        b.extend_from_slice(&3u16.to_be_bytes());
        for i in face {
            b.extend_from_slice(&i.to_be_bytes());
        }
        b.push(1);
        f32be(&mut b, &[0.5]);
    }
    b.extend_from_slice(&[3, b'a', b'b', b'c']);
    let (r, c) = read_ok("be.ply", &binary("binary_big_endian", header, &b));
    assert_eq!(
        pos(&c),
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]
    );
    assert_eq!(c.triangles, vec![[0, 1, 2], [2, 1, 0]]);
    assert_eq!(r.ignored_statements, 3, "2 edges + 1 material");
}

#[test]
fn list_properties_skipped_in_ascii() {
    let text = "ply
format ascii 1.0
element vertex 3
property float x
property list uchar int extra
property float y
property float z
element face 1
property list uchar int vertex_indices
property list int float texcoord
element edge 1
property list uchar int verts
end_header
0 2 5 6 0 0
1 0 0 0
0 3 1 2 3 1 0
3 0 1 2 6 0 0 1 0 0 1
2 0 1
";
    let (r, c) = read_ok("skip.ply", text.as_bytes());
    assert_eq!(
        pos(&c),
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    );
    assert_eq!(r.triangles, 1);
    assert_eq!(r.ignored_statements, 1);
}

#[test]
fn degenerate_and_short_faces_are_counted() {
    let text = "ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
element face 5
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
1 1 0
3 0 1 2
3 0 0 2
4 0 1 2 1
2 0 1
0
";
    let (r, c) = read_ok("deg.ply", text.as_bytes());
    assert_eq!(c.triangles, vec![[0, 1, 2]]);
    assert_eq!(r.degenerate_faces_skipped, 2);
    assert_eq!(r.short_faces_skipped, 2);
}

#[test]
fn header_errors() {
    let e = read_err("magic.ply", b"plx\nformat ascii 1.0\nend_header\n");
    malformed_with(&e, "magic");
    let e = read_err("empty-file.ply", b"");
    malformed_with(&e, "magic");
    let e = read_err(
        "fmt.ply",
        b"ply\nformat binary_middle_endian 1.0\nend_header\n",
    );
    malformed_with(&e, "binary_middle_endian");
    let e = read_err("nofmt.ply", b"ply\nelement vertex 0\nend_header\n");
    malformed_with(&e, "format");
    let e = read_err(
        "type.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
    );
    malformed_with(&e, "float128");
    malformed_with(&e, "line 4");
    let e = read_err(
        "noz.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
          element face 0\nproperty list uchar int vertex_indices\nend_header\n",
    );
    malformed_with(&e, "'z'");
    let e = read_err(
        "noface.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
          property float z\nend_header\n0 0 0\n",
    );
    malformed_with(&e, "face");
    let e = read_err(
        "noidx.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
          property float z\nelement face 1\nproperty list uchar int corners\nend_header\n",
    );
    malformed_with(&e, "vertex_indices");
    let e = read_err(
        "order.ply",
        b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
          element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    );
    malformed_with(&e, "before");
    let e = read_err(
        "prop.ply",
        b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
    );
    malformed_with(&e, "before any element");
    let e = read_err(
        "count.ply",
        b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n",
    );
    malformed_with(&e, "-3");
}

fn malformed_with(e: &MeshError, needle: &str) {
    assert!(matches!(e, MeshError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains(needle), "{e}");
}

#[test]
fn too_many_vertices() {
    let e = read_err(
        "huge.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4294967296\nproperty float x\n\
          property float y\nproperty float z\nelement face 0\n\
          property list uchar int vertex_indices\nend_header\n",
    );
    assert!(matches!(e, MeshError::TooManyVertices { .. }), "{e}");
}

#[test]
fn index_out_of_range() {
    let text = ASCII_QUAD.replace("3 0 1 4", "3 0 1 5");
    let e = read_err("oor.ply", text.as_bytes());
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                index: 5,
                vertex_count: 5,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("face 1"), "{e}");
    let text = ASCII_QUAD.replace("3 0 1 4", "3 0 -1 4");
    let e = read_err("neg.ply", text.as_bytes());
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: -1, .. }),
        "{e}"
    );
    // Binary, fast path, negative int.
    let mut body = le_rgba_body();
    let n = body.len();
    body[n - 4..].copy_from_slice(&(-7i32).to_le_bytes());
    let e = read_err(
        "oorb.ply",
        &binary("binary_little_endian", LE_RGBA_HEADER, &body),
    );
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: -7, .. }),
        "{e}"
    );
}

/// Issue 14, failure 7: NaN texture coordinates were accepted and written back out.
#[test]
fn non_finite_texture_coordinates_are_errors() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                property float z\nproperty float u\nproperty float v\nelement face 1\n\
                property list uchar int vertex_indices\nend_header\n\
                0 0 0 0 0\n1 0 0 1 0\n0 1 0 nan 1\n3 0 1 2\n";
    let e = read_err("nan-uv.ply", text.as_bytes());
    assert!(matches!(e, MeshError::NonFiniteUv { index: 2, .. }), "{e}");
    let ok = text.replace("nan", "0.5");
    read_ok("uv.ply", ok.as_bytes());
}

#[test]
fn non_finite_coordinates_are_errors() {
    let text = ASCII_QUAD.replace("1 1 0\n", "1 nan 0\n");
    let e = read_err("nan.ply", text.as_bytes());
    assert!(matches!(e, MeshError::NonFinite { vertex: 2, .. }), "{e}");
    let mut body = le_rgba_body();
    body[4..8].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let e = read_err(
        "inf.ply",
        &binary("binary_little_endian", LE_RGBA_HEADER, &body),
    );
    assert!(matches!(e, MeshError::NonFinite { vertex: 0, .. }), "{e}");
}

#[test]
fn bad_ascii_number() {
    let text = ASCII_QUAD.replace("1 1 0\n", "1 x1 0\n");
    let e = read_err("num.ply", text.as_bytes());
    assert!(matches!(e, MeshError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains("line 13"), "{e}");
}

#[test]
fn empty_mesh_is_an_error() {
    let text = ASCII_QUAD.replace("element face 2", "element face 0");
    let e = read_err("empty.ply", text.as_bytes());
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
    let text = ASCII_QUAD
        .replace("3 0 1 4", "3 0 1 1")
        .replace("4 0 1 2 3", "2 0 1");
    let e = read_err("alldeg.ply", text.as_bytes());
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
}

#[test]
fn unreadable_path_and_unknown_extension() {
    let mut c = Collect::default();
    let e = read_mesh(std::path::Path::new("/nonexistent/dir/x.ply"), &mut c).unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }), "{e}");
    assert!(e.to_string().starts_with("/nonexistent/dir/x.ply: "), "{e}");
    let e = read_err("x.xyz", b"whatever");
    assert!(matches!(e, MeshError::UnknownFormat { .. }), "{e}");
}

#[test]
fn visitor_errors_pass_through() {
    struct Fail;
    impl MeshVisitor for Fail {
        fn header(&mut self, _: &MeshHeader) -> Result<(), MeshError> {
            Ok(())
        }
        fn vertex(&mut self, _: &Vertex) -> Result<(), MeshError> {
            Ok(())
        }
        fn triangle(&mut self, _: [u32; 3]) -> Result<(), MeshError> {
            Err(MeshError::Visitor("disk full".into()))
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.ply");
    std::fs::write(&path, ASCII_QUAD).unwrap();
    let e = read_mesh(&path, &mut Fail).unwrap_err();
    assert!(
        matches!(&e, MeshError::Visitor(m) if m == "disk full"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------
// Writer round trips
// ---------------------------------------------------------------------------------------

fn write_and_read(
    attributes: Attributes,
    vertices: &[Vertex],
    triangles: &[[u32; 3]],
) -> (Collect, tessera_mesh::ImportReport) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rt.ply");
    let opts = PlyWriterOptions {
        attributes,
        vertex_count: vertices.len() as u64,
        face_count: triangles.len() as u64,
        comments: vec!["round trip".into()],
    };
    let mut w = PlyWriter::create(&path, &opts).unwrap();
    for v in vertices {
        w.write_vertex(v).unwrap();
    }
    for t in triangles {
        w.write_triangle(*t).unwrap();
    }
    w.finish().unwrap();
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap();
    (c, r)
}

/// What a reader gives back for `v` when only `a` is stored.
fn masked(v: &Vertex, a: Attributes) -> Vertex {
    let d = Vertex::default();
    Vertex {
        position: v.position,
        normal: if a.normals { v.normal } else { d.normal },
        color: if a.colors { v.color } else { d.color },
        uv: if a.uvs { v.uv } else { d.uv },
        // Writers ignore textures.
        texture: d.texture,
    }
}

#[test]
fn writer_round_trip_all_attribute_combinations() {
    let vertices: Vec<Vertex> = (0..4)
        .map(|i| {
            let f = i as f32;
            Vertex {
                position: [f, -f * 0.5, 1e-7 * f],
                normal: [0.1 * f, 0.2, -0.3],
                color: [i as u8, 200, 7, 100 + i as u8],
                uv: [0.25 * f, 1.0 - 0.25 * f],
                texture: i,
            }
        })
        .collect();
    let triangles = [[0, 1, 2], [2, 3, 0], [3, 1, 0]];
    for bits in 0..8 {
        let a = Attributes {
            normals: bits & 1 != 0,
            colors: bits & 2 != 0,
            uvs: bits & 4 != 0,
            textures: false,
        };
        let (c, r) = write_and_read(a, &vertices, &triangles);
        assert_eq!(c.headers[0].attributes, a);
        assert_eq!(c.headers[0].vertex_count, Some(4));
        assert_eq!(c.headers[0].face_count, Some(3));
        let want: Vec<Vertex> = vertices.iter().map(|v| masked(v, a)).collect();
        assert_eq!(c.vertices, want);
        assert_eq!(c.triangles, triangles);
        assert_eq!(r.triangles, 3);
    }
}

fn arb_mesh() -> impl Strategy<Value = (Attributes, Vec<Vertex>, Vec<[u32; 3]>)> {
    let vertex = (
        prop::array::uniform3(-1e6f32..1e6),
        prop::array::uniform3(-1f32..1.0),
        prop::array::uniform4(any::<u8>()),
        prop::array::uniform2(-4f32..4.0),
    )
        .prop_map(|(position, normal, color, uv)| Vertex {
            position,
            normal,
            color,
            uv,
            texture: tessera_mesh::NO_TEXTURE,
        });
    let attrs = (any::<bool>(), any::<bool>(), any::<bool>()).prop_map(|(normals, colors, uvs)| {
        Attributes {
            normals,
            colors,
            uvs,
            textures: false,
        }
    });
    (attrs, prop::collection::vec(vertex, 3..40)).prop_flat_map(|(a, vs)| {
        let n = vs.len() as u32;
        let tri = prop::array::uniform3(0..n).prop_filter("non-degenerate", |t| {
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2]
        });
        (Just(a), Just(vs), prop::collection::vec(tri, 1..60))
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn random_meshes_round_trip_exactly((a, vs, ts) in arb_mesh()) {
        let (c, r) = write_and_read(a, &vs, &ts);
        let want: Vec<Vertex> = vs.iter().map(|v| masked(v, a)).collect();
        prop_assert_eq!(c.vertices, want);
        prop_assert_eq!(c.triangles, ts.clone());
        prop_assert_eq!(r.triangles, ts.len() as u64);
        prop_assert_eq!(r.degenerate_faces_skipped, 0);
    }
}

// ---------------------------------------------------------------------------------------
// Real data
// ---------------------------------------------------------------------------------------

#[test]
fn real_gargo_color_ply() {
    let Some(path) = shared_data("gargo-color.ply") else {
        return;
    };
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap();
    assert_eq!(r.triangles, 50_000);
    assert_eq!(c.triangles.len(), 50_000);
    let a = c.headers[0].attributes;
    assert!(a.normals && a.colors, "{a:?}");
    assert_eq!(r.vertices as usize, c.vertices.len());
}

/// Parse speed of a generated binary PLY (run with `--ignored --nocapture`; the number
/// is only meaningful in an optimized build).
#[test]
#[ignore]
fn binary_parse_speed() {
    struct Count(u64, u64);
    impl MeshVisitor for Count {
        fn header(&mut self, _: &MeshHeader) -> Result<(), MeshError> {
            Ok(())
        }
        fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
            self.0 += v.position[0].to_bits() as u64 & 1;
            Ok(())
        }
        fn triangle(&mut self, t: [u32; 3]) -> Result<(), MeshError> {
            self.1 += u64::from(t[0] & 1);
            Ok(())
        }
    }
    let side: u32 = 1500; // ~4.5M triangles, ~85 MB
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.ply");
    let opts = PlyWriterOptions {
        attributes: Attributes::default(),
        vertex_count: u64::from(side * side),
        face_count: u64::from(2 * (side - 1) * (side - 1)),
        comments: vec![],
    };
    let mut w = PlyWriter::create(&path, &opts).unwrap();
    for y in 0..side {
        for x in 0..side {
            w.write_vertex(&Vertex {
                position: [x as f32, y as f32, 0.0],
                ..Vertex::default()
            })
            .unwrap();
        }
    }
    for y in 0..side - 1 {
        for x in 0..side - 1 {
            let i = y * side + x;
            w.write_triangle([i, i + 1, i + side]).unwrap();
            w.write_triangle([i + 1, i + side + 1, i + side]).unwrap();
        }
    }
    w.finish().unwrap();
    let bytes = std::fs::metadata(&path).unwrap().len();
    let mut best = f64::MAX;
    for _ in 0..3 {
        let t = std::time::Instant::now();
        let r = read_mesh(&path, &mut Count(0, 0)).unwrap();
        best = best.min(t.elapsed().as_secs_f64());
        assert_eq!(r.triangles, opts.face_count);
    }
    eprintln!(
        "{} MB in {:.3} s: {:.0} MB/s, {:.1} M triangles/s",
        bytes / 1_000_000,
        best,
        bytes as f64 / best / 1e6,
        opts.face_count as f64 / best / 1e6
    );
}

/// Issue 14, failure 7: faces or garbage after the declared elements were ignored
/// silently, and a file cut inside its last number read as valid. Both are now in the
/// report (and warned about); complete files report neither.
#[test]
fn trailing_data_and_a_cut_last_line_are_reported() {
    let (r, _) = read_ok("quad.ply", ASCII_QUAD.as_bytes());
    assert_eq!(
        (r.trailing_bytes_ignored, r.unterminated_last_line),
        (0, false)
    );
    let extra = format!("{ASCII_QUAD}3 0 1 2\n");
    let (r, _) = read_ok("extra.ply", extra.as_bytes());
    assert_eq!(r.trailing_bytes_ignored, 4, "{r:?}");
    let cut = ASCII_QUAD.trim_end();
    let (r, _) = read_ok("cut.ply", cut.as_bytes());
    assert!(
        r.unterminated_last_line && r.trailing_bytes_ignored == 0,
        "{r:?}"
    );
    let mut body = le_rgba_body();
    body.extend_from_slice(&[1, 2, 3]);
    let (r, _) = read_ok(
        "extra-le.ply",
        &binary("binary_little_endian", LE_RGBA_HEADER, &body),
    );
    assert_eq!(r.trailing_bytes_ignored, 3, "{r:?}");
    let (r, _) = read_ok(
        "le.ply",
        &binary("binary_little_endian", LE_RGBA_HEADER, &le_rgba_body()),
    );
    assert_eq!(r.trailing_bytes_ignored, 0, "{r:?}");
}

/// Issue 14: a PLY of triangle strips (`element tristrips`, -1 restarting a strip, as
/// the Stanford Igea scan ships) was refused as a point cloud; it reads as triangles
/// with alternating winding, strip-turning degenerates dropped, in ASCII and binary.
#[test]
fn triangle_strips_read_as_triangles() {
    let head = "element vertex 5\nproperty float x\nproperty float y\nproperty float z\n\
                element tristrips 1\nproperty list int int vertex_indices\n";
    let verts = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 1 0\n";
    let text = format!("ply\nformat ascii 1.0\n{head}end_header\n{verts}8 0 1 2 3 -1 1 3 4\n");
    let (r, c) = read_ok("strips.ply", text.as_bytes());
    // 0 1 2 3 -> (0,1,2), (2,1,3); restart; 1 3 4 -> (1,3,4).
    assert_eq!(c.triangles, vec![[0, 1, 2], [2, 1, 3], [1, 3, 4]]);
    assert_eq!(r.triangles, 3);
    assert_eq!(c.headers[0].face_count, None);
    // A turning degenerate (2 repeated) is dropped, the parity kept: triangle 3 of
    // the strip is odd, so (2, 3, 4) is drawn as (3, 2, 4).
    let text = format!("ply\nformat ascii 1.0\n{head}end_header\n{verts}6 0 1 2 2 3 4\n");
    let (r, c) = read_ok("turn.ply", text.as_bytes());
    assert_eq!(c.triangles, vec![[0, 1, 2], [3, 2, 4]]);
    assert_eq!(r.degenerate_faces_skipped, 0);
    // Binary little endian, the same strip.
    let mut body = Vec::new();
    for v in [
        [0f32, 0., 0.],
        [1., 0., 0.],
        [0., 1., 0.],
        [1., 1., 0.],
        [2., 1., 0.],
    ] {
        for x in v {
            body.extend_from_slice(&x.to_le_bytes());
        }
    }
    body.extend_from_slice(&8i32.to_le_bytes());
    for i in [0i32, 1, 2, 3, -1, 1, 3, 4] {
        body.extend_from_slice(&i.to_le_bytes());
    }
    let (_, c) = read_ok(
        "strips-le.ply",
        &binary("binary_little_endian", head, &body),
    );
    assert_eq!(c.triangles, vec![[0, 1, 2], [2, 1, 3], [1, 3, 4]]);
    // An index out of range is an error naming it.
    let bad = format!("ply\nformat ascii 1.0\n{head}end_header\n{verts}3 0 1 9\n");
    let e = read_err("bad-strip.ply", bad.as_bytes());
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: 9, .. }),
        "{e}"
    );
}
