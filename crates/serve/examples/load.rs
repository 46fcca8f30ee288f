//! A load smoke test for `tessera serve`, loopback only: N concurrent clients (one
//! keep-alive connection each) issue random valid range requests for a bounded time and
//! check every body against the local file; optionally a share of hostile requests
//! (garbage, traversal, huge heads, bad ranges) on fresh connections, which must get a
//! 4xx or be closed. Prints requests, errors, throughput and latency percentiles.
//!
//! `cargo run -p tessera-serve --example load -- URL FILE [--clients 100] [--seconds 10] [--hostile PCT]`

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: load URL FILE [--clients N] [--seconds S] [--hostile PCT]";
    let (url, file) = match (args.first(), args.get(1)) {
        (Some(u), Some(f)) => (u.clone(), f.clone()),
        _ => {
            eprintln!("{usage}");
            std::process::exit(2);
        }
    };
    let opt = |name: &str, default: u64| -> u64 {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map(|v| {
                v.parse()
                    .unwrap_or_else(|_| panic!("{name}: not a number: {v}"))
            })
            .unwrap_or(default)
    };
    // Bounded whatever is asked.
    let clients = opt("--clients", 100).clamp(1, 2000);
    let seconds = opt("--seconds", 10).clamp(1, 120);
    let hostile = opt("--hostile", 0).min(100);
    let host = url
        .strip_prefix("http://")
        .and_then(|r| r.split('/').next())
        .expect("an http:// URL");
    let addr: SocketAddr = host.parse().expect("URL host must be IP:PORT");
    assert!(addr.ip().is_loopback(), "loopback only");
    let bytes = std::fs::read(&file).expect("reading FILE");
    let len = bytes.len() as u64;
    // Every client opens its keep-alive connection with a first request, then all start
    // together: `clients` connections are open at once for the whole run.
    let ready = std::sync::Barrier::new(clients as usize);
    let t0 = std::sync::OnceLock::<Instant>::new();

    struct Out {
        lat_us: Vec<u32>,
        errors: Vec<String>,
        body_bytes: u64,
        hostile: u64,
    }
    let outs: Vec<Out> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..clients)
            .map(|c| {
                let (url, bytes, ready, t0) = (&url, &bytes, &ready, &t0);
                std::thread::Builder::new()
                    .stack_size(256 << 10)
                    .spawn_scoped(sc, move || {
                        let agent = ureq::Agent::new_with_config(
                            ureq::Agent::config_builder()
                                .http_status_as_error(false)
                                .timeout_global(Some(Duration::from_secs(30)))
                                .build(),
                        );
                        let mut rng = c.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
                        let mut next = move || {
                            rng ^= rng << 13;
                            rng ^= rng >> 7;
                            rng ^= rng << 17;
                            rng
                        };
                        let mut out = Out {
                            lat_us: Vec::new(),
                            errors: Vec::new(),
                            body_bytes: 0,
                            hostile: 0,
                        };
                        let valid = |out: &mut Out, a: u64, b: u64| {
                            let t = Instant::now();
                            let r = agent
                                .get(url.as_str())
                                .header("Range", format!("bytes={a}-{b}"))
                                .call();
                            let r = r.map_err(|e| e.to_string()).and_then(|mut r| {
                                let status = r.status().as_u16();
                                let body = r
                                    .body_mut()
                                    .with_config()
                                    .limit(1 << 30)
                                    .read_to_vec()
                                    .map_err(|e| e.to_string())?;
                                Ok((status, body))
                            });
                            out.lat_us
                                .push(t.elapsed().as_micros().min(u32::MAX as u128) as u32);
                            match r {
                                Ok((206, body)) if body[..] == bytes[a as usize..=b as usize] => {
                                    out.body_bytes += body.len() as u64
                                }
                                Ok((206, _)) => {
                                    out.errors.push(format!("bytes {a}-{b}: wrong body"))
                                }
                                Ok((s, _)) => out.errors.push(format!("bytes {a}-{b}: status {s}")),
                                Err(e) => out.errors.push(format!("bytes {a}-{b}: {e}")),
                            }
                        };
                        valid(&mut out, 0, 0);
                        if ready.wait().is_leader() {
                            t0.get_or_init(Instant::now);
                        }
                        ready.wait();
                        let deadline = t0.get().copied().unwrap_or_else(Instant::now)
                            + Duration::from_secs(seconds);
                        while Instant::now() < deadline {
                            if hostile > 0 && next() % 100 < hostile {
                                out.hostile += 1;
                                if let Err(e) = hostile_request(addr, next()) {
                                    out.errors.push(e);
                                }
                                continue;
                            }
                            let a = next() % len;
                            let b = a + next() % (len - a).min(256 << 10);
                            valid(&mut out, a, b);
                        }
                        out
                    })
                    .expect("spawning a client thread")
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let wall = t0
        .get()
        .map_or(0.0, |t| t.elapsed().as_secs_f64())
        .max(1e-3);
    let mut lat: Vec<u32> = outs.iter().flat_map(|o| o.lat_us.iter().copied()).collect();
    lat.sort_unstable();
    let errors: Vec<&String> = outs.iter().flat_map(|o| o.errors.iter()).collect();
    let body: u64 = outs.iter().map(|o| o.body_bytes).sum();
    let hostile_n: u64 = outs.iter().map(|o| o.hostile).sum();
    let pct = |p: f64| {
        lat.get(((lat.len() as f64 * p) as usize).min(lat.len().saturating_sub(1)))
            .map_or(0.0, |&u| u as f64 / 1e3)
    };
    println!(
        "clients {clients}, {seconds} s, {} range requests ({:.0}/s), {hostile_n} hostile",
        lat.len(),
        lat.len() as f64 / wall
    );
    println!(
        "body bytes checked {:.1} MiB ({:.1} MiB/s)",
        body as f64 / 1048576.0,
        body as f64 / 1048576.0 / wall
    );
    println!(
        "latency ms: p50 {:.2}  p99 {:.2}  max {:.2}",
        pct(0.50),
        pct(0.99),
        pct(1.0)
    );
    println!("errors {}", errors.len());
    for e in errors.iter().take(10) {
        println!("  {e}");
    }
    if !errors.is_empty() {
        std::process::exit(1);
    }
}

/// One hostile request on a fresh connection: it must get a 4xx (or be closed).
fn hostile_request(addr: SocketAddr, pick: u64) -> Result<(), String> {
    let big = "a".repeat(40 << 10);
    let reqs: [Vec<u8>; 8] = [
        b"GET /models/../../etc/passwd HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".to_vec(),
        b"GET /models/%2e%2e%2fsecret HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".to_vec(),
        b"GARBAGE GARBAGE\r\n\r\n".to_vec(),
        format!("GET /models/x HTTP/1.1\r\nHost: x\r\nX: {big}\r\n\r\n").into_bytes(),
        b"POST /api/models HTTP/1.1\r\nHost: x\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc".to_vec(),
        b"GET /models/nope.tsr HTTP/1.1\r\nHost: x\r\nRange: bytes=-\r\nConnection: close\r\n\r\n".to_vec(),
        b"\x16\x03\x01\x00\xff\x01\x00".to_vec(),
        b"GET /models/a%00.tsr HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".to_vec(),
    ];
    let req = &reqs[(pick % reqs.len() as u64) as usize];
    let mut s = TcpStream::connect(addr).map_err(|e| format!("hostile connect: {e}"))?;
    s.set_read_timeout(Some(Duration::from_secs(30))).ok();
    let _ = s.write_all(req);
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    if buf.is_empty() {
        return Ok(()); // closed: refused
    }
    let status = String::from_utf8_lossy(&buf[..buf.len().min(12)]).into_owned();
    match status.get(9..10) {
        Some("4") => Ok(()),
        _ => Err(format!(
            "hostile request {}: answered {status:?}",
            pick % reqs.len() as u64
        )),
    }
}
