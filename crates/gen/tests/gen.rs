//! End-to-end tests: generate, read back with `tessera_mesh::read_mesh`, check the contracts.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use tessera_gen::*;
use tessera_mesh::{read_mesh, Attributes, PlyWriter, PlyWriterOptions, Vertex};
use tessera_testkit::{fnv1a, MeshCollector};

fn load(path: &Path) -> MeshCollector {
    let mut m = MeshCollector::default();
    let report = read_mesh(path, &mut m).expect("read back");
    assert_eq!(report.degenerate_faces_skipped, 0);
    assert_eq!(report.vertices, m.vertices.len() as u64);
    assert_eq!(report.triangles, m.triangles.len() as u64);
    m
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn pos(m: &MeshCollector, i: u32) -> [f64; 3] {
    m.vertices[i as usize].position.map(f64::from)
}

/// Normal (not unit) of triangle `t`.
fn normal(m: &MeshCollector, t: [u32; 3]) -> [f64; 3] {
    let (a, b, c) = (pos(m, t[0]), pos(m, t[1]), pos(m, t[2]));
    cross(sub(b, a), sub(c, a))
}

/// Directed edge -> number of uses.
fn directed_edges(m: &MeshCollector) -> HashMap<(u32, u32), u32> {
    let mut edges = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    edges
}

fn assert_unique_positions(m: &MeshCollector) {
    let set: HashSet<[u32; 3]> = m
        .vertices
        .iter()
        .map(|v| v.position.map(f32::to_bits))
        .collect();
    assert_eq!(set.len(), m.vertices.len(), "duplicate vertex positions");
}

fn assert_non_degenerate(m: &MeshCollector) {
    for t in &m.triangles {
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "repeated index {t:?}"
        );
        let nrm = normal(m, *t);
        assert!(dot(nrm, nrm) > 0.0, "degenerate triangle {t:?}");
    }
}

/// Every check of the sphere contract.
fn check_sphere(m: &MeshCollector, noise: f32) {
    let v = m.vertices.len() as i64;
    let f = m.triangles.len() as i64;
    let edges = directed_edges(m);
    for (&(a, b), &count) in &edges {
        assert_eq!(
            count, 1,
            "directed edge ({a},{b}) used {count} times: inconsistent orientation"
        );
        assert_eq!(
            edges.get(&(b, a)),
            Some(&1),
            "edge ({a},{b}) has no opposite use"
        );
    }
    let e = edges.len() as i64 / 2;
    assert_eq!(v - e + f, 2, "Euler characteristic");
    assert_eq!(3 * f, 2 * e);
    assert_unique_positions(m);
    assert_non_degenerate(m);
    // Outward: the mesh is star-shaped around the origin.
    for t in &m.triangles {
        let c = [0, 1, 2].map(|k| (0..3).map(|i| pos(m, t[i])[k]).sum::<f64>() / 3.0);
        assert!(dot(normal(m, *t), c) > 0.0, "inward triangle {t:?}");
    }
    let lo = 1.0 - f64::from(noise) - 1e-6;
    let hi = 1.0 + f64::from(noise) + 1e-6;
    for (i, _) in m.vertices.iter().enumerate() {
        let p = pos(m, i as u32);
        let r = dot(p, p).sqrt();
        assert!(r >= lo && r <= hi, "vertex {i} at radius {r}");
    }
    // Well-shaped triangles (the tangent-adjusted cube map keeps them near right isosceles).
    let mut min_angle = 180.0f64;
    for t in &m.triangles {
        for k in 0..3 {
            let a = pos(m, t[k]);
            let u = sub(pos(m, t[(k + 1) % 3]), a);
            let w = sub(pos(m, t[(k + 2) % 3]), a);
            let cos = dot(u, w) / (dot(u, u) * dot(w, w)).sqrt();
            min_angle = min_angle.min(cos.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    eprintln!(
        "{} triangles: smallest angle {min_angle:.1} degrees",
        m.triangles.len()
    );
    assert!(min_angle > 20.0, "sliver: {min_angle} degrees");
    // Every vertex is used.
    let mut used = vec![false; m.vertices.len()];
    for t in &m.triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u));
}

#[test]
fn spheres_are_closed_oriented_manifolds() {
    let dir = tempfile::tempdir().unwrap();
    for (requested, seed) in [
        (12u64, 0u64),
        (100, 1),
        (1_000, 2),
        (10_000, 3),
        (50_000, 4),
    ] {
        let path = dir.path().join(format!("s{requested}.ply"));
        let opts = SphereOptions {
            triangles: requested,
            seed,
            ..Default::default()
        };
        let report = write_sphere(&path, &opts, &tessera_gen::NoProgress).unwrap();
        let n = sphere_resolution(requested).unwrap();
        assert_eq!(report.triangles, 12 * n * n);
        assert_eq!(report.vertices, 6 * n * n + 2);
        if requested >= 1000 {
            let rel = (report.triangles as f64 - requested as f64).abs() / requested as f64;
            assert!(rel < 0.1, "{requested} -> {}", report.triangles);
        }
        let m = load(&path);
        assert_eq!(m.vertices.len() as u64, report.vertices);
        assert_eq!(m.triangles.len() as u64, report.triangles);
        assert_eq!(m.header.attributes, Attributes::default());
        check_sphere(&m, opts.noise);
    }
}

#[test]
fn sphere_is_bumpy_and_noise_zero_is_round() {
    let dir = tempfile::tempdir().unwrap();
    let bumpy = dir.path().join("bumpy.ply");
    write_sphere(
        &bumpy,
        &SphereOptions {
            triangles: 20_000,
            noise: 0.1,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let m = load(&bumpy);
    check_sphere(&m, 0.1);
    let radii: Vec<f64> = (0..m.vertices.len())
        .map(|i| dot(pos(&m, i as u32), pos(&m, i as u32)).sqrt())
        .collect();
    let min = radii.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = radii.iter().cloned().fold(0.0, f64::max);
    assert!(max - min > 0.05, "not bumpy: radius in [{min}, {max}]");

    let round = dir.path().join("round.ply");
    write_sphere(
        &round,
        &SphereOptions {
            triangles: 5_000,
            noise: 0.0,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let m = load(&round);
    check_sphere(&m, 0.0);
}

#[test]
fn sphere_colors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ply");
    write_sphere(
        &path,
        &SphereOptions {
            triangles: 5_000,
            colors: true,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let m = load(&path);
    assert!(m.header.attributes.colors);
    assert!(!m.header.attributes.normals);
    let distinct: HashSet<[u8; 4]> = m.vertices.iter().map(|v| v.color).collect();
    assert!(distinct.len() > 50, "only {} colours", distinct.len());
    assert!(m.vertices.iter().all(|v| v.color[3] == 255));
    check_sphere(&m, 0.05);
}

#[test]
fn generators_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let s = |seed| SphereOptions {
        triangles: 30_000,
        seed,
        colors: true,
        ..Default::default()
    };
    write_sphere(&p("a.ply"), &s(5), &tessera_gen::NoProgress).unwrap();
    write_sphere(&p("b.ply"), &s(5), &tessera_gen::NoProgress).unwrap();
    write_sphere(&p("c.ply"), &s(6), &tessera_gen::NoProgress).unwrap();
    let read = |name: &str| std::fs::read(p(name)).unwrap();
    assert_eq!(read("a.ply"), read("b.ply"));
    assert_ne!(read("a.ply"), read("c.ply"));

    let t = |seed| TerrainOptions {
        triangles: 30_000,
        seed,
        colors: true,
    };
    write_terrain(&p("ta.ply"), &t(5), &tessera_gen::NoProgress).unwrap();
    write_terrain(&p("tb.ply"), &t(5), &tessera_gen::NoProgress).unwrap();
    write_terrain(&p("tc.ply"), &t(6), &tessera_gen::NoProgress).unwrap();
    assert_eq!(read("ta.ply"), read("tb.ply"));
    assert_ne!(read("ta.ply"), read("tc.ply"));
}

/// The exact bytes are part of the contract (same on every machine, every run). If a
/// deliberate change to a generator alters them, update the constants.
#[test]
fn golden_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.ply");
    write_sphere(
        &s,
        &SphereOptions {
            triangles: 2_000,
            seed: 42,
            colors: true,
            noise: 0.05,
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let t = dir.path().join("t.ply");
    write_terrain(
        &t,
        &TerrainOptions {
            triangles: 2_000,
            seed: 42,
            colors: true,
        },
        &tessera_gen::NoProgress,
    )
    .unwrap();
    let hs = fnv1a(&std::fs::read(&s).unwrap());
    let ht = fnv1a(&std::fs::read(&t).unwrap());
    assert_eq!(
        (hs, ht),
        (GOLDEN_SPHERE, GOLDEN_TERRAIN),
        "got {hs:#018x}, {ht:#018x}"
    );
}

const GOLDEN_SPHERE: u64 = 0xf43d_d217_d9ce_2b65;
const GOLDEN_TERRAIN: u64 = 0x19cf_6187_abf2_0970;

#[test]
fn terrain_is_an_open_grid() {
    let dir = tempfile::tempdir().unwrap();
    for (requested, colors) in [(2u64, false), (1_000, true), (20_000, false)] {
        let path = dir.path().join(format!("t{requested}.ply"));
        let report = write_terrain(
            &path,
            &TerrainOptions {
                triangles: requested,
                seed: 9,
                colors,
            },
            &tessera_gen::NoProgress,
        )
        .unwrap();
        let mm = terrain_resolution(requested).unwrap();
        assert_eq!(report.vertices, mm * mm);
        assert_eq!(report.triangles, 2 * (mm - 1) * (mm - 1));
        if requested >= 1000 {
            let rel = (report.triangles as f64 - requested as f64).abs() / requested as f64;
            assert!(rel < 0.1, "{requested} -> {}", report.triangles);
        }
        let m = load(&path);
        assert_eq!(m.header.attributes.colors, colors);
        assert_eq!(m.triangles.len() as u64, report.triangles);
        let edges = directed_edges(&m);
        let mut boundary = 0;
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "directed edge ({a},{b}) used twice");
            if !edges.contains_key(&(b, a)) {
                boundary += 1;
            }
        }
        assert_eq!(boundary, 4 * (mm - 1), "boundary edges");
        let e = (edges.len() as u64 + boundary) / 2;
        assert_eq!(
            m.vertices.len() as i64 - e as i64 + m.triangles.len() as i64,
            1,
            "Euler (disc)"
        );
        assert_unique_positions(&m);
        assert_non_degenerate(&m);
        for t in &m.triangles {
            assert!(normal(&m, *t)[2] > 0.0, "triangle {t:?} faces down");
        }
        let mut zmin = f32::INFINITY;
        let mut zmax = f32::NEG_INFINITY;
        for v in &m.vertices {
            let [x, y, z] = v.position;
            assert!((0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y));
            assert!((MIN_HEIGHT..=MAX_HEIGHT).contains(&z), "height {z}");
            zmin = zmin.min(z);
            zmax = zmax.max(z);
        }
        if requested >= 1000 {
            assert!(zmax - zmin > 0.03, "flat terrain: [{zmin}, {zmax}]");
        }
    }
}

/// Two triangles with every attribute, bounding box 2 x 1 x 0.5.
fn write_tiny(path: &Path) {
    let opts = PlyWriterOptions {
        attributes: Attributes {
            normals: true,
            colors: true,
            uvs: true,
            textures: false,
        },
        vertex_count: 4,
        face_count: 2,
        comments: vec![],
    };
    let mut w = PlyWriter::create(path, &opts).unwrap();
    let corners = [
        [0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.5],
        [0.0, 1.0, 0.5],
    ];
    for (i, p) in corners.into_iter().enumerate() {
        w.write_vertex(&Vertex {
            position: p,
            normal: [0.0, -0.4, 0.8],
            color: [10 * i as u8, 20, 30, 200],
            uv: [i as f32 * 0.25, 0.5],
            texture: tessera_mesh::NO_TEXTURE,
        })
        .unwrap();
    }
    w.write_triangle([0, 1, 2]).unwrap();
    w.write_triangle([0, 2, 3]).unwrap();
    w.finish().unwrap();
}

#[test]
fn tile_copies_and_translates() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("tiny.ply");
    write_tiny(&input);
    let src = load(&input);
    for copies in [1u32, 2, 5] {
        let out = dir.path().join(format!("tiled{copies}.ply"));
        let report = write_tiled(
            &input,
            &out,
            &TileOptions { copies },
            &tessera_gen::NoProgress,
        )
        .unwrap();
        let k = u64::from(copies);
        assert_eq!(
            report,
            GenReport {
                vertices: 4 * k,
                triangles: 2 * k
            }
        );
        let m = load(&out);
        assert_eq!(m.header.attributes, src.header.attributes);
        assert_eq!(m.vertices.len() as u64, 4 * k);
        assert_eq!(m.triangles.len() as u64, 2 * k);
        let cols = (1..).find(|c| c * c >= copies).unwrap();
        for c in 0..copies {
            let off = [(c % cols) as f32 * 2.2, (c / cols) as f32 * 1.1, 0.0];
            for i in 0..4 {
                let v = m.vertices[(4 * c + i) as usize];
                let s = src.vertices[i as usize];
                for (a, o) in off.iter().enumerate() {
                    assert!(
                        (v.position[a] - (s.position[a] + o)).abs() < 1e-5,
                        "copy {c} vertex {i}"
                    );
                }
                assert_eq!((v.normal, v.color, v.uv), (s.normal, s.color, s.uv));
            }
            for t in 0..2 {
                let got = m.triangles[(2 * c + t) as usize];
                assert_eq!(got, src.triangles[t as usize].map(|i| i + 4 * c));
            }
        }
        assert_unique_positions(&m);
    }
}

#[test]
fn invalid_arguments_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.ply");
    let invalid = |r: Result<GenReport, GenError>| matches!(r, Err(GenError::InvalidArgument(_)));
    for triangles in [0, 11, 10_000_000_000, u64::MAX] {
        assert!(
            invalid(write_sphere(
                &out,
                &SphereOptions {
                    triangles,
                    ..Default::default()
                },
                &tessera_gen::NoProgress
            )),
            "{triangles}"
        );
    }
    for noise in [-0.1, 1.0, 2.0, f32::NAN, f32::INFINITY] {
        let o = SphereOptions {
            triangles: 1000,
            noise,
            ..Default::default()
        };
        assert!(
            invalid(write_sphere(&out, &o, &tessera_gen::NoProgress)),
            "{noise}"
        );
    }
    for triangles in [0, 1, 10_000_000_000, u64::MAX] {
        let o = TerrainOptions {
            triangles,
            ..Default::default()
        };
        assert!(
            invalid(write_terrain(&out, &o, &tessera_gen::NoProgress)),
            "{triangles}"
        );
    }
    let input = dir.path().join("tiny.ply");
    write_tiny(&input);
    assert!(invalid(write_tiled(
        &input,
        &out,
        &TileOptions { copies: 0 },
        &tessera_gen::NoProgress
    )));
    let missing = dir.path().join("missing.ply");
    assert!(matches!(
        write_tiled(
            &missing,
            &out,
            &TileOptions { copies: 2 },
            &tessera_gen::NoProgress
        ),
        Err(GenError::Mesh(_))
    ));
    // Nothing was written.
    assert!(!out.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    // Errors display as one line.
    let e = write_sphere(
        &out,
        &SphereOptions {
            triangles: 3,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .unwrap_err();
    assert!(!e.to_string().contains('\n'));
}

#[test]
fn unwritable_output_is_a_mesh_error() {
    let out = Path::new("/nonexistent-dir-tessera-gen/out.ply");
    let r = write_sphere(
        out,
        &SphereOptions {
            triangles: 1000,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    );
    assert!(matches!(r, Err(GenError::Mesh(_))));
}

/// Records every call, to check the protocol's order and totals.
#[derive(Default)]
struct Recorder {
    calls: std::sync::Mutex<Vec<(String, u64)>>,
}

impl Progress for Recorder {
    fn stage(&self, name: &str, total: u64) {
        self.calls
            .lock()
            .unwrap()
            .push((format!("stage {name}"), total));
    }
    fn advance(&self, n: u64) {
        self.calls.lock().unwrap().push(("advance".into(), n));
    }
    fn finish_stage(&self) {
        self.calls.lock().unwrap().push(("finish".into(), 0));
    }
}

#[test]
fn progress_is_reported() {
    // Why: the CLI's bar is driven by this protocol; one stage whose advances add up to
    // its total, then finished.
    let dir = tempfile::tempdir().unwrap();
    let rec = Recorder::default();
    let path = dir.path().join("p.ply");
    let report = write_sphere(
        &path,
        &SphereOptions {
            triangles: 1_500_000,
            noise: 0.0,
            ..Default::default()
        },
        &rec,
    )
    .unwrap();
    let calls = rec.calls.into_inner().unwrap();
    let total = report.vertices + report.triangles;
    assert_eq!(calls.first(), Some(&("stage generate".to_string(), total)));
    assert_eq!(calls.last(), Some(&("finish".to_string(), 0)));
    let advances: Vec<u64> = calls[1..calls.len() - 1]
        .iter()
        .map(|(c, n)| {
            assert_eq!(c, "advance");
            *n
        })
        .collect();
    assert!(advances.len() >= 2, "{} advances", advances.len());
    assert_eq!(advances.iter().sum::<u64>(), total);
}
