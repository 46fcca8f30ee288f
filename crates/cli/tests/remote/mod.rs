//! Shared by the remote-model CLI tests (`serve.rs`, `nginx.rs`): a remote model must
//! give the same `info` report and the same rendered frames as the local file.
#![allow(dead_code)]

use std::process::Command;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

/// `tessera info TARGET --json`, without the `file` field (the path or URL).
pub fn info_json(target: &str) -> serde_json::Value {
    let o = tessera().args(["info", target, "--json"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v["file"] = serde_json::Value::Null;
    v
}

/// Renders a 2-frame complete orbit of `local` and of `url` and asserts the PNG files
/// are byte-identical (and not empty).
pub fn assert_same_renders(local: &str, url: &str) {
    let dir = tempfile::tempdir().unwrap();
    let render = |target: &str, out: &str| {
        let o = tessera()
            .args(["render", target, "--orbit", "2", "--complete"])
            .args(["--width", "200", "--height", "150", "--out"])
            .arg(dir.path().join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    render(local, "local");
    render(url, "remote");
    for f in ["frame_00000.png", "frame_00001.png"] {
        let a = std::fs::read(dir.path().join("local").join(f)).unwrap();
        let b = std::fs::read(dir.path().join("remote").join(f)).unwrap();
        assert!(a.len() > 1_000, "{f}: {} bytes", a.len());
        assert!(
            a == b,
            "{f}: the remote render of {url} differs from the local one"
        );
    }
}
