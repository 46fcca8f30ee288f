//! STL importer (ascii and binary).
//!
//! STL is what CAD tools and 3D scanners export, but it is a triangle soup: every facet
//! repeats its three corner positions. Tessera needs an indexed mesh, so corners with
//! bit-identical positions are welded through a hash map. That map holds every distinct
//! position (about 40 bytes each), so memory grows with the number of unique vertices;
//! vertices are still delivered to the visitor as soon as they are first seen. Facet
//! normals are per face, not per vertex, and are dropped (`attributes.normals = false`).

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::common::{finish_report, PolygonEmitter};
use crate::source::{ReadErr, Source};
use crate::{ImportReport, MeshError, MeshHeader, MeshVisitor, Vertex};

/// Binary STL: 80-byte header + u32 facet count, then 50 bytes per facet.
const BINARY_HEADER: u64 = 84;
const FACET_BYTES: u64 = 50;

/// Read the STL file at `path` into `visitor`.
pub(crate) fn read_stl(
    path: &Path,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let open = || File::open(path).map_err(|e| MeshError::io(path, e));
    let file = open()?;
    let size = file.metadata().map_err(|e| MeshError::io(path, e))?.len();
    read_stl_from(path, size, file, open, visitor)
}

/// Read STL data of `size` bytes: the first 512 bytes of `first` decide ascii or binary,
/// then the stream `open_again` returns is read from the start; `path` is only used in
/// messages.
pub(crate) fn read_stl_from<R: Read>(
    path: &Path,
    size: u64,
    first: R,
    open_again: impl FnOnce() -> Result<R, MeshError>,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let mut head = Vec::with_capacity(512);
    first
        .take(512)
        .read_to_end(&mut head)
        .map_err(|e| MeshError::io(path, e))?;
    let declared = head
        .get(80..84)
        .map(|b| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
    let is_binary_size = declared.is_some_and(|n| size == BINARY_HEADER + FACET_BYTES * n);
    let mut src = Source::new(open_again()?);
    let mut welder = Welder::new(path);
    if !is_binary_size && looks_like_ascii(&head) {
        visitor.header(&MeshHeader::default())?;
        read_ascii(&mut src, &mut welder, visitor)?;
    } else {
        let Some(n) = declared else {
            return Err(MeshError::truncated(
                path,
                "binary STL header needs 84 bytes",
            ));
        };
        let expected = BINARY_HEADER + FACET_BYTES * n;
        if size > expected {
            tracing::warn!(
                "{}: ignoring {} bytes after the last STL facet",
                path.display(),
                size - expected
            );
        }
        visitor.header(&MeshHeader {
            face_count: Some(n),
            ..MeshHeader::default()
        })?;
        read_binary(&mut src, n, &mut welder, visitor)?;
    }
    finish_report(path, welder.report)
}

/// `solid` followed by text (binary files sometimes start with `solid` too), after a
/// UTF-8 byte order mark if there is one.
fn looks_like_ascii(head: &[u8]) -> bool {
    let head = head.strip_prefix(&[0xEF, 0xBB, 0xBF]).unwrap_or(head);
    head.trim_ascii_start().starts_with(b"solid")
        && head
            .iter()
            .all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace())
}

/// Welds corners with identical positions and turns facets into indexed triangles.
struct Welder<'p> {
    path: &'p Path,
    /// Position bit patterns → output index (memory: one entry per unique vertex).
    map: HashMap<[u32; 3], u32>,
    emitter: PolygonEmitter,
    corners: Vec<u32>,
    /// Corners seen so far (names the culprit of a NaN).
    corner_no: u64,
    report: ImportReport,
}

impl<'p> Welder<'p> {
    fn new(path: &'p Path) -> Self {
        Welder {
            path,
            map: HashMap::new(),
            emitter: PolygonEmitter::default(),
            corners: Vec::with_capacity(4),
            corner_no: 0,
            report: ImportReport::default(),
        }
    }

    /// Add one corner of the current facet.
    fn corner(&mut self, p: [f32; 3], visitor: &mut dyn MeshVisitor) -> Result<(), MeshError> {
        if !p.iter().all(|c| c.is_finite()) {
            return Err(MeshError::NonFinite {
                path: self.path.to_path_buf(),
                vertex: self.corner_no,
            });
        }
        self.corner_no += 1;
        // `+ 0.0` turns -0.0 into 0.0 so both weld together.
        let key = p.map(|c| (c + 0.0).to_bits());
        let index = match self.map.get(&key) {
            Some(&i) => i,
            None => {
                let i = u32::try_from(self.map.len()).map_err(|_| MeshError::TooManyVertices {
                    path: self.path.to_path_buf(),
                })?;
                visitor.vertex(&Vertex {
                    position: p,
                    ..Vertex::default()
                })?;
                self.report.vertices += 1;
                self.map.insert(key, i);
                i
            }
        };
        self.corners.push(index);
        Ok(())
    }

    /// Close the current facet.
    fn end_facet(&mut self, visitor: &mut dyn MeshVisitor) -> Result<(), MeshError> {
        let r = self.emitter.emit(&self.corners, visitor, &mut self.report);
        self.corners.clear();
        r
    }
}

fn read_binary<R: Read>(
    src: &mut Source<R>,
    n: u64,
    welder: &mut Welder<'_>,
    visitor: &mut dyn MeshVisitor,
) -> Result<(), MeshError> {
    let path = welder.path;
    let err = |e: ReadErr, what: String| match e {
        ReadErr::Io(e) => MeshError::io(path, e),
        _ => MeshError::truncated(path, what),
    };
    src.skip(BINARY_HEADER)
        .map_err(|e| err(e, "the 84-byte binary STL header".into()))?;
    for i in 0..n {
        let rec = src
            .take(FACET_BYTES as usize)
            .map_err(|e| err(e, format!("expected facet {i} of {n}")))?;
        let mut corners = [[0f32; 3]; 3];
        for (k, c) in corners.iter_mut().enumerate() {
            for (j, x) in c.iter_mut().enumerate() {
                let off = 12 + 12 * k + 4 * j;
                let mut b = [0u8; 4];
                b.copy_from_slice(rec.get(off..off + 4).unwrap_or(&[0; 4]));
                *x = f32::from_le_bytes(b);
            }
        }
        for c in corners {
            welder.corner(c, visitor)?;
        }
        welder.end_facet(visitor)?;
    }
    Ok(())
}

fn read_ascii<R: Read>(
    src: &mut Source<R>,
    welder: &mut Welder<'_>,
    visitor: &mut dyn MeshVisitor,
) -> Result<(), MeshError> {
    let path = welder.path;
    let mut line = Vec::new();
    let mut in_facet = false;
    loop {
        let more = src.line_into(&mut line, 1 << 16).map_err(|e| match e {
            ReadErr::Io(e) => MeshError::io(path, e),
            other => MeshError::malformed(path, format!("line {}", src.line), format!("{other:?}")),
        })?;
        if !more {
            break;
        }
        let at = || format!("line {}", src.line.saturating_sub(1));
        let text = String::from_utf8_lossy(&line);
        let mut w = text.split_ascii_whitespace();
        match w.next() {
            None | Some("solid" | "endsolid" | "outer" | "endloop") => {}
            Some("facet") => {
                in_facet = true;
                welder.corners.clear();
            }
            Some("vertex") if in_facet => {
                let p = parse_xyz(w).ok_or_else(|| {
                    MeshError::malformed(path, at(), format!("bad vertex line '{}'", text.trim()))
                })?;
                welder.corner(p, visitor)?;
            }
            Some("endfacet") if in_facet => {
                in_facet = false;
                welder.end_facet(visitor)?;
            }
            Some(other) => {
                return Err(MeshError::malformed(
                    path,
                    at(),
                    format!("unexpected '{other}' in ascii STL"),
                ))
            }
        }
    }
    if in_facet {
        return Err(MeshError::truncated(
            path,
            "file ends inside a facet (expected 'endfacet')",
        ));
    }
    Ok(())
}

fn parse_xyz<'a>(mut w: impl Iterator<Item = &'a str>) -> Option<[f32; 3]> {
    let mut p = [0f32; 3];
    for c in &mut p {
        *c = w.next()?.parse().ok()?;
    }
    w.next().is_none().then_some(p)
}
