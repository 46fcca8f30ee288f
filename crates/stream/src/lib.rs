//! Tessera's streaming core: what each frame decides, for every front end.
//!
//! CPU only (no GPU types, no threads of its own, no file I/O; it builds for
//! `wasm32-unknown-unknown`). A [`Scheduler`] per model holds the policy that keeps a
//! partly resident cut crack-free and the frame from ever waiting: selection over what
//! is resident, residency [`Groups`] and their readiness, the needed groups and their
//! priorities, prefetch sets, the upload budget per frame, eviction order and
//! hysteresis, and the per-frame [`FrameStats`]. It drives two small traits:
//!
//! - a [`PatchSource`]: request nodes with priorities (replacing, so cancelling, the
//!   previous wants), poll finished or failed ones; `tessera-page`'s loader threads over
//!   a memory map today, next an HTTP fetcher, a web worker in the browser;
//! - a [`ResidentStore`]: upload a patch, evict it, report bytes; `tessera-render`'s GPU
//!   cache, or an in-memory fake in the tests.
//!
//! Several models in one scene keep one scheduler each and share one store budget and
//! one RAM budget: a [`BudgetSplit`] turns each model's per-frame demand
//! ([`FrameStats::wanted_bytes`]) into its budgets ([`Scheduler::set_budgets`]).
//!
//! Every front end runs its models' frames through one [`Driver`] (budgets split,
//! schedulers run, paged indices grown, planes fitted, "settled" decided), so a
//! per-frame feature is written once for the window, `tessera render` and the browser.
//!
//! Both caches the scheduler keeps (decoded patches in RAM, groups in the store) use one
//! [`Lru`] type under a byte budget, with one frame counter for recency.
//!
//! [`bench`]: the core over a model held in memory ([`bench::SliceSource`] and a
//! [`CountingStore`]), its frames run and timed the same way natively and in WebAssembly.

pub mod bench;
mod drive;
mod groups;
pub mod impostor;
mod lru;
mod morph;
mod scheduler;
mod source;
mod split;
mod store;

pub use drive::{
    Budgets, DrivenModel, Driver, IndexGrower, OneStore, SceneBudgets, SceneStores, WholeIndex,
};
pub use groups::Groups;
pub use impostor::{
    ImpostorDraw, ImpostorOptions, ImpostorSample, ImpostorStats, Impostors, ModelSphere,
};
pub use lru::{Lru, PREFERENCE_WINDOW};
pub use morph::{MorphOptions, MorphSummary, LATE_RATIO};
pub use scheduler::{
    decoded_bytes, default_clock, memory_split, Clock, CompleteError, FrameStats, Mode, Scheduler,
    SchedulerOptions, MAX_UPLOAD_ROUNDS, PREFETCH_GROWTH, UNLOAD_GROWTH,
};
pub use source::{Answer, PatchSource};
pub use split::{BudgetSplit, ModelDemand, DEAD_BAND_DIVISOR, DEMAND_HALF_LIFE_S};
pub use store::{CountingStore, ResidentStore, StoreError};
