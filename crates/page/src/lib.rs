//! Asynchronous paging of model patches: the frame never waits on disk.
//!
//! Following GoLD §4.1 (asynchronous paging), the render thread only ever *asks* for
//! patches and *looks* at what is already in RAM; reading, CRC checking and decoding
//! happen on loader threads. A [`Pager`] owns:
//!
//! - a priority queue of wanted nodes, replaced wholesale by every [`Pager::request`]
//!   (so stale wants from earlier frames are dropped);
//! - loader thread(s) that pop the highest-priority node, read + decode it with
//!   [`Model::decode_patch`] and hand the result back;
//! - a RAM budget over decoded patch sizes with LRU eviction that never evicts nodes
//!   [`Pager::pin`]ned for the current frame (see [`cache`]);
//! - an event list drained by [`Pager::poll`].
//!
//! All public calls take one short-held mutex and never do I/O (except
//! [`Pager::advise`], which only issues `madvise(WILLNEED)` hints), so they return in
//! microseconds even while a loader sits in a slow read.
//!
//! # Priorities
//! Larger priority loads first. The pager has no notion of visibility: a caller that
//! wants "visible nodes first, then prefetch" gives visible nodes priorities above all
//! prefetch priorities (e.g. `1e6 + screen_error` vs `screen_error`), and may call
//! [`Pager::advise`] on the prefetch set so the kernel starts reading it ahead.
//!
//! # Failures
//! A patch that fails to read or decode (bad CRC, truncated file, bad node index) is
//! reported once as [`Event::Failed`] and remembered: later requests skip it, so it is
//! never retried in a loop. The caller keeps drawing its parent.

pub mod cache;
mod loader;

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use rustc_hash::FxHashSet;
use tessera_format::{Model, PatchData};

use crate::loader::{Queued, Shared, State};

/// Pager configuration.
#[derive(Clone, Debug)]
pub struct PagerOptions {
    /// RAM budget in bytes, counted as decoded patch sizes ([`cache::decoded_bytes`]).
    /// Default 256 MiB.
    pub ram_budget_bytes: u64,
    /// Number of loader threads (at least 1 is used). Default 1.
    pub threads: usize,
    /// Test hook: sleep this long before every patch read, to simulate a slow disk.
    pub read_delay: Option<Duration>,
}

impl Default for PagerOptions {
    fn default() -> Self {
        PagerOptions {
            ram_budget_bytes: 256 << 20,
            threads: 1,
            read_delay: None,
        }
    }
}

/// Something that happened on a loader thread, reported by [`Pager::poll`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// The node's patch is resident; `bytes` is its decoded size.
    Loaded { node: u32, bytes: u64 },
    /// The node's patch could not be loaded; it will not be retried.
    Failed { node: u32, error: String },
}

/// Counters and gauges, see [`Pager::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PagerStats {
    /// Decoded bytes of resident patches.
    pub resident_bytes: u64,
    /// Number of resident patches.
    pub resident_patches: usize,
    /// Requests still queued (not yet picked up by a loader).
    pub pending: usize,
    /// Patches loaded successfully (including ones then refused for lack of room).
    pub loads: u64,
    /// Patches evicted to stay within the budget.
    pub evictions: u64,
    /// Patches that failed to load.
    pub failures: u64,
    /// [`Pager::get`] calls that found the patch resident.
    pub hits: u64,
    /// [`Pager::get`] calls that did not.
    pub misses: u64,
}

/// Loads patches of one model on background threads under a RAM budget.
/// See the crate docs.
pub struct Pager {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Pager {
    /// Starts `opts.threads` loader threads (at least one) for `model`.
    pub fn new(model: Arc<Model>, opts: PagerOptions) -> Pager {
        let shared = Arc::new(Shared {
            model,
            read_delay: opts.read_delay,
            state: Mutex::new(State::new(opts.ram_budget_bytes)),
            wake: Condvar::new(),
        });
        let n = opts.threads.max(1);
        let mut threads = Vec::with_capacity(n);
        for i in 0..n {
            let s = shared.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("tessera-page-{i}"))
                .spawn(move || loader::run(&s));
            match spawned {
                Ok(h) => threads.push(h),
                Err(e) => tracing::error!(thread = i, error = %e, "cannot spawn loader thread"),
            }
        }
        tracing::debug!(
            threads = threads.len(),
            budget = opts.ram_budget_bytes,
            "pager started"
        );
        Pager { shared, threads }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        self.shared.lock()
    }

    /// Replaces the pending queue with `wanted` (node, priority; larger priority loads
    /// first). Nodes already resident, in flight, or known to fail are skipped, as are
    /// duplicates (the first occurrence wins). Never blocks on I/O.
    pub fn request(&self, wanted: &[(u32, f32)]) {
        let mut st = self.state();
        st.queue.clear();
        let mut seen = FxHashSet::default();
        for &(node, priority) in wanted {
            if !seen.insert(node)
                || st.cache.contains(node)
                || st.in_flight.contains(&node)
                || st.failed.contains(&node)
            {
                continue;
            }
            st.queue.push(Queued {
                priority,
                seq: seen.len() as u64,
                node,
            });
        }
        let any = !st.queue.is_empty();
        drop(st);
        if any {
            self.shared.wake.notify_all();
        }
    }

    /// Kernel read-ahead hints (`madvise(WILLNEED)`) for a prefetch set: cheap, reads
    /// nothing. Resident nodes are skipped.
    pub fn advise(&self, nodes: &[u32]) {
        let todo: Vec<u32> = {
            let st = self.state();
            nodes
                .iter()
                .copied()
                .filter(|&n| !st.cache.contains(n))
                .collect()
        };
        for n in todo {
            self.shared.model.advise_willneed(n as usize);
        }
    }

    /// Marks `nodes` as drawn this frame: they will not be evicted until the next
    /// `pin` call replaces the set.
    pub fn pin(&self, nodes: &[u32]) {
        self.state().cache.set_pinned(nodes);
    }

    /// The resident patch of `node`, marking it most recently used.
    pub fn get(&self, node: u32) -> Option<Arc<PatchData>> {
        let mut st = self.state();
        let got = st.cache.touch(node);
        if got.is_some() {
            st.stats.hits += 1;
        } else {
            st.stats.misses += 1;
        }
        got
    }

    /// Whether `node`'s patch is resident (does not count as a use).
    pub fn is_resident(&self, node: u32) -> bool {
        self.state().cache.contains(node)
    }

    /// Drains the events since the last call.
    pub fn poll(&self) -> Vec<Event> {
        std::mem::take(&mut self.state().events)
    }

    /// Current counters.
    pub fn stats(&self) -> PagerStats {
        let st = self.state();
        PagerStats {
            resident_bytes: st.cache.resident_bytes(),
            resident_patches: st.cache.len(),
            pending: st.queue.len(),
            ..st.stats
        }
    }

    /// The model being paged.
    pub fn model(&self) -> &Arc<Model> {
        &self.shared.model
    }
}

impl Drop for Pager {
    fn drop(&mut self) {
        {
            let mut st = self.state();
            st.shutdown = true;
            st.queue.clear();
        }
        self.shared.wake.notify_all();
        for h in self.threads.drain(..) {
            if h.join().is_err() {
                tracing::error!("loader thread panicked");
            }
        }
        tracing::debug!("pager stopped");
    }
}
