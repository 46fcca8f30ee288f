//! The Tessera model file (`.tsr`): one self-describing, versioned, little-endian file
//! holding a binary forest of tetrahedra, one compressed mesh patch per tetrahedron.
//!
//! Everything that reads or writes a model goes through this crate; `docs/format.md` is
//! the byte-level manual and must stay true to the structs below. This crate knows
//! nothing of GPUs or thread policies.
//!
//! Layout: [`Header`] (256 bytes) | node table (`node_count` x [`NodeRecord`], 128 bytes
//! each, ordered by level then Morton code of the tetrahedron centre) | patch data (one
//! encoded patch per node, in node-table order, each with its own CRC-32).

mod codec;
mod error;
mod grid;
mod reader;
mod records;
mod verify;
mod writer;

pub use codec::{
    decode_patch, encode_patch, oct_decode, oct_encode, PatchData, MAX_PATCH_TRIANGLES,
    MAX_PATCH_VERTICES, PATCH_CODEC_VERSION, PATCH_FLAG_MORPH, PATCH_FLAG_ZSTD, PATCH_HEADER_BYTES,
};
pub use error::FormatError;
pub use grid::Grid;
pub use reader::Model;
pub use records::{
    Header, NodeRecord, ATTR_COLORS, ATTR_NORMALS, ATTR_UVS, FORMAT_VERSION, MAGIC, NODE_FLAG_LEAF,
    NO_NODE,
};
pub use verify::{verify_structure, VerifyReport, MAX_PROBLEM_MESSAGES};
pub use writer::{header_crc32, write_model, PatchSpool, SpooledPatch};
