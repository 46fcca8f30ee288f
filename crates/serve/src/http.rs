//! Request handling: routing by name lookup, the model files (conditional and range
//! requests), the catalogue, CORS and the access log.

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use axum::body::Body;
use axum::extract::{Request, State as AxState};
use axum::http::{header, HeaderMap, HeaderValue, Method, Response, StatusCode};
use axum::middleware::Next;
use axum::Router;
use bytes::Bytes;
use tower_http::cors::{Any, CorsLayer};

use crate::body::{FileBody, Logged, Segment};
use crate::models::{open_model, open_regular, validate, Models};
use crate::range::{self, Ranges};

/// What every handler shares.
pub struct Shared {
    pub models: Models,
    pub request_timeout: Duration,
    /// The browser viewer served at `/`, if any.
    pub web: Web,
    /// 3D Tiles tilesets served at `/tiles/NAME/` (`tessera serve --tiles DIR`): each
    /// directory's name and canonical path.
    pub tiles: Vec<(String, std::path::PathBuf)>,
}

/// Where the static files served at `/` come from.
#[derive(Clone, Debug)]
pub enum Web {
    None,
    /// A directory (canonical path): `tessera serve --web DIR`.
    Dir(std::path::PathBuf),
    /// The viewer built into the binary: its files and their gzipped copies
    /// ([`crate::EMBEDDED_WEB`], [`crate::EMBEDDED_WEB_GZIP`]).
    Embedded(
        &'static [(&'static str, &'static [u8])],
        &'static [(&'static str, &'static [u8])],
    ),
}

impl Web {
    fn is_some(&self) -> bool {
        !matches!(self, Web::None)
    }
}

type St = Arc<Shared>;

/// The application: one fallback handler that dispatches on the raw path (so nothing
/// decodes or normalises it behind our back), CORS, and the access log outermost.
pub fn router(shared: St) -> Router {
    let cors = CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([Method::GET, Method::HEAD, Method::OPTIONS])
        .allow_headers([
            header::RANGE,
            header::IF_RANGE,
            header::IF_NONE_MATCH,
            header::IF_MODIFIED_SINCE,
            header::IF_MATCH,
            header::IF_UNMODIFIED_SINCE,
        ])
        .expose_headers([
            header::CONTENT_RANGE,
            header::CONTENT_LENGTH,
            header::ETAG,
            header::ACCEPT_RANGES,
            header::LAST_MODIFIED,
        ])
        .max_age(Duration::from_secs(86_400));
    Router::new()
        .fallback(dispatch)
        .with_state(shared)
        .layer(cors)
        .layer(axum::middleware::from_fn(allow_on_options))
        .layer(axum::middleware::from_fn(access_log))
}

/// The methods every resource here allows.
const ALLOW: &str = "GET, HEAD, OPTIONS";

/// tower-http's CORS layer answers every `OPTIONS` itself (as a preflight, `200`,
/// without `Allow`); RFC 9110 section 9.3.7 wants `Allow` on an `OPTIONS` answer.
async fn allow_on_options(req: Request, next: Next) -> Response<Body> {
    let options = req.method() == Method::OPTIONS;
    let mut resp = next.run(req).await;
    if options && !resp.headers().contains_key(header::ALLOW) {
        resp.headers_mut()
            .insert(header::ALLOW, HeaderValue::from_static(ALLOW));
    }
    resp
}

async fn access_log(req: Request, next: Next) -> Response<Body> {
    let start = Instant::now();
    let method = req.method().clone();
    let path: String = req.uri().path().chars().take(200).collect();
    let resp = next.run(req).await;
    let status = resp.status().as_u16();
    resp.map(|inner| {
        let done = http_body::Body::is_end_stream(&inner);
        Body::new(Logged {
            inner,
            method,
            path,
            status,
            start,
            sent: 0,
            done,
        })
    })
}

async fn dispatch(AxState(st): AxState<St>, req: Request) -> Response<Body> {
    // GET and HEAD requests have no body we would read.
    let (parts, _) = req.into_parts();
    let method = parts.method.clone();
    let path = parts.uri.path().to_string();
    let route = if path == "/api/models" {
        Route::Catalogue
    } else if let Some(rest) = path.strip_prefix("/models/") {
        Route::Model(rest.to_string())
    } else if let Some(rest) = path.strip_prefix("/tiles/") {
        Route::Tiles(rest.to_string())
    } else if path == "/" {
        Route::Root
    } else if st.web.is_some() {
        Route::Static(path.clone())
    } else {
        return text(StatusCode::NOT_FOUND, "not found\n");
    };
    if method == Method::OPTIONS {
        // Not a CORS preflight (the CORS layer answers those): say what is allowed.
        let mut r = empty(StatusCode::NO_CONTENT);
        r.headers_mut()
            .insert(header::ALLOW, HeaderValue::from_static(ALLOW));
        return r;
    }
    if method != Method::GET && method != Method::HEAD {
        let mut r = text(
            StatusCode::METHOD_NOT_ALLOWED,
            "only GET, HEAD and OPTIONS\n",
        );
        r.headers_mut()
            .insert(header::ALLOW, HeaderValue::from_static(ALLOW));
        return r;
    }
    let head = method == Method::HEAD;
    let work = async {
        match route {
            Route::Root if st.web.is_some() => {
                static_file(&st, &parts.headers, "/index.html").await
            }
            Route::Root => text(
                StatusCode::OK,
                "tessera serve: the model catalogue is at /api/models; no viewer page is \
                 served here (`--web DIR` serves one, as does a tessera built after \
                 scripts/build-web)\n",
            ),
            Route::Static(p) => static_file(&st, &parts.headers, &p).await,
            Route::Tiles(p) => tiles_file(&st, &parts.headers, &p).await,
            Route::Catalogue => catalogue(&st).await,
            Route::Model(raw) => model(&st, &parts.headers, &raw, head).await,
        }
    };
    let mut resp = match tokio::time::timeout(st.request_timeout, work).await {
        Ok(r) => r,
        Err(_) => text(StatusCode::SERVICE_UNAVAILABLE, "timed out\n"),
    };
    if head {
        // Same headers, no body (Content-Length stays the GET's).
        *resp.body_mut() = Body::empty();
    }
    resp
}

enum Route {
    Root,
    Catalogue,
    Model(String),
    Static(String),
    Tiles(String),
}

/// The content type of a static file of the web directory, by extension.
fn content_type(name: &str) -> &'static str {
    match name
        .rsplit_once('.')
        .map(|(_, e)| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("html") | Some("htm") => "text/html; charset=utf-8",
        Some("js") | Some("mjs") => "text/javascript; charset=utf-8",
        Some("wasm") => "application/wasm",
        Some("json") => "application/json",
        Some("css") => "text/css; charset=utf-8",
        Some("png") => "image/png",
        Some("jpg") | Some("jpeg") => "image/jpeg",
        Some("glb") => "model/gltf-binary",
        Some("gltf") => "model/gltf+json",
        Some("svg") => "image/svg+xml",
        Some("txt") | Some("md") => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    }
}

/// Whether an `Accept-Encoding` header accepts gzip (`gzip` or `*`, not at `q=0`).
pub fn accepts_gzip(headers: &HeaderMap) -> bool {
    let mut gzip = None;
    let mut star = None;
    for v in headers.get_all(header::ACCEPT_ENCODING) {
        let Ok(v) = v.to_str() else { continue };
        for item in v.split(',') {
            let mut parts = item.split(';');
            let coding = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let q = parts
                .filter_map(|p| p.trim().strip_prefix("q="))
                .find_map(|q| q.trim().parse::<f32>().ok())
                .unwrap_or(1.0);
            match coding.as_str() {
                "gzip" | "x-gzip" => gzip = Some(q > 0.0),
                "*" => star = Some(q > 0.0),
                _ => {}
            }
        }
    }
    gzip.or(star).unwrap_or(false)
}

/// A file of the web directory: every segment of `path` percent-decoded and checked
/// like a model name (no separators, control characters or leading dots), the result
/// resolved inside the directory (symbolic links out of it are not followed), read
/// whole (the viewer's files are small); or the embedded file of that name. To a
/// client that accepts gzip, its gzipped copy (`NAME.gz`, which `scripts/build-web`
/// writes beside the files that compress; in a directory only when at least as new
/// as the file) with `Content-Encoding: gzip`.
async fn static_file(st: &St, headers: &HeaderMap, path: &str) -> Response<Body> {
    let Some(rel) = relative_path(path) else {
        return text(StatusCode::NOT_FOUND, "not found\n");
    };
    let name = rel.to_string_lossy().into_owned();
    let gzip = accepts_gzip(headers);
    // (The body, whether it is the gzipped copy.)
    let read: Option<(bytes::Bytes, bool)> = match &st.web {
        Web::None => None,
        Web::Embedded(files, gzipped) => {
            let find = |list: &'static [(&'static str, &'static [u8])]| {
                list.iter()
                    .find(|(n, _)| *n == name)
                    .map(|(_, b)| bytes::Bytes::from_static(b))
            };
            find(files).map(|raw| match find(gzipped) {
                Some(gz) if gzip => (gz, true),
                _ => (raw, false),
            })
        }
        Web::Dir(root) => dir_file(root.clone(), rel, gzip).await,
    };
    file_response(&name, read)
}

/// A file of a served tileset: `/tiles/NAME/PATH` is `PATH` under the tileset
/// directory named `NAME`, checked and resolved as the web directory's files are.
async fn tiles_file(st: &St, headers: &HeaderMap, path: &str) -> Response<Body> {
    let (tileset, rest) = path.split_once('/').unwrap_or((path, ""));
    let root = decode_name(tileset).and_then(|n| {
        st.tiles
            .iter()
            .find(|(name, _)| *name == n)
            .map(|(_, r)| r.clone())
    });
    let (Some(root), Some(rel)) = (root, relative_path(rest)) else {
        return text(StatusCode::NOT_FOUND, "not found\n");
    };
    let name = rel.to_string_lossy().into_owned();
    let read = dir_file(root, rel, accepts_gzip(headers)).await;
    file_response(&name, read)
}

/// Every segment of `path` percent-decoded and checked like a model name (no
/// separators, control characters or leading dots).
fn relative_path(path: &str) -> Option<std::path::PathBuf> {
    let mut rel = std::path::PathBuf::new();
    for seg in path.trim_start_matches('/').split('/') {
        rel.push(decode_name(seg)?);
    }
    Some(rel)
}

/// The file `rel` under the directory `root` (canonical), resolved inside it only
/// (symbolic links out of it are not followed), read whole; its gzipped copy instead
/// (`NAME.gz`, when at least as new) to a client that accepts gzip.
async fn dir_file(
    root: std::path::PathBuf,
    rel: std::path::PathBuf,
    gzip: bool,
) -> Option<(bytes::Bytes, bool)> {
    tokio::task::spawn_blocking(move || {
        let p = std::fs::canonicalize(root.join(&rel)).ok()?;
        if !p.starts_with(&root) {
            return None;
        }
        // A FIFO or device in the directory is refused, never opened blocking.
        let read = |p: &std::path::Path| -> Option<Vec<u8>> {
            let mut f = open_regular(p, true).ok()?;
            let mut b = Vec::new();
            std::io::Read::read_to_end(&mut f, &mut b).ok()?;
            Some(b)
        };
        if gzip {
            let mut gz = p.clone().into_os_string();
            gz.push(".gz");
            let gz = std::path::PathBuf::from(gz);
            let modified =
                |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
            let fresh = modified(&gz).zip(modified(&p)).is_some_and(|(g, f)| g >= f);
            let inside = std::fs::canonicalize(&gz)
                .ok()
                .filter(|g| g.starts_with(&root));
            if let (true, Some(gz)) = (fresh, inside) {
                if let Some(b) = read(&gz) {
                    return Some((bytes::Bytes::from(b), true));
                }
            }
        }
        read(&p).map(|b| (bytes::Bytes::from(b), false))
    })
    .await
    .ok()
    .flatten()
}

/// The answer for a static file named `name` (its content type by extension), or 404.
fn file_response(name: &str, read: Option<(bytes::Bytes, bool)>) -> Response<Body> {
    let Some((body, gzipped)) = read else {
        return text(StatusCode::NOT_FOUND, "not found\n");
    };
    let n = body.len();
    let mut r = Response::new(Body::from(body));
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(content_type(name)),
    );
    if gzipped {
        h.insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
    }
    // The body depends on the request's Accept-Encoding (for caches).
    h.insert(header::VARY, HeaderValue::from_static("accept-encoding"));
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(n));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r
}

fn text(status: StatusCode, msg: &'static str) -> Response<Body> {
    let mut r = Response::new(Body::from(msg));
    *r.status_mut() = status;
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    r.headers_mut()
        .insert(header::CONTENT_LENGTH, HeaderValue::from(msg.len()));
    r
}

fn empty(status: StatusCode) -> Response<Body> {
    let mut r = Response::new(Body::empty());
    *r.status_mut() = status;
    r
}

/// Percent-decodes one path segment; `None` for bad escapes, invalid UTF-8, or a result
/// that could never be a served name (separators, NUL and other control characters).
pub fn decode_name(raw: &str) -> Option<String> {
    let b = raw.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b.get(i + 1..i + 3)?;
            let h = std::str::from_utf8(hex).ok()?;
            out.push(u8::from_str_radix(h, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    let s = String::from_utf8(out).ok()?;
    crate::models::servable_name(&s).then_some(s)
}

/// Percent-encodes a name for a URL path segment (everything but unreserved bytes).
pub fn encode_name(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

async fn catalogue(st: &St) -> Response<Body> {
    let st2 = st.clone();
    // New builds in a served directory appear here without a restart: a stat of each
    // input, a rescan only when one changed, the body rebuilt only when the set did.
    let body = tokio::task::spawn_blocking(move || {
        st2.models.refresh();
        st2.models.catalogue_json(catalogue_body)
    })
    .await
    .unwrap_or_else(|_| Bytes::from_static(b"{\"models\": []}\n"));
    let n = body.len();
    let mut r = Response::new(Body::from(body));
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(n));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r
}

/// The catalogue's JSON for a served set.
fn catalogue_body(set: &std::collections::BTreeMap<String, crate::models::Entry>) -> Vec<u8> {
    let models: Vec<serde_json::Value> = set
        .iter()
        .map(|(file, e)| {
            let i = &e.info;
            let name = file.strip_suffix(".tsr").unwrap_or(file).to_string();
            serde_json::json!({
                "name": name,
                "url": format!("/models/{}", encode_name(file)),
                "bytes": i.identity.size(),
                "triangles": i.triangles,
                "bounding_sphere": {
                    "center": [i.bounding_sphere[0], i.bounding_sphere[1], i.bounding_sphere[2]],
                    "radius": i.bounding_sphere[3],
                },
                "format_version": i.format_version,
                "nodes": i.nodes,
                "etag": i.identity.etag(),
            })
        })
        .collect();
    let mut body =
        serde_json::to_vec_pretty(&serde_json::json!({ "models": models })).unwrap_or_default();
    body.push(b'\n');
    body
}

/// An entity-tag list (`If-Match`, `If-None-Match`): `Any` for `*`.
enum Tags {
    Any,
    List(Vec<(bool, String)>),
}

fn tags(headers: &HeaderMap, name: header::HeaderName) -> Option<Tags> {
    let mut list = Vec::new();
    let mut seen = false;
    for v in headers.get_all(name) {
        seen = true;
        let Ok(s) = v.to_str() else { continue };
        if s.trim() == "*" {
            return Some(Tags::Any);
        }
        let mut rest = s;
        loop {
            rest = rest.trim_start_matches([' ', '\t', ',']);
            if rest.is_empty() {
                break;
            }
            let weak = rest.starts_with("W/");
            if weak {
                rest = &rest[2..];
            }
            let Some(r) = rest.strip_prefix('"') else {
                break;
            };
            let Some(end) = r.find('"') else { break };
            list.push((weak, format!("\"{}\"", &r[..end])));
            rest = &r[end + 1..];
        }
    }
    seen.then_some(Tags::List(list))
}

fn date(headers: &HeaderMap, name: header::HeaderName) -> Option<SystemTime> {
    httpdate::parse_http_date(headers.get(name)?.to_str().ok()?).ok()
}

async fn model(st: &St, headers: &HeaderMap, raw: &str, head: bool) -> Response<Body> {
    let Some(name) = decode_name(raw) else {
        return text(StatusCode::BAD_REQUEST, "bad model name\n");
    };
    let Some(entry) = st.models.lookup(&name) else {
        return text(StatusCode::NOT_FOUND, "no such model\n");
    };
    // Open once; stat and validate that descriptor; every byte sent comes from it.
    let known = entry.info.clone();
    let path = entry.path.clone();
    let opened = tokio::task::spawn_blocking(move || {
        let f = open_model(&path, entry.from_dir).map_err(|e| (true, e.to_string()))?;
        let info = validate(&f, Some(&entry.info)).map_err(|e| (false, e))?;
        Ok::<_, (bool, String)>((f, info))
    })
    .await;
    let (file, info) = match opened {
        Ok(Ok(x)) => x,
        Ok(Err((_, why))) => {
            st.models.warn_once(&format!(
                "{}: not served: {why}",
                entry_path(&st.models, &name)
            ));
            return text(StatusCode::NOT_FOUND, "no such model\n");
        }
        Err(_) => return text(StatusCode::INTERNAL_SERVER_ERROR, "internal error\n"),
    };
    if info.identity != known.identity {
        st.models.update(&name, info.clone());
    }
    let len = info.identity.size();
    let etag = info.identity.etag();
    let modified = info.identity.modified();

    let mut base = HeaderMap::new();
    base.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    if let Ok(v) = HeaderValue::from_str(&etag) {
        base.insert(header::ETAG, v);
    }
    if let Ok(v) = HeaderValue::from_str(&httpdate::fmt_http_date(modified)) {
        base.insert(header::LAST_MODIFIED, v);
    }
    // Models are replaced by new builds: caches must revalidate (cheap: 304).
    base.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    base.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    let respond = |status: StatusCode, extra: &[(header::HeaderName, HeaderValue)], body: Body| {
        let mut r = Response::new(body);
        *r.status_mut() = status;
        r.headers_mut().extend(base.clone());
        for (k, v) in extra {
            r.headers_mut().insert(k.clone(), v.clone());
        }
        r
    };

    // Preconditions, in RFC 9110 section 13.2.2's order.
    match tags(headers, header::IF_MATCH) {
        Some(Tags::Any) => {}
        Some(Tags::List(l)) => {
            if !l.iter().any(|(weak, t)| !weak && *t == etag) {
                return respond(StatusCode::PRECONDITION_FAILED, &[], Body::empty());
            }
        }
        None => {
            if let Some(d) = date(headers, header::IF_UNMODIFIED_SINCE) {
                if modified > d {
                    return respond(StatusCode::PRECONDITION_FAILED, &[], Body::empty());
                }
            }
        }
    }
    match tags(headers, header::IF_NONE_MATCH) {
        Some(Tags::Any) => return respond(StatusCode::NOT_MODIFIED, &[], Body::empty()),
        Some(Tags::List(l)) => {
            // Weak comparison.
            if l.iter().any(|(_, t)| *t == etag) {
                return respond(StatusCode::NOT_MODIFIED, &[], Body::empty());
            }
        }
        None => {
            if let Some(d) = date(headers, header::IF_MODIFIED_SINCE) {
                if modified <= d {
                    return respond(StatusCode::NOT_MODIFIED, &[], Body::empty());
                }
            }
        }
    }

    let octets = (
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    // Range applies to GET only (RFC 9110 14.2); a HEAD gets the full 200's headers.
    let ranges = match headers.get(header::RANGE).and_then(|v| v.to_str().ok()) {
        Some(v) if !head && if_range_holds(headers, &etag, modified) => range::parse(v, len),
        _ => Ranges::Ignore,
    };
    match ranges {
        Ranges::Ignore => {
            let body = FileBody::new(file, vec![Segment::File { offset: 0, len }]);
            respond(
                StatusCode::OK,
                &[octets, (header::CONTENT_LENGTH, HeaderValue::from(len))],
                Body::new(body),
            )
        }
        Ranges::Unsatisfiable | Ranges::TooMany => {
            let cr = HeaderValue::from_str(&format!("bytes */{len}"))
                .unwrap_or(HeaderValue::from_static("bytes */0"));
            respond(
                StatusCode::RANGE_NOT_SATISFIABLE,
                &[
                    (header::CONTENT_RANGE, cr),
                    (header::CONTENT_LENGTH, HeaderValue::from(0)),
                ],
                Body::empty(),
            )
        }
        Ranges::Satisfiable(rs) if rs.len() == 1 => {
            let r = rs[0].clone();
            let cr = format!("bytes {}-{}/{len}", r.start, r.end - 1);
            let body = FileBody::new(
                file,
                vec![Segment::File {
                    offset: r.start,
                    len: r.end - r.start,
                }],
            );
            respond(
                StatusCode::PARTIAL_CONTENT,
                &[
                    octets,
                    (header::CONTENT_LENGTH, HeaderValue::from(r.end - r.start)),
                    (
                        header::CONTENT_RANGE,
                        HeaderValue::from_str(&cr).unwrap_or(HeaderValue::from_static("")),
                    ),
                ],
                Body::new(body),
            )
        }
        Ranges::Satisfiable(rs) => {
            let boundary = boundary(&etag);
            let mut segs = Vec::with_capacity(rs.len() * 2 + 1);
            for r in &rs {
                segs.push(Segment::Bytes(Bytes::from(format!(
                    "\r\n--{boundary}\r\nContent-Type: application/octet-stream\r\nContent-Range: bytes {}-{}/{len}\r\n\r\n",
                    r.start,
                    r.end - 1
                ))));
                segs.push(Segment::File {
                    offset: r.start,
                    len: r.end - r.start,
                });
            }
            segs.push(Segment::Bytes(Bytes::from(format!(
                "\r\n--{boundary}--\r\n"
            ))));
            let body = FileBody::new(file, segs);
            let ct = format!("multipart/byteranges; boundary={boundary}");
            respond(
                StatusCode::PARTIAL_CONTENT,
                &[
                    (
                        header::CONTENT_TYPE,
                        HeaderValue::from_str(&ct)
                            .unwrap_or(HeaderValue::from_static("multipart/byteranges")),
                    ),
                    (header::CONTENT_LENGTH, HeaderValue::from(body.len())),
                ],
                Body::new(body),
            )
        }
    }
}

/// `If-Range`: the range is served only if the validator names the current file: a
/// strong ETag equal to ours, or a date equal to our `Last-Modified`. Absent: true.
fn if_range_holds(headers: &HeaderMap, etag: &str, modified: SystemTime) -> bool {
    let Some(v) = headers.get(header::IF_RANGE) else {
        return true;
    };
    let Ok(v) = v.to_str() else { return false };
    let v = v.trim();
    if v.starts_with('"') || v.starts_with("W/") {
        return v == etag; // weak tags never match (strong comparison)
    }
    httpdate::parse_http_date(v).is_ok_and(|d| d == modified)
}

/// A multipart boundary unlikely to occur in the data (70 characters at most).
fn boundary(etag: &str) -> String {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    etag.hash(&mut h);
    SystemTime::now().hash(&mut h);
    std::thread::current().id().hash(&mut h);
    let a = h.finish();
    a.hash(&mut h);
    format!("tessera-{:016x}{:016x}", a, h.finish())
}

fn entry_path(models: &Models, name: &str) -> String {
    models
        .lookup(name)
        .map(|e| e.path.display().to_string())
        .unwrap_or_else(|| name.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_encoding() {
        let h = |v: &str| {
            let mut m = HeaderMap::new();
            m.insert(header::ACCEPT_ENCODING, HeaderValue::from_str(v).unwrap());
            accepts_gzip(&m)
        };
        assert!(h("gzip"));
        assert!(h("gzip, deflate, br, zstd"));
        assert!(h("br;q=1.0, GZIP;q=0.5"));
        assert!(h("*"));
        assert!(h("x-gzip"));
        assert!(!h("gzip;q=0"));
        assert!(!h("gzip;q=0.0, *"));
        assert!(!h("*;q=0"));
        assert!(!h("identity"));
        assert!(!h("br, deflate"));
        assert!(!accepts_gzip(&HeaderMap::new()));
    }
}
