//! The frame scheduler: what one frame draws, asks for, uploads and evicts.
//!
//! Three modes ([`Mode`]):
//! - **progressive** ([`Scheduler::frame`], interactive): the frame never waits. It
//!   selects the best cut of what the store holds, asks the [`PatchSource`] for what is
//!   missing (visible first, then the prefetch set) and uploads, within a per-frame byte
//!   budget, the groups whose patches have all arrived. Coarser nodes stand in until then.
//! - **complete** ([`Scheduler::complete_frame`], offline frames, references): the cut as
//!   if everything were resident; missing patches are read on the spot
//!   ([`PatchSource::read_now`]) and a cut larger than the store is drawn in several
//!   passes, evicting between them.
//! - **full resolution**: every leaf, no culling: the brute-force reference.
//!
//! Crack-freedom while partly resident comes from residency groups ([`Groups`]): a
//! group counts only when all its members are resident and the groups it depends on
//! count. Eviction is by group, least recently used first, under a byte budget, never
//! a group touched in the current frame (the groups of the drawn nodes and everything
//! they depend on), and preferring groups that even a view with spheres grown by
//! [`UNLOAD_GROWTH`] would not need (hysteresis).
//!
//! Time: the scheduler reads no clock of its own; the caller passes the frame's time
//! (for camera prediction) and may pass a clock for the selection-time statistic.

use std::sync::Arc;

use rustc_hash::{FxHashMap, FxHashSet};
use serde::Serialize;
use tessera_format::{ModelIndex, PatchData, NO_NODE};
use tessera_select::{
    predict_camera, prefetch_set, select_resident, should_unload, wants_refinement, Camera,
    NodeView, PrefetchOptions, Selection, ViewParams,
};

use crate::groups::{Groups, Readiness};
use crate::lru::Lru;
use crate::morph::{Morph, MorphOptions};
use crate::source::{Answer, PatchSource};
use crate::store::{ResidentStore, StoreError};

/// Select-upload rounds per progressive frame (each round's uploads make the next
/// level wanted, often already prefetched).
pub const MAX_UPLOAD_ROUNDS: usize = 8;
/// Sphere growth of the prefetch set.
pub const PREFETCH_GROWTH: f32 = 1.5;
/// Sphere growth of the unload test (more than the prefetch growth: hysteresis).
pub const UNLOAD_GROWTH: f32 = 2.0;
/// Priority added to visible missing nodes so they load before any prefetch.
const VISIBLE_PRIORITY: f32 = 1e6;
/// Highest priority a prefetch request gets.
const PREFETCH_PRIORITY_MAX: f32 = 1e5;
/// Priority of the view's whole cut while groups wait for an arrival blend: visible
/// work, after the nodes the cut misses now.
const DEMAND_PRIORITY: f32 = VISIBLE_PRIORITY;
/// Patches read per batch by a complete frame.
const COMPLETE_BATCH: usize = 64;
/// Backoff before an unavailable patch is asked for again (doubling per failed try)...
pub const RETRY_FIRST_MS: f64 = 500.0;
/// ... up to this.
pub const RETRY_MAX_MS: f64 = 30_000.0;
/// Unavailable patches are reported (one warning) at most this often.
pub const REPORT_EVERY_MS: f64 = 60_000.0;

/// How frames are produced; see the module docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    Progressive,
    Complete,
    FullResolution,
}

/// A clock in milliseconds (only differences are used).
pub type Clock = fn() -> f64;

/// The default clock: monotonic milliseconds natively; on `wasm32-unknown-unknown`,
/// where `std::time::Instant` is unavailable, always 0 (a browser front end passes
/// `performance.now()` instead).
pub fn default_clock() -> f64 {
    #[cfg(not(target_arch = "wasm32"))]
    {
        use std::sync::OnceLock;
        use std::time::Instant;
        static START: OnceLock<Instant> = OnceLock::new();
        START.get_or_init(Instant::now).elapsed().as_secs_f64() * 1e3
    }
    #[cfg(target_arch = "wasm32")]
    {
        0.0
    }
}

/// Options of a [`Scheduler`].
#[derive(Clone, Debug)]
pub struct SchedulerOptions {
    /// Screen-space error tolerance, pixels.
    pub tolerance_px: f32,
    /// Frustum and normal-cone culling.
    pub cull: bool,
    pub mode: Mode,
    /// Budget of the resident store (GPU bytes). Default 256 MiB.
    pub store_budget_bytes: u64,
    /// Budget of decoded patches held in RAM. Default 128 MiB.
    pub ram_budget_bytes: u64,
    /// Most bytes uploaded per progressive frame (the first group of a frame may exceed
    /// it, so a group larger than the budget still loads). Default 32 MiB.
    pub upload_budget_bytes: u64,
    /// Ask for the prefetch set (grown spheres, predicted camera). Default on.
    pub prefetch: bool,
    /// Clock for the selection-time statistic.
    pub clock: Clock,
    /// Geomorphing: the ratios of [`Scheduler::morph_ratios`] and the arrival blend.
    pub morph: MorphOptions,
}

impl Default for SchedulerOptions {
    fn default() -> Self {
        SchedulerOptions {
            tolerance_px: 1.0,
            cull: true,
            mode: Mode::Progressive,
            store_budget_bytes: 256 << 20,
            ram_budget_bytes: 128 << 20,
            upload_budget_bytes: 32 << 20,
            prefetch: true,
            clock: default_clock,
            morph: MorphOptions::default(),
        }
    }
}

/// The one split of a front end's memory figure (`tessera render --memory`, `tessera
/// view --memory`, the browser's `memoryBytes`) into (store, RAM) budgets: half for
/// the resident store (GPU vertex, index and texture bytes), a quarter for decoded
/// patches in RAM; the last quarter is headroom for what no budget counts (patches in
/// flight between source and store, the index, the window or page).
pub fn memory_split(memory_bytes: u64) -> (u64, u64) {
    (memory_bytes / 2, memory_bytes / 4)
}

impl SchedulerOptions {
    /// The options with their store and RAM budgets from one memory figure
    /// ([`memory_split`]).
    pub fn with_memory(self, memory_bytes: u64) -> SchedulerOptions {
        let (store, ram) = memory_split(memory_bytes);
        SchedulerOptions {
            store_budget_bytes: store,
            ram_budget_bytes: ram,
            ..self
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
    /// Bytes written to the store this frame.
    pub bytes_uploaded: u64,
    pub patches_uploaded: usize,
    /// Drawn nodes that were already resident when the frame began.
    pub cache_hits: usize,
    /// Nodes the view needed that were not resident when the frame began.
    pub cache_misses: usize,
    /// Progressive: patches asked of the source and not answered yet.
    pub pending_loads: usize,
    /// Patches that failed to load (bad checksum, truncation), cumulative.
    pub failed_patches: usize,
    /// CPU time of selection + prefetch, milliseconds.
    pub selection_ms: f64,
    /// Wall time of the frame until the GPU finished drawing it, milliseconds (set by
    /// the front end).
    pub frame_ms: f64,
    /// Render passes (more than one when a cut did not fit the store).
    pub passes: u32,
    pub gpu_resident_bytes: u64,
    /// Patches evicted from the store so far.
    pub gpu_evictions: u64,
    pub ram_resident_bytes: u64,
    /// Drawn nodes the view would refine whose children lie beyond the part of a paged
    /// index read so far: the front end should read more of the index
    /// ([`Scheduler::set_index`] then takes it).
    pub index_wants: usize,
    /// The view's demand: store bytes of the groups its whole cut needs (the cut drawn
    /// if everything were resident, with the groups it depends on), resident or not;
    /// what this view would hold with an unlimited budget. A progressive frame measures
    /// it; a front end sharing one budget between models splits by it. 0 for a frame
    /// that draws nothing (hidden, or nothing in view).
    pub wanted_bytes: u64,
    /// The store budget this frame ran under ([`Scheduler::set_budgets`]).
    pub gpu_budget_bytes: u64,
    /// Mean morph ratio over the drawn non-root nodes (0: every one at its own shape).
    pub morph_mean: f32,
    /// Largest morph ratio drawn.
    pub morph_max: f32,
    /// Groups blending in after arriving late, and groups waiting for such a blend
    /// before they refine (progressive frames): the view is still changing.
    pub morph_blending: usize,
    /// Groups the view needs that this frame neither loaded nor asked for because the
    /// budgets are full (the store of groups in use, or RAM of the more urgent groups
    /// being assembled): with nothing pending, the view has done what its budgets
    /// allow (progressive frames).
    pub budget_limited: usize,
}

impl FrameStats {
    /// The statistics of several models' frames drawn as one (a scene): counts, bytes
    /// and times summed, the deepest level, the largest frame number and pass count.
    pub fn combined<'a>(parts: impl IntoIterator<Item = &'a FrameStats>) -> FrameStats {
        let mut out = FrameStats::default();
        for s in parts {
            out.frame = out.frame.max(s.frame);
            out.selected_nodes += s.selected_nodes;
            out.triangles += s.triangles;
            out.max_level = out.max_level.max(s.max_level);
            out.bytes_uploaded += s.bytes_uploaded;
            out.patches_uploaded += s.patches_uploaded;
            out.cache_hits += s.cache_hits;
            out.cache_misses += s.cache_misses;
            out.pending_loads += s.pending_loads;
            out.failed_patches += s.failed_patches;
            out.selection_ms += s.selection_ms;
            out.frame_ms = out.frame_ms.max(s.frame_ms);
            out.passes = out.passes.max(s.passes);
            out.gpu_resident_bytes += s.gpu_resident_bytes;
            out.gpu_evictions += s.gpu_evictions;
            out.ram_resident_bytes += s.ram_resident_bytes;
            out.index_wants += s.index_wants;
            out.wanted_bytes += s.wanted_bytes;
            out.gpu_budget_bytes += s.gpu_budget_bytes;
            // Weighted by nodes drawn (divided below).
            out.morph_mean += s.morph_mean * s.selected_nodes as f32;
            out.morph_max = out.morph_max.max(s.morph_max);
            out.morph_blending += s.morph_blending;
            out.budget_limited += s.budget_limited;
        }
        if out.selected_nodes > 0 {
            out.morph_mean /= out.selected_nodes as f32;
        }
        out
    }
}

/// Why a complete frame could not be drawn.
#[derive(Debug)]
pub enum CompleteError<E> {
    /// Nothing fits even in an empty store.
    StoreTooSmall,
    /// The source cannot read on demand (complete frames need it).
    NoBlockingReads,
    /// The front end's pass failed.
    Pass(E),
}

/// Per-node facts the statistics need (copied once from the index).
#[derive(Clone, Copy)]
struct NodeFacts {
    triangles: u32,
    vertices: u32,
    level: u8,
    /// The patch texture's size (`NodeRecord::texture_size`, `[0, 0]` without one).
    texture_size: [u16; 2],
}

/// What one needed group came to in an upload round ([`Scheduler::frame`]'s step 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum GroupStep {
    /// Uploaded whole.
    Uploaded,
    /// Not this round: failed, waiting for members, over a budget, or taken back.
    Skipped,
    /// The store is full of groups in use: the less urgent groups wait too.
    StoreFull,
}

/// The per-frame policy over one model. See the module docs.
pub struct Scheduler {
    nv: NodeView,
    groups: Groups,
    facts: Vec<NodeFacts>,
    /// Nodes with a child beyond the part of the index shown (a paged index read in
    /// part); empty for a whole index.
    cut_off: FxHashSet<u32>,
    opts: SchedulerOptions,
    /// Frames started: the one recency counter of both caches.
    frame: u64,
    /// Memo epoch of [`Readiness`] and of the group walks; separate from `frame`.
    epoch: u64,
    readiness: Readiness,
    /// Per group: epoch of the last walk that visited it.
    visit: Vec<u64>,
    /// What the store holds.
    res: Residency,
    /// Decoded patches in RAM.
    ram: Lru<Arc<PatchData>>,
    /// Nodes not asked for (failed, or unavailable until their retry time): their
    /// groups never count, their parents are drawn.
    failed: FxHashSet<u32>,
    /// Unavailable nodes (reads that failed): when to ask again (clock ms), tries.
    retry: FxHashMap<u32, (f64, u32)>,
    /// An unavailability was reported and nothing retried has loaded since.
    outage: bool,
    /// When unavailable patches were last reported (clock ms), and how many have been
    /// unavailable since.
    reported: Option<f64>,
    unreported: u64,
    sel: Selection,
    /// The whole cut of the last view (as if everything were resident): its demand.
    demand: Selection,
    prefetch: Vec<(u32, f32)>,
    prev_camera: Option<(Camera, f64)>,
    answers: Vec<Answer>,
    /// Morph ratios of the drawn nodes and the arrival blend.
    morph: Morph,
    /// Groups the last selection found complete but kept waiting for an arrival blend.
    blocked: Vec<u32>,
}

/// What the store holds, by node and by group, and the groups' LRU order. Apart from
/// the scheduler's read-only tables so an upload can borrow both.
struct Residency {
    /// Resident in the store, per node.
    resident: Vec<bool>,
    /// Resident members, per group.
    members: Vec<u32>,
    /// Groups in the store (value unused); bytes: store bytes of their resident members.
    lru: Lru<()>,
    /// Patches evicted so far.
    evictions: u64,
}

impl Residency {
    /// Whether every member of group `g` is in the store.
    fn complete(&self, groups: &Groups, g: u32) -> bool {
        self.members[g as usize] as usize == groups.members(g).len()
    }

    /// Removes every resident member of group `g` from the store.
    fn evict_group<R: ResidentStore + ?Sized>(&mut self, groups: &Groups, store: &mut R, g: u32) {
        self.lru.remove(g);
        for &m in groups.members(g) {
            if std::mem::replace(&mut self.resident[m as usize], false) {
                store.evict(m);
                self.evictions += 1;
            }
        }
        self.members[g as usize] = 0;
    }

    /// Evicts the least recently used group not used in `frame` (preferring those
    /// `prefer` accepts); false if there is none.
    fn evict_one<R: ResidentStore + ?Sized>(
        &mut self,
        groups: &Groups,
        store: &mut R,
        frame: u64,
        prefer: &impl Fn(u32) -> bool,
    ) -> bool {
        match self.lru.victim(frame, prefer) {
            Some(g) => {
                self.evict_group(groups, store, g);
                true
            }
            None => false,
        }
    }

    /// Evicts every group not used in `frame` and not pinned.
    fn evict_unused<R: ResidentStore + ?Sized>(
        &mut self,
        groups: &Groups,
        store: &mut R,
        frame: u64,
    ) {
        for g in self.lru.unused_since(frame) {
            self.evict_group(groups, store, g);
        }
    }

    /// Uploads `node` (member of group `g`) in `frame`, evicting groups not used in
    /// `frame` to stay within the budget (and when the store itself is full). `pin`:
    /// the group is never evicted (roots: the fallback for everything else).
    #[allow(clippy::too_many_arguments)]
    fn upload<R: ResidentStore + ?Sized>(
        &mut self,
        groups: &Groups,
        store: &mut R,
        frame: u64,
        (node, g, pin): (u32, u32, bool),
        (patch, siblings): (&PatchData, &[&PatchData]),
        prefer: &impl Fn(u32) -> bool,
    ) -> Result<u64, StoreError> {
        if self.resident[node as usize] {
            return Ok(0);
        }
        let need = store.bytes_for(patch);
        if need > self.lru.budget() {
            return Err(StoreError::TooBig);
        }
        while self.lru.would_exceed(need) {
            if !self.evict_one(groups, store, frame, prefer) {
                return Err(StoreError::Full);
            }
        }
        let bytes = loop {
            match store.upload_in_group(node, patch, siblings) {
                Ok(b) => break b,
                Err(StoreError::Full) => {
                    if !self.evict_one(groups, store, frame, prefer) {
                        return Err(StoreError::Full);
                    }
                }
                Err(e) => return Err(e),
            }
        };
        self.resident[node as usize] = true;
        self.members[g as usize] += 1;
        self.lru.insert(g, (), bytes, frame);
        if pin {
            self.lru.pin(g);
        }
        Ok(bytes)
    }
}

impl Scheduler {
    /// A scheduler for the model `index` describes; nothing is resident yet.
    pub fn new(index: &ModelIndex, opts: SchedulerOptions) -> Scheduler {
        let (nv, groups, facts, cut_off) = Self::tables(index);
        let g = groups.len();
        let n = nv.len();
        Scheduler {
            readiness: Readiness::new(g),
            visit: vec![0; g],
            res: Residency {
                resident: vec![false; n],
                members: vec![0; g],
                lru: Lru::new(opts.store_budget_bytes),
                evictions: 0,
            },
            ram: Lru::new(opts.ram_budget_bytes),
            nv,
            groups,
            facts,
            cut_off,
            opts,
            frame: 0,
            epoch: 0,
            failed: FxHashSet::default(),
            retry: FxHashMap::default(),
            outage: false,
            reported: None,
            unreported: 0,
            sel: Selection::default(),
            demand: Selection::default(),
            prefetch: Vec::new(),
            prev_camera: None,
            answers: Vec::new(),
            morph: Morph::new(n, g),
            blocked: Vec::new(),
        }
    }

    /// The read-only tables of `index`.
    fn tables(index: &ModelIndex) -> (NodeView, Groups, Vec<NodeFacts>, FxHashSet<u32>) {
        let nv = NodeView::new(index.header(), index.nodes());
        let groups = Groups::new(&nv, index.nodes());
        let facts = index
            .nodes()
            .iter()
            .map(|n| NodeFacts {
                triangles: n.triangle_count,
                vertices: n.vertex_count,
                level: n.level,
                texture_size: n.texture_size,
            })
            .collect();
        let shown = index.nodes().len() as u64;
        let total = index.header().node_count;
        let cut_off = (0..index.nodes().len() as u32)
            .filter(|&i| {
                index.nodes()[i as usize]
                    .children
                    .iter()
                    .any(|&c| c != NO_NODE && (c as u64) >= shown && (c as u64) < total)
            })
            .collect();
        (nv, groups, facts, cut_off)
    }

    /// Takes a larger part of the same model's paged index (read further since this
    /// scheduler was made): the nodes it adds become selectable; everything resident stays
    /// resident. Node and group ids of the part already shown do not change (the index
    /// shows whole levels and groups are numbered in node order); should they anyway (an
    /// index of another model), the store is emptied first.
    pub fn set_index<R: ResidentStore + ?Sized>(&mut self, index: &ModelIndex, store: &mut R) {
        let (nv, groups, facts, cut_off) = Self::tables(index);
        let (old_n, old_g) = (self.nv.len(), self.groups.len());
        let stable = nv.len() >= old_n
            && groups.len() >= old_g
            && (0..old_n as u32).all(|i| groups.of(i) == self.groups.of(i))
            && (0..old_g as u32).all(|g| groups.members(g) == self.groups.members(g));
        if !stable {
            tracing::warn!("the new index does not extend the old one: emptying the store");
            for g in 0..old_g as u32 {
                self.res.evict_group(&self.groups, store, g);
            }
            self.ram = Lru::new(self.opts.ram_budget_bytes);
        }
        let (n, g) = (nv.len(), groups.len());
        self.nv = nv;
        self.groups = groups;
        self.facts = facts;
        self.cut_off = cut_off;
        self.readiness = Readiness::new(g);
        self.visit = vec![0; g];
        // (When not stable, evicting every group above cleared both.)
        self.res.resident.resize(n, false);
        self.res.members.resize(g, 0);
        self.morph.resize(n, g);
    }

    /// Nodes the index shows.
    pub fn node_count(&self) -> usize {
        self.nv.len()
    }

    /// The options.
    pub fn options(&self) -> &SchedulerOptions {
        &self.opts
    }

    /// Changes the screen-space tolerance from the next frame on (a viewer's slider).
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        if tolerance_px.is_finite() && tolerance_px > 0.0 {
            self.opts.tolerance_px = tolerance_px;
        }
    }

    /// Turns asking for the prefetch set on or off from the next frame on.
    pub fn set_prefetch(&mut self, prefetch: bool) {
        self.opts.prefetch = prefetch;
    }

    /// Changes the store and RAM budgets (a front end sharing one budget between
    /// models, [`crate::BudgetSplit`]). Raising one takes effect at once; lowering one
    /// evicts down to it at the start of the next frame ([`Scheduler::frame`] or
    /// [`Scheduler::idle_frame`]): first, least recently used first, the groups the
    /// previous frame did not use (those even a closer view would not need before the
    /// others, as for any eviction), then, if still over, the groups the previous
    /// frame drew, the least important on screen first (the cut coarsens from its
    /// finest, farthest diamonds; never a group before the groups that depend on it).
    /// Pinned roots are never evicted: a budget below them leaves the store over it.
    pub fn set_budgets(&mut self, store_budget_bytes: u64, ram_budget_bytes: u64) {
        self.opts.store_budget_bytes = store_budget_bytes;
        self.opts.ram_budget_bytes = ram_budget_bytes;
        self.res.lru.set_budget(store_budget_bytes);
        self.ram.set_budget(ram_budget_bytes);
    }

    /// The store and RAM budgets in effect.
    pub fn budgets(&self) -> (u64, u64) {
        (self.opts.store_budget_bytes, self.opts.ram_budget_bytes)
    }

    /// Store bytes of the groups this scheduler holds (what its store budget counts).
    pub fn resident_bytes(&self) -> u64 {
        self.res.lru.bytes()
    }

    /// Store bytes of the pinned roots (never evicted: the least a budget must allow).
    pub fn pinned_bytes(&self) -> u64 {
        let mut seen = FxHashSet::default();
        (0..self.nv.root_count())
            .map(|r| self.groups.of(r))
            .filter(|&g| seen.insert(g) && self.res.lru.last_used(g) == Some(u64::MAX))
            .filter_map(|g| self.res.lru.bytes_of(g))
            .sum()
    }

    /// Evicts down to the budgets after [`Scheduler::set_budgets`] lowered them, at the
    /// start of a frame (see there); `view`: this frame's view (None: not shown).
    fn evict_to_budget<R: ResidentStore + ?Sized>(
        &mut self,
        view: Option<&ViewParams>,
        store: &mut R,
    ) {
        let frame = self.frame;
        // RAM: patches touched by the previous frame stay (groups waiting for siblings).
        if self.ram.over_budget() {
            self.ram.shrink(frame.saturating_sub(1));
        }
        if !self.res.lru.over_budget() {
            return;
        }
        let (nv, groups) = (&self.nv, &self.groups);
        // 1. The normal order: groups the previous frame did not use, least recently
        //    used first, preferring those even a view with spheres grown by
        //    UNLOAD_GROWTH would not need.
        let unloadable = |h: u32| match view {
            Some(view) => groups
                .members(h)
                .iter()
                .all(|&x| should_unload(nv, x, view, UNLOAD_GROWTH)),
            None => false,
        };
        let keep = frame.saturating_sub(1);
        while self.res.lru.over_budget() {
            if !self.res.evict_one(groups, store, keep, &unloadable) {
                break;
            }
        }
        if !self.res.lru.over_budget() {
            return;
        }
        // 2. Still over: coarsen the previous frame's cut. A group (the children of a
        //    diamond D) costs the screen the projected error of D, which bounds that of
        //    every group depending on it (errors and saturated spheres only shrink down
        //    the hierarchy), so evicting the smallest first never strands a dependent;
        //    equal ones go finest (largest id) first. This runs before selection, so
        //    the frame draws the coarser cut and nothing it draws is evicted.
        let mut cut: Vec<(f32, u32)> = self
            .res
            .lru
            .used_since(keep)
            .into_iter()
            .map(|g| {
                let pri = match (view, groups.members(g).first()) {
                    (Some(view), Some(&m)) => {
                        let p = nv.nodes()[m as usize].parent;
                        if p == NO_NODE {
                            f32::INFINITY
                        } else {
                            let d = &nv.nodes()[p as usize];
                            projected_error(view, d.error, d.saturated_sphere)
                        }
                    }
                    _ => 0.0,
                };
                (pri, g)
            })
            .collect();
        cut.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
        for (_, g) in cut {
            if !self.res.lru.over_budget() {
                break;
            }
            self.res.evict_group(groups, store, g);
        }
    }

    /// Evicts every group but the pinned roots now (a model hidden, or making room for
    /// another model's complete frame in a shared store).
    pub fn release<R: ResidentStore + ?Sized>(&mut self, store: &mut R) {
        self.res.evict_unused(&self.groups, store, u64::MAX);
    }

    /// A frame of a model that is not shown: nothing is drawn or asked for (the
    /// source's wants are cancelled), answers still arriving go to the RAM cache, and
    /// the store is evicted down to its budget as [`Scheduler::frame`] would (every
    /// group is unused now). Demand 0.
    pub fn idle_frame<S, R>(&mut self, source: &mut S, store: &mut R) -> FrameStats
    where
        S: PatchSource + ?Sized,
        R: ResidentStore + ?Sized,
    {
        self.frame += 1;
        self.collect(source);
        self.evict_to_budget(None, store);
        self.sel.draw.clear();
        self.sel.missing.clear();
        self.morph.ratios.clear();
        self.demand.draw.clear();
        self.prefetch.clear();
        source.request(&[]);
        self.prev_camera = None;
        let mut stats = FrameStats {
            pending_loads: source.pending(),
            ..FrameStats::default()
        };
        self.finish_stats(&mut stats, store);
        stats
    }

    /// The view's demand ([`FrameStats::wanted_bytes`]): the whole cut for `view` (failed
    /// groups excepted) and the closure of the groups it needs, in the store's bytes.
    fn wanted_bytes<R: ResidentStore + ?Sized>(&mut self, view: &ViewParams, store: &R) -> u64 {
        let (groups, failed) = (&self.groups, &self.failed);
        let ok = |n: u32| failed.is_empty() || !group_failed(groups, failed, groups.of(n));
        select_resident(&self.nv, view, &ok, &mut self.demand);
        let starts = self.demand.draw.iter().map(|&n| groups.of(n));
        let all = group_closure(groups, &mut self.visit, &mut self.epoch, starts);
        all.iter()
            .flat_map(|&g| groups.members(g))
            .map(|&m| {
                let f = self.facts[m as usize];
                store.estimate_bytes(f.vertices, f.triangles)
                    + store.estimate_texture_bytes(f.texture_size)
            })
            .sum()
    }

    /// The residency groups.
    pub fn groups(&self) -> &Groups {
        &self.groups
    }

    /// Nodes drawn by the last frame, depth-first order.
    pub fn draw(&self) -> &[u32] {
        &self.sel.draw
    }

    /// The morph ratio of each node of [`Scheduler::draw`] (same order): 0 draws a
    /// node's own shape, 1 its parent's (see `tessera_select::morph` and
    /// [`crate::MorphOptions`]). All zero with morphing off.
    pub fn morph_ratios(&self) -> &[f32] {
        &self.morph.ratios
    }

    /// Turns geomorphing on or off from the next frame on (a viewer's toggle).
    pub fn set_morph(&mut self, enabled: bool) {
        self.opts.morph.enabled = enabled;
    }

    /// Arrival blend duration in effect (0 when morphing is off).
    fn blend_s(&self) -> f64 {
        if self.opts.morph.enabled {
            self.opts.morph.arrival_blend_s.max(0.0)
        } else {
            0.0
        }
    }

    /// The ratios of the final cut of this frame, into `stats`.
    fn update_morph(&mut self, view: &ViewParams, blend: bool, now: f64, stats: &mut FrameStats) {
        let m = self.morph.update(
            &self.nv,
            &self.groups,
            view,
            &self.sel.draw,
            &self.opts.morph,
            blend,
            self.frame,
            now,
        );
        stats.morph_mean = m.mean;
        stats.morph_max = m.max;
        // Groups kept waiting for a blend count too: the view is still changing.
        stats.morph_blending = m.blending + self.blocked.len();
    }

    /// Nodes known to fail.
    pub fn failed(&self) -> &FxHashSet<u32> {
        &self.failed
    }

    /// Nodes of [`Scheduler::failed`] that could not be read this time and are asked
    /// for again after a backoff (the others failed for good: corrupt bytes, or bytes
    /// that do not exist).
    pub fn retrying(&self) -> usize {
        self.retry.len()
    }

    /// Whether `node` could not be read this time (network, I/O) and is asked for again
    /// after a backoff, rather than failed for good.
    pub fn is_retrying(&self, node: u32) -> bool {
        self.retry.contains_key(&node)
    }

    /// Reads the roots now (when the source can block) and uploads them, pinned: the
    /// first frame then shows the whole model at its coarsest level and nothing else is
    /// loaded before it. A root that fails is skipped (a hole, reported). Without
    /// blocking reads the roots are asked for by the first frame like any missing node.
    pub fn load_roots<S, R>(&mut self, source: &mut S, store: &mut R)
    where
        S: PatchSource + ?Sized,
        R: ResidentStore + ?Sized,
    {
        let roots: Vec<u32> = (0..self.nv.root_count()).collect();
        let Some(answers) = source.read_now(&roots) else {
            return;
        };
        for a in answers {
            match a {
                Answer::Loaded { node, patch } => {
                    let key = (node, self.groups.of(node), true);
                    let r = self.res.upload(
                        &self.groups,
                        store,
                        self.frame,
                        key,
                        (&patch, &[]),
                        &|_| false,
                    );
                    if let Err(e) = r {
                        tracing::warn!(node, error = ?e, "root patch skipped");
                        self.failed.insert(node);
                    }
                }
                Answer::Failed { node, error } => {
                    tracing::warn!(node, %error, "root patch skipped");
                    self.failed.insert(node);
                }
                Answer::Unavailable { node, error } => self.unavailable(node, &error),
            }
        }
    }

    /// Remembers that `node` could not be read: its parent is drawn until its retry
    /// time. Reported with one warning, then at most every [`REPORT_EVERY_MS`] while
    /// reads keep failing: never per node or per frame.
    fn unavailable(&mut self, node: u32, error: &str) {
        self.failed.insert(node);
        self.outage = true;
        let now = (self.opts.clock)();
        let tries = self.retry.get(&node).map_or(0, |r| r.1) + 1;
        let wait = (RETRY_FIRST_MS * 2f64.powi(tries as i32 - 1)).min(RETRY_MAX_MS);
        self.retry.insert(node, (now + wait, tries));
        self.unreported += 1;
        if self.reported.is_none_or(|t| now - t >= REPORT_EVERY_MS) {
            tracing::warn!(
                node,
                %error,
                failed_reads = self.unreported,
                "patches unavailable: coarser nodes are shown; retrying with backoff"
            );
            self.reported = Some(now);
            self.unreported = 0;
        } else {
            tracing::debug!(node, %error, tries, "patch unavailable");
        }
    }

    /// Unavailable nodes whose retry time has come are wanted again.
    fn retry_due(&mut self) {
        if self.retry.is_empty() {
            return;
        }
        let now = (self.opts.clock)();
        for (node, (at, _)) in &self.retry {
            if *at <= now {
                self.failed.remove(node);
            }
        }
    }

    /// A patch arrived: an unavailable one has recovered.
    fn loaded(&mut self, node: u32) {
        if self.retry.remove(&node).is_some() && self.outage {
            self.outage = false;
            tracing::info!(node, "patches available again");
        }
    }

    /// The cut the store can draw for `camera` right now, without changing anything
    /// (no request, no upload, no recency): for picking, and for tests.
    pub fn resident_cut(&mut self, camera: &Camera) -> Vec<u32> {
        let view = self.view_params(camera);
        let mut sel = Selection::default();
        std::mem::swap(&mut sel, &mut self.sel);
        self.select_resident_now(&view);
        std::mem::swap(&mut sel, &mut self.sel);
        sel.draw
    }

    fn view_params(&self, camera: &Camera) -> ViewParams {
        ViewParams::new(
            camera,
            self.nv.cube_origin(),
            self.opts.tolerance_px,
            self.opts.cull,
        )
    }

    /// Collects the source's answers: patches into the RAM cache, failures remembered.
    fn collect<S: PatchSource + ?Sized>(&mut self, source: &mut S) {
        let mut answers = std::mem::take(&mut self.answers);
        source.poll(&mut answers);
        for a in answers.drain(..) {
            match a {
                Answer::Loaded { node, patch } => {
                    self.loaded(node);
                    if (node as usize) < self.res.resident.len() {
                        let bytes = decoded_bytes(&patch);
                        let (admitted, _) = self.ram.admit(node, patch, bytes, self.frame);
                        if !admitted {
                            tracing::debug!(
                                node,
                                bytes,
                                "patch refused: RAM full of wanted patches"
                            );
                        }
                    }
                }
                Answer::Failed { node, error } => {
                    if self.failed.insert(node) {
                        tracing::warn!(node, %error, "patch skipped, its parent is shown instead");
                    }
                }
                Answer::Unavailable { node, error } => self.unavailable(node, &error),
            }
        }
        self.answers = answers;
        self.retry_due();
    }

    /// Selection over what the store holds (groups complete and reachable).
    fn select_resident_now(&mut self, view: &ViewParams) {
        self.epoch += 1;
        let epoch = self.epoch;
        let (nv, groups, res, morph) = (&self.nv, &self.groups, &self.res, &self.morph);
        let (frame, blend_s) = (self.frame, self.blend_s());
        // A group whose parent group blends in waits (see `crate::morph`).
        let blocked = std::cell::RefCell::new(std::mem::take(&mut self.blocked));
        blocked.borrow_mut().clear();
        let complete = |g: u32| {
            res.complete(groups, g) && {
                let b = morph.blocks(nv, groups, g, frame, blend_s);
                if b {
                    blocked.borrow_mut().push(g);
                }
                !b
            }
        };
        let readiness = std::cell::RefCell::new(&mut self.readiness);
        let usable = |n: u32| {
            readiness
                .borrow_mut()
                .ready(groups, groups.of(n), epoch, &complete)
        };
        select_resident(&self.nv, view, &usable, &mut self.sel);
        // Only groups held back by the blend alone count as waiting (a group whose
        // dependencies are not ready would not be drawn anyway).
        let mut blocked = std::mem::take(&mut *blocked.borrow_mut());
        blocked.retain(|&g| {
            groups
                .dependencies(g)
                .iter()
                .all(|&d| readiness.borrow_mut().ready(groups, d, epoch, &complete))
        });
        blocked.sort_unstable();
        blocked.dedup();
        self.blocked = blocked;
    }

    /// While groups wait for their parents' arrival blend, the selection does not reach
    /// below them, so it would not ask for what lies there: ask for the view's whole cut
    /// (its demand, as if everything were resident) instead, below the visible
    /// priorities and above the prefetch, so the levels below load during the blend.
    fn want_demand(&mut self, wanted: &mut Vec<(u32, f32)>) {
        let groups = &self.groups;
        let starts = self.demand.draw.iter().map(|&n| groups.of(n));
        for g in group_closure(groups, &mut self.visit, &mut self.epoch, starts) {
            for &m in groups.members(g) {
                if !self.res.resident[m as usize]
                    && !self.ram.contains(m)
                    && !self.failed.contains(&m)
                {
                    wanted.push((m, DEMAND_PRIORITY));
                }
            }
        }
    }

    /// Marks the groups of the drawn nodes and everything they depend on (which
    /// includes the groups of all their ancestors) as used in this frame: evicting any
    /// of them would make a drawn group unusable.
    fn touch_draw_set(&mut self) {
        let groups = &self.groups;
        // Groups waiting for an arrival blend are used as well: they are drawn next.
        let starts = self.sel.draw.iter().map(|&n| groups.of(n));
        let starts = starts.chain(self.blocked.iter().copied());
        for g in group_closure(groups, &mut self.visit, &mut self.epoch, starts) {
            self.res.lru.touch(g, self.frame);
        }
    }

    /// Groups (with priority) that must be loaded for the missing nodes: each one's
    /// group and, transitively, the incomplete groups it depends on (dependencies are
    /// nearer the root and get higher priorities, so they load first).
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
                if !self.res.complete(&self.groups, g) {
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

    /// One progressive frame (never waits): see the module docs. `time_s` is the
    /// frame's time in seconds (any origin), used to predict the camera.
    pub fn frame<S, R>(
        &mut self,
        camera: &Camera,
        time_s: f64,
        source: &mut S,
        store: &mut R,
    ) -> FrameStats
    where
        S: PatchSource + ?Sized,
        R: ResidentStore + ?Sized,
    {
        let clock = self.opts.clock;
        self.frame += 1;
        let mut stats = FrameStats::default();
        // 1. Answers in, budgets kept, the cut selected over what is resident.
        self.collect(source);
        let view = self.view_params(camera);
        self.evict_to_budget(Some(&view), store);
        self.morph.set_now(time_s);
        self.select_and_look_ahead(camera, &view, time_s, store, &mut stats);
        let draw_before: FxHashSet<u32> = self.sel.draw.iter().copied().collect();
        // 2. Finished groups uploaded, most urgent first, re-selecting as they land.
        let mut wanted: Vec<(u32, f32)> = Vec::new();
        let planned = self.upload_rounds(&view, store, &mut wanted, &mut stats);
        if !self.blocked.is_empty() {
            self.want_demand(&mut wanted);
        }
        // 3. The prefetch set in the RAM the visible groups leave; the wants sent.
        self.want_prefetch(&stats, planned, &mut wanted);
        source.request(&wanted);
        let hint: Vec<u32> = self
            .prefetch
            .iter()
            .map(|&(n, _)| n)
            .filter(|&n| !self.ram.contains(n))
            .collect();
        source.hint(&hint);
        // 4. The morph ratios of the final cut and the frame's figures.
        stats.pending_loads = source.pending();
        stats.cache_hits = self
            .sel
            .draw
            .iter()
            .filter(|n| draw_before.contains(n))
            .count();
        stats.passes = 1;
        let ts = clock();
        self.update_morph(&view, true, time_s, &mut stats);
        stats.selection_ms += clock() - ts;
        self.prev_camera = Some((camera.clone(), time_s));
        self.finish_stats(&mut stats, store);
        stats
    }

    /// Step 1 of [`Scheduler::frame`]: the cut over what is resident, its misses, the
    /// detail the index does not show yet ([`FrameStats::index_wants`]), the prefetch set
    /// (grown spheres and the camera predicted from the last frame's) and the view's
    /// demand ([`FrameStats::wanted_bytes`]).
    fn select_and_look_ahead<R: ResidentStore + ?Sized>(
        &mut self,
        camera: &Camera,
        view: &ViewParams,
        time_s: f64,
        store: &R,
        stats: &mut FrameStats,
    ) {
        let clock = self.opts.clock;
        let ts = clock();
        self.select_resident_now(view);
        stats.cache_misses = self.sel.missing.len();
        if !self.cut_off.is_empty() {
            stats.index_wants = self
                .sel
                .draw
                .iter()
                .filter(|&&n| {
                    self.cut_off.contains(&n)
                        && wants_refinement(&self.nv, n, view, PREFETCH_GROWTH)
                })
                .count();
        }
        if self.opts.prefetch {
            let predicted = self.prev_camera.as_ref().map(|(prev, t)| {
                let dt = (time_s - t).max(0.0);
                predict_camera(prev, camera, dt, dt * 4.0)
            });
            let popts = PrefetchOptions {
                sphere_growth: PREFETCH_GROWTH,
                predicted,
            };
            prefetch_set(&self.nv, view, &popts, &mut self.prefetch);
        } else {
            self.prefetch.clear();
        }
        stats.wanted_bytes = self.wanted_bytes(view, store);
        stats.selection_ms = clock() - ts;
    }

    /// Step 2 of [`Scheduler::frame`]: finished groups uploaded, most urgent first,
    /// within the byte budget; then the cut selected again, since uploaded groups make
    /// their children wanted, which the source may already have delivered (prefetched).
    /// A few rounds per frame ([`MAX_UPLOAD_ROUNDS`]), never waiting. The missing
    /// members of the needed groups go into `wanted`; returns the RAM the groups asked
    /// for take once complete (only groups that fit in RAM together are asked for).
    fn upload_rounds<R: ResidentStore + ?Sized>(
        &mut self,
        view: &ViewParams,
        store: &mut R,
        wanted: &mut Vec<(u32, f32)>,
        stats: &mut FrameStats,
    ) -> u64 {
        let clock = self.opts.clock;
        let mut budget = self.opts.upload_budget_bytes;
        let mut stale = false;
        let mut planned = 0u64;
        for round in 0..MAX_UPLOAD_ROUNDS {
            let ts = clock();
            if round > 0 {
                self.select_resident_now(view);
            }
            self.touch_draw_set();
            let needed = self.needed_groups();
            stats.selection_ms += clock() - ts;
            wanted.clear();
            planned = 0;
            let uploads_before = stats.patches_uploaded;
            stats.budget_limited = 0;
            for (i, &(g, pri)) in needed.iter().enumerate() {
                let step = self.upload_group(
                    view,
                    store,
                    (g, pri),
                    &mut budget,
                    &mut planned,
                    wanted,
                    stats,
                );
                if step == GroupStep::StoreFull {
                    // Full of groups in use: the less urgent groups after this one
                    // wait too, or they would take the room this one waits for (a
                    // budget that grows, in a scene, would fill with whatever is
                    // small instead of what matters most). At most this group's bytes
                    // stay unused.
                    stats.budget_limited += needed.len() - i;
                    break;
                }
            }
            stale = stats.patches_uploaded > uploads_before;
            if !stale {
                break;
            }
        }
        if stale {
            // The last round uploaded: draw what it made usable.
            let ts = clock();
            self.select_resident_now(view);
            self.touch_draw_set();
            stats.selection_ms += clock() - ts;
        }
        planned
    }

    /// One needed group `(g, pri)` of an upload round: asked for (its missing members
    /// into `wanted`) if it fits in RAM beside the more urgent ones (`planned`), and
    /// uploaded whole when all its members are in RAM and the frame's upload `budget`
    /// and the store allow it.
    #[allow(clippy::too_many_arguments)]
    fn upload_group<R: ResidentStore + ?Sized>(
        &mut self,
        view: &ViewParams,
        store: &mut R,
        (g, pri): (u32, f32),
        budget: &mut u64,
        planned: &mut u64,
        wanted: &mut Vec<(u32, f32)>,
        stats: &mut FrameStats,
    ) -> GroupStep {
        let (nv, groups, frame) = (&self.nv, &self.groups, self.frame);
        if group_failed(groups, &self.failed, g) {
            return GroupStep::Skipped;
        }
        // Hysteresis: evict first what even a view with spheres grown by
        // UNLOAD_GROWTH (more than the prefetch growth) would not need.
        let unloadable = |h: u32| {
            groups
                .members(h)
                .iter()
                .all(|&x| should_unload(nv, x, view, UNLOAD_GROWTH))
        };
        // A group is assembled in RAM (decoded) before its upload. Groups are asked
        // for, most urgent first, only while they fit in the RAM budget together: more
        // would not all fit, so arrivals would be refused or evict each other's
        // patches, to be fetched again and again while none completes. One that does
        // not fit beside the more urgent ones is not asked for and its patches in RAM
        // are not touched (they make room).
        let group_ram: u64 = groups
            .members(g)
            .iter()
            .filter(|&&m| !self.res.resident[m as usize])
            .map(|&m| {
                self.ram
                    .bytes_of(m)
                    .unwrap_or_else(|| estimate_decoded(&self.facts[m as usize]))
            })
            .sum();
        if *planned > 0 && *planned + group_ram > self.ram.budget() {
            stats.budget_limited += 1;
            return GroupStep::Skipped;
        }
        *planned += group_ram;
        let mut patches: Vec<(u32, Arc<PatchData>)> = Vec::new();
        let mut all = true;
        for &m in groups.members(g) {
            if self.res.resident[m as usize] {
                continue;
            }
            // A use: patches of a group still waiting for siblings stay in RAM.
            match self.ram.touch(m, frame) {
                Some(p) => patches.push((m, p.clone())),
                None => {
                    all = false;
                    wanted.push((m, VISIBLE_PRIORITY + pri));
                }
            }
        }
        let size: u64 = patches.iter().map(|(_, p)| store.bytes_for(p)).sum();
        if !all || (size > *budget && stats.patches_uploaded > 0) {
            return GroupStep::Skipped;
        }
        // A group is uploaded whole or not at all: room for all of it first (a partly
        // uploaded group is unusable, unused, so evicted next frame, then uploaded
        // again: churn), within the budget and the store. One larger than the whole
        // budget is skipped (a shared budget may grow).
        if size > self.res.lru.budget() {
            stats.budget_limited += 1;
            return GroupStep::Skipped;
        }
        let refs: Vec<&PatchData> = patches.iter().map(|(_, p)| p.as_ref()).collect();
        let mut room = true;
        while room && (self.res.lru.would_exceed(size) || !store.has_room(&refs)) {
            room = self.res.evict_one(groups, store, frame, &unloadable);
        }
        if !room {
            return GroupStep::StoreFull;
        }
        let mut whole = true;
        for (m, p) in &patches {
            let key = (*m, g, nv.nodes()[*m as usize].parent == NO_NODE);
            let what = (p.as_ref(), refs.as_slice());
            match self
                .res
                .upload(groups, store, frame, key, what, &unloadable)
            {
                Ok(b) => {
                    *budget -= b.min(*budget);
                    stats.bytes_uploaded += b;
                    stats.patches_uploaded += 1;
                }
                Err(StoreError::Full) => {
                    whole = false;
                    break;
                }
                Err(StoreError::TooBig) => {
                    tracing::warn!(node = m, "patch larger than the store, skipped");
                    self.failed.insert(*m);
                }
            }
        }
        if !whole {
            // The store was full after all (fragmentation): take the part back.
            self.res.evict_group(groups, store, g);
            return GroupStep::Skipped;
        }
        // Keep the group from being evicted by later uploads of this frame.
        self.res.lru.touch(g, frame);
        GroupStep::Uploaded
    }

    /// Step 3 of [`Scheduler::frame`]: the prefetch set into `wanted`, at priorities
    /// below anything visible, in the RAM the visible groups leave (`planned` taken: a
    /// prefetch set larger than that would evict itself, fetched again and again), the
    /// most urgent first when not all of it fits; none while the view needs more than
    /// the store holds (its own cut comes first).
    fn want_prefetch(&self, stats: &FrameStats, planned: u64, wanted: &mut Vec<(u32, f32)>) {
        let (res, ram, failed, facts) = (&self.res, &self.ram, &self.failed, &self.facts);
        let mut fresh: Vec<(u32, f32, u64)> = self
            .prefetch
            .iter()
            .filter(|&&(n, _)| !res.resident[n as usize] && !failed.contains(&n))
            .map(|&(n, pri)| {
                let held = ram.bytes_of(n);
                (
                    n,
                    pri,
                    held.unwrap_or_else(|| estimate_decoded(&facts[n as usize])),
                )
            })
            .collect();
        let room = if stats.wanted_bytes > self.res.lru.budget() {
            0
        } else {
            ram.budget().saturating_sub(planned)
        };
        if fresh.iter().map(|f| f.2).sum::<u64>() > room {
            fresh.sort_by(|a, b| b.1.total_cmp(&a.1));
            let mut taken = 0u64;
            fresh.retain(|f| {
                taken += f.2;
                taken <= room
            });
        }
        for (n, pri, _) in fresh {
            if !ram.contains(n) {
                wanted.push((n, pri.min(PREFETCH_PRIORITY_MAX)));
            }
        }
    }

    /// One complete or full-resolution frame (see the module docs): the whole cut is
    /// made resident, reading what is missing with [`PatchSource::read_now`]; `pass`
    /// draws the given resident nodes (`true`: first pass of the frame, clear the
    /// target) and is called again after evictions when the cut does not fit.
    ///
    /// A patch of the cut found corrupt while the frame is drawn leaves a hole only at
    /// full resolution (which draws leaves and nothing else). In a complete frame the
    /// frame is drawn again with the failure known, so its parent stands in for it in
    /// this very frame (at most [`COMPLETE_REDRAWS`] times: a model with more corrupt
    /// levels shows the rest from the next frame on).
    pub fn complete_frame<S, R, E>(
        &mut self,
        camera: &Camera,
        source: &mut S,
        store: &mut R,
        mut pass: impl FnMut(&mut R, &[u32], &[f32], bool) -> Result<(), E>,
    ) -> Result<FrameStats, CompleteError<E>>
    where
        S: PatchSource + ?Sized,
        R: ResidentStore + ?Sized,
    {
        let mut total = FrameStats::default();
        for redraw in 0..=COMPLETE_REDRAWS {
            let failed_before = self.failed.len();
            let mut s = self.complete_frame_once(camera, source, store, &mut pass)?;
            s.bytes_uploaded += total.bytes_uploaded;
            s.patches_uploaded += total.patches_uploaded;
            s.passes += total.passes;
            s.selection_ms += total.selection_ms;
            total = s;
            let corrupt = |n: &u32| self.failed.contains(n) && !self.retry.contains_key(n);
            let new_failure =
                self.failed.len() > failed_before && self.sel.draw.iter().any(corrupt);
            if self.opts.mode == Mode::FullResolution || !new_failure {
                break;
            }
            if redraw == COMPLETE_REDRAWS {
                tracing::warn!("corrupt patches in the cut; the next frame shows their parents");
            } else {
                // The frame counter moves on, so nothing of the first attempt stays pinned.
                tracing::info!("corrupt patches in the cut; drawing the frame again");
            }
        }
        Ok(total)
    }

    fn complete_frame_once<S, R, E>(
        &mut self,
        camera: &Camera,
        source: &mut S,
        store: &mut R,
        pass: &mut dyn FnMut(&mut R, &[u32], &[f32], bool) -> Result<(), E>,
    ) -> Result<FrameStats, CompleteError<E>>
    where
        S: PatchSource + ?Sized,
        R: ResidentStore + ?Sized,
    {
        let clock = self.opts.clock;
        self.frame += 1;
        let frame = self.frame;
        let mut stats = FrameStats::default();
        self.collect(source);
        let ts = clock();
        let full = self.opts.mode == Mode::FullResolution;
        let view = self.view_params(camera);
        if full {
            self.sel.draw.clear();
            self.sel.missing.clear();
            let hot = self.nv.nodes();
            let failed = &self.failed;
            self.sel.draw.extend(
                (0..hot.len() as u32)
                    .filter(|&n| hot[n as usize].children == [NO_NODE, NO_NODE])
                    .filter(|n| !failed.contains(n)),
            );
        } else {
            let (failed, groups) = (&self.failed, &self.groups);
            // Everything counts as resident except groups with a failed member.
            let ok = |n: u32| !group_failed(groups, failed, groups.of(n));
            select_resident(&self.nv, &view, &ok, &mut self.sel);
        }
        if full {
            // Every leaf at its own shape.
            self.morph.ratios.clear();
            self.morph.ratios.resize(self.sel.draw.len(), 0.0);
        } else {
            self.update_morph(&view, false, 0.0, &mut stats);
        }
        stats.selection_ms = clock() - ts;

        let groups = &self.groups;
        let mut todo: Vec<u32> = Vec::new();
        for &n in &self.sel.draw {
            if self.res.resident[n as usize] {
                self.res.lru.touch(groups.of(n), frame);
                stats.cache_hits += 1;
            } else {
                todo.push(n);
            }
        }
        stats.cache_misses = todo.len();
        // A group's members read together (one batch unless it is larger): each upload
        // has its siblings at hand for the morph targets' attributes.
        todo.sort_by_key(|&n| groups.of(n));
        let mut drawn = vec![false; self.sel.draw.len()];
        let mut cleared = false;
        let (mut unavailable, mut recovered) = (Vec::new(), Vec::new());
        let mut next = 0;
        loop {
            // Read and upload batches until everything is resident or the store is full.
            let mut full_now = false;
            while next < todo.len() && !full_now {
                let end = (next + COMPLETE_BATCH).min(todo.len());
                let answers = source
                    .read_now(&todo[next..end])
                    .ok_or(CompleteError::NoBlockingReads)?;
                // The batch's patches by group: a member's siblings for its upload.
                let mut by_group: FxHashMap<u32, Vec<Arc<PatchData>>> = FxHashMap::default();
                for a in &answers {
                    if let Answer::Loaded { node, patch } = a {
                        by_group
                            .entry(groups.of(*node))
                            .or_default()
                            .push(patch.clone());
                    }
                }
                for (i, a) in answers.into_iter().enumerate() {
                    match a {
                        Answer::Loaded { node, patch } => {
                            if self.retry.contains_key(&node) {
                                recovered.push(node);
                            }
                            let g = groups.of(node);
                            let root = self.nv.nodes()[node as usize].parent == NO_NODE;
                            let key = (node, g, root);
                            let siblings: Vec<&PatchData> =
                                by_group[&g].iter().map(|p| p.as_ref()).collect();
                            let what = (patch.as_ref(), siblings.as_slice());
                            match self.res.upload(groups, store, frame, key, what, &|_| false) {
                                Ok(b) => {
                                    stats.bytes_uploaded += b;
                                    stats.patches_uploaded += 1;
                                    self.res.lru.touch(g, frame);
                                }
                                Err(StoreError::Full) => {
                                    full_now = true;
                                    next += i;
                                    break;
                                }
                                Err(StoreError::TooBig) => {
                                    tracing::warn!(node, "patch larger than the store");
                                    self.failed.insert(node);
                                }
                            }
                        }
                        Answer::Failed { node, error } => {
                            tracing::warn!(node, %error, "patch skipped");
                            self.failed.insert(node);
                        }
                        Answer::Unavailable { node, error } => {
                            self.failed.insert(node);
                            unavailable.push((node, error));
                        }
                    }
                }
                if !full_now {
                    next = end;
                }
                // Hand this batch's writes over now: a GPU keeps a staging copy of every
                // write until it is submitted, which would double the memory of a cut
                // streamed through the store.
                store.flush();
            }
            // One pass over what is resident and not drawn yet.
            let (mut nodes, mut ratios) = (Vec::new(), Vec::new());
            for (i, &n) in self.sel.draw.iter().enumerate() {
                if !drawn[i] && self.res.resident[n as usize] {
                    nodes.push(n);
                    ratios.push(self.morph.ratios[i]);
                    drawn[i] = true;
                }
            }
            if nodes.is_empty() && cleared && next >= todo.len() {
                break;
            }
            if nodes.is_empty() && full_now {
                return Err(CompleteError::StoreTooSmall);
            }
            pass(store, &nodes, &ratios, !cleared).map_err(CompleteError::Pass)?;
            cleared = true;
            stats.passes += 1;
            if next >= todo.len() {
                break;
            }
            // Make room: everything drawn so far may go (later writes are ordered after
            // the pass just handed over). Pinned roots stay.
            self.res.evict_unused(groups, store, frame + 1);
        }
        for node in recovered {
            self.loaded(node);
        }
        for (node, error) in unavailable {
            self.unavailable(node, &error);
        }
        self.prev_camera = None;
        self.finish_stats(&mut stats, store);
        Ok(stats)
    }

    fn finish_stats<R: ResidentStore + ?Sized>(&self, stats: &mut FrameStats, store: &R) {
        stats.frame = self.frame;
        stats.gpu_budget_bytes = self.opts.store_budget_bytes;
        stats.failed_patches = self.failed.len();
        stats.gpu_resident_bytes = store.resident_bytes();
        stats.gpu_evictions = self.res.evictions;
        stats.ram_resident_bytes = self.ram.bytes();
        // What was drawn: a patch of the cut that failed to load (a full-resolution frame
        // keeps its hole) is not counted.
        let drawn = || self.sel.draw.iter().filter(|n| !self.failed.contains(n));
        stats.selected_nodes = drawn().count();
        stats.triangles = drawn()
            .map(|&n| u64::from(self.facts[n as usize].triangles))
            .sum();
        stats.max_level = self
            .sel
            .draw
            .iter()
            .map(|&n| self.facts[n as usize].level)
            .max()
            .unwrap_or(0);
    }
}

/// Complete frames drawn again at most this many times when corrupt patches turn up in
/// their cut ([`Scheduler::complete_frame`]).
pub const COMPLETE_REDRAWS: usize = 3;

/// Pixels the model-space `error` of a node with saturated sphere `sphere` projects to
/// from `view` (infinite from inside the sphere).
fn projected_error(view: &ViewParams, error: f32, sphere: [f32; 4]) -> f32 {
    let e = view.eye;
    let (dx, dy, dz) = (sphere[0] - e.x, sphere[1] - e.y, sphere[2] - e.z);
    let d = (dx * dx + dy * dy + dz * dz).sqrt() - sphere[3];
    if d <= 0.0 {
        f32::INFINITY
    } else {
        error * view.px_per_unit / d
    }
}

/// The groups `starts` and, transitively, every group they depend on, each once (the
/// `visit` stamps of a fresh `epoch` mark those seen).
fn group_closure(
    groups: &Groups,
    visit: &mut [u64],
    epoch: &mut u64,
    starts: impl IntoIterator<Item = u32>,
) -> Vec<u32> {
    *epoch += 1;
    let stamp = *epoch;
    let mut out = Vec::new();
    let mut stack: Vec<u32> = starts.into_iter().collect();
    while let Some(g) = stack.pop() {
        if visit[g as usize] == stamp {
            continue;
        }
        visit[g as usize] = stamp;
        out.push(g);
        stack.extend_from_slice(groups.dependencies(g));
    }
    out
}

/// Whether a member of group `g` failed (such a group can never be complete).
fn group_failed(groups: &Groups, failed: &FxHashSet<u32>, g: u32) -> bool {
    groups.members(g).iter().any(|m| failed.contains(m))
}

/// [`decoded_bytes`] of a patch not loaded yet, from its node's counts, on the high
/// side: every vertex attribute a patch may have (position, normal, morph target,
/// colour, UV) and, for a texture, its texels, their mips and as much again encoded.
fn estimate_decoded(f: &NodeFacts) -> u64 {
    let texels = u64::from(f.texture_size[0]) * u64::from(f.texture_size[1]);
    u64::from(f.vertices) * 48 + u64::from(f.triangles) * 12 + texels * 4 * 2
}

/// Bytes a decoded patch occupies in RAM (array payloads, the texture's texels and
/// charts included; the small `Vec` headers are not counted). This is what the RAM
/// budget counts.
pub fn decoded_bytes(p: &PatchData) -> u64 {
    use std::mem::size_of;
    let texture = p.texture.as_ref().map_or(0, |t| {
        t.rgba.len() + t.encoded.len() + t.mips.iter().map(Vec::len).sum::<usize>()
    });
    (p.positions.len() * size_of::<[u32; 3]>()
        + p.normals.len() * size_of::<[f32; 3]>()
        + p.colors.len() * size_of::<[u8; 4]>()
        + p.uvs.len() * size_of::<[f32; 2]>()
        + p.morph_targets.len() * size_of::<[u32; 3]>()
        + p.indices.len() * size_of::<u32>()
        + p.charts.len() * size_of::<tessera_format::TextureChart>()
        + p.chart_ids.len() * size_of::<u16>()
        + texture) as u64
}
