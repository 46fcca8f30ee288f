//! A streaming binary little-endian PLY writer with atomic output.
//!
//! Tools that produce meshes (the generator, exporters, tests) need to write files far
//! larger than RAM, and must never leave a half-written file where a finished one is
//! expected. [`PlyWriter`] therefore streams into a temporary file beside the target (a
//! [`tessera_format::AtomicFile`]), checks at [`PlyWriter::finish`] that exactly the
//! declared numbers of vertices and triangles were written, fsyncs, and only then renames
//! the file into place. A writer dropped without `finish` (an error, a panic, a killed run
//! between the two) removes its temporary file, so nothing ever appears at the target path.

use std::io::Write;
use std::path::{Path, PathBuf};
use tessera_format::{AtomicFile, AtomicFileError};

use crate::{Attributes, MeshError, Vertex};

/// Size of the write buffer.
const BUFFER_BYTES: usize = 1 << 20;

/// What a [`PlyWriter`] will write: the header must be known before the first vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyWriterOptions {
    /// Optional attributes to write per vertex (position is always written). PLY has no
    /// texture index: `textures` and [`Vertex::texture`] are ignored (the UVs are
    /// written when `uvs` is set).
    pub attributes: Attributes,
    /// Exact number of vertices that will be written.
    pub vertex_count: u64,
    /// Exact number of triangles that will be written.
    pub face_count: u64,
    /// `comment` lines for the header (line breaks are replaced by spaces).
    pub comments: Vec<String>,
}

/// Streams a binary little-endian PLY file: all vertices, then all triangles.
///
/// Vertex layout: `float x y z`, then `float nx ny nz` if normals, `uchar red green blue
/// alpha` if colours, `float u v` if uvs. Faces: `property list uchar uint vertex_indices`.
#[derive(Debug)]
pub struct PlyWriter {
    path: PathBuf,
    /// `None` once finished (or after the file was handed over in `finish`).
    out: Option<AtomicFile>,
    attributes: Attributes,
    vertex_count: u64,
    face_count: u64,
    vertices_written: u64,
    faces_written: u64,
}

impl PlyWriter {
    /// Create the temporary file beside `path` and write the header.
    pub fn create(path: &Path, opts: &PlyWriterOptions) -> Result<PlyWriter, MeshError> {
        if opts.vertex_count > u64::from(u32::MAX) {
            return Err(MeshError::TooManyVertices {
                path: path.to_path_buf(),
            });
        }
        if path.file_name().is_none() {
            return Err(MeshError::Usage {
                path: path.to_path_buf(),
                detail: "output path has no file name".into(),
            });
        }
        let file = AtomicFile::create(path, BUFFER_BYTES).map_err(io_error)?;
        let mut writer = PlyWriter {
            path: path.to_path_buf(),
            out: Some(file),
            attributes: opts.attributes,
            vertex_count: opts.vertex_count,
            face_count: opts.face_count,
            vertices_written: 0,
            faces_written: 0,
        };
        let header = header_text(opts);
        writer.write_bytes(header.as_bytes())?;
        Ok(writer)
    }

    /// The path the finished file will have.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Append one vertex. Fails after the first triangle, past the declared count, or on a
    /// non-finite position (which no reader would accept back).
    pub fn write_vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        if self.faces_written > 0 {
            return Err(self.usage("vertex written after a triangle; write all vertices first"));
        }
        if self.vertices_written >= self.vertex_count {
            return Err(self.usage(format!(
                "more vertices written than the {} declared",
                self.vertex_count
            )));
        }
        if !v.position.iter().all(|c| c.is_finite()) {
            return Err(MeshError::NonFinite {
                path: self.path.clone(),
                vertex: self.vertices_written,
            });
        }
        let mut buf = [0u8; 48];
        let len = encode_vertex(&mut buf, v, self.attributes);
        self.write_bytes(&buf[..len])?;
        self.vertices_written += 1;
        Ok(())
    }

    /// Append one triangle of vertex indices (each below the declared vertex count).
    pub fn write_triangle(&mut self, idx: [u32; 3]) -> Result<(), MeshError> {
        if self.faces_written >= self.face_count {
            return Err(self.usage(format!(
                "more triangles written than the {} declared",
                self.face_count
            )));
        }
        if let Some(&bad) = idx.iter().find(|&&i| u64::from(i) >= self.vertex_count) {
            return Err(MeshError::IndexOutOfRange {
                path: self.path.clone(),
                line_or_offset: format!("triangle {}", self.faces_written),
                index: i64::from(bad),
                vertex_count: self.vertex_count,
            });
        }
        let mut buf = [0u8; 13];
        buf[0] = 3;
        for (k, i) in idx.iter().enumerate() {
            buf[1 + 4 * k..5 + 4 * k].copy_from_slice(&i.to_le_bytes());
        }
        self.write_bytes(&buf)?;
        self.faces_written += 1;
        Ok(())
    }

    /// Check the counts, flush, fsync and rename the file onto its final path.
    /// On error the temporary file is removed and nothing is left at the final path.
    pub fn finish(mut self) -> Result<(), MeshError> {
        if self.vertices_written != self.vertex_count || self.faces_written != self.face_count {
            return Err(self.usage(format!(
                "wrote {} vertices and {} triangles, but the header declares {} and {}",
                self.vertices_written, self.faces_written, self.vertex_count, self.face_count
            )));
        }
        let Some(out) = self.out.take() else {
            return Err(self.usage("writer already failed"));
        };
        out.commit().map_err(io_error)
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), MeshError> {
        match self.out.as_mut() {
            Some(out) => out
                .write_all(bytes)
                .map_err(|e| MeshError::io(out.tmp_path(), e)),
            None => Err(self.usage("writer already finished")),
        }
    }

    fn usage(&self, detail: impl Into<String>) -> MeshError {
        MeshError::Usage {
            path: self.path.clone(),
            detail: detail.into(),
        }
    }
}

/// An [`AtomicFile`] error as a [`MeshError`] naming the file it concerns.
fn io_error(e: AtomicFileError) -> MeshError {
    MeshError::io(e.path, e.source)
}

fn header_text(opts: &PlyWriterOptions) -> String {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\n");
    for c in &opts.comments {
        let clean: String = c
            .chars()
            .map(|ch| if ch == '\n' || ch == '\r' { ' ' } else { ch })
            .collect();
        h.push_str("comment ");
        h.push_str(&clean);
        h.push('\n');
    }
    h.push_str(&format!("element vertex {}\n", opts.vertex_count));
    h.push_str("property float x\nproperty float y\nproperty float z\n");
    if opts.attributes.normals {
        h.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if opts.attributes.colors {
        h.push_str(
            "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n",
        );
    }
    if opts.attributes.uvs {
        h.push_str("property float u\nproperty float v\n");
    }
    h.push_str(&format!("element face {}\n", opts.face_count));
    h.push_str("property list uchar uint vertex_indices\nend_header\n");
    h
}

/// Encode `v` into `buf` (48 bytes is the largest layout); returns the length used.
fn encode_vertex(buf: &mut [u8; 48], v: &Vertex, attributes: Attributes) -> usize {
    let mut n = 0;
    let put_f32 = |buf: &mut [u8; 48], n: &mut usize, x: f32| {
        buf[*n..*n + 4].copy_from_slice(&x.to_le_bytes());
        *n += 4;
    };
    for &c in &v.position {
        put_f32(buf, &mut n, c);
    }
    if attributes.normals {
        for &c in &v.normal {
            put_f32(buf, &mut n, c);
        }
    }
    if attributes.colors {
        buf[n..n + 4].copy_from_slice(&v.color);
        n += 4;
    }
    if attributes.uvs {
        for &c in &v.uv {
            put_f32(buf, &mut n, c);
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(v: u64, f: u64) -> PlyWriterOptions {
        PlyWriterOptions {
            vertex_count: v,
            face_count: f,
            ..Default::default()
        }
    }

    fn dir_is_empty(dir: &Path) -> bool {
        std::fs::read_dir(dir)
            .map(|mut d| d.next().is_none())
            .unwrap_or(false)
    }

    #[test]
    fn writes_header_and_body() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut o = opts(3, 1);
        o.comments.push("hello\nworld".into());
        let mut w = PlyWriter::create(&path, &o).unwrap();
        for i in 0..3 {
            w.write_vertex(&Vertex {
                position: [i as f32, 0.0, 1.0],
                ..Default::default()
            })
            .unwrap();
        }
        w.write_triangle([0, 1, 2]).unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.starts_with("ply\nformat binary_little_endian 1.0\ncomment hello world\n"));
        let body = text.find("end_header\n").unwrap() + "end_header\n".len();
        assert_eq!(bytes.len() - body, 3 * 12 + 13);
        // Only the final file remains.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn dropped_writer_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut w = PlyWriter::create(&path, &opts(3, 1)).unwrap();
        w.write_vertex(&Vertex::default()).unwrap();
        drop(w);
        assert!(dir_is_empty(dir.path()));
    }

    #[test]
    fn count_mismatch_fails_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut w = PlyWriter::create(&path, &opts(3, 1)).unwrap();
        for _ in 0..3 {
            w.write_vertex(&Vertex::default()).unwrap();
        }
        let err = w.finish().unwrap_err();
        assert!(err.to_string().contains("declares"), "{err}");
        assert!(dir_is_empty(dir.path()));
    }

    #[test]
    fn misuse_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut w = PlyWriter::create(&path, &opts(3, 2)).unwrap();
        for _ in 0..3 {
            w.write_vertex(&Vertex::default()).unwrap();
        }
        assert!(
            w.write_vertex(&Vertex::default()).is_err(),
            "too many vertices"
        );
        assert!(w.write_triangle([0, 1, 3]).is_err(), "index out of range");
        w.write_triangle([0, 1, 2]).unwrap();
        assert!(
            w.write_vertex(&Vertex::default()).is_err(),
            "vertex after triangle"
        );
        let nan = Vertex {
            position: [f32::NAN, 0.0, 0.0],
            ..Default::default()
        };
        assert!(matches!(w.write_vertex(&nan), Err(MeshError::Usage { .. })));
        w.write_triangle([2, 1, 0]).unwrap();
        assert!(w.write_triangle([0, 1, 2]).is_err(), "too many triangles");
        w.finish().unwrap();
        assert!(path.exists());
    }

    #[test]
    fn non_finite_position_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut w = PlyWriter::create(&path, &opts(1, 0)).unwrap();
        let nan = Vertex {
            position: [0.0, f32::INFINITY, 0.0],
            ..Default::default()
        };
        assert!(matches!(
            w.write_vertex(&nan),
            Err(MeshError::NonFinite { vertex: 0, .. })
        ));
    }

    #[test]
    fn unwritable_directory_is_io_error() {
        let path = Path::new("/nonexistent-dir-tessera/t.ply");
        let err = PlyWriter::create(path, &opts(0, 0)).unwrap_err();
        assert!(matches!(err, MeshError::Io { .. }));
    }
}
