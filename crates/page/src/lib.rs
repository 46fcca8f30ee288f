//! Asynchronous paging of model patches: the frame never waits on disk (or network).
//! A [`Pager`] is a [`PatchSource`] of `tessera-stream` over any [`PatchReader`]: the
//! memory-mapped local `Model`, or a remote one.
//!
//! Following GoLD §4.1 (asynchronous paging), the render thread only ever *asks* for
//! patches and *collects* finished ones; reading, CRC checking and decoding happen on
//! loader threads. A [`Pager`] owns:
//!
//! - a priority queue of wanted nodes, replaced wholesale by every [`Pager::request`]
//!   (so stale wants from earlier frames are cancelled);
//! - loader thread(s) that pop the highest-priority node together with the queued
//!   nodes beside it in the node table (their patches are beside it in the file:
//!   coalescing, at most [`BATCH_MAX_PATCHES`] patches and [`BATCH_MAX_BYTES`]), read +
//!   decode them with one [`PatchReader::decode_patches`] (one range request for a
//!   remote model) and publish the results;
//! - the list of answers drained by [`Pager::poll`].
//!
//! Which patches stay in RAM, and for how long, is the streaming core's decision
//! (`tessera_stream::Scheduler` keeps decoded patches in its RAM cache); the pager
//! holds a patch only between decoding it and the next poll.
//!
//! All public calls take one short-held mutex and never do I/O (except
//! [`Pager::advise`], which only issues `madvise(WILLNEED)` hints, and
//! [`PatchSource::read_now`], which is meant to block), so they return in microseconds
//! even while a loader sits in a slow read.
//!
//! # Priorities
//! Larger priority loads first. The pager has no notion of visibility: a caller that
//! wants "visible nodes first, then prefetch" gives visible nodes priorities above all
//! prefetch priorities (e.g. `1e6 + screen_error` vs `screen_error`).
//!
//! Each loader thread has one read in flight; a remote source bounds its own requests
//! in flight on top of that (`tessera-http`: 3).
//!
//! # Failures
//! A patch that fails to decode (bad CRC, corrupt bytes, bad node index) is answered
//! once as [`Answer::Failed`] and remembered: later requests skip it, so it is never
//! retried in a loop. A read that fails (I/O or network error, after the source's own
//! retries) is answered as [`Answer::Unavailable`] and not remembered: the scheduler
//! asks for it again after a backoff. Either way the caller keeps drawing its parent.

mod grow;
mod loader;

pub use grow::ThreadGrower;

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use rayon::prelude::*;
use tessera_format::PatchReader;
use tessera_stream::{Answer, PatchSource};

use crate::loader::{Shared, State};

/// Most patches one loader read takes together (the top node and its neighbours): the
/// coalescing rule of every reader (`tessera_format::ranges::Span`).
pub const BATCH_MAX_PATCHES: usize = tessera_format::ranges::COALESCE_MAX_PATCHES;
/// Most bytes one loader read spans (the top node always).
pub const BATCH_MAX_BYTES: u64 = tessera_format::ranges::COALESCE_MAX_BYTES;

/// Pager configuration.
#[derive(Clone, Debug)]
pub struct PagerOptions {
    /// Number of loader threads (at least 1 is used). Default 1.
    pub threads: usize,
    /// Test hook: sleep this long before every patch read, to simulate a slow disk.
    pub read_delay: Option<Duration>,
}

impl Default for PagerOptions {
    fn default() -> Self {
        PagerOptions {
            threads: 1,
            read_delay: None,
        }
    }
}

/// Counters and gauges, see [`Pager::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PagerStats {
    /// Requests queued and not yet picked up by a loader.
    pub queued: usize,
    /// Requests a loader is reading now.
    pub in_flight: usize,
    /// Patches loaded successfully.
    pub loads: u64,
    /// Patches that failed to load.
    pub failures: u64,
    /// Encoded bytes of the patches loaded (what was read from the file or network).
    pub bytes_read: u64,
}

/// Loads patches of one model on background threads. See the crate docs.
pub struct Pager {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Pager {
    /// Starts `opts.threads` loader threads (at least one) reading `model` (a local
    /// memory-mapped `Model`, or any other [`PatchReader`]).
    pub fn new(model: Arc<dyn PatchReader>, opts: PagerOptions) -> Pager {
        let shared = Arc::new(Shared {
            model,
            read_delay: opts.read_delay,
            state: Mutex::new(State::default()),
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
        tracing::debug!(threads = threads.len(), "pager started");
        Pager { shared, threads }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        self.shared.lock()
    }

    /// Replaces the pending queue with `wanted` (node, priority; larger priority loads
    /// first). Nodes in flight, answered and not yet polled, or known to fail are
    /// skipped, as are duplicates (the first occurrence wins). Never blocks on I/O.
    pub fn request(&self, wanted: &[(u32, f32)]) {
        let mut st = self.state();
        st.clear_queue();
        for &(node, priority) in wanted {
            if st.queued.contains_key(&node)
                || st.in_flight.contains(&node)
                || st.answered.contains(&node)
                || st.failed.contains(&node)
            {
                continue;
            }
            st.push(node, priority);
        }
        let any = !st.queue.is_empty();
        drop(st);
        if any {
            self.shared.wake.notify_all();
        }
    }

    /// Kernel read-ahead hints (`madvise(WILLNEED)`) for a prefetch set: cheap, reads
    /// nothing.
    pub fn advise(&self, nodes: &[u32]) {
        for &n in nodes {
            self.shared.model.advise(n as usize);
        }
    }

    /// Moves the answers finished since the last call into `out`.
    pub fn poll_into(&self, out: &mut Vec<Answer>) {
        let mut st = self.state();
        st.answered.clear();
        out.append(&mut st.done);
    }

    /// The answers finished since the last call.
    pub fn poll(&self) -> Vec<Answer> {
        let mut out = Vec::new();
        self.poll_into(&mut out);
        out
    }

    /// Current counters.
    pub fn stats(&self) -> PagerStats {
        let st = self.state();
        PagerStats {
            queued: st.queued.len(),
            in_flight: st.in_flight.len(),
            ..st.stats
        }
    }

    /// The model being paged.
    pub fn model(&self) -> &Arc<dyn PatchReader> {
        &self.shared.model
    }

    /// Reads and decodes `nodes` now on the calling thread and rayon's pool (offline
    /// frames); answers in the order given. The nodes are read in table (file) order,
    /// [`BATCH_MAX_PATCHES`] per [`PatchReader::decode_patches`] call, so a remote model
    /// coalesces the adjacent ones.
    pub fn read_blocking(&self, nodes: &[u32]) -> Vec<Answer> {
        let model = &self.shared.model;
        let mut order: Vec<usize> = (0..nodes.len()).collect();
        order.sort_by_key(|&k| nodes[k]);
        let read: Vec<(usize, Answer)> = order
            .par_chunks(BATCH_MAX_PATCHES)
            .flat_map_iter(|chunk| {
                let ids: Vec<usize> = chunk.iter().map(|&k| nodes[k] as usize).collect();
                let results = model.decode_patches(&ids);
                chunk
                    .iter()
                    .zip(results)
                    .map(|(&k, r)| (k, Answer::from_read(nodes[k], r)))
                    .collect::<Vec<_>>()
            })
            .collect();
        let mut out: Vec<Option<Answer>> = vec![None; nodes.len()];
        for (k, a) in read {
            out[k] = Some(a);
        }
        out.into_iter()
            .zip(nodes)
            .map(|(a, &node)| {
                a.unwrap_or_else(|| Answer::Failed {
                    node,
                    error: "the reader gave no answer".into(),
                })
            })
            .collect()
    }
}

impl PatchSource for Pager {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        Pager::request(self, wanted);
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        self.poll_into(out);
    }
    fn pending(&self) -> usize {
        let s = self.stats();
        s.queued + s.in_flight
    }
    fn hint(&mut self, nodes: &[u32]) {
        self.advise(nodes);
    }
    fn read_now(&mut self, nodes: &[u32]) -> Option<Vec<Answer>> {
        Some(self.read_blocking(nodes))
    }
}

impl Drop for Pager {
    fn drop(&mut self) {
        {
            let mut st = self.state();
            st.shutdown = true;
            st.clear_queue();
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
