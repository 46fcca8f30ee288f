//! Issue 14, "no input lost": the default grid used to follow the mean edge alone, so a
//! mesh with a wide range of triangle sizes lost its small triangles at the finest level
//! (two corners on one grid point; 0.19-1.4% of two public meshes), silently. The grid
//! now also follows the shortest sampled edge, and whatever still collapses is counted
//! with the bits that would keep it.

use std::fmt::Write as _;
use std::path::Path;

use tessera_build::{build, BuildOptions, BuildReport, NoProgress, MAX_QUANT_BITS};
use tessera_format::{Model, NODE_FLAG_LEAF};

/// A `n` x `n` grid of quads (two triangles each) of side `step` from `origin`, in the
/// plane z = origin[2], appended to `obj` whose vertex count is `*base`.
fn grid(obj: &mut String, base: &mut usize, origin: [f64; 3], n: usize, step: f64) {
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (origin[0] + i as f64 * step, origin[1] + j as f64 * step);
            writeln!(obj, "v {x:.9} {y:.9} {:.9}", origin[2]).unwrap();
        }
    }
    let id = |i: usize, j: usize| *base + j * (n + 1) + i + 1;
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            writeln!(obj, "f {a} {b} {c}\nf {a} {c} {d}").unwrap();
        }
    }
    *base += (n + 1) * (n + 1);
}

/// 28,800 triangles of edge 1/120 on the unit square and 7,200 of edge 2e-5 (400x
/// shorter) in a small square above it, 1 unit away.
fn wide_range_obj() -> String {
    let (mut obj, mut base) = (String::new(), 0);
    grid(&mut obj, &mut base, [0.0, 0.0, 0.0], 120, 1.0 / 120.0);
    grid(&mut obj, &mut base, [0.5, 0.5, 1.0], 60, 2e-5);
    obj
}

/// The bounding cube's edge.
fn cube_size(r: &BuildReport) -> f64 {
    r.quant_step * (1u64 << r.quant_bits) as f64
}

const INPUT_TRIANGLES: u64 = 2 * (120 * 120 + 60 * 60);

fn built(input: &Path, out: &Path, quant_bits: Option<u32>) -> (BuildReport, u64) {
    let opts = BuildOptions {
        quant_bits,
        ..Default::default()
    };
    let r = build(input, out, &opts, &NoProgress).unwrap();
    let m = Model::open(out).unwrap();
    let leaves: u64 = m
        .nodes()
        .iter()
        .filter(|n| n.flags & NODE_FLAG_LEAF != 0)
        .map(|n| u64::from(n.triangle_count))
        .sum();
    (r, leaves)
}

#[test]
fn a_wide_range_of_triangle_sizes_keeps_every_input_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("wide.obj");
    std::fs::write(&input, wide_range_obj()).unwrap();
    let out = dir.path().join("wide.tsr");

    let (r, leaves) = built(&input, &out, None);
    eprintln!(
        "default: {} bits (mean edge {:.3e}), {leaves} of {INPUT_TRIANGLES} triangles at the \
         finest level, {} collapsed, {} B/triangle",
        r.quant_bits,
        r.mean_edge,
        r.triangles_collapsed_by_grid,
        r.bytes_per_input_triangle()
    );
    assert_eq!(r.input_triangles, INPUT_TRIANGLES);
    assert_eq!(r.triangles_collapsed_by_grid, 0);
    assert_eq!(r.degenerate_triangles_removed, 0);
    assert_eq!(r.quant_bits_to_keep_all, None);
    assert_eq!(
        leaves, INPUT_TRIANGLES,
        "the finest level holds every triangle"
    );

    // Negative control: the mean-edge grid (12 bits here, a cell of ~2.4e-4) loses the
    // small square, and says which grid would keep it.
    let mean_bits = tessera_build::partition::auto_quant_bits(cube_size(&r), r.mean_edge);
    assert!(mean_bits < r.quant_bits, "{mean_bits} vs {}", r.quant_bits);
    let (coarse, leaves) = built(&input, &out, Some(mean_bits));
    eprintln!(
        "{mean_bits} bits: {leaves} triangles kept, {} collapsed, keep all with {:?}",
        coarse.triangles_collapsed_by_grid, coarse.quant_bits_to_keep_all
    );
    assert!(coarse.triangles_collapsed_by_grid > 3000);
    assert_eq!(
        leaves + coarse.triangles_collapsed_by_grid + coarse.duplicate_triangles_removed,
        INPUT_TRIANGLES
    );
    let keep = coarse.quant_bits_to_keep_all.expect("bits that keep them");
    let (again, leaves) = built(&input, &out, Some(keep));
    assert_eq!(again.triangles_collapsed_by_grid, 0, "{keep} bits");
    assert_eq!(leaves, INPUT_TRIANGLES);
}

#[test]
fn a_sliver_beyond_the_finest_grid_is_reported_not_silently_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sliver.obj");
    let mut obj = String::new();
    let mut base = 0;
    grid(&mut obj, &mut base, [0.0, 0.0, 0.0], 40, 1.0 / 40.0);
    // One triangle with an edge of 1e-7 (a 2^21 grid's cell is ~5e-7 here), with an
    // area: its corners are distinct in the input.
    obj.push_str("v 0.3 0.3 0.5\nv 0.3000001 0.3 0.5\nv 0.3 0.4 0.5\n");
    writeln!(obj, "f {} {} {}", base + 1, base + 2, base + 3).unwrap();
    std::fs::write(&input, obj).unwrap();
    let (r, leaves) = built(&input, &dir.path().join("s.tsr"), None);
    assert_eq!(r.triangles_collapsed_by_grid, 1, "{r:?}");
    assert_eq!(r.quant_bits_to_keep_all, Some(MAX_QUANT_BITS));
    assert_eq!(leaves, 2 * 40 * 40);
    // The sliver does not buy the whole model 21 bits: at most MAX_EXTRA_BITS more
    // than the mean edge asks for.
    assert!(
        r.quant_bits
            <= tessera_build::partition::auto_quant_bits(cube_size(&r), r.mean_edge)
                + tessera_build::partition::MAX_EXTRA_BITS,
        "{} bits",
        r.quant_bits
    );
}
