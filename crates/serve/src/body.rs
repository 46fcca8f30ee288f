//! Response bodies: byte ranges of one open file (plain or as `multipart/byteranges`
//! parts), and the access-log wrapper that counts what was really sent.

use std::collections::VecDeque;
use std::fs::File;
use std::future::Future;
use std::io;
use std::os::unix::fs::FileExt;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{ready, Context, Poll};
use std::time::Instant;

use axum::http;
use bytes::Bytes;
use http_body::{Frame, SizeHint};
use tokio::task::JoinHandle;

/// Bytes read from the file per frame.
const CHUNK: u64 = 128 << 10;

/// A piece of a response body.
pub enum Segment {
    /// Literal bytes (multipart boundaries and part headers).
    Bytes(Bytes),
    /// `len` bytes of the file from `offset`.
    File { offset: u64, len: u64 },
}

/// A body made of file ranges and literal bytes, all read from ONE open file: the
/// descriptor that was stat'ed for the ETag and length, so a model renamed over while
/// the response is on its way never mixes bytes of two builds. Reads run on tokio's
/// blocking pool one chunk at a time (`pread`), so a slow client holds no thread.
pub struct FileBody {
    file: Arc<File>,
    segments: VecDeque<Segment>,
    remaining: u64,
    reading: Option<JoinHandle<io::Result<Vec<u8>>>>,
}

impl FileBody {
    pub fn new(file: File, segments: Vec<Segment>) -> FileBody {
        let remaining = segments
            .iter()
            .map(|s| match s {
                Segment::Bytes(b) => b.len() as u64,
                Segment::File { len, .. } => *len,
            })
            .sum();
        FileBody {
            file: Arc::new(file),
            segments: segments.into(),
            remaining,
            reading: None,
        }
    }

    /// Total bytes the body will yield.
    pub fn len(&self) -> u64 {
        self.remaining
    }
}

impl http_body::Body for FileBody {
    type Data = Bytes;
    type Error = io::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, io::Error>>> {
        let this = &mut *self;
        loop {
            if let Some(job) = this.reading.as_mut() {
                let got = ready!(Pin::new(job).poll(cx));
                this.reading = None;
                let chunk = match got {
                    Ok(Ok(c)) => c,
                    Ok(Err(e)) => return Poll::Ready(Some(Err(e))),
                    Err(e) => return Poll::Ready(Some(Err(io::Error::other(e)))),
                };
                this.remaining -= chunk.len() as u64;
                return Poll::Ready(Some(Ok(Frame::data(Bytes::from(chunk)))));
            }
            match this.segments.pop_front() {
                None => return Poll::Ready(None),
                Some(Segment::Bytes(b)) => {
                    if b.is_empty() {
                        continue;
                    }
                    this.remaining -= b.len() as u64;
                    return Poll::Ready(Some(Ok(Frame::data(b))));
                }
                Some(Segment::File { offset, len }) => {
                    if len == 0 {
                        continue;
                    }
                    let n = len.min(CHUNK);
                    if len > n {
                        this.segments.push_front(Segment::File {
                            offset: offset + n,
                            len: len - n,
                        });
                    }
                    let file = this.file.clone();
                    this.reading = Some(tokio::task::spawn_blocking(move || {
                        let mut buf = vec![0u8; n as usize];
                        // A short read means the file shrank under us (rewritten in
                        // place): fail the body, so the client sees a truncated
                        // response rather than wrong bytes.
                        file.read_exact_at(&mut buf, offset)?;
                        Ok(buf)
                    }));
                }
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.remaining == 0 && self.reading.is_none()
    }

    fn size_hint(&self) -> SizeHint {
        SizeHint::with_exact(self.remaining)
    }
}

/// Wraps a response body; writes the access-log line when the body is finished or
/// dropped (the client went away): method, path, status, bytes sent, milliseconds.
pub struct Logged<B> {
    pub inner: B,
    pub method: http::Method,
    pub path: String,
    pub status: u16,
    pub start: Instant,
    pub sent: u64,
    pub done: bool,
}

impl<B> http_body::Body for Logged<B>
where
    B: http_body::Body<Data = Bytes> + Unpin,
{
    type Data = Bytes;
    type Error = B::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, B::Error>>> {
        let this = &mut *self;
        let r = ready!(Pin::new(&mut this.inner).poll_frame(cx));
        match &r {
            Some(Ok(f)) => {
                if let Some(d) = f.data_ref() {
                    this.sent += d.len() as u64;
                }
            }
            None => this.done = true,
            Some(Err(_)) => {}
        }
        if this.inner.is_end_stream() {
            this.done = true;
        }
        Poll::Ready(r)
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

impl<B> Drop for Logged<B> {
    fn drop(&mut self) {
        let ms = self.start.elapsed().as_secs_f64() * 1e3;
        tracing::info!(
            target: "tessera_serve::access",
            "{} {} {} {} bytes {:.1} ms{}",
            self.method,
            self.path,
            self.status,
            self.sent,
            ms,
            if self.done || self.method == http::Method::HEAD { "" } else { " (incomplete)" }
        );
    }
}
