//! The one frame driver: what every front end (the desktop window, `tessera render`,
//! the browser's canvas viewer and its three.js `Stream`) does each frame around its
//! models' [`Scheduler`]s, written once.
//!
//! A [`Driver`] holds the models of a scene, each with its scheduler, its
//! [`PatchSource`] and its [`IndexGrower`] (whatever reads more of a paged index off the
//! frame: a thread natively, a task in the browser), and takes its budgets from a
//! [`Budgets`] (a scene's own [`SceneBudgets`], or a browser page's share). One
//! progressive frame ([`Driver::frame`]) is, in order:
//!
//! 1. indices read further since the last frame taken ([`Driver::take_grown`]: the
//!    store is told first, [`SceneStores::index_grown`], then the scheduler and the
//!    source);
//! 2. the budgets split by the models' last demand ([`Budgets::share`]) and the models
//!    over their new budget run first, so the memory they free is there for the others'
//!    uploads in this same frame;
//! 3. each shown model's [`Scheduler::frame`], a hidden one's [`Scheduler::idle_frame`];
//!    a model whose view wants detail its index does not show yet starts growing it;
//! 4. the combined statistics.
//!
//! The front end then draws [`Driver::draws`] with near and far planes fitted to what
//! is drawn ([`Driver::fitted_planes`]), and asks [`Driver::settled`] whether streaming
//! has come to rest (the one definition of a converged view: nothing pending, growing
//! or blending, nothing missing but what can never arrive or the budgets leave out).
//!
//! The clock is the caller's: every call takes the frame's time in seconds. No GPU, no
//! threads, no I/O: the driver builds for wasm32 like the rest of the crate.

use std::sync::Arc;

use glam::DVec3;
use tessera_format::ModelIndex;
use tessera_select::{clip_planes_along, Camera, Placement};

use crate::scheduler::{FrameStats, Scheduler};
use crate::source::PatchSource;
use crate::split::{BudgetSplit, ModelDemand};
use crate::store::ResidentStore;

/// The index a model selects over, and whatever reads more of it off the frame (a
/// thread, a task) as the view asks ([`FrameStats::index_wants`]).
pub trait IndexGrower {
    /// The index the model selects over now (the last one taken).
    fn index(&self) -> &ModelIndex;
    /// Starts reading more of the index unless a read is running or the grower is
    /// backing off after a failure. Never blocks.
    fn grow(&mut self, time_s: f64);
    /// The index read further since the last call, when it shows more nodes than
    /// [`IndexGrower::index`] did; `index` is that one from now on. Never blocks.
    fn take(&mut self, time_s: f64) -> Option<Arc<ModelIndex>>;
    /// A read is running.
    fn growing(&self) -> bool;
}

/// An index read whole: nothing to grow.
#[derive(Clone, Debug)]
pub struct WholeIndex(pub Arc<ModelIndex>);

impl IndexGrower for WholeIndex {
    fn index(&self) -> &ModelIndex {
        &self.0
    }
    fn grow(&mut self, _time_s: f64) {}
    fn take(&mut self, _time_s: f64) -> Option<Arc<ModelIndex>> {
        None
    }
    fn growing(&self) -> bool {
        false
    }
}

/// The stores of a scene's models: a GPU cache the models share (each model's
/// [`ResidentStore`] a view of it), or a store of one model.
pub trait SceneStores {
    /// Model `model`'s store, borrowed from `self` for one call.
    type Store<'a>: ResidentStore
    where
        Self: 'a;
    /// Model `model`'s store.
    fn store(&mut self, model: usize) -> Self::Store<'_>;
    /// Model `model` selects over `index` from now on (a paged index grown): the
    /// store readies what it keeps per node (levels, parents) before the scheduler
    /// takes the index. Default: nothing.
    fn index_grown(&mut self, model: usize, index: &ModelIndex) {
        let _ = (model, index);
    }
    /// Store bytes the stores can really hold together (a cache's buffers may fill
    /// unevenly); a scene's split never hands out more. Default: no limit.
    fn usable_bytes(&self) -> u64 {
        u64::MAX
    }
}

/// A store of one model as a scene's stores (the browser's views, the tests).
pub struct OneStore<'s, R: ?Sized>(pub &'s mut R);

impl<R: ResidentStore + ?Sized> SceneStores for OneStore<'_, R> {
    type Store<'a>
        = &'a mut R
    where
        Self: 'a;
    fn store(&mut self, _model: usize) -> &mut R {
        self.0
    }
}

/// Where the models' budgets come from each frame.
pub trait Budgets {
    /// Each model's (store, RAM) budgets for the frame at `time_s`, from their demands
    /// (their last frames', [`ModelDemand::of`]) and what the stores can hold
    /// (`usable_store`); `None` leaves every model's budgets as they are. May be asked
    /// more than once a frame (an idle view asking whether its share moved).
    fn share(
        &mut self,
        time_s: f64,
        demands: &[ModelDemand],
        usable_store: u64,
    ) -> Option<Vec<(u64, u64)>>;
}

/// The budgets of a scene that owns its memory: one store and one RAM total, split
/// between its models by demand ([`BudgetSplit`]); a scene of one model keeps both
/// totals (its scheduler's own budgets).
#[derive(Clone, Debug)]
pub struct SceneBudgets {
    split: BudgetSplit,
    totals: (u64, u64),
}

impl SceneBudgets {
    /// A scene's budgets of `store_total` and `ram_total` bytes.
    pub fn new(store_total: u64, ram_total: u64) -> SceneBudgets {
        SceneBudgets {
            split: BudgetSplit::new(store_total, ram_total),
            totals: (store_total, ram_total),
        }
    }

    /// The totals.
    pub fn totals(&self) -> (u64, u64) {
        self.totals
    }
}

impl Budgets for SceneBudgets {
    fn share(
        &mut self,
        time_s: f64,
        demands: &[ModelDemand],
        usable_store: u64,
    ) -> Option<Vec<(u64, u64)>> {
        if demands.len() < 2 {
            return None;
        }
        self.split
            .set_totals(usable_store.min(self.totals.0), self.totals.1);
        Some(self.split.update(time_s, demands).to_vec())
    }
}

/// One model of a [`Driver`]: its scheduler, patch source and index (with its grower),
/// whether it is shown and its part of the last frame.
pub struct DrivenModel<S, G> {
    pub scheduler: Scheduler,
    pub source: S,
    pub grower: G,
    visible: bool,
    /// Where the model stands in the scene (its coordinates to the world's).
    placement: Placement,
    stats: FrameStats,
}

impl<S: PatchSource, G: IndexGrower> DrivenModel<S, G> {
    /// The index the scheduler selects over (grown from a paged one, if it was).
    pub fn index(&self) -> &ModelIndex {
        self.grower.index()
    }

    /// Whether the model is shown.
    pub fn is_visible(&self) -> bool {
        self.visible
    }

    /// Where the model stands in the scene.
    pub fn placement(&self) -> &Placement {
        &self.placement
    }

    /// The world `camera` and world near/far planes as this model is drawn with them:
    /// in its own coordinates (see `tessera_select::placement`; unchanged for a model
    /// that stands where its coordinates say).
    pub fn view(&self, camera: &Camera, planes: (f64, f64)) -> (Camera, (f64, f64)) {
        (
            self.placement.camera_to_model(camera),
            self.placement.planes_to_model(planes),
        )
    }

    /// This model's part of the last frame.
    pub fn stats(&self) -> &FrameStats {
        &self.stats
    }

    /// Replaces this model's part of the last frame (a front end's complete frames,
    /// which it runs model by model).
    pub fn set_stats(&mut self, stats: FrameStats) {
        self.stats = stats;
    }

    /// What the model asks of the budgets: its last frame's demand (none while hidden).
    pub fn demand(&self) -> ModelDemand {
        ModelDemand::of(&self.scheduler, self.stats.wanted_bytes, self.visible)
    }

    /// Whether this model's streaming has come to rest after its last frame: nothing
    /// pending at the source or in the scheduler, no index read running or wanted, no
    /// morph blending in, and nothing missing from the cut but nodes that failed for
    /// good (corrupt, or past the end of a truncated file: their parents are the view's
    /// final state) or that the budgets leave out ([`FrameStats::budget_limited`]), as
    /// long as no node is waiting to be read again (a network outage retried with
    /// backoff is not at rest). A hidden model is.
    pub fn settled(&self) -> bool {
        if !self.visible {
            return true;
        }
        let s = &self.stats;
        let retrying = self.scheduler.retrying();
        let failed_for_good = self.scheduler.failed().len().saturating_sub(retrying);
        // Every missing node the view can still get is asked for, so it is pending;
        // missing with nothing pending means the misses are the failed nodes' groups
        // (a group with a member that failed for good is never usable) or what the
        // budgets leave out.
        let misses_settled = s.cache_misses == 0 || failed_for_good > 0 || s.budget_limited > 0;
        s.pending_loads == 0
            && retrying == 0
            && misses_settled
            && s.index_wants == 0
            && s.morph_blending == 0
            && self.source.pending() == 0
            && !self.grower.growing()
    }
}

/// The per-frame driver of a scene's models. See the module docs.
pub struct Driver<S, G, B> {
    models: Vec<DrivenModel<S, G>>,
    budgets: B,
}

impl<S: PatchSource, G: IndexGrower, B: Budgets> Driver<S, G, B> {
    /// An empty scene taking its budgets from `budgets`.
    pub fn new(budgets: B) -> Self {
        Driver {
            models: Vec::new(),
            budgets,
        }
    }

    /// Adds a model (shown) selecting over `grower`'s index; returns its number.
    pub fn add(&mut self, scheduler: Scheduler, source: S, grower: G) -> usize {
        self.models.push(DrivenModel {
            scheduler,
            source,
            grower,
            visible: true,
            placement: Placement::IDENTITY,
            stats: FrameStats::default(),
        });
        self.models.len() - 1
    }

    /// Places model `i` in the scene (by default it stands where its coordinates say):
    /// its scheduler selects for the frame's camera taken into its coordinates.
    pub fn set_placement(&mut self, i: usize, placement: Placement) {
        self.models[i].placement = placement;
    }

    /// Reads every model's roots now where its source can block, and uploads them
    /// pinned ([`Scheduler::load_roots`]; a source that cannot block has them asked for
    /// by the first frame).
    pub fn load_roots<St: SceneStores>(&mut self, stores: &mut St) {
        for (i, m) in self.models.iter_mut().enumerate() {
            m.scheduler.load_roots(&mut m.source, &mut stores.store(i));
        }
    }

    /// Number of models.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    /// Whether the scene has no model.
    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }

    /// Model `i`.
    pub fn model(&self, i: usize) -> &DrivenModel<S, G> {
        &self.models[i]
    }

    /// Model `i`, mutably.
    pub fn model_mut(&mut self, i: usize) -> &mut DrivenModel<S, G> {
        &mut self.models[i]
    }

    /// The models.
    pub fn models(&self) -> &[DrivenModel<S, G>] {
        &self.models
    }

    /// The budgets.
    pub fn budgets(&self) -> &B {
        &self.budgets
    }

    /// The budgets, mutably (a page changing a model's cap).
    pub fn budgets_mut(&mut self) -> &mut B {
        &mut self.budgets
    }

    /// Shows or hides model `i` from the next frame on. A hidden model draws and asks
    /// for nothing; its demand is 0, so the others get its memory (all but its pinned
    /// roots) as they need it.
    pub fn set_visible(&mut self, i: usize, visible: bool) {
        self.models[i].visible = visible;
    }

    /// Changes every model's screen-space tolerance (pixels) from the next frame on.
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        for m in &mut self.models {
            m.scheduler.set_tolerance_px(tolerance_px);
        }
    }

    /// Turns every model's prefetch set on or off from the next frame on.
    pub fn set_prefetch(&mut self, prefetch: bool) {
        for m in &mut self.models {
            m.scheduler.set_prefetch(prefetch);
        }
    }

    /// Turns every model's geomorphing on or off from the next frame on.
    pub fn set_morph(&mut self, enabled: bool) {
        for m in &mut self.models {
            m.scheduler.set_morph(enabled);
        }
    }

    fn demands(&self) -> Vec<ModelDemand> {
        self.models.iter().map(DrivenModel::demand).collect()
    }

    /// Splits the budgets by the models' last demands now (every frame does; a scene
    /// calls it once after [`Driver::load_roots`] for the first split: no demand yet,
    /// an even share of what the roots leave). True when any model's budgets moved.
    pub fn rebalance(&mut self, time_s: f64, usable_store: u64) -> bool {
        let demands = self.demands();
        let Some(budgets) = self.budgets.share(time_s, &demands, usable_store) else {
            return false;
        };
        let mut moved = false;
        for (m, &(store, ram)) in self.models.iter_mut().zip(&budgets) {
            if m.scheduler.budgets() != (store, ram) {
                m.scheduler.set_budgets(store, ram);
                moved = true;
            }
        }
        moved
    }

    /// Whether the budgets' split has moved away from what the models hold (another
    /// model came, went or wants more): an idle view runs a frame to follow.
    pub fn budgets_moved(&mut self, time_s: f64, usable_store: u64) -> bool {
        let demands = self.demands();
        match self.budgets.share(time_s, &demands, usable_store) {
            Some(b) => self
                .models
                .iter()
                .zip(&b)
                .any(|(m, &b)| m.scheduler.budgets() != b),
            None => false,
        }
    }

    /// Takes the indices read further since the last frame: each model's store is
    /// readied, then its scheduler and source select over the grown index (what is
    /// resident stays). True when any model's index grew.
    pub fn take_grown<St: SceneStores>(&mut self, time_s: f64, stores: &mut St) -> bool {
        let mut grew = false;
        for (i, m) in self.models.iter_mut().enumerate() {
            let Some(ix) = m.grower.take(time_s) else {
                continue;
            };
            stores.index_grown(i, &ix);
            m.scheduler.set_index(&ix, &mut stores.store(i));
            m.source.set_index(&ix);
            grew = true;
        }
        grew
    }

    /// One progressive frame of `select` (the camera the cut is chosen for) at
    /// `time_s`: grown indices taken, budgets split, every model's scheduler run (see
    /// the module docs). Returns the models' statistics combined
    /// ([`FrameStats::combined`]); [`DrivenModel::stats`] has each one's.
    pub fn frame<St: SceneStores>(
        &mut self,
        select: &Camera,
        time_s: f64,
        stores: &mut St,
    ) -> FrameStats {
        self.take_grown(time_s, stores);
        self.rebalance(time_s, stores.usable_bytes());
        let mut order: Vec<usize> = (0..self.models.len()).collect();
        if self.models.len() > 1 {
            // Models over their (new) budget first: the memory they free in a shared
            // store is there for the others' uploads in this same frame.
            order.sort_by_key(|&i| {
                let s = &self.models[i].scheduler;
                s.budgets().0 as i128 - s.resident_bytes() as i128
            });
        }
        for i in order {
            let m = &mut self.models[i];
            let mut store = stores.store(i);
            m.stats = if m.visible {
                let camera = m.placement.camera_to_model(select);
                let stats = m
                    .scheduler
                    .frame(&camera, time_s, &mut m.source, &mut store);
                if stats.index_wants > 0 && !m.grower.index().is_complete() {
                    m.grower.grow(time_s);
                }
                stats
            } else {
                m.scheduler.idle_frame(&mut m.source, &mut store)
            };
        }
        let mut stats = FrameStats::combined(self.models.iter().map(|m| &m.stats));
        stats.passes = 1;
        stats
    }

    /// The last frame's statistics of the models combined.
    pub fn stats(&self) -> FrameStats {
        FrameStats::combined(self.models.iter().map(|m| &m.stats))
    }

    /// Whether every shown model's streaming has come to rest
    /// ([`DrivenModel::settled`]).
    pub fn settled(&self) -> bool {
        self.models.iter().all(DrivenModel::settled)
    }

    /// What the last frame draws: each model's number, the nodes drawn and their morph
    /// ratios (same order), hidden models with nothing.
    pub fn draws(&self) -> impl Iterator<Item = (usize, &[u32], &[f32])> + '_ {
        self.models
            .iter()
            .enumerate()
            .map(|(i, m)| (i, m.scheduler.draw(), m.scheduler.morph_ratios()))
    }

    /// Near and far planes for `camera` fitted to the tight spheres of the nodes the
    /// last frame draws, of every model (each index's spheres taken to model
    /// coordinates through its cube origin, then to the world through the model's
    /// placement): a close-up gets a near plane just in front of the surface it looks
    /// at, and one depth buffer serves the whole scene. World units.
    pub fn fitted_planes(&self, camera: &Camera) -> (f64, f64) {
        let mut spheres = Vec::new();
        for m in &self.models {
            let index = m.grower.index();
            let origin = DVec3::from(index.header().cube_origin);
            let nodes = index.nodes();
            spheres.extend(m.scheduler.draw().iter().filter_map(|&n| {
                let s = nodes.get(n as usize)?.tight_sphere;
                let c = origin + DVec3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
                // f32 spheres: widen by their rounding.
                let r = f64::from(s[3]) * (1.0 + 1e-6) + c.abs().max_element() * 1e-6;
                Some(m.placement.sphere_to_world(c, r))
            }));
        }
        clip_planes_along(
            DVec3::from(camera.position),
            camera.basis().forward,
            spheres,
        )
    }

    /// Near and far planes for `camera` around the whole of every shown model (their
    /// headers' bounding spheres): for frames whose cut is not known before it is
    /// drawn (complete frames, drawn in several passes that share planes).
    pub fn bounding_planes(&self, camera: &Camera) -> (f64, f64) {
        let spheres = self.models.iter().filter(|m| m.visible).map(|m| {
            let b = m.grower.index().header().bounding_sphere;
            m.placement
                .sphere_to_world(DVec3::new(b[0], b[1], b[2]), b[3].max(1e-9))
        });
        clip_planes_along(
            DVec3::from(camera.position),
            camera.basis().forward,
            spheres,
        )
    }
}
