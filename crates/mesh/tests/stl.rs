//! STL importer tests: ascii, binary, welding and errors.

mod common;

use common::*;
use tessera_mesh::{Attributes, MeshError};

const ASCII: &str = "solid cube part
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 1 0 0
      vertex 1 1 0
    endloop
  endfacet
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 1 1 0
      vertex 0 1 -0
    endloop
  endfacet
  facet normal 0 0 0
    outer loop
      vertex 0 0 0
      vertex 0 0 0
      vertex 1 1 0
    endloop
  endfacet
endsolid cube part
";

#[test]
fn ascii_is_welded() {
    let (r, c) = read_ok("a.stl", ASCII.as_bytes());
    assert_eq!(c.headers[0].attributes, Attributes::default());
    assert_eq!(c.headers[0].face_count, None);
    assert_eq!(r.vertices, 4);
    assert_eq!(c.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(r.degenerate_faces_skipped, 1);
}

fn binary(facets: &[[[f32; 3]; 3]], header: &[u8; 80]) -> Vec<u8> {
    let mut b = header.to_vec();
    b.extend_from_slice(&(facets.len() as u32).to_le_bytes());
    for f in facets {
        f32le(&mut b, &[0.0, 0.0, 1.0]);
        for p in f {
            f32le(&mut b, p);
        }
        b.extend_from_slice(&[0, 0]);
    }
    b
}

fn facets() -> Vec<[[f32; 3]; 3]> {
    vec![
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
        [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
        [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
    ]
}

#[test]
fn binary_is_welded_even_with_solid_header() {
    let mut header = [b' '; 80];
    header[..5].copy_from_slice(b"solid");
    let (r, c) = read_ok("b.stl", &binary(&facets(), &header));
    assert_eq!(c.headers[0].face_count, Some(3));
    assert_eq!(r.vertices, 4);
    assert_eq!(c.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(r.degenerate_faces_skipped, 1);
    assert_eq!(pos(&c)[3], [0.0, 1.0, 0.0]);
}

#[test]
fn binary_truncated() {
    let b = binary(&facets(), &[0; 80]);
    let e = read_err("t.stl", &b[..b.len() - 10]);
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
    assert!(e.to_string().contains("facet 2 of 3"), "{e}");
    let e = read_err("h.stl", &[0u8; 40]);
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
}

#[test]
fn binary_nan_and_empty() {
    let mut f = facets();
    f[1][2][1] = f32::NAN;
    let e = read_err("nan.stl", &binary(&f, &[0; 80]));
    assert!(matches!(e, MeshError::NonFinite { vertex: 5, .. }), "{e}");
    let e = read_err("empty.stl", &binary(&[], &[0; 80]));
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
}

#[test]
fn ascii_errors() {
    let e = read_err(
        "bad.stl",
        ASCII.replace("vertex 1 0 0", "vertex 1 zero 0").as_bytes(),
    );
    assert!(matches!(e, MeshError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains("line 5"), "{e}");
    let cut = &ASCII[..ASCII.find("endloop").unwrap()];
    let e = read_err("cut.stl", cut.as_bytes());
    assert!(matches!(e, MeshError::Truncated { .. }), "{e}");
    let e = read_err(
        "nan2.stl",
        ASCII.replace("vertex 1 1 0", "vertex 1 NaN 0").as_bytes(),
    );
    assert!(matches!(e, MeshError::NonFinite { .. }), "{e}");
    let e = read_err("empty2.stl", b"solid x\nendsolid x\n");
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
}
