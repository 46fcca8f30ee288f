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
//! Textured models (`ATTR_TEXTURE`): each resident patch also holds its own texture
//! (with mips, made at upload: `crate::texture`) and the bind group that draws it, in
//! its [`Slot`]; the texture's bytes count in the slot's bytes, the resident bytes and
//! the budget, which the textures share with the buffers' growth (a buffer grows only
//! into budget no texture holds, a texture is uploaded only into budget neither buffer
//! has grown into). Models without textures pay nothing for this.
//!
//! Several models share one cache: slots are keyed by (model, node), so the buffers,
//! the allocators and their free space are shared, and each model's scheduler sees its
//! own [`GpuStore`] (its uploads, evictions and bytes). The single-model methods
//! (`slot`, `upload`, `evict`, ...) are model 0's.

use std::ops::Range;

use range_alloc::RangeAllocator;
use rustc_hash::FxHashMap;
use tessera_format::{
    morph_targets, patch_is_textured, patch_texel_size, source_uv, texel_lod, texels, vertex_chart,
    PatchData, TextureCodec,
};
use tessera_stream::{ResidentStore, StoreError};

use crate::texture::{
    bc7_uploads_as_blocks, level_size, texture_gpu_bytes, texture_gpu_bytes_as, SlotTexture,
    TextureKit,
};

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
    /// RGBA8, white when the model has no colours. Textured models: the vertex's
    /// coordinate in its patch texture, unorm16 x 2 ([`uv_unorm16`]).
    pub color: [u8; 4],
    /// The target's colour (same rule as the normal); textured models: its texture
    /// coordinate ([`gpu_vertices_as`]).
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

/// A texture coordinate (normalised, clamped to 0..1) as unorm16 x 2, in the bytes of a
/// [`GpuVertex`] colour slot (textured models: the textured pipeline reads locations 4
/// and 5 as `Unorm16x2`).
pub fn uv_unorm16(t: [f32; 2]) -> [u8; 4] {
    // NaN clamps to NaN, which casts to 0.
    let q = |v: f32| ((v.clamp(0.0, 1.0) * 65535.0).round() as u16).to_le_bytes();
    let (a, b) = (q(t[0]), q(t[1]));
    [a[0], a[1], b[0], b[1]]
}

/// Converts a decoded patch to GPU vertices, positions in the local frame
/// (`grid * quant_step`), morph targets with their attributes: a target is a surviving
/// vertex of the parent's simplification, whose normal and colour are taken from the
/// vertex at that position in this patch, else in one of `siblings` (the other patches
/// of its residency group: about 8% of the moving vertices of the Bunny and the Dragon
/// move onto a survivor of a sibling); one hash lookup per moving vertex, at upload
/// only. A survivor found nowhere lends nothing: the vertex keeps its own attributes
/// while it moves. Textured patches ([`patch_is_textured`]) carry texture coordinates
/// instead of colours ([`gpu_vertices_as`]).
pub fn gpu_vertices(
    p: &PatchData,
    siblings: &[&PatchData],
    quant_step: f64,
    out: &mut Vec<GpuVertex>,
) {
    gpu_vertices_as(p, siblings, quant_step, patch_is_textured(p), out);
}

/// [`gpu_vertices`], textured or not as told. Textured: the colour slots hold the
/// vertex's coordinate in the patch texture, `charts[chart_ids[i]].map(uvs[i])`, and its
/// target's, as [`uv_unorm16`] (no chart: the source uv as it is); the target's uv is
/// [`MorphTarget::uv`] mapped through the vertex's own chart. Normals follow the
/// untextured rule ([`MorphTarget::donor`]).
pub fn gpu_vertices_as(
    p: &PatchData,
    siblings: &[&PatchData],
    quant_step: f64,
    textured: bool,
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
    let normal = |p: &PatchData, i: usize| match p.normals.get(i) {
        Some(&n) if p.normals.len() == p.positions.len() => oct_snorm16(n),
        _ => [0, 0],
    };
    let color = |p: &PatchData, i: usize| p.colors.get(i).copied().unwrap_or([255; 4]);
    let targets = morph_targets(p, siblings, textured);
    for (i, q) in p.positions.iter().enumerate() {
        let position = local(q);
        let n = normal(p, i);
        let (c, own_chart) = if textured {
            let ch = vertex_chart(p, i);
            let uv = source_uv(p, i);
            (uv_unorm16(ch.map_or(uv, |ch| ch.map(uv))), ch)
        } else {
            (color(p, i), None)
        };
        let mut v = GpuVertex {
            position,
            target: position,
            normal: n,
            target_normal: n,
            color: c,
            target_color: c,
        };
        if let Some(Some(t)) = targets.get(i) {
            v.target = local(&t.position);
            if let Some((s, j)) = t.donor {
                v.target_normal = normal(s, j);
                if !textured {
                    v.target_color = color(s, j);
                } else if let (Some(own), Some(u)) = (own_chart, t.uv) {
                    v.target_color = uv_unorm16(own.map(u));
                }
            }
        }
        out.push(v);
    }
}

/// Where a resident patch lives.
#[derive(Clone, Debug, PartialEq)]
pub struct Slot {
    /// Vertex range (in vertices) in the vertex buffer: draw with `base_vertex = start`.
    pub vertices: Range<u32>,
    /// Index range (in indices) in the index buffer.
    pub indices: Range<u32>,
    /// The node's tag ([`vertex_tag`]), drawn with it as instance data.
    pub tag: u32,
    /// Textured patches: the patch texture, drawn through the textured pipeline
    /// (bind group 1); None for patches of models without textures.
    pub texture: Option<SlotTexture>,
    /// Textured patches: the model-space size of a texel of the patch texture (over
    /// its textured triangles), 0 when unknown.
    pub texel_size: f32,
    /// Textured patches: mip levels between this patch's texels and its parent's
    /// (`log2(parent texel / own texel)`, 0..8; 0 when unknown). Drawn at morph ratio
    /// `r`, the texture is sampled no finer than level `r * texel_lod`, so a patch that
    /// morphs in from its parent's shape also shows its parent's texel detail, and
    /// sharpens as it morphs (no texture pop at a switch).
    pub texel_lod: f32,
}

impl Slot {
    /// GPU bytes held: vertices, indices and the texture (mips included).
    pub fn bytes(&self) -> u64 {
        u64::from(self.vertices.end - self.vertices.start) * VERTEX_BYTES
            + u64::from(self.indices.end - self.indices.start) * INDEX_BYTES
            + self.texture.as_ref().map_or(0, |t| t.bytes)
    }
}

/// Counters of the cache.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuCacheStats {
    /// Bytes of the resident patches, their textures included.
    pub resident_bytes: u64,
    /// The textures' part of `resident_bytes`.
    pub texture_bytes: u64,
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
    /// Per model: each node's parent and the parent's error ([`GpuCache::set_nodes`]),
    /// for the texel detail a patch morphs from.
    parents: Vec<Vec<(u32, f32)>>,
    /// Per model: whether it is textured ([`GpuCache::set_textured`]).
    textured: Vec<bool>,
    /// Per model: its header's texture codec ([`GpuCache::set_texture_codec`]), for the
    /// GPU bytes of textures not read yet.
    codecs: Vec<Option<TextureCodec>>,
    /// Whether the device samples BC7 (`TEXTURE_COMPRESSION_BC`): BC7 patch textures
    /// are uploaded as blocks, else decoded to RGBA8.
    bc7: bool,
    /// The texture layout, sampler and grey stand-in, made at the first textured upload.
    kit: Option<TextureKit>,
    /// Bytes the vertex and index buffers and the textures may take together: the
    /// buffers' maxima (the budget, as clamped). Textures and buffer growth share it.
    total: u64,
    /// The device's largest texture (larger patch textures start at a smaller mip).
    max_texture_dim: u32,
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
/// The buffers start at most at this part of their maximum: textures share the budget
/// with the buffers' capacity (which never shrinks), and a small budget's buffers
/// starting at their maxima would leave no room for any texture. (Untextured models
/// draw the same either way; a small budget's buffers just grow on demand.)
const INITIAL_SHARE: u32 = 8;

/// A patch texture's texels as they go to the GPU.
enum TexelsRef<'p> {
    /// Width, height, RGBA8, the mips made ahead (or none).
    Rgba(u32, u32, &'p [u8], &'p [Vec<u8>]),
    /// Width, height and the BC7 blocks of every level, uploaded as blocks.
    Bc7(u32, u32, &'p [Vec<u8>]),
    /// Width, height and BC7 blocks the device cannot sample: decoded to RGBA8 (every
    /// stored level) at upload.
    Bc7Decoded(u32, u32, &'p [Vec<u8>]),
}

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
    /// A pool of at most `budget_bytes`, starting at [`INITIAL_BUFFER_BYTES`] or
    /// [`INITIAL_SHARE`] of the maximum, whichever is less.
    fn new(
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
        elem_bytes: u64,
        budget_bytes: u64,
    ) -> Pool {
        let max = (budget_bytes / elem_bytes).min(u64::from(u32::MAX)) as u32;
        let start = ((INITIAL_BUFFER_BYTES.min(budget_bytes) / elem_bytes) as u32)
            .min((max / INITIAL_SHARE).max(1))
            .min(max);
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

    fn capacity_bytes(&self) -> u64 {
        u64::from(self.capacity()) * self.elem_bytes
    }

    /// The capacity it may grow to with `room` bytes to spare (at most its maximum).
    fn limit(&self, room: u64) -> u32 {
        let extra = (room / self.elem_bytes).min(u64::from(u32::MAX)) as u32;
        self.capacity().saturating_add(extra).min(self.max)
    }

    /// Free elements now.
    fn available(&self) -> u32 {
        self.alloc.total_available()
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

    /// Doubles the capacity (at least to `n`, at most to `limit`), copying the
    /// contents with `enc`.
    fn grow(&mut self, device: &wgpu::Device, enc: &mut wgpu::CommandEncoder, n: u32, limit: u32) {
        let new_cap = self.capacity().saturating_mul(2).max(n).min(limit);
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
        let mut cache = GpuCache {
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
            parents: Vec::new(),
            textured: Vec::new(),
            codecs: Vec::new(),
            bc7: device
                .features()
                .contains(wgpu::Features::TEXTURE_COMPRESSION_BC),
            kit: None,
            total: 0,
            max_texture_dim: device.limits().max_texture_dimension_2d,
            scratch: Vec::new(),
        };
        cache.total = u64::from(cache.vertices.max) * VERTEX_BYTES
            + u64::from(cache.indices.max) * INDEX_BYTES;
        cache
    }

    /// Marks `model` textured (its header has `ATTR_TEXTURE`) or not: its patches are
    /// uploaded with texture coordinates and drawn with their textures from then on
    /// (upload before the call keeps what it made). A patch with charts is drawn
    /// textured whatever the switch says ([`patch_is_textured`]); the switch makes a
    /// textured model's patch that came without its texture draw textured too, with a
    /// 1x1 grey texture.
    pub fn set_textured(&mut self, model: u32, textured: bool) {
        let m = model as usize;
        if self.textured.len() <= m {
            self.textured.resize(m + 1, false);
        }
        self.textured[m] = textured;
    }

    /// Records `model`'s texture codec (its header's `texture_codec`): the GPU bytes of
    /// its textures before they are read ([`GpuCache::texture_bytes_for`]) depend on it.
    pub fn set_texture_codec(&mut self, model: u32, codec: Option<TextureCodec>) {
        let m = model as usize;
        if self.codecs.len() <= m {
            self.codecs.resize(m + 1, None);
        }
        self.codecs[m] = codec;
    }

    /// Whether the device samples BC7 textures (`TEXTURE_COMPRESSION_BC`).
    pub fn samples_bc7(&self) -> bool {
        self.bc7
    }

    /// Where BC7 textures go up as blocks, the device's largest texture (a texture
    /// whose first level that fits is not whole blocks is decoded:
    /// [`bc7_uploads_as_blocks`]); `None` where every BC7 texture is decoded.
    pub fn bc7_block_limit(&self) -> Option<u32> {
        self.bc7.then_some(self.max_texture_dim)
    }

    /// Whether a BC7 texture of `width` x `height` goes to this device as blocks.
    fn bc7_as_blocks(&self, width: u32, height: u32) -> bool {
        self.bc7 && bc7_uploads_as_blocks(width, height, self.max_texture_dim)
    }

    /// Whether `patch` of `model` is uploaded (and drawn) textured.
    fn uploads_textured(&self, model: u32, patch: &PatchData) -> bool {
        self.textured.get(model as usize).copied().unwrap_or(false) || patch_is_textured(patch)
    }

    /// The texture bytes `patch` takes once uploaded for `model` (0: none, or the
    /// shared grey stand-in), and its texels when it has a texture of its own.
    fn texture_plan<'p>(&self, model: u32, patch: &'p PatchData) -> (u64, Option<TexelsRef<'p>>) {
        if patch.positions.is_empty() || !self.uploads_textured(model, patch) {
            return (0, None);
        }
        match &patch.texture {
            Some(t)
                if t.width > 0
                    && t.height > 0
                    && t.rgba.len() as u64 == 4 * u64::from(t.width) * u64::from(t.height) =>
            {
                let bytes = texture_gpu_bytes(t.width, t.height, self.max_texture_dim);
                (
                    bytes,
                    Some(TexelsRef::Rgba(t.width, t.height, &t.rgba[..], &t.mips[..])),
                )
            }
            Some(t) if t.width > 0 && t.height > 0 && !t.blocks.is_empty() => {
                let blocks = self.bc7_as_blocks(t.width, t.height);
                let bytes = texture_gpu_bytes_as(t.width, t.height, self.max_texture_dim, blocks);
                let texels = if blocks {
                    TexelsRef::Bc7(t.width, t.height, &t.blocks[..])
                } else {
                    TexelsRef::Bc7Decoded(t.width, t.height, &t.blocks[..])
                };
                (bytes, Some(texels))
            }
            _ => (0, None),
        }
    }

    /// GPU bytes `patch` takes once uploaded for `model`: vertices, indices and its
    /// texture with the mip chain ([`Slot::bytes`] of the slot it gets).
    pub fn patch_bytes(&self, model: u32, patch: &PatchData) -> u64 {
        patch.positions.len() as u64 * VERTEX_BYTES
            + patch.indices.len() as u64 * INDEX_BYTES
            + self.texture_plan(model, patch).0
    }

    /// GPU bytes a patch texture of `size` texels of `model` takes on this device (mips
    /// included), by the model's texture codec.
    pub fn texture_bytes_for(&self, model: u32, size: [u16; 2]) -> u64 {
        let (w, h) = (u32::from(size[0]), u32::from(size[1]));
        let bc7 = self.codecs.get(model as usize).copied().flatten() == Some(TextureCodec::Bc7);
        texture_gpu_bytes_as(w, h, self.max_texture_dim, bc7 && self.bc7_as_blocks(w, h))
    }

    /// The bind group layout of the patch textures (group 1 of the textured pipeline),
    /// once a textured patch has been uploaded.
    pub fn texture_layout(&self) -> Option<&wgpu::BindGroupLayout> {
        self.kit.as_ref().map(|k| &k.layout)
    }

    /// Bytes left in the budget for growing a buffer or a texture: the budget less the
    /// buffers' capacities and the resident textures.
    fn room(&self) -> u64 {
        self.total.saturating_sub(
            self.vertices.capacity_bytes()
                + self.indices.capacity_bytes()
                + self.stats.texture_bytes,
        )
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
    /// contents on the GPU), keeping `reserve` bytes of the budget free (for the
    /// patch's texture); false when neither can grow.
    fn grow(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (nv, ni): (u32, u32),
        reserve: u64,
    ) -> bool {
        // Without textures the budget holds both buffers at their maxima, so the limits
        // are the maxima.
        let room = self.room().saturating_sub(reserve);
        let (v_lim, i_lim) = (self.vertices.limit(room), self.indices.limit(room));
        let (can_v, can_i) = (
            self.vertices.capacity() < v_lim,
            self.indices.capacity() < i_lim,
        );
        let (mut want_v, mut want_i) = (
            self.vertices.available() < nv && can_v,
            self.indices.available() < ni && can_i,
        );
        if !want_v && !want_i {
            // Fragmentation: room in total but no contiguous range; grow whichever can.
            (want_v, want_i) = (can_v, can_i);
        }
        if !want_v && !want_i {
            return false;
        }
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera patch cache growth"),
        });
        if want_v {
            self.vertices.grow(device, &mut enc, nv, v_lim);
        }
        if want_i {
            // What the vertex buffer's growth left.
            let i_lim = self.indices.limit(self.room().saturating_sub(reserve));
            if self.indices.capacity() < i_lim {
                self.indices.grow(device, &mut enc, ni, i_lim);
            }
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
    /// Takes `model`'s node table from its index: each node's level (as
    /// [`GpuCache::set_levels`]) and its parent and the parent's error (the texel detail
    /// a textured patch morphs from: [`Slot::texel_lod`]).
    pub fn set_nodes(&mut self, model: u32, index: &tessera_format::ModelIndex) {
        let nodes = index.nodes();
        self.set_levels(model, nodes.iter().map(|n| n.level).collect());
        let m = model as usize;
        if self.parents.len() <= m {
            self.parents.resize_with(m + 1, Vec::new);
        }
        self.parents[m] = nodes
            .iter()
            .map(|n| {
                let e = nodes.get(n.parent as usize).map_or(0.0, |p| p.error);
                (n.parent, e)
            })
            .collect();
    }

    /// The texel detail a textured patch of `texel_size` morphs from ([`texel_lod`]):
    /// its parent's slot's texel when resident, else the one its error allows.
    fn texel_lod(&self, model: u32, node: u32, texel_size: f32) -> f32 {
        let Some(&(parent, error)) = self
            .parents
            .get(model as usize)
            .and_then(|p| p.get(node as usize))
        else {
            return 0.0;
        };
        if parent == tessera_format::NO_NODE {
            return 0.0;
        }
        let parent_texel = self
            .slots
            .get(&slot_key(model, parent))
            .map_or(0.0, |s| s.texel_size);
        texel_lod(texel_size, parent_texel, error)
    }

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
        self.has_room_for(nv, ni, 0)
    }

    /// [`GpuCache::has_room`] with `texture_bytes` of textures too (they share the
    /// budget with the buffers' growth).
    pub fn has_room_for(&self, nv: u64, ni: u64, texture_bytes: u64) -> bool {
        // Elements each buffer must grow by.
        let grow = |p: &Pool, n: u64| {
            let short = n.saturating_sub(u64::from(p.available()));
            (short <= u64::from(p.max - p.capacity())).then_some(short * p.elem_bytes)
        };
        match (grow(&self.vertices, nv), grow(&self.indices, ni)) {
            (Some(v), Some(i)) => v + i + texture_bytes <= self.room(),
            _ => false,
        }
    }

    /// Bytes the models' patches can take together, at most: the budget, or less when
    /// the resident patches' mix of vertex and index bytes would fill one of the two
    /// buffers first (each is capped at its share of the budget: [`VERTEX_SHARE`]).
    ///
    /// With textures resident, the mix is of three (vertex, index and texture bytes),
    /// and what the buffers have grown to counts whether used or not (they never
    /// shrink): the most bytes in that mix whose buffers and textures fit the budget.
    pub fn usable_bytes(&self) -> u64 {
        let v = u64::from(self.vertices.capacity() - self.vertices.alloc.total_available())
            * VERTEX_BYTES;
        let i =
            u64::from(self.indices.capacity() - self.indices.alloc.total_available()) * INDEX_BYTES;
        let (max_v, max_i) = (
            u64::from(self.vertices.max) * VERTEX_BYTES,
            u64::from(self.indices.max) * INDEX_BYTES,
        );
        let t = self.stats.texture_bytes;
        if t > 0 {
            let total = (v + i + t) as f64;
            let (fv, fi, ft) = (v as f64 / total, i as f64 / total, t as f64 / total);
            let (cv, ci) = (
                self.vertices.capacity_bytes() as f64,
                self.indices.capacity_bytes() as f64,
            );
            let fits = |x: f64| {
                fv * x <= max_v as f64
                    && fi * x <= max_i as f64
                    && (fv * x).max(cv) + (fi * x).max(ci) + ft * x <= self.total as f64
            };
            // The fit shrinks as the bytes grow: bisect.
            let (mut lo, mut hi) = (0u64, self.total);
            while lo < hi {
                let mid = lo + (hi - lo).div_ceil(2);
                if fits(mid as f64) {
                    lo = mid;
                } else {
                    hi = mid - 1;
                }
            }
            return lo;
        }
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

    /// Bytes the buffers can grow to (the cache's budget, as clamped); the textures
    /// share it with them.
    pub fn max_bytes(&self) -> u64 {
        self.total
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
        let textured = self.uploads_textured(model, patch);
        let (texture_bytes, texels) = self.texture_plan(model, patch);
        if nv > self.vertices.max
            || ni > self.indices.max
            || u64::from(nv) * VERTEX_BYTES + u64::from(ni) * INDEX_BYTES + texture_bytes
                > self.total
        {
            return Err(StoreError::TooBig);
        }
        let (vertices, indices) = loop {
            // The buffers never shrink: only evictions make room for a texture.
            if texture_bytes > self.room() {
                return Err(StoreError::Full);
            }
            match self.try_alloc(nv, ni) {
                Some(r) => break r,
                None => {
                    if !self.grow(device, queue, (nv, ni), texture_bytes) {
                        return Err(StoreError::Full);
                    }
                }
            }
        };
        let texture = if textured {
            let kit = self
                .kit
                .get_or_insert_with(|| TextureKit::new(device, queue));
            let max = self.max_texture_dim;
            Some(match texels {
                Some(TexelsRef::Rgba(w, h, rgba, mips)) => {
                    kit.upload(device, queue, w, h, rgba, mips, max)
                }
                Some(TexelsRef::Bc7(w, h, blocks)) => {
                    kit.upload_bc7(device, queue, w, h, blocks, max)
                }
                Some(TexelsRef::Bc7Decoded(w, h, blocks)) => {
                    let mut levels = blocks.iter().enumerate().map(|(l, b)| {
                        let (lw, lh) = level_size(w, h, l as u32);
                        texels::bc7_to_rgba(b, lw, lh)
                    });
                    let rgba = levels.next().unwrap_or_default();
                    let mips: Vec<Vec<u8>> = levels.collect();
                    kit.upload(device, queue, w, h, &rgba, &mips, max)
                }
                None => kit.grey(),
            })
        } else {
            None
        };
        debug_assert_eq!(texture.as_ref().map_or(0, |t| t.bytes), texture_bytes);
        let mut verts = std::mem::take(&mut self.scratch);
        let level = self
            .levels
            .get(model as usize)
            .and_then(|l| l.get(node as usize))
            .copied()
            .unwrap_or(0);
        gpu_vertices_as(patch, siblings, quant_step, textured, &mut verts);
        self.vertices
            .write(queue, vertices.start, bytemuck::cast_slice(&verts));
        self.scratch = verts;
        self.indices
            .write(queue, indices.start, bytemuck::cast_slice(&patch.indices));
        let texel_size = match (&texture, &patch.texture) {
            (Some(_), Some(t)) => patch_texel_size(patch, t.width, t.height, quant_step),
            _ => 0.0,
        };
        let slot = Slot {
            vertices,
            indices,
            tag: vertex_tag(model, node, level),
            texture,
            texel_size,
            texel_lod: self.texel_lod(model, node, texel_size),
        };
        let bytes = slot.bytes();
        self.stats.resident_bytes += bytes;
        self.stats.texture_bytes += texture_bytes;
        self.stats.uploaded_bytes += bytes;
        self.stats.uploads += 1;
        let m = self.model_entry(model);
        m.resident_bytes += bytes;
        m.texture_bytes += texture_bytes;
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
            let texture_bytes = slot.texture.as_ref().map_or(0, |t| t.bytes);
            // The texture (and its bind group) go with the slot; wgpu frees them once
            // submitted work that draws them is done.
            self.vertices.free(slot.vertices);
            self.indices.free(slot.indices);
            self.stats.resident_bytes -= bytes;
            self.stats.texture_bytes -= texture_bytes;
            self.stats.evictions += 1;
            let m = self.model_entry(model);
            m.resident_bytes -= bytes;
            m.texture_bytes -= texture_bytes;
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
        self.cache.patch_bytes(self.model, patch)
    }
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        u64::from(vertices) * VERTEX_BYTES + u64::from(triangles) * 3 * INDEX_BYTES
    }
    fn estimate_texture_bytes(&self, size: [u16; 2]) -> u64 {
        self.cache.texture_bytes_for(self.model, size)
    }
    fn has_room(&self, patches: &[&PatchData]) -> bool {
        let nv = patches.iter().map(|p| p.positions.len() as u64).sum();
        let ni = patches.iter().map(|p| p.indices.len() as u64).sum();
        let nt = patches
            .iter()
            .map(|p| self.cache.texture_plan(self.model, p).0)
            .sum();
        self.cache.has_room_for(nv, ni, nt)
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
    fn texel_lod_is_the_levels_to_the_parents_texels() {
        // The parent's texel known: log2 of the ratio, clamped to 0..8.
        assert_eq!(texel_lod(0.25, 1.0, 9.0), 2.0);
        assert_eq!(texel_lod(1.0, 0.5, 9.0), 0.0);
        assert_eq!(texel_lod(1.0, 1024.0, 9.0), 8.0);
        // Unknown: the texel the parent's error allows (error / sqrt 2).
        let l = texel_lod(0.5, 0.0, 2.0 * std::f32::consts::SQRT_2);
        assert!((l - 2.0).abs() < 1e-5, "{l}");
        // No texels of its own, or nothing known: 0.
        assert_eq!(texel_lod(0.0, 1.0, 1.0), 0.0);
        assert_eq!(texel_lod(1.0, 0.0, 0.0), 0.0);
        assert_eq!(texel_lod(f32::NAN, 1.0, 1.0), 0.0);
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

    fn unorm16(c: [u8; 4]) -> [f32; 2] {
        let u = u16::from_le_bytes([c[0], c[1]]);
        let v = u16::from_le_bytes([c[2], c[3]]);
        [f32::from(u) / 65535.0, f32::from(v) / 65535.0]
    }

    fn close(a: [f32; 2], b: [f32; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4
    }

    /// Textured patches: the colour slots carry the chart-mapped uv (clamped), and a
    /// moving vertex's target uv is that of the vertex of its own patch and chart at the
    /// target, the nearest one; no such vertex (another chart, or a sibling's only),
    /// its own.
    #[test]
    fn targets_take_the_uv_of_the_survivor_in_the_same_chart() {
        use tessera_format::TextureChart;
        let chart = |image, scale: f32, offset: [f32; 2]| TextureChart {
            image,
            scale: [scale, scale],
            offset,
        };
        let a = PatchData {
            // 0: moves onto [8, 0, 0], where 1 (chart 1), 2 and 3 (chart 0) lie;
            // 4: moves onto [16, 0, 0] (a survivor of the sibling);
            // 5: moves onto [24, 0, 0], where only a vertex of another chart lies;
            // 6: stays (target itself); 7: out of its chart's range (clamped); 8:
            // moves onto [8, 0, 0] in chart 2, on the same image as chart 0 (another
            // rectangle of the atlas).
            positions: vec![
                [0, 0, 0],
                [8, 0, 0],
                [8, 0, 0],
                [8, 0, 0],
                [12, 0, 0],
                [20, 0, 0],
                [24, 0, 0],
                [28, 0, 0],
                [4, 0, 0],
            ],
            uvs: vec![
                [0.10, 0.10],
                [0.20, 0.20],
                [0.90, 0.90],
                [0.30, 0.25],
                [0.50, 0.50],
                [0.60, 0.60],
                [0.70, 0.70],
                [5.00, -3.0],
                [0.15, 0.15],
            ],
            morph_targets: vec![
                [8, 0, 0],
                [8, 0, 0],
                [8, 0, 0],
                [8, 0, 0],
                [16, 0, 0],
                [24, 0, 0],
                [24, 0, 0],
                [28, 0, 0],
                [8, 0, 0],
            ],
            charts: vec![
                chart(0, 0.5, [0.25, 0.0]),
                chart(2, 1.0, [0.0, 0.0]),
                chart(0, 0.25, [0.0, 0.5]),
            ],
            chart_ids: vec![0, 1, 0, 0, 0, 0, 1, 0, 2],
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        let b = PatchData {
            positions: vec![[16, 0, 0], [16, 0, 0]],
            uvs: vec![[0.40, 0.40], [0.55, 0.50]],
            morph_targets: vec![[16, 0, 0]; 2],
            // The sibling's own charts: image 0 is chart 1 there.
            charts: vec![chart(3, 1.0, [0.0, 0.0]), chart(0, 0.25, [0.5, 0.5])],
            chart_ids: vec![0, 1],
            ..Default::default()
        };
        assert!(patch_is_textured(&a));
        let mut out = Vec::new();
        gpu_vertices(&a, &[&b], 0.5, &mut out);
        let own = |i: usize| unorm16(out[i].color);
        let target = |i: usize| unorm16(out[i].target_color);
        let map0 = |uv: [f32; 2]| [uv[0] * 0.5 + 0.25, uv[1] * 0.5];
        assert!(close(own(0), map0([0.10, 0.10])), "{:?}", own(0));
        assert!(close(own(1), [0.20, 0.20]));
        // Vertex 0 (chart 0): 1 is in chart 1; of 2 and 3 (chart 0), 3 is nearer.
        assert!(close(target(0), map0([0.30, 0.25])), "{:?}", target(0));
        // Vertex 1 (chart 1): only itself is in chart 1 at [8, 0, 0].
        assert!(close(target(1), own(1)));
        // Vertex 4: only the sibling has a vertex at [16, 0, 0]: its own uv (the
        // sibling's uv may lie outside vertex 4's rectangle of this texture).
        assert_eq!(out[4].target_color, out[4].color);
        // Vertex 5: the only vertex at [24, 0, 0] is in chart 1: own uv.
        assert!(close(target(5), own(5)), "{:?} vs {:?}", target(5), own(5));
        // Vertex 8 (chart 2, the same image as chart 0): no vertex of chart 2 at
        // [8, 0, 0]: own uv, not chart 0's.
        assert_eq!(out[8].target_color, out[8].color);
        // Vertex 6 stays; vertex 7's uv is clamped into the texture.
        assert_eq!(out[6].target_color, out[6].color);
        assert!(close(own(7), [1.0, 0.0]), "{:?}", own(7));
        // Without the sibling, the same.
        gpu_vertices(&a, &[], 0.5, &mut out);
        assert_eq!(out[4].target_color, out[4].color);
        assert!(close(unorm16(out[0].target_color), map0([0.30, 0.25])));
        // Untextured, the same patch carries colours (white without any).
        let plain = PatchData {
            charts: vec![],
            chart_ids: vec![],
            ..a.clone()
        };
        assert!(!patch_is_textured(&plain));
        gpu_vertices(&plain, &[], 0.5, &mut out);
        assert!(out
            .iter()
            .all(|v| v.color == [255; 4] && v.target_color == [255; 4]));
    }
}
