//! Mesh input and output for Tessera, streamed with bounded memory.
//!
//! Importers do not build an in-memory mesh: they push vertices and triangles into a
//! [`MeshVisitor`], so the builder can spill them to disk as they arrive and a file of
//! 10^9 triangles never has to fit in RAM. Every importer reports bad input as a
//! [`MeshError`] naming the file and the problem; problems that can be skipped safely
//! (degenerate faces, for instance) are counted in the [`ImportReport`] instead.

mod common;
mod error;
#[doc(hidden)]
pub mod fuzzing;
mod obj;
mod ply_read;
mod ply_write;
mod progress;
mod source;
mod stl;
mod types;

pub use error::MeshError;
pub use ply_write::{PlyWriter, PlyWriterOptions};
pub use progress::{NoProgress, Progress};
pub use types::{Attributes, ImportReport, MeshHeader, MeshVisitor, Vertex};

use std::path::Path;

/// The input formats Tessera reads, chosen from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFormat {
    Ply,
    Obj,
    Stl,
}

impl InputFormat {
    /// Guess the format from the extension (case-insensitive; a `.gz` after it is looked
    /// through: `scan.ply.gz` is PLY). `None` when unknown.
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let mut ext = path.extension()?.to_str()?.to_ascii_lowercase();
        if ext == "gz" {
            ext = Path::new(path.file_stem()?)
                .extension()?
                .to_str()?
                .to_ascii_lowercase();
        }
        match ext.as_str() {
            "ply" => Some(InputFormat::Ply),
            "obj" => Some(InputFormat::Obj),
            "stl" => Some(InputFormat::Stl),
            _ => None,
        }
    }

    /// The format the first bytes of a (decompressed) file show, where they are
    /// unambiguous: `ply` starts every PLY file. OBJ and STL have no magic number.
    fn from_magic(head: &[u8]) -> Option<InputFormat> {
        head.starts_with(b"ply").then_some(InputFormat::Ply)
    }
}

/// The gzip magic number.
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// The first `n` bytes of a stream (fewer if it is shorter).
fn head_of(r: impl std::io::Read, n: u64) -> std::io::Result<Vec<u8>> {
    let mut head = Vec::new();
    std::io::Read::read_to_end(&mut r.take(n), &mut head)?;
    Ok(head)
}

/// Read a mesh file, streaming its vertices and triangles into `visitor`.
///
/// Calls, in order: `visitor.header(..)` exactly once, then `vertex(..)` and `triangle(..)`
/// calls. A triangle only references vertices already delivered (indices are global,
/// 0-based, in delivery order). Polygons are triangulated (fan). Returns what was read and
/// what was skipped; fails with a [`MeshError`] naming the file on unreadable, truncated
/// or malformed input. An error returned by the visitor is passed through unchanged.
///
/// Gzip-compressed files (by content, whatever the name: `scan.ply.gz`) are read through
/// the inflater as they stream; the format comes from the extension (looked through
/// `.gz`), else from the first bytes where they say it (PLY).
pub fn read_mesh(path: &Path, visitor: &mut dyn MeshVisitor) -> Result<ImportReport, MeshError> {
    use flate2::read::MultiGzDecoder;
    let io = |e| MeshError::io(path, e);
    let open = || std::fs::File::open(path).map_err(io);
    let gzip = head_of(open()?, 2).map_err(io)? == GZIP_MAGIC;
    let open_gz = || open().map(MultiGzDecoder::new);
    let format = match InputFormat::from_path(path) {
        Some(f) => Some(f),
        None if gzip => InputFormat::from_magic(&head_of(open_gz()?, 3).map_err(io)?),
        None => InputFormat::from_magic(&head_of(open()?, 3).map_err(io)?),
    };
    let Some(format) = format else {
        return Err(MeshError::UnknownFormat {
            path: path.to_path_buf(),
        });
    };
    match (format, gzip) {
        (InputFormat::Ply, false) => ply_read::read_ply(path, visitor),
        (InputFormat::Obj, false) => obj::read_obj(path, visitor),
        (InputFormat::Stl, false) => stl::read_stl(path, visitor),
        (InputFormat::Ply, true) => ply_read::read_ply_from(path, open_gz()?, visitor),
        (InputFormat::Obj, true) => obj::read_obj_from(path, open_gz, visitor),
        (InputFormat::Stl, true) => {
            // Binary STL is told from ASCII by its size: inflate once to count.
            let size = std::io::copy(&mut open_gz()?, &mut std::io::sink()).map_err(io)?;
            stl::read_stl_from(path, size, open_gz()?, open_gz, visitor)
        }
    }
}
