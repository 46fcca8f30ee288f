//! Issue 11: computed normals are shared by every copy of a position, so UV seams never
//! show in the shading (a textured cow rendered with creased legs and horns, sibling
//! normals 70-160 degrees apart, smooth once its `vt` lines were removed).

use std::fmt::Write as _;

use tessera_build::import::{compute_normals, import};
use tessera_build::NoProgress;

const SEGMENTS: usize = 16;
const RINGS: usize = 8;

/// A UV sphere as exported by modelling tools: one vertex per (position, uv) pair, so
/// the seam at longitude 0 and every pole vertex are split into copies; no normals.
fn uv_sphere_obj() -> String {
    let mut obj = String::new();
    for j in 0..=RINGS {
        let theta = std::f64::consts::PI * j as f64 / RINGS as f64;
        for i in 0..=SEGMENTS {
            let phi = std::f64::consts::TAU * (i % SEGMENTS) as f64 / SEGMENTS as f64;
            let (x, y, z) = (
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            // Exactly the same coordinates for every copy of a position.
            let (x, y, z) = if j == 0 || j == RINGS {
                (0.0, y, 0.0)
            } else {
                (x, y, z)
            };
            writeln!(obj, "v {x:.7} {y:.7} {z:.7}").unwrap();
            let (u, v) = (i as f64 / SEGMENTS as f64, j as f64 / RINGS as f64);
            writeln!(obj, "vt {u:.6} {v:.6}").unwrap();
        }
    }
    let id = |i: usize, j: usize| j * (SEGMENTS + 1) + i + 1;
    for j in 0..RINGS {
        for i in 0..SEGMENTS {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if j > 0 {
                writeln!(obj, "f {a}/{a} {b}/{b} {c}/{c}").unwrap();
            }
            if j + 1 < RINGS {
                writeln!(obj, "f {a}/{a} {c}/{c} {d}/{d}").unwrap();
            }
        }
    }
    obj
}

/// How far the unit normal `n` at `p` leans around the sphere's axis (y), in degrees
/// (signed). The quads' diagonals make every vertex lean a little, the same at every
/// vertex of a ring by symmetry, but one-sided normals at the seam lean differently.
fn azimuthal_lean_deg(n: [f32; 3], p: [f64; 3]) -> f64 {
    let r = (p[0] * p[0] + p[2] * p[2]).sqrt();
    if r < 1e-9 {
        return 0.0; // a pole: any meridian
    }
    let t = [-p[2] / r, 0.0, p[0] / r];
    let d: f64 = (0..3).map(|k| f64::from(n[k]) * t[k]).sum();
    d.clamp(-1.0, 1.0).asin().to_degrees()
}

#[test]
fn copies_of_a_position_share_one_computed_normal() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.obj");
    std::fs::write(&input, uv_sphere_obj()).unwrap();
    // An ample memory budget (one pass over the positions) and a tiny one (many).
    for memory in [1u64 << 30, 1 << 10] {
        let tmp = tempfile::tempdir().unwrap();
        let imp = import(&input, tmp.path(), &Default::default(), &NoProgress).unwrap();
        assert!(imp.normals_computed && imp.attributes.uvs);
        let normals = compute_normals(&imp, tmp.path(), memory, &|| false).unwrap();
        let mut by_pos: std::collections::HashMap<[u32; 3], Vec<u32>> = Default::default();
        for i in 0..imp.vertex_count as u32 {
            let p = imp.vertices.get(i).position;
            by_pos.entry(p.map(f32::to_bits)).or_default().push(i);
        }
        let mut copies = 0;
        let mut lean: std::collections::BTreeMap<i64, (f64, f64)> = Default::default();
        for ids in by_pos.values() {
            let n0 = normals.get(ids[0]);
            for &i in ids {
                assert_eq!(normals.get(i), n0, "copies {ids:?} (memory {memory})");
                copies += usize::from(i != ids[0]);
            }
            let p = imp.vertices.get(ids[0]).position.map(f64::from);
            let l = azimuthal_lean_deg(n0, p);
            let ring = lean
                .entry((p[1] * 1e4).round() as i64)
                .or_insert((f64::INFINITY, f64::NEG_INFINITY));
            *ring = (ring.0.min(l), ring.1.max(l));
        }
        let worst = lean.values().map(|(lo, hi)| hi - lo).fold(0.0, f64::max);
        eprintln!(
            "memory {memory}: {copies} copies, leans differ by up to {worst:.4} deg in a ring"
        );
        // One seam copy per inner ring, SEGMENTS - 1 copies at each pole (the importer
        // emits only the (v, vt) pairs faces use).
        assert_eq!(copies, (RINGS - 1) + 2 * (SEGMENTS - 1));
        assert!(worst < 0.01, "{worst} degrees");
    }
}
