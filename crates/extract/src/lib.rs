//! Cut extraction, the offline output of a model (`tessera extract`): a cut chosen by
//! `tessera-select` (`select_cut` for a camera or an error, `uniform_level_cut` for a
//! level) has its patches decoded in parallel and CRC checked, merged into one mesh
//! (bit-identical border vertices welded: positions share one global grid, so the
//! merged cut is crack-free) and edge-checked ([`extract_nodes`]), then written:
//!
//! - [`write_cut_ply`]: a binary PLY in model coordinates (through `tessera-mesh`'s
//!   atomic writer);
//! - [`write_cut_gltf`] (`gltf_write`): glTF 2.0, `.glb` or `.gltf` with its buffer
//!   embedded: the welded mesh with colours, or a textured model's patches, each with
//!   its own texture.
//!
//! Its own crate so that selection stays pure CPU with no threads and no file output
//! (the run-time front ends need only `tessera-select`).

pub mod extract;
pub mod gltf_write;

pub use extract::{decode_nodes, extract_nodes, extract_nodes_keeping, write_cut_ply, Extracted};
pub use gltf_write::{
    encode_gltf, write_cut_gltf, GltfContainer, GltfContent, GltfFrame, GltfSummary,
};
