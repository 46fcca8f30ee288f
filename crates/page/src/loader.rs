//! The loader threads and the state they share with the [`Pager`](crate::Pager).
//!
//! Separate from the public API so the locking discipline is in one place: the mutex
//! is held only to pop the queue and to publish a result, never across the (possibly
//! slow) read + decode, so the render thread's calls never wait on disk.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use rustc_hash::FxHashSet;
use tessera_format::PatchReader;
use tessera_stream::Answer;

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
    pub queue: BinaryHeap<Queued>,
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

/// A loader thread's body: pop, read + decode unlocked, publish; until shutdown.
pub(crate) fn run(shared: &Shared) {
    loop {
        let node = {
            let mut st = shared.lock();
            loop {
                if st.shutdown {
                    return;
                }
                if let Some(q) = st.queue.pop() {
                    st.in_flight.insert(q.node);
                    break q.node;
                }
                st = match shared.wake.wait(st) {
                    Ok(g) => g,
                    Err(p) => p.into_inner(),
                };
            }
        };
        if let Some(d) = shared.read_delay {
            if !delay(shared, d) {
                shared.lock().in_flight.remove(&node);
                return;
            }
        }
        let result = shared.model.decode_patch(node as usize);
        let mut st = shared.lock();
        st.in_flight.remove(&node);
        st.answered.insert(node);
        if let Err(e) = &result {
            tracing::warn!(node, error = %e, "patch failed to load");
            st.stats.failures += 1;
            st.failed.insert(node);
        } else {
            st.stats.loads += 1;
        }
        st.done.push(Answer::from_result(node, result));
    }
}
