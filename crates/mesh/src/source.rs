//! A buffered byte reader tuned for the binary importers' hot loops.
//!
//! `std::io::BufReader` costs a call and a copy per value; the PLY and STL readers want
//! to borrow a whole record (or a single value) straight out of the buffer after one
//! bounds check. [`Source`] keeps a 1 MiB window over the file, refills it on demand, and
//! knows the absolute byte offset and (for text) nothing more, so memory stays bounded
//! however large the file is.

use std::io::Read;

/// Default window size.
const WINDOW: usize = 1 << 20;

/// Why a low-level read stopped.
#[derive(Debug)]
pub(crate) enum ReadErr {
    /// The file ended before the requested bytes.
    Eof,
    /// The operating system failed the read.
    Io(std::io::Error),
    /// A text token that is not what was expected (message for the user).
    Parse(String),
    /// A vertex index outside `0..vertex_count` (the raw value from the file).
    BadIndex(i64),
    /// A list count the data cannot match (PLY): `at` is where the count is, its byte
    /// offset in binary files or its line in text; `why` completes "list count N ...".
    BadListCount { count: u64, at: u64, why: String },
}

impl From<std::io::Error> for ReadErr {
    fn from(e: std::io::Error) -> Self {
        ReadErr::Io(e)
    }
}

/// A refillable window over a reader.
/// The UTF-8 byte order mark.
const UTF8_BOM: [u8; 3] = [0xEF, 0xBB, 0xBF];

pub(crate) struct Source<R> {
    inner: R,
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    /// Absolute offset of `buf[0]`.
    base: u64,
    /// Newlines consumed so far by the text helpers (for "line N" messages).
    pub(crate) line: u64,
    /// The last byte consumed before the window last slid (see [`Source::last_byte`]).
    prev: Option<u8>,
    /// [`Source::line_into`] returned a last line that the file ends inside (no
    /// newline after it): a file cut short there reads as a shorter, valid line.
    pub(crate) unterminated: bool,
}

/// What [`Source::drain`] found after the last byte a reader consumed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Tail {
    pub bytes: u64,
    /// Bytes other than ASCII whitespace.
    pub non_space: u64,
    /// The file's last byte is a newline.
    pub ends_in_newline: bool,
}

impl<R: Read> Source<R> {
    pub(crate) fn new(inner: R) -> Self {
        Source {
            inner,
            buf: vec![0; WINDOW],
            pos: 0,
            end: 0,
            base: 0,
            line: 1,
            prev: None,
            unterminated: false,
        }
    }

    /// The last byte consumed, if any.
    fn last_byte(&self) -> Option<u8> {
        if self.pos > 0 {
            Some(self.buf[self.pos - 1])
        } else {
            self.prev
        }
    }

    /// Consumes the rest of the file, counting it.
    pub(crate) fn drain(&mut self) -> Result<Tail, ReadErr> {
        let mut tail = Tail {
            ends_in_newline: self.last_byte() == Some(b'\n'),
            ..Tail::default()
        };
        while self.ensure(1)? {
            let window = &self.buf[self.pos..self.end];
            tail.bytes += window.len() as u64;
            tail.non_space += window.iter().filter(|b| !b.is_ascii_whitespace()).count() as u64;
            tail.ends_in_newline = window.last() == Some(&b'\n');
            self.pos = self.end;
        }
        Ok(tail)
    }

    /// Absolute offset of the next unread byte.
    pub(crate) fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    /// Make at least `n` bytes available; `false` when the file ends first.
    #[inline]
    pub(crate) fn ensure(&mut self, n: usize) -> Result<bool, ReadErr> {
        if self.end - self.pos >= n {
            return Ok(true);
        }
        self.refill(n)
    }

    #[cold]
    fn refill(&mut self, n: usize) -> Result<bool, ReadErr> {
        // Slide the unread tail to the front, grow if one request exceeds the window.
        if self.pos > 0 {
            self.prev = Some(self.buf[self.pos - 1]);
        }
        self.buf.copy_within(self.pos..self.end, 0);
        self.base += self.pos as u64;
        self.end -= self.pos;
        self.pos = 0;
        if n > self.buf.len() {
            self.buf.resize(n.next_power_of_two(), 0);
        }
        while self.end < n {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => return Ok(false),
                Ok(k) => self.end += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(ReadErr::Io(e)),
            }
        }
        Ok(true)
    }

    /// Borrow the next `n` bytes and consume them.
    #[inline]
    pub(crate) fn take(&mut self, n: usize) -> Result<&[u8], ReadErr> {
        if !self.ensure(n)? {
            return Err(ReadErr::Eof);
        }
        let start = self.pos;
        self.pos += n;
        Ok(&self.buf[start..start + n])
    }

    /// Skip `n` bytes (any size, without growing the window).
    pub(crate) fn skip(&mut self, mut n: u64) -> Result<(), ReadErr> {
        while n > 0 {
            if !self.ensure(1)? {
                return Err(ReadErr::Eof);
            }
            let step = n.min((self.end - self.pos) as u64);
            self.pos += step as usize;
            n -= step;
        }
        Ok(())
    }

    /// The next byte without consuming it; `None` at end of file.
    #[inline]
    pub(crate) fn peek(&mut self) -> Result<Option<u8>, ReadErr> {
        if !self.ensure(1)? {
            return Ok(None);
        }
        Ok(Some(self.buf[self.pos]))
    }

    /// Read one line (without `\n` / `\r\n`) into `out`, at most `max` bytes.
    /// `false` at end of file with nothing read.
    pub(crate) fn line_into(&mut self, out: &mut Vec<u8>, max: usize) -> Result<bool, ReadErr> {
        out.clear();
        // A UTF-8 byte order mark before the first line (editors on Windows write one)
        // is not part of the text: skipping it keeps the first statement.
        if self.base == 0 && self.pos == 0 && self.ensure(3)? && self.buf[..3] == UTF8_BOM {
            self.pos = 3;
        }
        loop {
            if !self.ensure(1)? {
                if out.last() == Some(&b'\r') {
                    out.pop();
                }
                self.unterminated |= !out.is_empty();
                return Ok(!out.is_empty());
            }
            let window = &self.buf[self.pos..self.end];
            match window.iter().position(|&b| b == b'\n') {
                Some(i) => {
                    out.extend_from_slice(&window[..i]);
                    self.pos += i + 1;
                    self.line += 1;
                    if out.last() == Some(&b'\r') {
                        out.pop();
                    }
                    return check_len(out, max).map(|_| true);
                }
                None => {
                    out.extend_from_slice(window);
                    self.pos = self.end;
                    check_len(out, max)?;
                }
            }
        }
    }

    /// The next whitespace-separated token (counting newlines); `None` at end of file.
    pub(crate) fn token(&mut self) -> Result<Option<&[u8]>, ReadErr> {
        // Skip whitespace.
        loop {
            match self.peek()? {
                None => return Ok(None),
                Some(b) if b.is_ascii_whitespace() => {
                    if b == b'\n' {
                        self.line += 1;
                    }
                    self.pos += 1;
                }
                Some(_) => break,
            }
        }
        // Find the token end inside the window, growing it for a token split at the edge.
        let mut len = 0;
        loop {
            if !self.ensure(len + 1)? {
                break;
            }
            if self.buf[self.pos + len].is_ascii_whitespace() {
                break;
            }
            len += 1;
            if len > 4096 {
                return Err(ReadErr::Parse("token longer than 4096 bytes".into()));
            }
        }
        let start = self.pos;
        self.pos += len;
        Ok(Some(&self.buf[start..start + len]))
    }
}

fn check_len(out: &[u8], max: usize) -> Result<(), ReadErr> {
    if out.len() > max {
        return Err(ReadErr::Parse(format!("line longer than {max} bytes")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_window_refills() {
        let data: Vec<u8> = (0..=255u8).cycle().take(10_000).collect();
        let mut s = Source::new(&data[..]);
        s.buf = vec![0; 7];
        let mut got = Vec::new();
        while let Ok(b) = s.take(3) {
            got.extend_from_slice(b);
        }
        assert_eq!(got.len(), 9999);
        assert_eq!(&got[..], &data[..9999]);
        assert!(s.take(1).is_ok());
        assert!(matches!(s.take(1), Err(ReadErr::Eof)));
    }

    #[test]
    fn tokens_and_lines() {
        let mut s = Source::new(&b"ab  cd\r\n\nef"[..]);
        s.buf = vec![0; 2];
        assert_eq!(s.token().unwrap(), Some(&b"ab"[..]));
        assert_eq!(s.token().unwrap(), Some(&b"cd"[..]));
        assert_eq!(s.token().unwrap(), Some(&b"ef"[..]));
        assert_eq!(s.line, 3);
        assert_eq!(s.token().unwrap(), None);
        let mut s = Source::new(&b"one\r\ntwo\nthree"[..]);
        let mut l = Vec::new();
        assert!(s.line_into(&mut l, 100).unwrap());
        assert_eq!(l, b"one");
        assert!(s.line_into(&mut l, 100).unwrap());
        assert_eq!(l, b"two");
        assert!(s.line_into(&mut l, 100).unwrap());
        assert_eq!(l, b"three");
        assert!(!s.line_into(&mut l, 100).unwrap());
        assert!(s.line_into(&mut l, 2).is_err() || l.is_empty());
    }
}
