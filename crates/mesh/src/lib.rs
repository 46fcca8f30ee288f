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
    /// Guess the format from the extension (case-insensitive). `None` when unknown.
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "ply" => Some(InputFormat::Ply),
            "obj" => Some(InputFormat::Obj),
            "stl" => Some(InputFormat::Stl),
            _ => None,
        }
    }
}

/// Read a mesh file, streaming its vertices and triangles into `visitor`.
///
/// Calls, in order: `visitor.header(..)` exactly once, then `vertex(..)` and `triangle(..)`
/// calls. A triangle only references vertices already delivered (indices are global,
/// 0-based, in delivery order). Polygons are triangulated (fan). Returns what was read and
/// what was skipped; fails with a [`MeshError`] naming the file on unreadable, truncated
/// or malformed input. An error returned by the visitor is passed through unchanged.
pub fn read_mesh(path: &Path, visitor: &mut dyn MeshVisitor) -> Result<ImportReport, MeshError> {
    match InputFormat::from_path(path) {
        Some(InputFormat::Ply) => ply_read::read_ply(path, visitor),
        Some(InputFormat::Obj) => obj::read_obj(path, visitor),
        Some(InputFormat::Stl) => stl::read_stl(path, visitor),
        None => Err(MeshError::UnknownFormat {
            path: path.to_path_buf(),
        }),
    }
}
