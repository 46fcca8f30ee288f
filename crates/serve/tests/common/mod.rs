//! Shared by the server's integration tests: a small built model, a server started on
//! its own thread within a time limit, raw requests, and the warnings logged.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use tessera_serve::{ServeError, ServeOptions, Server};

/// Builds a small sphere model (cached per process) and returns its bytes.
pub fn built(seed: u64, triangles: u64) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("sphere.ply");
    let tsr = dir.path().join("sphere.tsr");
    tessera_gen::write_sphere(
        &ply,
        &tessera_gen::SphereOptions {
            triangles,
            seed,
            colors: false,
            noise: 0.05,
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    tessera_build::build(
        &ply,
        &tsr,
        &tessera_build::BuildOptions {
            leaf_triangles: 400,
            node_triangles: 200,
            threads: Some(2),
            ..Default::default()
        },
        &tessera_build::NoProgress,
    )
    .unwrap();
    std::fs::read(&tsr).unwrap()
}

// ---------------------------------------------------------------- the log

/// Every warning logged in this process (tests filter by their own temporary paths).
static WARNINGS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// A `tracing` subscriber that keeps the message of every warning.
struct Capture;

struct Message<'a>(&'a mut String);

impl tracing::field::Visit for Message<'_> {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0.push_str(&format!("{value:?}"));
        }
    }
}

impl tracing::Subscriber for Capture {
    fn enabled(&self, m: &tracing::Metadata<'_>) -> bool {
        *m.level() <= tracing::Level::WARN
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, e: &tracing::Event<'_>) {
        let mut s = String::new();
        e.record(&mut Message(&mut s));
        WARNINGS.lock().unwrap().push(s);
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

pub fn capture_warnings() {
    static ONCE: OnceLock<()> = OnceLock::new();
    ONCE.get_or_init(|| {
        let _ = tracing::subscriber::set_global_default(Capture);
    });
}

/// Warnings that mention every one of `parts`.
pub fn warnings_with(parts: &[&str]) -> Vec<String> {
    WARNINGS
        .lock()
        .unwrap()
        .iter()
        .filter(|w| parts.iter().all(|p| w.contains(p)))
        .cloned()
        .collect()
}

// ---------------------------------------------------------------- server

/// A server on its own thread and runtime, stopped gracefully when dropped.
pub struct TestServer {
    pub addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<Result<(), ServeError>>>,
}

impl TestServer {
    /// Binds and serves `inputs`; panics if that takes over 20 s (a startup that blocks,
    /// as the old code did on a FIFO).
    pub fn start(inputs: &[PathBuf], opts: ServeOptions) -> Result<TestServer, ServeError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let inputs = inputs.to_vec();
        let thread = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                let server = match Server::bind(&inputs, opts).await {
                    Ok(s) => s,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return Ok(());
                    }
                };
                let _ = ready_tx.send(Ok(server.local_addr()));
                server
                    .run(async {
                        let _ = rx.await;
                    })
                    .await
            })
        });
        let addr = ready_rx
            .recv_timeout(Duration::from_secs(20))
            .expect("the server did not start within 20 s")?;
        Ok(TestServer {
            addr,
            stop: Some(tx),
            thread: Some(thread),
        })
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// Signals shutdown and waits for the server to return; how long that took.
    pub fn stop(&mut self) -> Duration {
        let t = Instant::now();
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            t.join().unwrap().unwrap();
        }
        t.elapsed()
    }
}

impl Drop for TestServer {
    fn drop(&mut self) {
        self.stop();
    }
}

pub struct Resp {
    pub status: u16,
    pub head: String,
    pub body: Vec<u8>,
}

impl Resp {
    pub fn header(&self, name: &str) -> Option<String> {
        self.head.split("\r\n").find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim()
                .eq_ignore_ascii_case(name)
                .then(|| v.trim().to_string())
        })
    }
}

/// One request on a fresh connection, answered within 10 s (else a panic).
pub fn request(addr: SocketAddr, method: &str, path: &str, extra: &str) -> Resp {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: x\r\n{extra}Connection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf)
        .unwrap_or_else(|e| panic!("{method} {path}: no answer: {e}"));
    let end = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a response head");
    let head = String::from_utf8_lossy(&buf[..end]).to_string();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    Resp {
        status,
        head,
        body: buf[end + 4..].to_vec(),
    }
}

/// Options for the hostile-directory tests: a free port, rescans every 100 ms, no
/// viewer.
pub fn quick_opts() -> ServeOptions {
    ServeOptions {
        addr: "127.0.0.1:0".parse().unwrap(),
        rescan_interval: Duration::from_millis(100),
        embedded_web: false,
        ..ServeOptions::default()
    }
}
