//! Where patches come from: the [`PatchSource`] trait.
//!
//! The scheduler only ever *asks* ([`PatchSource::request`], replacing the previous
//! wants wholesale, so what the view no longer needs is cancelled) and *collects*
//! ([`PatchSource::poll`]); a source does its reading and decoding elsewhere (loader
//! threads over a memory map in `tessera-page`, an HTTP fetcher, a web worker) and
//! never makes a frame wait. Answers may come in any order, late, or not at all; a
//! failed node is reported once and never asked for again; an unavailable one (a read
//! that failed: network, I/O) is asked for again after a backoff.

use std::sync::Arc;

use tessera_format::{FormatError, ModelIndex, PatchData};

/// One finished request.
#[derive(Clone, Debug)]
pub enum Answer {
    /// The node's patch, decoded (and CRC checked).
    Loaded { node: u32, patch: Arc<PatchData> },
    /// The node's patch cannot be had (bad checksum, truncated file, network error
    /// that the source gave up on); its parent is drawn instead.
    Failed { node: u32, error: String },
    /// The node's patch could not be read this time (a network or I/O error the source
    /// gave up on): its parent is drawn instead, and the scheduler asks for it again
    /// after a backoff (the server may come back).
    Unavailable { node: u32, error: String },
}

impl Answer {
    /// The answer for `node` from a read-and-decode result.
    pub fn from_result<E: std::fmt::Display>(node: u32, r: Result<PatchData, E>) -> Answer {
        match r {
            Ok(p) => Answer::Loaded {
                node,
                patch: Arc::new(p),
            },
            Err(e) => Answer::Failed {
                node,
                error: e.to_string(),
            },
        }
    }

    /// The answer for `node` from a read-and-decode result, telling failures that may
    /// pass (I/O: [`Answer::Unavailable`]) from bad data ([`Answer::Failed`]).
    pub fn from_read(node: u32, r: Result<PatchData, FormatError>) -> Answer {
        match r {
            Err(e @ FormatError::Io { .. }) => Answer::Unavailable {
                node,
                error: e.to_string(),
            },
            r => Answer::from_result(node, r),
        }
    }

    /// The node answered.
    pub fn node(&self) -> u32 {
        match self {
            Answer::Loaded { node, .. }
            | Answer::Failed { node, .. }
            | Answer::Unavailable { node, .. } => *node,
        }
    }
}

/// A source of decoded patches. See the module docs.
pub trait PatchSource {
    /// Replaces the wanted set with `wanted` (node, priority; larger priority first;
    /// the first occurrence of a node wins). Nodes asked before and missing now are
    /// cancelled where the source can; ones already in flight may still be answered.
    /// Never blocks.
    fn request(&mut self, wanted: &[(u32, f32)]);
    /// Moves the answers finished since the last call into `out`. Never blocks.
    fn poll(&mut self, out: &mut Vec<Answer>);
    /// Requests asked for and not answered yet.
    fn pending(&self) -> usize;
    /// A hint that `nodes` (the prefetch set) will likely be wanted soon (e.g. kernel
    /// read-ahead). Default: nothing.
    fn hint(&mut self, nodes: &[u32]) {
        let _ = nodes;
    }
    /// Reads `nodes` now, blocking, for offline (complete) frames; `None` when the
    /// source cannot block (a browser's main thread). Default: `None`.
    fn read_now(&mut self, nodes: &[u32]) -> Option<Vec<Answer>> {
        let _ = nodes;
        None
    }
    /// Selects over `index` from now on (a paged index read further): a source that
    /// plans its reads from the node table takes the new one. Default: nothing (a
    /// reader that grows its own index, as `tessera-page`'s).
    fn set_index(&mut self, index: &Arc<ModelIndex>) {
        let _ = index;
    }
}
