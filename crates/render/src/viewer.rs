//! A view of one model: selection, paging, GPU cache and drawing tied together, one call
//! per frame. Shared by `tessera render`, the tests and (next) the window and the server.
//!
//! Three modes:
//! - [`Mode::Progressive`] (interactive): the frame never waits. It draws the best cut of
//!   what is on the GPU, asks the [`Pager`] for what is missing (visible first, then the
//!   prefetch set) and uploads, within a per-frame byte budget, the groups whose patches
//!   the loader threads have finished. Coarser nodes stand in until then.
//! - [`Mode::Complete`] (offline frames, references): the same cut as if everything were
//!   resident; missing patches are decoded on the spot (in parallel), and a cut larger
//!   than the GPU cache is drawn in several passes, evicting between them.
//! - [`Mode::FullResolution`]: every leaf, no culling: the brute-force reference.

use std::sync::Arc;
use std::time::{Duration, Instant};

use rayon::prelude::*;
use rustc_hash::FxHashSet;
use serde::Serialize;
use tessera_format::{Model, PatchData, ATTR_COLORS, NO_NODE};
use tessera_page::{Event, Pager, PagerOptions};
use tessera_select::{
    predict_camera, prefetch_set, select_resident, should_unload, Camera, NodeView,
    PrefetchOptions, Selection, ViewParams,
};

use crate::cache::{GpuCache, Slot, UploadError};
use crate::gpu::Gpu;
use crate::groups::{Groups, Readiness};
use crate::image::Image;
use crate::renderer::{FrameParams, Renderer};
use crate::RenderError;

/// Select-upload rounds per progressive frame (each round's uploads make the next
/// level wanted).
const MAX_UPLOAD_ROUNDS: usize = 8;
/// Sphere growth of the prefetch set.
const PREFETCH_GROWTH: f32 = 1.5;
/// Sphere growth of the unload test (more than the prefetch growth: hysteresis).
const UNLOAD_GROWTH: f32 = 2.0;

/// How frames are produced; see the module docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    Progressive,
    Complete,
    FullResolution,
}

/// Options of a [`Viewer`].
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// Screen-space error tolerance, pixels.
    pub tolerance_px: f32,
    /// Frustum and normal-cone culling.
    pub cull: bool,
    pub mode: Mode,
    /// GPU cache budget (vertex + index buffers). Default 256 MiB.
    pub gpu_budget_bytes: u64,
    /// Pager RAM budget (decoded patches). Default 128 MiB.
    pub ram_budget_bytes: u64,
    /// Loader threads of the pager. Default 1.
    pub loader_threads: usize,
    /// Test hook: every patch read is delayed by this much (progressive mode).
    pub read_delay: Option<Duration>,
    /// Most bytes uploaded to the GPU per progressive frame. Default 32 MiB.
    pub upload_budget_bytes: u64,
    /// Ask for the prefetch set (grown spheres, predicted camera). Default on.
    pub prefetch: bool,
    /// Clear colour, linear RGBA.
    pub background: [f64; 4],
}

impl Default for ViewerOptions {
    fn default() -> Self {
        ViewerOptions {
            tolerance_px: 1.0,
            cull: true,
            mode: Mode::Progressive,
            gpu_budget_bytes: 256 << 20,
            ram_budget_bytes: 128 << 20,
            loader_threads: 1,
            read_delay: None,
            upload_budget_bytes: 32 << 20,
            prefetch: true,
            background: [0.06, 0.07, 0.09, 1.0],
        }
    }
}

/// What one frame did (written per frame by `tessera render --stats`).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct FrameStats {
    pub frame: u64,
    /// Nodes drawn.
    pub selected_nodes: usize,
    pub triangles: u64,
    /// Deepest level drawn.
    pub max_level: u8,
    /// Bytes written to the GPU cache this frame.
    pub bytes_uploaded: u64,
    pub patches_uploaded: usize,
    /// Drawn nodes that were already on the GPU when the frame began.
    pub cache_hits: usize,
    /// Nodes the view needed that were not on the GPU when the frame began.
    pub cache_misses: usize,
    /// Progressive: patches asked of the loader and not yet on the GPU.
    pub pending_loads: usize,
    /// Patches that failed to load (bad checksum, truncation), cumulative.
    pub failed_patches: usize,
    /// CPU time of selection + prefetch, milliseconds.
    pub selection_ms: f64,
    /// Wall time of the frame until the GPU finished drawing it, milliseconds.
    pub frame_ms: f64,
    /// Render passes (more than one when a cut did not fit the GPU cache).
    pub passes: u32,
    pub gpu_resident_bytes: u64,
    /// Patches evicted from the GPU cache so far.
    pub gpu_evictions: u64,
    pub ram_resident_bytes: u64,
}

/// See the module docs.
pub struct Viewer {
    gpu: Gpu,
    renderer: Renderer,
    cache: GpuCache,
    model: Arc<Model>,
    nv: NodeView,
    groups: Groups,
    readiness: Readiness,
    pager: Pager,
    opts: ViewerOptions,
    quant_step: f64,
    /// Increases every selection (memo epoch) and every pass (LRU stamp).
    epoch: u64,
    frame: u64,
    sel: Selection,
    prefetch: Vec<(u32, f32)>,
    prev_camera: Option<(Camera, Instant)>,
    failed: FxHashSet<u32>,
    /// Per group: stamp of the last closure walk (needed-groups search).
    visit: Vec<u64>,
}

impl Viewer {
    /// Opens a viewer on `model` with its own headless device.
    pub fn new(model: Arc<Model>, opts: ViewerOptions) -> Result<Viewer, RenderError> {
        let gpu = Gpu::headless()?;
        Self::with_gpu(gpu, model, opts)
    }

    /// Opens a viewer on `model` with an existing device.
    pub fn with_gpu(
        gpu: Gpu,
        model: Arc<Model>,
        opts: ViewerOptions,
    ) -> Result<Viewer, RenderError> {
        let mut renderer = Renderer::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
        renderer.background = opts.background;
        renderer.has_colors = model.header().attributes & ATTR_COLORS != 0;
        let cache = GpuCache::new(&gpu.device, opts.gpu_budget_bytes);
        let nv = NodeView::new(model.header(), model.nodes());
        let groups = Groups::new(&nv, model.nodes());
        let readiness = Readiness::new(groups.len());
        let pager = Pager::new(
            model.clone(),
            PagerOptions {
                ram_budget_bytes: opts.ram_budget_bytes,
                threads: opts.loader_threads,
                read_delay: opts.read_delay,
            },
        );
        let quant_step = model.quant_step();
        let visit = vec![0; groups.len()];
        let mut v = Viewer {
            gpu,
            renderer,
            cache,
            model,
            nv,
            groups,
            readiness,
            pager,
            opts,
            quant_step,
            epoch: 1,
            frame: 0,
            sel: Selection::default(),
            prefetch: Vec::new(),
            prev_camera: None,
            failed: FxHashSet::default(),
            visit,
        };
        v.load_roots();
        Ok(v)
    }

    /// Decodes and uploads the roots synchronously (a few small patches), so the first
    /// frame shows the whole model at its coarsest level; nothing else is loaded before
    /// it. A root that fails to load is skipped (a hole, reported).
    fn load_roots(&mut self) {
        let roots: Vec<u32> = (0..self.nv.root_count()).collect();
        let decoded = self.decode_many(&roots);
        self.epoch += 1;
        for (n, r) in decoded {
            let g = self.groups.of(n);
            match r.and_then(|p| {
                self.cache
                    .upload(
                        &self.gpu.device,
                        &self.gpu.queue,
                        n,
                        g,
                        &p,
                        self.quant_step,
                        self.epoch,
                        &|_| true,
                    )
                    .map_err(|e| format!("{e:?}"))
            }) {
                // Roots stay resident for the viewer's lifetime: they are the fallback
                // for everything else.
                Ok(_) => self.cache.pin_group(g),
                Err(error) => {
                    tracing::warn!(node = n, %error, "root patch skipped");
                    self.failed.insert(n);
                }
            }
        }
    }

    /// Decodes `nodes` in parallel (CRC checked); errors as text.
    fn decode_many(&self, nodes: &[u32]) -> Vec<(u32, Result<PatchData, String>)> {
        let model = &self.model;
        nodes
            .par_iter()
            .map(|&n| (n, model.decode_patch(n as usize).map_err(|e| e.to_string())))
            .collect()
    }

    /// The device (e.g. to report the adapter).
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The model.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The options.
    pub fn options(&self) -> &ViewerOptions {
        &self.opts
    }

    /// Nodes drawn by the last frame.
    pub fn last_draw(&self) -> &[u32] {
        &self.sel.draw
    }

    /// Renders one frame of `camera` into the offscreen target (camera.width x
    /// camera.height); read it with [`Viewer::read_image`].
    pub fn render(&mut self, camera: &Camera) -> Result<FrameStats, RenderError> {
        let t0 = Instant::now();
        self.frame += 1;
        self.renderer
            .ensure_offscreen(&self.gpu.device, camera.width, camera.height);
        let h = self.model.header();
        let params = FrameParams::new(camera, h.cube_origin, h.bounding_sphere);
        self.renderer.set_frame(&self.gpu.queue, &params);
        let mut stats = match self.opts.mode {
            Mode::Progressive => self.progressive(camera)?,
            Mode::Complete | Mode::FullResolution => self.complete(camera)?,
        };
        self.gpu.wait_idle()?;
        stats.frame = self.frame;
        stats.frame_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.failed_patches = self.failed.len();
        let cs = self.cache.stats();
        stats.gpu_resident_bytes = cs.resident_bytes;
        stats.gpu_evictions = cs.evictions;
        stats.ram_resident_bytes = self.pager.stats().resident_bytes;
        stats.selected_nodes = self.sel.draw.len();
        let nodes = self.model.nodes();
        stats.triangles = self
            .sel
            .draw
            .iter()
            .map(|&n| u64::from(nodes[n as usize].triangle_count))
            .sum();
        stats.max_level = self
            .sel
            .draw
            .iter()
            .map(|&n| nodes[n as usize].level)
            .max()
            .unwrap_or(0);
        self.prev_camera = Some((camera.clone(), t0));
        Ok(stats)
    }

    /// The last frame's pixels.
    pub fn read_image(&self) -> Result<Image, RenderError> {
        self.renderer
            .read_offscreen(&self.gpu.device, &self.gpu.queue)
    }

    fn view_params(&self, camera: &Camera) -> ViewParams {
        ViewParams::new(
            camera,
            self.model.header().cube_origin,
            self.opts.tolerance_px,
            self.opts.cull,
        )
    }

    fn drain_events(&mut self) {
        for e in self.pager.poll() {
            if let Event::Failed { node, error } = e {
                tracing::warn!(node, %error, "patch skipped, its parent is shown instead");
                self.failed.insert(node);
            }
        }
    }

    /// Selection over what the GPU holds (groups complete and reachable).
    fn select_on_gpu(&mut self, view: &ViewParams) {
        self.epoch += 1;
        let epoch = self.epoch;
        let groups = &self.groups;
        let cache = &self.cache;
        let readiness = std::cell::RefCell::new(&mut self.readiness);
        let complete = |g: u32| cache.group_resident(g) == groups.members(g).len();
        let resident = |n: u32| {
            readiness
                .borrow_mut()
                .ready(groups, groups.of(n), epoch, &complete)
        };
        select_resident(&self.nv, view, &resident, &mut self.sel);
    }

    /// Marks the groups of the drawn nodes and of all their ancestors as used now.
    fn touch_draw_set(&mut self) {
        // The groups of the drawn nodes and everything they depend on (which includes
        // the groups of all their ancestors): evicting any of them would make a drawn
        // group unusable.
        self.epoch += 1;
        let stamp = self.epoch;
        let mut stack: Vec<u32> = Vec::new();
        for &n in &self.sel.draw {
            stack.push(self.groups.of(n));
            while let Some(g) = stack.pop() {
                if self.visit[g as usize] == stamp {
                    continue;
                }
                self.visit[g as usize] = stamp;
                self.cache.touch_group(g, stamp);
                stack.extend_from_slice(self.groups.dependencies(g));
            }
        }
    }

    /// Groups (with priority) that must be loaded for the missing nodes: each one's
    /// group and, transitively, the incomplete groups it depends on (deps first).
    fn needed_groups(&mut self) -> Vec<(u32, f32)> {
        self.epoch += 1;
        let stamp = self.epoch;
        let mut out = Vec::new();
        let mut stack = Vec::new();
        for &(n, pri) in &self.sel.missing {
            let pri = if pri.is_finite() { pri } else { 1e9 };
            stack.push((self.groups.of(n), 0u32));
            while let Some((g, depth)) = stack.pop() {
                if self.visit[g as usize] == stamp {
                    continue;
                }
                self.visit[g as usize] = stamp;
                if self.cache.group_resident(g) < self.groups.members(g).len() {
                    // Dependencies are nearer the root: load them first.
                    out.push((g, pri + depth as f32));
                }
                for &d in self.groups.dependencies(g) {
                    stack.push((d, depth + 1));
                }
            }
        }
        out.sort_by(|a, b| b.1.total_cmp(&a.1));
        out
    }

    fn group_failed(&self, g: u32) -> bool {
        group_has_failure(&self.groups, &self.failed, g)
    }

    fn progressive(&mut self, camera: &Camera) -> Result<FrameStats, RenderError> {
        let mut stats = FrameStats::default();
        self.drain_events();
        let view = self.view_params(camera);
        let ts = Instant::now();
        self.select_on_gpu(&view);
        let draw_before: Vec<u32> = self.sel.draw.clone();
        stats.cache_misses = self.sel.missing.len();
        if self.opts.prefetch {
            let predicted = self.prev_camera.as_ref().map(|(prev, t)| {
                let dt = t.elapsed().as_secs_f64();
                predict_camera(prev, camera, dt, dt * 4.0)
            });
            let popts = PrefetchOptions {
                sphere_growth: PREFETCH_GROWTH,
                predicted,
            };
            prefetch_set(&self.nv, &view, &popts, &mut self.prefetch);
        } else {
            self.prefetch.clear();
        }
        stats.selection_ms = ts.elapsed().as_secs_f64() * 1e3;

        // Upload finished groups, most urgent first, within the byte budget; then select
        // again, since uploaded groups make their children wanted, which the loader may
        // already hold (prefetched). A few rounds per frame, never waiting.
        let mut budget = self.opts.upload_budget_bytes;
        let mut wanted: Vec<(u32, f32)> = Vec::new();
        let mut pin: Vec<u32> = Vec::new();
        let mut stale = false;
        for round in 0..MAX_UPLOAD_ROUNDS {
            let ts = Instant::now();
            if round > 0 {
                self.select_on_gpu(&view);
            }
            self.touch_draw_set();
            let needed = self.needed_groups();
            stats.selection_ms += ts.elapsed().as_secs_f64() * 1e3;
            let stamp = self.epoch;
            wanted.clear();
            pin.clear();
            let uploads_before = stats.patches_uploaded;
            // Hysteresis: evict first what even a view with spheres grown by 2 (more than
            // the prefetch growth) would not need.
            let (nv, groups) = (&self.nv, &self.groups);
            let unloadable = |g: u32| {
                groups
                    .members(g)
                    .iter()
                    .all(|&m| should_unload(nv, m, &view, UNLOAD_GROWTH))
            };
            for &(g, pri) in &needed {
                if self.group_failed(g) {
                    continue;
                }
                let members = self.groups.members(g);
                let mut patches: Vec<(u32, Arc<PatchData>)> = Vec::with_capacity(members.len());
                let mut all = true;
                for &m in members {
                    if self.cache.contains(m) {
                        continue;
                    }
                    match self.pager.get(m) {
                        Some(p) => patches.push((m, p)),
                        None => {
                            all = false;
                            wanted.push((m, 1e6 + pri));
                        }
                    }
                }
                let size: u64 = patches
                    .iter()
                    .map(|(_, p)| crate::cache::patch_gpu_bytes(p))
                    .sum();
                // The budget may be exceeded by the first group of a frame, so a group
                // larger than the budget still loads.
                if !all || (size > budget && stats.patches_uploaded > 0) {
                    pin.extend(patches.iter().map(|(m, _)| *m));
                    continue;
                }
                for (m, p) in &patches {
                    match self.cache.upload(
                        &self.gpu.device,
                        &self.gpu.queue,
                        *m,
                        g,
                        p,
                        self.quant_step,
                        stamp,
                        &unloadable,
                    ) {
                        Ok(b) => {
                            budget -= b.min(budget);
                            stats.bytes_uploaded += b;
                            stats.patches_uploaded += 1;
                        }
                        Err(UploadError::Full) => break,
                        Err(UploadError::TooBig) => {
                            tracing::warn!(node = m, "patch larger than the GPU cache, skipped");
                            self.failed.insert(*m);
                        }
                    }
                }
                // Keep the group from being evicted by later uploads of this frame.
                self.cache.touch_group(g, stamp);
            }
            stale = stats.patches_uploaded > uploads_before;
            if !stale {
                break;
            }
        }
        if stale {
            // The last round uploaded: draw what it made usable.
            let ts = Instant::now();
            self.select_on_gpu(&view);
            self.touch_draw_set();
            stats.selection_ms += ts.elapsed().as_secs_f64() * 1e3;
        }
        // Prefetch: lower priorities than anything visible.
        for &(n, pri) in &self.prefetch {
            if !self.cache.contains(n) && !self.pager.is_resident(n) {
                wanted.push((n, pri.min(1e5)));
            }
        }
        self.pager.request(&wanted);
        let advise: Vec<u32> = self.prefetch.iter().map(|&(n, _)| n).collect();
        self.pager.advise(&advise);
        self.pager.pin(&pin);
        // Asked for and not yet read (the pager drops what is resident or in flight).
        stats.pending_loads = self.pager.stats().pending;
        let before: FxHashSet<u32> = draw_before.into_iter().collect();
        stats.cache_hits = self.sel.draw.iter().filter(|n| before.contains(n)).count();
        self.submit_pass(
            self.sel.draw.iter().filter_map(|&n| self.cache.slot(n)),
            true,
        )?;
        stats.passes = 1;
        Ok(stats)
    }

    /// Encodes and submits one render pass drawing `slots` into the offscreen target;
    /// `clear` starts the frame, otherwise the pass adds to what is there.
    fn submit_pass<'a>(
        &'a self,
        slots: impl Iterator<Item = &'a Slot>,
        clear: bool,
    ) -> Result<(), RenderError> {
        let (color, depth) = self
            .renderer
            .offscreen_views()
            .ok_or(RenderError::NoFrame)?;
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("tessera frame encoder"),
            });
        self.renderer
            .encode_pass(&mut enc, color, depth, &self.cache, slots, clear);
        self.gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    fn complete(&mut self, camera: &Camera) -> Result<FrameStats, RenderError> {
        let mut stats = FrameStats::default();
        let ts = Instant::now();
        let full = self.opts.mode == Mode::FullResolution;
        if full {
            self.sel.draw.clear();
            self.sel.missing.clear();
            let hot = self.nv.nodes();
            self.sel.draw.extend(
                (0..hot.len() as u32)
                    .filter(|&n| hot[n as usize].children == [NO_NODE, NO_NODE])
                    .filter(|n| !self.failed.contains(n)),
            );
        } else {
            let view = self.view_params(camera);
            let (failed, groups) = (&self.failed, &self.groups);
            // Everything counts as resident except groups with a failed member.
            let ok = |n: u32| !group_has_failure(groups, failed, groups.of(n));
            select_resident(&self.nv, &view, &ok, &mut self.sel);
        }
        stats.selection_ms = ts.elapsed().as_secs_f64() * 1e3;

        self.epoch += 1;
        let mut stamp = self.epoch;
        let mut todo: Vec<u32> = Vec::new();
        for &n in &self.sel.draw {
            match self.cache.slot(n).map(|s| s.group) {
                Some(g) => {
                    self.cache.touch_group(g, stamp);
                    stats.cache_hits += 1;
                }
                None => todo.push(n),
            }
        }
        stats.cache_misses = todo.len();
        let mut drawn = vec![false; self.sel.draw.len()];
        let mut cleared = false;
        let mut next = 0;
        loop {
            // Decode and upload batches until everything is on the GPU or it is full.
            let mut full_now = false;
            while next < todo.len() && !full_now {
                let batch = &todo[next..(next + 64).min(todo.len())];
                let decoded = self.decode_many(batch);
                for (i, (n, r)) in decoded.into_iter().enumerate() {
                    match r {
                        Ok(p) => {
                            let g = self.groups.of(n);
                            match self.cache.upload(
                                &self.gpu.device,
                                &self.gpu.queue,
                                n,
                                g,
                                &p,
                                self.quant_step,
                                stamp,
                                &|_| true,
                            ) {
                                Ok(b) => {
                                    stats.bytes_uploaded += b;
                                    stats.patches_uploaded += 1;
                                    self.cache.touch_group(g, stamp);
                                }
                                Err(UploadError::Full) => {
                                    full_now = true;
                                    next += i;
                                    break;
                                }
                                Err(UploadError::TooBig) => {
                                    tracing::warn!(node = n, "patch larger than the GPU cache");
                                    self.failed.insert(n);
                                }
                            }
                        }
                        Err(error) => {
                            tracing::warn!(node = n, %error, "patch skipped");
                            self.failed.insert(n);
                        }
                    }
                }
                if !full_now {
                    next += batch.len();
                }
                // Flush the staged writes of this batch now: wgpu keeps a staging copy of
                // every write until the next submit, which would double the memory of a
                // cut streamed through the cache.
                self.gpu.queue.submit([]);
            }
            // One pass over what is on the GPU and not drawn yet.
            let cache = &self.cache;
            let mut slots = Vec::new();
            for (i, &n) in self.sel.draw.iter().enumerate() {
                if !drawn[i] {
                    if let Some(s) = cache.slot(n) {
                        slots.push(s);
                        drawn[i] = true;
                    }
                }
            }
            if slots.is_empty() && cleared && next >= todo.len() {
                break;
            }
            if slots.is_empty() && full_now {
                // Nothing fits even in an empty cache.
                return Err(RenderError::CacheTooSmall);
            }
            self.submit_pass(slots.into_iter(), !cleared)?;
            cleared = true;
            stats.passes += 1;
            if next >= todo.len() {
                break;
            }
            // Make room: everything drawn so far may go (writes of the next uploads are
            // ordered after the pass just submitted).
            self.epoch += 1;
            stamp = self.epoch;
            self.cache.evict_unused(stamp);
        }
        // Corrupt patches found now: a complete frame without them needs a new cut.
        if !full && self.sel.draw.iter().any(|n| self.failed.contains(n)) {
            tracing::warn!("corrupt patches in the cut; the next frame shows their parents");
        }
        Ok(stats)
    }
}

/// Whether a member of group `g` failed to load (such a group can never be complete).
fn group_has_failure(groups: &Groups, failed: &FxHashSet<u32>, g: u32) -> bool {
    groups.members(g).iter().any(|m| failed.contains(m))
}
