//! Every WGSL shader of the workspace parses and validates with naga, with no GPU, and
//! translates to GLSL ES 3.00 (the browser's WebGL2): a shader error shows up here, not
//! as a device error on a user's machine.

use std::path::{Path, PathBuf};

/// Every `.wgsl` file under the workspace's `crates/*/src`.
fn workspace_shaders() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "wgsl") {
                out.push(p);
            }
        }
    }
    let crates = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = Vec::new();
    for c in std::fs::read_dir(&crates).unwrap().flatten() {
        walk(&c.path().join("src"), &mut out);
    }
    out.sort();
    out
}

/// Validates `source` and translates each entry point to GLSL ES 3.00 for WebGL2:
/// (entry point, GLSL) of each.
fn validate_for_webgl2(name: &str, source: &str) -> Vec<(String, String)> {
    let module = naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{name}: invalid shader: {e:?}"));
    let mut translated = Vec::new();
    for ep in &module.entry_points {
        let options = naga::back::glsl::Options {
            version: naga::back::glsl::Version::Embedded {
                version: 300,
                is_webgl: true,
            },
            ..Default::default()
        };
        let pipeline = naga::back::glsl::PipelineOptions {
            shader_stage: ep.stage,
            entry_point: ep.name.clone(),
            multiview: None,
        };
        let mut out = String::new();
        let mut w = naga::back::glsl::Writer::new(
            &mut out,
            &module,
            &info,
            &options,
            &pipeline,
            naga::proc::BoundsCheckPolicies::default(),
        )
        .unwrap_or_else(|e| panic!("{name} {}: {e:?}", ep.name));
        w.write()
            .unwrap_or_else(|e| panic!("{name} {}: {e:?}", ep.name));
        assert!(out.starts_with("#version 300 es"), "{name} {}", ep.name);
        translated.push((ep.name.clone(), out));
    }
    translated
}

/// The patch shader, the window's blit and the browser's depth pick: every WGSL file
/// (a new one is found and checked without touching this test).
#[test]
fn every_wgsl_file_validates_and_translates_for_webgl2() {
    let files = workspace_shaders();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in ["patch.wgsl", "blit.wgsl", "pick.wgsl"] {
        assert!(
            names.iter().any(|n| n == want),
            "{want} not found: {names:?}"
        );
    }
    for p in &files {
        let source = std::fs::read_to_string(p).unwrap();
        let entries = validate_for_webgl2(&p.display().to_string(), &source);
        assert!(!entries.is_empty(), "{}", p.display());
    }
}

#[test]
fn patch_shader_validates() {
    let module = naga::front::wgsl::parse_str(tessera_render::PATCH_SHADER)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string(tessera_render::PATCH_SHADER)));
    let mut v = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    );
    v.validate(&module)
        .unwrap_or_else(|e| panic!("invalid shader: {e:?}"));
    let entry: Vec<&str> = module
        .entry_points
        .iter()
        .map(|e| e.name.as_str())
        .collect();
    assert!(
        ["vs_main", "fs_main", "vs_textured", "fs_textured"]
            .iter()
            .all(|e| entry.contains(e)),
        "{entry:?}"
    );
}

#[test]
fn broken_shader_is_caught() {
    // Negative control: the same check fails on a type error.
    let bad = tessera_render::PATCH_SHADER
        .replace("max(dot(n, frame.light_dir.xyz), 0.0)", "max(n, 0.0)");
    let parsed = naga::front::wgsl::parse_str(&bad);
    let failed = match parsed {
        Err(_) => true,
        Ok(m) => naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&m)
        .is_err(),
    };
    assert!(failed);
}

/// The patch shader's textured fragment stage samples with explicit gradients in
/// GLSL ES 3.00 too (the mip clamp of a patch morphing in needs them).
#[test]
fn patch_shader_translates_for_webgl2() {
    let entries = validate_for_webgl2("patch.wgsl", tessera_render::PATCH_SHADER);
    let (_, out) = entries
        .iter()
        .find(|(name, _)| name == "fs_textured")
        .expect("fs_textured");
    assert!(out.contains("textureGrad"), "{out}");
}
