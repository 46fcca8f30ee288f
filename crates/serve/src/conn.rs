//! The accept loop: a bounded number of HTTP/1.1 connections, each with a header read
//! timeout (hyper's, which also covers idle keep-alive time), a size limit on request
//! heads and a write-stall timeout; graceful shutdown.
//!
//! Accept errors (EMFILE when the descriptors run out, ENFILE, ENOBUFS) repeat for as
//! long as their cause lasts and a connection waits in the backlog: under `ulimit -n 64`
//! the old loop logged 20 lines a second. [`AcceptBackoff`] logs the first error at
//! once and then at most one line a second with the count, and backs off accepting
//! (50 ms doubling to 1 s) until an accept succeeds.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};
use tokio::time::{Instant, Sleep};

use crate::ServeOptions;

pub async fn accept_loop(
    listener: TcpListener,
    app: Router,
    opts: &ServeOptions,
    shutdown: impl Future<Output = ()> + Send,
) -> io::Result<()> {
    let max = opts.max_connections.clamp(1, Semaphore::MAX_PERMITS) as u32;
    let permits = Arc::new(Semaphore::new(max as usize));
    let (stop_tx, stop_rx) = watch::channel(false);
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(opts.header_read_timeout)
        .max_buf_size(opts.max_header_bytes.max(8192))
        .keep_alive(true);
    let service = TowerToHyperService::new(app);
    let mut backoff = AcceptBackoff::default();
    tokio::pin!(shutdown);
    loop {
        let permit = tokio::select! {
            _ = &mut shutdown => break,
            p = permits.clone().acquire_owned() => match p {
                Ok(p) => p,
                Err(_) => break,
            },
        };
        let (stream, peer) = tokio::select! {
            _ = &mut shutdown => break,
            r = listener.accept() => match r {
                Ok(x) => x,
                Err(e) => {
                    // EMFILE and friends: back off instead of spinning.
                    let wait = backoff.failed(std::time::Instant::now(), |n, over| {
                        if n <= 1 {
                            tracing::warn!("accept failed: {e} (backing off)");
                        } else {
                            tracing::warn!(
                                "accept failed {n} times in the last {:.1} s: {e} (backing off)",
                                over.as_secs_f64()
                            );
                        }
                    });
                    tokio::time::sleep(wait).await;
                    continue;
                }
            },
        };
        backoff.succeeded(std::time::Instant::now(), |n| {
            tracing::info!("accepting again after {n} failed accept(s)")
        });
        let _ = stream.set_nodelay(true);
        let io = TokioIo::new(StallGuard::new(stream, opts.write_timeout));
        let conn = http.serve_connection(io, service.clone());
        let stop = stop_rx.clone();
        tokio::spawn(async move {
            let _permit = permit;
            tokio::pin!(conn);
            let r = tokio::select! {
                r = conn.as_mut() => r,
                _ = stopped(stop) => {
                    conn.as_mut().graceful_shutdown();
                    conn.await
                }
            };
            if let Err(e) = r {
                tracing::debug!("connection from {peer}: {e}");
            }
        });
    }
    drop(listener);
    let _ = stop_tx.send(true);
    // Every connection holds a permit: all of them back means all are done.
    match tokio::time::timeout(opts.shutdown_grace, permits.acquire_many(max)).await {
        Ok(_) => {}
        Err(_) => tracing::warn!(
            "shutdown: {} connection(s) still busy after {:?}; closing them",
            max as usize - permits.available_permits(),
            opts.shutdown_grace
        ),
    }
    Ok(())
}

/// First wait after a failed accept.
const ACCEPT_BACKOFF_MIN: Duration = Duration::from_millis(50);
/// Longest wait between accepts while they fail (a freed descriptor is used within it).
const ACCEPT_BACKOFF_MAX: Duration = Duration::from_secs(1);
/// At most one accept warning per this interval.
const ACCEPT_LOG_EVERY: Duration = Duration::from_secs(1);

/// Rate-limited logging and exponential backoff of failing accepts; the clock is a
/// parameter so the policy is tested without waiting.
#[derive(Debug, Default)]
pub struct AcceptBackoff {
    /// The wait before the next accept while they fail (zero: none failed).
    delay: Duration,
    /// When the last warning was logged.
    last_log: Option<std::time::Instant>,
    /// Failures since the last warning (not yet reported).
    unreported: u64,
    /// Failures in the current run of them.
    run: u64,
}

impl AcceptBackoff {
    /// Records a failed accept at `now`; calls `log(count, over)` when a warning is due
    /// (the first failure, then at most one each [`ACCEPT_LOG_EVERY`], with the failures
    /// counted since the last one) and returns how long to wait before accepting again.
    pub fn failed(&mut self, now: std::time::Instant, log: impl FnOnce(u64, Duration)) -> Duration {
        self.unreported += 1;
        self.run += 1;
        match self.last_log {
            Some(t) if now.duration_since(t) < ACCEPT_LOG_EVERY => {}
            Some(t) => {
                log(self.unreported, now.duration_since(t));
                self.unreported = 0;
                self.last_log = Some(now);
            }
            None => {
                log(self.unreported, Duration::ZERO);
                self.unreported = 0;
                self.last_log = Some(now);
            }
        }
        self.delay = if self.delay.is_zero() {
            ACCEPT_BACKOFF_MIN
        } else {
            (self.delay * 2).min(ACCEPT_BACKOFF_MAX)
        };
        self.delay
    }

    /// Records a successful accept; after a run of failures calls `log(failures)` once.
    pub fn succeeded(&mut self, now: std::time::Instant, log: impl FnOnce(u64)) {
        if self.run > 0 {
            log(self.run);
        }
        self.delay = Duration::ZERO;
        self.run = 0;
        self.unreported = 0;
        // The next failure after a recovery is reported at once (not the rest of a run).
        self.last_log = self
            .last_log
            .filter(|t| now.duration_since(*t) < ACCEPT_LOG_EVERY);
    }
}

/// Completes once shutdown is signalled.
async fn stopped(mut rx: watch::Receiver<bool>) {
    loop {
        if *rx.borrow_and_update() {
            return;
        }
        if rx.changed().await.is_err() {
            std::future::pending::<()>().await;
        }
    }
}

/// A TCP stream whose writes fail with `TimedOut` once they have made no progress for
/// `timeout`: a client that stops reading its response cannot hold a connection forever.
struct StallGuard {
    inner: TcpStream,
    timeout: Duration,
    stall: Pin<Box<Sleep>>,
    armed: bool,
}

impl StallGuard {
    fn new(inner: TcpStream, timeout: Duration) -> StallGuard {
        StallGuard {
            inner,
            timeout,
            stall: Box::pin(tokio::time::sleep(timeout)),
            armed: false,
        }
    }

    /// Called with the result of a write-side poll.
    fn check<T>(&mut self, cx: &mut Context<'_>, r: Poll<io::Result<T>>) -> Poll<io::Result<T>> {
        match r {
            Poll::Ready(x) => {
                self.armed = false;
                Poll::Ready(x)
            }
            Poll::Pending => {
                if !self.armed {
                    self.armed = true;
                    let deadline = Instant::now() + self.timeout;
                    self.stall.as_mut().reset(deadline);
                }
                match self.stall.as_mut().poll(cx) {
                    Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        "client stopped reading",
                    ))),
                    Poll::Pending => Poll::Pending,
                }
            }
        }
    }
}

impl AsyncRead for StallGuard {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl AsyncWrite for StallGuard {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        self.check(cx, r)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        self.check(cx, r)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let r = Pin::new(&mut self.inner).poll_flush(cx);
        self.check(cx, r)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let r = Pin::new(&mut self.inner).poll_shutdown(cx);
        self.check(cx, r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 29: `ulimit -n 64` flooded the log with 20 "accept failed" lines a second.
    /// Failing accepts every 50 ms for 10 s now log at most one line a second, and the
    /// waits grow to a second.
    #[test]
    fn accept_errors_are_rate_limited_and_backed_off() {
        let mut b = AcceptBackoff::default();
        let t0 = std::time::Instant::now();
        let (mut lines, mut counted, mut waits) = (0u64, 0u64, Vec::new());
        let mut t = t0;
        while t < t0 + Duration::from_secs(10) {
            let w = b.failed(t, |n, _| {
                lines += 1;
                counted += n;
            });
            waits.push(w);
            t += Duration::from_millis(50);
        }
        let failures = waits.len() as u64;
        assert!(
            lines <= 11,
            "{lines} warnings for {failures} failures in 10 s"
        );
        assert!(lines >= 9, "{lines}: failures must still be reported");
        assert!(counted <= failures && counted + 20 >= failures);
        assert_eq!(waits[0], ACCEPT_BACKOFF_MIN);
        assert_eq!(*waits.last().unwrap(), ACCEPT_BACKOFF_MAX);
        let mut recovered = 0;
        b.succeeded(t, |n| recovered = n);
        assert_eq!(recovered, failures);
        assert_eq!(b.failed(t, |_, _| {}), ACCEPT_BACKOFF_MIN);
    }
}
