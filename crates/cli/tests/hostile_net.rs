//! Issue 29 item 6 at the command line: `tessera info URL` against a server that accepts
//! connections and never answers took 180 s to fail (60 s x 3 attempts). Now a clear
//! `error:` and a non-zero exit within 10 s; and a FIFO in a served directory does not
//! keep `tessera serve` from starting.

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
    let t = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(["info", &format!("http://{addr}/models/m.tsr")])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_within(&mut child, Duration::from_secs(30));
    let took = t.elapsed();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    eprintln!("{took:?}: {err}");
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
