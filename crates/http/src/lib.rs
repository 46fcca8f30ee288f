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
//!   a [`PatchReader`], so `tessera-page`'s loader threads (one request in flight per
//!   thread) and the viewer read it like a local file.
//!
//! Only `http://` URLs: TLS is not compiled in.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tessera_format::{ByteSource, FormatError, ModelIndex, PatchData, PatchReader};

/// Bytes fetched by the first request of a model.
pub const PREFIX_BYTES: u64 = 64 << 10;
/// Attempts per range request (transient failures only).
const ATTEMPTS: u32 = 3;

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
        if range.end <= self.prefix.len() as u64 {
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

/// A model on an HTTP server: its index (read with one or two requests) and patches
/// fetched on demand. See the crate docs.
#[derive(Debug)]
pub struct RemoteModel {
    source: HttpSource,
    index: ModelIndex,
}

impl RemoteModel {
    /// Opens the model at `url` and reads and validates its index.
    pub fn open(url: &str) -> Result<RemoteModel, FormatError> {
        let source = HttpSource::open(url)?;
        let index = ModelIndex::read(&source)?;
        tracing::debug!(
            url,
            nodes = index.nodes().len(),
            bytes = source.bytes_fetched(),
            "opened remote model"
        );
        Ok(RemoteModel { source, index })
    }

    /// The byte source (for its counters).
    pub fn source(&self) -> &HttpSource {
        &self.source
    }
}

impl PatchReader for RemoteModel {
    fn index(&self) -> &ModelIndex {
        &self.index
    }
    fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        self.index.read_patch(&self.source, i)
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
