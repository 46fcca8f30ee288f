//! The loader threads and the state they share with the [`Pager`](crate::Pager).
//!
//! Separate from the public API so the locking discipline is in one place: the mutex
//! is held only to pop the queue and to publish a result, never across the (possibly
//! slow) read + decode, so the render thread's calls never wait on disk.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use rustc_hash::{FxHashMap, FxHashSet};
use tessera_format::{FormatError, PatchData, PatchReader};
use tessera_stream::Answer;

use tessera_format::ranges::Span;

use crate::PagerStats;

/// One queued request: larger priority first, then earlier in the request slice.
#[derive(Debug)]
pub(crate) struct Queued {
    pub priority: f32,
    pub seq: u64,
    pub node: u32,
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        self.priority
            .total_cmp(&other.priority)
            .then_with(|| other.seq.cmp(&self.seq))
    }
}

/// Everything behind the pager's mutex.
#[derive(Default)]
pub(crate) struct State {
    /// Highest priority first; entries whose node is no longer in `queued` (taken into
    /// a neighbour's batch) are skipped when popped.
    pub queue: BinaryHeap<Queued>,
    /// The nodes of `queue` still waiting, with their priorities.
    pub queued: FxHashMap<u32, f32>,
    pub in_flight: FxHashSet<u32>,
    /// Nodes of `done` (not polled yet): not queued again.
    pub answered: FxHashSet<u32>,
    pub failed: FxHashSet<u32>,
    pub done: Vec<Answer>,
    pub stats: PagerStats,
    pub shutdown: bool,
}

pub(crate) struct Shared {
    pub model: Arc<dyn PatchReader>,
    pub read_delay: Option<Duration>,
    pub state: Mutex<State>,
    pub wake: Condvar,
}

impl State {
    /// Empties the queue.
    pub fn clear_queue(&mut self) {
        self.queue.clear();
        self.queued.clear();
    }

    /// Queues `node` (not queued yet).
    pub fn push(&mut self, node: u32, priority: f32) {
        let seq = self.queued.len() as u64;
        self.queued.insert(node, priority);
        self.queue.push(Queued {
            priority,
            seq,
            node,
        });
    }

    /// Takes the highest-priority node and the queued nodes beside it in the table
    /// (their patches are beside it in the file), at most [`BATCH_MAX_PATCHES`] patches
    /// and [`BATCH_MAX_BYTES`] (the first node always); in flight from now on. Order:
    /// the popped node, then its neighbours by priority.
    fn take_batch(&mut self, model: &dyn PatchReader) -> Option<Vec<u32>> {
        let first = loop {
            let q = self.queue.pop()?;
            if self.queued.remove(&q.node).is_some() {
                break q.node;
            }
        };
        let latest = model.latest_index();
        let index = latest.as_deref().unwrap_or(model.index());
        let range = |n: u32| index.patch_range(n as usize).ok();
        // The first node always; its neighbours as far as every reader's coalescing
        // rule allows (`Span`: patch count, gaps, bytes spanned).
        let mut span = range(first).map(Span::new);
        let mut near: Vec<(u32, f32)> = Vec::new();
        // Alternately one step up and one down the table, while the next node is queued
        // and fits: (last node taken, step, still growing).
        let count = index.nodes().len() as i64;
        let mut ends = [(i64::from(first), 1i64, true), (i64::from(first), -1, true)];
        while ends.iter().any(|e| e.2) {
            for e in ends.iter_mut().filter(|e| e.2) {
                let n = e.0 + e.1;
                e.2 = false;
                if n < 0 || n >= count {
                    continue;
                }
                let n = n as u32;
                let (Some(&p), Some(s), Some(r)) = (self.queued.get(&n), span.as_mut(), range(n))
                else {
                    continue;
                };
                if s.try_add(&r) {
                    near.push((n, p));
                    *e = (i64::from(n), e.1, true);
                }
            }
        }
        near.sort_by(|a, b| b.1.total_cmp(&a.1));
        let mut batch = Vec::with_capacity(near.len() + 1);
        batch.push(first);
        for (n, _) in near {
            self.queued.remove(&n);
            batch.push(n);
        }
        for &n in &batch {
            self.in_flight.insert(n);
        }
        Some(batch)
    }
}

impl Shared {
    /// Locks the state; a panic elsewhere while holding it does not poison the pager
    /// (the state is only mutated in small, consistent steps).
    pub fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Sleeps `delay`, waking early on shutdown. Returns false if shut down.
fn delay(shared: &Shared, delay: Duration) -> bool {
    let end = Instant::now() + delay;
    let mut st = shared.lock();
    loop {
        if st.shutdown {
            return false;
        }
        let now = Instant::now();
        if now >= end {
            return true;
        }
        st = match shared.wake.wait_timeout(st, end - now) {
            Ok((g, _)) => g,
            Err(p) => p.into_inner().0,
        };
    }
}

/// A loader thread's body: take a batch (the top node and its queued neighbours), read
/// and decode it unlocked with one [`PatchReader::decode_patches`], publish; until
/// shutdown.
pub(crate) fn run(shared: &Shared) {
    loop {
        let batch = {
            let mut st = shared.lock();
            loop {
                if st.shutdown {
                    return;
                }
                if let Some(b) = st.take_batch(shared.model.as_ref()) {
                    break b;
                }
                st = match shared.wake.wait(st) {
                    Ok(g) => g,
                    Err(p) => p.into_inner(),
                };
            }
        };
        if let Some(d) = shared.read_delay {
            if !delay(shared, d * batch.len() as u32) {
                let mut st = shared.lock();
                for n in &batch {
                    st.in_flight.remove(n);
                }
                return;
            }
        }
        let nodes: Vec<usize> = batch.iter().map(|&n| n as usize).collect();
        let results = shared.model.decode_patches(&nodes);
        let index = shared.model.latest_index();
        let index = index.as_deref().unwrap_or(shared.model.index());
        let mut st = shared.lock();
        for (&node, result) in batch.iter().zip(results) {
            if result.is_ok() {
                let bytes = index
                    .nodes()
                    .get(node as usize)
                    .map_or(0, |r| r.patch_bytes);
                st.stats.bytes_read += u64::from(bytes);
            }
            publish(&mut st, node, result);
        }
        // A reader answering fewer results than asked: the rest fail, never hang.
        let unanswered: Vec<u32> = batch
            .iter()
            .copied()
            .filter(|n| st.in_flight.contains(n))
            .collect();
        for node in unanswered {
            let e = FormatError::InvalidInput {
                detail: "the reader gave no answer".into(),
            };
            publish(&mut st, node, Err(e));
        }
    }
}

/// Records one read's result as an answer: a failure that may pass (network, I/O) is
/// answered [`Answer::Unavailable`] and may be asked for again; any other is answered
/// [`Answer::Failed`] and remembered (never read again).
fn publish(st: &mut State, node: u32, result: Result<PatchData, FormatError>) {
    st.in_flight.remove(&node);
    st.answered.insert(node);
    let answer = Answer::from_read(node, result);
    match &answer {
        Answer::Loaded { .. } => st.stats.loads += 1,
        Answer::Unavailable { error, .. } => {
            tracing::debug!(node, %error, "patch unavailable for now");
            st.stats.failures += 1;
        }
        Answer::Failed { error, .. } => {
            tracing::warn!(node, %error, "patch failed to load");
            st.stats.failures += 1;
            st.failed.insert(node);
        }
    }
    st.done.push(answer);
}
