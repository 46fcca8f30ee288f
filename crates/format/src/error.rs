//! The one error type of this crate.
//!
//! Model files come from disk and may be truncated, corrupted or written by a newer
//! Tessera; every such case must surface as a [`FormatError`] (never a panic), with a
//! message precise enough to tell a user which file, node or check failed.

use std::path::PathBuf;

use crate::records::NO_NODE;

/// Everything that can go wrong reading, writing or decoding a model file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// An operating-system I/O error, with the file it concerns where known.
    ///
    /// The cause is in the message and deliberately not also the error's `source()`:
    /// anyhow's `{:#}` (the CLI's) prints every link of a chain, so it would print twice.
    #[error("I/O error{}: {cause}", path_suffix(path))]
    Io {
        path: Option<PathBuf>,
        cause: std::io::Error,
    },
    /// The write was stopped (Ctrl-C) before it finished; nothing was written.
    #[error("interrupted before the model was written (nothing written)")]
    Interrupted,
    /// The file does not start with [`crate::MAGIC`]: not a Tessera model.
    #[error("not a Tessera model file (bad magic bytes)")]
    BadMagic,
    /// The file was written by a newer format version than this code reads.
    #[error("unsupported format version {found} (this build reads version {supported}): it was written by a newer Tessera; update Tessera to open it")]
    UnsupportedVersion { found: u32, supported: u32 },
    /// The file was written by an older format version, which this code no longer reads.
    #[error("model file format version {found} is older than this Tessera's ({supported}): rebuild the model from its source mesh with `tessera build`")]
    OldVersion { found: u32, supported: u32 },
    /// The file is shorter than its header (or the fixed header size) says.
    #[error("file truncated: expected {expected_bytes} bytes, found {actual_bytes}")]
    Truncated {
        expected_bytes: u64,
        actual_bytes: u64,
    },
    /// The header's CRC-32 does not match its bytes.
    #[error("header checksum mismatch (corrupt header)")]
    HeaderChecksum,
    /// The header's checksum is right but its fields are inconsistent.
    #[error("invalid header: {detail}")]
    InvalidHeader { detail: String },
    /// A CRC-32 of the paged index (block table, a directory block, a page) does not
    /// match its bytes.
    #[error("index checksum mismatch in the {part} (corrupt index)")]
    IndexChecksum { part: String },
    /// An index page has the right checksum but does not decode.
    #[error("corrupt index page {page}: {detail}")]
    CorruptIndexPage { page: u64, detail: String },
    /// A patch's CRC-32 does not match its bytes.
    #[error("patch checksum mismatch for node {node} (corrupt patch data)")]
    PatchChecksum { node: u32 },
    /// A node's patch byte range lies outside the patch data section.
    #[error("patch of node {node} lies outside the patch data section")]
    PatchOutOfRange { node: u32 },
    /// A patch's bytes have the right checksum but do not decode to a valid patch.
    #[error("corrupt patch{}: {detail}", node_suffix(*node))]
    CorruptPatch { node: u32, detail: String },
    /// A node record is inconsistent (bad links, out-of-range indices, ...).
    #[error("invalid node {node}: {detail}")]
    InvalidNode { node: u32, detail: String },
    /// A caller passed inconsistent arguments (e.g. to [`crate::write_model`]).
    #[error("invalid input: {detail}")]
    InvalidInput { detail: String },
}

impl FormatError {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FormatError::Io {
            path: Some(path.into()),
            cause: source,
        }
    }

    /// Attaches a node index to errors that carry one but were produced without it
    /// (e.g. by the standalone [`crate::decode_patch`], which reports [`NO_NODE`]).
    pub fn with_node(self, node: u32) -> Self {
        match self {
            FormatError::CorruptPatch {
                node: NO_NODE,
                detail,
            } => FormatError::CorruptPatch { node, detail },
            other => other,
        }
    }
}

impl From<std::io::Error> for FormatError {
    fn from(source: std::io::Error) -> Self {
        FormatError::Io {
            path: None,
            cause: source,
        }
    }
}

fn path_suffix(path: &Option<PathBuf>) -> String {
    match path {
        Some(p) => format!(" on {}", p.display()),
        None => String::new(),
    }
}

fn node_suffix(node: u32) -> String {
    if node == NO_NODE {
        String::new()
    } else {
        format!(" of node {node}")
    }
}
