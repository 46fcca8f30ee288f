//! A real `tessera serve` on 127.0.0.1 (port 0) with real clients: ureq for ordinary
//! requests, raw TCP for the hostile ones clients refuse to send.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use tessera_serve::{ServeError, ServeOptions};

mod common;
use common::{built, TestServer};

// ---------------------------------------------------------------- models

fn model_a() -> &'static [u8] {
    static M: OnceLock<Vec<u8>> = OnceLock::new();
    M.get_or_init(|| built(7, 20_000))
}

fn model_b() -> &'static [u8] {
    static M: OnceLock<Vec<u8>> = OnceLock::new();
    M.get_or_init(|| built(11, 12_000))
}

/// Writes `bytes` atomically (temporary file, rename), as the builder does.
fn replace(path: &Path, bytes: &[u8]) {
    let tmp = path.with_file_name(format!(
        ".{}.tmp-test",
        path.file_name().unwrap().to_str().unwrap()
    ));
    std::fs::write(&tmp, bytes).unwrap();
    std::fs::rename(&tmp, path).unwrap();
}

// ---------------------------------------------------------------- server

fn opts() -> ServeOptions {
    ServeOptions {
        addr: "127.0.0.1:0".parse().unwrap(),
        ..ServeOptions::default()
    }
}

/// A served directory holding `a.tsr` (model A); returns (tempdir, served dir).
fn served_dir() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("served");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("a.tsr"), model_a()).unwrap();
    (tmp, dir)
}

// ---------------------------------------------------------------- clients

fn agent() -> ureq::Agent {
    ureq::Agent::new_with_config(
        ureq::Agent::config_builder()
            .http_status_as_error(false)
            .max_redirects(0)
            .timeout_global(Some(Duration::from_secs(20)))
            .build(),
    )
}

struct Resp {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Resp {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

fn get(url: &str, headers: &[(&str, &str)]) -> Resp {
    let mut req = agent().get(url);
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    let mut r = req.call().unwrap();
    let status = r.status().as_u16();
    let hs = r
        .headers()
        .iter()
        .map(|(k, v)| (k.as_str().to_string(), v.to_str().unwrap_or("").to_string()))
        .collect();
    let body = r
        .body_mut()
        .with_config()
        .limit(1 << 30)
        .read_to_vec()
        .unwrap();
    Resp {
        status,
        headers: hs,
        body,
    }
}

/// Sends `request` as is on a fresh connection and reads the answer to EOF (send
/// `Connection: close`). `None` if the server closed without answering.
fn raw(addr: SocketAddr, request: &[u8]) -> Option<Resp> {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    s.write_all(request).unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    parse_response(&buf)
}

fn parse_response(buf: &[u8]) -> Option<Resp> {
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&buf[..end]).unwrap();
    let mut lines = head.split("\r\n");
    let status: u16 = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect();
    Some(Resp {
        status,
        headers,
        body: buf[end + 4..].to_vec(),
    })
}

fn get_raw(addr: SocketAddr, target: &str) -> Option<Resp> {
    raw(
        addr,
        format!("GET {target} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").as_bytes(),
    )
}

fn catalogue(s: &TestServer) -> serde_json::Value {
    serde_json::from_slice(&get(&s.url("/api/models"), &[]).body).unwrap()
}

fn model_names(catalogue: &serde_json::Value) -> Vec<String> {
    let models = catalogue["models"].as_array().unwrap();
    models
        .iter()
        .map(|m| m["name"].as_str().unwrap().to_string())
        .collect()
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

// ---------------------------------------------------------------- tests

#[test]
fn random_ranges_match_the_file() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let file = model_a();
    let len = file.len() as u64;
    let url = s.url("/models/a.tsr");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let agent = agent();
    for i in 0..300 {
        let a = rng.next() % len;
        let b = if i % 3 == 0 {
            a + rng.next() % 64
        } else {
            a + rng.next() % (len - a)
        };
        let mut r = agent
            .get(&url)
            .header("Range", format!("bytes={a}-{b}"))
            .call()
            .unwrap();
        assert_eq!(r.status(), 206);
        let end = (b + 1).min(len);
        assert_eq!(
            r.headers()["content-range"].to_str().unwrap(),
            format!("bytes {a}-{}/{len}", end - 1)
        );
        assert_eq!(
            r.headers()["content-length"].to_str().unwrap(),
            (end - a).to_string()
        );
        assert!(r.headers().get("content-encoding").is_none());
        let body = r.body_mut().read_to_vec().unwrap();
        assert!(body == file[a as usize..end as usize], "range {a}-{b}");
    }
    // The whole file.
    let r = get(&url, &[]);
    assert_eq!(r.status, 200);
    assert_eq!(r.header("accept-ranges"), Some("bytes"));
    assert_eq!(r.header("content-type"), Some("application/octet-stream"));
    assert!(r.body == file);
}

#[test]
fn range_forms() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let file = model_a();
    let len = file.len();
    let url = s.url("/models/a.tsr");
    // Suffix.
    let r = get(&url, &[("Range", "bytes=-100")]);
    assert_eq!(r.status, 206);
    assert_eq!(
        r.header("content-range").unwrap(),
        format!("bytes {}-{}/{len}", len - 100, len - 1)
    );
    assert!(r.body == file[len - 100..]);
    // Suffix longer than the file: the whole file, as a 206.
    let r = get(&url, &[("Range", &format!("bytes=-{}", len * 2))]);
    assert_eq!(r.status, 206);
    assert!(r.body == file);
    // Open-ended.
    let r = get(&url, &[("Range", "bytes=1000-")]);
    assert_eq!(r.status, 206);
    assert_eq!(
        r.header("content-range").unwrap(),
        format!("bytes 1000-{}/{len}", len - 1)
    );
    assert!(r.body == file[1000..]);
    // Last byte past the end is clamped.
    let r = get(
        &url,
        &[("Range", &format!("bytes={}-{}", len - 5, len + 1000))],
    );
    assert_eq!(r.status, 206);
    assert!(r.body == file[len - 5..]);
    // Unsatisfiable.
    for spec in [
        format!("bytes={len}-"),
        format!("bytes={}-{}", len + 10, len + 20),
        "bytes=-0".into(),
    ] {
        let r = get(&url, &[("Range", &spec)]);
        assert_eq!(r.status, 416, "{spec}");
        assert_eq!(
            r.header("content-range").unwrap(),
            format!("bytes */{len}"),
            "{spec}"
        );
        assert!(r.body.is_empty());
    }
    // Malformed or another unit: ignored, the whole file.
    for spec in [
        "bytes=9-5",
        "bytes=abc",
        "bytes=",
        "items=0-10",
        "bytes 0-10",
        "bytes=0-10;",
        "bytes=--5",
        "bytes=1-2-3",
    ] {
        let r = get(&url, &[("Range", spec)]);
        assert_eq!(r.status, 200, "{spec}");
        assert!(r.body == file, "{spec}");
    }
    // Overlapping ranges merge into one plain 206.
    let r = get(&url, &[("Range", "bytes=0-99,50-199,200-299")]);
    assert_eq!(r.status, 206);
    assert_eq!(
        r.header("content-range").unwrap(),
        format!("bytes 0-299/{len}")
    );
    assert!(r.body == file[..300]);
    // Multi-range: multipart/byteranges, parts in ascending order.
    let r = get(&url, &[("Range", "bytes=500-599, 0-9, -20")]);
    assert_eq!(r.status, 206);
    let ct = r.header("content-type").unwrap().to_string();
    let boundary = ct
        .strip_prefix("multipart/byteranges; boundary=")
        .expect(&ct);
    assert_eq!(
        r.header("content-length").unwrap(),
        r.body.len().to_string()
    );
    let parts = parse_multipart(&r.body, boundary);
    let want = [(0usize, 10usize), (500, 600), (len - 20, len)];
    assert_eq!(parts.len(), 3);
    for ((cr, data), (a, b)) in parts.iter().zip(want) {
        assert_eq!(*cr, format!("bytes {a}-{}/{len}", b - 1));
        assert!(data[..] == file[a..b]);
    }
    // An unsatisfiable part among satisfiable ones is dropped.
    let r = get(&url, &[("Range", &format!("bytes=0-9,{}-", len + 5))]);
    assert_eq!(r.status, 206);
    assert!(r.body == file[..10]);
    // Too many parts: refused with 416.
    let many: Vec<String> = (0..100)
        .map(|i| format!("{}-{}", i * 100, i * 100 + 1))
        .collect();
    let r = get(&url, &[("Range", &format!("bytes={}", many.join(",")))]);
    assert_eq!(r.status, 416);
    assert_eq!(r.header("content-range").unwrap(), format!("bytes */{len}"));
    // HEAD ignores Range and sends the 200's headers, no body.
    let r = raw(
        s.addr,
        b"HEAD /models/a.tsr HTTP/1.1\r\nHost: x\r\nRange: bytes=0-9\r\nConnection: close\r\n\r\n",
    )
    .unwrap();
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-length").unwrap(), len.to_string());
    assert_eq!(r.header("accept-ranges").unwrap(), "bytes");
    assert!(r.header("etag").is_some() && r.header("last-modified").is_some());
    assert!(r.body.is_empty());
    // Even a client that asks for gzip gets identity bytes for a range.
    let r = get(
        &url,
        &[("Range", "bytes=0-99"), ("Accept-Encoding", "gzip, br")],
    );
    assert_eq!(r.status, 206);
    assert!(r.header("content-encoding").is_none());
    assert!(r.body == file[..100]);
}

fn parse_multipart(body: &[u8], boundary: &str) -> Vec<(String, Vec<u8>)> {
    let delim = format!("\r\n--{boundary}");
    let d = delim.as_bytes();
    let mut cuts = Vec::new();
    let mut i = 0;
    while i + d.len() <= body.len() {
        if &body[i..i + d.len()] == d {
            cuts.push(i);
            i += d.len();
        } else {
            i += 1;
        }
    }
    assert!(body.ends_with(format!("{delim}--\r\n").as_bytes()));
    let mut parts = Vec::new();
    for w in cuts.windows(2) {
        let part = &body[w[0] + d.len() + 2..w[1]];
        let end = part.windows(4).position(|x| x == b"\r\n\r\n").unwrap();
        let head = std::str::from_utf8(&part[..end]).unwrap();
        let cr = head
            .split("\r\n")
            .find_map(|l| l.strip_prefix("Content-Range: "))
            .unwrap()
            .to_string();
        assert!(head.contains("Content-Type: application/octet-stream"));
        parts.push((cr, part[end + 4..].to_vec()));
    }
    parts
}

#[test]
fn validators_and_conditionals() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let file = model_a();
    let url = s.url("/models/a.tsr");
    let r = get(&url, &[("Range", "bytes=0-9")]);
    let etag = r.header("etag").unwrap().to_string();
    let lm = r.header("last-modified").unwrap().to_string();
    assert!(etag.starts_with('"') && etag.ends_with('"') && !etag.starts_with("W/"));
    assert!(httpdate::parse_http_date(&lm).is_ok() || lm.ends_with("GMT"));
    // Stable across requests.
    assert_eq!(get(&url, &[]).header("etag").unwrap(), etag);
    // 304s.
    let r = get(&url, &[("If-None-Match", &etag)]);
    assert_eq!(r.status, 304);
    assert!(r.body.is_empty());
    assert_eq!(r.header("etag").unwrap(), etag);
    assert_eq!(
        get(&url, &[("If-None-Match", &format!("\"x\", W/{etag}"))]).status,
        304
    );
    assert_eq!(get(&url, &[("If-None-Match", "*")]).status, 304);
    assert_eq!(get(&url, &[("If-None-Match", "\"other\"")]).status, 200);
    assert_eq!(get(&url, &[("If-Modified-Since", &lm)]).status, 304);
    assert_eq!(
        get(
            &url,
            &[("If-Modified-Since", "Mon, 01 Jan 1990 00:00:00 GMT")]
        )
        .status,
        200
    );
    // If-Range: current strong tag -> 206; stale tag, weak tag, old date -> 200 whole file.
    let r = get(&url, &[("Range", "bytes=10-19"), ("If-Range", &etag)]);
    assert_eq!(r.status, 206);
    assert!(r.body == file[10..20]);
    let r = get(&url, &[("Range", "bytes=10-19"), ("If-Range", &lm)]);
    assert_eq!(r.status, 206);
    for stale in [
        "\"stale\"".to_string(),
        format!("W/{etag}"),
        "Mon, 01 Jan 1990 00:00:00 GMT".into(),
        "garbage".into(),
    ] {
        let r = get(&url, &[("Range", "bytes=10-19"), ("If-Range", &stale)]);
        assert_eq!(r.status, 200, "{stale}");
        assert!(r.body == file, "{stale}");
    }
    // If-Match: a clean mismatch.
    assert_eq!(
        get(&url, &[("If-Match", "\"stale\""), ("Range", "bytes=0-9")]).status,
        412
    );
    assert_eq!(
        get(&url, &[("If-Match", &etag), ("Range", "bytes=0-9")]).status,
        206
    );
    assert_eq!(
        get(
            &url,
            &[("If-Unmodified-Since", "Mon, 01 Jan 1990 00:00:00 GMT")]
        )
        .status,
        412
    );
}

#[test]
fn cors() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let r = raw(
        s.addr,
        b"OPTIONS /models/a.tsr HTTP/1.1\r\nHost: x\r\nOrigin: https://example.org\r\nAccess-Control-Request-Method: GET\r\nAccess-Control-Request-Headers: range, if-range\r\nConnection: close\r\n\r\n",
    )
    .unwrap();
    assert!(r.status == 200 || r.status == 204, "{}", r.status);
    assert_eq!(r.header("access-control-allow-origin"), Some("*"));
    let methods = r
        .header("access-control-allow-methods")
        .unwrap()
        .to_ascii_uppercase();
    for m in ["GET", "HEAD", "OPTIONS"] {
        assert!(methods.contains(m), "{methods}");
    }
    let allowed = r
        .header("access-control-allow-headers")
        .unwrap()
        .to_ascii_lowercase();
    assert!(
        allowed.contains("range") && allowed.contains("if-range"),
        "{allowed}"
    );
    let r = get(
        &s.url("/models/a.tsr"),
        &[("Origin", "https://example.org"), ("Range", "bytes=0-3")],
    );
    assert_eq!(r.status, 206);
    assert_eq!(r.header("access-control-allow-origin"), Some("*"));
    let exposed = r
        .header("access-control-expose-headers")
        .unwrap()
        .to_ascii_lowercase();
    for h in ["content-range", "content-length", "etag", "accept-ranges"] {
        assert!(exposed.contains(h), "{exposed}");
    }
    let r = get(&s.url("/api/models"), &[("Origin", "https://example.org")]);
    assert_eq!(r.header("access-control-allow-origin"), Some("*"));
}

#[test]
fn catalogue_lists_valid_models_and_skips_others() {
    let (tmp, dir) = served_dir();
    std::fs::write(dir.join("b.tsr"), model_b()).unwrap();
    std::fs::write(dir.join("junk.tsr"), b"this is not a model").unwrap();
    std::fs::write(dir.join("truncated.tsr"), &model_a()[..1000]).unwrap();
    std::fs::write(dir.join(".hidden.tsr"), model_a()).unwrap();
    std::fs::write(dir.join("notes.txt"), b"hello").unwrap();
    let single = tmp.path().join("single.tsr");
    std::fs::write(&single, model_b()).unwrap();
    let s = TestServer::start(&[dir.clone(), single], opts()).unwrap();
    let r = get(&s.url("/api/models"), &[]);
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), Some("application/json"));
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    let models = v["models"].as_array().unwrap();
    let names = model_names(&v);
    assert_eq!(names, ["a", "b", "single"]);
    let a = &models[0];
    let h = tessera_format::ModelIndex::parse_header(model_a(), model_a().len() as u64).unwrap();
    assert_eq!(a["url"], "/models/a.tsr");
    assert_eq!(a["bytes"], model_a().len() as u64);
    assert_eq!(a["triangles"], h.input_triangles);
    assert_eq!(a["nodes"], h.node_count);
    assert_eq!(a["format_version"], h.version);
    assert_eq!(a["bounding_sphere"]["radius"], h.bounding_sphere[3]);
    assert_eq!(a["bounding_sphere"]["center"][0], h.bounding_sphere[0]);
    assert!(h.input_triangles > 10_000);
    // Every url works; skipped files are not served.
    for m in models {
        let r = get(
            &s.url(m["url"].as_str().unwrap()),
            &[("Range", "bytes=0-7")],
        );
        assert_eq!(r.status, 206);
        assert_eq!(&r.body[..], &model_a()[..8]);
    }
    for bad in ["junk.tsr", "truncated.tsr", ".hidden.tsr", "notes.txt"] {
        assert_eq!(
            get(&s.url(&format!("/models/{bad}")), &[]).status / 100,
            4,
            "{bad}"
        );
    }
    // A new build appears without a restart; a removed one disappears.
    std::fs::write(dir.join("c.tsr"), model_b()).unwrap();
    std::fs::remove_file(dir.join("b.tsr")).unwrap();
    let names = model_names(&catalogue(&s));
    assert_eq!(names, ["a", "c", "single"]);
    assert_eq!(get(&s.url("/models/c.tsr"), &[]).status, 200);
    assert_eq!(get(&s.url("/models/b.tsr"), &[]).status, 404);
}

/// The error a start with these inputs fails with (panics if it starts).
fn start_error(inputs: &[PathBuf], o: ServeOptions) -> ServeError {
    match TestServer::start(inputs, o) {
        Err(e) => e,
        Ok(_) => panic!("started with {inputs:?}"),
    }
}

#[test]
fn start_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let junk = tmp.path().join("junk.tsr");
    std::fs::write(&junk, b"not a model").unwrap();
    let e = start_error(&[junk], opts());
    let msg = e.to_string();
    assert!(matches!(e, ServeError::NoModels { .. }), "{msg}");
    assert!(
        msg.contains("junk.tsr") && msg.contains("not a valid model"),
        "{msg}"
    );
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert!(matches!(
        start_error(&[empty], opts()),
        ServeError::NoModels { .. }
    ));
    let missing = tmp.path().join("missing.tsr");
    assert!(matches!(
        start_error(&[missing], opts()),
        ServeError::Input { .. }
    ));
    // Address in use.
    let good = tmp.path().join("good.tsr");
    std::fs::write(&good, model_a()).unwrap();
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let o = ServeOptions {
        addr: busy.local_addr().unwrap(),
        ..ServeOptions::default()
    };
    let e = start_error(std::slice::from_ref(&good), o);
    let msg = e.to_string();
    assert!(matches!(e, ServeError::AddrInUse { .. }), "{msg}");
    assert!(
        msg.contains("already in use") && msg.contains("--addr 127.0.0.1:0"),
        "{msg}"
    );
    // Two models with one name.
    let other = tmp.path().join("d");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("good.tsr"), model_a()).unwrap();
    assert!(matches!(
        start_error(&[good, other], opts()),
        ServeError::NameClash { .. }
    ));
}

#[test]
fn atomic_replacement_is_picked_up_cleanly() {
    let (_tmp, dir) = served_dir();
    let path = dir.join("a.tsr");
    let s = TestServer::start(&[dir], opts()).unwrap();
    let url = s.url("/models/a.tsr");
    let old = get(&url, &[("Range", "bytes=0-99")]);
    let old_etag = old.header("etag").unwrap().to_string();

    // A response in flight when the new build lands: all of it comes from the old file.
    let mut slow = TcpStream::connect(s.addr).unwrap();
    slow.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    slow.write_all(b"GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut first = [0u8; 4096];
    let n = slow.read(&mut first).unwrap();
    assert!(n > 0);

    replace(&path, model_b());

    let mut buf = first[..n].to_vec();
    slow.read_to_end(&mut buf).unwrap();
    let r = parse_response(&buf).unwrap();
    assert_eq!(r.status, 200);
    assert!(r.body == model_a(), "an in-flight response mixed bytes");
    assert_eq!(r.header("etag").unwrap(), old_etag);

    // The new file, a new ETag; If-Range with the old tag gets the whole new file.
    let r = get(&url, &[("Range", "bytes=0-99"), ("If-Range", &old_etag)]);
    assert_eq!(r.status, 200);
    assert!(r.body == model_b());
    let new_etag = r.header("etag").unwrap().to_string();
    assert_ne!(new_etag, old_etag);
    let r = get(&url, &[("Range", "bytes=100-199"), ("If-Range", &new_etag)]);
    assert_eq!(r.status, 206);
    assert!(r.body == model_b()[100..200]);
    // If-Match with the old tag: a clean 412, no bytes.
    let r = get(&url, &[("Range", "bytes=100-199"), ("If-Match", &old_etag)]);
    assert_eq!(r.status, 412);
    assert!(r.body.is_empty());
    // Same bytes again under a new inode: still a new tag (identity, not content).
    replace(&path, model_b());
    assert_ne!(get(&url, &[]).header("etag").unwrap(), new_etag);
    // The catalogue follows.
    let v = catalogue(&s);
    assert_eq!(v["models"][0]["bytes"], model_b().len() as u64);
    // Replaced by something that is not a model: no longer served.
    replace(&path, b"garbage garbage garbage");
    assert_eq!(get(&url, &[]).status, 404);
}

#[test]
fn path_traversal_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("served");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("a.tsr"), model_a()).unwrap();
    // Outside the served directory: a valid model and a secret, and links to both.
    const SECRET: &[u8] = b"TOP-SECRET-DO-NOT-SERVE";
    let mut outside = model_b().to_vec();
    outside.extend_from_slice(SECRET);
    std::fs::write(tmp.path().join("outside.tsr"), &outside).unwrap();
    std::fs::write(tmp.path().join("secret.txt"), SECRET).unwrap();
    std::os::unix::fs::symlink(tmp.path().join("outside.tsr"), dir.join("evil.tsr")).unwrap();
    std::os::unix::fs::symlink("../secret.txt", dir.join("secret.tsr")).unwrap();
    std::os::unix::fs::symlink("a.tsr", dir.join("alias.tsr")).unwrap(); // inside: fine
    let s = TestServer::start(std::slice::from_ref(&dir), opts()).unwrap();
    let abs = tmp.path().join("outside.tsr").display().to_string();
    let targets = [
        "/models/evil.tsr".to_string(),
        "/models/secret.tsr".into(),
        "/models/../outside.tsr".into(),
        "/models/../secret.txt".into(),
        "/models/..%2foutside.tsr".into(),
        "/models/%2e%2e%2foutside.tsr".into(),
        "/models/%2E%2E%2Fsecret.txt".into(),
        "/models/%2e%2e/outside.tsr".into(),
        "/models/.%2e/outside.tsr".into(),
        "/models/..%5coutside.tsr".into(),
        "/models/..\\outside.tsr".into(),
        "/models/%252e%252e%252foutside.tsr".into(),
        "/models/%c0%ae%c0%ae%2foutside.tsr".into(),
        "/models/..".into(),
        "/models/".into(),
        "/models/a.tsr/../../outside.tsr".into(),
        "/models/./a.tsr".into(),
        format!("/models/{abs}"),
        format!("/models/{}", abs.replace('/', "%2f")),
        "/models//etc/passwd".into(),
        "/models/%2fetc%2fpasswd".into(),
        "/models/a.tsr%00".into(),
        "/models/a.tsr%00.txt".into(),
        "/models/A.TSR".into(),
        "/models/secret.txt".into(),
        "/../outside.tsr".into(),
        "/outside.tsr".into(),
        "/secret.txt".into(),
        "/models/a.tsr%2f..%2f..%2fsecret.txt".into(),
        "/api/models/../../secret.txt".into(),
    ];
    assert!(targets.len() >= 15);
    for t in &targets {
        let r = get_raw(s.addr, t);
        let r = r.unwrap_or_else(|| panic!("{t}: no answer"));
        assert!(r.status == 400 || r.status == 404, "{t}: {}", r.status);
        assert!(
            !r.body.windows(SECRET.len()).any(|w| w == SECRET),
            "{t} leaked"
        );
        assert!(r.body.len() < 100, "{t}: {} bytes", r.body.len());
    }
    // Absolute-form request targets are routed by their path only.
    let r = raw(s.addr, b"GET http://localhost/../secret.txt HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
    if let Some(r) = r {
        assert!(r.status == 400 || r.status == 404);
    }
    // Raw NUL and control bytes in the request line.
    let r = raw(
        s.addr,
        b"GET /models/a.tsr\x00/../secret.txt HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
    );
    if let Some(r) = r {
        assert_eq!(r.status, 400);
    }
    // A symlink inside the directory to a file inside is served; names are exact.
    assert_eq!(get_raw(s.addr, "/models/alias.tsr").unwrap().status, 200);
    assert!(get_raw(s.addr, "/models/a.tsr").unwrap().body == model_a());
    assert!(get_raw(s.addr, "/models/%61.tsr").unwrap().body == model_a());
    let names = model_names(&catalogue(&s));
    assert_eq!(names, ["a", "alias"]);
    // A link swapped in after startup is not followed either.
    std::fs::remove_file(dir.join("a.tsr")).unwrap();
    std::os::unix::fs::symlink(tmp.path().join("outside.tsr"), dir.join("a.tsr")).unwrap();
    let r = get_raw(s.addr, "/models/a.tsr").unwrap();
    assert_eq!(r.status, 404);
    assert!(!r.body.windows(SECRET.len()).any(|w| w == SECRET));
}

#[test]
fn hostile_requests_get_4xx_and_others_are_still_served() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let cases: Vec<Vec<u8>> = vec![
        b"POST /models/a.tsr HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_vec(),
        b"DELETE /models/a.tsr HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".to_vec(),
        b"GARBAGE\r\n\r\n".to_vec(),
        b"GET / HTTP/9.9\r\n\r\n".to_vec(),
        b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03".to_vec(), // a TLS hello
        format!("GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nX-Big: {}\r\nConnection: close\r\n\r\n", "a".repeat(64 << 10)).into_bytes(),
        format!("GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nRange: bytes={}\r\nConnection: close\r\n\r\n", "0-1,".repeat(3000)).into_bytes(),
        b"GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nRange: bytes=\xff\xfe\r\nConnection: close\r\n\r\n".to_vec(),
        b"GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nIf-Range: \xff\r\nRange: bytes=0-1\r\nConnection: close\r\n\r\n".to_vec(),
    ];
    for (i, c) in cases.iter().enumerate() {
        let r = raw(s.addr, c);
        if let Some(r) = r {
            assert!(r.status >= 400 || r.status == 200, "case {i}: {}", r.status);
            if r.status == 200 {
                assert!(r.body == model_a(), "case {i}");
            }
        }
        let ok = get(&s.url("/models/a.tsr"), &[("Range", "bytes=0-9")]);
        assert_eq!(ok.status, 206, "after case {i}");
    }
    assert_eq!(raw(s.addr, &cases[0]).unwrap().status, 405);
    assert_eq!(raw(s.addr, &cases[5]).unwrap().status, 431);
}

#[test]
fn slow_clients_are_dropped_and_others_served() {
    let (_tmp, dir) = served_dir();
    let o = ServeOptions {
        header_read_timeout: Duration::from_millis(800),
        ..opts()
    };
    let mut s = TestServer::start(&[dir], o).unwrap();
    // Slowloris: a partial header, then nothing.
    let mut slow: Vec<TcpStream> = (0..20)
        .map(|_| {
            let mut c = TcpStream::connect(s.addr).unwrap();
            c.write_all(b"GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nX-Slow: ")
                .unwrap();
            c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            c
        })
        .collect();
    // An idle keep-alive connection after one answered request.
    let mut idle = TcpStream::connect(s.addr).unwrap();
    idle.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    idle.write_all(b"GET /models/a.tsr HTTP/1.1\r\nHost: x\r\nRange: bytes=0-0\r\n\r\n")
        .unwrap();
    let t = Instant::now();
    // Others are served meanwhile.
    for _ in 0..10 {
        assert_eq!(
            get(&s.url("/models/a.tsr"), &[("Range", "bytes=0-9")]).status,
            206
        );
    }
    for c in &mut slow {
        let mut buf = Vec::new();
        let _ = c.read_to_end(&mut buf); // EOF (or a 408) once the timeout hits
        if !buf.is_empty() {
            let r = parse_response(&buf).unwrap();
            assert_eq!(r.status, 408);
        }
    }
    let mut buf = Vec::new();
    let _ = idle.read_to_end(&mut buf);
    let dt = t.elapsed();
    assert!(
        dt >= Duration::from_millis(700) && dt < Duration::from_secs(5),
        "{dt:?}"
    );
    assert_eq!(parse_response(&buf).unwrap().status, 206);
    assert_eq!(
        get(&s.url("/models/a.tsr"), &[("Range", "bytes=0-9")]).status,
        206
    );
    // Graceful shutdown returns promptly, with a connection half-way through a header.
    let mut half = TcpStream::connect(s.addr).unwrap();
    half.write_all(b"GET /mod").unwrap();
    let took = s.stop();
    assert!(took < Duration::from_secs(5), "{took:?}");
}

#[test]
fn connection_limit_queues_instead_of_failing() {
    let (_tmp, dir) = served_dir();
    let o = ServeOptions {
        max_connections: 2,
        header_read_timeout: Duration::from_millis(600),
        ..opts()
    };
    let s = TestServer::start(&[dir], o).unwrap();
    // Two idle connections take both slots; a third client waits until they time out.
    let _a = TcpStream::connect(s.addr).unwrap();
    let _b = TcpStream::connect(s.addr).unwrap();
    std::thread::sleep(Duration::from_millis(100));
    let t = Instant::now();
    assert_eq!(
        get(&s.url("/models/a.tsr"), &[("Range", "bytes=0-9")]).status,
        206
    );
    assert!(
        t.elapsed() >= Duration::from_millis(300),
        "{:?}",
        t.elapsed()
    );
}

#[test]
fn concurrent_clients_get_exact_bytes() {
    let (_tmp, dir) = served_dir();
    let s = TestServer::start(&[dir], opts()).unwrap();
    let url = s.url("/models/a.tsr");
    let file = model_a();
    let len = file.len() as u64;
    std::thread::scope(|sc| {
        for t in 0..16u64 {
            let url = &url;
            sc.spawn(move || {
                let agent = agent();
                let mut rng = Rng(t * 7919 + 1);
                for _ in 0..40 {
                    let a = rng.next() % len;
                    let b = a + rng.next() % (len - a).min(100_000);
                    let mut r = agent
                        .get(url)
                        .header("Range", format!("bytes={a}-{b}"))
                        .call()
                        .unwrap();
                    assert_eq!(r.status(), 206);
                    let body = r.body_mut().read_to_vec().unwrap();
                    assert!(body == file[a as usize..=b as usize]);
                }
            });
        }
    });
}
