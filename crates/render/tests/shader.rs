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
