//! Cut selection for Tessera: which patches of a model to draw for a camera.
//!
//! Pure CPU, no GPU. Selection uses no threads and no I/O besides reading a camera file,
//! and depends only on the node records of `tessera-format` ([`tessera_format::Header`],
//! [`tessera_format::NodeRecord`]), so it runs on a memory-mapped node table, on a table
//! fetched over HTTP, or on hand-built arrays in tests. Only `extract` (feature
//! `extract`, off by default) reads patches (through [`tessera_format::Model`], in
//! parallel) and writes a file (a PLY, through `tessera-mesh`).
//!
//! - [`camera`]: the shared camera and its JSON format (`docs/camera.md`), view matrix
//!   and frustum in a model's local frame.
//! - [`select`]: the stateless top-down traversal of ATP section 4 ([`select_cut`]) with
//!   frustum, backface and screen-space-error decisions; uniform level cuts.
//! - [`residency`]: residency-aware selection that never waits ([`select_resident`]),
//!   prefetch ([`prefetch_set`], [`predict_camera`]) and eviction with hysteresis
//!   ([`should_unload`]) on a compact [`NodeView`] of the node table.
//! - [`merge`]: welding the decoded patches of a cut into one mesh ([`merge_patches`]).
//! - [`edges`]: edge-use counts of a mesh ([`edge_report`]), the crack detector.
//! - `extract` (feature `extract`): a chosen cut decoded, merged and edge-checked as one
//!   mesh (`extract_nodes`), written as a PLY in model coordinates (`write_cut_ply`).
//! - `gltf_write` (feature `extract`): a cut written as glTF 2.0, `.glb` or `.gltf`
//!   (`write_cut_gltf`): the welded mesh with colours, or a textured model's patches
//!   with their own textures.

pub mod camera;
pub mod edges;
#[cfg(feature = "extract")]
pub mod extract;
#[doc(hidden)]
pub mod fuzzing;
#[cfg(feature = "extract")]
pub mod gltf_write;
pub mod merge;
pub mod morph;
pub mod path;
pub mod residency;
pub mod select;

pub use camera::{
    clip_planes_along, Camera, CameraError, CameraErrorKind, Frustum, Orbit, ViewBasis,
    CAMERA_FIELDS,
};
pub use edges::{edge_report, EdgeReport};
#[cfg(feature = "extract")]
pub use extract::{decode_nodes, extract_nodes, extract_nodes_keeping, write_cut_ply, Extracted};
#[cfg(feature = "extract")]
pub use gltf_write::{write_cut_gltf, GltfContainer, GltfContent, GltfSummary};
pub use merge::{merge_patches, CutMesh, PatchRef};
pub use morph::{group_ratio, morph_ratio, refinement_ratio, DEFAULT_MORPH_WINDOW};
pub use path::{CameraPath, PathError, PATH_FIELDS};
pub use residency::{
    predict_camera, prefetch_set, select_resident, should_unload, wants_refinement, HotNode,
    NodeView, PrefetchOptions, Selection,
};
pub use select::{
    closest_distance, is_backfacing, is_leaf, needs_refinement, select_cut, select_cut_into,
    traverse_into, uniform_level_cut, Criterion, Cut, Decision, ViewParams,
};

#[cfg(test)]
mod proptests;
