//! Issue 14, failure 5: `tessera build same.obj -o same.obj` replaced the input with the
//! model (exit 0), and an output that is a directory failed only after the whole build.
//! Both are refused before any work, and the input is untouched.

use std::path::Path;

use tessera_build::{build, BuildOptions, NoProgress};

const OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n";

fn refused(input: &Path, output: &Path, expect: &str) {
    let e = build(input, output, &BuildOptions::default(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains(expect), "{}: {e}", output.display());
    assert_eq!(
        std::fs::read_to_string(input).unwrap(),
        OBJ,
        "the input changed"
    );
}

#[test]
fn output_that_is_the_input_or_a_directory_is_refused_before_building() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("same.obj");
    std::fs::write(&input, OBJ).unwrap();
    refused(&input, &input, "is the input");
    // The same file through another spelling, a hard link and a symbolic link.
    refused(
        &input,
        &dir.path().join(".").join("same.obj"),
        "is the input",
    );
    let hard = dir.path().join("hard.obj");
    std::fs::hard_link(&input, &hard).unwrap();
    refused(&input, &hard, "is the input");
    #[cfg(unix)]
    {
        let soft = dir.path().join("soft.tsr");
        std::os::unix::fs::symlink(&input, &soft).unwrap();
        refused(&input, &soft, "is the input");
    }
    let sub = dir.path().join("out");
    std::fs::create_dir(&sub).unwrap();
    refused(&input, &sub, "is a directory");
    refused(
        &input,
        &dir.path().join("nowhere").join("m.tsr"),
        "does not exist",
    );
    // A real output still builds.
    let out = dir.path().join("m.tsr");
    build(&input, &out, &BuildOptions::default(), &NoProgress).unwrap();
    assert!(out.is_file());
}

/// Issue 14, failure 10: a build killed by SIGKILL (or a second Ctrl-C) left its work
/// directory (up to 3.4x the input) and a temporary model file. The next build in that
/// directory removes the leftovers of processes that are gone, and leaves those of
/// running processes alone.
#[cfg(target_os = "linux")]
#[test]
fn leftovers_of_dead_builds_are_removed_by_the_next_build() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.obj");
    std::fs::write(&input, OBJ).unwrap();
    // PID 999999999 cannot exist (Linux's pid_max is at most 2^22); PID 1 always does.
    let dead_dir = dir.path().join(".tessera-build-999999999-Ab12Cd");
    std::fs::create_dir(&dead_dir).unwrap();
    std::fs::write(dead_dir.join("vertices.bin"), vec![0u8; 4096]).unwrap();
    let dead_tmp = dir.path().join(".out.tsr.tmp-999999999-0");
    std::fs::write(&dead_tmp, b"").unwrap();
    let live_dir = dir.path().join(".tessera-build-1-Ef34Gh");
    std::fs::create_dir(&live_dir).unwrap();
    let other = dir.path().join(".other.tsr.tmp-999999999-0");
    std::fs::write(&other, b"").unwrap();
    let out = dir.path().join("out.tsr");
    build(&input, &out, &BuildOptions::default(), &NoProgress).expect("build");
    assert!(out.exists());
    assert!(
        !dead_dir.exists(),
        "the dead build's work directory is still there"
    );
    assert!(
        !dead_tmp.exists(),
        "the dead build's temporary model is still there"
    );
    assert!(
        live_dir.exists(),
        "a running process's directory was removed"
    );
    // Another output's temporary file is not this build's business.
    assert!(other.exists());
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n.starts_with(&format!(".tessera-build-{}-", std::process::id()))),
        "this build left its own directory: {names:?}"
    );
}

/// Issue 14, failure 4: a FIFO as input hung (the importers open the file twice) and
/// ignored the first SIGTERM. It is refused before it is opened, so nothing blocks.
#[cfg(unix)]
#[test]
fn a_fifo_as_input_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("mesh.obj");
    let status = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo");
    assert!(status.success());
    let out = dir.path().join("out.tsr");
    // No writer ever opens the FIFO: an importer that opened it would block forever.
    let e = build(&fifo, &out, &BuildOptions::default(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
    assert!(!out.exists());
}
