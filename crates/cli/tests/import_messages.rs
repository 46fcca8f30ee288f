//! Issue 14, failure 8, through the binary: an input the OS will not read is reported on
//! one `error:` line that gives the OS's cause once. The CLI prints errors with anyhow's
//! `{:#}`, which appends every `source()` of the chain; a mesh I/O error that showed its
//! cause and also returned it as its source printed it twice ("missing.ply: No such file
//! or directory (os error 2): No such file or directory (os error 2)").

use std::path::Path;
use std::process::Command;

/// Runs `tessera ARGS`; returns (exit code, stderr).
fn tessera(args: &[&std::ffi::OsStr]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .env_remove("TESSERA_LOG")
        .args(args)
        .output()
        .expect("run tessera");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code().unwrap_or(-1), stderr)
}

/// The single `error:` line of `stderr`.
fn error_line(stderr: &str) -> &str {
    assert!(!stderr.contains("panicked"), "panicked:\n{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(lines.len(), 1, "want one `error:` line:\n{stderr}");
    lines[0]
}

/// What the OS says when `path` is read (its words differ between systems).
fn os_cause(path: &Path) -> String {
    std::fs::read(path)
        .expect_err("the read must fail")
        .to_string()
}

#[test]
fn io_errors_name_their_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.ply");
    let a_dir = dir.path().join("adir.ply");
    std::fs::create_dir(&a_dir).unwrap();
    let out_ply = dir.path().join("out.ply");
    let out_tsr = dir.path().join("out.tsr");
    for input in [&missing, &a_dir] {
        let cause = os_cause(input);
        let name = input.display().to_string();
        let runs: [&[&std::ffi::OsStr]; 2] = [
            &[
                "gen".as_ref(),
                "tile".as_ref(),
                input.as_os_str(),
                "--copies".as_ref(),
                "2".as_ref(),
                "-o".as_ref(),
                out_ply.as_os_str(),
                "-q".as_ref(),
            ],
            &[
                "build".as_ref(),
                input.as_os_str(),
                "-o".as_ref(),
                out_tsr.as_os_str(),
                "-q".as_ref(),
            ],
        ];
        for args in runs {
            let (code, stderr) = tessera(args);
            assert_ne!(code, 0, "{args:?} succeeded");
            let line = error_line(&stderr);
            assert!(line.contains(&format!("{name}: {cause}")), "{line}");
            assert_eq!(line.matches(&cause).count(), 1, "{line}");
        }
    }
    // A mesh written where it cannot be: the writer's temporary file names the cause once.
    let nowhere = dir.path().join("no/such/dir/out.ply");
    let (code, stderr) = tessera(&[
        "gen".as_ref(),
        "sphere".as_ref(),
        "--triangles".as_ref(),
        "100".as_ref(),
        "-o".as_ref(),
        nowhere.as_os_str(),
        "-q".as_ref(),
    ]);
    assert_ne!(code, 0);
    let line = error_line(&stderr);
    let cause = os_cause(&nowhere);
    assert_eq!(line.matches(&cause).count(), 1, "{line}");
}
