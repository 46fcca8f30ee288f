//! The WGSL shader parses and validates with naga, with no GPU: a shader error shows up
//! here, not as a device error on a user's machine.

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

/// Every entry point translates to GLSL ES 3.00, the browser's WebGL2 (what wgpu's GL
/// backend does at pipeline creation there), so a construct WebGL2 lacks fails here.
#[test]
fn patch_shader_translates_for_webgl2() {
    let module = naga::front::wgsl::parse_str(tessera_render::PATCH_SHADER).unwrap();
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap();
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
        .unwrap_or_else(|e| panic!("{}: {e:?}", ep.name));
        w.write().unwrap_or_else(|e| panic!("{}: {e:?}", ep.name));
        assert!(out.starts_with("#version 300 es"), "{}", ep.name);
        if ep.name == "fs_textured" {
            assert!(out.contains("textureGrad"), "{out}");
        }
    }
}
