//! Replays the `Range` header fuzz corpus (`fuzz/corpus/http_range/`: the forms of RFC
//! 9110 section 14.2 and the malformed ones the server must ignore or refuse) and every
//! crash the fuzzer found (`fuzz/regressions/http_range/`, minimised) through the fuzz
//! target's own body (`tessera_serve::fuzzing::fuzz_range`), on stable: no panic, and
//! the answer each seed must get.

use std::path::{Path, PathBuf};

use tessera_serve::fuzzing::fuzz_range;

/// Seeds and the start of the answer each must get.
const EXPECTED: &[(&str, &str)] = &[
    ("single", "206 [0..100]"),
    ("suffix", "206 [900..1000]"),
    ("open", "206 [900..1000]"),
    ("multi", "206 [0..10, 20..41]"),
    ("unsat", "416 (unsatisfiable)"),
    ("huge", "206 [0..1099511627776]"),
    ("bad-unit", "200"),
    ("reversed", "200"),
    ("empty-len", "416"),
    ("many", "416 (too many parts)"),
    ("tabs", "206 [1..3, 4..5]"),
    ("invalid-utf8", "200"),
];

fn files(kind: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz")
        .join(kind)
        .join("http_range");
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file());
    v.sort();
    v
}

#[test]
fn range_corpus_replays_with_the_expected_answers() {
    let seeds = files("corpus");
    assert!(
        seeds.len() >= EXPECTED.len(),
        "fuzz/corpus/http_range/ is missing seeds"
    );
    for p in seeds.iter().chain(&files("regressions")) {
        let answer = fuzz_range(&std::fs::read(p).unwrap());
        let name = p.file_name().unwrap().to_string_lossy();
        if let Some((_, want)) = EXPECTED.iter().find(|(n, _)| *n == name) {
            assert!(
                answer.starts_with(want),
                "{name}: {answer} (expected {want})"
            );
        }
    }
    for (name, _) in EXPECTED {
        assert!(
            seeds.iter().any(|p| p.ends_with(name)),
            "seed {name} missing"
        );
    }
}
