//! `tessera export-tiles` (issue 33) from the command line: the summary it prints, the
//! files it writes, and the refusals (exit code 1, one clear line, nothing written or
//! left behind, never a panic) for a file that is not a model, an output directory
//! that is missing, not a directory, not empty, already a tileset without `--force`, or
//! not writable, and for bad placements.

mod common;

use common::*;

fn no_panic(err: &str) {
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn export_tiles_writes_a_tileset_and_refuses_what_it_must() {
    let built = build_sphere(8_000, 3, false, &small_options());
    let work = tempfile::tempdir().unwrap();
    let out = work.path().join("tiles");

    let (code, stdout, err) = run_tessera(args![
        "export-tiles",
        built.model_path,
        "-o",
        out,
        "--quiet"
    ]);
    assert_eq!(code, 0, "{err}");
    for line in ["tiles ", "files ", "bytes ", "per input triangle", "time "] {
        assert!(stdout.contains(line), "summary lacks {line:?}: {stdout}");
    }
    let tileset: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
    assert_eq!(tileset["asset"]["version"], "1.1");
    let glbs = std::fs::read_dir(out.join("tiles")).unwrap().count();
    assert_eq!(
        glbs,
        built.model.nodes().len() - built.model.header().root_count as usize + 1
    );

    // JSON summary; the same tileset again refused, then replaced with --force.
    let (code, _, err) = run_tessera(args!["export-tiles", built.model_path, "-o", out]);
    assert_eq!(code, 1);
    assert!(
        err.contains("already holds a tileset") && err.contains("--force"),
        "{err}"
    );
    let (code, stdout, err) = run_tessera(args![
        "export-tiles",
        built.model_path,
        "-o",
        out,
        "--force",
        "--json"
    ]);
    assert_eq!(code, 0, "{err}");
    let s: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(s["files"].as_u64().unwrap() as usize, glbs + 1);
    assert!(s["bytes_per_input_triangle"].as_f64().unwrap() > 0.0);

    // Placed on the Earth: the root transform is the east-north-up frame there.
    let placed = work.path().join("placed");
    let (code, _, err) = run_tessera(args![
        "export-tiles",
        built.model_path,
        "-o",
        placed,
        "--origin",
        "-122.4,37.8,10",
        "--quiet"
    ]);
    assert_eq!(code, 0, "{err}");
    let t: serde_json::Value =
        serde_json::from_slice(&std::fs::read(placed.join("tileset.json")).unwrap()).unwrap();
    let m: Vec<f64> = t["root"]["transform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let r = (m[12] * m[12] + m[13] * m[13] + m[14] * m[14]).sqrt();
    assert!(
        (6.36e6..6.38e6).contains(&r),
        "the root is {r} m from the Earth's centre"
    );

    let not_model = work.path().join("mesh.ply");
    std::fs::copy(&built.input, &not_model).unwrap();
    let full = work.path().join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("notes.txt"), "mine").unwrap();
    let file = work.path().join("file");
    std::fs::write(&file, "x").unwrap();
    // A model with one byte of its last patch flipped: its index is fine, the patch
    // fails its checksum half way through the export.
    let corrupt = work.path().join("corrupt.tsr");
    let mut bytes = std::fs::read(&built.model_path).unwrap();
    let last = bytes.len() - 10;
    bytes[last] ^= 0xff;
    std::fs::write(&corrupt, bytes).unwrap();
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (
            vec![
                not_model.clone().into(),
                "-o".into(),
                work.path().join("a").into(),
            ],
            "not a readable Tessera model",
        ),
        (
            vec![
                corrupt.clone().into(),
                "-o".into(),
                work.path().join("e").into(),
            ],
            "checksum",
        ),
        (
            vec![
                work.path().join("none.tsr").into(),
                "-o".into(),
                work.path().join("b").into(),
            ],
            "No such file",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                work.path().join("no/such/dir").into(),
            ],
            "is not an existing directory",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                full.clone().into(),
                "--force".into(),
            ],
            "holds no tileset.json",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                file.clone().into(),
            ],
            "is not a directory",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                "/proc/tessera-tiles".into(),
            ],
            "cannot write /proc/tessera-tiles",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                work.path().join("c").into(),
                "--origin".into(),
                "1,2".into(),
            ],
            "three",
        ),
        (
            vec![
                built.model_path.clone().into(),
                "-o".into(),
                work.path().join("d").into(),
                "--ecef".into(),
                "0,0,0".into(),
            ],
            "--ecef",
        ),
    ];
    for (extra, want) in cases {
        let mut argv: Vec<std::ffi::OsString> = vec!["export-tiles".into()];
        argv.extend(extra);
        let argv: Vec<&std::ffi::OsStr> = argv.iter().map(|a| a.as_os_str()).collect();
        let (code, _, err) = run_tessera(&argv);
        no_panic(&err);
        assert_eq!(code, 1, "{argv:?}: {err}");
        assert!(err.contains(want), "{argv:?}: wanted {want:?} in {err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    }
    assert_eq!(
        std::fs::read_to_string(full.join("notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(std::fs::read_dir(&full).unwrap().count(), 1);
    let mut names: Vec<String> = std::fs::read_dir(work.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["corrupt.tsr", "file", "full", "mesh.ply", "placed", "tiles"],
        "nothing else written"
    );
    assert!(leftovers(work.path()).is_empty());
}
