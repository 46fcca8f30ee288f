//! A build is a pure function of its input and options: the same bytes whatever the
//! thread count, the order diamonds finish in, or the memory budget (which sets the
//! chunk sizes of the partition passes).

use std::path::Path;
use tessera_build::{build, BuildOptions, NoProgress};

fn sphere(dir: &Path) -> std::path::PathBuf {
    let input = dir.join("sphere.ply");
    tessera_gen::write_sphere(
        &input,
        &tessera_gen::SphereOptions {
            triangles: 60_000,
            colors: true,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    input
}

fn build_bytes(input: &Path, dir: &Path, name: &str, opts: &BuildOptions) -> Vec<u8> {
    let out = dir.join(name);
    build(input, &out, opts, &NoProgress).unwrap();
    std::fs::read(out).unwrap()
}

#[test]
fn same_bytes_for_any_threads_and_memory_budget() {
    // Why: diamond ids used to follow completion order, so two builds of one input
    // differed; and chunked passes must not depend on where the chunks end.
    let dir = tempfile::tempdir().unwrap();
    let input = sphere(dir.path());
    let base = BuildOptions {
        leaf_triangles: 512,
        node_triangles: 256,
        ..Default::default()
    };
    let reference = build_bytes(
        &input,
        dir.path(),
        "one.tsr",
        &BuildOptions {
            threads: Some(1),
            ..base.clone()
        },
    );
    for (name, opts) in [
        (
            "four.tsr",
            BuildOptions {
                threads: Some(4),
                ..base.clone()
            },
        ),
        (
            // The smallest chunks the partition passes use (16k faces).
            "small-memory.tsr",
            BuildOptions {
                threads: Some(3),
                memory_bytes: 1 << 20,
                ..base.clone()
            },
        ),
    ] {
        let bytes = build_bytes(&input, dir.path(), name, &opts);
        assert!(bytes == reference, "{name} differs from the 1-thread build");
    }
}
