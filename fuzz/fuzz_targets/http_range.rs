//! Fuzz target `http_range`: the server's `Range` header parser; the body is
//! `tessera_serve::fuzzing::fuzz_range`, which the crate's `tests/corpus.rs` replays on
//! the committed corpus (see `scripts/fuzz`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Any answer is fine; a panic inside (a part outside the file, unmerged parts) is a
    // finding.
    let _ = tessera_serve::fuzzing::fuzz_range(data);
});
