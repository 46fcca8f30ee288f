//! `tessera serve` as a user runs it: the printed address, a range and the catalogue over
//! a real socket, Ctrl-C, and the clear errors (busy port, nothing to serve).

mod common;
mod remote;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

/// Sends one request (`Connection: close`) and returns (status line, headers, body).
fn request(addr: SocketAddr, target: &str, extra: &str) -> (String, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: {addr}\r\n{extra}Connection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).unwrap();
    let end = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a response head");
    let head = String::from_utf8_lossy(&buf[..end]).into_owned();
    let (status, headers) = head.split_once("\r\n").unwrap_or((&head, ""));
    (
        status.to_string(),
        headers.to_ascii_lowercase(),
        buf[end + 4..].to_vec(),
    )
}

/// Starts `tessera serve MODEL --addr 127.0.0.1:0` and reads the bound address from its
/// first line ("serving 1 model at http://127.0.0.1:PORT/"); the rest of its output is
/// drained.
fn start_serve(model: &std::path::Path) -> (Running, SocketAddr) {
    let mut child = Running(
        tessera()
            .arg("serve")
            .arg(model)
            .args(["--addr", "127.0.0.1:0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut out = BufReader::new(child.0.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    assert!(line.starts_with("serving 1 model at http://"), "{line}");
    let addr: SocketAddr = line
        .trim()
        .trim_start_matches("serving 1 model at http://")
        .trim_end_matches('/')
        .parse()
        .unwrap();
    assert_ne!(addr.port(), 0);
    // Keep reading what it prints: a closed pipe would make its next line fail.
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    (child, addr)
}

struct Running(Child);
impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn serve_prints_its_address_and_serves_ranges_and_the_catalogue() {
    let built = common::build_sphere(20_000, 3, false, &common::small_options());
    let bytes = std::fs::read(&built.model_path).unwrap();
    let (mut child, addr) = start_serve(&built.model_path);
    let name = built
        .model_path
        .file_name()
        .unwrap()
        .to_str()
        .unwrap()
        .to_string();

    let (status, headers, body) = request(
        addr,
        &format!("/models/{name}"),
        "Range: bytes=100-1099\r\n",
    );
    assert!(status.contains(" 206 "), "{status}");
    assert!(
        headers.contains(&format!("content-range: bytes 100-1099/{}", bytes.len())),
        "{headers}"
    );
    assert!(headers.contains("etag: \""), "{headers}");
    assert!(body == bytes[100..1100]);

    let (status, _, body) = request(addr, "/api/models", "");
    assert!(status.contains(" 200 "), "{status}");
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    let m = &v["models"][0];
    assert_eq!(m["url"], format!("/models/{name}"));
    assert_eq!(m["bytes"], bytes.len() as u64);
    assert_eq!(m["triangles"], built.model.header().input_triangles);

    // Ctrl-C: a clean exit.
    // SAFETY: signalling our own child process by its id.
    unsafe {
        libc::kill(child.0.id() as i32, libc::SIGINT);
    }
    let t = Instant::now();
    loop {
        if let Some(status) = child.0.try_wait().unwrap() {
            assert!(status.success(), "{status}");
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "no exit after Ctrl-C"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn error_line(out: &std::process::Output) -> String {
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    lines[0].to_string()
}

#[test]
fn busy_port_and_nothing_to_serve_are_clear_errors() {
    let built = common::build_sphere(5_000, 4, false, &common::small_options());
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = busy.local_addr().unwrap().port();
    let out = tessera()
        .arg("serve")
        .arg(&built.model_path)
        .args(["--addr", &format!("127.0.0.1:{port}")])
        .output()
        .unwrap();
    let e = error_line(&out);
    assert!(
        e.contains("already in use") && e.contains("--addr 127.0.0.1:0"),
        "{e}"
    );

    let junk = built.dir.path().join("junk.tsr");
    std::fs::write(&junk, b"not a model at all").unwrap();
    let out = tessera()
        .arg("serve")
        .arg(&junk)
        .args(["--addr", "127.0.0.1:0"])
        .output()
        .unwrap();
    let e = error_line(&out);
    assert!(
        e.contains("no valid model") && e.contains("junk.tsr"),
        "{e}"
    );
}

/// `info` and `render` on an `http://` URL from `tessera serve`: the same report (but
/// the name) and byte-identical PNG frames as on the local file; a URL that serves no
/// model is one clear error.
#[test]
fn info_and_render_read_remote_models() {
    let built = common::build_sphere(20_000, 5, false, &common::small_options());
    let (_child, addr) = start_serve(&built.model_path);
    let base = format!("http://{addr}");
    let name = built.model_path.file_name().unwrap().to_str().unwrap();
    let url = format!("{base}/models/{name}");

    let local = built.model_path.to_str().unwrap();
    assert_eq!(remote::info_json(&url), remote::info_json(local));
    remote::assert_same_renders(local, &url);

    let o = tessera()
        .args(["info", &format!("{base}/models/missing.tsr")])
        .output()
        .unwrap();
    let err = error_line(&o);
    assert!(err.contains("not found"), "{err}");
    assert_eq!(String::from_utf8_lossy(&o.stderr).trim().lines().count(), 1);
}

/// `extract` on an `http://` URL from `tessera serve` writes the same PLY, byte for byte,
/// as on the local file (full resolution, a uniform level, a coarse error cut); a bad
/// level is the same clear error either way.
#[test]
fn extract_reads_remote_models() {
    let built = common::build_sphere(20_000, 6, true, &common::small_options());
    let (_child, addr) = start_serve(&built.model_path);
    let name = built.model_path.file_name().unwrap().to_str().unwrap();
    let url = format!("http://{addr}/models/{name}");
    let local = built.model_path.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let extract = |target: &str, cut: &[&str], out: &str| -> Vec<u8> {
        let path = dir.path().join(out);
        let o = tessera()
            .args(["extract", target])
            .args(cut)
            .arg("-o")
            .arg(&path)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(&path).unwrap()
    };
    let cuts: [&[&str]; 3] = [
        &["--max-error", "0"],
        &["--level", "1"],
        &["--max-error", "0.05"],
    ];
    for (i, cut) in cuts.iter().enumerate() {
        let a = extract(local, cut, &format!("local{i}.ply"));
        let b = extract(&url, cut, &format!("remote{i}.ply"));
        assert!(a.len() > 1_000, "{cut:?}: {} bytes", a.len());
        assert!(
            a == b,
            "{cut:?}: the remote extract differs from the local one"
        );
    }
    let bad = |target: &str| {
        let o = tessera()
            .args(["extract", target, "--level", "99", "-o"])
            .arg(dir.path().join("bad.ply"))
            .output()
            .unwrap();
        error_line(&o)
    };
    let (el, er) = (bad(local), bad(&url));
    assert!(
        el.contains("out of range") && er.contains("out of range"),
        "{el} / {er}"
    );
    assert!(er.contains(&url), "{er}");
    let o = tessera()
        .args([
            "extract",
            &format!("http://{addr}/models/missing.tsr"),
            "--level",
            "0",
            "-o",
        ])
        .arg(dir.path().join("missing.ply"))
        .output()
        .unwrap();
    let err = error_line(&o);
    assert!(err.contains("not found"), "{err}");
}
