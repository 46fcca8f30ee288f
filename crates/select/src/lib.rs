//! Cut selection for Tessera: which patches of a model to draw for a camera.
//!
//! Pure CPU, no GPU. Selection uses no threads and no I/O besides reading a camera file,
//! and depends only on the node records of `tessera-format` ([`tessera_format::Header`],
//! [`tessera_format::NodeRecord`]), so it runs on a memory-mapped node table, on a table
//! fetched over HTTP, or on hand-built arrays in tests. Extracting a cut (patches read,
//! merged and written as PLY or glTF) is `tessera-extract`'s.
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

pub mod camera;
pub mod edges;
#[doc(hidden)]
pub mod fuzzing;
pub mod merge;
pub mod morph;
pub mod path;
pub mod placement;
pub mod residency;
pub mod select;

pub use camera::{
    clip_planes_along, Camera, CameraError, CameraErrorKind, Frustum, Orbit, ViewBasis,
    CAMERA_FIELDS,
};
pub use edges::{boundary_edges, edge_report, EdgeReport};
pub use merge::{merge_patches, CutMesh, PatchRef};
pub use morph::{group_ratio, morph_ratio, refinement_ratio, DEFAULT_MORPH_WINDOW};
pub use path::{CameraPath, PathError, PATH_FIELDS};
pub use placement::Placement;
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
