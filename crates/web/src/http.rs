//! HTTP range requests with the browser's `fetch` (web-sys): the first request of a
//! model pins its length and `ETag`; later ones carry `If-Range` with it, so a model
//! replaced on the server is reported, never mixed with the old bytes (as
//! `tessera-http`).

use std::cell::{Cell, RefCell};
use std::ops::Range;

use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_futures::JsFuture;

use crate::plan::{parse_content_range, range_header};

/// Why a request failed.
#[derive(Debug)]
pub enum HttpError {
    /// Asking again will not help (not found, no range support, model changed).
    Fatal(String),
    /// Network trouble or a server error: may pass.
    Transient(String),
}

impl HttpError {
    pub fn message(&self) -> &str {
        match self {
            HttpError::Fatal(m) | HttpError::Transient(m) => m,
        }
    }
}

/// One remote model file.
pub struct Http {
    pub url: String,
    etag: RefCell<Option<String>>,
    len: Cell<u64>,
    pub requests: Cell<u64>,
    pub bytes: Cell<u64>,
}

fn js_message(e: &JsValue) -> String {
    if let Some(err) = e.dyn_ref::<js_sys::Error>() {
        return String::from(err.message());
    }
    e.as_string().unwrap_or_else(|| format!("{e:?}"))
}

impl Http {
    pub fn new(url: &str) -> Http {
        Http {
            url: url.to_string(),
            etag: RefCell::new(None),
            len: Cell::new(0),
            requests: Cell::new(0),
            bytes: Cell::new(0),
        }
    }

    /// Length of the file (after [`Http::open`]).
    pub fn len(&self) -> u64 {
        self.len.get()
    }

    /// The first request: up to `prefix` bytes from the start; sets the length and ETag.
    pub async fn open(&self, prefix: u64) -> Result<Vec<u8>, HttpError> {
        self.get(0..prefix.max(1), true).await
    }

    /// `GET` of `range` (clamped to the file when `first`).
    pub async fn get(&self, range: Range<u64>, first: bool) -> Result<Vec<u8>, HttpError> {
        self.get_abortable(range, first, None).await
    }

    /// [`Http::get`], aborted when `signal` is (an `AbortController`'s): the fetch
    /// rejects, and so does this, with [`HttpError::Transient`].
    pub async fn get_abortable(
        &self,
        range: Range<u64>,
        first: bool,
        signal: Option<&web_sys::AbortSignal>,
    ) -> Result<Vec<u8>, HttpError> {
        let fatal = |m: String| HttpError::Fatal(m);
        let init = web_sys::RequestInit::new();
        init.set_method("GET");
        if let Some(s) = signal {
            init.set_signal(Some(s));
        }
        let headers = web_sys::Headers::new().map_err(|e| fatal(js_message(&e)))?;
        headers
            .set("Range", &range_header(&range))
            .map_err(|e| fatal(js_message(&e)))?;
        if !first {
            if let Some(tag) = self.etag.borrow().as_deref() {
                headers
                    .set("If-Range", tag)
                    .map_err(|e| fatal(js_message(&e)))?;
            }
        }
        init.set_headers(&headers);
        let req = web_sys::Request::new_with_str_and_init(&self.url, &init)
            .map_err(|e| fatal(format!("bad model URL {}: {}", self.url, js_message(&e))))?;
        let global = js_sys::global();
        let promise = if let Some(w) = global.dyn_ref::<web_sys::Window>() {
            w.fetch_with_request(&req)
        } else if let Some(w) = global.dyn_ref::<web_sys::WorkerGlobalScope>() {
            w.fetch_with_request(&req)
        } else {
            return Err(fatal("no fetch in this context".into()));
        };
        self.requests.set(self.requests.get() + 1);
        let resp: web_sys::Response = match JsFuture::from(promise).await {
            Ok(r) => r.unchecked_into(),
            Err(e) => {
                let m = format!(
                    "cannot fetch {}: {} (the server is unreachable, dropped the connection, \
                     or refused cross-origin access: CORS)",
                    self.url,
                    js_message(&e)
                );
                return Err(if first {
                    HttpError::Fatal(m)
                } else {
                    HttpError::Transient(m)
                });
            }
        };
        let status = resp.status();
        let header = |name: &str| resp.headers().get(name).ok().flatten();
        let etag = header("etag");
        let discard = |resp: &web_sys::Response| {
            // Do not download a whole file we will not use.
            if let Some(body) = resp.body() {
                let _ = body.cancel();
            }
        };
        match status {
            206 => {}
            200 if !first && etag.is_some() && etag != *self.etag.borrow() => {
                discard(&resp);
                return Err(fatal(format!(
                    "the model changed on the server since it was opened ({}); reload the page",
                    self.url
                )));
            }
            200 => {
                discard(&resp);
                return Err(fatal(format!(
                    "the server ignores HTTP range requests (it answered 200 with the whole \
                     file for {}): serve the model with `tessera serve` or any server with \
                     Range support",
                    self.url
                )));
            }
            404 | 410 => {
                discard(&resp);
                return Err(fatal(format!(
                    "model not found: {} (HTTP {status})",
                    self.url
                )));
            }
            416 => {
                discard(&resp);
                let len = header("content-range")
                    .as_deref()
                    .and_then(parse_content_range)
                    .map(|c| c.1);
                return Err(fatal(match len {
                    Some(0) => format!("{} is empty: not a Tessera model", self.url),
                    _ => format!("range {range:?} is outside {}", self.url),
                }));
            }
            s if s >= 500 => {
                discard(&resp);
                let m = format!("server error {s} for {}", self.url);
                return Err(if first {
                    HttpError::Fatal(m)
                } else {
                    HttpError::Transient(m)
                });
            }
            s => {
                discard(&resp);
                return Err(fatal(format!(
                    "unexpected HTTP status {s} for {}",
                    self.url
                )));
            }
        }
        let Some((span, total)) = header("content-range")
            .as_deref()
            .and_then(parse_content_range)
        else {
            discard(&resp);
            return Err(fatal(format!(
                "206 without a readable Content-Range from {} (a cross-origin server must \
                 expose it: Access-Control-Expose-Headers: Content-Range)",
                self.url
            )));
        };
        let end = if first {
            range.end.min(total)
        } else {
            range.end
        };
        match span {
            Some((a, b)) if a == range.start && b + 1 == end => {}
            other => {
                discard(&resp);
                return Err(fatal(format!(
                    "asked {} for bytes {}-{}, got {other:?}",
                    self.url,
                    range.start,
                    end.saturating_sub(1)
                )));
            }
        }
        let buf = resp
            .array_buffer()
            .map_err(|e| HttpError::Transient(js_message(&e)))?;
        let buf = JsFuture::from(buf).await.map_err(|e| {
            HttpError::Transient(format!(
                "reading the body from {}: {}",
                self.url,
                js_message(&e)
            ))
        })?;
        let body = js_sys::Uint8Array::new(&buf).to_vec();
        self.bytes.set(self.bytes.get() + body.len() as u64);
        if body.len() as u64 != end - range.start {
            return Err(HttpError::Transient(format!(
                "body of {} bytes from {}, expected {}",
                body.len(),
                self.url,
                end - range.start
            )));
        }
        if first {
            self.len.set(total);
            *self.etag.borrow_mut() = etag;
        }
        Ok(body)
    }
}
