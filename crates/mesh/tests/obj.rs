//! OBJ importer tests: both streaming modes, every corner syntax, every error.

mod common;

use common::*;
use tessera_mesh::{read_mesh, Attributes, ImageSource, MeshError, Wrap, NO_TEXTURE};

/// What an OBJ with `vt` and `vn` corners and no material declares.
const NORMALS_AND_UVS: Attributes = Attributes {
    normals: true,
    colors: false,
    uvs: true,
    textures: false,
};

#[test]
fn direct_mode_positions_only() {
    let text = "# a quad and a triangle
mtllib x.mtl
o first
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
usemtl red
s off
f 1 2 3 4
g second
v 0 0 1
f -5 -4 -1
l 1 2
vt 0.5 0.5
vn 0 0 1
frobnicate 7
";
    let (r, c) = read_ok("d.obj", text.as_bytes());
    assert_eq!(c.headers[0].attributes, Attributes::default());
    assert_eq!(c.headers[0].vertex_count, None);
    assert_eq!(c.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    assert_eq!(pos(&c)[4], [0.0, 0.0, 1.0]);
    assert_eq!(r.vertices, 5);
    assert_eq!(r.triangles, 3);
    assert_eq!(r.polygons_triangulated, 1);
    // Issue 14, failure 8: the warning names what was ignored. Grouping, smoothing and
    // materials are not counted; the line `l 1 2` is geometry dropped, so it is.
    assert_eq!(r.ignored_statements, 2, "'frobnicate' and the line 'l'");
    let names: Vec<(&str, u64)> = r
        .ignored_by_name
        .iter()
        .map(|(n, &c)| (n.as_str(), c))
        .collect();
    assert_eq!(names, [("frobnicate", 1), ("l", 1)]);
}

#[test]
fn vertex_colours() {
    let text = "v 0 0 0 1 0 0\nv 1 0 0 0 0.5 0\nv 0 1 0 0 0 1\nf 1 2 3\n";
    let (_, c) = read_ok("col.obj", text.as_bytes());
    assert!(c.headers[0].attributes.colors);
    assert_eq!(c.vertices[0].color, [255, 0, 0, 255]);
    assert_eq!(c.vertices[1].color, [0, 128, 0, 255]);
}

#[test]
fn combined_mode_with_uvs_and_normals() {
    let text = "v 0 0 0
v 1 0 0
v 0 1 0
vt 0 0
vt 1 0
vt 0 1
vn 0 0 1
vn 0 0 -1
f 1/1/1 2/2/1 3/3/1
f 3/3/2 2/2/2 1/1/2
f 1/1/1 2/2/1 3/3/1
";
    let (r, c) = read_ok("vtn.obj", text.as_bytes());
    assert_eq!(c.headers[0].attributes, NORMALS_AND_UVS);
    assert_eq!(r.vertices, 6, "two normals per position");
    assert_eq!(c.triangles, vec![[0, 1, 2], [3, 4, 5], [0, 1, 2]]);
    assert_eq!(c.vertices[1].uv, [1.0, 0.0]);
    assert_eq!(c.vertices[3].normal, [0.0, 0.0, -1.0]);
    assert_eq!(c.vertices[3].position, [0.0, 1.0, 0.0]);
}

#[test]
fn all_corner_syntaxes_and_relative_indices() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0.25 0.75\nvn 1 0 0\n\
                f 1//1 2//1 3//1\nf 2/1 4/1 3/1\nf -3/-1/-1 -2 -1\n";
    let (r, c) = read_ok("syn.obj", text.as_bytes());
    assert_eq!(c.headers[0].attributes, NORMALS_AND_UVS);
    assert_eq!(r.triangles, 3);
    // v//vn corners get uv 0, v/vt corners normal 0.
    assert_eq!(c.vertices[0].uv, [0.0, 0.0]);
    assert_eq!(c.vertices[0].normal, [1.0, 0.0, 0.0]);
    assert_eq!(c.vertices[3].uv, [0.25, 0.75]);
    assert_eq!(c.vertices[3].normal, [0.0; 3]);
    let last = c.triangles[2];
    assert_eq!(c.vertices[last[0] as usize].position, [1.0, 0.0, 0.0]);
    assert_eq!(c.vertices[last[2] as usize].position, [1.0, 1.0, 0.0]);
}

#[test]
fn several_objects_share_global_indices() {
    let text = "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\no b\nv 5 0 0\nv 6 0 0\nv 5 1 0\nf 4 5 6\nf -3 -2 -1\n";
    let (r, c) = read_ok("multi.obj", text.as_bytes());
    assert_eq!(c.triangles, vec![[0, 1, 2], [3, 4, 5], [3, 4, 5]]);
    assert_eq!(r.vertices, 6);
}

#[test]
fn degenerate_short_crlf_continuation_and_comments() {
    let text = "v 0 0 0\r\nv 1 0 0 # trailing comment\r\nv 0 1 0\r\nf 1 2 \\\r\n 3\r\nf 1 1 2\r\nf 1 2\r\n";
    let (r, c) = read_ok("misc.obj", text.as_bytes());
    assert_eq!(c.triangles, vec![[0, 1, 2]]);
    assert_eq!(r.degenerate_faces_skipped, 1);
    assert_eq!(r.short_faces_skipped, 1);
}

#[test]
fn index_errors_name_the_line() {
    let e = read_err("oor.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                index: 4,
                vertex_count: 3,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("line 4"), "{e}");
    let e = read_err("zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: 0, .. }),
        "{e}"
    );
    let e = read_err("neg.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n");
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: -4, .. }),
        "{e}"
    );
    // Faces may only reference vertices defined before them.
    let e = read_err("fwd.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n");
    assert!(
        matches!(e, MeshError::IndexOutOfRange { index: 3, .. }),
        "{e}"
    );
    let e = read_err(
        "vt.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n",
    );
    assert!(e.to_string().contains("texture coordinate index 2"), "{e}");
    assert!(e.to_string().contains("line 5"), "{e}");
}

#[test]
fn malformed_lines() {
    let e = read_err("num.obj", b"v 0 0 0\nv 1 zero 0\n");
    assert!(matches!(e, MeshError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains("line 2"), "{e}");
    let e = read_err("short.obj", b"v 0 0\n");
    assert!(e.to_string().contains("at least 3"), "{e}");
    let e = read_err("corner.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/4/5/6\n");
    assert!(e.to_string().contains("bad face corner"), "{e}");
    let e = read_err("word.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
    assert!(
        e.to_string().contains("vertex index 'x' is not an integer"),
        "{e}"
    );
}

#[test]
fn nan_and_empty() {
    let e = read_err("nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    assert!(matches!(e, MeshError::NonFinite { vertex: 1, .. }), "{e}");
    let e = read_err("inf.obj", b"v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n");
    assert!(matches!(e, MeshError::NonFinite { vertex: 2, .. }), "{e}");
    // Issue 14, failure 7: NaN texture coordinates were kept and written back out.
    let e = read_err(
        "nan-vt.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt nan 0.5\nf 1/1 2/2 3/1\n",
    );
    assert!(matches!(e, MeshError::NonFiniteUv { index: 1, .. }), "{e}");
    assert!(e.to_string().contains("texture coordinate 1"), "{e}");
    let e = read_err("empty.obj", b"# nothing\nv 0 0 0\n");
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
    let e = read_err("zero-bytes.obj", b"");
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
}

#[test]
fn unreadable_obj() {
    let mut c = Collect::default();
    let e = read_mesh(std::path::Path::new("/nonexistent/m.obj"), &mut c).unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }), "{e}");
}

fn check_real(name: &str, triangles: u64) {
    let Some(path) = shared_data(name) else {
        return;
    };
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap();
    eprintln!("{name}: {r:?} {:?}", c.headers[0]);
    assert_eq!(r.triangles, triangles);
    assert_eq!(r.vertices as usize, c.vertices.len());
}

#[test]
fn real_bunny_obj() {
    check_real("bunny.obj", 69_451);
}

#[test]
fn real_nefertiti_obj() {
    check_real("nefertiti.obj", 99_938);
}

/// Issue 14, failure 6: an OBJ starting with a UTF-8 byte order mark lost its first `v`
/// line and shifted every face by one vertex. Text formats skip the mark.
#[test]
fn utf8_bom_before_the_first_line_is_skipped() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n";
    let (plain_r, plain) = read_ok("plain.obj", text.as_bytes());
    let mut bom = vec![0xEF, 0xBB, 0xBF];
    bom.extend_from_slice(text.as_bytes());
    let (r, c) = read_ok("bom.obj", &bom);
    assert_eq!(r.vertices, 4);
    assert_eq!(r.vertices, plain_r.vertices);
    assert_eq!(c.triangles, plain.triangles);
    assert_eq!(pos(&c), pos(&plain));
    // A PLY header and an ASCII STL too.
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let mut b = vec![0xEF, 0xBB, 0xBF];
    b.extend_from_slice(ply.as_bytes());
    let (r, _) = read_ok("bom.ply", &b);
    assert_eq!((r.vertices, r.triangles), (3, 1));
    let stl = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n";
    let mut b = vec![0xEF, 0xBB, 0xBF];
    b.extend_from_slice(stl.as_bytes());
    let (r, _) = read_ok("bom.stl", &b);
    assert_eq!(r.triangles, 1);
}

/// Issue 14, failure 7: a file cut inside its last number ("f 1 2 3" of "f 1 2 34")
/// reads as valid; the report says the file ends inside its last statement. A trailing
/// comment without a newline is not reported.
#[test]
fn a_cut_last_statement_is_reported() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let (r, _) = read_ok("whole.obj", text.as_bytes());
    assert!(!r.unterminated_last_line);
    let (r, _) = read_ok("cut.obj", text.trim_end().as_bytes());
    assert!(r.unterminated_last_line);
    let commented = format!("{text}# end");
    let (r, _) = read_ok("comment.obj", commented.as_bytes());
    assert!(!r.unterminated_last_line);
}

/// Reads `obj` written as `name` in a temp dir beside `others` (name, contents).
fn read_with_files(
    name: &str,
    obj: &str,
    others: &[(&str, &[u8])],
) -> (tessera_mesh::ImportReport, Collect, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    for (n, b) in others {
        let p = dir.path().join(n);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, b).unwrap();
    }
    let path = dir.path().join(name);
    std::fs::write(&path, obj).unwrap();
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap_or_else(|e| panic!("{name}: {e}"));
    (r, c, dir)
}

/// Issue 11: faces take their material's diffuse colour `Kd` (times the vertex colour),
/// from a library whose name holds a space; a position used by two materials becomes two
/// vertices, one of each colour.
#[test]
fn mtl_kd_colours_the_faces_of_each_material() {
    let mtl = "# two materials\nnewmtl red paint\nKd 1 0 0\n\nnewmtl grey\nKd 0.5\n";
    let obj = "mtllib my materials.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
               usemtl red paint\nf 1 2 3\nusemtl grey\nf 1 3 4\nusemtl red paint\nf 2 3 4\n";
    let (r, c, _d) = read_with_files("m.obj", obj, &[("my materials.mtl", mtl.as_bytes())]);
    assert!(c.headers[0].attributes.colors);
    assert_eq!(c.triangles.len(), 3);
    let color = |t: usize| c.triangles[t].map(|i| c.vertices[i as usize].color);
    assert_eq!(color(0), [[255, 0, 0, 255]; 3]);
    assert_eq!(color(1), [[128, 128, 128, 255]; 3]);
    assert_eq!(color(2), [[255, 0, 0, 255]; 3]);
    // Red uses all 4 positions, grey 3 of them: 7 vertices.
    assert_eq!(c.vertices.len(), 7);
    assert!(r.missing_files.is_empty() && r.textures_not_used.is_empty());
    assert!(r.unknown_materials.is_empty());
}

/// A vertex colour is multiplied by its material's `Kd`; a white library changes nothing
/// (and keeps the direct mode's one vertex per position).
#[test]
fn mtl_kd_tints_vertex_colours_and_white_materials_change_nothing() {
    let mtl = "newmtl half\nKd 0.5 0.5 0.5\n";
    let obj = "mtllib m.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nusemtl half\nf 1 2 3\n";
    let (_, c, _d) = read_with_files("t.obj", obj, &[("m.mtl", mtl.as_bytes())]);
    assert_eq!(c.vertices[0].color, [128, 0, 0, 255]);
    assert_eq!(c.vertices[2].color, [0, 0, 128, 255]);
    let white = "newmtl w\nKd 1 1 1\n";
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl w\nf 1 2 3\n";
    let (_, c, _d) = read_with_files("w.obj", obj, &[("m.mtl", white.as_bytes())]);
    assert!(!c.headers[0].attributes.colors);
    assert_eq!(c.vertices.len(), 3);
}

/// A missing library, a missing texture image and a `usemtl` no library defines are
/// warnings with what is missing named; the model is read whole.
#[test]
fn missing_materials_and_images_are_reported_and_the_model_kept() {
    let mtl = "newmtl photo\nKd 0.8 0.8 0.8\nmap_Kd -s 1 1 1 images/my photo.jpg\n";
    let obj = "mtllib gone.mtl\nmtllib here.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\n\
               vt 1 0\nvt 0 1\nusemtl photo\nf 1/1 2/2 3/3\nusemtl nosuch\nf 2/2 4/1 3/3\n";
    let (r, c, d) = read_with_files("p.obj", obj, &[("here.mtl", mtl.as_bytes())]);
    assert_eq!(c.triangles.len(), 2);
    assert!(r.textures_not_used.is_empty(), "{:?}", r.textures_not_used);
    assert!(r.textures.is_empty());
    assert!(!c.headers[0].attributes.textures);
    let gone = d.path().join("gone.mtl").display().to_string();
    let image = d.path().join("images/my photo.jpg").display().to_string();
    assert_eq!(r.missing_files, [gone, image]);
    assert_eq!(r.unknown_materials.get("nosuch"), Some(&1));
    // The textured material is drawn in its Kd; the unknown one white.
    assert_eq!(
        c.vertices[c.triangles[0][0] as usize].color,
        [204, 204, 204, 255]
    );
    assert_eq!(
        c.vertices[c.triangles[1][1] as usize].color,
        [255, 255, 255, 255]
    );
}

/// Issue 11 (appearance): two textured materials (one image in a directory whose name
/// holds a space, clamped; one JPEG), a third sharing the first's image with `-s`/`-o`,
/// and an untextured one. Each textured face's vertices carry their material's texture
/// index and the file's UVs (v not flipped; the third's through its offset and scale);
/// a position used by two materials is two vertices; a textured face without `vt` is
/// untextured and counted.
#[test]
fn map_kd_textures_are_described_and_sampled_per_vertex() {
    let mtl = "newmtl wood\nKd 0.5 0.5 0.5\nmap_Kd -clamp on -bm 1 tex dir/wood grain.png\n\
               newmtl stone\nmap_Kd stone.jpg\n\
               newmtl paint\nKd 1 0 0\n\
               newmtl wood scaled\nmap_Kd -s 2 4 1 -o 0.5 0.25 0 tex dir/wood grain.png\n";
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
               vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.25 0.75\n\
               usemtl wood\nf 1/1 2/2 3/3\n\
               usemtl stone\nf 1/1 3/3 4/5\n\
               usemtl paint\nf 2/2 4/4 3/3\n\
               usemtl wood scaled\nf 1/1 2/2 4/5\n\
               usemtl wood\nf 1 3 4\nf 1/1 2/2 3/3\n";
    let wood = png(8, 4);
    let stone = jpeg(16, 2);
    let (r, c, d) = read_with_files(
        "t.obj",
        obj,
        &[
            ("m.mtl", mtl.as_bytes()),
            ("tex dir/wood grain.png", &wood),
            ("stone.jpg", &stone),
        ],
    );
    let h = &c.headers[0].attributes;
    assert!(h.textures && h.uvs && h.colors);
    assert!(r.missing_files.is_empty() && r.unreadable_images.is_empty());
    assert!(r.textures_not_used.is_empty(), "{:?}", r.textures_not_used);
    assert_eq!(r.untextured_faces, 1);
    assert_eq!(r.textures.len(), 3, "{:?}", r.textures);
    let (t0, t1, t2) = (&r.textures[0], &r.textures[1], &r.textures[2]);
    let wood_path = d.path().join("tex dir/wood grain.png");
    assert_eq!(t0.material, "wood");
    assert_eq!(t0.image, ImageSource::File(wood_path.clone()));
    assert_eq!(t0.image_name, "tex dir/wood grain.png");
    assert_eq!(t0.tint, [255; 4], "OBJ images are not tinted by Kd");
    assert_eq!(t0.wrap, [Wrap::ClampToEdge; 2]);
    assert!(t0.v_up);
    assert_eq!(t0.size, [8, 4]);
    assert_eq!(t1.material, "stone");
    assert_eq!(t1.image, ImageSource::File(d.path().join("stone.jpg")));
    assert_eq!(
        (t1.tint, t1.wrap, t1.size),
        ([255; 4], [Wrap::Repeat; 2], [16, 2])
    );
    // One image, two materials: two textures with equal images.
    assert_eq!(t2.material, "wood scaled");
    assert_eq!(t2.image, t0.image);
    assert_eq!(t2.wrap, [Wrap::Repeat; 2]);

    assert_eq!(c.triangles.len(), 6);
    let tri = |t: usize| c.triangles[t].map(|i| c.vertices[i as usize]);
    let textures = |t: usize| tri(t).map(|v| v.texture);
    let uvs = |t: usize| tri(t).map(|v| v.uv);
    assert_eq!(textures(0), [0; 3]);
    assert_eq!(uvs(0), [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]);
    assert_eq!(
        tri(0)[0].color,
        [128, 128, 128, 255],
        "the fallback colour is Kd"
    );
    assert_eq!(textures(1), [1; 3]);
    assert_eq!(uvs(1), [[0.0, 0.0], [1.0, 1.0], [0.25, 0.75]]);
    assert_eq!(textures(2), [NO_TEXTURE; 3]);
    assert_eq!(tri(2)[0].color, [255, 0, 0, 255]);
    assert_eq!(textures(3), [2; 3]);
    // u' = 2 u + 0.5, v' = 4 v + 0.25.
    assert_eq!(uvs(3), [[0.5, 0.25], [2.5, 0.25], [1.0, 3.25]]);
    // The wood face without vt: untextured, in Kd.
    assert_eq!(textures(4), [NO_TEXTURE; 3]);
    assert_eq!(tri(4)[0].color, [128, 128, 128, 255]);
    // The last wood face reuses the first one's vertices.
    assert_eq!(c.triangles[5], c.triangles[0]);
    // Vertices of different textures are never one vertex.
    for (a, ta) in c.triangles.iter().enumerate() {
        for (b, tb) in c.triangles.iter().enumerate() {
            if textures(a)[0] != textures(b)[0] {
                assert!(
                    ta.iter().all(|i| !tb.contains(i)),
                    "{a} and {b} share a vertex"
                );
            }
        }
    }
    assert!(c
        .vertices
        .iter()
        .all(|v| v.texture == NO_TEXTURE || (v.texture as usize) < r.textures.len()));
}

/// A missing image and an unreadable one (a corrupt PNG, a text file named .jpg):
/// warnings naming them, their vertices untextured in `Kd`, the readable texture of a
/// third material still used.
#[test]
fn missing_and_unreadable_map_kd_images_fall_back_to_kd() {
    let mtl = "newmtl gone\nKd 0 1 0\nmap_Kd gone.png\n\
               newmtl corrupt\nKd 0 0 1\nmap_Kd corrupt.png\n\
               newmtl text\nmap_Kd notes.jpg\n\
               newmtl good\nmap_Kd good.png\n";
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n\
               usemtl gone\nf 1/1 2/2 3/3\nusemtl corrupt\nf 1/1 2/2 3/3\n\
               usemtl text\nf 1/1 2/2 3/3\nusemtl good\nf 1/1 2/2 3/3\n";
    let mut corrupt = png(4, 4);
    corrupt.truncate(30);
    corrupt[20] ^= 0xff;
    let (r, c, d) = read_with_files(
        "f.obj",
        obj,
        &[
            ("m.mtl", mtl.as_bytes()),
            ("corrupt.png", &corrupt),
            ("notes.jpg", b"just some text, no image"),
            ("good.png", &png(3, 5)),
        ],
    );
    let shown = |n: &str| d.path().join(n).display().to_string();
    assert_eq!(r.missing_files, [shown("gone.png")]);
    assert_eq!(
        r.unreadable_images,
        [shown("corrupt.png"), shown("notes.jpg")]
    );
    assert_eq!(r.textures.len(), 1);
    assert_eq!(r.textures[0].material, "good");
    assert_eq!(r.textures[0].size, [3, 5]);
    assert!(c.headers[0].attributes.textures);
    let tri = |t: usize| c.triangles[t].map(|i| c.vertices[i as usize]);
    assert_eq!(
        tri(0).map(|v| (v.texture, v.color)),
        [(NO_TEXTURE, [0, 255, 0, 255]); 3]
    );
    assert_eq!(
        tri(1).map(|v| (v.texture, v.color)),
        [(NO_TEXTURE, [0, 0, 255, 255]); 3]
    );
    assert_eq!(tri(2).map(|v| v.texture), [NO_TEXTURE; 3]);
    assert_eq!(tri(3).map(|v| v.texture), [0; 3]);
    // The UVs of the untextured faces are kept.
    assert_eq!(tri(0)[1].uv, [1.0, 0.0]);

    // All images missing: no vertex textured, and the header says so.
    let (r, c, _d) = read_with_files("g.obj", obj, &[("m.mtl", mtl.as_bytes())]);
    assert!(!c.headers[0].attributes.textures);
    assert!(r.textures.is_empty());
    assert_eq!(r.missing_files.len(), 4);
    assert!(c.vertices.iter().all(|v| v.texture == NO_TEXTURE));
}

/// The header's `textures` is exact: faces of a textured material that all lack `vt`
/// (and a face continued over two lines that has them) are told apart before the first
/// vertex; an image format other than PNG or JPEG is named as not used.
#[test]
fn the_header_knows_whether_any_vertex_is_textured() {
    let mtl = "newmtl t\nmap_Kd t.png\nnewmtl b\nmap_Kd b.bmp\n";
    let files: &[(&str, &[u8])] = &[("m.mtl", mtl.as_bytes()), ("t.png", &png(2, 2))];
    let head = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n";
    // vt used only outside the textured material; its faces have none.
    let obj = format!("{head}f 1/1 2/1 3/1\nusemtl t\nf 1//1 2//1 3//1\n");
    let (r, c, _d) = read_with_files("a.obj", &obj, files);
    assert!(!c.headers[0].attributes.textures && c.headers[0].attributes.uvs);
    assert!(r.textures.is_empty());
    assert_eq!(r.untextured_faces, 1);
    // A face continued with `\`.
    let obj = format!("{head}usemtl t\nf 1/1 \\\n 2/1 3/1\n");
    let (r, c, _d) = read_with_files("b.obj", &obj, files);
    assert!(c.headers[0].attributes.textures);
    assert_eq!(c.vertices.iter().filter(|v| v.texture == 0).count(), 3);
    assert_eq!(r.untextured_faces, 0);
    // A BMP: not used, named.
    let mut bmp = Vec::new();
    image::RgbImage::new(2, 2)
        .write_to(&mut std::io::Cursor::new(&mut bmp), image::ImageFormat::Bmp)
        .unwrap_or_else(|_| bmp = b"BM\0\0\0\0".to_vec());
    let obj = format!("{head}usemtl b\nf 1/1 2/1 3/1\n");
    let (r, c, _d) = read_with_files("c.obj", &obj, &[files[0], ("b.bmp", &bmp)]);
    assert!(!c.headers[0].attributes.textures);
    assert_eq!(r.textures_not_used.len(), 1, "{:?}", r.textures_not_used);
    assert!(
        r.textures_not_used[0].starts_with("b (image 'b.bmp'): "),
        "{:?}",
        r.textures_not_used
    );
    assert!(r.unreadable_images.is_empty());
}

/// The real textured scan (YCB scissors, from Blender): one material, one 4096 x 4096
/// PNG; every vertex samples it.
#[test]
fn ycb_scissors_vertices_sample_their_texture() {
    let Some(dir) = shared_data("ycb-scissors") else {
        return;
    };
    let path = dir.join("textured_simple_reoriented.obj");
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap();
    assert!(c.headers[0].attributes.textures);
    assert_eq!(r.textures.len(), 1, "{:?}", r.textures);
    let t = &r.textures[0];
    assert_eq!(t.material, "material_0.006");
    // The path checked against the asset policy (canonical) is the path read.
    let png = std::fs::canonicalize(dir.join("texture_map.png")).unwrap();
    assert_eq!(t.image, ImageSource::File(png));
    assert_eq!(t.image_name, "texture_map.png");
    assert_eq!(t.size, [4096, 4096]);
    assert!(t.v_up);
    assert_eq!(t.wrap, [Wrap::Repeat; 2]);
    // Kd 0.639216.
    assert_eq!(
        t.tint, [255; 4],
        "the image as it is (Kd is the fallback colour)"
    );
    assert!(r.missing_files.is_empty() && r.unreadable_images.is_empty());
    assert_eq!(r.triangles, 15728);
    assert!(c.vertices.iter().all(|v| v.texture == 0));
    assert!(c.vertices.iter().all(|v| v.color == [163, 163, 163, 255]));
}

/// A gzip-compressed OBJ is read in three passes through the inflater (the texture pass
/// too), its images found beside it.
#[test]
fn a_gzipped_textured_obj_finds_its_images() {
    use std::io::Write;
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n\
               usemtl t\nf 1/1 2/2 3/3\n";
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(obj.as_bytes()).unwrap();
    let gz = gz.finish().unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.mtl"), "newmtl t\nmap_Kd t.jpg\n").unwrap();
    std::fs::write(dir.path().join("t.jpg"), jpeg(3, 3)).unwrap();
    let path = dir.path().join("scan.obj.gz");
    std::fs::write(&path, gz).unwrap();
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c).unwrap();
    assert!(c.headers[0].attributes.textures);
    assert_eq!(r.textures.len(), 1);
    assert_eq!(r.textures[0].size, [3, 3]);
    assert!(c.vertices.iter().all(|v| v.texture == 0));
}
