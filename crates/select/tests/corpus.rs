//! Replays the fuzz corpora of the camera readers (`fuzz/corpus/{camera,camera_path}/`,
//! samples from `docs/camera.md`) and every crash the fuzzers found
//! (`fuzz/regressions/<target>/`, minimised) through the fuzz targets' own bodies
//! (`tessera_select::fuzzing`), on stable: no panic, errors as clear messages, and for
//! each regression the error its fix gives.

use tessera_select::fuzzing::{fuzz_camera, fuzz_camera_path};
use tessera_testkit::fuzz::{fuzz_files, read_bytes, regressions, Regression};

/// Each regression file (target, name) and a piece of the error its fix gives.
const REGRESSIONS: &[(&str, &str, &str)] = &[];

/// The target's error message for `data`, `None` when it is accepted.
fn run(target: &str, data: &[u8]) -> Option<String> {
    match target {
        "camera" => fuzz_camera(data).err().map(|e| e.to_string()),
        _ => fuzz_camera_path(data).err().map(|e| e.to_string()),
    }
}

#[test]
fn corpora_replay_without_panics() {
    for target in ["camera", "camera_path"] {
        let seeds = fuzz_files("corpus", target);
        assert!(
            seeds.len() >= 4,
            "fuzz/corpus/{target} has {} seeds",
            seeds.len()
        );
        let mut ok = 0;
        for f in seeds.iter().chain(&fuzz_files("regressions", target)) {
            match run(target, &read_bytes(f)) {
                None => ok += 1,
                Some(m) => assert!(m.len() > 5, "{}: unclear error {m:?}", f.display()),
            }
        }
        assert!(ok >= 2, "{target}: only {ok} seeds accepted");
    }
}

#[test]
fn regressions_give_their_errors() {
    for target in ["camera", "camera_path"] {
        for Regression { name, bytes, want } in regressions(target, REGRESSIONS) {
            match run(target, &bytes) {
                Some(m) => assert!(m.contains(want), "{target}/{name}: {m}"),
                None => panic!("{target}/{name} is accepted, expected {want:?}"),
            }
        }
    }
}
