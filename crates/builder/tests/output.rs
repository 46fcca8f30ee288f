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
