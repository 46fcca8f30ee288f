//! Shared by the remote-reader tests: a built model, a real `tessera serve` in process
//! (stopped gracefully or killed), and a fault-injecting, request-counting TCP proxy.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

use tessera_serve::{ServeOptions, Server};

/// Builds a sphere model of `triangles` into `dir/name`.
pub fn build(dir: &Path, name: &str, triangles: u64, seed: u64) -> PathBuf {
    build_paged(
        dir,
        name,
        triangles,
        seed,
        tessera_format::DEFAULT_PAGE_NODES,
    )
}

/// As [`build`], with `page_nodes` nodes per index page.
pub fn build_paged(dir: &Path, name: &str, triangles: u64, seed: u64, page_nodes: u32) -> PathBuf {
    let ply = dir.join(format!("{name}.ply"));
    let tsr = dir.join(name);
    let opts = tessera_gen::SphereOptions {
        triangles,
        seed,
        ..Default::default()
    };
    tessera_gen::write_sphere(&ply, &opts, &tessera_gen::NoProgress).unwrap();
    let b = tessera_build::BuildOptions {
        leaf_triangles: 400,
        node_triangles: 200,
        threads: Some(2),
        index_page_nodes: page_nodes,
        ..Default::default()
    };
    tessera_build::build(&ply, &tsr, &b, &tessera_build::NoProgress).unwrap();
    std::fs::remove_file(&ply).unwrap();
    tsr
}

/// A running `tessera serve`; stops gracefully when dropped, or is killed.
pub struct Served {
    pub addr: SocketAddr,
    /// `true`: kill (abort every task), `false`: graceful stop.
    stop: Option<tokio::sync::oneshot::Sender<bool>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Served {
    pub fn start(inputs: &[PathBuf]) -> Served {
        Served::start_at(inputs, "127.0.0.1:0".parse().unwrap())
    }

    /// Serves `inputs` at `addr` (retrying a few times while the port is still taken).
    pub fn start_at(inputs: &[PathBuf], addr: SocketAddr) -> Served {
        let rt = tokio::runtime::Runtime::new().unwrap();
        let opts = ServeOptions {
            addr,
            ..Default::default()
        };
        let mut tries = 0;
        let server = loop {
            match rt.block_on(Server::bind(inputs, opts.clone())) {
                Ok(s) => break s,
                Err(e) if tries < 50 => {
                    tries += 1;
                    eprintln!("bind {addr}: {e}; retrying");
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(e) => panic!("bind {addr}: {e}"),
            }
        };
        let addr = server.local_addr();
        let (tx, rx) = tokio::sync::oneshot::channel::<bool>();
        let thread = std::thread::spawn(move || {
            rt.block_on(async move {
                let (graceful_tx, graceful_rx) = tokio::sync::oneshot::channel::<()>();
                let run = tokio::spawn(server.run(async move {
                    let _ = graceful_rx.await;
                }));
                if rx.await.unwrap_or(false) {
                    run.abort();
                } else {
                    let _ = graceful_tx.send(());
                    let _ = run.await;
                }
            });
            // Dropping the runtime cancels every connection task mid-response.
            drop(rt);
        });
        Served {
            addr,
            stop: Some(tx),
            thread: Some(thread),
        }
    }

    pub fn url(&self, name: &str) -> String {
        format!("http://{}/models/{name}", self.addr)
    }

    /// Kills the server as a crash would: responses in flight are cut, the port closes.
    pub fn kill(mut self) {
        self.finish(true);
    }

    fn finish(&mut self, kill: bool) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(kill);
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.finish(false);
    }
}

/// What the proxy does to each request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// Forwards request and response unchanged.
    Pass = 0,
    /// Closes the connection without answering (a connection reset).
    Reset = 1,
    /// Forwards the response head and only half its body, then closes.
    Truncate = 2,
    /// Strips `Range` and `If-Range`, so the server answers `200` with the whole file.
    Whole = 3,
}

/// A TCP proxy in front of a server: one upstream connection per request
/// (`Connection: close`), faults injected by [`Fault`], requests counted, the most
/// requests in flight at once recorded, an optional delay per request.
pub struct Proxy {
    pub addr: SocketAddr,
    state: Arc<ProxyState>,
}

struct ProxyState {
    upstream: SocketAddr,
    fault: AtomicU8,
    delay_ms: AtomicU64,
    requests: AtomicU64,
    /// Requests per fault mode.
    by_fault: [AtomicU64; 4],
    in_flight: AtomicU64,
    max_in_flight: AtomicU64,
}

impl Proxy {
    pub fn start(upstream: SocketAddr) -> Proxy {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        let state = Arc::new(ProxyState {
            upstream,
            fault: AtomicU8::new(Fault::Pass as u8),
            delay_ms: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            by_fault: Default::default(),
            in_flight: AtomicU64::new(0),
            max_in_flight: AtomicU64::new(0),
        });
        let st = state.clone();
        std::thread::spawn(move || {
            for c in l.incoming() {
                let Ok(c) = c else { continue };
                let st = st.clone();
                std::thread::spawn(move || handle(c, &st));
            }
        });
        Proxy { addr, state }
    }

    pub fn url(&self, name: &str) -> String {
        format!("http://{}/models/{name}", self.addr)
    }

    pub fn set_fault(&self, f: Fault) {
        self.state.fault.store(f as u8, Ordering::SeqCst);
    }

    pub fn set_delay(&self, d: Duration) {
        self.state
            .delay_ms
            .store(d.as_millis() as u64, Ordering::SeqCst);
    }

    /// Requests received.
    pub fn requests(&self) -> u64 {
        self.state.requests.load(Ordering::SeqCst)
    }

    /// Requests received while `f` was set.
    pub fn requests_with(&self, f: Fault) -> u64 {
        self.state.by_fault[f as usize].load(Ordering::SeqCst)
    }

    /// The most requests in flight at once.
    pub fn max_in_flight(&self) -> u64 {
        self.state.max_in_flight.load(Ordering::SeqCst)
    }
}

/// The request head (through the blank line), or `None` at end of stream.
pub fn read_head(c: &mut TcpStream) -> Option<Vec<u8>> {
    let mut buf = Vec::new();
    let mut byte = [0u8; 1];
    while !buf.ends_with(b"\r\n\r\n") {
        match c.read(&mut byte) {
            Ok(1) => buf.push(byte[0]),
            _ => return None,
        }
        if buf.len() > 64 << 10 {
            return None;
        }
    }
    Some(buf)
}

fn handle(mut c: TcpStream, st: &ProxyState) {
    let _ = c.set_read_timeout(Some(Duration::from_secs(20)));
    let Some(head) = read_head(&mut c) else {
        return;
    };
    let fault = st.fault.load(Ordering::SeqCst);
    st.requests.fetch_add(1, Ordering::SeqCst);
    st.by_fault[fault as usize].fetch_add(1, Ordering::SeqCst);
    let now = st.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
    st.max_in_flight.fetch_max(now, Ordering::SeqCst);
    let delay = st.delay_ms.load(Ordering::SeqCst);
    if delay > 0 {
        std::thread::sleep(Duration::from_millis(delay));
    }
    let resp = (fault != Fault::Reset as u8)
        .then(|| forward(&head, fault, st.upstream))
        .flatten();
    // Out of flight once answered (the client may send its next request as soon as it
    // has read this one: counting the write would count one request twice).
    st.in_flight.fetch_sub(1, Ordering::SeqCst);
    if let Some(resp) = resp {
        let _ = c.write_all(&resp);
    }
    let _ = c.shutdown(Shutdown::Both);
}

/// The upstream's response to `head` (faults applied); `None` when it is down.
fn forward(head: &[u8], fault: u8, upstream: SocketAddr) -> Option<Vec<u8>> {
    let text = String::from_utf8_lossy(head);
    let mut out = String::new();
    for line in text.split("\r\n").filter(|l| !l.is_empty()) {
        let name = line.split(':').next().unwrap_or("").to_ascii_lowercase();
        let stripped = fault == Fault::Whole as u8 && (name == "range" || name == "if-range");
        if name != "connection" && !stripped {
            out.push_str(line);
            out.push_str("\r\n");
        }
    }
    out.push_str("Connection: close\r\n\r\n");
    // The server down: the client sees its connection closed.
    let mut u = TcpStream::connect(upstream).ok()?;
    let _ = u.set_read_timeout(Some(Duration::from_secs(20)));
    u.write_all(out.as_bytes()).ok()?;
    let mut resp = Vec::new();
    let _ = u.read_to_end(&mut resp);
    if fault == Fault::Truncate as u8 {
        let body = resp
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .map_or(0, |p| p + 4);
        let keep = body + (resp.len() - body) / 2;
        resp.truncate(keep);
    }
    Some(resp)
}
