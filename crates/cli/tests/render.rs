//! `tessera render` end to end: frames and statistics from an orbit and a path file,
//! the full-resolution reference, and clear errors on bad models and bad paths.

mod common;

use common::*;
use serde_json::Value;

fn stats(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("stats file")).expect("json")
}

#[test]
fn orbit_and_path_render_frames_with_stats() {
    let b = build_sphere(20_000, 3, false, &small_options());
    let out = b.dir.path().join("frames");
    let st = b.dir.path().join("stats.json");
    let (code, stdout, stderr) = run_tessera(args![
        "render",
        b.model_path,
        "--orbit",
        "3",
        "--out",
        out,
        "--stats",
        st,
        "--width",
        "160",
        "--height",
        "120"
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("3 frames"), "{stdout}");
    for i in 0..3 {
        let png = out.join(format!("frame_{i:05}.png"));
        assert!(png.exists(), "{} missing", png.display());
    }
    let s = stats(&st);
    let frames = s["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 3);
    for key in [
        "selected_nodes",
        "triangles",
        "bytes_uploaded",
        "cache_hits",
        "cache_misses",
        "pending_loads",
        "selection_ms",
        "frame_ms",
        "rss_bytes",
    ] {
        assert!(
            frames[0].get(key).is_some(),
            "stats lack {key}: {}",
            frames[0]
        );
    }
    assert!(frames[0]["triangles"].as_u64().unwrap() > 0);
    // The first frame draws the roots, nothing more.
    let roots = b.model.header().root_count as u64;
    assert!(frames[0]["selected_nodes"].as_u64().unwrap() <= roots);
    assert!(leftovers(&out).is_empty());

    // A path file, complete frames, and the full-resolution reference.
    let path = b.dir.path().join("path.json");
    std::fs::write(
        &path,
        r#"{"frames": 2, "keyframes": [
            {"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40},
            {"position": [4, 0, 0], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40}]}"#,
    )
    .unwrap();
    let mut leaves = 0u64;
    for (flag, name) in [("--complete", "c.json"), ("--full-resolution", "f.json")] {
        let st = b.dir.path().join(name);
        let (code, _, stderr) = run_tessera(args![
            "render",
            b.model_path,
            "--path",
            path,
            "--stats",
            st,
            "--width",
            "160",
            "--height",
            "120",
            flag
        ]);
        assert_eq!(code, 0, "{flag}: {stderr}");
        let s = stats(&st);
        let tri = s["frames"][0]["triangles"].as_u64().unwrap();
        if flag == "--full-resolution" {
            leaves = tri;
        } else {
            assert!(tri > 0);
        }
    }
    assert_eq!(
        leaves,
        b.model.header().input_triangles,
        "full resolution draws every leaf"
    );
}

#[test]
fn bad_paths_and_models_give_one_clear_error() {
    let b = build_sphere(5_000, 4, false, &small_options());
    let dir = b.dir.path();
    let path = dir.join("bad.json");
    std::fs::write(
        &path,
        r#"{"frames": 2, "keyframes": [{"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": "wide"}]}"#,
    )
    .unwrap();
    let (code, _, stderr) = run_tessera(args!["render", b.model_path, "--path", path]);
    assert_eq!(code, 1);
    assert!(stderr.contains("keyframes[0].fov_y_deg"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let bytes = std::fs::read(&b.model_path).unwrap();
    let short = dir.join("short.tsr");
    std::fs::write(&short, &bytes[..bytes.len() / 2]).unwrap();
    let newer = dir.join("newer.tsr");
    let mut nb = bytes.clone();
    nb[8] = 99;
    std::fs::write(&newer, &nb).unwrap();
    for (model, what) in [(&short, "truncat"), (&newer, "version")] {
        let (code, _, stderr) = run_tessera(args!["render", model, "--orbit", "1"]);
        assert_eq!(code, 1, "{stderr}");
        let line = stderr
            .lines()
            .find(|l| l.starts_with("error:"))
            .unwrap_or("");
        assert!(line.contains(what), "{what}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    let (code, _, stderr) = run_tessera(args!["render", b.model_path, "--orbit", "0"]);
    assert_eq!(code, 1, "{stderr}");
}
