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

mod records;

pub use records::{
    Header, NodeRecord, ATTR_COLORS, ATTR_NORMALS, ATTR_UVS, FORMAT_VERSION, MAGIC, NODE_FLAG_LEAF,
    NO_NODE,
};
