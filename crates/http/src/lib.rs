//! Tessera models over HTTP: any server that answers `Range` requests (`tessera serve`,
//! nginx, a CDN) serves a model as a plain file.
//!
//! - [`HttpSource`] is a [`ByteSource`] of HTTP range requests through one `ureq`
//!   connection pool. The first request fetches the file's first [`PREFIX_BYTES`]
//!   (header and, for models up to a few hundred nodes, the whole node table) and pins
//!   the file's `ETag`; every later request carries `If-Range` with it, so a model
//!   replaced on the server is detected (the server answers `200` with the new file)
//!   and reported, never mixed with the old bytes. Transient failures (connection
//!   errors, `5xx`) are retried with backoff; a short or mislabelled body is an error.
//! - [`RemoteModel`] is a [`ModelIndex`] read through it plus patches fetched on demand:
//!   a [`PatchReader`], so `tessera-page`'s loader threads and the viewer read it like a
//!   local file. [`PatchReader::decode_patches`] coalesces: patches adjacent in the file
//!   (the node table's Morton order puts siblings side by side) come with one range
//!   request of at most [`COALESCE_MAX_PATCHES`] patches and [`COALESCE_MAX_BYTES`].
//! - At most [`MAX_IN_FLIGHT`] requests of one source are in flight at once, whatever
//!   the number of threads reading it (loader threads, rayon's pool in complete frames);
//!   the others wait their turn (Nexus uses 3 too).
//!
//! Only `http://` URLs: TLS is not compiled in.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::Duration;

use tessera_format::{ByteSource, FormatError, ModelIndex, PatchData, PatchReader};

/// Bytes fetched by the first request of a model.
pub const PREFIX_BYTES: u64 = 64 << 10;
/// Attempts per range request (transient failures only).
const ATTEMPTS: u32 = 3;
/// Most range requests of one [`HttpSource`] in flight at once.
pub const MAX_IN_FLIGHT: usize = 3;
/// Most patches one coalesced request of [`RemoteModel::decode_patches`] fetches.
pub const COALESCE_MAX_PATCHES: usize = 16;
/// Most bytes one coalesced request fetches (a single larger patch gets its own).
pub const COALESCE_MAX_BYTES: u64 = 512 << 10;
/// Unwanted bytes between two wanted patches that a coalesced request may carry (at
/// 20 Mbit/s, 4 KiB cost under 2 ms; a round trip costs tens).
pub const COALESCE_MAX_GAP: u64 = 4096;

/// Whether `s` names a remote model (`http://` or `https://`) rather than a path.
pub fn is_url(s: &str) -> bool {
    let l = s.to_ascii_lowercase();
    l.starts_with("http://") || l.starts_with("https://")
}

/// A remote file read with HTTP range requests. See the crate docs.
pub struct HttpSource {
    agent: ureq::Agent,
    url: String,
    len: u64,
    etag: Option<String>,
    prefix: Vec<u8>,
    bytes_fetched: AtomicU64,
    requests: AtomicU64,
    slots: Slots,
}

/// A counting semaphore of [`MAX_IN_FLIGHT`] request slots.
#[derive(Default)]
struct Slots {
    busy: Mutex<usize>,
    freed: Condvar,
}

/// One taken slot, given back when dropped.
struct Slot<'a>(&'a Slots);

impl Slots {
    fn take(&self) -> Slot<'_> {
        let mut busy = self.busy.lock().unwrap_or_else(|p| p.into_inner());
        while *busy >= MAX_IN_FLIGHT {
            busy = self.freed.wait(busy).unwrap_or_else(|p| p.into_inner());
        }
        *busy += 1;
        Slot(self)
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        *self.0.busy.lock().unwrap_or_else(|p| p.into_inner()) -= 1;
        self.0.freed.notify_one();
    }
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("url", &self.url)
            .field("len", &self.len)
            .field("etag", &self.etag)
            .finish()
    }
}

/// What went wrong with one request: worth retrying or not.
enum Failure {
    Transient(String),
    Fatal(String),
}

/// `bytes A-B/TOTAL` (or `bytes */TOTAL`) of a `Content-Range` header.
fn parse_content_range(v: &str) -> Option<(Option<(u64, u64)>, u64)> {
    let rest = v.trim().strip_prefix("bytes")?.trim_start();
    let (span, total) = rest.split_once('/')?;
    let total: u64 = total.trim().parse().ok()?;
    if span.trim() == "*" {
        return Some((None, total));
    }
    let (a, b) = span.trim().split_once('-')?;
    Some((Some((a.parse().ok()?, b.parse().ok()?)), total))
}

impl HttpSource {
    /// Opens `url`: one range request for the first [`PREFIX_BYTES`], which must be
    /// answered `206` with the file's length (a server answering `200` does not support
    /// ranges and is refused with a message saying so).
    pub fn open(url: &str) -> Result<HttpSource, FormatError> {
        if url.to_ascii_lowercase().starts_with("https://") {
            return Err(FormatError::io(
                url,
                std::io::Error::other("https:// is not supported yet; use http:// or a local path"),
            ));
        }
        let config = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(10)))
            .timeout_global(Some(Duration::from_secs(60)))
            .max_idle_connections_per_host(16)
            .build();
        let mut src = HttpSource {
            agent: config.into(),
            url: url.to_string(),
            len: 0,
            etag: None,
            prefix: Vec::new(),
            bytes_fetched: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            slots: Slots::default(),
        };
        let (body, len, etag) = src.with_retries(|s| s.fetch(0..PREFIX_BYTES, true))?;
        src.len = len;
        src.etag = etag;
        src.prefix = body;
        Ok(src)
    }

    /// The URL.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Body bytes received so far.
    pub fn bytes_fetched(&self) -> u64 {
        self.bytes_fetched.load(Ordering::Relaxed)
    }

    /// Whether `range` lies in the prefix the first request fetched (read for free).
    fn in_prefix(&self, range: &Range<u64>) -> bool {
        range.end <= self.prefix.len() as u64
    }

    /// Range requests sent so far (retries included).
    pub fn requests(&self) -> u64 {
        self.requests.load(Ordering::Relaxed)
    }

    fn error(&self, msg: impl Into<String>) -> FormatError {
        FormatError::io(&self.url, std::io::Error::other(msg.into()))
    }

    fn with_retries<T>(
        &self,
        mut f: impl FnMut(&Self) -> Result<T, Failure>,
    ) -> Result<T, FormatError> {
        let mut delay = Duration::from_millis(50);
        for attempt in 1..=ATTEMPTS {
            match f(self) {
                Ok(v) => return Ok(v),
                Err(Failure::Fatal(m)) => return Err(self.error(m)),
                Err(Failure::Transient(m)) if attempt == ATTEMPTS => {
                    return Err(self.error(format!("{m} (after {ATTEMPTS} attempts)")))
                }
                Err(Failure::Transient(m)) => {
                    tracing::debug!(url = %self.url, attempt, error = %m, "retrying");
                    std::thread::sleep(delay);
                    delay *= 4;
                }
            }
        }
        unreachable!("the last attempt returns")
    }

    /// One `GET` of `range` (clamped to the file when `first`): body, file length, ETag.
    fn fetch(
        &self,
        range: Range<u64>,
        first: bool,
    ) -> Result<(Vec<u8>, u64, Option<String>), Failure> {
        let mut req = self
            .agent
            .get(&self.url)
            .header("Range", format!("bytes={}-{}", range.start, range.end - 1))
            .header("Accept-Encoding", "identity");
        if let (false, Some(tag)) = (first, &self.etag) {
            req = req.header("If-Range", tag);
        }
        let _slot = self.slots.take();
        self.requests.fetch_add(1, Ordering::Relaxed);
        let mut resp = req.call().map_err(|e| Failure::Transient(e.to_string()))?;
        let status = resp.status().as_u16();
        let header = |name: &str| {
            resp.headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        let etag = header("etag");
        let content_range = header("content-range");
        match status {
            206 => {}
            200 if !first && etag.is_some() && etag != self.etag => {
                return Err(Failure::Fatal(format!(
                    "the model changed on the server since it was opened (ETag {} -> {}); open it again",
                    self.etag.as_deref().unwrap_or("?"),
                    etag.as_deref().unwrap_or("?")
                )))
            }
            200 => {
                return Err(Failure::Fatal(
                    "the server ignores HTTP range requests (it answered 200 with the whole file); \
                     serve the model with `tessera serve` or any server with Range support"
                        .into(),
                ))
            }
            416 => {
                let len = content_range
                    .as_deref()
                    .and_then(parse_content_range)
                    .map(|c| c.1);
                return Err(Failure::Fatal(match len {
                    Some(0) => "the file is empty: not a Tessera model".into(),
                    Some(n) => format!("range {range:?} is outside the {n}-byte file"),
                    None => format!("range {range:?} not satisfiable"),
                }));
            }
            404 | 410 => return Err(Failure::Fatal(format!("not found ({status})"))),
            s if s >= 500 => return Err(Failure::Transient(format!("server error {s}"))),
            s => return Err(Failure::Fatal(format!("unexpected HTTP status {s}"))),
        }
        let (span, total) = content_range
            .as_deref()
            .and_then(parse_content_range)
            .ok_or_else(|| Failure::Fatal("206 without a valid Content-Range".into()))?;
        let Some((a, b)) = span else {
            return Err(Failure::Fatal("206 without a byte span".into()));
        };
        let end = if first {
            range.end.min(total)
        } else {
            range.end
        };
        if a != range.start || b + 1 != end {
            return Err(Failure::Fatal(format!(
                "asked for bytes {}-{}, got {a}-{b}",
                range.start,
                end - 1
            )));
        }
        let expect = end - range.start;
        let body = resp
            .body_mut()
            .with_config()
            .limit(expect.max(1))
            .read_to_vec()
            .map_err(|e| Failure::Transient(format!("reading the body: {e}")))?;
        self.bytes_fetched
            .fetch_add(body.len() as u64, Ordering::Relaxed);
        if body.len() as u64 != expect {
            return Err(Failure::Transient(format!(
                "body of {} bytes, expected {expect}",
                body.len()
            )));
        }
        Ok((body, total, etag))
    }
}

impl ByteSource for HttpSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        if range.end > self.len || range.start > range.end {
            return Err(FormatError::Truncated {
                expected_bytes: range.end,
                actual_bytes: self.len,
            });
        }
        if self.in_prefix(&range) {
            return Ok(Cow::Borrowed(
                &self.prefix[range.start as usize..range.end as usize],
            ));
        }
        if range.is_empty() {
            return Ok(Cow::Borrowed(&[]));
        }
        let r = range.clone();
        let (body, _, _) = self.with_retries(|s| s.fetch(r.clone(), false))?;
        Ok(Cow::Owned(body))
    }
}

/// A model on an HTTP server: its index (read with one or two requests, or its top
/// first and the rest as the view needs it) and patches fetched on demand. See the crate
/// docs.
#[derive(Debug)]
pub struct RemoteModel {
    source: HttpSource,
    index: ModelIndex,
    /// The index read so far (a paged open grows it; else the same as `index`).
    latest: RwLock<Arc<ModelIndex>>,
    /// Held while the index grows (one reader at a time).
    growing: Mutex<()>,
    patches_read: AtomicU64,
}

/// Index pages a paged open reads first (the builder's pages hold 512 nodes: the roots
/// and five or six levels under them).
pub const TOP_PAGES: u64 = 1;

impl RemoteModel {
    /// Opens the model at `url` and reads and validates its whole index.
    pub fn open(url: &str) -> Result<RemoteModel, FormatError> {
        let source = HttpSource::open(url)?;
        let index = ModelIndex::read(&source)?;
        Ok(Self::with_index(source, index, url))
    }

    /// Opens the model at `url` reading only the top of its paged index
    /// ([`TOP_PAGES`] pages); [`PatchReader::grow_index`] reads more, as the view needs
    /// it.
    pub fn open_paged(url: &str) -> Result<RemoteModel, FormatError> {
        let source = HttpSource::open(url)?;
        let index = ModelIndex::read_top(&source, TOP_PAGES)?;
        Ok(Self::with_index(source, index, url))
    }

    fn with_index(source: HttpSource, index: ModelIndex, url: &str) -> RemoteModel {
        tracing::debug!(
            url,
            nodes = index.nodes().len(),
            of = index.header().node_count,
            bytes = source.bytes_fetched(),
            "opened remote model"
        );
        RemoteModel {
            source,
            latest: RwLock::new(Arc::new(index.clone())),
            index,
            growing: Mutex::new(()),
            patches_read: AtomicU64::new(0),
        }
    }

    /// The index read so far.
    fn current(&self) -> Arc<ModelIndex> {
        self.latest
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The byte source (for its counters).
    pub fn source(&self) -> &HttpSource {
        &self.source
    }

    /// Patches fetched with range requests so far (each read counts; patches inside
    /// the first request's prefix are read for free and not counted).
    pub fn patches_read(&self) -> u64 {
        self.patches_read.load(Ordering::Relaxed)
    }
}

impl PatchReader for RemoteModel {
    fn index(&self) -> &ModelIndex {
        &self.index
    }
    fn transfer(&self) -> Option<(u64, u64)> {
        Some((self.source.bytes_fetched(), self.source.requests()))
    }
    fn latest_index(&self) -> Option<Arc<ModelIndex>> {
        let cur = self.current();
        (cur.nodes().len() > self.index.nodes().len()).then_some(cur)
    }
    /// Reads index pages until at least one more level shows (doubling the pages read
    /// each time: levels roughly double in size); a failed read leaves the index as it
    /// was, to be grown again later.
    fn grow_index(&self) -> bool {
        let _one = self.growing.lock().unwrap_or_else(|e| e.into_inner());
        let mut next = self.current();
        let shown = next.nodes().len();
        while next.nodes().len() == shown && !next.is_complete() {
            match next.grown(&self.source, 2 * next.loaded_pages()) {
                Ok(ix) => next = Arc::new(ix),
                Err(e) => {
                    tracing::warn!(url = self.source.url(), error = %e, "could not read more of the index");
                    return false;
                }
            }
        }
        let grew = next.nodes().len() > shown;
        if grew {
            tracing::debug!(
                nodes = next.nodes().len(),
                bytes = self.source.bytes_fetched(),
                "index grown"
            );
            *self.latest.write().unwrap_or_else(|e| e.into_inner()) = next;
        }
        grew
    }
    fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        let index = self.current();
        let range = index.patch_range(i)?;
        if !self.source.in_prefix(&range) {
            self.patches_read.fetch_add(1, Ordering::Relaxed);
        }
        let bytes = self.source.read(range)?;
        index.decode_patch(i, &bytes)
    }

    /// Groups `nodes` into runs of patches adjacent in the file (see the crate docs) and
    /// fetches each run with one range request; a failed request fails every node of
    /// its run, with the same message.
    fn decode_patches(&self, nodes: &[usize]) -> Vec<Result<PatchData, FormatError>> {
        let index = self.current();
        let mut out: Vec<Option<Result<PatchData, FormatError>>> =
            nodes.iter().map(|_| None).collect();
        // (range, position in `nodes`), in file order; bad indices answered at once.
        let mut ranges = Vec::with_capacity(nodes.len());
        for (k, &i) in nodes.iter().enumerate() {
            match index.patch_range(i) {
                Ok(r) => ranges.push((r, k)),
                Err(e) => out[k] = Some(Err(e)),
            }
        }
        ranges.sort_by_key(|(r, _)| (r.start, r.end));
        let mut start = 0;
        while start < ranges.len() {
            let span_start = ranges[start].0.start;
            let mut span_end = ranges[start].0.end;
            let mut end = start + 1;
            while end < ranges.len()
                && end - start < COALESCE_MAX_PATCHES
                && ranges[end].0.start <= span_end + COALESCE_MAX_GAP
                && ranges[end].0.end.max(span_end) - span_start <= COALESCE_MAX_BYTES
            {
                span_end = span_end.max(ranges[end].0.end);
                end += 1;
            }
            let run = &ranges[start..end];
            match self.source.read(span_start..span_end) {
                Ok(bytes) => {
                    if !self.source.in_prefix(&(span_start..span_end)) {
                        self.patches_read
                            .fetch_add(run.len() as u64, Ordering::Relaxed);
                    }
                    for (r, k) in run {
                        let b =
                            &bytes[(r.start - span_start) as usize..(r.end - span_start) as usize];
                        out[*k] = Some(index.decode_patch(nodes[*k], b));
                    }
                }
                Err(e) => {
                    // Io errors already name the URL: repeat only their message.
                    let msg = match &e {
                        FormatError::Io { cause, .. } => cause.to_string(),
                        other => other.to_string(),
                    };
                    for (_, k) in run {
                        out[*k] = Some(Err(self.source.error(msg.clone())));
                    }
                }
            }
            start = end;
        }
        out.into_iter()
            .map(|r| r.unwrap_or_else(|| Err(self.source.error("patch not read"))))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_range_parses() {
        assert_eq!(
            parse_content_range("bytes 0-9/100"),
            Some((Some((0, 9)), 100))
        );
        assert_eq!(parse_content_range("bytes */42"), Some((None, 42)));
        assert_eq!(parse_content_range("bytes 5-/9"), None);
        assert_eq!(parse_content_range("items 0-1/2"), None);
        assert!(is_url("HTTP://x/m.tsr") && !is_url("/tmp/http.tsr"));
    }
}
