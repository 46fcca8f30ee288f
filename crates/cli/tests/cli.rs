//! The `tessera` binary itself: exit codes, messages, and what is (not) left on disk.

mod common;

use common::*;
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use tessera_format::{Model, NODE_FLAG_LEAF};
use tessera_select::{select_cut, Criterion};

fn entries(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

/// The single `error:` line of a failed command's stderr (panics if there is not exactly
/// one, or if the command panicked).
fn error_line(stderr: &str) -> &str {
    assert!(
        !stderr.contains("panicked"),
        "the command panicked:\n{stderr}"
    );
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(
        lines.len(),
        1,
        "want exactly one `error:` line, stderr:\n{stderr}"
    );
    lines[0]
}

fn json(stdout: &str) -> Value {
    serde_json::from_str(stdout).unwrap_or_else(|e| panic!("not JSON ({e}):\n{stdout}"))
}

fn file_name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

/// A small model built through the library, for the corruption and extract tests.
fn small_model() -> Built {
    build_sphere(5_000, 11, true, &small_options())
}

// ---------------------------------------------------------------- gen, build, info

/// `gen sphere` writes the promised closed sphere, deterministically; `build --json` and
/// `info --json` agree with it, and info's bounding sphere contains every input vertex.
#[test]
fn gen_build_and_info_json() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("s.ply");
    let (code, out, err) = run_tessera(args![
        "gen",
        "sphere",
        "--triangles",
        "3000",
        "--seed",
        "9",
        "-o",
        ply,
        "-q"
    ]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("3072 triangles"), "{out}");
    let input = read_input(&ply);
    // n = round(sqrt(3000 / 12)) = 16: 12 n^2 triangles, 6 n^2 + 2 vertices.
    assert_eq!((input.triangles.len(), input.positions.len()), (3072, 1538));
    for p in &input.positions {
        let r = p.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!(
            (0.95 - 1e-5..=1.05 + 1e-5).contains(&r),
            "vertex at radius {r}"
        );
    }
    // Closed and consistently oriented: every directed edge once, with its reverse.
    let mut directed = std::collections::HashSet::new();
    for t in &input.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            assert!(directed.insert((a, b)), "directed edge {a}-{b} twice");
        }
    }
    assert!(
        directed.iter().all(|&(a, b)| directed.contains(&(b, a))),
        "the generated sphere has a boundary"
    );

    // Deterministic in the seed.
    let again = dir.path().join("again.ply");
    let other = dir.path().join("other.ply");
    run_tessera(args![
        "gen",
        "sphere",
        "--triangles",
        "3000",
        "--seed",
        "9",
        "-o",
        again,
        "-q"
    ]);
    run_tessera(args![
        "gen",
        "sphere",
        "--triangles",
        "3000",
        "--seed",
        "10",
        "-o",
        other,
        "-q"
    ]);
    assert_eq!(
        std::fs::read(&ply).unwrap(),
        std::fs::read(&again).unwrap(),
        "same seed, same bytes"
    );
    assert_ne!(
        std::fs::read(&ply).unwrap(),
        std::fs::read(&other).unwrap(),
        "another seed, another sphere"
    );

    let tsr = dir.path().join("s.tsr");
    let (code, out, err) = run_tessera(args![
        "build",
        ply,
        "-o",
        tsr,
        "--leaf-triangles",
        "400",
        "--node-triangles",
        "200",
        "-q",
        "--json"
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let b = json(&out);
    assert_eq!(b["input_triangles"], 3072);
    assert_eq!(b["input_vertices"], 1538);

    let (code, out, err) = run_tessera(args!["info", tsr, "--json"]);
    assert_eq!(code, 0, "{err}");
    let i = json(&out);
    assert_eq!(i["input"]["triangles"], 3072);
    assert_eq!(i["leaf_triangles"], 3072, "the leaves hold the whole input");
    assert_eq!(i["nodes"], b["nodes"]);
    assert_eq!(i["levels"], b["levels"]);
    let per_level = i["per_level"].as_array().unwrap();
    assert_eq!(per_level.len() as u64, i["levels"].as_u64().unwrap());
    let sum: u64 = per_level
        .iter()
        .map(|l| l["triangles"].as_u64().unwrap())
        .sum();
    assert_eq!(sum, i["triangles"].as_u64().unwrap());

    let c: Vec<f64> = i["bounding_sphere"]["center"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let r = i["bounding_sphere"]["radius"].as_f64().unwrap();
    assert_eq!(c.len(), 3);
    let far = input
        .positions
        .iter()
        .map(|p| {
            ((0..3)
                .map(|k| (f64::from(p[k]) - c[k]).powi(2))
                .sum::<f64>())
            .sqrt()
        })
        .fold(0.0f64, f64::max);
    assert!(
        far <= r * (1.0 + 1e-6),
        "a vertex is {far} from the bounding sphere's centre, radius {r}"
    );
    // The tightest sphere around this mesh has a radius of at most 1.05.
    eprintln!("info bounding sphere: centre {c:.4?}, radius {r:.4} (farthest input vertex {far:.4}; ratio {:.2})", r / far);

    // Human-readable output works too.
    let (code, out, _) = run_tessera(args!["info", tsr]);
    assert_eq!(code, 0);
    assert!(out.contains("bounding sphere"), "{out}");
}

// ---------------------------------------------------------------- verify

fn flip_byte(src: &Path, dst: &Path, offset: u64) {
    let mut b = std::fs::read(src).unwrap();
    b[offset as usize] ^= 0x5a;
    std::fs::write(dst, b).unwrap();
}

fn verify_fails(path: &Path, what: &str, expect_in_message: &str) -> String {
    let (code, out, err) = run_tessera(args!["verify", path]);
    assert_ne!(code, 0, "verify accepted a file with {what}:\n{out}{err}");
    let line = error_line(&err).to_owned();
    assert!(
        line.contains(&file_name(path)),
        "{what}: error does not name the file: {line}"
    );
    let all = format!("{out}{err}");
    assert!(
        all.contains(expect_in_message),
        "{what}: expected {expect_in_message:?} in:\n{all}"
    );
    all
}

/// `verify` passes on fresh builds and fails, naming the file and the problem, on files
/// damaged on purpose: a flipped byte in a patch, in the node table, in the header; a
/// changed version; truncation; not a model at all.
#[test]
fn verify_passes_on_builds_and_fails_on_corruption() {
    let b = small_model();
    let (code, out, err) = run_tessera(args!["verify", b.model_path]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("valid"), "{out}");
    let h = *b.model.header();
    let dir = b.dir.path();

    // A byte in the middle of a leaf's patch, and one in a root's.
    let leaf = b
        .model
        .nodes()
        .iter()
        .position(|n| n.flags & NODE_FLAG_LEAF != 0)
        .unwrap();
    for node in [leaf, 0] {
        let n = &b.model.nodes()[node];
        let bad = dir.join(format!("patch{node}.tsr"));
        flip_byte(
            &b.model_path,
            &bad,
            n.patch_offset + u64::from(n.patch_bytes) / 2,
        );
        let all = verify_fails(&bad, "a corrupt patch", &format!("node {node}"));
        assert!(all.contains("checksum"), "{all}");
    }
    let bad = dir.join("table.tsr");
    flip_byte(&b.model_path, &bad, h.index_layout().pages_offset + 7);
    verify_fails(&bad, "a corrupt index page", "index page 0");
    let bad = dir.join("header.tsr");
    flip_byte(&b.model_path, &bad, 100); // inside the cube origin
    verify_fails(&bad, "a corrupt header", "header");
    let bad = dir.join("version.tsr");
    let mut bytes = std::fs::read(&b.model_path).unwrap();
    bytes[8] = 99;
    std::fs::write(&bad, &bytes).unwrap();
    verify_fails(&bad, "an unknown version", "version 99");
    for (name, len) in [
        ("short1.tsr", bytes.len() - 1),
        ("half.tsr", bytes.len() / 2),
        ("tiny.tsr", 100),
    ] {
        let bad = dir.join(name);
        std::fs::write(&bad, &std::fs::read(&b.model_path).unwrap()[..len]).unwrap();
        verify_fails(&bad, "truncation", "truncated");
    }
    let bad = dir.join("notamodel.tsr");
    std::fs::write(&bad, vec![7u8; 4096]).unwrap();
    verify_fails(&bad, "garbage", "not a Tessera model");
    verify_fails(&dir.join("missing.tsr"), "no file at all", "missing.tsr");
}

// ---------------------------------------------------------------- bad input to build

fn write_ascii_ply(path: &Path, vertices: &[&str], faces: &[&str]) {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        vertices.len(),
        faces.len()
    );
    for v in vertices.iter().chain(faces) {
        s += v;
        s += "\n";
    }
    std::fs::write(path, s).unwrap();
}

/// A binary little-endian PLY with one triangle whose first vertex is NaN.
fn write_binary_ply_with_nan(path: &Path) {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
    for v in [[f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b.push(3);
    for i in [0u32, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(path, b).unwrap();
}

/// Every kind of bad input makes `build` exit non-zero with one `error:` line naming
/// the input, and leaves the output directory exactly as it was: no model, no
/// `.tessera-build-*` directory, no `.NAME.tmp-*` file.
#[test]
fn build_rejects_bad_input_cleanly() {
    let good = tempfile::tempdir().unwrap();
    let sphere = good.path().join("sphere.ply");
    tessera_gen::write_sphere(
        &sphere,
        &tessera_gen::SphereOptions {
            triangles: 2000,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let sphere_bytes = std::fs::read(&sphere).unwrap();

    type Make = Box<dyn Fn(&Path)>;
    let cases: Vec<(&str, &str, Make)> = vec![
        ("truncated binary PLY", "truncated.ply", {
            let b = sphere_bytes.clone();
            Box::new(move |p| std::fs::write(p, &b[..b.len() * 6 / 10]).unwrap())
        }),
        ("binary PLY cut inside the header", "cut-header.ply", {
            let b = sphere_bytes.clone();
            Box::new(move |p| std::fs::write(p, &b[..40]).unwrap())
        }),
        (
            "out-of-range index",
            "index.ply",
            Box::new(|p| write_ascii_ply(p, &["0 0 0", "1 0 0", "0 1 0"], &["3 0 1 7"])),
        ),
        (
            "negative index",
            "negative.obj",
            Box::new(|p| std::fs::write(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9\n").unwrap()),
        ),
        (
            "NaN coordinate (ascii PLY)",
            "nan.ply",
            Box::new(|p| write_ascii_ply(p, &["nan 0 0", "1 0 0", "0 1 0"], &["3 0 1 2"])),
        ),
        (
            "NaN coordinate (binary PLY)",
            "nan-bin.ply",
            Box::new(write_binary_ply_with_nan),
        ),
        (
            "infinite coordinate (OBJ)",
            "inf.obj",
            Box::new(|p| std::fs::write(p, "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n").unwrap()),
        ),
        (
            "empty PLY",
            "empty.ply",
            Box::new(|p| write_ascii_ply(p, &[], &[])),
        ),
        (
            "empty OBJ",
            "empty.obj",
            Box::new(|p| std::fs::write(p, "").unwrap()),
        ),
        (
            "only degenerate faces",
            "degenerate.obj",
            Box::new(|p| std::fs::write(p, "v 0 0 0\nv 1 0 0\nf 1 1 2\n").unwrap()),
        ),
        (
            "empty STL",
            "empty.stl",
            Box::new(|p| std::fs::write(p, "").unwrap()),
        ),
        // (A PLY under an unknown extension is read: its first bytes say PLY.)
        (
            "unknown extension",
            "mesh.xyz",
            Box::new(|p| std::fs::write(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap()),
        ),
        ("missing file", "missing.ply", Box::new(|_| {})),
        (
            "a directory",
            "adir.ply",
            Box::new(|p| std::fs::create_dir(p).unwrap()),
        ),
    ];
    for (what, name, make) in &cases {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join(name);
        make(&input);
        let before = entries(dir.path());
        let out = dir.path().join("out.tsr");
        let (code, stdout, stderr) = run_tessera(args!["build", input, "-o", out, "-q"]);
        assert_ne!(code, 0, "{what}: build succeeded:\n{stdout}{stderr}");
        let line = error_line(&stderr);
        assert!(
            line.contains(name),
            "{what}: the error does not name {name}: {line}"
        );
        assert!(!out.exists(), "{what}: an output file was left");
        assert_eq!(
            leftovers(dir.path()),
            Vec::<String>::new(),
            "{what}: temporary files left"
        );
        assert_eq!(entries(dir.path()), before, "{what}: the directory changed");
        eprintln!("{what:<34} -> exit {code}: {line}");
    }

    // An output that cannot be written (its directory does not exist).
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("no/such/dir/out.tsr");
    let (code, _, stderr) = run_tessera(args!["build", sphere, "-o", out, "-q"]);
    assert_ne!(code, 0);
    error_line(&stderr);
    assert_eq!(entries(dir.path()), BTreeSet::new());
    // Bad options.
    let out = dir.path().join("out.tsr");
    let (code, _, stderr) = run_tessera(args![
        "build",
        sphere,
        "-o",
        out,
        "-q",
        "--leaf-triangles",
        "4"
    ]);
    assert_ne!(code, 0);
    error_line(&stderr);
    assert_eq!(entries(dir.path()), BTreeSet::new());
}

// ---------------------------------------------------------------- extract

fn extract_json(args: &[&std::ffi::OsStr]) -> Value {
    let (code, out, err) = run_tessera(args);
    assert_eq!(code, 0, "extract failed: {out}{err}");
    json(&out)
}

fn write_camera(path: &Path, position: [f64; 3], target: [f64; 3]) {
    let cam = serde_json::json!({
        "position": position, "target": target, "up": [0.0, 0.0, 1.0],
        "fov_y_deg": 50.0, "width": 800, "height": 600,
    });
    std::fs::write(path, cam.to_string()).unwrap();
}

/// `extract` writes exactly the library's cut, in model coordinates, with the model's
/// attributes, and reports its counts and edge report; every criterion works; the cuts of
/// a closed model are closed.
#[test]
fn extract_writes_the_cut_and_reports_it() {
    let b = small_model();
    let m = &b.model;
    let h = *m.header();
    let dir = b.dir.path();
    let patches = decode_all(m);

    // The finest cut, compared vertex by vertex with the library's merge.
    let out = dir.join("finest.ply");
    let j = extract_json(args![
        "extract",
        b.model_path,
        "--max-error",
        "0",
        "-o",
        out,
        "--json"
    ]);
    let cut = select_cut(&h, m.nodes(), &Criterion::MaxError { max_error: 0.0 });
    let mesh = merge(&patches, &cut.nodes);
    assert_eq!(j["nodes"], cut.nodes.len());
    assert_eq!(j["triangles"], mesh.triangle_count());
    assert_eq!(j["triangles"], b.report.input_triangles);
    assert_eq!(j["vertices"], mesh.positions.len());
    assert_eq!(j["edges"]["boundary"], 0);
    assert_eq!(j["edges"]["nonmanifold"], 0);
    assert_eq!(j["closed_manifold"], true);
    let ply = read_input(&out);
    assert!(
        ply.attributes.normals && ply.attributes.colors && !ply.attributes.uvs,
        "{:?}",
        ply.attributes
    );
    assert_eq!(ply.positions.len(), mesh.positions.len());
    assert_eq!(ply.triangles.len(), mesh.triangle_count());
    for (k, q) in mesh.positions.iter().enumerate() {
        let p = m.grid().position(*q);
        assert_eq!(
            ply.positions[k],
            [p[0] as f32, p[1] as f32, p[2] as f32],
            "vertex {k}"
        );
        assert_eq!(ply.normals[k], mesh.normals[k], "normal {k}");
        assert_eq!(ply.colors[k], mesh.colors[k], "colour {k}");
    }
    let flat: Vec<u32> = ply.triangles.iter().flatten().copied().collect();
    assert_eq!(flat, mesh.indices);
    // The input's colours survive to the finest cut (look up by quantized position).
    let input = read_input(&b.input);
    let colour_at: std::collections::HashMap<[u32; 3], [u8; 4]> = mesh
        .positions
        .iter()
        .copied()
        .zip(mesh.colors.iter().copied())
        .collect();
    for (p, c) in input.positions.iter().zip(&input.colors) {
        assert_eq!(colour_at.get(&quantize(&h, *p)), Some(c));
    }

    // Every level, human-readable output.
    for level in 0..h.level_count {
        let out = dir.join(format!("level{level}.ply"));
        let (code, stdout, err) = run_tessera(args![
            "extract",
            b.model_path,
            "--level",
            level.to_string(),
            "-o",
            out
        ]);
        assert_eq!(code, 0, "{stdout}{err}");
        assert!(
            stdout.contains("0 boundary, 0 non-manifold"),
            "level {level}:\n{stdout}"
        );
        assert!(out.exists());
    }
    let j = extract_json(args![
        "extract",
        b.model_path,
        "--level",
        "0",
        "-o",
        dir.join("roots.ply"),
        "--json"
    ]);
    assert_eq!(j["nodes"], h.root_count);
    assert_eq!(j["levels"]["max"], 0);

    // Max-error at the model's max error: the roots.
    let j = extract_json(args![
        "extract",
        b.model_path,
        "--max-error",
        h.max_error.to_string(),
        "-o",
        dir.join("coarse.ply"),
        "--json"
    ]);
    assert_eq!(j["nodes"], h.root_count);

    // A camera close to the surface: non-uniform and, without culling, closed.
    let cam = dir.join("cam.json");
    write_camera(&cam, [1.15, 0.1, 0.2], [0.0, 0.0, 0.0]);
    let full = extract_json(args![
        "extract",
        b.model_path,
        "--camera",
        cam,
        "--tolerance",
        "1",
        "--no-cull",
        "-o",
        dir.join("v.ply"),
        "--json"
    ]);
    assert_eq!(full["closed_manifold"], true, "{full}");
    assert!(
        full["levels"]["max"].as_u64() > full["levels"]["min"].as_u64(),
        "expected a non-uniform cut: {full}"
    );
    let culled = extract_json(args![
        "extract",
        b.model_path,
        "--camera",
        cam,
        "--tolerance",
        "1",
        "-o",
        dir.join("vc.ply"),
        "--json"
    ]);
    assert!(
        culled["triangles"].as_u64() < full["triangles"].as_u64(),
        "culling keeps less: {culled} vs {full}"
    );
    assert!(
        culled["edges"]["boundary"].as_u64() > Some(0),
        "a culled cut is open"
    );
    assert_eq!(culled["criterion"]["cull"], true);
    // Looking away from the model with culling: an empty but valid PLY.
    write_camera(&cam, [5.0, 0.0, 0.0], [10.0, 0.0, 0.0]);
    let empty = dir.join("empty.ply");
    let j = extract_json(args![
        "extract",
        b.model_path,
        "--camera",
        cam,
        "--tolerance",
        "1",
        "-o",
        empty,
        "--json"
    ]);
    assert_eq!(
        (j["nodes"].as_u64(), j["triangles"].as_u64()),
        (Some(0), Some(0))
    );
    assert!(empty.exists());
    assert_eq!(leftovers(dir), Vec::<String>::new());
}

/// Failures of `extract`: one `error:` line, non-zero exit, no output and no temporary
/// file. A corrupt patch names the node; a bad camera names the file and the field;
/// arguments are checked.
#[test]
fn extract_fails_cleanly() {
    let b = small_model();
    let m = &b.model;
    let dir = b.dir.path();
    let out = dir.join("cut.ply");
    let check = |args: &[&std::ffi::OsStr], what: &str, expect: &[&str], usage: bool| {
        let (code, stdout, stderr) = run_tessera(args);
        assert_ne!(code, 0, "{what}: extract succeeded:\n{stdout}");
        if usage {
            assert_eq!(code, 2, "{what}: usage errors exit 2:\n{stderr}");
            assert!(stderr.starts_with("error:"), "{what}:\n{stderr}");
        } else {
            let line = error_line(&stderr);
            for e in expect {
                assert!(line.contains(e), "{what}: expected {e:?} in: {line}");
            }
            eprintln!("{what:<28} -> {line}");
        }
        assert!(!out.exists(), "{what}: output written");
        assert_eq!(
            leftovers(dir),
            Vec::<String>::new(),
            "{what}: temporary files left"
        );
    };

    // A corrupt leaf patch.
    let leaf = m
        .nodes()
        .iter()
        .position(|n| n.flags & NODE_FLAG_LEAF != 0)
        .unwrap();
    let n = &m.nodes()[leaf];
    let bad = dir.join("bad.tsr");
    flip_byte(
        &b.model_path,
        &bad,
        n.patch_offset + u64::from(n.patch_bytes) / 3,
    );
    check(
        args!["extract", bad, "--max-error", "0", "-o", out],
        "corrupt patch",
        &["bad.tsr", &format!("node {leaf}"), "checksum"],
        false,
    );
    // ... which a coarse cut does not read: that extraction succeeds.
    let (code, _, err) = run_tessera(args!["extract", bad, "--level", "0", "-o", out]);
    assert_eq!(code, 0, "{err}");
    std::fs::remove_file(&out).unwrap();

    // Bad cameras.
    let cam = dir.join("badcam.json");
    let base = serde_json::json!({"position": [3.0, 0.0, 0.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0], "fov_y_deg": 50.0, "width": 800, "height": 600});
    let mut fov = base.clone();
    fov["fov_y_deg"] = 190.0.into();
    let mut typo = base.clone();
    typo.as_object_mut()
        .unwrap()
        .insert("positon".into(), serde_json::json!([1, 2, 3]));
    let mut short = base.clone();
    short["target"] = serde_json::json!([0.0, 0.0]);
    let mut missing = base.clone();
    missing.as_object_mut().unwrap().remove("height");
    for (what, text, field) in [
        ("fov out of range", fov.to_string(), "fov_y_deg"),
        ("unknown field", typo.to_string(), "positon"),
        ("2-element target", short.to_string(), "target"),
        ("missing height", missing.to_string(), "height"),
        ("not JSON", "{ position: ".to_string(), "JSON"),
    ] {
        std::fs::write(&cam, text).unwrap();
        check(
            args![
                "extract",
                b.model_path,
                "--camera",
                cam,
                "--tolerance",
                "1",
                "-o",
                out
            ],
            what,
            &["badcam.json", field],
            false,
        );
    }
    check(
        args![
            "extract",
            b.model_path,
            "--camera",
            dir.join("nocam.json"),
            "--tolerance",
            "1",
            "-o",
            out
        ],
        "missing camera file",
        &["nocam.json"],
        false,
    );

    // Arguments.
    check(
        args!["extract", b.model_path, "-o", out],
        "no criterion",
        &[],
        true,
    );
    check(
        args![
            "extract",
            b.model_path,
            "--level",
            "0",
            "--max-error",
            "1",
            "-o",
            out
        ],
        "two criteria",
        &[],
        true,
    );
    std::fs::write(&cam, base.to_string()).unwrap();
    check(
        args!["extract", b.model_path, "--camera", cam, "-o", out],
        "camera without tolerance",
        &[],
        true,
    );
    check(
        args![
            "extract",
            b.model_path,
            "--level",
            "0",
            "--tolerance",
            "1",
            "-o",
            out
        ],
        "tolerance without camera",
        &[],
        true,
    );
    let levels = m.header().level_count.to_string();
    check(
        args!["extract", b.model_path, "--level", levels, "-o", out],
        "level out of range",
        &["--level", "levels"],
        false,
    );
    check(
        args!["extract", b.model_path, "--max-error", "-1", "-o", out],
        "negative error",
        &["--max-error"],
        false,
    );
    check(
        args!["extract", b.model_path, "--max-error", "NaN", "-o", out],
        "NaN error",
        &["--max-error"],
        false,
    );
    std::fs::write(&cam, base.to_string()).unwrap();
    check(
        args![
            "extract",
            b.model_path,
            "--camera",
            cam,
            "--tolerance",
            "-2",
            "-o",
            out
        ],
        "negative tolerance",
        &["--tolerance"],
        false,
    );
    check(
        args![
            "extract",
            dir.join("nomodel.tsr"),
            "--level",
            "0",
            "-o",
            out
        ],
        "missing model",
        &["nomodel.tsr"],
        false,
    );
    let no_dir: PathBuf = dir.join("no/such/dir/cut.ply");
    let (code, _, stderr) =
        run_tessera(args!["extract", b.model_path, "--level", "0", "-o", no_dir]);
    assert_ne!(code, 0);
    assert!(error_line(&stderr).contains("cut.ply"), "{stderr}");
}

/// `extract --help` documents every criterion.
#[test]
fn extract_help_documents_the_criteria() {
    let (code, out, _) = run_tessera(args!["extract", "--help"]);
    assert_eq!(code, 0);
    for flag in [
        "--max-error",
        "--camera",
        "--tolerance",
        "--no-cull",
        "--level",
        "--json",
        "--output",
    ] {
        assert!(out.contains(flag), "{flag} missing from:\n{out}");
    }
    assert!(out.contains("Uniform cut"), "{out}");
}

/// Silence the unused-import lint for helpers only some tests use.
#[allow(dead_code)]
fn _uses(_: &Model) {}

/// A 600k-triangle sphere in a temporary directory, the output path beside it, and the
/// time one whole `tessera build` of it takes (the model it wrote is removed), so tests
/// can interrupt builds at fractions of that time (import, partition, hierarchy, write).
fn timed_build_fixture() -> (tempfile::TempDir, PathBuf, PathBuf, std::time::Duration) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.ply");
    tessera_gen::write_sphere(
        &input,
        &tessera_gen::SphereOptions {
            triangles: 600_000,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let output = dir.path().join("model.tsr");
    let t = std::time::Instant::now();
    assert!(spawn_build(&input, &output).wait().unwrap().success());
    let full = t.elapsed();
    std::fs::remove_file(&output).unwrap();
    (dir, input, output, full)
}

/// `tessera build -q INPUT -o OUTPUT` as a child process, stderr captured.
fn spawn_build(input: &Path, output: &Path) -> std::process::Child {
    std::process::Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(["build", "-q"])
        .arg(input)
        .arg("-o")
        .arg(output)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap()
}

/// A build killed mid-way (SIGKILL: no destructor runs) leaves nothing at the output
/// path: the model is written to a temporary file and renamed only when complete.
#[test]
fn killed_build_leaves_no_output() {
    use std::os::unix::process::ExitStatusExt;
    let (_dir, input, output, full) = timed_build_fixture();
    let mut killed = 0;
    for fraction in [0.1, 0.35, 0.6, 0.85] {
        let mut child = spawn_build(&input, &output);
        std::thread::sleep(full.mul_f64(fraction));
        child.kill().ok();
        let status = child.wait().unwrap();
        if status.signal().is_some() {
            killed += 1;
            assert!(
                !output.exists(),
                "a build killed at {:.0}% of its run left {}",
                fraction * 100.0,
                output.display()
            );
        } else {
            // It finished before the signal arrived: a complete model is fine.
            std::fs::remove_file(&output).ok();
        }
        // (Hidden temporary files may remain after SIGKILL; a later build in the same
        // directory does not mistake them for anything.)
    }
    assert!(
        killed >= 2,
        "the builds finished before they could be killed"
    );
}

/// Ctrl-C (SIGINT) stops a build cleanly: an `interrupted` error, a non-zero exit, nothing
/// at the output path and no temporary directory left beside it.
#[test]
fn interrupted_build_cleans_up() {
    let (dir, input, output, full) = timed_build_fixture();
    let mut interrupted = 0;
    for fraction in [0.2, 0.5, 0.8] {
        let child = spawn_build(&input, &output);
        std::thread::sleep(full.mul_f64(fraction));
        // SAFETY: plain kill(2) on our own child.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
        let out = child.wait_with_output().unwrap();
        if out.status.success() {
            std::fs::remove_file(&output).ok(); // finished before the signal
            continue;
        }
        interrupted += 1;
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("interrupted"), "unexpected message: {err}");
        assert!(!output.exists());
        let left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(
            left.is_empty(),
            "temporary files left after Ctrl-C: {left:?}"
        );
    }
    assert!(interrupted >= 2, "the builds finished before the signal");
}

/// Issue 14, failures 7 and 8: a warning (here: a face after the declared ones) reaches
/// stderr as plain text when stderr is not a terminal (no ANSI colour codes), and the
/// build still succeeds.
#[test]
fn warnings_are_plain_text_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("extra.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
         end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n",
    )
    .unwrap();
    let out = dir.path().join("extra.tsr");
    let (code, _, err) = run_tessera(args!["build", &ply, "-o", &out]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("ignoring 4 bytes after the last element"),
        "{err}"
    );
    assert!(
        !err.contains('\u{1b}'),
        "colour codes in piped stderr: {err:?}"
    );
}
