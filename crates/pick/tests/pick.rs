//! Picking on real models (built here from real scans and a generated sphere), judged
//! against brute-force ray casts over the INPUT mesh.
//!
//! Two references per model, both every input triangle tested in `f64`:
//!
//! - the input quantised onto the model's grid (`Grid::quantize`, as the builder does;
//!   triangles with two corners on one grid point dropped, as the builder drops them).
//!   The leaves hold exactly these triangles, so pick must agree with it: hit <=> hit,
//!   distances within `1e-9` of the bounding radius. A disagreement is allowed only for
//!   a ray passing within `1e-7` radii of a triangle edge (where two correct ray/triangle
//!   tests may round differently);
//! - the raw input positions (`f32` from the file). Every stored vertex is within
//!   `grid.max_error()` (`e` below) of its input vertex, so: every pick hit lies within
//!   `e` of the raw mesh and every raw hit within `e` of the quantised mesh (both
//!   provable: the same barycentric point moves by at most `e`); hit <=> hit except for
//!   rays that pass within `e` of the mesh they miss (grazing a silhouette); and where
//!   both hit and the ray meets the raw triangle at `|cos| >= 0.25` to its normal, the
//!   distances differ by at most `2 e / |cos|` (the surface moves by at most `e`, the
//!   hit along the ray by `e / |cos|` on a flat piece; the factor 2 covers a hit moving
//!   to a neighbouring triangle; seen: at most 0.63 e / |cos|).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::DVec3;
use tessera_build::BuildOptions;
use tessera_format::{FormatError, Grid, Model, ModelIndex, PatchData, PatchReader, NO_NODE};
use tessera_mesh::{MeshError, MeshHeader, MeshVisitor, Vertex};
use tessera_pick::{pick, pick_resident, pick_with, Hit, PickOptions, PickStats, Ray};
use tessera_select::{Camera, Orbit};

// ---------------------------------------------------------------- models and meshes

fn data(name: &str) -> PathBuf {
    tessera_testkit::shared_data(name)
}

use tessera_testkit::{small_options, SplitMix64};

struct Built {
    _dir: tempfile::TempDir,
    input: PathBuf,
    path: PathBuf,
    model: Model,
}

fn build(input: Option<&Path>, opts: &BuildOptions) -> Built {
    let t = tessera_testkit::build_model(input, &tessera_testkit::sphere(50_000), opts);
    let model = Model::open(&t.path).expect("open");
    Built {
        _dir: t.dir,
        input: t.input,
        path: t.path,
        model,
    }
}

/// The input mesh as the importer hands it over.
#[derive(Default)]
struct Collect {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl MeshVisitor for Collect {
    fn header(&mut self, _: &MeshHeader) -> Result<(), MeshError> {
        Ok(())
    }
    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        self.positions.push(v.position);
        Ok(())
    }
    fn triangle(&mut self, t: [u32; 3]) -> Result<(), MeshError> {
        self.triangles.push(t);
        Ok(())
    }
}

/// A triangle soup in model coordinates, `f64`.
struct Soup {
    tris: Vec<[DVec3; 3]>,
    /// Bounding sphere per triangle (centroid, radius), for pre-filtering distances.
    spheres: Vec<(DVec3, f64)>,
}

impl Soup {
    fn new(tris: Vec<[DVec3; 3]>) -> Soup {
        let spheres = tris
            .iter()
            .map(|t| {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                (c, t.iter().map(|v| v.distance(c)).fold(0.0, f64::max))
            })
            .collect();
        Soup { tris, spheres }
    }
}

/// The raw input and the input quantised onto the model's grid.
struct Reference {
    raw: Soup,
    quantised: Soup,
    /// The quantised input with the triangles the builder drops (two corners on one grid
    /// point), for distances.
    quantised_all: Soup,
}

fn reference(input: &Path, grid: &Grid) -> Reference {
    let mut mesh = Collect::default();
    tessera_mesh::read_mesh(input, &mut mesh).expect("read the input mesh");
    let p64 = |p: [f32; 3]| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
    let raw = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| p64(mesh.positions[i as usize])))
        .collect();
    let q: Vec<[u32; 3]> = mesh.positions.iter().map(|&p| grid.quantize(p)).collect();
    let qp = |i: u32| DVec3::from_array(grid.position(q[i as usize]));
    let all: Vec<[DVec3; 3]> = mesh.triangles.iter().map(|t| t.map(qp)).collect();
    let kept = mesh
        .triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| q[i as usize]);
            a != b && b != c && a != c
        })
        .map(|t| t.map(qp))
        .collect();
    Reference {
        raw: Soup::new(raw),
        quantised: Soup::new(kept),
        quantised_all: Soup::new(all),
    }
}

// ---------------------------------------------------------------- brute-force geometry

/// Moller-Trumbore, both faces, `f64`: distance along the unit direction, if any.
fn ray_triangle(o: DVec3, d: DVec3, t: &[DVec3; 3]) -> Option<f64> {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - t[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let dist = e2.dot(q) * inv;
    (dist >= 0.0).then_some(dist)
}

/// Nearest hit on a soup: distance and triangle.
fn brute(soup: &Soup, o: DVec3, d: DVec3) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for (i, t) in soup.tris.iter().enumerate() {
        if let Some(dist) = ray_triangle(o, d, t) {
            if best.is_none_or(|b| dist < b.0) {
                best = Some((dist, i));
            }
        }
    }
    best
}

fn point_segment(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let e = b - a;
    let l = e.length_squared();
    let s = if l > 0.0 {
        ((p - a).dot(e) / l).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + e * s)
}

fn point_ray(p: DVec3, o: DVec3, d: DVec3) -> f64 {
    p.distance(o + d * (p - o).dot(d).max(0.0))
}

/// Distance between a half-line (unit `d`) and a segment: the interior critical point
/// of the squared distance if it lies in the domain, else the best on its borders
/// (`s = 0`, `s = 1`, `t = 0`).
fn ray_segment(o: DVec3, d: DVec3, a: DVec3, b: DVec3) -> f64 {
    let e = b - a;
    let w = o - a;
    let (bb, c, dd, ee) = (d.dot(e), e.dot(e), d.dot(w), e.dot(w));
    let denom = c - bb * bb;
    let mut best = point_ray(a, o, d)
        .min(point_ray(b, o, d))
        .min(point_segment(o, a, b));
    if denom > 1e-30 * c.max(1.0) {
        let t = (bb * ee - c * dd) / denom;
        let s = (ee - bb * dd) / denom;
        if t >= 0.0 && (0.0..=1.0).contains(&s) {
            best = best.min((o + d * t).distance(a + e * s));
        }
    }
    best
}

/// Closest distance from `p` to triangle `t` (Ericson, Real-Time Collision Detection).
fn point_triangle(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let [a, b, c] = *t;
    let n = (b - a).cross(c - a);
    let l = n.length_squared();
    if l > 0.0 {
        // Inside the prism over the triangle: the distance to its plane.
        let inside = [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(x, y)| (y - x).cross(p - x).dot(n) >= 0.0);
        if inside {
            return ((p - a).dot(n) / l.sqrt()).abs();
        }
    }
    point_segment(p, a, b)
        .min(point_segment(p, b, c))
        .min(point_segment(p, c, a))
}

/// Distance from `p` to the soup.
fn point_soup(soup: &Soup, p: DVec3) -> f64 {
    let mut best = f64::INFINITY;
    for (t, &(c, r)) in soup.tris.iter().zip(&soup.spheres) {
        if p.distance(c) - r < best {
            best = best.min(point_triangle(p, t));
        }
    }
    best
}

/// Distance from the half-line to the soup (0 where it meets a triangle).
fn ray_soup(soup: &Soup, o: DVec3, d: DVec3) -> f64 {
    let mut best = f64::INFINITY;
    for (t, &(c, r)) in soup.tris.iter().zip(&soup.spheres) {
        if point_ray(c, o, d) - r >= best {
            continue;
        }
        if ray_triangle(o, d, t).is_some() {
            return 0.0;
        }
        let dist = ray_segment(o, d, t[0], t[1])
            .min(ray_segment(o, d, t[1], t[2]))
            .min(ray_segment(o, d, t[2], t[0]))
            .min(point_triangle(o, t));
        best = best.min(dist);
    }
    best
}

/// Distance from the half-line to the nearest triangle edge of the soup.
fn ray_edges(soup: &Soup, o: DVec3, d: DVec3) -> f64 {
    let mut best = f64::INFINITY;
    for (t, &(c, r)) in soup.tris.iter().zip(&soup.spheres) {
        if point_ray(c, o, d) - r >= best {
            continue;
        }
        best = best
            .min(ray_segment(o, d, t[0], t[1]))
            .min(ray_segment(o, d, t[1], t[2]))
            .min(ray_segment(o, d, t[2], t[0]));
    }
    best
}

// ---------------------------------------------------------------- rays

fn sphere_of(index: &ModelIndex) -> (DVec3, f64) {
    let s = index.header().bounding_sphere;
    (DVec3::new(s[0], s[1], s[2]), s[3])
}

/// `count` rays from outside the bounding sphere (1.5 to 3.5 radii from its centre)
/// aimed at random points of its interior (within 0.9 radii).
fn rays_from_outside(index: &ModelIndex, count: usize, seed: u64) -> Vec<Ray> {
    let (c, r) = sphere_of(index);
    let mut rng = SplitMix64(seed);
    (0..count)
        .map(|_| {
            let from = c + DVec3::from(rng.unit_vector()) * r * (1.5 + 2.0 * rng.next_f64());
            let to = c + DVec3::from(rng.in_ball()) * r * 0.9;
            Ray::between(from.to_array(), to.to_array())
        })
        .collect()
}

/// `count` rays that miss the bounding sphere: from outside, passing it at 1.05 to 2
/// radii from its centre.
fn rays_that_miss(index: &ModelIndex, count: usize, seed: u64) -> Vec<Ray> {
    let (c, r) = sphere_of(index);
    let mut rng = SplitMix64(seed);
    (0..count)
        .map(|_| {
            // Along -u, passing `side * miss` (closest to the centre there).
            let u = DVec3::from(rng.unit_vector());
            let side = u.any_orthonormal_vector();
            let miss = r * (1.05 + rng.next_f64());
            let from = c + side * miss + u * r * (1.5 + 2.0 * rng.next_f64());
            Ray::new(from.to_array(), (-u).to_array())
        })
        .collect()
}

/// Rays starting inside the bounding sphere (within half a radius of its centre),
/// random directions.
fn rays_from_inside(index: &ModelIndex, count: usize, seed: u64) -> Vec<Ray> {
    let (c, r) = sphere_of(index);
    let mut rng = SplitMix64(seed);
    (0..count)
        .map(|_| {
            let from = c + DVec3::from(rng.in_ball()) * r * 0.5;
            Ray::new(from.to_array(), rng.unit_vector())
        })
        .collect()
}

// ---------------------------------------------------------------- the comparison

/// What a comparison saw, for the messages.
#[derive(Debug, Default)]
struct Tally {
    rays: usize,
    hits: usize,
    grazing_disagreements: usize,
    worst_dt_over_e: f64,
    worst_point_over_e: f64,
    decoded: usize,
    visited: usize,
}

fn unit(ray: &Ray) -> (DVec3, DVec3) {
    (
        DVec3::from_array(ray.origin),
        DVec3::from_array(ray.unit_dir().unwrap()),
    )
}

fn check_hit_shape(ray: &Ray, hit: &Hit) {
    let (o, d) = unit(ray);
    let n = DVec3::from_array(hit.normal);
    assert!((n.length() - 1.0).abs() < 1e-9, "normal {n} not unit");
    assert!(n.dot(d) <= 1e-12, "normal {n} faces away from the origin");
    assert!(hit.distance >= 0.0);
    let p = o + d * hit.distance;
    assert!(
        p.distance(DVec3::from_array(hit.point)) <= 1e-9 * (1.0 + hit.distance + o.length()),
        "point {:?} is not origin + distance * dir",
        hit.point
    );
}

/// Compares pick with both references on every ray; returns what it saw.
fn compare(b: &Built, reference: &Reference, rays: &[Ray]) -> Tally {
    let index = b.model.index();
    let grid = index.grid();
    let e = grid.max_error();
    let (_, radius) = sphere_of(index);
    let mut tally = Tally::default();
    for (k, ray) in rays.iter().enumerate() {
        let (hit, stats) = pick(&b.model, ray).expect("pick");
        assert!(stats.skipped.is_empty(), "{:?}", stats.skipped);
        tally.rays += 1;
        tally.decoded += stats.patches_decoded;
        tally.visited += stats.nodes_visited;
        let (o, d) = unit(ray);
        let what = || format!("ray {k} {ray:?}: pick {hit:?}");
        // Against the quantised input: the same triangles.
        let q = brute(&reference.quantised, o, d);
        match (&hit, q) {
            (Some(h), Some((t, _))) => {
                assert!(
                    (h.distance - t).abs() <= 1e-9 * radius,
                    "{}: quantised brute force at {t}",
                    what()
                );
            }
            (None, None) => {}
            _ => {
                let edge = ray_edges(&reference.quantised, o, d);
                assert!(
                    edge <= 1e-7 * radius,
                    "{}: quantised brute force {q:?}, nearest edge {edge}",
                    what()
                );
            }
        }
        if let Some(h) = &hit {
            check_hit_shape(ray, h);
            assert!(h.exact, "{}: a complete index gives exact hits", what());
            assert!(
                index.nodes()[h.node as usize].children == [NO_NODE; 2],
                "{}: not a leaf",
                what()
            );
        }
        // Against the raw input.
        let raw = brute(&reference.raw, o, d);
        match (&hit, raw) {
            (Some(h), Some((t, tri))) => {
                tally.hits += 1;
                let p = DVec3::from_array(h.point);
                let dp = point_soup(&reference.raw, p);
                assert!(
                    dp <= e * (1.0 + 1e-6),
                    "{}: {dp} from the raw mesh, max error {e}",
                    what()
                );
                tally.worst_point_over_e = tally.worst_point_over_e.max(dp / e);
                let rt = &reference.raw.tris[tri];
                let n = (rt[1] - rt[0]).cross(rt[2] - rt[0]).normalize();
                let cos = n.dot(d).abs();
                let dt = (h.distance - t).abs();
                if cos >= 0.25 {
                    assert!(
                        dt <= 2.0 * e / cos,
                        "{}: raw hit at {t} (cos {cos}), max error {e}",
                        what()
                    );
                    tally.worst_dt_over_e = tally.worst_dt_over_e.max(dt * cos / e);
                }
                let dq = point_soup(&reference.quantised_all, o + d * t);
                assert!(
                    dq <= e * (1.0 + 1e-6),
                    "{}: raw hit {dq} from the model",
                    what()
                );
            }
            (None, None) => {}
            (Some(h), None) => {
                tally.grazing_disagreements += 1;
                let dist = ray_soup(&reference.raw, o, d);
                assert!(
                    dist <= e * (1.0 + 1e-6),
                    "{}: the raw mesh is missed by {dist} (max error {e})",
                    what()
                );
                let p = DVec3::from_array(h.point);
                assert!(point_soup(&reference.raw, p) <= e * (1.0 + 1e-6));
            }
            (None, Some(_)) => {
                tally.grazing_disagreements += 1;
                let dist = ray_soup(&reference.quantised_all, o, d);
                assert!(
                    dist <= e * (1.0 + 1e-6),
                    "{}: raw hit {raw:?}, the model is missed by {dist} (max error {e})",
                    what()
                );
            }
        }
    }
    tally
}

fn check_model(b: &Built, seed: u64) -> Tally {
    let index = b.model.index();
    let reference = reference(&b.input, &index.grid());
    let leaves = index
        .nodes()
        .iter()
        .filter(|n| n.children == [NO_NODE; 2])
        .count();
    let outside = rays_from_outside(index, 200, seed);
    let t = compare(b, &reference, &outside);
    eprintln!("{}: outside {t:?}, {leaves} leaves", b.input.display());
    assert!(t.hits >= 40, "too few rays hit to judge: {t:?}");
    assert!(
        t.grazing_disagreements <= t.rays / 20,
        "more than 5% of the rays graze: {t:?}"
    );
    // A pick decodes a handful of patches, not the model.
    assert!(
        (t.decoded as f64 / t.rays as f64) < (leaves as f64 / 10.0).max(8.0),
        "{t:?} for {leaves} leaves"
    );
    let inside = compare(b, &reference, &rays_from_inside(index, 40, seed + 1));
    eprintln!("{}: inside {inside:?}", b.input.display());
    let miss = rays_that_miss(index, 20, seed + 2);
    let mut miss_decoded = 0;
    for ray in &miss {
        let (hit, stats) = pick(&b.model, ray).unwrap();
        assert_eq!(hit, None, "{ray:?}");
        miss_decoded += stats.patches_decoded;
    }
    eprintln!(
        "{}: misses decoded {miss_decoded} patches",
        b.input.display()
    );
    // Batches of one leaf find the same hits, and so does a test over all leaves
    // (what the viewer does with its drawn patches).
    let mut all_leaves: Vec<(u32, PatchData)> = Vec::new();
    for (i, n) in index.nodes().iter().enumerate() {
        if n.children == [NO_NODE; 2] {
            all_leaves.push((i as u32, b.model.decode_patch(i).unwrap()));
        }
    }
    for ray in outside.iter().take(40) {
        let (hit, _) = pick(&b.model, ray).unwrap();
        let (one, _) = pick_with(&b.model, ray, &PickOptions { batch: 1 }).unwrap();
        assert_eq!(hit.map(|h| h.distance), one.map(|h| h.distance), "{ray:?}");
        let resident = pick_resident(index, all_leaves.iter().map(|(i, p)| (*i, p)), ray).unwrap();
        assert_eq!(
            hit.map(|h| h.distance),
            resident.map(|h| h.distance),
            "{ray:?}"
        );
        if let Some(r) = resident {
            assert!(r.exact);
        }
    }
    t
}

// ---------------------------------------------------------------- the tests

#[test]
fn bunny_matches_brute_force_on_the_input() {
    let b = build(Some(&data("bunny.obj")), &small_options());
    check_model(&b, 1);
}

#[test]
fn nefertiti_matches_brute_force_on_the_input() {
    let b = build(Some(&data("nefertiti.obj")), &small_options());
    check_model(&b, 2);
}

fn sphere_model() -> &'static Built {
    static SPHERE: OnceLock<Built> = OnceLock::new();
    SPHERE.get_or_init(|| build(None, &small_options()))
}

#[test]
fn generated_sphere_matches_brute_force_and_every_ray_from_inside_hits() {
    let b = sphere_model();
    check_model(b, 3);
    // The sphere is closed: from its centre every direction hits, at 1 +- noise.
    let index = b.model.index();
    let (c, _) = sphere_of(index);
    let mut rng = SplitMix64(99);
    for _ in 0..50 {
        let ray = Ray::new(c.to_array(), rng.unit_vector());
        let (hit, _) = pick(&b.model, &ray).unwrap();
        let hit = hit.unwrap_or_else(|| panic!("{ray:?} escaped the closed sphere"));
        assert!(
            (0.9..1.1).contains(&hit.distance),
            "{ray:?}: {}",
            hit.distance
        );
    }
}

#[test]
fn empty_space_behind_and_bad_rays() {
    let b = sphere_model();
    let index = b.model.index();
    let (c, r) = sphere_of(index);
    // Pointing away from the model, from outside: nothing, nothing decoded.
    let from = c + DVec3::new(3.0 * r, 0.5 * r, 0.0);
    let away = Ray::new(from.to_array(), [1.0, 0.1, 0.0]);
    let (hit, stats) = pick(&b.model, &away).unwrap();
    assert_eq!(hit, None);
    assert_eq!(stats.patches_decoded, 0, "{stats:?}");
    // The same line the other way hits, twice through the sphere: the near side.
    let toward = Ray::new(from.to_array(), [-1.0, -0.1, 0.0]);
    let (hit, _) = pick(&b.model, &toward).unwrap();
    let hit = hit.expect("toward the sphere");
    assert!(hit.distance > 1.5 * r && hit.distance < 3.0 * r, "{hit:?}");
    // Far away in empty space.
    let far = Ray::new([1e6, 1e6, 1e6], [0.0, 1.0, 0.0]);
    assert_eq!(pick(&b.model, &far).unwrap().0, None);
    // A direction's length does not matter.
    let long = Ray::new(from.to_array(), [-1e9, -1e8, 0.0]);
    let (h2, _) = pick(&b.model, &long).unwrap();
    assert_eq!(h2.map(|h| h.node), Some(hit.node));
    assert!((h2.unwrap().distance - hit.distance).abs() < 1e-12 * r);
    // Zero and non-finite rays are refused.
    assert!(pick(&b.model, &Ray::new(from.to_array(), [0.0; 3])).is_err());
    assert!(pick(&b.model, &Ray::new([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0])).is_err());
}

#[test]
fn a_ray_through_the_image_centre_hits_what_the_camera_looks_at() {
    let b = sphere_model();
    let (c, r) = sphere_of(b.model.index());
    let cam = Camera::orbit(&Orbit {
        center: c.to_array(),
        radius: 4.0 * r,
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        width: 800,
        height: 600,
        ..Orbit::default()
    })
    .unwrap();
    let (hit, _) = pick(&b.model, &Ray::through_pixel(&cam, 400.0, 300.0)).unwrap();
    let hit = hit.expect("the centre pixel shows the sphere");
    // Distance to the surface of the sphere of radius 1 +- 0.05 (plus the error).
    assert!((hit.distance - (4.0 * r - 1.0)).abs() < 0.06, "{hit:?}");
    // A corner pixel looks past it.
    let (corner, _) = pick(&b.model, &Ray::through_pixel(&cam, 0.5, 0.5)).unwrap();
    assert_eq!(corner, None);
}

/// A model whose index is a paged index read in part (`ModelIndex::read_top`), patches
/// from the model file itself.
struct Partial<'a> {
    model: &'a Model,
    index: ModelIndex,
}

impl PatchReader for Partial<'_> {
    fn index(&self) -> &ModelIndex {
        &self.index
    }
    fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        self.index.read_patch(self.model.bytes(), i)
    }
}

#[test]
fn a_paged_index_read_in_part_gives_coarser_hits_marked_inexact() {
    let opts = BuildOptions {
        index_page_nodes: 4,
        ..small_options()
    };
    let b = build(None, &opts);
    let whole = b.model.index();
    let reference = reference(&b.input, &whole.grid());
    let e = whole.grid().max_error();
    let (c, _) = sphere_of(whole);
    let mut index = ModelIndex::read_top(b.model.bytes(), 1).unwrap();
    assert!(!index.is_complete());
    let mut pages = 1;
    let mut rounds = 0;
    let mut inexact = 0;
    loop {
        let shown = index.nodes().len();
        let reader = Partial {
            model: &b.model,
            index: index.clone(),
        };
        let complete = index.is_complete();
        let mut rng = SplitMix64(5 + rounds);
        for _ in 0..30 {
            // From the centre of the closed sphere: every ray hits a cut of the shown
            // levels too (a uniform cut is crack-free).
            let ray = Ray::new(c.to_array(), rng.unit_vector());
            let (hit, stats) = pick(&reader, &ray).unwrap();
            assert!(stats.skipped.is_empty());
            let hit = hit.unwrap_or_else(|| panic!("{shown} nodes shown: {ray:?} escaped"));
            check_hit_shape(&ray, &hit);
            let n = whole.nodes()[hit.node as usize];
            let leaf = n.children == [NO_NODE; 2];
            assert_eq!(hit.exact, leaf, "{shown} nodes shown: {hit:?}");
            inexact += usize::from(!hit.exact);
            assert!((hit.node as usize) < shown);
            if complete {
                assert!(hit.exact);
            }
            // The coarse patch stands within its error of the full-resolution surface.
            let dist = point_soup(&reference.raw, DVec3::from_array(hit.point));
            assert!(
                dist <= n.error as f64 * 1.001 + e,
                "{shown} nodes shown: hit {dist} from the input, node error {}",
                n.error
            );
        }
        if complete {
            break;
        }
        rounds += 1;
        pages *= 4;
        index = index.grown(b.model.bytes(), pages).unwrap();
    }
    assert!(rounds >= 2, "the test should see several partial indexes");
    assert!(inexact >= 30, "{inexact} inexact hits");
}

/// The model file with a byte flipped in the middle of one patch: a real corrupt patch
/// (its CRC no longer matches; `Model::open` checks only the index).
#[test]
fn a_corrupt_patch_is_skipped_and_reported() {
    let b = sphere_model();
    let (c, r) = sphere_of(b.model.index());
    let from = c + DVec3::new(0.3, 0.2, 3.0 * r);
    let ray = Ray::between(from.to_array(), c.to_array());
    let (good, _) = pick(&b.model, &ray).unwrap();
    let good = good.unwrap();
    let node = good.node as usize;
    let mut bytes = std::fs::read(&b.path).unwrap();
    let range = b.model.patch_range(node).unwrap();
    let mid = ((range.start + range.end) / 2) as usize;
    bytes[mid] ^= 0x5a;
    let dir = tempfile::tempdir().unwrap();
    let bad_path = dir.path().join("corrupt.tsr");
    std::fs::write(&bad_path, &bytes).unwrap();
    let bad = Model::open(&bad_path).unwrap();
    let (hit, stats): (Option<Hit>, PickStats) = pick(&bad, &ray).unwrap();
    assert_eq!(stats.skipped.len(), 1, "{stats:?}");
    assert_eq!(stats.skipped[0].0, good.node);
    assert!(stats.skipped[0].1.contains("checksum"), "{stats:?}");
    // Either nothing, or a hit farther away (another leaf behind the skipped one, or the
    // far side of the sphere), which is not exact: the skipped patch lay in front.
    if let Some(h) = hit {
        assert!(h.distance >= good.distance, "{h:?}");
        assert!(!h.exact, "{h:?}");
        assert_ne!(h.node, good.node);
    }
}
