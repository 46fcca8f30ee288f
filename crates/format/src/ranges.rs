//! One range planner for every reader of a model's patches: which patches one read
//! takes together (the coalescing rule and its constants: [`Span`]) and the HTTP
//! headers that carry a range (`Range`, `Content-Range`). Shared by the native HTTP
//! reader (`tessera-http`), the pager's batches (`tessera-page`), the browser's fetch
//! planner and its pick reader (`tessera-web`), so they never drift apart.

use std::ops::Range;

/// Most patches one read takes: enough to amortise a request's latency over a
/// diamond's children and their neighbours, few enough that a request cancelled when
/// the view turns wastes little.
pub const COALESCE_MAX_PATCHES: usize = 16;
/// Most bytes one read spans (patches and the gaps between them): about 4 ms at 1 Gbit/s,
/// so the wanted patches behind it never wait long.
pub const COALESCE_MAX_BYTES: u64 = 512 << 10;
/// Largest gap between two patches read together: fetching up to 4 KiB of bytes nobody
/// asked for costs less than another request's round trip.
pub const COALESCE_MAX_GAP: u64 = 4096;

/// The bytes of one read being planned: a first patch's range grown by the patches
/// that may join it ([`Span::try_add`]), on either side.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Span {
    /// From the first byte of the lowest patch to the end of the highest.
    pub range: Range<u64>,
    /// Patches in the read.
    pub patches: usize,
}

impl Span {
    /// A read of the patch at `first`.
    pub fn new(first: Range<u64>) -> Span {
        Span {
            range: first,
            patches: 1,
        }
    }

    /// Whether the patch at `r` may join: fewer than [`COALESCE_MAX_PATCHES`] in the
    /// read, at most [`COALESCE_MAX_GAP`] bytes from it on either side (overlaps are
    /// fine), and the whole within [`COALESCE_MAX_BYTES`].
    pub fn admits(&self, r: &Range<u64>) -> bool {
        let gap = r
            .start
            .saturating_sub(self.range.end)
            .max(self.range.start.saturating_sub(r.end));
        let start = self.range.start.min(r.start);
        let end = self.range.end.max(r.end);
        self.patches < COALESCE_MAX_PATCHES
            && gap <= COALESCE_MAX_GAP
            && end - start <= COALESCE_MAX_BYTES
    }

    /// Adds the patch at `r` when it may join ([`Span::admits`]); true if it did.
    pub fn try_add(&mut self, r: &Range<u64>) -> bool {
        if !self.admits(r) {
            return false;
        }
        self.range = self.range.start.min(r.start)..self.range.end.max(r.end);
        self.patches += 1;
        true
    }
}

/// The reads of `ranges` (patch ranges sorted by start): each read the longest run of
/// consecutive ranges a [`Span`] admits, as (bytes, indices into `ranges`).
pub fn coalesce(ranges: &[Range<u64>]) -> Vec<(Range<u64>, Range<usize>)> {
    let mut out = Vec::new();
    let mut start = 0;
    while start < ranges.len() {
        let mut span = Span::new(ranges[start].clone());
        let mut end = start + 1;
        while end < ranges.len() && span.try_add(&ranges[end]) {
            end += 1;
        }
        out.push((span.range, start..end));
        start = end;
    }
    out
}

/// `bytes A-B/TOTAL` (or `bytes */TOTAL`) of a `Content-Range` header; a span must have
/// `A <= B < TOTAL` (RFC 9110 section 14.4), so `B + 1` never overflows.
pub fn parse_content_range(v: &str) -> Option<(Option<(u64, u64)>, u64)> {
    let rest = v.trim().strip_prefix("bytes")?.trim_start();
    let (span, total) = rest.split_once('/')?;
    let total: u64 = total.trim().parse().ok()?;
    if span.trim() == "*" {
        return Some((None, total));
    }
    let (a, b) = span.trim().split_once('-')?;
    let (a, b): (u64, u64) = (a.trim().parse().ok()?, b.trim().parse().ok()?);
    (a <= b && b < total).then_some((Some((a, b)), total))
}

/// The `Range` header value for `range` (end exclusive, not empty).
pub fn range_header(range: &Range<u64>) -> String {
    format!("bytes={}-{}", range.start, range.end.saturating_sub(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_follow_the_rule_on_both_sides() {
        let mut s = Span::new(10_000..11_000);
        assert!(s.try_add(&(11_000..12_000)), "adjacent after");
        assert!(s.try_add(&(5_000..6_000)), "a 4000-byte gap before");
        assert!(!s.try_add(&(16_097..16_100)), "a 4097-byte gap after");
        assert_eq!((s.range.clone(), s.patches), (5_000..12_000, 3));
        let mut big = Span::new(0..(COALESCE_MAX_BYTES - 10));
        assert!(!big.try_add(&(COALESCE_MAX_BYTES - 10..COALESCE_MAX_BYTES + 1)));
        let mut many = Span::new(0..1);
        for i in 1..COALESCE_MAX_PATCHES as u64 {
            assert!(many.try_add(&(i..i + 1)));
        }
        assert!(!many.try_add(&(100..101)), "a 17th patch");
    }

    #[test]
    fn coalesce_splits_sorted_ranges_into_reads() {
        let r = [0..100, 100..200, 10_000..10_100, 10_200..10_300];
        assert_eq!(coalesce(&r), vec![(0..200, 0..2), (10_000..10_300, 2..4)]);
        assert!(coalesce(&[]).is_empty());
    }

    #[test]
    fn content_ranges_are_checked() {
        assert_eq!(
            parse_content_range("bytes 0-65535/1000000"),
            Some((Some((0, 65535)), 1_000_000))
        );
        assert_eq!(parse_content_range("bytes */42"), Some((None, 42)));
        assert_eq!(parse_content_range("items 0-1/2"), None);
        assert_eq!(parse_content_range("bytes 5-4/10"), None);
        assert_eq!(parse_content_range("bytes 0-10/10"), None);
        assert_eq!(parse_content_range("bytes 0-18446744073709551615/0"), None);
        assert_eq!(range_header(&(10..20)), "bytes=10-19");
    }
}
