//! A model streamed for another renderer: [`Stream`], the wasm-bindgen class under the
//! three.js adapter (`web/tessera-three.js`). The same reader, fetch plan, decode
//! workers and `Scheduler` as the canvas [`crate::Viewer`] (it opens the model through
//! the same [`open_model`] and streams through the same [`Remote`]), with no device of
//! its own: its store ([`KeptStore`]) keeps each resident patch's arrays as a three.js
//! `BufferGeometry` takes them (positions relative to the model origin as f32, normals,
//! linear vertex colours, texture coordinates mapped into the patch texture, u32
//! indices, the texture's RGBA8) until the page takes them, and records what was
//! added and evicted; each frame the page builds and disposes its meshes from that and
//! shows the scheduler's draw list with its morph ratios. Geomorphing as the canvas
//! viewer: each vertex's morph target and its attributes ([`tessera_format::morph_targets`],
//! the GPU cache's own lookup) go with the arrays, and the page's shader blends each
//! mesh toward them by its node's ratio ([`Stream::ratios`]).

use std::sync::Arc;

use glam::DVec3;
use rustc_hash::FxHashMap;
use serde_json::json;
use tessera_format::{Grid, ModelIndex, PatchData, PatchTexture, ATTR_COLORS, ATTR_TEXTURE};
use tessera_nav::Navigator;
use tessera_select::Camera;
use tessera_stream::{ResidentStore, SceneStores, StoreError};
use wasm_bindgen::prelude::*;

use crate::viewer::{
    home_navigator, new_scheduler, now_ms, open_model, Remote, StreamOptions, Streamed,
};

/// Bytes a vertex takes as the adapter's attributes: position and normal (f32 x 3
/// each), plus a linear colour (f32 x 3, untextured models with colours) or a texture
/// coordinate (f32 x 2, textured models); twice that with its morph target's (a patch
/// with moving vertices: all but the roots, nearly).
fn vertex_bytes(colors: bool, textured: bool, morphs: bool) -> u64 {
    let own = 24 + if colors { 12 } else { 0 } + if textured { 8 } else { 0 };
    if morphs {
        own * 2
    } else {
        own
    }
}

/// An sRGB-encoded 8-bit channel as linear light (three.js takes vertex colours in its
/// linear working space; Tessera's own shader shows the stored values as they are,
/// i.e. as sRGB).
fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// One resident patch's arrays for a three.js `BufferGeometry`.
struct PatchArrays {
    positions: Vec<f32>,
    normals: Vec<f32>,
    colors: Vec<f32>,
    uvs: Vec<f32>,
    indices: Vec<u32>,
    /// RGBA8 rows top to bottom (sampled at v = 0 first, as glTF: `flipY` false), width,
    /// height.
    texture: Option<(Vec<u8>, u32, u32)>,
    /// The morph targets, as `positions`, `normals`, `colors` and `uvs` (empty when no
    /// vertex moves; a vertex whose target is itself repeats its own).
    targets: Vec<f32>,
    target_normals: Vec<f32>,
    target_colors: Vec<f32>,
    target_uvs: Vec<f32>,
    /// Mip levels between the texture's texels and the parent's
    /// ([`tessera_format::texel_lod`]): drawn at ratio r, sampled no finer than r times it.
    texel_lod: f32,
}

/// The adapter's `ResidentStore`: patches kept as arrays until the page takes them, with
/// the nodes added and evicted since it last asked. Bytes are counted per vertex
/// ([`vertex_bytes`]), 4 an index and the texture with its mips (as uploaded to a device
/// whose largest texture is `max_texture_dim`), as the GPU cache counts its own.
struct KeptStore {
    grid: Grid,
    /// Model coordinates of the positions' origin (the page places the meshes there).
    origin: DVec3,
    colors: bool,
    textured: bool,
    max_texture_dim: u32,
    /// Resident nodes: their bytes, their texture's texel size (model space, 0 without)
    /// and their arrays until taken.
    held: FxHashMap<u32, (u64, f32, Option<PatchArrays>)>,
    /// Each node's parent and the parent's error (for the texel detail a textured patch
    /// morphs from).
    parents: Vec<(u32, f32)>,
    bytes: u64,
    added: Vec<u32>,
    removed: Vec<u32>,
    /// Patches evicted so far.
    evicted: u64,
}

/// Whether any vertex of `patch` moves when it morphs.
fn morphs(patch: &PatchData) -> bool {
    patch.morph_targets.len() == patch.positions.len()
        && patch
            .morph_targets
            .iter()
            .zip(&patch.positions)
            .any(|(t, q)| t != q)
}

impl KeptStore {
    fn position(&self, q: [u32; 3]) -> [f32; 3] {
        let p = DVec3::from(self.grid.position(q)) - self.origin;
        [p.x as f32, p.y as f32, p.z as f32]
    }

    fn arrays(&self, patch: &PatchData, siblings: &[&PatchData], texel_lod: f32) -> PatchArrays {
        let positions = patch
            .positions
            .iter()
            .flat_map(|&q| self.position(q))
            .collect();
        let has_normals = patch.normals.len() == patch.positions.len();
        let normals = if has_normals {
            patch.normals.iter().flatten().copied().collect()
        } else {
            Vec::new()
        };
        let linear = |c: [u8; 4]| {
            [
                srgb_to_linear(c[0]),
                srgb_to_linear(c[1]),
                srgb_to_linear(c[2]),
            ]
        };
        let has_colors = self.colors && patch.colors.len() == patch.positions.len();
        let colors = if has_colors {
            patch.colors.iter().flat_map(|&c| linear(c)).collect()
        } else {
            Vec::new()
        };
        let textured = !patch.charts.is_empty();
        let chart = |i: usize| {
            patch
                .chart_ids
                .get(i)
                .and_then(|&c| patch.charts.get(usize::from(c)))
        };
        let mapped = |i: usize, uv: [f32; 2]| chart(i).map_or([0.0; 2], |ch| ch.map(uv));
        let uvs = if textured {
            patch
                .uvs
                .iter()
                .enumerate()
                .flat_map(|(i, &uv)| mapped(i, uv))
                .collect()
        } else {
            Vec::new()
        };
        // The morph targets: the GPU cache's lookup, as f32 arrays beside the own.
        let (mut targets, mut target_normals, mut target_colors, mut target_uvs) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let found = tessera_format::morph_targets(patch, siblings, textured);
        if !found.is_empty() {
            let n = patch.positions.len();
            targets.reserve(n * 3);
            for (i, t) in found.iter().enumerate() {
                let q = t.as_ref().map_or(patch.positions[i], |t| t.position);
                targets.extend(self.position(q));
                let donor = t.as_ref().and_then(|t| t.donor);
                if has_normals {
                    let n = donor
                        .and_then(|(s, j)| {
                            (s.normals.len() == s.positions.len()).then(|| s.normals[j])
                        })
                        .unwrap_or(patch.normals[i]);
                    target_normals.extend(n);
                }
                if has_colors {
                    let c = donor
                        .and_then(|(s, j)| s.colors.get(j).copied())
                        .unwrap_or(patch.colors[i]);
                    target_colors.extend(linear(c));
                }
                if textured {
                    let uv = t.as_ref().and_then(|t| t.uv).unwrap_or(patch.uvs[i]);
                    target_uvs.extend(mapped(i, uv));
                }
            }
        }
        // A BC7 texture decoded on this thread (no decode workers) comes as blocks:
        // three.js gets RGBA8 texels (every stored level).
        let decoded = patch
            .texture
            .as_ref()
            .filter(|t| t.rgba.is_empty() && !t.blocks.is_empty())
            .and_then(|t| {
                let mut d = PatchTexture {
                    rgba: Vec::new(),
                    mips: Vec::new(),
                    ..t.clone()
                };
                d.decode_rgba().ok().map(|()| d)
            });
        let texture = decoded
            .as_ref()
            .or(patch.texture.as_ref())
            .filter(|t| !t.rgba.is_empty())
            .map(|t| {
                // Larger than the device's largest texture: the first mip that fits (the
                // workers' chain when they made one).
                let (mut rgba, mut w, mut h) = (t.rgba.clone(), t.width, t.height);
                let mut level = 0;
                while w.max(h) > self.max_texture_dim.max(1) {
                    let next = match t.mips.get(level) {
                        Some(m) => (m.clone(), (w / 2).max(1), (h / 2).max(1)),
                        None => tessera_render::downsample(&rgba, w, h),
                    };
                    (rgba, w, h) = next;
                    level += 1;
                }
                (rgba, w, h)
            });
        PatchArrays {
            positions,
            normals,
            colors,
            uvs,
            indices: patch.indices.clone(),
            texture,
            targets,
            target_normals,
            target_colors,
            target_uvs,
            texel_lod,
        }
    }

    /// The model-space size of a texel of `patch`'s texture (0 without one).
    fn texel_size(&self, patch: &PatchData) -> f32 {
        patch
            .texture
            .as_ref()
            .filter(|t| !t.rgba.is_empty() || !t.blocks.is_empty())
            .map_or(0.0, |t| {
                tessera_format::patch_texel_size(patch, t.width, t.height, self.grid.step())
            })
    }

    /// [`tessera_format::texel_lod`] of `node` with texels of `texel_size`: its parent's
    /// when resident, else the one the parent's error allows.
    fn texel_lod(&self, node: u32, texel_size: f32) -> f32 {
        let Some(&(parent, error)) = self.parents.get(node as usize) else {
            return 0.0;
        };
        if parent == tessera_format::NO_NODE {
            return 0.0;
        }
        let parent_texel = self.held.get(&parent).map_or(0.0, |h| h.1);
        tessera_format::texel_lod(texel_size, parent_texel, error)
    }
}

impl ResidentStore for KeptStore {
    fn bytes_for(&self, patch: &PatchData) -> u64 {
        let tex = patch.texture.as_ref().map_or(0, |t| {
            tessera_render::texture_gpu_bytes(t.width, t.height, self.max_texture_dim)
        });
        patch.positions.len() as u64 * vertex_bytes(self.colors, self.textured, morphs(patch))
            + patch.indices.len() as u64 * 4
            + tex
    }
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        // As a patch that morphs (all but roots, nearly).
        u64::from(vertices) * vertex_bytes(self.colors, self.textured, true)
            + u64::from(triangles) * 12
    }
    fn estimate_texture_bytes(&self, size: [u16; 2]) -> u64 {
        tessera_render::texture_gpu_bytes(
            u32::from(size[0]),
            u32::from(size[1]),
            self.max_texture_dim,
        )
    }
    fn upload_in_group(
        &mut self,
        node: u32,
        patch: &PatchData,
        siblings: &[&PatchData],
    ) -> Result<u64, StoreError> {
        self.evict(node);
        let bytes = self.bytes_for(patch);
        let texel_size = self.texel_size(patch);
        let lod = self.texel_lod(node, texel_size);
        let arrays = self.arrays(patch, siblings, lod);
        self.held.insert(node, (bytes, texel_size, Some(arrays)));
        self.bytes += bytes;
        self.added.push(node);
        Ok(bytes)
    }
    fn evict(&mut self, node: u32) {
        if let Some((b, _, _)) = self.held.remove(&node) {
            self.bytes -= b;
            self.removed.push(node);
            self.evicted += 1;
        }
    }
    fn resident_bytes(&self) -> u64 {
        self.bytes
    }
}

/// The kept arrays as the driver's stores (one model): a grown index extends the
/// parents table the texel detail is read from.
impl SceneStores for KeptStore {
    type Store<'a>
        = &'a mut KeptStore
    where
        Self: 'a;
    fn store(&mut self, _model: usize) -> &mut KeptStore {
        self
    }
    fn index_grown(&mut self, _model: usize, index: &ModelIndex) {
        self.parents = parents_of(index);
    }
}

/// Each node's parent and the parent's error (none for a root: `NO_NODE`, 0).
fn parents_of(index: &ModelIndex) -> Vec<(u32, f32)> {
    index
        .nodes()
        .iter()
        .map(|n| {
            let e = index
                .nodes()
                .get(n.parent as usize)
                .map_or(0.0, |p| p.error);
            (n.parent, e)
        })
        .collect()
}

/// A remote model streamed for the page's own renderer (the three.js adapter): see the
/// module docs.
#[wasm_bindgen]
pub struct Stream {
    /// The model streamed (what the canvas viewer shares).
    m: Streamed,
    store: KeptStore,
    nav: Navigator,
    points_min: DVec3,
    points_max: DVec3,
}

fn err(msg: impl std::fmt::Display) -> JsError {
    JsError::new(&msg.to_string())
}

fn set(obj: &js_sys::Object, key: &str, value: &JsValue) {
    let _ = js_sys::Reflect::set(obj, &JsValue::from_str(key), value);
}

#[wasm_bindgen]
impl Stream {
    /// Opens the model at `url`. `options` is a JSON object: `tolerancePx` (default 1),
    /// `memoryBytes` (default 512 MiB: half for the resident patches' arrays and
    /// textures, as the page's GPU holds them, a quarter for decoded patches waiting),
    /// `prefixBytes` (as [`crate::Viewer::open`]), `maxTextureDim` (the page's largest
    /// texture, default 4096: larger patch textures are handed over from their first
    /// mip that fits). Errors carry a message meant for the page.
    pub async fn open(url: String, options: String) -> Result<Stream, JsError> {
        let opened_ms = now_ms();
        let (o, _) = StreamOptions::parse(&options)?;
        let opened = open_model(&url, o.prefix_bytes).await?;
        let grid = Grid::of_header(opened.index.header());
        let nav = home_navigator(&opened.scene, grid.step(), 1280, 720);
        let (points_min, points_max) = (opened.scene.min, opened.scene.max);
        let (http, index, roots, rest) = opened.split();
        let index = Arc::new(index);
        let header = index.header();
        let colors = header.attributes & ATTR_COLORS != 0;
        let textured = header.attributes & ATTR_TEXTURE != 0;
        let b = header.bounding_sphere;
        // The positions' origin: the bounding sphere's centre on the quantisation grid's
        // origin side, so f32 positions keep their precision about the model.
        let origin = DVec3::new(b[0], b[1], b[2]);
        let mut scheduler = new_scheduler(&index, &o);
        // The workers need not make mips: WebGL makes them at upload.
        let mut source = Remote::new(http, &index, roots, false);
        let mut store = KeptStore {
            grid,
            origin,
            // Textured models draw their texture alone (as the native textured pipeline).
            colors: colors && !textured,
            textured,
            max_texture_dim: o.max_texture_dim.unwrap_or(4096),
            held: FxHashMap::default(),
            parents: parents_of(&index),
            bytes: 0,
            added: Vec::new(),
            removed: Vec::new(),
            evicted: 0,
        };
        scheduler.load_roots(&mut source, &mut store);
        Ok(Stream {
            m: Streamed::new(index, scheduler, source, rest, opened_ms),
            store,
            nav,
            points_min,
            points_max,
        })
    }

    /// Decodes fetched patches with `decode` ([`crate::Viewer::set_decoder`]).
    pub fn set_decoder(&mut self, decode: js_sys::Function, workers: u32) {
        self.m.source_mut().set_decoder(decode, workers);
    }

    /// Changes the screen-space tolerance (pixels).
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        self.m.scheduler_mut().set_tolerance_px(tolerance_px);
    }

    /// Changes the memory budget (bytes; split as at open, and shared with the page's
    /// other models as at open): lowering it evicts down to it at the next frame
    /// (unused patches first, then the drawn cut coarsened).
    pub fn set_memory_bytes(&mut self, bytes: f64) {
        self.m.set_memory(bytes.max(0.0) as u64);
    }

    /// Model coordinates of the origin the patch positions are relative to.
    pub fn origin(&self) -> Vec<f64> {
        self.store.origin.to_array().to_vec()
    }

    /// The roots' box in model coordinates: `[min x, y, z, max x, y, z]`.
    pub fn bounds(&self) -> Vec<f64> {
        let (a, b) = (self.points_min, self.points_max);
        vec![a.x, a.y, a.z, b.x, b.y, b.z]
    }

    /// The desktop's home view of `width` x `height` pixels (docs/camera.md JSON): framed
    /// by the roots, up guessed from their box.
    pub fn home_camera(&mut self, width: u32, height: u32) -> String {
        self.nav.resize(width.max(1), height.max(1));
        self.nav.home_camera().to_json_string()
    }

    /// The model's guessed up axis (`"+y"`, `"-z"`, ...).
    pub fn up_axis(&self) -> String {
        self.nav.up().to_string()
    }

    /// One frame of the view `camera_json` (docs/camera.md, model coordinates; width
    /// and height the drawing buffer's) at `time_ms`: answers in, requests out,
    /// patches made resident and evicted (then [`Stream::take_removed`],
    /// [`Stream::take_added`], [`Stream::draw`]). Returns the statistics as JSON; a
    /// fatal streaming error comes back as an exception.
    pub fn frame(&mut self, camera_json: &str, time_ms: f64) -> Result<String, JsError> {
        if let Some(m) = self.m.source().fatal.borrow().as_ref() {
            return Err(err(m));
        }
        let camera = Camera::from_json_str(camera_json).map_err(|e| err(format!("camera: {e}")))?;
        // The shared driver, as the canvas viewer's and the desktop's.
        self.m.driver.frame(&camera, time_ms / 1e3, &mut self.store);
        self.m.framed();
        let converged = self.m.settled();
        self.m.converged(converged);
        let s = self.m.stats();
        let mut out = self.m.stats_json(converged);
        let own = json!({
            "resident_nodes": self.store.held.len(),
            "evicted": self.store.evicted,
            // Bytes of the resident patches as the page holds them, and the budget.
            "resident_bytes": s.gpu_resident_bytes,
            "budget_bytes": s.gpu_budget_bytes,
            "textured": self.store.textured,
            "colors": self.store.colors,
        });
        if let (serde_json::Value::Object(o), serde_json::Value::Object(mine)) = (&mut out, own) {
            o.extend(mine);
        }
        Ok(out.to_string())
    }

    /// Nodes evicted since the last call (their meshes are to be disposed).
    pub fn take_removed(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.store.removed)
    }

    /// Nodes made resident since the last call and still resident (their arrays wait
    /// in [`Stream::take_patch`]). Take the removed first: a node evicted and made
    /// resident again is in both.
    pub fn take_added(&mut self) -> Vec<u32> {
        let mut added = std::mem::take(&mut self.store.added);
        added.sort_unstable();
        added.dedup();
        added.retain(|n| self.store.held.get(n).is_some_and(|h| h.2.is_some()));
        added
    }

    /// The arrays of resident `node`'s patch, handed over once (this side keeps only
    /// its byte count): an object of `positions` (Float32Array x 3, model coordinates
    /// minus [`Stream::origin`]), `normals` (Float32Array x 3, may be empty), `colors`
    /// (Float32Array x 3, linear, empty without vertex colours), `uvs` (Float32Array
    /// x 2 into the patch texture, v down, empty without one), `indices`
    /// (Uint32Array), and with a texture `texture` (Uint8Array RGBA8, rows top to
    /// bottom), `width`, `height`; `level`; the morph targets `targets`,
    /// `targetNormals`, `targetColors`, `targetUvs` (as the own arrays, all empty when
    /// no vertex moves) and `texelLod` (drawn at ratio r, sample the texture no finer
    /// than mip level r * texelLod). Undefined when not resident or taken.
    pub fn take_patch(&mut self, node: u32) -> JsValue {
        let Some(a) = self.store.held.get_mut(&node).and_then(|h| h.2.take()) else {
            return JsValue::UNDEFINED;
        };
        let o = js_sys::Object::new();
        set(
            &o,
            "positions",
            &js_sys::Float32Array::from(&a.positions[..]).into(),
        );
        set(
            &o,
            "normals",
            &js_sys::Float32Array::from(&a.normals[..]).into(),
        );
        set(
            &o,
            "colors",
            &js_sys::Float32Array::from(&a.colors[..]).into(),
        );
        set(&o, "uvs", &js_sys::Float32Array::from(&a.uvs[..]).into());
        set(
            &o,
            "indices",
            &js_sys::Uint32Array::from(&a.indices[..]).into(),
        );
        let f32s = |key: &str, v: &[f32]| set(&o, key, &js_sys::Float32Array::from(v).into());
        f32s("targets", &a.targets);
        f32s("targetNormals", &a.target_normals);
        f32s("targetColors", &a.target_colors);
        f32s("targetUvs", &a.target_uvs);
        set(&o, "texelLod", &JsValue::from(a.texel_lod));
        if let Some((rgba, w, h)) = &a.texture {
            set(&o, "texture", &js_sys::Uint8Array::from(&rgba[..]).into());
            set(&o, "width", &JsValue::from(*w));
            set(&o, "height", &JsValue::from(*h));
        }
        let level = self
            .m
            .index()
            .nodes()
            .get(node as usize)
            .map_or(0, |n| n.level);
        set(&o, "level", &JsValue::from(level));
        o.into()
    }

    /// The nodes to show this frame (the scheduler's draw list: a crack-free cut of
    /// what is resident).
    pub fn draw(&self) -> Vec<u32> {
        self.m.scheduler().draw().to_vec()
    }

    /// The morph ratio of each node of [`Stream::draw`] (same order): 0 draws a patch at
    /// its own shape, 1 at its parent's (blend each vertex toward its target by it). All
    /// zero with morphing off.
    pub fn ratios(&self) -> Vec<f32> {
        let r = self.m.scheduler().morph_ratios();
        (0..self.m.scheduler().draw().len())
            .map(|k| r.get(k).copied().unwrap_or(0.0))
            .collect()
    }

    /// Turns geomorphing on or off from the next frame on.
    pub fn set_morph(&mut self, enabled: bool) {
        self.m.scheduler_mut().set_morph(enabled);
    }

    /// Stops streaming: requests in flight finish into nothing (also on drop).
    pub fn close(&mut self) {
        self.m.source().closed.set(true);
    }
}
