//! The browser client's fetch logic, independent of the browser (so it is tested
//! natively): what to ask the server for and how to turn answers into the streaming
//! core's [`Answer`]s.
//!
//! - [`SparseBytes`]: the parts of a remote model fetched so far, as a
//!   [`ByteSource`] that records the first range it lacks. The index is read by the
//!   native reader code ([`ModelIndex::read_top`], [`ModelIndex::grown`]) in a loop
//!   ([`SparseBytes::attempt`]): run it, fetch the range it lacked, run it again. The
//!   first request is the file's first [`PREFIX_BYTES`] (as `tessera-http`), which holds
//!   the header, the block table and, for models of a few thousand nodes, the first
//!   index page.
//! - [`Fetcher`]: the patch requests. The scheduler's wants (replaced every frame) are
//!   taken highest priority first; each request is the top node with the wanted nodes
//!   beside it in the file (gaps up to [`COALESCE_MAX_GAP`], at most
//!   [`COALESCE_MAX_PATCHES`] patches and [`COALESCE_MAX_BYTES`]: the rule of
//!   `tessera-http`), at most [`MAX_IN_FLIGHT`] requests at once. Bodies wait until
//!   [`Fetcher::drain`] decodes them (CRC checked, [`ModelIndex::decode_patch`]) within a
//!   time budget per call, so a frame never waits for more than that much decoding.
//!   A request none of whose patches the view has wanted for [`CANCEL_AFTER_WANTS`]
//!   wanted sets in a row is cancelled ([`Fetcher::take_cancelled`]: the page aborts
//!   it) when wanted patches wait for its slot, so a turned camera does not wait behind
//!   the bytes of the view it left.

use std::cell::Cell;
use std::collections::VecDeque;
use std::ops::Range;
use std::sync::Arc;

use rustc_hash::{FxHashMap, FxHashSet};
use tessera_format::{ByteSource, FormatError, ModelIndex};
use tessera_stream::Answer;

/// Bytes fetched by the first request of a model (as `tessera_http::PREFIX_BYTES`).
pub const PREFIX_BYTES: u64 = 64 << 10;
/// Most range requests in flight at once (as `tessera_http::MAX_IN_FLIGHT`).
pub const MAX_IN_FLIGHT: usize = 3;
/// The coalescing rule and the range headers: every reader's (`tessera_format::ranges`).
pub use tessera_format::ranges::{
    parse_content_range, range_header, Span, COALESCE_MAX_BYTES, COALESCE_MAX_GAP,
    COALESCE_MAX_PATCHES,
};

/// A request in flight is cancelled once none of its patches was in this many wanted
/// sets in a row ([`Fetcher::set_wanted`]; the scheduler gives one a frame): a few
/// frames, so a patch flickering at the edge of the view (or of the prefetch set) is not
/// aborted and asked for again, while a view turned away stops fetching within ~70 ms
/// at 60 fps.
pub const CANCEL_AFTER_WANTS: u32 = 4;

/// Parts of a remote file fetched so far. See the module docs.
pub struct SparseBytes {
    len: u64,
    chunks: Vec<(u64, Vec<u8>)>,
    /// The first range a read lacked (start, end).
    missing: Cell<Option<(u64, u64)>>,
}

impl std::fmt::Debug for SparseBytes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseBytes")
            .field("len", &self.len)
            .field("chunks", &self.chunks.len())
            .field("held_bytes", &self.held_bytes())
            .finish()
    }
}

/// What one run of reader code over [`SparseBytes`] came to.
#[derive(Debug)]
pub enum Attempt<T> {
    Done(T),
    /// It needs these bytes: fetch them, [`SparseBytes::insert`] them, run it again.
    Need(Range<u64>),
    Failed(FormatError),
}

impl SparseBytes {
    /// A file of `len` bytes of which nothing is known yet.
    pub fn new(len: u64) -> SparseBytes {
        SparseBytes {
            len,
            chunks: Vec::new(),
            missing: Cell::new(None),
        }
    }

    /// Adds `bytes` fetched from offset `start`.
    pub fn insert(&mut self, start: u64, bytes: Vec<u8>) {
        self.chunks.push((start, bytes));
    }

    /// Bytes held (every chunk).
    pub fn held_bytes(&self) -> u64 {
        self.chunks.iter().map(|(_, b)| b.len() as u64).sum()
    }

    /// Runs `f` over what is held: its result, or the first range it lacked.
    pub fn attempt<T>(&self, f: impl FnOnce(&SparseBytes) -> Result<T, FormatError>) -> Attempt<T> {
        self.missing.set(None);
        let r = f(self);
        match (r, self.missing.take()) {
            (Ok(v), _) => Attempt::Done(v),
            (Err(_), Some((a, b))) => Attempt::Need(a..b),
            (Err(e), None) => Attempt::Failed(e),
        }
    }
}

impl ByteSource for SparseBytes {
    fn len(&self) -> u64 {
        self.len
    }

    fn read(&self, range: Range<u64>) -> Result<std::borrow::Cow<'_, [u8]>, FormatError> {
        if range.start > range.end || range.end > self.len {
            return Err(FormatError::Truncated {
                expected_bytes: range.end,
                actual_bytes: self.len,
            });
        }
        if range.is_empty() {
            return Ok(std::borrow::Cow::Borrowed(&[]));
        }
        for (start, bytes) in &self.chunks {
            let end = start + bytes.len() as u64;
            if *start <= range.start && range.end <= end {
                let a = (range.start - start) as usize;
                let b = (range.end - start) as usize;
                return Ok(std::borrow::Cow::Borrowed(&bytes[a..b]));
            }
        }
        if self.missing.get().is_none() {
            self.missing.set(Some((range.start, range.end)));
        }
        Err(FormatError::io(
            "remote model",
            std::io::Error::other(format!("bytes {range:?} not fetched yet")),
        ))
    }
}

/// One range request the fetcher wants sent.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// Pass it back to [`Fetcher::complete`].
    pub id: u64,
    /// Bytes of the file (end exclusive).
    pub range: Range<u64>,
    /// Nodes whose patches lie in it, in file order.
    pub nodes: Vec<u32>,
}

/// A request in flight: its nodes, and for how many wanted sets in a row none of them
/// was wanted.
struct InFlight {
    nodes: Vec<u32>,
    range: Range<u64>,
    unwanted: u32,
}

/// A fetched patch waiting to be decoded.
struct Fetched {
    node: u32,
    body: Arc<Vec<u8>>,
    at: Range<usize>,
}

/// Counters of a [`Fetcher`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FetchStats {
    /// Range requests sent (the index's included when counted by the caller).
    pub requests: u64,
    /// Body bytes received for patches.
    pub bytes: u64,
    /// Patches decoded, and the time that took (milliseconds, main thread).
    pub decoded: u64,
    pub decode_ms: f64,
    /// Largest time one patch took to decode, milliseconds.
    pub decode_max_ms: f64,
    /// Requests that failed (network, HTTP status): their nodes answered unavailable.
    pub failed_requests: u64,
    /// Requests cancelled ([`Fetcher::take_cancelled`]) and the bytes they asked for.
    pub cancelled_requests: u64,
    pub cancelled_bytes: u64,
    /// Of `decoded`, the patches decoded by workers ([`Fetcher::take_jobs`]), and the
    /// workers' time (milliseconds, off the main thread; their mips included).
    pub worker_decoded: u64,
    pub worker_ms: f64,
    /// Main-thread milliseconds taking the workers' replies in (copying them into
    /// the decoded patches), all and the largest.
    pub reply_ms: f64,
    pub reply_max_ms: f64,
}

/// The patch requests of one model. See the module docs.
pub struct Fetcher {
    index: Arc<ModelIndex>,
    /// Wanted nodes, highest priority first (the scheduler's order).
    order: Vec<u32>,
    wanted: FxHashSet<u32>,
    /// Nodes in a request in flight or fetched and not decoded yet.
    busy: FxHashSet<u32>,
    requests: FxHashMap<u64, InFlight>,
    /// Cancel requests nobody wants ([`CANCEL_AFTER_WANTS`]); off: let them finish.
    cancel: bool,
    ready: VecDeque<Fetched>,
    /// Answers settled without decoding (failed requests).
    settled: Vec<Answer>,
    /// Nodes failed for good ([`Fetcher::fail`]).
    gone: FxHashSet<u32>,
    /// Patches handed to decode workers and not answered yet, and their decoded bytes
    /// (estimated from their node records: [`Fetcher::job_bytes`]).
    at_workers: usize,
    at_workers_bytes: u64,
    next_id: u64,
    stats: FetchStats,
}

impl Fetcher {
    /// A fetcher for the model `index` describes (it may be a paged index read in part;
    /// [`Fetcher::set_index`] takes a grown one).
    pub fn new(index: Arc<ModelIndex>) -> Fetcher {
        Fetcher {
            index,
            order: Vec::new(),
            wanted: FxHashSet::default(),
            busy: FxHashSet::default(),
            requests: FxHashMap::default(),
            cancel: true,
            ready: VecDeque::new(),
            settled: Vec::new(),
            gone: FxHashSet::default(),
            at_workers: 0,
            at_workers_bytes: 0,
            next_id: 0,
            stats: FetchStats::default(),
        }
    }

    /// Takes a grown index of the same model.
    pub fn set_index(&mut self, index: Arc<ModelIndex>) {
        self.index = index;
    }

    /// Whether requests nobody wants any more are cancelled (default: yes).
    pub fn set_cancel(&mut self, cancel: bool) {
        self.cancel = cancel;
    }

    /// Counters.
    pub fn stats(&self) -> FetchStats {
        self.stats
    }

    /// Replaces the wanted set (node, priority; larger first; first occurrence wins).
    /// A request in flight none of whose nodes was wanted for [`CANCEL_AFTER_WANTS`]
    /// sets in a row is given by the next [`Fetcher::take_cancelled`].
    pub fn set_wanted(&mut self, wanted: &[(u32, f32)]) {
        let mut w: Vec<(u32, f32)> = wanted.to_vec();
        // Stable: equal priorities keep the scheduler's order.
        w.sort_by(|a, b| b.1.total_cmp(&a.1));
        self.order.clear();
        self.wanted.clear();
        let shown = self.index.nodes().len() as u32;
        for (n, _) in w {
            if n < shown && self.wanted.insert(n) {
                self.order.push(n);
            }
        }
        for r in self.requests.values_mut() {
            if r.nodes.iter().any(|n| self.wanted.contains(n)) {
                r.unwanted = 0;
            } else {
                r.unwanted += 1;
            }
        }
    }

    /// The requests to abort: in flight, none of their nodes wanted for
    /// [`CANCEL_AFTER_WANTS`] wanted sets in a row, as many (the oldest first) as wanted
    /// patches waiting for a slot could use (none when cancelling is off). They
    /// are forgotten here (their nodes are free to be asked for again, and an answer
    /// that still comes for one is dropped); nothing is answered for their nodes, which
    /// nobody wants.
    pub fn take_cancelled(&mut self) -> Vec<u64> {
        if !self.cancel {
            return Vec::new();
        }
        // Only to free a slot that wanted patches wait for: a request left to finish
        // costs nothing then, and its patches may be wanted again (a view turned back).
        let waiting = self.order.iter().filter(|&&n| self.free(n)).count();
        let slots = MAX_IN_FLIGHT.saturating_sub(self.requests.len());
        let need = waiting.min(MAX_IN_FLIGHT).saturating_sub(slots);
        if need == 0 {
            return Vec::new();
        }
        let mut ids: Vec<u64> = self
            .requests
            .iter()
            .filter(|(_, r)| r.unwanted >= CANCEL_AFTER_WANTS)
            .map(|(&id, _)| id)
            .collect();
        // The oldest first (the first to have been asked for).
        ids.sort_unstable();
        ids.truncate(need);
        for id in &ids {
            let r = self.requests.remove(id).expect("listed above");
            for n in &r.nodes {
                self.busy.remove(n);
            }
            self.stats.cancelled_requests += 1;
            self.stats.cancelled_bytes += r.range.end - r.range.start;
        }
        ids
    }

    /// Requests asked for and not answered yet (wanted or in flight).
    pub fn pending(&self) -> usize {
        self.wanted.len()
            + self
                .busy
                .iter()
                .filter(|n| !self.wanted.contains(n))
                .count()
    }

    /// Nodes failed for good (their bytes do not exist), never asked again.
    pub fn gone(&self) -> &FxHashSet<u32> {
        &self.gone
    }

    /// Requests in flight.
    pub fn in_flight(&self) -> usize {
        self.requests.len()
    }

    /// Fetched patches not decoded yet (waiting, or at the decode workers).
    pub fn undecoded(&self) -> usize {
        self.ready.len() + self.at_workers
    }

    /// Patches at the decode workers.
    pub fn at_workers(&self) -> usize {
        self.at_workers
    }

    /// Bytes node `n`'s patch takes decoded (its reply: vertices with every attribute,
    /// indices, the texture with its mips), estimated from its node record: what the
    /// decode workers' replies in flight are bounded by.
    pub fn job_bytes(&self, n: u32) -> u64 {
        self.index.node(n as usize).map_or(0, |r| {
            let texels = u64::from(r.texture_size[0]) * u64::from(r.texture_size[1]);
            u64::from(r.patch_bytes)
                + u64::from(r.vertex_count) * 48
                + u64::from(r.triangle_count) * 12
                + texels * 16 / 3
        })
    }

    /// Fetched patches, in arrival order, for decode workers: as many as keep at most
    /// `max_jobs` at the workers and their decoded bytes ([`Fetcher::job_bytes`]) at most
    /// `max_bytes` (one at least, when none is there); each node and its job's message
    /// ([`crate::wire::Job`]: what decoding needs from the node record, then the
    /// patch's bytes). Each is answered with [`Fetcher::deliver`], or given back with
    /// [`Fetcher::requeue`] when its worker failed.
    pub fn take_jobs(
        &mut self,
        max_jobs: usize,
        max_bytes: u64,
        mips: bool,
        blocks: Option<u32>,
    ) -> Vec<(u32, Vec<u8>)> {
        let mut out = Vec::new();
        while self.at_workers < max_jobs {
            let Some(f) = self.ready.front() else { break };
            let cost = self.job_bytes(f.node);
            if self.at_workers > 0 && self.at_workers_bytes + cost > max_bytes {
                break;
            }
            let f = self.ready.pop_front().expect("front checked");
            match crate::wire::Job::of(&self.index, f.node, mips, blocks) {
                Ok(job) => {
                    self.at_workers += 1;
                    self.at_workers_bytes += cost;
                    out.push((f.node, job.to_bytes(&f.body[f.at])));
                }
                Err(e) => {
                    self.busy.remove(&f.node);
                    self.wanted.remove(&f.node);
                    self.settled.push(Answer::Failed {
                        node: f.node,
                        error: e.to_string(),
                    });
                }
            }
        }
        out
    }

    fn job_done(&mut self, node: u32) {
        self.at_workers = self.at_workers.saturating_sub(1);
        self.at_workers_bytes = self.at_workers_bytes.saturating_sub(self.job_bytes(node));
    }

    /// A decode worker's answer for a node of [`Fetcher::take_jobs`], the worker's
    /// milliseconds, and this thread's for taking the reply in: taken by the next
    /// [`Fetcher::drain_settled`] (or [`Fetcher::drain`]).
    pub fn deliver(&mut self, answer: Answer, worker_ms: f64, reply_ms: f64) {
        let node = match &answer {
            Answer::Loaded { node, .. }
            | Answer::Failed { node, .. }
            | Answer::Unavailable { node, .. } => *node,
        };
        self.job_done(node);
        self.busy.remove(&node);
        self.wanted.remove(&node);
        self.stats.decoded += 1;
        self.stats.worker_decoded += 1;
        self.stats.worker_ms += worker_ms;
        self.stats.reply_ms += reply_ms;
        self.stats.reply_max_ms = self.stats.reply_max_ms.max(reply_ms);
        self.settled.push(answer);
    }

    /// Gives back a job whose worker failed (its message as taken): decoded by the next
    /// [`Fetcher::drain`] on this thread, first.
    pub fn requeue(&mut self, node: u32, job: Vec<u8>) {
        self.job_done(node);
        let body = match crate::wire::Job::parse(&job) {
            Ok((_, bytes)) => bytes.to_vec(),
            Err(_) => Vec::new(),
        };
        let at = 0..body.len();
        self.ready.push_front(Fetched {
            node,
            body: Arc::new(body),
            at,
        });
    }

    fn free(&self, n: u32) -> bool {
        self.wanted.contains(&n) && !self.busy.contains(&n)
    }

    /// The next request to send, if fewer than [`MAX_IN_FLIGHT`] are in flight and a
    /// wanted patch is not asked for yet: the top wanted node with the wanted nodes
    /// beside it in the file.
    pub fn next_request(&mut self) -> Option<Request> {
        if self.requests.len() >= MAX_IN_FLIGHT {
            return None;
        }
        let top = *self.order.iter().find(|&&n| self.free(n))?;
        let range_of = |n: u32| self.index.patch_range(n as usize).ok();
        let first = range_of(top)?;
        let (mut lo, mut hi) = (top, top);
        let mut span = Span::new(first);
        let shown = self.index.nodes().len() as u32;
        // Forward: wanted patches after this one, across small gaps (the bytes of the
        // unwanted ones between are the gaps).
        let mut j = hi + 1;
        while j < shown {
            let Some(r) = range_of(j) else { break };
            if !span.admits(&r) || self.busy.contains(&j) {
                break;
            }
            if self.wanted.contains(&j) {
                span.try_add(&r);
                hi = j;
            }
            j += 1;
        }
        // Backward, the same way.
        let mut j = lo;
        while j > 0 {
            j -= 1;
            let Some(r) = range_of(j) else { break };
            if !span.admits(&r) || self.busy.contains(&j) {
                break;
            }
            if self.wanted.contains(&j) {
                span.try_add(&r);
                lo = j;
            }
        }
        let nodes: Vec<u32> = (lo..=hi).filter(|&n| self.wanted.contains(&n)).collect();
        for &n in &nodes {
            self.busy.insert(n);
        }
        let id = self.next_id;
        self.next_id += 1;
        self.requests.insert(
            id,
            InFlight {
                nodes: nodes.clone(),
                range: span.range.clone(),
                unwanted: 0,
            },
        );
        self.stats.requests += 1;
        Some(Request {
            id,
            range: span.range,
            nodes,
        })
    }

    /// The answer to request `id`: its body (exactly the bytes asked for), or why it
    /// failed (the nodes are answered unavailable: the scheduler asks again after a
    /// backoff).
    pub fn complete(&mut self, id: u64, result: Result<Vec<u8>, String>) {
        let Some(InFlight { nodes, .. }) = self.requests.remove(&id) else {
            return;
        };
        let ranges: Vec<Option<Range<u64>>> = nodes
            .iter()
            .map(|&n| self.index.patch_range(n as usize).ok())
            .collect();
        let start = ranges.iter().flatten().map(|r| r.start).min().unwrap_or(0);
        let end = ranges.iter().flatten().map(|r| r.end).max().unwrap_or(0);
        let result = result.and_then(|b| {
            if b.len() as u64 == end - start {
                Ok(b)
            } else {
                Err(format!(
                    "body of {} bytes, expected {}",
                    b.len(),
                    end - start
                ))
            }
        });
        match result {
            Ok(body) => {
                self.stats.bytes += body.len() as u64;
                let body = Arc::new(body);
                for (&node, r) in nodes.iter().zip(ranges) {
                    let r = r.expect("range checked above");
                    self.ready.push_back(Fetched {
                        node,
                        body: body.clone(),
                        at: (r.start - start) as usize..(r.end - start) as usize,
                    });
                }
            }
            Err(error) => {
                self.stats.failed_requests += 1;
                for node in nodes {
                    self.busy.remove(&node);
                    self.wanted.remove(&node);
                    self.settled.push(Answer::Unavailable {
                        node,
                        error: error.clone(),
                    });
                }
            }
        }
    }

    /// Fails request `id` for good: its nodes are answered [`Answer::Failed`] (their
    /// bytes do not exist: past the end of a truncated file), never asked again.
    pub fn fail(&mut self, id: u64, error: &str) {
        let Some(InFlight { nodes, .. }) = self.requests.remove(&id) else {
            return;
        };
        self.stats.failed_requests += 1;
        for node in nodes {
            self.busy.remove(&node);
            self.wanted.remove(&node);
            self.gone.insert(node);
            self.settled.push(Answer::Failed {
                node,
                error: error.to_string(),
            });
        }
    }

    /// Moves settled answers (failed requests, the decode workers' answers) into `out`,
    /// decoding nothing here (the decode workers take the fetched patches).
    pub fn drain_settled(&mut self, out: &mut Vec<Answer>) {
        out.append(&mut self.settled);
    }

    /// Moves settled answers into `out` and decodes fetched patches, in arrival order,
    /// until `budget_ms` of `clock` (milliseconds) have passed (at least one patch per
    /// call). Returns the patches decoded.
    pub fn drain(&mut self, out: &mut Vec<Answer>, budget_ms: f64, clock: fn() -> f64) -> usize {
        out.append(&mut self.settled);
        let t0 = clock();
        let mut n = 0;
        while let Some(f) = self.ready.pop_front() {
            let t = clock();
            let r = self
                .index
                .decode_patch(f.node as usize, &f.body[f.at.clone()]);
            let ms = clock() - t;
            self.stats.decoded += 1;
            self.stats.decode_ms += ms;
            self.stats.decode_max_ms = self.stats.decode_max_ms.max(ms);
            self.busy.remove(&f.node);
            self.wanted.remove(&f.node);
            out.push(Answer::from_result(f.node, r));
            n += 1;
            if clock() - t0 >= budget_ms {
                break;
            }
        }
        n
    }
}

/// The leaf patches one full-resolution pick needs, fetched as it goes: a
/// [`PatchReader`](tessera_format::PatchReader) over the patches fetched so far for
/// [`tessera_pick::pick_with`]. A pass ([`PickReader::attempt`]) that reaches patches it
/// lacks records the first batch of them and answers the ranges to fetch; the pick
/// runs again once they are [`PickReader::insert`]ed, until a pass lacks nothing. The
/// walk is best first, so each pass fetches only the next batch the ray needs.
pub struct PickReader {
    index: Arc<ModelIndex>,
    bytes: std::sync::Mutex<FxHashMap<u32, Vec<u8>>>,
    missing: std::sync::Mutex<Option<Vec<u32>>>,
}

/// What one pass of a [`PickReader`] came to.
#[derive(Debug)]
pub enum PickAttempt {
    Done(Option<tessera_pick::Hit>, tessera_pick::PickStats),
    /// Fetch these ranges (each with the nodes whose patches it holds, in file order)
    /// and run again.
    Need(Vec<(Range<u64>, Vec<u32>)>),
}

impl PickReader {
    /// A pick over `index` with nothing fetched yet.
    pub fn new(index: Arc<ModelIndex>) -> PickReader {
        PickReader {
            index,
            bytes: Default::default(),
            missing: Default::default(),
        }
    }

    /// Bytes of patches held.
    pub fn held_bytes(&self) -> u64 {
        self.bytes
            .lock()
            .unwrap()
            .values()
            .map(|b| b.len() as u64)
            .sum()
    }

    /// One pass of the pick along `ray` (model coordinates).
    pub fn attempt(&self, ray: &tessera_pick::Ray) -> Result<PickAttempt, tessera_pick::PickError> {
        *self.missing.lock().unwrap() = None;
        let (hit, stats) =
            tessera_pick::pick_with(self, ray, &tessera_pick::PickOptions::default())?;
        let Some(mut nodes) = self.missing.lock().unwrap().take() else {
            return Ok(PickAttempt::Done(hit, stats));
        };
        // Coalesced as the patch requests: neighbours in the file, small gaps.
        let range_of = |n: u32| self.index.patch_range(n as usize).ok();
        nodes.retain(|&n| range_of(n).is_some());
        nodes.sort_by_key(|&n| range_of(n).map(|r| r.start));
        let ranges: Vec<Range<u64>> = nodes
            .iter()
            .map(|&n| range_of(n).expect("kept above"))
            .collect();
        let out: Vec<(Range<u64>, Vec<u32>)> = tessera_format::ranges::coalesce(&ranges)
            .into_iter()
            .map(|(span, members)| (span, nodes[members].to_vec()))
            .collect();
        if out.is_empty() {
            // Only nodes without a patch range were lacking: nothing more to fetch.
            return Ok(PickAttempt::Done(hit, stats));
        }
        Ok(PickAttempt::Need(out))
    }

    /// The body of a range [`PickReader::attempt`] asked for, starting at byte `start`
    /// of the file, holding the patches of `nodes`.
    pub fn insert(&self, start: u64, body: &[u8], nodes: &[u32]) {
        let mut bytes = self.bytes.lock().unwrap();
        for &n in nodes {
            let Ok(r) = self.index.patch_range(n as usize) else {
                continue;
            };
            let (a, b) = ((r.start - start) as usize, (r.end - start) as usize);
            if r.start >= start && b <= body.len() {
                bytes.insert(n, body[a..b].to_vec());
            }
        }
    }
}

impl tessera_format::PatchReader for PickReader {
    fn index(&self) -> &ModelIndex {
        &self.index
    }

    fn decode_patch(&self, i: usize) -> Result<tessera_format::PatchData, FormatError> {
        self.decode_patches(&[i])
            .pop()
            .expect("one answer per node")
    }

    fn decode_patches(
        &self,
        nodes: &[usize],
    ) -> Vec<Result<tessera_format::PatchData, FormatError>> {
        let bytes = self.bytes.lock().unwrap();
        let absent: Vec<u32> = nodes
            .iter()
            .map(|&n| n as u32)
            .filter(|n| !bytes.contains_key(n))
            .collect();
        let mut missing = self.missing.lock().unwrap();
        if !absent.is_empty() && missing.is_none() {
            *missing = Some(absent);
        }
        nodes
            .iter()
            .map(|&n| match bytes.get(&(n as u32)) {
                Some(b) => self.index.decode_patch(n, b),
                None => Err(FormatError::io(
                    "remote model",
                    std::io::Error::other(format!("patch {n} not fetched yet")),
                )),
            })
            .collect()
    }
}
