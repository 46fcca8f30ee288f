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
