//! The GPU patch cache: two big buffers (vertices, indices) carved up by range
//! allocators, a byte budget, and least-recently-used eviction.
//!
//! Why two big buffers and not one buffer per patch: a cut is hundreds to thousands of
//! patches; one buffer per patch means one allocation per upload and a vertex/index
//! buffer rebind per draw, and GPU allocators round small buffers up. Here a patch is a
//! vertex range and an index range; every draw uses the same two bindings and picks its
//! patch with `base_vertex` and the index range. The allocator is `range-alloc` (the
//! gfx-rs crate wgpu's own backends use), so nothing of this is hand-written but the
//! bookkeeping.
//!
//! The cache is mechanics only: which patches to hold and what to evict is decided by
//! `tessera_stream::Scheduler`, through [`GpuStore`], the cache's `ResidentStore`
//! face. The buffers start small and grow on demand up to the budget.
//!
//! Several models share one cache: slots are keyed by (model, node), so the buffers,
//! the allocators and their free space are shared, and each model's scheduler sees its
//! own [`GpuStore`] (its uploads, evictions and bytes). The single-model methods
//! (`slot`, `upload`, `evict`, ...) are model 0's.

use std::ops::Range;

use range_alloc::RangeAllocator;
use rustc_hash::FxHashMap;
use tessera_format::PatchData;
use tessera_stream::{ResidentStore, StoreError};

/// One vertex as the shader reads it, 40 bytes: the vertex and its morph target (the
/// position and attributes it takes in its parent's shape, see `tessera_select::morph`).
///
/// Size: the target adds 16 bytes to the 24 a vertex took without morphing: its
/// position (f32 x 3, the same grid point the file stores, exact in the local frame),
/// and octahedral normals (own and target as snorm16 x 2 each: 4 bytes apiece instead
/// of 8 for one snorm16 xyz + tag, so the second normal costs nothing). The node tag
/// moved to the per-draw instance data ([`Slot::tag`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuVertex {
    /// Local frame (model coordinates minus the cube origin).
    pub position: [f32; 3],
    /// Morph target, local frame; equal to `position` for survivors, locked border
    /// vertices and roots.
    pub target: [f32; 3],
    /// Unit normal, octahedral, snorm16 x 2 ([`oct_snorm16`]).
    pub normal: [i16; 2],
    /// The target's normal, same coding (the surviving vertex's normal when it is in
    /// the patch, else the vertex's own).
    pub target_normal: [i16; 2],
    /// RGBA8, white when the model has no colours.
    pub color: [u8; 4],
    /// The target's colour (same rule as the normal).
    pub target_color: [u8; 4],
}

/// Bytes per vertex.
pub const VERTEX_BYTES: u64 = std::mem::size_of::<GpuVertex>() as u64;
const _: () = assert!(VERTEX_BYTES == 40);
/// Bytes per index (u32 indices: patches may exceed 65536 vertices on odd inputs).
pub const INDEX_BYTES: u64 = 4;

/// The tag of a node's draw ([`Slot::tag`]): its level in the top 6 bits (levels above
/// 63 share 63), a hash of (model, node) in the low 10, for the colour-by-node and
/// by-level modes.
pub fn vertex_tag(model: u32, node: u32, level: u8) -> u32 {
    let mut h = (node ^ model.wrapping_mul(0x9E37_79B9)).wrapping_mul(0x85EB_CA6B);
    h ^= h >> 13;
    (u32::from(level.min(63)) << 10) | (h & 0x3FF)
}

/// A unit vector as octahedral snorm16 x 2 (the shader's `oct_decode` inverts it; the
/// zero vector, of a patch without normals (the builder always writes them), gives
/// (0, 0): +z).
pub fn oct_snorm16(n: [f32; 3]) -> [i16; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if l1.is_nan() || l1 <= 0.0 {
        return [0, 0];
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let sx = if x >= 0.0 { 1.0 } else { -1.0 };
        let sy = if y >= 0.0 { 1.0 } else { -1.0 };
        (x, y) = ((1.0 - y.abs()) * sx, (1.0 - x.abs()) * sy);
    }
    let q = |v: f32| (v.clamp(-1.0, 1.0) * 32767.0).round() as i16;
    [q(x), q(y)]
}

/// Converts a decoded patch to GPU vertices, positions in the local frame
/// (`grid * quant_step`), morph targets with their attributes: a target is a surviving
/// vertex of the parent's simplification, whose normal and colour are taken from the
/// vertex at that position in this patch, else in one of `siblings` (the other patches
/// of its residency group: about 8% of the moving vertices of the Bunny and the Dragon
/// move onto a survivor of a sibling); one hash lookup per moving vertex, at upload
/// only. A survivor found nowhere lends nothing: the vertex keeps its own attributes
/// while it moves.
pub fn gpu_vertices(
    p: &PatchData,
    siblings: &[&PatchData],
    quant_step: f64,
    out: &mut Vec<GpuVertex>,
) {
    out.clear();
    out.reserve(p.positions.len());
    let local = |q: &[u32; 3]| {
        [
            (q[0] as f64 * quant_step) as f32,
            (q[1] as f64 * quant_step) as f32,
            (q[2] as f64 * quant_step) as f32,
        ]
    };
    let attributes = |p: &PatchData, i: usize| {
        let n = match p.normals.get(i) {
            Some(&n) if p.normals.len() == p.positions.len() => oct_snorm16(n),
            _ => [0, 0],
        };
        (n, p.colors.get(i).copied().unwrap_or([255; 4]))
    };
    let morphs = p.morph_targets.len() == p.positions.len()
        && p.morph_targets
            .iter()
            .zip(&p.positions)
            .any(|(t, q)| t != q);
    // Where each position is: this patch first (source 0), then the siblings.
    let mut at: FxHashMap<[u32; 3], (u32, u32)> = FxHashMap::default();
    if morphs {
        let sources = std::iter::once(p).chain(siblings.iter().copied());
        for (k, s) in sources.enumerate() {
            for (i, q) in s.positions.iter().enumerate() {
                at.entry(*q).or_insert((k as u32, i as u32));
            }
        }
    }
    for (i, q) in p.positions.iter().enumerate() {
        let position = local(q);
        let (n, c) = attributes(p, i);
        let mut v = GpuVertex {
            position,
            target: position,
            normal: n,
            target_normal: n,
            color: c,
            target_color: c,
        };
        if morphs && p.morph_targets[i] != *q {
            let t = &p.morph_targets[i];
            v.target = local(t);
            if let Some(&(k, j)) = at.get(t) {
                let s = if k == 0 { p } else { siblings[k as usize - 1] };
                (v.target_normal, v.target_color) = attributes(s, j as usize);
            }
        }
        out.push(v);
    }
}

/// Where a resident patch lives.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Slot {
    /// Vertex range (in vertices) in the vertex buffer: draw with `base_vertex = start`.
    pub vertices: Range<u32>,
    /// Index range (in indices) in the index buffer.
    pub indices: Range<u32>,
    /// The node's tag ([`vertex_tag`]), drawn with it as instance data.
    pub tag: u32,
}

impl Slot {
    /// GPU bytes held.
    pub fn bytes(&self) -> u64 {
        u64::from(self.vertices.end - self.vertices.start) * VERTEX_BYTES
            + u64::from(self.indices.end - self.indices.start) * INDEX_BYTES
    }
}

/// Counters of the cache.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuCacheStats {
    pub resident_bytes: u64,
    pub resident_patches: usize,
    pub uploaded_bytes: u64,
    pub uploads: u64,
    pub evictions: u64,
}

/// The GPU patch cache. See the module docs.
pub struct GpuCache {
    vertices: Pool,
    indices: Pool,
    /// Keyed by [`slot_key`] (model, node).
    slots: FxHashMap<u64, Slot>,
    stats: GpuCacheStats,
    /// Per model: resident bytes and patches, uploads, evictions.
    per_model: Vec<GpuCacheStats>,
    /// Per model: the level of each node (for the vertex tags); see
    /// [`GpuCache::set_levels`].
    levels: Vec<Vec<u8>>,
    scratch: Vec<GpuVertex>,
}

/// The key of `node` of `model` in the cache.
#[inline]
fn slot_key(model: u32, node: u32) -> u64 {
    (u64::from(model) << 32) | u64::from(node)
}

/// Capacity each buffer starts with; it doubles on demand up to the budget, so memory
/// follows what the views need (on lavapipe GPU memory is process memory, and wgpu
/// zero-fills a buffer before its first use).
/// The vertex buffer's part of the budget. Patches hold 0.56-0.57 vertices per
/// triangle on the bunny, Nefertiti, Gargoyle and a 2M-triangle generated model at the
/// default leaf size (~0.69 with the tests' 512-triangle leaves), so at 40 bytes a
/// vertex against 12 bytes of indices a triangle, vertices take 65-70% of a cut's
/// bytes. With half each (the split of the 24-byte vertex), the vertex buffer filled
/// first and a quarter of the budget could never be used.
pub const VERTEX_SHARE: f64 = 0.68;

const INITIAL_BUFFER_BYTES: u64 = 8 << 20;

/// One growable GPU buffer carved into element ranges (vertices or indices).
struct Pool {
    buffer: wgpu::Buffer,
    alloc: RangeAllocator<u32>,
    /// Largest capacity, in elements, the budget allows.
    max: u32,
    elem_bytes: u64,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl Pool {
    /// A pool of at most `budget_bytes`, starting at [`INITIAL_BUFFER_BYTES`].
    fn new(
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
        elem_bytes: u64,
        budget_bytes: u64,
    ) -> Pool {
        let max = (budget_bytes / elem_bytes).min(u64::from(u32::MAX)) as u32;
        let start = ((INITIAL_BUFFER_BYTES.min(budget_bytes) / elem_bytes) as u32).min(max);
        Pool {
            buffer: Self::make_buffer(device, label, usage, u64::from(start) * elem_bytes),
            alloc: RangeAllocator::new(0..start),
            max,
            elem_bytes,
            label,
            usage,
        }
    }

    fn make_buffer(
        device: &wgpu::Device,
        label: &str,
        usage: wgpu::BufferUsages,
        bytes: u64,
    ) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: usage | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    fn capacity(&self) -> u32 {
        self.alloc.initial_range().end
    }

    fn can_grow(&self) -> bool {
        self.capacity() < self.max
    }

    /// Too few free elements in total for `n`, and room to grow.
    fn short_of(&self, n: u32) -> bool {
        self.alloc.total_available() < n && self.can_grow()
    }

    /// A range of `n` elements; empty ranges are legal for empty patches and cost nothing.
    fn allocate(&mut self, n: u32) -> Option<Range<u32>> {
        if n == 0 {
            Some(0..0)
        } else {
            self.alloc.allocate_range(n).ok()
        }
    }

    fn free(&mut self, r: Range<u32>) {
        if !r.is_empty() {
            self.alloc.free_range(r);
        }
    }

    /// Doubles the capacity (at least to `n`, at most to the maximum), copying the
    /// contents with `enc`.
    fn grow(&mut self, device: &wgpu::Device, enc: &mut wgpu::CommandEncoder, n: u32) {
        let new_cap = self.capacity().saturating_mul(2).max(n).min(self.max);
        let nb = Self::make_buffer(
            device,
            self.label,
            self.usage,
            u64::from(new_cap) * self.elem_bytes,
        );
        enc.copy_buffer_to_buffer(&self.buffer, 0, &nb, 0, self.buffer.size());
        self.buffer = nb;
        self.alloc.grow_to(new_cap);
    }

    /// Writes `data` at element `start` (nothing for empty data).
    fn write(&self, queue: &wgpu::Queue, start: u32, data: &[u8]) {
        if !data.is_empty() {
            queue.write_buffer(&self.buffer, u64::from(start) * self.elem_bytes, data);
        }
    }
}

impl GpuCache {
    /// Two buffers sharing `budget_bytes` ([`VERTEX_SHARE`] of it for vertices, the
    /// rest for indices, each clamped to the device's maximum buffer size), starting
    /// small and growing on demand.
    pub fn new(device: &wgpu::Device, budget_bytes: u64) -> GpuCache {
        let max = device.limits().max_buffer_size;
        let v_cap = ((budget_bytes as f64 * VERTEX_SHARE) as u64).clamp(256 << 10, max);
        let i_cap = budget_bytes.saturating_sub(v_cap).clamp(256 << 10, max);
        GpuCache {
            vertices: Pool::new(
                device,
                "tessera patch cache: vertices",
                wgpu::BufferUsages::VERTEX,
                VERTEX_BYTES,
                v_cap,
            ),
            indices: Pool::new(
                device,
                "tessera patch cache: indices",
                wgpu::BufferUsages::INDEX,
                INDEX_BYTES,
                i_cap,
            ),
            slots: FxHashMap::default(),
            stats: GpuCacheStats::default(),
            per_model: Vec::new(),
            levels: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// The vertex buffer (bind it whole; slots address it with `base_vertex`).
    pub fn vertex_buffer(&self) -> &wgpu::Buffer {
        &self.vertices.buffer
    }

    /// The index buffer (u32 indices; slots address it by index range).
    pub fn index_buffer(&self) -> &wgpu::Buffer {
        &self.indices.buffer
    }

    /// Grows whichever buffer lacks room for `nv` vertices / `ni` indices (copying the
    /// contents on the GPU); false when both are at their maximum.
    fn grow(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, nv: u32, ni: u32) -> bool {
        let (mut want_v, mut want_i) = (self.vertices.short_of(nv), self.indices.short_of(ni));
        if !want_v && !want_i {
            // Fragmentation: room in total but no contiguous range; grow whichever can.
            (want_v, want_i) = (self.vertices.can_grow(), self.indices.can_grow());
        }
        if !want_v && !want_i {
            return false;
        }
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera patch cache growth"),
        });
        if want_v {
            self.vertices.grow(device, &mut enc, nv);
        }
        if want_i {
            self.indices.grow(device, &mut enc, ni);
        }
        // Submitted now: writes staged before it land first, later ones after the copy.
        queue.submit([enc.finish()]);
        true
    }

    /// The slot of a resident node (of model 0).
    #[inline]
    pub fn slot(&self, node: u32) -> Option<&Slot> {
        self.slot_of(0, node)
    }

    /// The slot of resident `node` of `model`.
    #[inline]
    pub fn slot_of(&self, model: u32, node: u32) -> Option<&Slot> {
        self.slots.get(&slot_key(model, node))
    }

    /// Whether `node` (of model 0) is resident.
    #[inline]
    pub fn contains(&self, node: u32) -> bool {
        self.contains_of(0, node)
    }

    /// Whether `node` of `model` is resident.
    #[inline]
    pub fn contains_of(&self, model: u32, node: u32) -> bool {
        self.slots.contains_key(&slot_key(model, node))
    }

    /// Counters of the whole cache (every model).
    pub fn stats(&self) -> GpuCacheStats {
        GpuCacheStats {
            resident_patches: self.slots.len(),
            ..self.stats
        }
    }

    /// The level of every node of `model` (its index's nodes in order), for the tags
    /// of the vertices uploaded from now on. Nodes without one are tagged level 0.
    pub fn set_levels(&mut self, model: u32, levels: Vec<u8>) {
        let m = model as usize;
        if self.levels.len() <= m {
            self.levels.resize_with(m + 1, Vec::new);
        }
        self.levels[m] = levels;
    }

    /// Counters of `model`'s patches.
    pub fn model_stats(&self, model: u32) -> GpuCacheStats {
        self.per_model
            .get(model as usize)
            .copied()
            .unwrap_or_default()
    }

    /// Whether `nv` vertices and `ni` indices more would fit, counting growth up to the
    /// budget (a contiguous range may still be missing: fragmentation).
    pub fn has_room(&self, nv: u64, ni: u64) -> bool {
        let free =
            |p: &Pool| u64::from(p.alloc.total_available()) + u64::from(p.max - p.capacity());
        free(&self.vertices) >= nv && free(&self.indices) >= ni
    }

    /// Bytes the models' patches can take together, at most: the budget, or less when
    /// the resident patches' mix of vertex and index bytes would fill one of the two
    /// buffers first (each is capped at its share of the budget: [`VERTEX_SHARE`]).
    pub fn usable_bytes(&self) -> u64 {
        let v = u64::from(self.vertices.capacity() - self.vertices.alloc.total_available())
            * VERTEX_BYTES;
        let i =
            u64::from(self.indices.capacity() - self.indices.alloc.total_available()) * INDEX_BYTES;
        let (max_v, max_i) = (
            u64::from(self.vertices.max) * VERTEX_BYTES,
            u64::from(self.indices.max) * INDEX_BYTES,
        );
        if v + i == 0 {
            return max_v + max_i;
        }
        let total = (v + i) as f64;
        let by_v = if v > 0 {
            max_v as f64 * total / v as f64
        } else {
            f64::INFINITY
        };
        let by_i = if i > 0 {
            max_i as f64 * total / i as f64
        } else {
            f64::INFINITY
        };
        (by_v.min(by_i) as u64).min(max_v + max_i)
    }

    /// Bytes the buffers can grow to (the cache's budget, as clamped).
    pub fn max_bytes(&self) -> u64 {
        u64::from(self.vertices.max) * VERTEX_BYTES + u64::from(self.indices.max) * INDEX_BYTES
    }

    fn model_entry(&mut self, model: u32) -> &mut GpuCacheStats {
        let i = model as usize;
        if self.per_model.len() <= i {
            self.per_model.resize(i + 1, GpuCacheStats::default());
        }
        &mut self.per_model[i]
    }

    /// Uploads `patch` for `node` (of model 0), growing the buffers up to the budget
    /// when there is no room; [`StoreError::Full`] when they are at their maximum and
    /// still have no room (the caller evicts and retries). A node already resident is
    /// left as is.
    pub fn upload(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        node: u32,
        patch: &PatchData,
        quant_step: f64,
    ) -> Result<u64, StoreError> {
        self.upload_for(device, queue, 0, node, patch, quant_step)
    }

    /// [`GpuCache::upload`] for `node` of `model`.
    pub fn upload_for(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        model: u32,
        node: u32,
        patch: &PatchData,
        quant_step: f64,
    ) -> Result<u64, StoreError> {
        self.upload_in_group(device, queue, (model, node), (patch, &[]), quant_step)
    }

    /// [`GpuCache::upload_for`] with the other patches of the node's residency group at
    /// hand (for its morph targets' attributes: [`gpu_vertices`]).
    pub fn upload_in_group(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (model, node): (u32, u32),
        (patch, siblings): (&PatchData, &[&PatchData]),
        quant_step: f64,
    ) -> Result<u64, StoreError> {
        let key = slot_key(model, node);
        if self.slots.contains_key(&key) {
            return Ok(0);
        }
        let nv = u32::try_from(patch.positions.len()).map_err(|_| StoreError::TooBig)?;
        let ni = u32::try_from(patch.indices.len()).map_err(|_| StoreError::TooBig)?;
        if nv > self.vertices.max || ni > self.indices.max {
            return Err(StoreError::TooBig);
        }
        let (vertices, indices) = loop {
            match self.try_alloc(nv, ni) {
                Some(r) => break r,
                None => {
                    if !self.grow(device, queue, nv, ni) {
                        return Err(StoreError::Full);
                    }
                }
            }
        };
        let mut verts = std::mem::take(&mut self.scratch);
        let level = self
            .levels
            .get(model as usize)
            .and_then(|l| l.get(node as usize))
            .copied()
            .unwrap_or(0);
        gpu_vertices(patch, siblings, quant_step, &mut verts);
        self.vertices
            .write(queue, vertices.start, bytemuck::cast_slice(&verts));
        self.scratch = verts;
        self.indices
            .write(queue, indices.start, bytemuck::cast_slice(&patch.indices));
        let slot = Slot {
            vertices,
            indices,
            tag: vertex_tag(model, node, level),
        };
        let bytes = slot.bytes();
        self.stats.resident_bytes += bytes;
        self.stats.uploaded_bytes += bytes;
        self.stats.uploads += 1;
        let m = self.model_entry(model);
        m.resident_bytes += bytes;
        m.uploaded_bytes += bytes;
        m.uploads += 1;
        m.resident_patches += 1;
        self.slots.insert(key, slot);
        Ok(bytes)
    }

    fn try_alloc(&mut self, nv: u32, ni: u32) -> Option<(Range<u32>, Range<u32>)> {
        let v = self.vertices.allocate(nv)?;
        match self.indices.allocate(ni) {
            Some(i) => Some((v, i)),
            None => {
                self.vertices.free(v);
                None
            }
        }
    }

    /// Frees `node`'s slot (of model 0; nothing if not resident).
    pub fn evict(&mut self, node: u32) {
        self.evict_of(0, node);
    }

    /// Frees the slot of `node` of `model` (nothing if not resident).
    pub fn evict_of(&mut self, model: u32, node: u32) {
        if let Some(slot) = self.slots.remove(&slot_key(model, node)) {
            let bytes = slot.bytes();
            self.vertices.free(slot.vertices);
            self.indices.free(slot.indices);
            self.stats.resident_bytes -= bytes;
            self.stats.evictions += 1;
            let m = self.model_entry(model);
            m.resident_bytes -= bytes;
            m.evictions += 1;
            m.resident_patches -= 1;
        }
    }
}

/// The cache as the streaming core's [`ResidentStore`] for one model: the cache with
/// the device and queue it uploads through, the model's grid step and its number in
/// the cache (0 for a single model).
pub struct GpuStore<'a> {
    pub cache: &'a mut GpuCache,
    pub device: &'a wgpu::Device,
    pub queue: &'a wgpu::Queue,
    pub quant_step: f64,
    pub model: u32,
}

impl ResidentStore for GpuStore<'_> {
    fn bytes_for(&self, patch: &PatchData) -> u64 {
        patch_gpu_bytes(patch)
    }
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        u64::from(vertices) * VERTEX_BYTES + u64::from(triangles) * 3 * INDEX_BYTES
    }
    fn has_room(&self, patches: &[&PatchData]) -> bool {
        let nv = patches.iter().map(|p| p.positions.len() as u64).sum();
        let ni = patches.iter().map(|p| p.indices.len() as u64).sum();
        self.cache.has_room(nv, ni)
    }
    fn upload(&mut self, node: u32, patch: &PatchData) -> Result<u64, StoreError> {
        self.upload_in_group(node, patch, &[])
    }
    fn upload_in_group(
        &mut self,
        node: u32,
        patch: &PatchData,
        siblings: &[&PatchData],
    ) -> Result<u64, StoreError> {
        self.cache.upload_in_group(
            self.device,
            self.queue,
            (self.model, node),
            (patch, siblings),
            self.quant_step,
        )
    }
    fn evict(&mut self, node: u32) {
        self.cache.evict_of(self.model, node);
    }
    /// This model's bytes.
    fn resident_bytes(&self) -> u64 {
        self.cache.model_stats(self.model).resident_bytes
    }
    fn flush(&mut self) {
        // Submitting nothing hands the staged writes to the device and frees their
        // staging copies.
        self.queue.submit([]);
    }
}

/// GPU bytes `p` takes once uploaded.
pub fn patch_gpu_bytes(p: &PatchData) -> u64 {
    p.positions.len() as u64 * VERTEX_BYTES + p.indices.len() as u64 * INDEX_BYTES
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(e: [i16; 2]) -> [f32; 3] {
        // The shader's oct_decode.
        let (x, y) = (f32::from(e[0]) / 32767.0, f32::from(e[1]) / 32767.0);
        let z = 1.0 - x.abs() - y.abs();
        let t = (-z).max(0.0);
        let (x, y) = (
            x - if x < 0.0 { -t } else { t },
            y - if y < 0.0 { -t } else { t },
        );
        let l = (x * x + y * y + z * z).sqrt();
        [x / l, y / l, z / l]
    }

    #[test]
    fn octahedral_normals_round_trip() {
        for n in [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [0.6, -0.8, 0.0],
            [-0.48, 0.6, -0.64],
            [0.577, 0.577, 0.577],
        ] {
            let l = f32::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            let n = [n[0] / l, n[1] / l, n[2] / l];
            let d = decode(oct_snorm16(n));
            let dot = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
            assert!(dot > 0.999_99, "{n:?} -> {d:?}");
        }
    }

    /// A vertex moving onto a survivor takes the survivor's normal and colour as its
    /// target's, from its own patch or from a sibling; one that stays keeps its own.
    #[test]
    fn targets_take_the_survivors_attributes() {
        let a = PatchData {
            positions: vec![[0, 0, 0], [4, 0, 0], [8, 0, 0]],
            normals: vec![[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            colors: vec![[10, 0, 0, 255], [20, 0, 0, 255], [30, 0, 0, 255]],
            morph_targets: vec![[0, 0, 0], [0, 0, 0], [16, 0, 0]],
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        let b = PatchData {
            positions: vec![[16, 0, 0]],
            normals: vec![[0.0, -1.0, 0.0]],
            colors: vec![[40, 0, 0, 255]],
            morph_targets: vec![[16, 0, 0]],
            ..Default::default()
        };
        let mut out = Vec::new();
        gpu_vertices(&a, &[&b], 0.5, &mut out);
        assert_eq!(out[0].target, out[0].position);
        assert_eq!(out[0].target_normal, out[0].normal);
        // Onto a survivor of the same patch.
        assert_eq!(out[1].target, [0.0, 0.0, 0.0]);
        assert_eq!(out[1].target_normal, out[0].normal);
        assert_eq!(out[1].target_color, [10, 0, 0, 255]);
        // Onto a survivor of the sibling.
        assert_eq!(out[2].target, [8.0, 0.0, 0.0]);
        assert_eq!(out[2].target_normal, oct_snorm16([0.0, -1.0, 0.0]));
        assert_eq!(out[2].target_color, [40, 0, 0, 255]);
        // Without the sibling it keeps its own.
        gpu_vertices(&a, &[], 0.5, &mut out);
        assert_eq!(out[2].target_normal, out[2].normal);
        assert_eq!(out[2].target_color, [30, 0, 0, 255]);
    }
}
