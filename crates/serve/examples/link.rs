//! A userspace slow-link simulator for the streaming benchmarks, loopback only: a TCP
//! proxy between a client and `tessera serve` that delays every byte by a fixed one-way
//! latency and limits each direction to a fixed rate (a token bucket; data is delayed,
//! never dropped). It stands in for `tc qdisc ... netem delay 20ms rate 20mbit`, which the
//! kernels of our build machines do not have ("Specified qdisc kind is unknown", also
//! inside `ip netns`).
//!
//! The model of the link: each direction is one transmitter shared by all connections
//! (one access link, as a home line is); a chunk read from the sender (at most 4 KiB, so
//! the store-and-forward error stays under 2 ms at 20 Mbit/s) leaves the transmitter once
//! the bucket (depth 16 KiB) has its bytes, and arrives `--delay-ms` later. Backpressure:
//! at most about one bandwidth-delay product plus 256 KiB is queued per connection and
//! direction; beyond that the proxy stops reading, so TCP flow control slows the sender.
//! What it does not model: loss, reordering, jitter, a queue shared by both directions.
//!
//! On SIGINT or SIGTERM (or `--seconds` elapsed) it prints one summary line: connections,
//! HTTP requests (request lines seen), bytes each way, and the milliseconds from the first to the last byte delivered.
//! `--log FILE` writes one line per delivered chunk: `ms_since_start conn dir bytes`
//! (`dir` is `up`, client to server, or `down`).
//!
//! `cargo run -p tessera-serve --example link -- LISTEN UPSTREAM [--delay-ms 20] [--rate-mbit 20] [--log FILE]`
//! (LISTEN, e.g. `127.0.0.1:0`: the bound address is printed first, `listening on ADDR`.)

use std::io::Write;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::time::Instant;

const CHUNK: usize = 4 << 10;
const BURST_BYTES: f64 = 16384.0;

/// One direction of the link: a token bucket kept as a virtual clock (the instant the
/// transmitter is free again), shared by every connection.
struct Direction {
    name: &'static str,
    free_at: Mutex<Instant>,
    secs_per_byte: f64,
    bytes: AtomicU64,
}

impl Direction {
    /// When a chunk of `n` bytes read now has left the transmitter.
    fn transmit(&self, n: usize) -> Instant {
        let now = Instant::now();
        let burst = Duration::from_secs_f64(BURST_BYTES * self.secs_per_byte);
        let mut free = self.free_at.lock().unwrap();
        let start = (*free).max(now.checked_sub(burst).unwrap_or(now));
        *free = start + Duration::from_secs_f64(n as f64 * self.secs_per_byte);
        (*free).max(now)
    }
}

struct Link {
    start: Instant,
    delay: Duration,
    up: Direction,
    down: Direction,
    connections: AtomicU64,
    /// HTTP/1.1 request lines seen going up (a count for the benchmarks; a line split
    /// across two reads is missed).
    requests: AtomicU64,
    first_ms: AtomicU64,
    last_ms: AtomicU64,
    log: Option<Mutex<std::io::BufWriter<std::fs::File>>>,
    queue_chunks: usize,
}

impl Link {
    fn delivered(&self, conn: u64, dir: &Direction, n: usize) {
        dir.bytes.fetch_add(n as u64, Ordering::Relaxed);
        let ms = self.start.elapsed().as_millis() as u64;
        self.first_ms.fetch_min(ms, Ordering::Relaxed);
        self.last_ms.fetch_max(ms, Ordering::Relaxed);
        if let Some(log) = &self.log {
            let _ = writeln!(log.lock().unwrap(), "{ms} {conn} {} {n}", dir.name);
        }
    }

    fn summary(&self) -> String {
        let first = self.first_ms.load(Ordering::Relaxed);
        let last = self.last_ms.load(Ordering::Relaxed);
        format!(
            "link: {} connections, {} requests, up {} bytes, down {} bytes, first-to-last byte {} ms",
            self.connections.load(Ordering::Relaxed),
            self.requests.load(Ordering::Relaxed),
            self.up.bytes.load(Ordering::Relaxed),
            self.down.bytes.load(Ordering::Relaxed),
            last.saturating_sub(first.min(last)),
        )
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: link LISTEN UPSTREAM [--delay-ms 20] [--rate-mbit 20] [--log FILE] [--seconds S]";
    let addr = |i: usize| -> SocketAddr {
        let a: SocketAddr = args.get(i).and_then(|s| s.parse().ok()).unwrap_or_else(|| {
            eprintln!("{usage}");
            std::process::exit(2)
        });
        assert!(a.ip().is_loopback(), "loopback only");
        a
    };
    let (listen, upstream) = (addr(0), addr(1));
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let num = |name: &str, default: f64| -> f64 {
        opt(name).map_or(default, |v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}: not a number: {v}"))
        })
    };
    let delay = Duration::from_secs_f64(num("--delay-ms", 20.0).max(0.0) / 1e3);
    let rate_bytes = num("--rate-mbit", 20.0).max(0.01) * 1e6 / 8.0;
    let seconds = num("--seconds", 0.0);
    let log = opt("--log").map(|p| {
        let f = std::fs::File::create(p).unwrap_or_else(|e| panic!("{p}: {e}"));
        Mutex::new(std::io::BufWriter::new(f))
    });
    let bdp = rate_bytes * delay.as_secs_f64() + 256.0 * 1024.0;
    let direction = |name| Direction {
        name,
        free_at: Mutex::new(Instant::now()),
        secs_per_byte: 1.0 / rate_bytes,
        bytes: AtomicU64::new(0),
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime");
    rt.block_on(async move {
        let link = Arc::new(Link {
            start: Instant::now(),
            delay,
            up: direction("up"),
            down: direction("down"),
            connections: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            first_ms: AtomicU64::new(u64::MAX),
            last_ms: AtomicU64::new(0),
            log,
            queue_chunks: (bdp / CHUNK as f64).ceil() as usize + 1,
        });
        let listener = TcpListener::bind(listen).await.expect("bind LISTEN");
        println!("listening on {}", listener.local_addr().unwrap());
        let _ = std::io::stdout().flush();
        let accept = {
            let link = link.clone();
            async move {
                loop {
                    let Ok((client, _)) = listener.accept().await else {
                        continue;
                    };
                    let link = link.clone();
                    tokio::spawn(async move {
                        let Ok(server) = TcpStream::connect(upstream).await else {
                            return;
                        };
                        let conn = link.connections.fetch_add(1, Ordering::Relaxed);
                        // The client's connect returned at once; on the simulated link its
                        // handshake takes a round trip, so nothing it sends leaves before.
                        let handshake = Some(Instant::now() + 2 * link.delay);
                        let _ = client.set_nodelay(true);
                        let _ = server.set_nodelay(true);
                        let (cr, cw) = client.into_split();
                        let (sr, sw) = server.into_split();
                        let up = tokio::spawn(pump(link.clone(), conn, handshake, cr, sw));
                        pump(link, conn, None, sr, cw).await;
                        let _ = up.await;
                    });
                }
            }
        };
        let stop = async {
            let mut term =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                    .expect("SIGTERM handler");
            let timer = async {
                if seconds > 0.0 {
                    tokio::time::sleep(Duration::from_secs_f64(seconds)).await
                } else {
                    std::future::pending().await
                }
            };
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
                _ = timer => {}
            }
        };
        tokio::select! {
            _ = accept => {}
            _ = stop => {}
        }
        if let Some(log) = &link.log {
            let _ = log.lock().unwrap().flush();
        }
        println!("{}", link.summary());
    });
    rt.shutdown_background();
}

/// Copies one direction of one connection through the link: a reader stamps each chunk
/// with its arrival time, a writer sleeps until then and writes it. A writer that fails
/// drops its queue, which stops the reader at its next chunk.
/// `handshake` is given for the client-to-server direction only (`up`).
async fn pump(
    link: Arc<Link>,
    conn: u64,
    handshake: Option<Instant>,
    mut from: OwnedReadHalf,
    mut to: OwnedWriteHalf,
) {
    let up = handshake.is_some();
    let (tx, mut rx) = mpsc::channel::<(Instant, Vec<u8>)>(link.queue_chunks);
    let reader = {
        let link = link.clone();
        async move {
            let dir = if up { &link.up } else { &link.down };
            loop {
                let mut buf = vec![0u8; CHUNK];
                match read(&mut from, &mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        buf.truncate(n);
                        if up {
                            let lines = buf.windows(11).filter(|w| w == b" HTTP/1.1\r\n");
                            link.requests
                                .fetch_add(lines.count() as u64, Ordering::Relaxed);
                        }
                        let sent = dir.transmit(n);
                        let at = handshake.map_or(sent, |h| sent.max(h)) + link.delay;
                        if tx.send((at, buf)).await.is_err() {
                            break;
                        }
                    }
                }
            }
        }
    };
    let writer = async move {
        let dir = if up { &link.up } else { &link.down };
        while let Some((at, buf)) = rx.recv().await {
            tokio::time::sleep_until(at).await;
            if write_all(&mut to, &buf).await.is_err() {
                return;
            }
            link.delivered(conn, dir, buf.len());
        }
        // The sender closed its side: dropping `to` passes the half-close on.
    };
    tokio::join!(reader, writer);
}

// Plain readiness loops: tokio's `io-util` feature is not in this crate's dependency set.
async fn read(from: &mut OwnedReadHalf, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        from.readable().await?;
        match from.try_read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => continue,
            r => return r,
        }
    }
}

async fn write_all(to: &mut OwnedWriteHalf, mut buf: &[u8]) -> std::io::Result<()> {
    while !buf.is_empty() {
        to.writable().await?;
        match to.try_write(buf) {
            Ok(n) => buf = &buf[n..],
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(e) => return Err(e),
        }
    }
    Ok(())
}
