//! Geomorphing (GoLD): at a morph ratio of 1 every vertex of a diamond's children sits on
//! its morph target, and the children must then show exactly the parent diamond's surface,
//! or switching child <-> parent pops. Each child triangle's image at ratio 1 is
//! classified as degenerate (two or three corners on one point: it vanishes), exact (the
//! same three grid points as a parent triangle, same winding) or stray (neither: it
//! would pop).
//!
//! Run with `--nocapture` to see the shares per model.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use tessera_build::diamond::{self, SimplifyConfig};
use tessera_build::patch::{WorkPatch, WorkVertex};
use tessera_build::{build, BuildOptions, NoProgress};
use tessera_format::{Model, PatchData, NO_NODE};

type Tri = [[u32; 3]; 3];

/// Rotation with the smallest point first: equal for two triangles on the same points
/// exactly when they also have the same winding.
fn canon(t: Tri) -> Tri {
    let r = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn f(p: [u32; 3]) -> [f64; 3] {
    p.map(|c| c as f64)
}

fn area(t: Tri) -> f64 {
    let c = cross(sub(f(t[1]), f(t[0])), sub(f(t[2]), f(t[0])));
    0.5 * dot(c, c).sqrt()
}

/// Distance from `p` to triangle `t` (Ericson, Real-Time Collision Detection 5.1.5).
fn point_triangle_distance(p: [f64; 3], t: Tri) -> f64 {
    let (a, b, c) = (f(t[0]), f(t[1]), f(t[2]));
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let at = |s: f64, u: f64| {
        let q = [
            a[0] + s * ab[0] + u * ac[0],
            a[1] + s * ab[1] + u * ac[1],
            a[2] + s * ab[2] + u * ac[2],
        ];
        let d = sub(p, q);
        dot(d, d).sqrt()
    };
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return at(0.0, 0.0);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at(1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(d1 / (d1 - d3), 0.0);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at(0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(0.0, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    if !denom.is_finite() {
        // Zero-area triangle: the nearest of its edges.
        return [(a, b), (b, c), (c, a)]
            .iter()
            .map(|&(x, y)| {
                let e = sub(y, x);
                let s = (dot(sub(p, x), e) / dot(e, e).max(1e-300)).clamp(0.0, 1.0);
                let d = sub(p, [x[0] + s * e[0], x[1] + s * e[1], x[2] + s * e[2]]);
                dot(d, d).sqrt()
            })
            .fold(f64::INFINITY, f64::min);
    }
    at(vb * denom, vc * denom)
}

/// Shares of one comparison of children at ratio 1 against a parent surface.
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    triangles: u64,
    degenerate: u64,
    exact: u64,
    stray: u64,
    area: f64,
    stray_area: f64,
    parent_triangles: u64,
    /// Parent triangles that no child triangle's image equals.
    uncovered: u64,
    /// Largest distance from a stray image's centroid or edge midpoints to the parent
    /// triangles around its corners, in grid steps.
    max_stray_distance: f64,
    /// Strays with such a point more than a grid step off the parent surface (the others
    /// lie on it: another triangulation of the same surface), and their area.
    off_surface: u64,
    off_surface_area: f64,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.triangles += o.triangles;
        self.degenerate += o.degenerate;
        self.exact += o.exact;
        self.stray += o.stray;
        self.area += o.area;
        self.stray_area += o.stray_area;
        self.parent_triangles += o.parent_triangles;
        self.uncovered += o.uncovered;
        self.max_stray_distance = self.max_stray_distance.max(o.max_stray_distance);
        self.off_surface += o.off_surface;
        self.off_surface_area += o.off_surface_area;
    }

    fn stray_share(&self) -> f64 {
        self.stray as f64 / self.triangles.max(1) as f64
    }

    fn stray_area_share(&self) -> f64 {
        self.stray_area / self.area.max(1e-300)
    }

    fn off_surface_share(&self) -> f64 {
        self.off_surface as f64 / self.triangles.max(1) as f64
    }

    fn line(&self, what: &str) -> String {
        format!(
            "{what}: {} child triangles: degenerate {:.2}%, exact {:.2}%, stray {} = {:.4}% \
             (area {:.4}%); parent triangles {} uncovered {} ({:.4}%); farthest stray {:.2} \
             steps; off the surface {} = {:.4}% (area {:.4}%)",
            self.triangles,
            100.0 * self.degenerate as f64 / self.triangles.max(1) as f64,
            100.0 * self.exact as f64 / self.triangles.max(1) as f64,
            self.stray,
            100.0 * self.stray_share(),
            100.0 * self.stray_area_share(),
            self.parent_triangles,
            self.uncovered,
            100.0 * self.uncovered as f64 / self.parent_triangles.max(1) as f64,
            self.max_stray_distance,
            self.off_surface,
            100.0 * self.off_surface_share(),
            100.0 * self.off_surface_area / self.area.max(1e-300),
        )
    }
}

/// Classifies `children` (each triangle: its corners and their targets) against the
/// parent triangles.
fn classify(children: &[(Tri, Tri)], parent: &[Tri]) -> Tally {
    let mut t = Tally {
        parent_triangles: parent.len() as u64,
        ..Default::default()
    };
    let set: HashSet<Tri> = parent.iter().map(|&p| canon(p)).collect();
    let mut hit: HashSet<Tri> = HashSet::new();
    let mut around: HashMap<[u32; 3], Vec<usize>> = HashMap::new();
    for (i, p) in parent.iter().enumerate() {
        for c in p {
            around.entry(*c).or_default().push(i);
        }
    }
    for &(tri, img) in children {
        let a = area(tri);
        t.triangles += 1;
        t.area += a;
        if img[0] == img[1] || img[1] == img[2] || img[0] == img[2] {
            t.degenerate += 1;
        } else if set.contains(&canon(img)) {
            t.exact += 1;
            hit.insert(canon(img));
        } else {
            t.stray += 1;
            t.stray_area += a;
            let probes = [
                [0.5, 0.5, 0.0],
                [0.0, 0.5, 0.5],
                [0.5, 0.0, 0.5],
                [1.0 / 3.0; 3],
            ];
            let mut farthest = 0.0f64;
            for w in &probes {
                let p = [0, 1, 2].map(|d| (0..3).map(|k| w[k] * img[k][d] as f64).sum::<f64>());
                let near = img
                    .iter()
                    .flat_map(|c| around.get(c).into_iter().flatten())
                    .map(|&i| point_triangle_distance(p, parent[i]))
                    .fold(f64::INFINITY, f64::min);
                farthest = farthest.max(near);
            }
            t.max_stray_distance = t.max_stray_distance.max(farthest);
            if farthest > 1.0 {
                t.off_surface += 1;
                t.off_surface_area += a;
            }
        }
    }
    t.uncovered = set.iter().filter(|p| !hit.contains(*p)).count() as u64;
    t
}

fn triangles(p: &PatchData) -> impl Iterator<Item = Tri> + '_ {
    p.indices
        .chunks_exact(3)
        .map(|t| [0, 1, 2].map(|k| p.positions[t[k] as usize]))
}

fn images(p: &PatchData) -> Vec<(Tri, Tri)> {
    p.indices
        .chunks_exact(3)
        .map(|t| {
            (
                [0, 1, 2].map(|k| p.positions[t[k] as usize]),
                [0, 1, 2].map(|k| p.morph_targets[t[k] as usize]),
            )
        })
        .collect()
}

/// Every diamond with children: its nodes and the nodes of its children.
fn diamonds(m: &Model) -> Vec<(Vec<usize>, Vec<usize>)> {
    let nodes = m.index().nodes();
    let mut by_id: BTreeMap<u32, (Vec<usize>, Vec<usize>)> = BTreeMap::new();
    for (i, n) in nodes.iter().enumerate() {
        by_id.entry(n.diamond).or_default().0.push(i);
    }
    for (i, n) in nodes.iter().enumerate() {
        if n.parent != NO_NODE {
            let d = nodes[n.parent as usize].diamond;
            by_id.get_mut(&d).expect("parent's diamond").1.push(i);
        }
    }
    by_id.into_values().filter(|d| !d.1.is_empty()).collect()
}

/// The children of every diamond at ratio 1 against the diamond's own patches, from the
/// model file. Also checks that a position shared by two children of a diamond has one
/// target.
fn model_tally(path: &Path) -> Tally {
    let m = Model::open(path).expect("open model");
    let mut total = Tally::default();
    for (parents, children) in diamonds(&m) {
        let parent: Vec<Tri> = parents
            .iter()
            .flat_map(|&i| triangles(&m.decode_patch(i).expect("patch")).collect::<Vec<_>>())
            .collect();
        let mut kids = Vec::new();
        let mut target_of: HashMap<[u32; 3], [u32; 3]> = HashMap::new();
        for &c in &children {
            let p = m.decode_patch(c).expect("patch");
            assert_eq!(p.morph_targets.len(), p.positions.len());
            for (q, t) in p.positions.iter().zip(&p.morph_targets) {
                let seen = *target_of.entry(*q).or_insert(*t);
                assert_eq!(
                    seen, *t,
                    "position {q:?} has two targets in one diamond's children"
                );
            }
            kids.extend(images(&p));
        }
        // Positions on an edge that is not used by exactly two child triangles (the
        // diamond's outer border, the model's boundary) are locked: they must not move,
        // or the neighbouring diamond's children would crack away from them.
        let mut edges: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
        for (t, _) in &kids {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        for ((a, b), n) in edges {
            if n != 2 {
                for q in [a, b] {
                    assert_eq!(target_of[&q], q, "locked position {q:?} moves");
                }
            }
        }
        total.add(&classify(&kids, &parent));
    }
    total
}

/// Replays every diamond's simplification from the model's child patches (the same
/// steps as the build, on the decoded children) and compares the children at ratio 1
/// with the repaired output, and with the simplifier's own output and the repaired one
/// together: a stray there lands neither on the simplifier's surface nor on the
/// repair's (the strays that the border repair alone explains do not count).
fn replay_tally(path: &Path, cfg: &SimplifyConfig) -> (Tally, Tally) {
    let m = Model::open(path).expect("open model");
    let (mut final_total, mut unexplained) = (Tally::default(), Tally::default());
    for (parents, children) in diamonds(&m) {
        let target: usize = parents
            .iter()
            .map(|&i| m.index().nodes()[i].triangle_count as usize)
            .sum();
        let kids: Vec<WorkPatch> = children
            .iter()
            .map(|&c| {
                let p = m.decode_patch(c).expect("patch");
                WorkPatch {
                    vertices: (0..p.positions.len())
                        .map(|i| WorkVertex {
                            q: p.positions[i],
                            normal: p.normals.get(i).copied().unwrap_or_default(),
                            color: p.colors.get(i).copied().unwrap_or([255; 4]),
                            uv: p.uvs.get(i).copied().unwrap_or_default(),
                            texture: tessera_mesh::NO_TEXTURE,
                        })
                        .collect(),
                    indices: p.indices,
                }
            })
            .collect();
        let refs: Vec<&WorkPatch> = kids.iter().collect();
        let merged = diamond::merge(&refs);
        let locks = diamond::border_locks(&merged.pid, &merged.indices);
        let (raw, _) = diamond::simplify(&merged, &locks, target, cfg);
        let mut repaired = raw.clone();
        diamond::repair(&merged.vertices, &merged.pid, &mut repaired);
        let dest = diamond::morph_destinations(&merged, &locks, &raw, &repaired);
        let q = |i: u32| merged.vertices[i as usize].q;
        let tris = |ix: &[u32]| -> Vec<Tri> {
            ix.chunks_exact(3)
                .map(|t| [q(t[0]), q(t[1]), q(t[2])])
                .collect()
        };
        let imgs: Vec<(Tri, Tri)> = merged
            .indices
            .chunks_exact(3)
            .map(|t| {
                (
                    [q(t[0]), q(t[1]), q(t[2])],
                    [0, 1, 2].map(|k| q(dest[t[k] as usize])),
                )
            })
            .collect();
        final_total.add(&classify(&imgs, &tris(&repaired)));
        unexplained.add(&classify(&imgs, &[tris(&raw), tris(&repaired)].concat()));
    }
    (final_total, unexplained)
}

fn shared_data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(name)
}

/// The Stanford Bunny from `../shared/data`, or the bundled Nefertiti when it is absent.
fn real_scan() -> (String, PathBuf) {
    let bunny = shared_data("bunny.obj");
    if bunny.is_file() {
        return ("bunny".into(), bunny);
    }
    eprintln!(
        "{} is missing: using the bundled nefertiti.obj.gz",
        bunny.display()
    );
    let gz = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/nefertiti.obj.gz");
    ("nefertiti".into(), gz)
}

fn sphere(dir: &Path, triangles: u64) -> PathBuf {
    let input = dir.join("sphere.ply");
    tessera_gen::write_sphere(
        &input,
        &tessera_gen::SphereOptions {
            triangles,
            ..Default::default()
        },
        &tessera_gen::NoProgress,
    )
    .expect("sphere");
    input
}

fn opts() -> BuildOptions {
    BuildOptions {
        leaf_triangles: 2000,
        node_triangles: 1000,
        threads: Some(1),
        ..Default::default()
    }
}

fn built(input: &Path, dir: &Path, name: &str) -> PathBuf {
    let out = dir.join(name);
    build(input, &out, &opts(), &NoProgress).expect("build");
    out
}

fn cfg() -> SimplifyConfig {
    SimplifyConfig {
        node_triangles: 1000,
        normal_weight: 0.5,
        color_weight: 0.5,
        has_colors: false,
        use_normals: false,
    }
}

/// Builds `input`, checks the model's children at ratio 1 against their parents, and
/// replays the diamonds' simplifications to compare with the simplifier's own surface.
fn check(name: &str, input: &Path, dir: &Path) -> (Tally, Tally) {
    let model = built(input, dir, &format!("{name}.tsr"));
    let whole = model_tally(&model);
    eprintln!("{}", whole.line(&format!("{name}, model")));
    let (fin, rest) = replay_tally(&model, &cfg());
    eprintln!(
        "{}",
        fin.line(&format!("{name}, replay vs the repaired output"))
    );
    eprintln!(
        "{}",
        rest.line(&format!("{name}, replay, not explained by the repair"))
    );
    (whole, rest)
}

#[test]
fn real_scan_children_at_ratio_one_show_the_parent() {
    // Why: the destinations were the nearest survivor along edges, under which 13-14% of
    // a diamond's child triangles (Bunny, Nefertiti) did not land on a parent triangle
    // at ratio 1, 7.5-9% of them (12-18% of the area) more than a grid step off the
    // parent surface: a pop at every switch. Measured since: 1.2-1.3% strays, 0.5-0.6%
    // off the surface; 0.17-0.29% land on neither the simplifier's triangles nor the
    // border repair's (the others are where the repair re-triangulated).
    let dir = tempfile::tempdir().unwrap();
    let (name, input) = real_scan();
    let (whole, rest) = check(&name, &input, dir.path());
    assert!(rest.stray_share() < 0.005, "{}", rest.line("unexplained"));
    assert!(
        rest.stray_area_share() < 0.003,
        "{}",
        rest.line("unexplained")
    );
    assert!(whole.stray_share() < 0.02, "{}", whole.line("model"));
    assert!(whole.off_surface_share() < 0.009, "{}", whole.line("model"));
}

#[test]
fn sphere_children_at_ratio_one_lie_on_the_parent() {
    // Why: as above, on a closed model (only diamond borders are locked). Measured: 1.55%
    // strays (nearest survivors: 16.7%), 0.16% of the triangles (0.75% of the area) more
    // than a grid step off the parent surface (2.0%, 7.7%); 0.13% not explained by the
    // border repair.
    let dir = tempfile::tempdir().unwrap();
    let input = sphere(dir.path(), 200_000);
    let (whole, rest) = check("sphere", &input, dir.path());
    assert!(rest.stray_share() < 0.003, "{}", rest.line("unexplained"));
    assert!(whole.stray_share() < 0.02, "{}", whole.line("model"));
    assert!(whole.off_surface_share() < 0.003, "{}", whole.line("model"));
    assert!(
        whole.off_surface_area / whole.area < 0.012,
        "{}",
        whole.line("model")
    );
}

#[test]
#[ignore = "measurement: prints the shares for the scans in ../shared/data"]
fn measure_all() {
    let dir = tempfile::tempdir().unwrap();
    let mut inputs = vec![("sphere".to_string(), sphere(dir.path(), 200_000))];
    for name in ["bunny.obj", "nefertiti.obj"] {
        let p = shared_data(name);
        if p.is_file() {
            inputs.push((name.to_string(), p));
        }
    }
    for (name, input) in inputs {
        check(&name, &input, dir.path());
    }
}
#[test]
#[ignore = "timing: builds TESSERA_INPUT once with the default options"]
fn build_timing() {
    let input = PathBuf::from(std::env::var("TESSERA_INPUT").expect("TESSERA_INPUT"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.tsr");
    let t = std::time::Instant::now();
    build(&input, &out, &BuildOptions::default(), &NoProgress).expect("build");
    eprintln!("build {:.3} s", t.elapsed().as_secs_f64());
}
