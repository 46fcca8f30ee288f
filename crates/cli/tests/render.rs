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

/// Issue 14, failure 3: what a render says of corrupt patches is true for its mode. At
/// full resolution a corrupt leaf is a hole (not "their parents were drawn"); in a
/// complete frame a corrupt leaf's parent is drawn instead; a corrupt root leaves its
/// part missing. The statistics count the skipped patch, and the frame draws exactly
/// the corrupt leaf's triangles fewer.
#[test]
fn skipped_patches_are_reported_truthfully_for_the_mode() {
    let b = build_sphere(20_000, 3, false, &small_options());
    let nodes = b.model.nodes();
    // Every fourth leaf, so that some are in view whatever the camera.
    let leaves: Vec<usize> = (0..nodes.len())
        .filter(|&i| nodes[i].flags & tessera_format::NODE_FLAG_LEAF != 0)
        .step_by(4)
        .collect();
    assert!(leaves.len() >= 4);
    let render = |model: &std::path::Path, mode: &str, tag: &str| {
        let st = b.dir.path().join(format!("{tag}.json"));
        let out = b.dir.path().join(tag);
        let (code, _, stderr) = run_tessera(args![
            "render",
            model,
            mode,
            "--orbit",
            "1",
            "--stats",
            st,
            "--out",
            out,
            "--width",
            "192",
            "--height",
            "144",
            "--tolerance",
            "0.01"
        ]);
        assert_eq!(code, 0, "{tag}: {stderr}");
        let s = stats(&st);
        let f = &s["frames"][0];
        let img = tessera_image::Image::load_png(&out.join("frame_00000.png")).unwrap();
        let bg = img.pixel(0, 0);
        let background = (0..img.height)
            .flat_map(|y| (0..img.width).map(move |x| (x, y)))
            .filter(|&(x, y)| img.pixel(x, y) == bg)
            .count();
        (
            stderr,
            f["triangles"].as_u64().unwrap(),
            s["summary"]["failed_patches"].as_u64().unwrap(),
            background,
        )
    };
    let (_, full_good, failed, _) = render(&b.model_path, "--full-resolution", "good-full");
    let (_, _, _, bg_good) = render(&b.model_path, "--complete", "good-complete");
    assert_eq!(failed, 0);
    let corrupt = |which: &[usize], name: &str| {
        let mut bytes = std::fs::read(&b.model_path).unwrap();
        for &node in which {
            let n = &nodes[node];
            bytes[(n.patch_offset + u64::from(n.patch_bytes) / 2) as usize] ^= 0x5a;
        }
        let p = b.dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let bad_leaf = corrupt(&leaves, "leaf.tsr");
    let (err, full, failed, _) = render(&bad_leaf, "--full-resolution", "leaf-full");
    assert_eq!(failed, leaves.len() as u64);
    assert!(err.contains("full resolution draws leaves only"), "{err}");
    assert!(!err.contains("parents were drawn"), "{err}");
    let lost: u64 = leaves
        .iter()
        .map(|&l| u64::from(nodes[l].triangle_count))
        .sum();
    assert_eq!(
        full,
        full_good - lost,
        "holes of exactly the leaves' triangles"
    );
    // (A tolerance of 0.01 px puts the leaves in the complete cut.) The parent stands in
    // within the same frame: no hole (a few edge pixels may
    // differ where the coarser parent's silhouette does).
    let (err, _, failed, bg) = render(&bad_leaf, "--complete", "leaf-complete");
    assert!(failed >= 1);
    assert!(err.contains("their parents were drawn instead"), "{err}");
    eprintln!("background pixels: {bg_good} intact, {bg} with a corrupt leaf");
    assert!(
        bg.abs_diff(bg_good) <= 40,
        "{bg} vs {bg_good} background pixels"
    );
    let bad_root = corrupt(&[0], "root.tsr");
    let (err, _, failed, _) = render(&bad_root, "--complete", "root-complete");
    assert!(failed >= 1);
    assert!(err.contains("root patch"), "{err}");
    assert!(err.contains("missing"), "{err}");
}
