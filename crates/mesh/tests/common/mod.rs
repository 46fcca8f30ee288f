//! Helpers shared by the importer tests: a visitor that records everything and a way to
//! read a byte string as a file of a given name.
#![allow(dead_code)]

use std::path::PathBuf;

use tessera_mesh::{read_mesh, ImportReport, MeshError, MeshHeader, MeshVisitor, Vertex};

#[derive(Default, Debug)]
pub struct Collect {
    pub headers: Vec<MeshHeader>,
    pub vertices: Vec<Vertex>,
    pub triangles: Vec<[u32; 3]>,
}

impl MeshVisitor for Collect {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError> {
        assert!(
            self.vertices.is_empty() && self.triangles.is_empty(),
            "header after data"
        );
        self.headers.push(header.clone());
        Ok(())
    }
    fn vertex(&mut self, vertex: &Vertex) -> Result<(), MeshError> {
        assert_eq!(self.headers.len(), 1, "vertex before header");
        self.vertices.push(*vertex);
        Ok(())
    }
    fn triangle(&mut self, indices: [u32; 3]) -> Result<(), MeshError> {
        assert!(
            indices.iter().all(|&i| (i as usize) < self.vertices.len()),
            "triangle {indices:?} references an undelivered vertex"
        );
        self.triangles.push(indices);
        Ok(())
    }
}

/// Write `bytes` as `name` in a fresh temp dir and read it with `read_mesh`.
pub fn read_bytes(name: &str, bytes: &[u8]) -> (Result<ImportReport, MeshError>, Collect) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write test file");
    let mut c = Collect::default();
    let r = read_mesh(&path, &mut c);
    (r, c)
}

/// Read and expect success.
pub fn read_ok(name: &str, bytes: &[u8]) -> (ImportReport, Collect) {
    let (r, c) = read_bytes(name, bytes);
    match r {
        Ok(r) => (r, c),
        Err(e) => panic!("reading {name} failed: {e}"),
    }
}

/// Read and expect failure; the message must be one line naming the file.
pub fn read_err(name: &str, bytes: &[u8]) -> MeshError {
    let (r, _) = read_bytes(name, bytes);
    match r {
        Ok(r) => panic!("reading {name} succeeded unexpectedly: {r:?}"),
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains(name), "message does not name the file: {msg}");
            assert!(!msg.contains('\n'), "message spans several lines: {msg}");
            e
        }
    }
}

/// `shared/data/<name>` beside the repository, if present.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} absent, skipping", p.display());
        None
    }
}

pub fn pos(c: &Collect) -> Vec<[f32; 3]> {
    c.vertices.iter().map(|v| v.position).collect()
}

/// Little-endian binary helpers.
pub fn f32le(out: &mut Vec<u8>, xs: &[f32]) {
    for x in xs {
        out.extend_from_slice(&x.to_le_bytes());
    }
}
pub fn f32be(out: &mut Vec<u8>, xs: &[f32]) {
    for x in xs {
        out.extend_from_slice(&x.to_be_bytes());
    }
}

/// A `w` x `h` PNG (a gradient, so the bytes are not trivial).
pub fn png(w: u32, h: u32) -> Vec<u8> {
    encode(w, h, image::ImageFormat::Png)
}

/// A `w` x `h` JPEG.
pub fn jpeg(w: u32, h: u32) -> Vec<u8> {
    encode(w, h, image::ImageFormat::Jpeg)
}

fn encode(w: u32, h: u32, format: image::ImageFormat) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 128]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, format).expect("encode test image");
    out.into_inner()
}
