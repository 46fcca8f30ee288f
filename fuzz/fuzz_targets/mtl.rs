//! Fuzz target `mtl`: the body is `tessera_mesh::fuzzing::fuzz_mtl` (the MTL material
//! library parser, issue 29), which the crate's `tests/corpus.rs` replays on the
//! committed corpus (see `scripts/fuzz`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Errors are expected; a panic inside is a finding.
    let _ = tessera_mesh::fuzzing::fuzz_mtl(data);
});
