//! Tessera models over HTTP: any server that answers `Range` requests (`tessera serve`,
//! nginx, a CDN) serves a model as a plain file.
//!
//! - [`HttpSource`] is a [`ByteSource`] of HTTP range requests through one `ureq`
//!   connection pool. The first request fetches the file's first [`PREFIX_BYTES`]
//!   (header and, for models up to a few hundred nodes, the whole node table) and pins
//!   the file's `ETag`; every later request carries `If-Range` with it and every `206`
//!   must carry the same tag, so a model replaced on the server is detected (the server
//!   answers `200` with the new file, or a `206` of another tag) and reported, never
//!   mixed with the old bytes. A redirect of the first request is followed (to
//!   `http://` URLs only, at most [`MAX_REDIRECTS`]); a redirect to anything else is
//!   reported as what it is.
//! - [`RemoteModel`] is a [`ModelIndex`] read through it plus patches fetched on demand:
//!   a [`PatchReader`], so `tessera-page`'s loader threads and the viewer read it like a
//!   local file. [`PatchReader::decode_patches`] coalesces: patches adjacent in the file
//!   (the node table's Morton order puts siblings side by side) come with one range
//!   request of at most [`COALESCE_MAX_PATCHES`] patches and [`COALESCE_MAX_BYTES`].
//! - At most [`MAX_IN_FLIGHT`] requests of one source are in flight at once, whatever
//!   the number of threads reading it (loader threads, rayon's pool in complete frames);
//!   the others wait their turn (Nexus uses 3 too).
//!
//! **The server cannot make the client allocate or wait without bound** (issue 29):
//!
//! - Sizes are checked before anything is fetched: the index a header claims must fit
//!   what its node count can take and [`MAX_READ_BYTES`] (a forged header with a valid
//!   CRC claiming a 1 GB index is refused after the first 64 KiB, as the local reader
//!   refuses it), no read asks for more than [`MAX_READ_BYTES`], a `Content-Range` or
//!   `Content-Length` that is not the range asked for is refused (checked arithmetic:
//!   `bytes 0-18446744073709551615/0` is an error, not a wrapped `+ 1`), and a body is
//!   read with the expected length as its limit (memory grows with the bytes that
//!   arrive, never with what a header announces).
//! - Time: [`CONNECT_TIMEOUT`] (5 s) to connect, [`STALL_TIMEOUT`] (5 s) without a byte
//!   while waiting for or reading an answer, and each read (all its attempts) within
//!   [`READ_DEADLINE`] (8 s) plus its bytes at [`MIN_BYTES_PER_S`] (256 KiB/s), so a
//!   silent server fails a read in 5 s and one that drips in about 8. A read that timed
//!   out makes every read of the source for the next [`UNAVAILABLE_COOLDOWN`] fail at
//!   once with the same error (a render of hundreds of patches against a stalled server
//!   fails in seconds, not one timeout per patch), and
//!   [`HttpOptions::deadline`] bounds everything read through a source (`tessera info`).
//! - Retries: up to [`ATTEMPTS`] attempts, within the read's deadline, for failures
//!   that may pass (connection refused or reset, a short body, `5xx`, `408`, `429`);
//!   none for the rest (other `4xx`, a mislabelled answer, a changed model, timeouts,
//!   which already spent the read's time).
//! - Every error says what kind it is ([`classify`] and [`ErrorClass`]): the server
//!   unavailable, the model changed, the answer refused, or the bytes corrupt.
//!
//! Only `http://` URLs: TLS is not compiled in.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant};

use tessera_format::{ByteSource, FormatError, Header, ModelIndex, PatchData, PatchReader};

/// Bytes fetched by the first request of a model.
pub const PREFIX_BYTES: u64 = 64 << 10;
/// Attempts per range request (failures that may pass only, within its deadline).
pub const ATTEMPTS: u32 = 3;
/// Most time to connect (one attempt). A LAN or loopback connect takes well under a
/// millisecond, a WAN one under a second; 5 s covers a lost SYN retransmitted at 1 s
/// and 3 s.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// Most time without a byte from the server while waiting for or reading an answer
/// (`tessera serve` answers from its own disk in milliseconds; a proxy or CDN fetching
/// a cold object in a second or two).
pub const STALL_TIMEOUT: Duration = Duration::from_secs(5);
/// The time each read has (all its attempts), plus its bytes at [`MIN_BYTES_PER_S`]:
/// a 64 KiB first request 8.25 s, a 512 KiB coalesced one 10 s.
pub const READ_DEADLINE: Duration = Duration::from_secs(8);
/// The slowest transfer a read waits for beyond [`READ_DEADLINE`] (2 Mbit/s).
pub const MIN_BYTES_PER_S: u64 = 256 << 10;
/// Most bytes one read may ask for, and most bytes of index a header may claim for
/// [`RemoteModel::open`] (256 MiB: a paged index of about 8 million nodes; patches are
/// at most a few MiB).
pub const MAX_READ_BYTES: u64 = 256 << 20;
/// After a read timed out, how long every other read of the source fails at once
/// instead of waiting for its own timeout.
pub const UNAVAILABLE_COOLDOWN: Duration = Duration::from_secs(2);
/// Most redirects the first request follows.
pub const MAX_REDIRECTS: u32 = 5;
/// Most range requests of one [`HttpSource`] in flight at once.
pub const MAX_IN_FLIGHT: usize = 3;
use tessera_format::ranges::{coalesce, parse_content_range};
/// The coalescing rule of [`RemoteModel::decode_patches`]: every reader's
/// (`tessera_format::ranges`).
pub use tessera_format::ranges::{COALESCE_MAX_BYTES, COALESCE_MAX_GAP, COALESCE_MAX_PATCHES};
/// Upper bound of one node's uncompressed index page bytes (`docs/format.md`; the
/// reader's own bound in `tessera_format::pages`).
const MAX_NODE_PAGE_BYTES: u64 = 128;

/// Whether `s` names a remote model (`http://` or `https://`) rather than a path.
pub fn is_url(s: &str) -> bool {
    let l = s.to_ascii_lowercase();
    l.starts_with("http://") || l.starts_with("https://")
}

/// What kind of failure a read of a remote model was: what a caller tells its user and
/// whether trying again can help.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorClass {
    /// The server could not be reached or did not answer in time (connection refused or
    /// reset, a timeout, `5xx`, `408`, `429`): it may pass; read again later.
    Unavailable,
    /// The model on the server is no longer the one opened (its `ETag` or length
    /// changed): open it again.
    Changed,
    /// The server answered, but not with what was asked (`404` and other `4xx`, no range
    /// support, a redirect away from `http://`, a mislabelled range, a header claiming
    /// more than a client reads): trying again will not help.
    Refused,
    /// The bytes arrived but are not a valid model (a checksum or decoding failure, an
    /// inconsistent header or index).
    Corrupt,
}

impl ErrorClass {
    /// How a report names patches that failed so: "unavailable", "changed on the
    /// server", "refused by the server", "corrupt".
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorClass::Unavailable => "unavailable",
            ErrorClass::Changed => "changed on the server",
            ErrorClass::Refused => "refused by the server",
            ErrorClass::Corrupt => "corrupt",
        }
    }
}

/// A failed request of an [`HttpSource`]: the message and its [`ErrorClass`]. It
/// reaches callers inside [`FormatError::Io`] (use [`classify`]).
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct HttpError {
    /// What kind of failure.
    pub class: ErrorClass,
    message: String,
    /// A timeout (the server stalled): starts an [`UNAVAILABLE_COOLDOWN`].
    timed_out: bool,
}

impl HttpError {
    fn new(class: ErrorClass, message: impl Into<String>) -> HttpError {
        HttpError {
            class,
            message: message.into(),
            timed_out: false,
        }
    }

    fn timed_out(message: impl Into<String>) -> HttpError {
        HttpError {
            timed_out: true,
            ..unavailable(message)
        }
    }
}

/// The kind of a failure of [`HttpSource`] or [`RemoteModel`]: the class of an
/// [`HttpError`]; another I/O error is [`ErrorClass::Unavailable`] (it may pass); every
/// other [`FormatError`] (checksums, decoding, headers) is [`ErrorClass::Corrupt`].
pub fn classify(e: &FormatError) -> ErrorClass {
    match e {
        FormatError::Io { cause, .. } => cause
            .get_ref()
            .and_then(|inner| inner.downcast_ref::<HttpError>())
            .map_or(ErrorClass::Unavailable, |h| h.class),
        _ => ErrorClass::Corrupt,
    }
}

/// Settings of an [`HttpSource`] beyond the fixed timeouts.
#[derive(Clone, Debug, Default)]
pub struct HttpOptions {
    /// Everything read through the source (the open included) must be read within this
    /// from the open; later reads fail as [`ErrorClass::Unavailable`] (None: no overall
    /// bound, each read has its own deadline). `tessera info` uses 15 s.
    pub deadline: Option<Duration>,
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
    /// The end of [`HttpOptions::deadline`], and the deadline.
    deadline: Option<(Instant, Duration)>,
    /// When the last read failed for want of the server, and why.
    down: Mutex<Option<(Instant, String)>>,
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

/// How one attempt of a request failed.
enum Attempt {
    /// May pass: try again if the read's deadline allows.
    Retry(HttpError),
    /// Final.
    Stop(HttpError),
    /// The source is in its [`UNAVAILABLE_COOLDOWN`]: final, and not a new failure.
    Down(HttpError),
}

/// A successful answer of one attempt.
enum Reply {
    /// A `206` of the range asked for: body, file length, ETag.
    Bytes(Vec<u8>, u64, Option<String>),
    /// A redirect to this `Location`.
    Redirect(String),
}

fn unavailable(m: impl Into<String>) -> HttpError {
    HttpError::new(ErrorClass::Unavailable, m)
}

fn refused(m: impl Into<String>) -> HttpError {
    HttpError::new(ErrorClass::Refused, m)
}

/// What a `ureq` error means for the attempt that got it.
fn ureq_failure(e: ureq::Error, doing: &str) -> Attempt {
    use std::io::ErrorKind as K;
    match e {
        ureq::Error::Timeout(ureq::Timeout::PerRead) => {
            Attempt::Stop(HttpError::timed_out(format!(
                "{doing}: the server sent nothing for {} s",
                STALL_TIMEOUT.as_secs()
            )))
        }
        ureq::Error::Timeout(ureq::Timeout::Connect) => {
            Attempt::Stop(HttpError::timed_out(format!(
                "{doing}: could not connect within {} s",
                CONNECT_TIMEOUT.as_secs()
            )))
        }
        ureq::Error::Timeout(t) => Attempt::Stop(HttpError::timed_out(format!(
            "{doing}: timed out ({t}): the server is stalled or too slow"
        ))),
        ureq::Error::Io(io) if matches!(io.kind(), K::TimedOut | K::WouldBlock) => {
            Attempt::Stop(HttpError::timed_out(format!("{doing}: timed out: {io}")))
        }
        ureq::Error::Io(io) => Attempt::Retry(unavailable(format!("{doing}: {io}"))),
        ureq::Error::ConnectionFailed => {
            Attempt::Retry(unavailable(format!("{doing}: connection failed")))
        }
        ureq::Error::HostNotFound => Attempt::Stop(unavailable(format!("{doing}: host not found"))),
        other => Attempt::Stop(refused(format!("{doing}: {other}"))),
    }
}

/// The `http://` URL a redirect from `from` (an `http://` URL) to `location` leads to,
/// or why it is not followed (another scheme: `file://`, `https://`, `data:`...).
fn redirect_target(from: &str, location: &str) -> Result<String, HttpError> {
    let loc = location.trim();
    let scheme = loc.split_once(':').map(|(s, _)| s).filter(|s| {
        s.starts_with(|c: char| c.is_ascii_alphabetic())
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
    });
    match scheme {
        Some(s) if s.eq_ignore_ascii_case("http") => return Ok(loc.to_string()),
        Some(s) => {
            return Err(refused(format!(
                "the server redirects to {loc:?}, a {s}: URL: only redirects to http:// URLs are followed"
            )))
        }
        None => {}
    }
    // A reference relative to `from` = http://AUTHORITY/PATH.
    let authority_end = from
        .get("http://".len()..)
        .and_then(|rest| rest.find('/'))
        .map_or(from.len(), |i| "http://".len() + i);
    if let Some(rest) = loc.strip_prefix("//") {
        return Ok(format!("http://{rest}"));
    }
    if loc.starts_with('/') {
        return Ok(format!("{}{loc}", &from[..authority_end]));
    }
    let base = match from.rfind('/') {
        Some(i) if i >= authority_end => &from[..=i],
        _ => &from[..authority_end],
    };
    let sep = if base.ends_with('/') { "" } else { "/" };
    Ok(format!("{base}{sep}{loc}"))
}

impl HttpSource {
    /// Opens `url`: one range request for the first [`PREFIX_BYTES`], which must be
    /// answered `206` with the file's length (a server answering `200` does not support
    /// ranges and is refused with a message saying so).
    pub fn open(url: &str) -> Result<HttpSource, FormatError> {
        Self::open_with(url, &HttpOptions::default())
    }

    /// [`HttpSource::open`] with settings.
    pub fn open_with(url: &str, opts: &HttpOptions) -> Result<HttpSource, FormatError> {
        let started = Instant::now();
        if url.to_ascii_lowercase().starts_with("https://") {
            return Err(FormatError::io(
                url,
                std::io::Error::other(refused(
                    "https:// is not supported yet; use http:// or a local path",
                )),
            ));
        }
        let config = ureq::Agent::config_builder()
            .http_status_as_error(false)
            // Redirects are followed by `open` itself: only to http:// URLs.
            .max_redirects(0)
            .timeout_connect(Some(CONNECT_TIMEOUT))
            .timeout_per_read(Some(STALL_TIMEOUT))
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
            deadline: opts.deadline.map(|d| (started + d, d)),
            down: Mutex::new(None),
        };
        let mut redirects = 0;
        loop {
            let at = src.url.clone();
            match src.with_retries(PREFIX_BYTES, |s, deadline| {
                s.fetch(&at, 0..PREFIX_BYTES, true, deadline)
            })? {
                Reply::Bytes(body, len, etag) => {
                    src.len = len;
                    src.etag = etag;
                    src.prefix = body;
                    return Ok(src);
                }
                Reply::Redirect(location) => {
                    redirects += 1;
                    let next = redirect_target(&src.url, &location).map_err(|e| src.error(e))?;
                    if redirects > MAX_REDIRECTS {
                        return Err(src.error(refused(format!(
                            "more than {MAX_REDIRECTS} redirects (the last to {next})"
                        ))));
                    }
                    tracing::debug!(from = %src.url, to = %next, "following a redirect");
                    src.url = next;
                }
            }
        }
    }

    /// The URL (after the redirects of the first request).
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

    fn error(&self, e: HttpError) -> FormatError {
        let kind = match e.class {
            ErrorClass::Unavailable if e.timed_out => std::io::ErrorKind::TimedOut,
            ErrorClass::Unavailable => std::io::ErrorKind::Other,
            ErrorClass::Changed | ErrorClass::Refused | ErrorClass::Corrupt => {
                std::io::ErrorKind::InvalidData
            }
        };
        FormatError::io(&self.url, std::io::Error::new(kind, e))
    }

    /// The deadline of a read of `bytes` starting now (see the crate docs).
    fn read_deadline(&self, bytes: u64) -> Instant {
        let own = Instant::now()
            + READ_DEADLINE
            + Duration::from_secs_f64(bytes as f64 / MIN_BYTES_PER_S as f64);
        self.deadline.map_or(own, |(d, _)| d.min(own))
    }

    /// The error every read gets during an [`UNAVAILABLE_COOLDOWN`] or past the
    /// overall deadline.
    fn down_now(&self) -> Option<HttpError> {
        if let Some((_, d)) = self.deadline.filter(|(end, _)| Instant::now() >= *end) {
            return Some(unavailable(format!(
                "the {} s allowed for reading this model have passed",
                d.as_secs_f64()
            )));
        }
        let down = self.down.lock().unwrap_or_else(|p| p.into_inner());
        let (at, why) = down.as_ref()?;
        let ago = at.elapsed();
        (ago < UNAVAILABLE_COOLDOWN).then(|| {
            unavailable(format!(
                "{why} (the server failed {} ms ago; not asked again yet)",
                ago.as_millis()
            ))
        })
    }

    fn with_retries<T>(
        &self,
        bytes: u64,
        mut f: impl FnMut(&Self, Instant) -> Result<T, Attempt>,
    ) -> Result<T, FormatError> {
        if bytes > MAX_READ_BYTES {
            return Err(self.error(refused(format!(
                "a read of {bytes} bytes is more than the {} MiB this client reads at once",
                MAX_READ_BYTES >> 20
            ))));
        }
        let deadline = self.read_deadline(bytes);
        let mut delay = Duration::from_millis(50);
        // Only a timeout starts a cool-down (the failures that cost time; a refused
        // connection or a short body fail fast by themselves, and failing the reads
        // queued behind them at once would only speed up a pager's backoff); any other
        // outcome ends one.
        let failed = |e: HttpError| {
            *self.down.lock().unwrap_or_else(|p| p.into_inner()) =
                e.timed_out.then(|| (Instant::now(), e.message.clone()));
            self.error(e)
        };
        for attempt in 1..=ATTEMPTS {
            match f(self, deadline) {
                Ok(v) => {
                    *self.down.lock().unwrap_or_else(|p| p.into_inner()) = None;
                    return Ok(v);
                }
                Err(Attempt::Down(e)) => return Err(self.error(e)),
                Err(Attempt::Stop(e)) => return Err(failed(e)),
                Err(Attempt::Retry(mut e))
                    if attempt == ATTEMPTS || Instant::now() + delay >= deadline =>
                {
                    e.message = format!("{} (after {attempt} attempts)", e.message);
                    return Err(failed(e));
                }
                Err(Attempt::Retry(e)) => {
                    tracing::debug!(url = %self.url, attempt, error = %e, "retrying");
                    std::thread::sleep(delay);
                    delay *= 4;
                }
            }
        }
        unreachable!("the last attempt returns")
    }

    /// One `GET` of `range` from `url` (clamped to the file when `first`) within
    /// `deadline`.
    fn fetch(
        &self,
        url: &str,
        range: Range<u64>,
        first: bool,
        deadline: Instant,
    ) -> Result<Reply, Attempt> {
        let mut req = self
            .agent
            .get(url)
            .header("Range", format!("bytes={}-{}", range.start, range.end - 1))
            .header("Accept-Encoding", "identity");
        if let (false, Some(tag)) = (first, &self.etag) {
            req = req.header("If-Range", tag);
        }
        let _slot = self.slots.take();
        // Checked after the wait for a slot: the server may have failed meanwhile.
        if let Some(e) = self.down_now() {
            return Err(Attempt::Down(e));
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(Attempt::Stop(HttpError::timed_out(
                "no time left for this read",
            )));
        }
        let req = req.config().timeout_global(Some(left)).build();
        self.requests.fetch_add(1, Ordering::Relaxed);
        let mut resp = req.call().map_err(|e| ureq_failure(e, "the request"))?;
        let status = resp.status().as_u16();
        let header = |name: &str| {
            resp.headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        let etag = header("etag");
        let content_range = header("content-range");
        let content_length = header("content-length");
        let changed = |now: &str| {
            Attempt::Stop(HttpError::new(
                ErrorClass::Changed,
                format!(
                    "the model changed on the server since it was opened (ETag {} -> {now}); open it again",
                    self.etag.as_deref().unwrap_or("none"),
                ),
            ))
        };
        match status {
            206 => {}
            200 if !first && etag.is_some() && etag != self.etag => {
                return Err(changed(etag.as_deref().unwrap_or("?")))
            }
            200 => return Err(Attempt::Stop(refused(
                "the server ignores HTTP range requests (it answered 200 with the whole file); \
                     serve the model with `tessera serve` or any server with Range support",
            ))),
            301 | 302 | 303 | 307 | 308 if first => {
                return match header("location") {
                    Some(l) => Ok(Reply::Redirect(l)),
                    None => Err(Attempt::Stop(refused(format!(
                        "redirect ({status}) without a Location"
                    )))),
                }
            }
            300..=399 => {
                return Err(Attempt::Stop(refused(format!(
                    "unexpected redirect ({status}) to {}",
                    header("location").as_deref().unwrap_or("nowhere")
                ))))
            }
            416 => {
                let len = content_range
                    .as_deref()
                    .and_then(parse_content_range)
                    .map(|c| c.1);
                return Err(Attempt::Stop(refused(match len {
                    Some(0) => "the file is empty: not a Tessera model".into(),
                    Some(n) => format!("range {range:?} is outside the {n}-byte file"),
                    None => format!("range {range:?} not satisfiable"),
                })));
            }
            404 | 410 => return Err(Attempt::Stop(refused(format!("not found ({status})")))),
            408 | 429 => {
                return Err(Attempt::Retry(unavailable(format!(
                    "the server is busy ({status})"
                ))))
            }
            s if s >= 500 => return Err(Attempt::Retry(unavailable(format!("server error {s}")))),
            s => {
                return Err(Attempt::Stop(refused(format!(
                    "unexpected HTTP status {s}"
                ))))
            }
        }
        // Every 206 must be of the file that was opened.
        if !first {
            if let Some(pinned) = &self.etag {
                match &etag {
                    Some(t) if t == pinned => {}
                    Some(t) => return Err(changed(t)),
                    None => {
                        return Err(Attempt::Stop(refused(format!(
                            "a 206 without an ETag (the model was opened with ETag {pinned}): \
                             cannot tell whether it changed"
                        ))))
                    }
                }
            }
        }
        let bad = |m: String| Attempt::Stop(refused(m));
        let (span, total) = content_range
            .as_deref()
            .and_then(parse_content_range)
            .ok_or_else(|| {
                bad(format!(
                    "206 without a valid Content-Range ({:?})",
                    content_range.as_deref().unwrap_or("none")
                ))
            })?;
        let Some((a, b)) = span else {
            return Err(bad("206 without a byte span".into()));
        };
        if !first && total != self.len {
            return Err(Attempt::Stop(HttpError::new(
                ErrorClass::Changed,
                format!(
                    "the file on the server is now {total} bytes (it was {} when opened); open it again",
                    self.len
                ),
            )));
        }
        let end = if first {
            range.end.min(total)
        } else {
            range.end
        };
        // `b < total` and `a <= b` hold (parse_content_range), so `b + 1` cannot wrap.
        if a != range.start || b.checked_add(1) != Some(end) {
            return Err(bad(format!(
                "asked for bytes {}-{}, got {a}-{b}",
                range.start,
                range.end - 1
            )));
        }
        let expect = end - range.start;
        if let Some(n) = content_length.as_deref() {
            if n.trim().parse::<u64>().ok() != Some(expect) {
                return Err(bad(format!(
                    "a {expect}-byte range answered with Content-Length {n}"
                )));
            }
        }
        let body = resp
            .body_mut()
            .with_config()
            .limit(expect.max(1))
            .read_to_vec()
            .map_err(|e| match ureq_failure(e, "reading the body") {
                // A connection cut mid-body may pass; a body over its length will not.
                Attempt::Stop(e) if e.class == ErrorClass::Refused => Attempt::Stop(e),
                other => other,
            })?;
        self.bytes_fetched
            .fetch_add(body.len() as u64, Ordering::Relaxed);
        if body.len() as u64 != expect {
            return Err(Attempt::Retry(unavailable(format!(
                "body of {} bytes, expected {expect}",
                body.len()
            ))));
        }
        Ok(Reply::Bytes(body, total, etag))
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
        match self.with_retries(range.end - range.start, |s, deadline| {
            s.fetch(&s.url, r.clone(), false, deadline)
        })? {
            Reply::Bytes(body, _, _) => Ok(Cow::Owned(body)),
            // `fetch` answers a redirect only to the first request.
            Reply::Redirect(l) => Err(self.error(refused(format!("unexpected redirect to {l}")))),
        }
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

/// The header of `source` (in the first request's prefix), checked as the local reader
/// checks it and, before any byte of the index is asked for, against the most index its
/// node and page counts can need: every node takes at most [`MAX_NODE_PAGE_BYTES`]
/// before compression and zstd adds at most 1/256 plus a frame's overhead. A local
/// file's length bounds its header; a server's `Content-Range` can claim any length.
fn checked_header(source: &HttpSource) -> Result<Header, FormatError> {
    let prefix = source.read(0..tessera_format::HEADER_BYTES.min(source.len()))?;
    let h = ModelIndex::parse_header(&prefix, source.len())?;
    let layout = h.index_layout();
    let raw = 8 * layout.page_count + MAX_NODE_PAGE_BYTES * h.node_count;
    let most = layout.pages_offset + raw + raw / 256 + 128 * layout.page_count + 4096;
    let claimed = h.patch_data_offset - h.index_offset;
    if h.patch_data_offset > most {
        return Err(FormatError::InvalidHeader {
            detail: format!(
                "the index is {claimed} bytes, more than its {} nodes in {} pages can take \
                 (at most {most}): a corrupt or forged header",
                h.node_count, layout.page_count
            ),
        });
    }
    Ok(h)
}

/// Index pages a paged open reads first (the builder's pages hold 512 nodes: the roots
/// and five or six levels under them).
pub const TOP_PAGES: u64 = 1;

impl RemoteModel {
    /// Opens the model at `url` and reads and validates its whole index.
    pub fn open(url: &str) -> Result<RemoteModel, FormatError> {
        Self::open_with(url, &HttpOptions::default())
    }

    /// [`RemoteModel::open`] with settings.
    pub fn open_with(url: &str, opts: &HttpOptions) -> Result<RemoteModel, FormatError> {
        let source = HttpSource::open_with(url, opts)?;
        let header = checked_header(&source)?;
        let index_bytes = header.patch_data_offset - header.index_offset;
        if index_bytes > MAX_READ_BYTES {
            return Err(source.error(refused(format!(
                "the header claims an index of {index_bytes} bytes, more than the {} MiB this \
                 client reads (a forged header, or a model to open paged)",
                MAX_READ_BYTES >> 20
            ))));
        }
        let index = ModelIndex::read(&source)?;
        Ok(Self::with_index(source, index, url))
    }

    /// Opens the model at `url` reading only the top of its paged index
    /// ([`TOP_PAGES`] pages); [`PatchReader::grow_index`] reads more, as the view needs
    /// it.
    pub fn open_paged(url: &str) -> Result<RemoteModel, FormatError> {
        Self::open_paged_with(url, &HttpOptions::default())
    }

    /// [`RemoteModel::open_paged`] with settings.
    pub fn open_paged_with(url: &str, opts: &HttpOptions) -> Result<RemoteModel, FormatError> {
        let source = HttpSource::open_with(url, opts)?;
        checked_header(&source)?;
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
        let spans: Vec<Range<u64>> = ranges.iter().map(|(r, _)| r.clone()).collect();
        for (span, members) in coalesce(&spans) {
            let (span_start, span_end) = (span.start, span.end);
            let run = &ranges[members];
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
                    // Io errors already name the URL: repeat only their message (and
                    // their class).
                    let msg = match &e {
                        FormatError::Io { cause, .. } => cause.to_string(),
                        other => other.to_string(),
                    };
                    let class = classify(&e);
                    for (_, k) in run {
                        out[*k] = Some(Err(self.source.error(HttpError::new(class, msg.clone()))));
                    }
                }
            }
        }
        out.into_iter()
            .map(|r| r.unwrap_or_else(|| Err(self.source.error(refused("patch not read")))))
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
        // Issue 29: `b + 1` wrapped; a span must lie inside the file.
        assert_eq!(parse_content_range("bytes 0-18446744073709551615/0"), None);
        assert_eq!(parse_content_range("bytes 0-9/9"), None);
        assert_eq!(parse_content_range("bytes 9-0/100"), None);
        assert!(is_url("HTTP://x/m.tsr") && !is_url("/tmp/http.tsr"));
    }

    #[test]
    fn redirects_resolve_to_http_only() {
        let from = "http://h:1/models/a.tsr";
        let ok = |l: &str| redirect_target(from, l).unwrap();
        assert_eq!(ok("http://o/x.tsr"), "http://o/x.tsr");
        assert_eq!(ok("/b.tsr"), "http://h:1/b.tsr");
        assert_eq!(ok("b.tsr"), "http://h:1/models/b.tsr");
        assert_eq!(ok("//o:2/c.tsr"), "http://o:2/c.tsr");
        assert_eq!(
            redirect_target("http://h", "b.tsr").unwrap(),
            "http://h/b.tsr"
        );
        for bad in [
            "file:///etc/passwd",
            "https://h/a.tsr",
            "data:,x",
            "FILE:/x",
        ] {
            let e = redirect_target(from, bad).unwrap_err();
            assert_eq!(e.class, ErrorClass::Refused);
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    #[test]
    fn errors_are_classified() {
        let e = FormatError::io("u", std::io::Error::other(unavailable("gone")));
        assert_eq!(classify(&e), ErrorClass::Unavailable);
        let e = FormatError::io("u", std::io::Error::other(refused("no")));
        assert_eq!(classify(&e), ErrorClass::Refused);
        assert_eq!(
            classify(&FormatError::PatchChecksum { node: 3 }),
            ErrorClass::Corrupt
        );
        let local = FormatError::io("f", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(classify(&local), ErrorClass::Unavailable);
        assert_eq!(ErrorClass::Corrupt.as_str(), "corrupt");
    }
}
