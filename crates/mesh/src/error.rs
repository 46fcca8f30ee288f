//! The one error type of the mesh crate.
//!
//! Every variant names the file it concerns and displays as a single line
//! `"{path}: {problem}"`, so a user who feeds Tessera a broken file learns which file and
//! what is wrong with it without reading a backtrace.

use std::path::PathBuf;

/// Why a mesh could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The operating system refused a read, write, rename, ...
    ///
    /// The cause is part of the message and deliberately not also the error's
    /// [`source`](std::error::Error::source): a chain printer (anyhow's `{:#}`, which the
    /// CLI uses) prints every link of the chain, so an error that shows its cause *and*
    /// returns it prints it twice ("x.ply: Is a directory (os error 21): Is a directory
    /// (os error 21)"), and a wrapper that shows only our message (`#[error("{0}")]`
    /// without `#[source]`) would lose it if the message left it out. The field is not
    /// called `source`, which thiserror would take for the source.
    #[error("{}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// The file extension is not one of `.ply`, `.obj`, `.stl`, `.gltf`, `.glb` (or the
    /// content matches none).
    #[error("{}: unknown mesh format (expected .ply, .obj, .stl, .gltf or .glb; PLY, OBJ and STL optionally .gz)", path.display())]
    UnknownFormat { path: PathBuf },
    /// The file ends before the data its header (or syntax) promises.
    #[error("{}: file is truncated: {detail}", path.display())]
    Truncated { path: PathBuf, detail: String },
    /// The content violates the format. `line_or_offset` is e.g. `line 12` or `byte 4096`.
    #[error("{}: {line_or_offset}: {detail}", path.display())]
    Malformed {
        path: PathBuf,
        line_or_offset: String,
        detail: String,
    },
    /// A face references a vertex that does not exist.
    #[error(
        "{}: {line_or_offset}: vertex index {index} out of range (the mesh has {vertex_count} vertices)",
        path.display()
    )]
    IndexOutOfRange {
        path: PathBuf,
        line_or_offset: String,
        index: i64,
        vertex_count: u64,
    },
    /// A vertex position is NaN or infinite.
    #[error("{}: vertex {vertex} has a non-finite coordinate (NaN or infinity)", path.display())]
    NonFinite { path: PathBuf, vertex: u64 },
    /// A texture coordinate is NaN or infinite (it would be kept and written back out).
    #[error("{}: texture coordinate {index} is not finite (NaN or infinity)", path.display())]
    NonFiniteUv { path: PathBuf, index: u64 },
    /// The file holds no triangle at all (after skipping degenerate faces).
    #[error("{}: the mesh has no triangles", path.display())]
    Empty { path: PathBuf },
    /// More vertices than a `u32` index can address.
    #[error("{}: more than {} vertices; Tessera indexes vertices with 32 bits", path.display(), u32::MAX)]
    TooManyVertices { path: PathBuf },
    /// A writer was used against its contract (counts, order).
    #[error("{}: {detail}", path.display())]
    Usage { path: PathBuf, detail: String },
    /// A file the input names (a glTF buffer or image, an OBJ material library or
    /// texture) that may not be read: outside the allowed root, not a regular file, or
    /// too large (see [`crate::AssetPolicy`]). `detail` names the reference and what to
    /// do.
    #[error("{}: {detail}", path.display())]
    Refused { path: PathBuf, detail: String },
    /// The reader stopped because [`crate::MeshVisitor::cancelled`] said so (Ctrl-C).
    #[error("interrupted")]
    Interrupted,
    /// An error raised by a [`crate::MeshVisitor`], passed through unchanged.
    #[error("{0}")]
    Visitor(String),
}

impl MeshError {
    /// Shorthand for [`MeshError::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> MeshError {
        MeshError::Io {
            path: path.into(),
            cause: source,
        }
    }

    /// Shorthand for [`MeshError::Malformed`].
    pub fn malformed(
        path: impl Into<PathBuf>,
        line_or_offset: impl Into<String>,
        detail: impl Into<String>,
    ) -> MeshError {
        MeshError::Malformed {
            path: path.into(),
            line_or_offset: line_or_offset.into(),
            detail: detail.into(),
        }
    }

    /// Shorthand for [`MeshError::Truncated`].
    pub fn truncated(path: impl Into<PathBuf>, detail: impl Into<String>) -> MeshError {
        MeshError::Truncated {
            path: path.into(),
            detail: detail.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_one_line_starting_with_path() {
        let errors = [
            MeshError::io("/a/b.ply", std::io::Error::other("boom")),
            MeshError::UnknownFormat {
                path: "/a/b.xyz".into(),
            },
            MeshError::truncated("/a/b.ply", "expected 3 vertices, got 2"),
            MeshError::malformed("/a/b.obj", "line 3", "bad number"),
            MeshError::IndexOutOfRange {
                path: "/a/b.obj".into(),
                line_or_offset: "line 4".into(),
                index: 7,
                vertex_count: 3,
            },
            MeshError::NonFinite {
                path: "/a/b.ply".into(),
                vertex: 2,
            },
            MeshError::Empty {
                path: "/a/b.ply".into(),
            },
            MeshError::TooManyVertices {
                path: "/a/b.ply".into(),
            },
        ];
        for e in errors {
            let s = e.to_string();
            assert!(s.starts_with("/a/b."), "{s}");
            assert!(!s.contains('\n'), "{s}");
        }
    }
}
