//! Scene files end to end: `tessera gen scene` lays out copies of a built model,
//! `tessera render` draws the scene (every copy on screen, upright, apart), and bad
//! scene files (a missing model, duplicate names, a bad transform) fail with a message
//! that names the entry, exit code 1, no panic.

mod common;

use common::*;
use serde_json::Value;

#[test]
fn a_generated_scene_of_copies_renders() {
    let b = build_sphere(20_000, 3, false, &small_options());
    let dir = b.dir.path();
    let gen = |out: &std::path::Path| {
        run_tessera(args![
            "gen",
            "scene",
            "--model",
            b.model_path,
            "--copies",
            "9",
            "-o",
            out
        ])
    };
    let scene = dir.join("scene.json");
    let (code, stdout, stderr) = gen(&scene);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("9 copies"), "{stdout}");
    let text = std::fs::read_to_string(&scene).expect("scene file");
    let v: Value = serde_json::from_str(&text).expect("json");
    assert_eq!(v["tessera_scene"], 1);
    let models = v["models"].as_array().expect("models");
    assert_eq!(models.len(), 9);
    // The model path is relative to the scene's folder.
    assert_eq!(models[0]["model"], "model.tsr", "{text}");
    // The same options write the same file.
    let again = dir.join("again.json");
    let (code, _, stderr) = gen(&again);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(std::fs::read_to_string(&again).unwrap(), text);

    let out = dir.join("frames");
    let st = dir.join("stats.json");
    // Looking down on the ground (+z up), the 3 x 3 grid of copies (1.5 apart) in view.
    let cam = dir.join("above.json");
    std::fs::write(
        &cam,
        r#"{"frames": 1, "keyframes": [{"position": [0, -0.5, 9], "target": [0, 0, 0.5],
            "up": [0, 1, 0], "fov_y_deg": 50}]}"#,
    )
    .unwrap();
    let (code, _, stderr) = run_tessera(args![
        "render",
        scene,
        "--path",
        cam,
        "--complete",
        "--out",
        out,
        "--stats",
        st,
        "--width",
        "320",
        "--height",
        "180"
    ]);
    assert_eq!(code, 0, "{stderr}");
    let s: Value = serde_json::from_str(&std::fs::read_to_string(&st).unwrap()).unwrap();
    assert_eq!(s["scene_models"], 9);
    let img = tessera_image::Image::load_png(&out.join("frame_00000.png")).expect("frame");
    // Nine copies apart on the ground, seen from above: separate blobs of
    // surface, counted by connected components of non-background pixels.
    let bg = &img.rgba[0..3].to_vec();
    let (w, h) = (img.width as usize, img.height as usize);
    let mut seen = vec![false; w * h];
    let mut blobs = 0;
    for start in 0..w * h {
        if seen[start] || img.rgba[start * 4..start * 4 + 3] == bg[..] {
            continue;
        }
        let mut stack = vec![start];
        seen[start] = true;
        let mut size = 0;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if !seen[j] && img.rgba[j * 4..j * 4 + 3] != bg[..] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1)
            }
            if x + 1 < w {
                visit(i + 1)
            }
            if y > 0 {
                visit(i - w)
            }
            if y + 1 < h {
                visit(i + w)
            }
        }
        if size > 30 {
            blobs += 1;
        }
    }
    eprintln!("{blobs} separate copies on screen");
    assert_eq!(blobs, 9, "the copies stand apart");
}

#[test]
fn bad_scene_files_name_the_entry() {
    let b = build_sphere(20_000, 3, false, &small_options());
    let dir = b.dir.path();
    let cases = [
        (
            r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "model.tsr"}, {"name": "gone", "model": "missing.tsr"}]}"#,
            "model \"gone\": cannot open",
        ),
        (
            r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "model.tsr"}, {"name": "a", "model": "model.tsr"}]}"#,
            "models[1].name: \"a\" names two models",
        ),
        (
            r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "model.tsr", "scale": -2}]}"#,
            "models[0].scale: a positive number",
        ),
        (
            r#"{"tessera_scene": 1, "models": [{"name": "a", "model": "model.tsr", "matrix": [1,0,0,0, 0,2,0,0, 0,0,1,0, 0,0,0,1]}]}"#,
            "not a similarity",
        ),
        ("{\"tessera_scene\": 1, \"models\": [", "not a scene file"),
    ];
    for (k, (text, want)) in cases.iter().enumerate() {
        let scene = dir.join(format!("bad{k}.json"));
        std::fs::write(&scene, text).unwrap();
        let (code, _, stderr) = run_tessera(args![
            "render", scene, "--orbit", "1", "--width", "64", "--height", "48"
        ]);
        assert_eq!(code, 1, "{text}: {stderr}");
        assert!(
            stderr.contains(want),
            "{text}\n  stderr: {stderr}\n  want: {want}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
