//! Entry point of the fuzz target `http_range` (`fuzz/fuzz_targets/http_range.rs`) and
//! of its replay as an ordinary test (`tests/corpus.rs`): one function, so the two cannot
//! drift apart. Compiled always (a few lines, no dependency); hidden from the docs, not an
//! API.
//!
//! Input: the first 8 bytes (little endian, zero-padded) are the representation's length,
//! the rest is the `Range` header's value (invalid UTF-8 replaced, as a lenient server
//! would after `HeaderValue::to_str` fails: such a header is ignored anyway). A resolved
//! answer that breaks what the response writer relies on panics, which the fuzzer
//! reports as a crash.

use crate::range::{parse, Ranges, MAX_PARTS};

/// Parses the header of `data` and checks the answer: every satisfiable part non-empty,
/// inside the representation, sorted, disjoint and not adjacent (merged), at most
/// [`MAX_PARTS`] of them. Returns what the server answers: `200`, `416`, or `206` with
/// the parts.
pub fn fuzz_range(data: &[u8]) -> String {
    let mut len = [0u8; 8];
    let n = data.len().min(8);
    len[..n].copy_from_slice(&data[..n]);
    let len = u64::from_le_bytes(len);
    let value = String::from_utf8_lossy(&data[n..]);
    let r = parse(&value, len);
    if let Ranges::Satisfiable(parts) = &r {
        assert!(
            !parts.is_empty() && parts.len() <= MAX_PARTS,
            "{value:?}: {parts:?}"
        );
        for (i, p) in parts.iter().enumerate() {
            assert!(
                p.start < p.end && p.end <= len,
                "{value:?} (len {len}): {p:?}"
            );
            if i > 0 {
                assert!(
                    parts[i - 1].end < p.start,
                    "{value:?}: not merged {parts:?}"
                );
            }
        }
    }
    match r {
        Ranges::Ignore => "200 (header ignored)".into(),
        Ranges::Unsatisfiable => "416 (unsatisfiable)".into(),
        Ranges::TooMany => "416 (too many parts)".into(),
        Ranges::Satisfiable(p) => format!("206 {p:?}"),
    }
}
