//! Replays the fuzz corpora of the mesh importers (`fuzz/corpus/{ply,obj,stl,gltf,mtl}/`, the
//! committed seeds) and every crash the fuzzers found (`fuzz/regressions/<target>/`,
//! minimised) through the fuzz targets' own bodies (`tessera_mesh::fuzzing`), on stable:
//! no panic, errors as clear one-line messages, and for each regression the error its
//! fix gives. Then an adversarial corpus: every seed truncated at many offsets and
//! mutated byte by byte (deterministically), again without a panic.

use tessera_mesh::fuzzing::{fuzz_gltf, fuzz_mtl, fuzz_obj, fuzz_ply, fuzz_stl, FUZZ_PATH};
use tessera_mesh::{ImportReport, MeshError};
use tessera_testkit::fuzz::{fuzz_files, read_bytes, regressions, Regression};
use tessera_testkit::Rng;

type Target = fn(&[u8]) -> Result<ImportReport, MeshError>;

const TARGETS: [(&str, Target); 5] = [
    ("ply", fuzz_ply),
    ("obj", fuzz_obj),
    ("stl", fuzz_stl),
    ("gltf", fuzz_gltf),
    ("mtl", fuzz_mtl),
];

/// Each regression file and a piece of the error its fix gives.
const REGRESSIONS: &[(&str, &str, &str)] = &[];

/// Hand-written malformed inputs whose messages once named the wrong problem (issue 14,
/// failure 8), and glTF files that lie about their buffers (issue 11), each with the
/// target that reads it and a piece of the error it gives now. They also seed the
/// adversarial corpus below.
fn malformed_inputs() -> Vec<(&'static str, Vec<u8>, String)> {
    let ply = |format: &str, count: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face 1\nproperty list {count} int vertex_indices\n\
             end_header\n"
        )
        .into_bytes()
    };
    let ascii = |body: &str| [ply("ascii", "uint"), body.as_bytes().to_vec()].concat();
    let mut binary = ply("binary_little_endian", "uint");
    let count_at = binary.len() + 36;
    for x in [0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        binary.extend_from_slice(&x.to_le_bytes());
    }
    binary.extend_from_slice(&u32::MAX.to_le_bytes());
    binary.extend_from_slice(&[0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
    let binary_want = format!("byte {count_at}: face 0 of 1: list count 4294967295 is implausible");
    vec![
        (
            "obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1.5 2 3\n".to_vec(),
            "line 4: vertex index '1.5' is not an integer".into(),
        ),
        (
            "obj",
            b"v 0 0 0\nv 1 0 0 1 2 3 4 5\nv 0 1 0\nf 1 2 3\n".to_vec(),
            "line 2: v has 8 numbers".into(),
        ),
        (
            "obj",
            b"v 0 0 0\nv 1 0 0 junk\nv 0 1 0\nf 1 2 3\n".to_vec(),
            "line 2: v: 'junk' is not a number".into(),
        ),
        (
            "ply",
            ascii("0 0 0\n1 0 0\n0 1 0\n3 0.5 1 2\n"),
            "line 13: face 0 of 1: vertex index 0.5 is not an integer".into(),
        ),
        (
            "ply",
            ascii("0 0 0\n1 0 0\n0 1 0\n4294967295 0 1 2\n"),
            "line 13: face 0 of 1: list count 4294967295 is implausible".into(),
        ),
        ("ply", binary, binary_want),
        (
            "gltf",
            gltf(r#"{"byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA=="}"#),
            "bufferView 0 needs bytes 0..36 of buffer 0, which has only 4 bytes".into(),
        ),
        (
            "gltf",
            gltf(r#"{"byteLength": 36, "uri": "scan.bin"}"#),
            "buffer 0: names an external file 'scan.bin', which this reader may not open".into(),
        ),
        (
            "gltf",
            gltf(r#"{"byteLength": 36, "uri": "data:application/octet-stream;base64,A"}"#),
            "buffer 0: bad data URI: base64".into(),
        ),
    ]
}

/// A one-triangle glTF whose only buffer is `buffer` (JSON).
fn gltf(buffer: &str) -> Vec<u8> {
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "buffers": [{buffer}],
        "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
        "accessors": [{{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}]}}"#
    )
    .into_bytes()
}

fn target(name: &str) -> Target {
    TARGETS
        .iter()
        .find(|(t, _)| *t == name)
        .map(|&(_, run)| run)
        .unwrap_or_else(|| panic!("no fuzz target {name}"))
}

fn assert_clear(e: &MeshError) {
    let m = e.to_string();
    assert!(
        m.starts_with(FUZZ_PATH),
        "message does not name the input: {m}"
    );
    assert!(m.len() > FUZZ_PATH.len() + 5, "message says nothing: {m}");
}

#[test]
fn corpora_replay_without_panics() {
    for (target, run) in TARGETS {
        let seeds = fuzz_files("corpus", target);
        assert!(
            seeds.len() >= 5,
            "fuzz/corpus/{target} has {} seeds",
            seeds.len()
        );
        let mut ok = 0;
        for f in seeds.iter().chain(&fuzz_files("regressions", target)) {
            match run(&read_bytes(f)) {
                Ok(_) => ok += 1,
                Err(e) => assert_clear(&e),
            }
        }
        // The seeds are mostly valid meshes: a reader that refuses them all is broken.
        assert!(ok * 2 > seeds.len(), "{target}: only {ok} seeds read");
    }
}

#[test]
fn regressions_give_their_errors() {
    for (target, run) in TARGETS {
        for Regression { name, bytes, want } in regressions(target, REGRESSIONS) {
            match run(&bytes) {
                Ok(r) => panic!("{target}/{name} reads as {r:?}, expected an error with {want:?}"),
                Err(e) => {
                    assert_clear(&e);
                    assert!(e.to_string().contains(want), "{target}/{name}: {e}");
                }
            }
        }
    }
}

#[test]
fn malformed_inputs_give_their_errors() {
    for (name, bytes, want) in malformed_inputs() {
        match target(name)(&bytes) {
            Ok(r) => panic!("{name}: {want:?} reads as {r:?}"),
            Err(e) => {
                assert_clear(&e);
                assert!(e.to_string().contains(&want), "{name}: {e}");
            }
        }
    }
}

/// Bytes an adversary likes: digits, signs, separators, huge and negative counts.
const INTERESTING: &[&[u8]] = &[
    b"-1",
    b"4294967295",
    b"1e39",
    b"nan",
    b"inf",
    b"0",
    b"/",
    b"//",
    b"\\\n",
    b" ",
    b"\n",
    b"\r\n",
    b"\xef\xbb\xbf",
    b"\0",
    b"\xff\xff\xff\xff",
    b"3.5",
    b"-0",
    b"#",
];

/// Truncations at many offsets and random edits of `seed`.
fn malformed(seed: &[u8], rng: &mut Rng, count: usize) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for k in 0..count / 2 {
        out.push(seed[..seed.len() * k / (count / 2)].to_vec());
    }
    while out.len() < count {
        let mut b = seed.to_vec();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(b.len());
            match rng.below(4) {
                0 => b[at] = rng.next_u64() as u8,
                1 => b[at] ^= 1 << rng.below(8),
                2 => {
                    let s = INTERESTING[rng.below(INTERESTING.len())];
                    b.splice(at..at, s.iter().copied());
                }
                _ => {
                    let end = (at + 1 + rng.below(16)).min(b.len());
                    b.drain(at..end);
                }
            }
            if b.is_empty() {
                break;
            }
        }
        out.push(b);
    }
    out
}

#[test]
fn adversarial_meshes_give_errors_not_panics() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut total = 0;
    let mut errors = 0;
    let mut seeds: Vec<(Target, Vec<u8>)> = Vec::new();
    for (target, run) in TARGETS {
        seeds.extend(
            fuzz_files("corpus", target)
                .iter()
                .map(|f| (run, read_bytes(f))),
        );
    }
    seeds.extend(
        malformed_inputs()
            .into_iter()
            .map(|(t, b, _)| (target(t), b)),
    );
    for (run, seed) in seeds {
        for bad in malformed(&seed, &mut rng, 40) {
            total += 1;
            if let Err(e) = run(&bad) {
                assert_clear(&e);
                errors += 1;
            }
        }
    }
    eprintln!("{total} malformed meshes: {errors} errors, the rest read");
    assert!(
        total >= 100 && errors >= 100,
        "{total} meshes, {errors} errors"
    );
}
