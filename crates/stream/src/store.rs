//! Where resident patches live: the [`ResidentStore`] trait (the GPU cache in
//! `tessera-render`; an in-memory fake in the tests).
//!
//! The store is mechanics only: it uploads and frees single patches and says how many
//! bytes a patch takes. Which patches to hold, for how long, and what to evict when is
//! the scheduler's decision ([`crate::Scheduler`]), under its own byte budget.

use tessera_format::PatchData;

/// Why an upload did not happen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreError {
    /// No room now (the scheduler evicts something and tries again, or stops
    /// uploading this frame).
    Full,
    /// The patch alone is larger than the store can ever hold.
    TooBig,
}

/// Resident patches, by node. See the module docs.
pub trait ResidentStore {
    /// Bytes `patch` would take once uploaded (what the scheduler's budget counts).
    fn bytes_for(&self, patch: &PatchData) -> u64;
    /// Bytes a patch of `vertices` vertices and `triangles` triangles would take, from
    /// the index alone (the demand of a view, [`crate::FrameStats::wanted_bytes`], counts
    /// patches not loaded yet). Default: 24 bytes a vertex and 4 an index, as the GPU
    /// cache and [`CountingStore`] count.
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        u64::from(vertices) * 24 + u64::from(triangles) * 12
    }
    /// Bytes a patch texture of `size` texels (`NodeRecord::texture_size`, `[0, 0]` for
    /// none) would take once uploaded, from the index alone; added to
    /// [`ResidentStore::estimate_bytes`] for the demand. Default: 0 (a store that holds
    /// no textures, as [`CountingStore`]).
    fn estimate_texture_bytes(&self, size: [u16; 2]) -> u64 {
        let _ = size;
        0
    }
    /// Whether `patches` (one residency group) would fit now, together: the scheduler
    /// uploads a group whole or not at all, and makes room (evicts) before it starts.
    /// A store whose space is not one pool (a GPU cache's vertex and index buffers)
    /// can be full before the scheduler's byte budget is reached. Default: true (the
    /// upload itself answers [`StoreError::Full`]).
    fn has_room(&self, patches: &[&PatchData]) -> bool {
        let _ = patches;
        true
    }
    /// Makes `node`'s patch resident; returns the bytes it takes. `siblings`: the other
    /// patches of its residency group at hand (those loaded with it; may be incomplete,
    /// or empty): a store that draws morph targets takes a target's attributes from the
    /// sibling holding the surviving vertex when the patch itself does not; other
    /// stores ignore them.
    fn upload_in_group(
        &mut self,
        node: u32,
        patch: &PatchData,
        siblings: &[&PatchData],
    ) -> Result<u64, StoreError>;
    /// [`ResidentStore::upload_in_group`] with no sibling at hand.
    fn upload(&mut self, node: u32, patch: &PatchData) -> Result<u64, StoreError> {
        self.upload_in_group(node, patch, &[])
    }
    /// Frees `node`'s patch (nothing if not resident).
    fn evict(&mut self, node: u32);
    /// Bytes held by resident patches.
    fn resident_bytes(&self) -> u64;
    /// Hands staged uploads to the device (a GPU store submits them so their staging
    /// memory is released). Default: nothing.
    fn flush(&mut self) {}
}

/// A borrowed store is a store (a scene of one model hands its store out by
/// reference: [`crate::OneStore`]). Every method forwards, defaults included.
impl<R: ResidentStore + ?Sized> ResidentStore for &mut R {
    fn bytes_for(&self, patch: &PatchData) -> u64 {
        (**self).bytes_for(patch)
    }
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        (**self).estimate_bytes(vertices, triangles)
    }
    fn estimate_texture_bytes(&self, size: [u16; 2]) -> u64 {
        (**self).estimate_texture_bytes(size)
    }
    fn has_room(&self, patches: &[&PatchData]) -> bool {
        (**self).has_room(patches)
    }
    fn upload_in_group(
        &mut self,
        node: u32,
        patch: &PatchData,
        siblings: &[&PatchData],
    ) -> Result<u64, StoreError> {
        (**self).upload_in_group(node, patch, siblings)
    }
    fn evict(&mut self, node: u32) {
        (**self).evict(node)
    }
    fn resident_bytes(&self) -> u64 {
        (**self).resident_bytes()
    }
    fn flush(&mut self) {
        (**self).flush()
    }
}

/// A store that holds nothing but counts: bytes as a GPU store would take them
/// (24 bytes a vertex, 4 an index). For running the scheduler without a device:
/// policy tests, the bench module (`crate::bench`), benchmarks of the streaming core.
#[derive(Debug, Default)]
pub struct CountingStore {
    bytes: u64,
    held: rustc_hash::FxHashMap<u32, u64>,
}

impl CountingStore {
    /// Nodes held.
    pub fn len(&self) -> usize {
        self.held.len()
    }
    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }
}

impl ResidentStore for CountingStore {
    fn bytes_for(&self, p: &PatchData) -> u64 {
        p.positions.len() as u64 * 24 + p.indices.len() as u64 * 4
    }
    fn upload_in_group(
        &mut self,
        node: u32,
        p: &PatchData,
        _siblings: &[&PatchData],
    ) -> Result<u64, StoreError> {
        let b = self.bytes_for(p);
        if let Some(old) = self.held.insert(node, b) {
            self.bytes -= old;
        }
        self.bytes += b;
        Ok(b)
    }
    fn evict(&mut self, node: u32) {
        self.bytes -= self.held.remove(&node).unwrap_or(0);
    }
    fn resident_bytes(&self) -> u64 {
        self.bytes
    }
}
