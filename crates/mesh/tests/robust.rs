//! Robustness: no input bytes may make an importer panic, and whatever it delivers must
//! respect the visitor contract (checked by `Collect`).

mod common;

use common::*;
use proptest::prelude::*;

const PLY_ASCII: &[u8] = b"ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
property list uchar int junk
element face 2
property list uchar int vertex_indices
end_header
0 0 0 1 5
1 0 0 0
1 1 0 2 1 2
0 1 0 0
4 0 1 2 3
3 0 1 3
";

const OBJ: &[u8] =
    b"v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\nf -1 -2 -3\n";

fn ply_binary() -> Vec<u8> {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n\
property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
element face 2\nproperty list uchar uint vertex_indices\nelement other 1\nproperty short q\nend_header\n"
        .to_vec();
    for p in [
        [0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        f32le(&mut b, &p);
        b.extend_from_slice(&[1, 2, 3]);
    }
    for f in [[0u32, 1, 2], [0, 2, 3]] {
        b.push(3);
        for i in f {
            b.extend_from_slice(&i.to_le_bytes());
        }
    }
    b.extend_from_slice(&[0, 1]);
    b
}

fn stl_binary() -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&2u32.to_le_bytes());
    for f in [
        [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
        [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ] {
        f32le(&mut b, &[0.0, 0.0, 1.0]);
        for p in f {
            f32le(&mut b, &p);
        }
        b.extend_from_slice(&[0, 0]);
    }
    b
}

/// Same bytes, header claiming big-endian: garbage values, must still not panic.
fn big_endian_header(b: Vec<u8>) -> Vec<u8> {
    let text = b"binary_little_endian";
    match b.windows(text.len()).position(|w| w == text) {
        Some(i) => [&b[..i], &b"binary_big_endian"[..], &b[i + text.len()..]].concat(),
        None => b,
    }
}

fn samples() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("a.ply", PLY_ASCII.to_vec()),
        ("b.ply", ply_binary()),
        ("c.obj", OBJ.to_vec()),
        ("d.stl", stl_binary()),
        ("e.ply", big_endian_header(ply_binary())),
    ]
}

#[test]
fn samples_are_valid() {
    for (name, bytes) in samples().into_iter().take(4) {
        read_ok(name, &bytes);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    /// Overwrite a few bytes and truncate: errors are fine, panics are not.
    #[test]
    fn mutated_files_never_panic(
        which in 0usize..5,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
    ) {
        let (name, mut bytes) = samples().swap_remove(which);
        for (at, value) in edits {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        if do_cut {
            bytes.truncate(cut.index(bytes.len() + 1));
        }
        let (result, collected) = read_bytes(name, &bytes);
        if let Ok(report) = result {
            prop_assert_eq!(report.triangles as usize, collected.triangles.len());
            prop_assert_eq!(report.vertices as usize, collected.vertices.len());
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300), ext in 0usize..3) {
        let name = ["r.ply", "r.obj", "r.stl"][ext];
        let _ = read_bytes(name, &bytes);
    }
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).expect("gzip");
    e.finish().expect("gzip")
}

/// Gzip-compressed inputs read as their plain bytes do, whatever the name (`.ply.gz`,
/// or a compressed file named `.ply`); an unknown extension is read when the content
/// says PLY; a corrupt or truncated gzip stream is an error naming the file.
#[test]
fn gzip_inputs_read_as_the_plain_ones() {
    for (name, bytes) in samples().into_iter().take(4) {
        let (plain, c) = read_ok(name, &bytes);
        let z = gzip(&bytes);
        for gz_name in [format!("{name}.gz"), name.to_string()] {
            let (r, d) = read_ok(&gz_name, &z);
            assert_eq!(r, plain, "{gz_name}");
            assert_eq!(d.triangles, c.triangles, "{gz_name}");
            assert_eq!(d.vertices, c.vertices, "{gz_name}");
        }
        let cut = &z[..z.len() / 2];
        let e = read_err(&format!("{name}.gz"), cut);
        assert!(!e.to_string().is_empty());
    }
    read_ok("scan.data", PLY_ASCII);
    read_ok("scan.data.gz", &gzip(PLY_ASCII));
    let e = read_err("scan.data", OBJ);
    assert!(
        matches!(e, tessera_mesh::MeshError::UnknownFormat { .. }),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------
// Issue 14, failure 8: messages name the real problem and where it is
// ---------------------------------------------------------------------------------------

/// `message` without the temporary directory before the file name.
fn after_dir(e: &tessera_mesh::MeshError) -> String {
    let m = e.to_string();
    match m.rfind('/') {
        Some(i) => m[i + 1..].to_string(),
        None => m,
    }
}

/// A float where a vertex index belongs said "vertex index 0 out of range" in PLY
/// (`0.5 as i64`) and "bad vertex index" in OBJ; both now say it is not an integer, on
/// its line, with the token.
#[test]
fn a_float_vertex_index_is_not_an_integer() {
    let e = read_err("float.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1.5 2 3\n");
    assert_eq!(
        after_dir(&e),
        "float.obj: line 4: vertex index '1.5' is not an integer"
    );
    // Combined mode, and the other tables.
    let e = read_err(
        "float-vt.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1.0 3/1\n",
    );
    assert_eq!(
        after_dir(&e),
        "float-vt.obj: line 5: texture coordinate index '1.0' is not an integer"
    );
    // An integer too long for 64 bits is out of range, not "not an integer".
    let e = read_err(
        "long.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",
    );
    assert_eq!(
        after_dir(&e),
        "long.obj: line 4: vertex index '99999999999999999999' is out of range (3 defined so far)"
    );
    let ply = |face: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
             end_header\n0 0 0\n1 0 0\n0 1 0\n{face}\n"
        )
    };
    let e = read_err("float.ply", ply("3 0.5 1 2").as_bytes());
    assert_eq!(
        after_dir(&e),
        "float.ply: line 13: face 0 of 1: vertex index 0.5 is not an integer"
    );
    let e = read_err("nan.ply", ply("3 0 nan 2").as_bytes());
    assert!(
        e.to_string()
            .ends_with("vertex index NaN is not an integer"),
        "{e}"
    );
    // An integer out of range still says so.
    let e = read_err("big.ply", ply("3 0 1 7").as_bytes());
    assert!(
        matches!(e, tessera_mesh::MeshError::IndexOutOfRange { index: 7, .. }),
        "{e}"
    );
}

/// `v` with more numbers than any form of it (`v 1 2 3 4 5 6 7 8`: two statements run
/// together, or an unknown dialect) was read as its first seven and the rest dropped; a
/// junk word and five numbers are errors too. Each names the `v` line. The forms in use
/// (x y z, x y z w, x y z r g b, x y z r g b a) still read.
#[test]
fn obj_vertex_with_extra_numbers_is_an_error_at_its_line() {
    let forms = "x y z, x y z w, x y z r g b or x y z r g b a";
    for (name, line, want) in [
        (
            "eight.obj",
            "v 1 0 0 1 2 3 4 5",
            format!("v has 8 numbers (expected {forms})"),
        ),
        (
            "five.obj",
            "v 1 0 0 1 2",
            format!("v has 5 numbers (expected {forms})"),
        ),
        (
            "junk.obj",
            "v 1 0 0 junk",
            format!("v: 'junk' is not a number (expected {forms})"),
        ),
    ] {
        let text = format!("v 0 0 0\n{line}\nv 0 1 0\nf 1 2 3\n");
        let e = read_err(name, text.as_bytes());
        assert_eq!(after_dir(&e), format!("{name}: line 2: {want}"));
    }
    let e = read_err(
        "vn.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1 0\nf 1//1 2//1 3//1\n",
    );
    assert_eq!(
        after_dir(&e),
        "vn.obj: line 4: vn has 4 numbers (expected x y z)"
    );
    let e = read_err(
        "vt.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0 0 0\nf 1/1 2/1 3/1\n",
    );
    assert_eq!(
        after_dir(&e),
        "vt.obj: line 4: vt has 4 numbers (expected u [v [w]])"
    );
    // The legitimate forms.
    let (r, c) = read_ok("w.obj", b"v 0 0 0 1\nv 1 0 0 1\nv 0 1 0 0.5\nf 1 2 3\n");
    assert_eq!((r.vertices, r.triangles), (3, 1));
    assert_eq!(pos(&c)[2], [0.0, 1.0, 0.0]);
    let (_, c) = read_ok(
        "rgb.obj",
        b"v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
    );
    assert_eq!(c.vertices[1].color, [0, 255, 0, 255]);
    let (_, c) = read_ok(
        "rgba.obj",
        b"v 0 0 0 1 0 0 1\nv 1 0 0 0 1 0 1\nv 0 1 0 0 0 1 0\nf 1 2 3\n",
    );
    assert_eq!(c.vertices[2].color, [0, 0, 255, 0]);
}

/// A PLY list count of 4294967295 (a uint32 -1) read the rest of the file as the list and
/// reported "file is truncated". A face list longer than the vertex count is refused at
/// its count, with the face and the count's byte (binary) or line (text); a list that
/// nothing bounds (a strip, a property Tessera skips) and that runs past the end of the
/// file says its count is too large, at the count.
#[test]
fn ply_huge_list_count_is_implausible_not_truncated() {
    let header = |format: &str, count: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list {count} int vertex_indices\n\
             end_header\n"
        )
    };
    let mut bin = header("binary_little_endian", "uint").into_bytes();
    let count_at = bin.len() + 36;
    f32le(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    bin.extend_from_slice(&u32::MAX.to_le_bytes());
    for i in [0i32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let e = read_err("count.ply", &bin);
    let implausible = "list count 4294967295 is implausible: a face cannot have more corners \
                       than the mesh has vertices (3)";
    assert_eq!(
        after_dir(&e),
        format!("count.ply: byte {count_at}: face 0 of 1: {implausible}")
    );
    // The common layout (a uchar count, read by the fast path) is checked too.
    let mut bin = header("binary_little_endian", "uchar").into_bytes();
    f32le(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    bin.extend_from_slice(&[255, 0, 0, 0, 0]);
    let e = read_err("uchar.ply", &bin);
    assert!(
        e.to_string()
            .contains("face 0 of 1: list count 255 is implausible"),
        "{e}"
    );
    let ascii = header("ascii", "uint") + "0 0 0\n1 0 0\n0 1 0\n4294967295 0 1 2\n";
    let e = read_err("count-ascii.ply", ascii.as_bytes());
    assert_eq!(
        after_dir(&e),
        format!("count-ascii.ply: line 13: face 0 of 1: {implausible}")
    );
    // A list of an element Tessera skips, before the faces.
    let mut bin = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
                   property float y\nproperty float z\nelement camera 1\n\
                   property list uint float params\nelement face 1\n\
                   property list uchar int vertex_indices\nend_header\n"
        .as_bytes()
        .to_vec();
    let count_at = bin.len() + 36;
    f32le(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    bin.extend_from_slice(&u32::MAX.to_le_bytes());
    f32le(&mut bin, &[1.0, 2.0]);
    bin.push(3);
    for i in [0i32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let e = read_err("camera.ply", &bin);
    assert_eq!(
        after_dir(&e),
        format!(
            "camera.ply: byte {count_at}: element 'camera' number 0 of 1: list count 4294967295 \
             is too large: the file ends before the list does (a corrupt count, or a truncated file)"
        )
    );
    // Triangle strips, in text.
    let strips = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                  property float z\nelement tristrips 1\nproperty list uint int vertex_indices\n\
                  end_header\n0 0 0\n1 0 0\n0 1 0\n4294967295 0 1 2\n";
    let e = read_err("strips.ply", strips.as_bytes());
    assert_eq!(
        after_dir(&e),
        "strips.ply: line 13: triangle strip 0 of 1: list count 4294967295 is too large: the \
         file ends before the list does (a corrupt count, or a truncated file)"
    );
    // A file cut inside a plausible face list is still "truncated".
    let mut bin = header("binary_little_endian", "uchar").into_bytes();
    f32le(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    bin.extend_from_slice(&[3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0]);
    let e = read_err("cut.ply", &bin);
    assert_eq!(
        after_dir(&e),
        "cut.ply: file is truncated: expected face 0 of 1"
    );
}

/// The error and its `source()` chain as anyhow's `{:#}` prints it (what the CLI shows).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut next = e.source();
    while let Some(cause) = next {
        s = format!("{s}: {cause}");
        next = cause.source();
    }
    s
}

/// An I/O error showed its cause in its message and returned it as its `source()`, so
/// `tessera gen tile` printed "missing.ply: No such file or directory (os error 2): No
/// such file or directory (os error 2)". The chain holds the cause once, also through a
/// transparent wrapper (tessera-gen's `GenError`) and a `{0}` one (tessera-build's).
#[test]
fn io_errors_print_their_cause_once() {
    #[derive(Debug, thiserror::Error)]
    enum Transparent {
        #[error(transparent)]
        Mesh(#[from] tessera_mesh::MeshError),
    }
    #[derive(Debug, thiserror::Error)]
    enum Shown {
        #[error("{0}")]
        Mesh(tessera_mesh::MeshError),
    }
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.ply");
    let a_dir = dir.path().join("adir.ply");
    std::fs::create_dir(&a_dir).unwrap();
    for (path, kind) in [
        (&missing, std::io::ErrorKind::NotFound),
        (&a_dir, std::io::ErrorKind::IsADirectory),
    ] {
        let mut c = Collect::default();
        let e = tessera_mesh::read_mesh(path, &mut c).unwrap_err();
        // The OS's words for the cause ("Is a directory (os error 21)").
        let cause = match &e {
            tessera_mesh::MeshError::Io { cause, .. } => cause.to_string(),
            other => panic!("not an I/O error: {other}"),
        };
        assert_eq!(e.to_string(), format!("{}: {cause}", path.display()));
        assert!(matches!(&e, tessera_mesh::MeshError::Io { cause, .. } if cause.kind() == kind));
        let once = |s: String| assert_eq!(s.matches(&cause).count(), 1, "{s}");
        once(chain(&e));
        once(chain(&Transparent::from(e)));
        once(chain(&Shown::Mesh(
            tessera_mesh::read_mesh(path, &mut c).unwrap_err(),
        )));
    }
}

/// The `tracing` subscriber of this test binary: it keeps the messages of the events each
/// thread sees. Global, not scoped (`with_default`): a scoped subscriber raced with the
/// tests on other threads, which reach the same callsites with no subscriber and can
/// leave them cached as "never interested" (tracing-core's interest cache), so the test
/// below missed its warning in most runs.
struct Messages;

thread_local! {
    static SEEN: std::cell::RefCell<Vec<String>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl tracing::Subscriber for Messages {
    fn enabled(&self, _: &tracing::Metadata<'_>) -> bool {
        true
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, event: &tracing::Event<'_>) {
        struct Message<'a>(&'a mut String);
        impl tracing::field::Visit for Message<'_> {
            fn record_debug(&mut self, f: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                if f.name() == "message" {
                    *self.0 = format!("{v:?}");
                }
            }
        }
        let mut m = String::new();
        event.record(&mut Message(&mut m));
        SEEN.with(|s| s.borrow_mut().push(m));
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

/// Read `bytes` as `name` and return the warning about ignored input.
fn ignored_warning(name: &str, bytes: &[u8]) -> (tessera_mesh::ImportReport, String) {
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(|| {
        tracing::subscriber::set_global_default(Messages).expect("no other global subscriber");
        // Callsites registered by other threads while the subscriber was being set.
        tracing::callsite::rebuild_interest_cache();
    });
    SEEN.with(|s| s.borrow_mut().clear());
    let (r, _) = read_ok(name, bytes);
    let all = SEEN.with(|s| s.borrow().clone());
    let warning = all
        .iter()
        .find(|m| m.contains("ignored"))
        .unwrap_or_else(|| panic!("no warning about ignored input in {all:?}"));
    (
        r,
        warning[warning.rfind('/').map_or(0, |i| i + 1)..].to_string(),
    )
}

/// "ignored 1 unsupported statements or elements" said neither which nor where: the
/// warning names each ignored PLY element and OBJ keyword with its count, most frequent
/// first. (`usemtl`, `mtllib`, `o`, `g` and `s` are not counted: no geometry is lost.)
#[test]
fn ignored_statements_and_elements_are_named() {
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nelement camera 1\nproperty float view_px\nelement face 1\n\
               property list uchar int vertex_indices\nelement edge 2\nproperty int a\n\
               end_header\n0 0 0\n1 0 0\n0 1 0\n5\n3 0 1 2\n0\n1\n";
    let (r, w) = ignored_warning("cam.ply", ply.as_bytes());
    assert_eq!(r.ignored_statements, 3);
    assert_eq!(
        w,
        "cam.ply: ignored 3 unsupported statements or elements: element edge (2), element camera (1)"
    );
    let obj = "mtllib m.mtl\nusemtl red\no x\ng y\ns 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\n\
               cstype bspline\ncurv 0 1 1 2\ncurv 0 1 2 3\nl 1 2\nf 1 2 3\n";
    let (r, w) = ignored_warning("free.obj", obj.as_bytes());
    assert_eq!(r.ignored_statements, 4);
    assert_eq!(
        w,
        "free.obj: ignored 4 unsupported statements or elements: curv (2), cstype (1), l (1)"
    );
    // Garbage keeps the list bounded: 32 names, the rest counted as `other names`.
    let mut garbage = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    for k in 0..100 {
        garbage += &format!("kw{k:03} 1\n");
    }
    let (r, w) = ignored_warning("garbage.obj", garbage.as_bytes());
    assert_eq!(r.ignored_statements, 100);
    assert_eq!(r.ignored_by_name.len(), 33);
    assert_eq!(r.ignored_by_name["other names"], 68);
    assert!(
        w.starts_with(
            "garbage.obj: ignored 100 unsupported statements or elements: other names (68), kw000 (1),"
        ),
        "{w}"
    );
}
