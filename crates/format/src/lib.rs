//! The Tessera model file (`.tsr`): one self-describing, versioned, little-endian file
//! holding a binary forest of tetrahedra, one compressed mesh patch per tetrahedron.
//!
//! Everything that reads or writes a model goes through this crate; `docs/format.md` is
//! the byte-level manual and must stay true to the structs below. This crate knows
//! nothing of GPUs or thread policies, and its reader does no I/O of its own: a
//! [`ModelIndex`] is parsed from bytes and patches are decoded from bytes, which come
//! from a [`ByteSource`]. Features: `mmap` (default) adds the memory-mapped local
//! [`Model`] and `verify_structure` over it (`verify_index` checks a model in any
//! [`ByteSource`]); `write` (default) the atomic writer. Without them
//! the crate builds for `wasm32-unknown-unknown`.
//!
//! Layout: [`Header`] (256 bytes) | paged index (a block table, a directory of pages, and
//! zstd-compressed pages of node records, ordered by level then Morton code of the
//! tetrahedron centre; read whole or page by page) | patch data (one encoded patch per
//! node, in node order, each with its own CRC-32).

#[cfg(feature = "write")]
mod atomic;
mod codec;
mod drawing;
mod error;
#[doc(hidden)]
pub mod fuzzing;
mod grid;
mod index;
mod pages;
pub mod ranges;
#[cfg(feature = "mmap")]
mod reader;
mod records;
mod verify;
#[cfg(feature = "write")]
mod writer;

#[cfg(feature = "write")]
pub use atomic::{AtomicFile, AtomicFileError};
pub use codec::texels;
pub use codec::{
    chart_plane_at, chart_plane_uv, decode_patch, decode_patch_with, encode_patch, oct_decode,
    oct_encode, stored_uv, PatchData, PatchHeader, PatchShape, PatchTexture, TextureChart,
    TextureCodec, BC7_ZSTD_LEVEL, MAX_PATCH_CHARTS, MAX_PATCH_TRIANGLES, MAX_PATCH_VERTICES,
    PATCH_CODEC_VERSION, PATCH_FLAG_MORPH, PATCH_FLAG_ZSTD, PATCH_HEADER_BYTES, RECUT_IMAGE,
    UV_FRACTION_BITS,
};
pub use drawing::{
    morph_targets, patch_is_textured, patch_texel_size, source_uv, texel_lod, vertex_chart,
    MorphTarget,
};
pub use error::FormatError;
pub use grid::Grid;
pub use index::{ByteSource, IndexStats, ModelIndex, PatchReader, HEADER_BYTES, NODE_BYTES};
pub use pages::{
    decode_page, encode_page, stored_cone, IndexLayout, PageEntry, DEFAULT_PAGE_NODES,
    DIRECTORY_BLOCK_PAGES, MAX_PAGE_NODES, PAGE_ENTRY_BYTES,
};
#[cfg(feature = "mmap")]
pub use reader::{MappedFile, Model};
pub use records::{
    header_crc32, Header, NodeRecord, ATTR_COLORS, ATTR_NORMALS, ATTR_TEXTURE, ATTR_UVS,
    FORMAT_VERSION, MAGIC, MAX_TEXTURE_DIM, NODE_FLAG_LEAF, NO_NODE,
};
#[cfg(feature = "mmap")]
pub use verify::verify_structure;
pub use verify::{verify_index, VerifyReport, MAX_PROBLEM_MESSAGES};
#[cfg(feature = "write")]
pub use writer::{
    encode_index, replace_index, write_model, write_model_until, PatchSpool, SpooledPatch,
};
