//! Picking at full resolution: the point of a model under the cursor, found on the
//! finest geometry the model file holds, not on whatever coarse level is drawn.
//!
//! CPU only, no threads, no file I/O of its own (it builds for `wasm32-unknown-unknown`):
//! patches come from any [`PatchReader`] (the memory-mapped local model, a remote model
//! over HTTP, a test wrapper).
//!
//! How [`pick`] works:
//!
//! 1. The ray (model coordinates, `f64`) is moved into the index's local frame
//!    (`- cube_origin`, in `f64`) and its direction made unit length.
//! 2. Best-first walk of the forest from the roots, ordered by the distance at which the
//!    ray enters a node's sphere: an internal node is opened when the ray meets its
//!    *saturated* sphere (which holds the patches of all its descendants); a leaf (no
//!    children), or a node whose children the index read so far does not show (a paged
//!    index read in part), is queued with the entry distance into its *tight* sphere
//!    (its own patch's vertices). Spheres are stored in `f32`; the test widens them by a
//!    relative `1e-6` plus one grid step, so it never rejects a sphere the ray touches.
//! 3. Queued leaves are decoded in batches ([`PickOptions::batch`]) with one
//!    [`PatchReader::decode_patches`] call per batch, so a remote reader can fetch
//!    neighbouring patches with one request. Each node of a batch is first passed to
//!    [`PatchReader::advise`], so the memory-mapped model starts all of the batch's
//!    reads at once, of just those bytes. Every triangle is tested exactly: the
//!    watertight ray/triangle test of Woop, Benthin and Wald (2013) in `f64` on the grid
//!    positions (`q * step`, relative to the ray origin). Both faces count (scans are
//!    open surfaces); hits behind the origin (`t < 0`) do not.
//! 4. The walk stops as soon as the nearest hit so far is no farther than the entry
//!    distance of everything still queued: no unseen patch can hold a nearer point.
//!
//! A patch that fails to read or decode is skipped and reported in
//! [`PickStats::skipped`]; a hit farther than where the ray entered a skipped patch's
//! sphere is reported with [`Hit::exact`] false, since the skipped patch might have held
//! a nearer point. [`pick_resident`] tests patches the caller already holds (e.g. those
//! drawn), without reading anything.
//!
//! [`PatchReader`]: tessera_format::PatchReader
//! [`PatchReader::decode_patches`]: tessera_format::PatchReader::decode_patches
//! [`PatchReader::advise`]: tessera_format::PatchReader::advise

#![warn(missing_docs)]

mod ray;
mod traverse;
mod triangle;

pub use ray::Ray;
pub use traverse::{pick, pick_resident, pick_with, PickOptions, DEFAULT_BATCH};

/// The nearest point where a ray meets a model's surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The point, model coordinates: `origin + distance * unit(dir)`.
    pub point: [f64; 3],
    /// Distance from the ray origin along the unit direction, model units (`>= 0`).
    pub distance: f64,
    /// Node whose patch holds the triangle hit.
    pub node: u32,
    /// Triangle of that patch (index into the decoded patch's triangle list).
    pub triangle: u32,
    /// Geometric normal of the triangle (from its grid positions), unit length, turned to
    /// face the ray origin.
    pub normal: [f64; 3],
    /// True when the hit is on the full-resolution geometry: the patch is a leaf, and no
    /// patch skipped for a read or decode error could have held a nearer point. False
    /// when the index read so far (a paged index read in part) shows no deeper level
    /// there, so the hit is on a coarser patch, or when a skipped patch lay in front.
    pub exact: bool,
}

/// What one pick did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PickStats {
    /// Node spheres tested against the ray.
    pub nodes_visited: usize,
    /// Patches read and decoded successfully.
    pub patches_decoded: usize,
    /// Triangles tested against the ray.
    pub triangles_tested: usize,
    /// Patches that could not be read or decoded (corrupt data, a failed remote read):
    /// the node and the error's message. They were skipped; see [`Hit::exact`].
    pub skipped: Vec<(u32, String)>,
}

/// Why a pick could not be attempted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PickError {
    /// The ray's origin is not finite, or its direction is zero or not finite.
    #[error("invalid ray: origin {origin:?}, direction {dir:?} (the origin must be finite, the direction finite and non-zero)")]
    InvalidRay {
        /// The ray's origin.
        origin: [f64; 3],
        /// The ray's direction.
        dir: [f64; 3],
    },
}
