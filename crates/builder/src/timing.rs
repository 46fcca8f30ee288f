//! CPU time per phase of the diamond step, summed over worker threads, so a profile of
//! the build needs no profiler: `TESSERA_LOG=info tessera build ...` prints it.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The phases of [`crate::hierarchy`]'s per-diamond work, in order.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Phase {
    /// Leaf buckets read and welded (leaves only).
    LeafLoad,
    /// Leaf clean-up (degenerate and duplicate triangles).
    LeafClean,
    /// Leaf vertex-cache and fetch optimisation.
    LeafOptimize,
    /// All children's patches loaded: read from the spool, or the leaf phases above
    /// (which this includes).
    Children,
    Merge,
    BorderLocks,
    Simplify,
    Repair,
    Morph,
    /// Children encoded and written to the output spool.
    Emit,
    Split,
    /// Parent patches optimised, bounds computed.
    Optimize,
    /// Re-cut parent patches' textures baked.
    Recut,
    /// Parent patches written to the work spool.
    Spool,
}

const PHASES: usize = Phase::Spool as usize + 1;
const NAMES: [&str; PHASES] = [
    "leaf_load",
    "leaf_clean",
    "leaf_optimize",
    "children",
    "merge",
    "border_locks",
    "simplify",
    "repair",
    "morph",
    "emit",
    "split",
    "optimize",
    "recut",
    "spool",
];

#[derive(Default)]
pub(crate) struct Phases {
    ns: [AtomicU64; PHASES],
}

impl Phases {
    /// Starts timing on this thread.
    pub fn lap(&self) -> Lap<'_> {
        Lap {
            phases: self,
            t: Instant::now(),
        }
    }

    /// Logs the CPU seconds of every phase.
    pub fn log(&self) {
        let secs: Vec<String> = NAMES
            .iter()
            .zip(&self.ns)
            .map(|(n, v)| format!("{n}={:.2}", v.load(Ordering::Relaxed) as f64 * 1e-9))
            .collect();
        tracing::info!(cpu_seconds = %secs.join(" "), "diamond phases");
    }
}

/// A running stopwatch: [`Lap::mark`] charges the time since the last mark to a phase.
pub(crate) struct Lap<'a> {
    phases: &'a Phases,
    t: Instant,
}

impl Lap<'_> {
    pub fn mark(&mut self, p: Phase) {
        let now = Instant::now();
        self.phases.ns[p as usize].fetch_add((now - self.t).as_nanos() as u64, Ordering::Relaxed);
        self.t = now;
    }
}
