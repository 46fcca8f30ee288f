//! Issue 29: what lies in a served directory cannot make `tessera serve` block, flood
//! its log or slow every catalogue request: FIFOs and other non-regular files are
//! skipped before anything opens them, each unservable name is warned about once, the
//! catalogue is cached, and `OPTIONS` says what is allowed. Every test here failed on
//! the code before the fix (startup hung on the FIFO; no warning for bad names; no
//! `Allow`; a rescan per catalogue request).

mod common;

use std::ffi::CString;
use std::net::SocketAddr;
use std::os::unix::ffi::OsStrExt;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{capture_warnings, quick_opts, request, warnings_with, TestServer};

fn model() -> &'static [u8] {
    static M: OnceLock<Vec<u8>> = OnceLock::new();
    M.get_or_init(|| common::built(5, 8_000))
}

fn names(addr: SocketAddr) -> Vec<String> {
    let r = request(addr, "GET", "/api/models", "");
    assert_eq!(r.status, 200);
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    v["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap().to_string())
        .collect()
}

fn mkfifo(p: &Path) {
    let c = CString::new(p.as_os_str().as_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo");
}

// ---------------------------------------------------------------- tests

/// Issue 29 item 4: `mkfifo d/evil.tsr; tessera serve d` hung at startup with nothing
/// printed; a FIFO added later hung every `/api/models` (a blocking thread leaked a
/// request); a FIFO named as an input hung too. Now each is skipped with one warning.
#[test]
fn issue_29_fifos_are_skipped_without_blocking() {
    capture_warnings();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("served");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("a.tsr"), model()).unwrap();
    mkfifo(&dir.join("evil.tsr"));
    let lone = tmp.path().join("lone.tsr");
    mkfifo(&lone);
    let s = TestServer::start(&[dir.clone(), lone], quick_opts()).unwrap();
    assert_eq!(names(s.addr), ["a"]);

    // Added while serving: every catalogue request still answers at once.
    mkfifo(&dir.join("late.tsr"));
    for i in 0..5 {
        let t = Instant::now();
        assert_eq!(names(s.addr), ["a"], "request {i}");
        assert!(
            t.elapsed() < Duration::from_secs(3),
            "catalogue took {:?}",
            t.elapsed()
        );
    }
    for bad in ["evil.tsr", "late.tsr", "lone.tsr"] {
        assert_eq!(
            request(s.addr, "GET", &format!("/models/{bad}"), "").status,
            404
        );
    }
    // Periodic rescans (every 100 ms here) do not repeat the warnings.
    std::thread::sleep(Duration::from_millis(500));
    let root = tmp.path().to_str().unwrap();
    for bad in ["evil.tsr", "late.tsr", "lone.tsr"] {
        let w = warnings_with(&[root, bad]);
        assert_eq!(w.len(), 1, "{bad}: {w:?}");
        assert!(w[0].contains("not a regular file"), "{w:?}");
    }
}

/// Issue 29 item 8: served names with `\n`, `\t`, `\` or a leading `.` were skipped
/// without the warning the docs promised. Now one warning each (the name quoted, so a
/// newline cannot forge a log line), not repeated by rescans.
#[test]
fn issue_29_unservable_names_are_warned_about_once() {
    capture_warnings();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("names");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("ok.tsr"), model()).unwrap();
    let bad = [
        "new\nline.tsr",
        "tab\there.tsr",
        "back\\slash.tsr",
        ".hidden.tsr",
    ];
    for b in bad {
        std::fs::write(dir.join(b), model()).unwrap();
    }
    let s = TestServer::start(std::slice::from_ref(&dir), quick_opts()).unwrap();
    for _ in 0..3 {
        assert_eq!(names(s.addr), ["ok"]);
    }
    std::thread::sleep(Duration::from_millis(500));
    let root = tmp.path().to_str().unwrap();
    for (b, shown) in bad.iter().zip([
        "new\\nline.tsr",
        "tab\\there.tsr",
        "back\\\\slash.tsr",
        ".hidden.tsr",
    ]) {
        let w = warnings_with(&[root, shown]);
        assert_eq!(w.len(), 1, "{b:?}: {w:?}");
        assert!(!w[0].contains('\n'), "{w:?}");
    }
}

/// Issue 29 item 8: `OPTIONS` answered 200 without `Allow` (the CORS layer answers
/// every `OPTIONS` as a preflight).
#[test]
fn issue_29_options_answers_with_allow() {
    let tmp = tempfile::tempdir().unwrap();
    let one = tmp.path().join("a.tsr");
    std::fs::write(&one, model()).unwrap();
    let s = TestServer::start(&[one], quick_opts()).unwrap();
    for (path, extra) in [
        ("/models/a.tsr", ""),
        ("/api/models", ""),
        (
            "/models/a.tsr",
            "Origin: https://example.org\r\nAccess-Control-Request-Method: GET\r\n",
        ),
    ] {
        let r = request(s.addr, "OPTIONS", path, extra);
        assert!(r.status / 100 == 2, "{path}: {}", r.status);
        let allow = r.header("allow").unwrap_or_default();
        for m in ["GET", "HEAD", "OPTIONS"] {
            assert!(allow.contains(m), "{path} {extra:?}: Allow {allow:?}");
        }
    }
}

/// Issue 29 item 8: every `/api/models` rescanned the directory (1,000 models: 25-34 ms
/// a request, 100 concurrent requests 2.1 s). Now a request stats the directory and
/// serves the cached body; a new build still shows in the next request.
#[test]
fn issue_29_catalogue_of_1000_models_is_cached() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("many");
    std::fs::create_dir(&dir).unwrap();
    let first = dir.join("m0000.tsr");
    std::fs::write(&first, model()).unwrap();
    for i in 1..1000 {
        // Hard links: 1,000 names to open and check, one copy of the bytes on disk.
        std::fs::hard_link(&first, dir.join(format!("m{i:04}.tsr"))).unwrap();
    }
    let s = TestServer::start(std::slice::from_ref(&dir), quick_opts()).unwrap();
    let addr = s.addr;
    assert_eq!(names(addr).len(), 1000);
    let mut ms: Vec<f64> = (0..40)
        .map(|_| {
            let t = Instant::now();
            let r = request(addr, "GET", "/api/models", "");
            assert_eq!(r.status, 200);
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    let median = ms[ms.len() / 2];
    let t = Instant::now();
    let threads: Vec<_> = (0..100)
        .map(|_| std::thread::spawn(move || request(addr, "GET", "/api/models", "").status))
        .collect();
    for th in threads {
        assert_eq!(th.join().unwrap(), 200);
    }
    let concurrent = t.elapsed();
    eprintln!(
        "1,000 models: catalogue median {median:.2} ms, max {:.2} ms; 100 concurrent {concurrent:?}",
        ms[ms.len() - 1]
    );
    // Before: a rescan per request (tens of ms each in a debug build, seconds for 100).
    assert!(median < 15.0, "median {median:.2} ms");
    assert!(concurrent < Duration::from_millis(1500), "{concurrent:?}");
    // The cache follows the directory.
    std::fs::hard_link(&first, dir.join("new.tsr")).unwrap();
    let n = names(addr);
    assert_eq!(n.len(), 1001);
    assert!(n.contains(&"new".to_string()));
    std::fs::remove_file(dir.join("m0001.tsr")).unwrap();
    assert_eq!(names(addr).len(), 1000);
}
