//! Issue 29 item 6 at the command line: `tessera info URL` against a server that accepts
//! connections and never answers took 180 s to fail (60 s x 3 attempts). Now a clear
//! `error:` and a non-zero exit within 10 s; and a FIFO in a served directory does not
//! keep `tessera serve` from starting.

mod common;

use std::io::{BufRead, BufReader, Read};
use std::net::TcpListener;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The child's exit status; kills it and panics if it runs longer than `limit`.
fn wait_within(child: &mut Child, limit: Duration) -> ExitStatus {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Runs `tessera ARGS` with its standard error captured, killed past `limit`: its exit
/// status, standard error and run time.
fn run_within(args: &[&std::ffi::OsStr], limit: Duration) -> (ExitStatus, String, Duration) {
    let t = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_within(&mut child, limit);
    let took = t.elapsed();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    eprintln!("{took:?}: {err}");
    (status, err, took)
}

#[test]
fn issue_29_info_against_a_silent_server_fails_within_10_s() {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for c in l.incoming().take(8) {
            // Accepted, read, never answered (held open until the test ends).
            if let Ok(mut c) = c {
                let _ = c.set_read_timeout(Some(Duration::from_secs(30)));
                let mut buf = [0u8; 4096];
                let _ = c.read(&mut buf);
                held.push(c);
            }
        }
        std::thread::sleep(Duration::from_secs(60));
    });
    let url = format!("http://{addr}/models/m.tsr");
    let (status, err, took) = run_within(&["info".as_ref(), url.as_ref()], Duration::from_secs(30));
    assert!(!status.success());
    assert!(took < Duration::from_secs(10), "{took:?}");
    assert!(
        err.contains("error:") && err.contains("sent nothing"),
        "{err}"
    );
}

#[test]
fn issue_29_serve_starts_beside_a_fifo() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("d");
    std::fs::create_dir(&dir).unwrap();
    let status = Command::new("mkfifo")
        .arg(dir.join("evil.tsr"))
        .status()
        .unwrap();
    assert!(status.success());
    let mut child = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(["serve", dir.to_str().unwrap(), "--addr", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // No model besides the FIFO: a clear start error, at once (before: a hang).
    let status = wait_within(&mut child, Duration::from_secs(10));
    let mut err = String::new();
    for line in BufReader::new(child.stderr.take().unwrap()).lines() {
        err.push_str(&line.unwrap());
        err.push('\n');
    }
    assert!(!status.success(), "{err}");
    assert!(
        err.contains("evil.tsr") && err.contains("not a regular file"),
        "{err}"
    );
}

/// Answers the first `answered` requests of a connection stream as a static file server
/// of `bytes` would (single ranges, an ETag), then accepts and never answers: a server
/// that goes silent after the client opened the model.
fn serve_then_go_silent(bytes: Vec<u8>, answered: usize) -> std::net::SocketAddr {
    use std::io::Write;
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || {
        let mut served = 0;
        let mut held = Vec::new();
        for c in l.incoming().take(64) {
            let Ok(mut c) = c else { continue };
            let _ = c.set_read_timeout(Some(Duration::from_secs(30)));
            loop {
                // One request head.
                let mut head = Vec::new();
                let mut b = [0u8; 1];
                while !head.ends_with(b"\r\n\r\n") {
                    match c.read(&mut b) {
                        Ok(1) => head.push(b[0]),
                        _ => break,
                    }
                }
                if !head.ends_with(b"\r\n\r\n") {
                    break;
                }
                if served >= answered {
                    held.push(c);
                    break;
                }
                served += 1;
                let text = String::from_utf8_lossy(&head).to_ascii_lowercase();
                let (a, z) = text
                    .lines()
                    .find_map(|l| l.strip_prefix("range: bytes="))
                    .and_then(|r| {
                        let (a, z) = r.trim().split_once('-')?;
                        let a: usize = a.parse().ok()?;
                        let z: usize = z.parse().unwrap_or(bytes.len() - 1);
                        Some((a, z.min(bytes.len() - 1)))
                    })
                    .unwrap_or((0, bytes.len() - 1));
                let body = &bytes[a..=z];
                let reply = format!(
                    "HTTP/1.1 206 Partial Content\r\nContent-Length: {}\r\n\
                     Content-Range: bytes {a}-{z}/{}\r\nETag: \"m1\"\r\n\
                     Accept-Ranges: bytes\r\n\r\n",
                    body.len(),
                    bytes.len()
                );
                if c.write_all(reply.as_bytes()).is_err() || c.write_all(body).is_err() {
                    break;
                }
            }
        }
        std::thread::sleep(Duration::from_secs(60));
    });
    addr
}

/// Issue 29 item 6: `render --complete` against a server that goes silent once the model
/// is open took 552 s, then exited 0 with coarse frames and called the missing patches
/// "corrupt". Now it fails within seconds, non-zero, calling them unavailable.
#[test]
fn issue_29_render_complete_against_a_server_gone_silent_fails_and_says_why() {
    let built = common::build_sphere(60_000, 3, false, &common::small_options());
    let bytes = std::fs::read(&built.model_path).unwrap();
    // The first request (64 KiB: header, index, roots of this model) is answered.
    let addr = serve_then_go_silent(bytes, 1);
    let out = tempfile::tempdir().unwrap();
    let url = format!("http://{addr}/m.tsr");
    let flags = [
        "render",
        url.as_str(),
        "--orbit",
        "1",
        "--complete",
        "--width",
        "320",
        "--height",
        "240",
        "--out",
    ];
    let args: Vec<&std::ffi::OsStr> = flags
        .iter()
        .map(|a| a.as_ref())
        .chain([out.path().as_os_str()])
        .collect();
    let (status, err, took) = run_within(&args, Duration::from_secs(120));
    assert!(!status.success(), "exit 0 with incomplete frames: {err}");
    assert!(
        err.contains("could not be read") && err.contains("incomplete"),
        "{err}"
    );
    assert!(
        !err.contains("corrupt"),
        "unavailable patches called corrupt: {err}"
    );
    assert!(took < Duration::from_secs(60), "{took:?}");
}
