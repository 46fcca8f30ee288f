//! The `Range` request header (RFC 9110 section 14.2), resolved against a file length.

use std::ops::Range;

/// At most this many parts in one `multipart/byteranges` answer (after coalescing);
/// a request for more is refused with `416` (RFC 9110 lets a server reject "many small
/// ranges", a sign of a broken client or a denial-of-service attempt).
pub const MAX_PARTS: usize = 64;

/// At most this many range specs are even looked at; a header with more is refused.
const MAX_SPECS: usize = 1024;

/// What a `Range` header asks for, resolved against the current length.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Ranges {
    /// No usable range: another unit than `bytes`, or a malformed ranges-specifier.
    /// The whole representation is sent with `200` (RFC 9110: a server MAY ignore it).
    Ignore,
    /// Well-formed, but no range overlaps the file: `416` with `Content-Range: bytes */LEN`.
    Unsatisfiable,
    /// More parts than [`MAX_PARTS`] (or specs than we parse): refused with `416`.
    TooMany,
    /// The satisfiable ranges, sorted, overlapping and adjacent ones merged; non-empty.
    /// One range: a plain `206`; several: `multipart/byteranges`.
    Satisfiable(Vec<Range<u64>>),
}

/// Parses `value` (the header's value) against a representation of `len` bytes.
pub fn parse(value: &str, len: u64) -> Ranges {
    let value = value.trim_matches([' ', '\t']);
    let Some((unit, set)) = value.split_once('=') else {
        return Ranges::Ignore;
    };
    if !unit.eq_ignore_ascii_case("bytes") {
        return Ranges::Ignore;
    }
    let mut ranges: Vec<Range<u64>> = Vec::new();
    let mut specs = 0usize;
    for spec in set.split(',') {
        let spec = spec.trim_matches([' ', '\t']);
        if spec.is_empty() {
            // Empty list elements are allowed by the list syntax (RFC 9110 5.6.1).
            continue;
        }
        specs += 1;
        if specs > MAX_SPECS {
            return Ranges::TooMany;
        }
        let Some((first, last)) = spec.split_once('-') else {
            return Ranges::Ignore;
        };
        if first.is_empty() {
            // suffix-range: the last N bytes.
            let Some(n) = digits(last) else {
                return Ranges::Ignore;
            };
            if n > 0 && len > 0 {
                ranges.push(len - n.min(len)..len);
            }
        } else {
            let Some(first) = digits(first) else {
                return Ranges::Ignore;
            };
            let last = if last.is_empty() {
                None
            } else {
                match digits(last) {
                    Some(l) if l >= first => Some(l),
                    // last < first: an invalid range-spec makes the whole header invalid.
                    _ => return Ranges::Ignore,
                }
            };
            if first < len {
                let end = last.map_or(len, |l| l.saturating_add(1).min(len));
                ranges.push(first..end);
            }
        }
    }
    if specs == 0 {
        return Ranges::Ignore;
    }
    if ranges.is_empty() {
        return Ranges::Unsatisfiable;
    }
    ranges.sort_by_key(|r| r.start);
    let mut merged: Vec<Range<u64>> = Vec::with_capacity(ranges.len());
    for r in ranges {
        match merged.last_mut() {
            Some(m) if r.start <= m.end => m.end = m.end.max(r.end),
            _ => merged.push(r),
        }
    }
    if merged.len() > MAX_PARTS {
        return Ranges::TooMany;
    }
    Ranges::Satisfiable(merged)
}

/// `1*DIGIT` as a number, saturating at `u64::MAX` (a position past any file).
fn digits(s: &str) -> Option<u64> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some(s.bytes().fold(0u64, |n, b| {
        n.saturating_mul(10).saturating_add(u64::from(b - b'0'))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sat(v: &str, len: u64) -> Vec<Range<u64>> {
        match parse(v, len) {
            Ranges::Satisfiable(r) => r,
            other => panic!("{v}: {other:?}"),
        }
    }

    #[test]
    fn single_ranges() {
        assert_eq!(sat("bytes=0-9", 100), vec![0..10]);
        assert_eq!(sat("bytes=90-200", 100), vec![90..100]);
        assert_eq!(sat("bytes=10-", 100), vec![10..100]);
        assert_eq!(sat("bytes=-10", 100), vec![90..100]);
        assert_eq!(sat("bytes=-1000", 100), vec![0..100]);
        assert_eq!(
            sat("BYTES = 5-5".replace(' ', "").as_str(), 100),
            vec![5..6]
        );
        assert_eq!(sat("bytes=99-99999999999999999999999", 100), vec![99..100]);
    }

    #[test]
    fn unsatisfiable_and_malformed() {
        assert_eq!(parse("bytes=100-", 100), Ranges::Unsatisfiable);
        assert_eq!(parse("bytes=100-200", 100), Ranges::Unsatisfiable);
        assert_eq!(parse("bytes=-0", 100), Ranges::Unsatisfiable);
        assert_eq!(parse("bytes=-5", 0), Ranges::Unsatisfiable);
        assert_eq!(parse("bytes=0-", 0), Ranges::Unsatisfiable);
        for bad in [
            "bytes=9-5",
            "bytes=a-b",
            "bytes=-",
            "bytes=",
            "bytes=1-2-3",
            "items=0-5",
            "bytes 0-5",
            "0-5",
            "bytes=0x10-20",
            "bytes=+1-2",
            "bytes=1 -2",
            "bytes=0-5,9-1",
        ] {
            assert_eq!(parse(bad, 100), Ranges::Ignore, "{bad}");
        }
    }

    #[test]
    fn multiple_ranges_sorted_and_merged() {
        assert_eq!(sat("bytes=50-59, 0-9", 100), vec![0..10, 50..60]);
        assert_eq!(sat("bytes=0-9,5-19,20-29", 100), vec![0..30]);
        assert_eq!(sat("bytes=0-9,,-10", 100), vec![0..10, 90..100]);
        assert_eq!(sat("bytes=0-9,500-600", 100), vec![0..10]);
        let many: Vec<String> = (0..65).map(|i| format!("{}-{}", i * 10, i * 10)).collect();
        assert_eq!(
            parse(&format!("bytes={}", many.join(",")), 1000),
            Ranges::TooMany
        );
    }
}
