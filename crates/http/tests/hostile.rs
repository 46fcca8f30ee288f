//! Issue 29: a server cannot make the HTTP client allocate or wait without bound, and
//! every failure says what it is. Each test runs a tiny scripted server on loopback
//! (silent, dripping, changing its ETag, forging a header, mislabelling a range,
//! redirecting to `file://`) and bounds the client's time to a clear error. Each failed
//! on the code before the fix: 180 s to fail against a silent server, a 1 GiB index
//! request made for a forged header, a 206 of another ETag accepted, a panic on
//! `Content-Range: bytes 0-18446744073709551615/0`, "too many redirects" for a redirect
//! to `file://`, non-transient failures retried.

mod common;

use std::io::Write;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use tessera_format::{header_crc32, Header, PatchReader, HEADER_BYTES};
use tessera_http::{classify, ErrorClass, HttpOptions, RemoteModel, PREFIX_BYTES};

// ---------------------------------------------------------------- the server

/// A scripted HTTP/1.1 server on 127.0.0.1: `script(n, head, stream)` answers request
/// `n` (counted from 0 over all connections); a connection stays open for the next
/// request until either side closes it. Connections idle 30 s are dropped.
struct Hostile {
    addr: SocketAddr,
    requests: Arc<AtomicU64>,
}

type Script = dyn Fn(u64, &str, &mut TcpStream) + Send + Sync;

impl Hostile {
    fn start(script: impl Fn(u64, &str, &mut TcpStream) + Send + Sync + 'static) -> Hostile {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        let requests = Arc::new(AtomicU64::new(0));
        let script: Arc<Script> = Arc::new(script);
        let counter = requests.clone();
        std::thread::spawn(move || {
            for c in l.incoming() {
                let Ok(mut c) = c else { continue };
                let (script, counter) = (script.clone(), counter.clone());
                std::thread::spawn(move || {
                    let _ = c.set_read_timeout(Some(Duration::from_secs(30)));
                    while let Some(head) = common::read_head(&mut c) {
                        let head = String::from_utf8_lossy(&head);
                        let n = counter.fetch_add(1, Ordering::SeqCst);
                        script(n, &head, &mut c);
                    }
                });
            }
        });
        Hostile { addr, requests }
    }

    fn url(&self) -> String {
        format!("http://{}/models/m.tsr", self.addr)
    }

    fn requests(&self) -> u64 {
        self.requests.load(Ordering::SeqCst)
    }
}

/// The `Range: bytes=A-B` of a request head.
fn range_of(head: &str) -> (u64, u64) {
    let v = head
        .split("\r\n")
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.eq_ignore_ascii_case("range")
                .then(|| v.trim().to_string())
        })
        .expect("a Range header");
    let (a, b) = v.strip_prefix("bytes=").unwrap().split_once('-').unwrap();
    (a.parse().unwrap(), b.parse().unwrap())
}

/// Answers a range request from `bytes` correctly, with `etag` (if any).
fn answer_range(c: &mut TcpStream, head: &str, bytes: &[u8], etag: Option<&str>) {
    let (a, b) = range_of(head);
    let b = b.min(bytes.len() as u64 - 1);
    let tag = etag.map_or(String::new(), |t| format!("ETag: {t}\r\n"));
    let _ = write!(
        c,
        "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes {a}-{b}/{}\r\nContent-Length: {}\r\n{tag}\r\n",
        bytes.len(),
        b + 1 - a
    );
    let _ = c.write_all(&bytes[a as usize..=b as usize]);
}

fn close_with(c: &mut TcpStream, response: &str) {
    let _ = c.write_all(response.as_bytes());
    let _ = c.shutdown(std::net::Shutdown::Both);
}

/// A built model bigger than [`PREFIX_BYTES`] (patches outside the first request).
fn model() -> Arc<Vec<u8>> {
    static M: OnceLock<Arc<Vec<u8>>> = OnceLock::new();
    M.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let p = common::build(dir.path(), "h.tsr", 30_000, 13);
        let b = std::fs::read(&p).unwrap();
        assert!(b.len() as u64 > 2 * PREFIX_BYTES);
        Arc::new(b)
    })
    .clone()
}

/// `f()` on its own thread; panics unless it returns within `limit` (the old client
/// took minutes) or if it panicked. Returns its result and how long it took.
fn within<T: Send + 'static>(
    limit: Duration,
    f: impl FnOnce() -> T + Send + 'static,
) -> (T, Duration) {
    let (tx, rx) = std::sync::mpsc::channel();
    let t = Instant::now();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(limit) {
        Ok(v) => (v, t.elapsed()),
        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
            panic!("no answer within {limit:?}")
        }
        Err(_) => panic!("the client panicked"),
    }
}

/// Opens `url`, expecting an error within `limit`: its message, class and the time.
fn open_err(url: String, limit: Duration) -> (String, ErrorClass, Duration) {
    let (r, took) = within(limit, move || RemoteModel::open(&url).map(|_| ()));
    let e = r.expect_err("the open should fail");
    eprintln!("{took:?}: {e}");
    (e.to_string(), classify(&e), took)
}

// ---------------------------------------------------------------- time

/// Issue 29 item 6: `tessera info` against a silent server took 180 s (60 s x 3 tries).
/// Now the stall timeout (5 s) ends it, with no retry.
#[test]
fn issue_29_silent_server_fails_in_seconds() {
    let s = Hostile::start(|_, _, _| std::thread::sleep(Duration::from_secs(30)));
    let (msg, class, took) = open_err(s.url(), Duration::from_secs(15));
    assert!(took < Duration::from_secs(8), "{took:?}");
    assert!(msg.contains("sent nothing for 5 s"), "{msg}");
    assert_eq!(class, ErrorClass::Unavailable);
    assert_eq!(s.requests(), 1, "a stalled server is not asked again");
}

/// A server that drips its answer (a byte every 50 ms) is cut off by the read's
/// deadline (8 s + 0.25 s for 64 KiB), not waited on for hours.
#[test]
fn issue_29_dripping_server_fails_at_the_read_deadline() {
    let s = Hostile::start(|_, _, c| {
        let _ = c.write_all(
            b"HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-65535/100000\r\nContent-Length: 65536\r\n\r\n",
        );
        for _ in 0..600 {
            if c.write_all(b"x").is_err() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    });
    let (msg, class, took) = open_err(s.url(), Duration::from_secs(20));
    assert!(took < Duration::from_secs(10), "{took:?}");
    assert!(took > Duration::from_secs(7), "{took:?}");
    assert!(msg.contains("timed out"), "{msg}");
    assert_eq!(class, ErrorClass::Unavailable);
}

/// Issue 29 item 6: `render --complete` against a server that went silent took 552 s.
/// After the first reads fail (5 s), every other read fails at once
/// (`UNAVAILABLE_COOLDOWN`), named unavailable, not corrupt.
#[test]
fn issue_29_server_gone_silent_fails_every_read_fast() {
    let bytes = model();
    let b = bytes.clone();
    let s = Hostile::start(move |n, head, c| {
        if n == 0 {
            answer_range(c, head, &b, Some("\"v1\""));
        } else {
            std::thread::sleep(Duration::from_secs(30));
        }
    });
    let m = Arc::new(RemoteModel::open(&s.url()).unwrap());
    let outside: Vec<usize> = (0..m.index().nodes().len())
        .filter(|&i| m.index().patch_range(i).unwrap().start >= PREFIX_BYTES)
        .collect();
    assert!(
        outside.len() >= 24,
        "{} patches outside the prefix",
        outside.len()
    );
    let (results, took) = within(Duration::from_secs(30), move || {
        let threads: Vec<_> = outside
            .iter()
            .take(24)
            .map(|&i| {
                let m = m.clone();
                std::thread::spawn(move || m.decode_patch(i).map(|_| ()))
            })
            .collect();
        threads
            .into_iter()
            .map(|t| t.join().unwrap())
            .collect::<Vec<_>>()
    });
    eprintln!("24 reads against a silent server failed in {took:?}");
    assert!(took < Duration::from_secs(10), "{took:?}");
    for (k, r) in results.into_iter().enumerate() {
        let e = r.expect_err("no patch can arrive");
        if k < 4 {
            eprintln!("{e}");
        }
        assert_eq!(classify(&e), ErrorClass::Unavailable, "{e}");
    }
    assert!(s.requests() <= 1 + 6, "{} requests", s.requests());
}

/// An overall deadline ([`HttpOptions::deadline`], what `tessera info` sets) bounds
/// everything read through the source.
#[test]
fn overall_deadline_bounds_the_open() {
    let s = Hostile::start(|_, _, _| std::thread::sleep(Duration::from_secs(30)));
    let url = s.url();
    let (r, took) = within(Duration::from_secs(10), move || {
        RemoteModel::open_with(
            &url,
            &HttpOptions {
                deadline: Some(Duration::from_secs(1)),
            },
        )
        .map(|_| ())
    });
    let e = r.unwrap_err();
    assert!(took < Duration::from_secs(3), "{took:?}: {e}");
    assert_eq!(classify(&e), ErrorClass::Unavailable);
}

// ---------------------------------------------------------------- the model changed

/// Issue 29 item 6: a 206 with a changed ETag was accepted (its bytes then failed their
/// CRCs, or worse, passed). Now every 206 must carry the ETag the model was opened
/// with; one without any is refused too.
#[test]
fn issue_29_a_206_of_another_etag_is_the_model_changed() {
    let bytes = model();
    for (later, want) in [
        (Some("\"v2\""), ErrorClass::Changed),
        (None, ErrorClass::Refused),
    ] {
        let b = bytes.clone();
        let s = Hostile::start(move |n, head, c| {
            let tag = if n == 0 { Some("\"v1\"") } else { later };
            answer_range(c, head, &b, tag);
        });
        let m = RemoteModel::open(&s.url()).unwrap();
        let i = (0..m.index().nodes().len())
            .rfind(|&i| m.index().patch_range(i).unwrap().start >= PREFIX_BYTES)
            .unwrap();
        let e = m.decode_patch(i).expect_err("a 206 of another file");
        eprintln!("{later:?}: {e}");
        assert_eq!(classify(&e), want, "{e}");
        if want == ErrorClass::Changed {
            assert!(e.to_string().contains("changed on the server"), "{e}");
        }
        assert_eq!(s.requests(), 2, "not retried");
    }
}

// ---------------------------------------------------------------- sizes

/// `bytes` with the header rewritten by `edit` and its CRC made valid again.
fn forged(bytes: &[u8], edit: impl FnOnce(&mut Header)) -> Vec<u8> {
    let mut h: Header = bytemuck_read(&bytes[..HEADER_BYTES as usize]);
    edit(&mut h);
    h.header_crc32 = header_crc32(&h);
    let mut out = bytes[..PREFIX_BYTES as usize].to_vec();
    out[..HEADER_BYTES as usize].copy_from_slice(header_bytes(&h));
    out
}

fn bytemuck_read(b: &[u8]) -> Header {
    assert_eq!(b.len(), std::mem::size_of::<Header>());
    // SAFETY: Header is #[repr(C)] Pod of exactly these many bytes; read unaligned.
    unsafe { std::ptr::read_unaligned(b.as_ptr() as *const Header) }
}

fn header_bytes(h: &Header) -> &[u8] {
    // SAFETY: Header is #[repr(C)] Pod of HEADER_BYTES bytes.
    unsafe { std::slice::from_raw_parts(h as *const Header as *const u8, HEADER_BYTES as usize) }
}

/// Serves `prefix` as the first 64 KiB of a file of `total` bytes; any later request is
/// counted and closed unanswered.
fn serve_prefix(prefix: Vec<u8>, total: u64) -> Hostile {
    Hostile::start(move |n, _, c| {
        if n > 0 {
            let _ = c.shutdown(std::net::Shutdown::Both);
            return;
        }
        let _ = write!(
            c,
            "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-{}/{total}\r\nContent-Length: {}\r\nETag: \"f\"\r\n\r\n",
            prefix.len() - 1,
            prefix.len()
        );
        let _ = c.write_all(&prefix);
    })
}

/// Issue 29 item 5: a forged header (valid CRC) claiming a 1 GiB index made the client
/// ask for, download and hold it (993 MB) before validating anything; the same header
/// in a local file is refused at once. Now refused after the first request: the index
/// must fit what the header's nodes can take, and at most 256 MiB.
#[test]
fn issue_29_a_forged_index_size_is_refused_before_fetching() {
    let bytes = model();
    // The node count kept: 1 GiB is far more than its nodes can take.
    const GIB: u64 = 1 << 30;
    let prefix = forged(&bytes, |h| {
        h.patch_data_offset += GIB;
        h.file_bytes += GIB;
    });
    let total = bytemuck_read(&prefix[..HEADER_BYTES as usize]).file_bytes;
    let s = serve_prefix(prefix, total);
    let (msg, class, took) = open_err(s.url(), Duration::from_secs(10));
    assert!(msg.contains("forged"), "{msg}");
    assert_eq!(class, ErrorClass::Corrupt);
    assert_eq!(
        s.requests(),
        1,
        "nothing but the first 64 KiB was asked for"
    );
    assert!(took < Duration::from_secs(2), "{took:?}");

    // Ten million nodes claimed (patch data to match): a 300 MiB index they could take,
    // beyond what this client reads.
    let prefix = forged(&bytes, |h| {
        let nodes = 10_000_000u64;
        h.node_count = nodes;
        h.page_count =
            tessera_format::IndexLayout::new(nodes, h.page_nodes, HEADER_BYTES).page_count as _;
        h.patch_data_offset += 300 << 20;
        h.patch_data_bytes = nodes * 64;
        h.file_bytes = h.patch_data_offset + h.patch_data_bytes;
    });
    let total = bytemuck_read(&prefix[..HEADER_BYTES as usize]).file_bytes;
    let s = serve_prefix(prefix, total);
    let (msg, class, _) = open_err(s.url(), Duration::from_secs(10));
    assert!(msg.contains("256 MiB"), "{msg}");
    assert_eq!(class, ErrorClass::Refused);
    assert_eq!(s.requests(), 1);
}

/// Issue 29 item 8: `Content-Range: bytes 0-18446744073709551615/0` was accepted
/// because `b + 1` wrapped (a panic in a debug build). A span past the file's end, a
/// `Content-Length` other than the range's, and a garbled answer are refused at once,
/// never retried.
#[test]
fn issue_29_mislabelled_answers_are_refused_without_retries() {
    for (what, answer) in [
        (
            "overflowing Content-Range",
            "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-18446744073709551615/0\r\nContent-Length: 0\r\n\r\n",
        ),
        (
            "span past the end",
            "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-65535/10\r\nContent-Length: 65536\r\n\r\n",
        ),
        (
            "Content-Length of another size",
            "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-65535/100000\r\nContent-Length: 900000000\r\n\r\n",
        ),
        ("not HTTP", "SSH-2.0-OpenSSH_9.2\r\n\r\n"),
        ("forbidden", "HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\n\r\n"),
    ] {
        let answer = answer.to_string();
        let s = Hostile::start(move |_, _, c| close_with(c, &answer));
        let (msg, class, took) = open_err(s.url(), Duration::from_secs(10));
        assert_eq!(class, ErrorClass::Refused, "{what}: {msg}");
        assert_eq!(s.requests(), 1, "{what}: retried: {msg}");
        assert!(took < Duration::from_secs(2), "{what}: {took:?}");
    }
    // Failures that may pass are still retried: 503 three times, then a clear error.
    let s =
        Hostile::start(|_, _, c| close_with(c, "HTTP/1.1 503 Busy\r\nContent-Length: 0\r\n\r\n"));
    let (msg, class, _) = open_err(s.url(), Duration::from_secs(10));
    assert_eq!(class, ErrorClass::Unavailable);
    assert!(msg.contains("after 3 attempts"), "{msg}");
    assert_eq!(s.requests(), 3);
}

// ---------------------------------------------------------------- redirects

/// Issue 29 item 8: a redirect to `file://` was reported as "too many redirects". Now
/// it is named; a redirect to an `http://` URL is followed and the model read there.
#[test]
fn issue_29_redirects_are_reported_truthfully() {
    let s = Hostile::start(|_, _, c| {
        close_with(
            c,
            "HTTP/1.1 302 Found\r\nLocation: file:///etc/passwd\r\nContent-Length: 0\r\n\r\n",
        )
    });
    let (msg, class, _) = open_err(s.url(), Duration::from_secs(10));
    assert!(!msg.contains("too many"), "{msg}");
    assert!(
        msg.contains("file:///etc/passwd") && msg.contains("only redirects to http://"),
        "{msg}"
    );
    assert_eq!(class, ErrorClass::Refused);

    let bytes = model();
    let target = Hostile::start(move |_, head, c| answer_range(c, head, &bytes, Some("\"t\"")));
    let to = format!("http://{}/real/m.tsr", target.addr);
    let moved = Hostile::start(move |_, _, c| {
        close_with(
            c,
            &format!("HTTP/1.1 301 Moved\r\nLocation: {to}\r\nContent-Length: 0\r\n\r\n"),
        )
    });
    let m = RemoteModel::open(&moved.url()).unwrap();
    assert!(
        m.source().url().ends_with("/real/m.tsr"),
        "{}",
        m.source().url()
    );
    let last = m.index().nodes().len() - 1;
    m.decode_patch(last).unwrap();
    assert_eq!(moved.requests(), 1, "later reads go to the target");

    // A loop of redirects ends with a message saying so.
    let looping = Hostile::start(|_, _, c| {
        close_with(
            c,
            "HTTP/1.1 302 Found\r\nLocation: /models/m.tsr\r\nContent-Length: 0\r\n\r\n",
        )
    });
    let (msg, _, _) = open_err(looping.url(), Duration::from_secs(10));
    assert!(msg.contains("more than 5 redirects"), "{msg}");
}
