//! Replays the fuzz corpora of the camera readers (`fuzz/corpus/{camera,camera_path}/`,
//! samples from `docs/camera.md`) and every crash the fuzzers found
//! (`fuzz/regressions/<target>/`, minimised) through the fuzz targets' own bodies
//! (`tessera_select::fuzzing`), on stable: no panic, errors as clear messages, and for
//! each regression the error its fix gives.

use std::path::{Path, PathBuf};

use tessera_select::fuzzing::{fuzz_camera, fuzz_camera_path};

/// Each regression file (target, name) and a piece of the error its fix gives.
const REGRESSIONS: &[(&str, &str, &str)] = &[];

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

fn files(kind: &str, target: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(fuzz_dir().join(kind).join(target))
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file());
    v.sort();
    v
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

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
        let seeds = files("corpus", target);
        assert!(
            seeds.len() >= 4,
            "fuzz/corpus/{target} has {} seeds",
            seeds.len()
        );
        let mut ok = 0;
        for f in seeds.iter().chain(&files("regressions", target)) {
            match run(target, &read(f)) {
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
        for f in files("regressions", target) {
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            let Some(&(_, _, want)) = REGRESSIONS
                .iter()
                .find(|(t, n, _)| *t == target && *n == name)
            else {
                panic!("fuzz/regressions/{target}/{name} has no expected error in REGRESSIONS");
            };
            match run(target, &read(&f)) {
                Some(m) => assert!(m.contains(want), "{target}/{name}: {m}"),
                None => panic!("{target}/{name} is accepted, expected {want:?}"),
            }
        }
    }
}
