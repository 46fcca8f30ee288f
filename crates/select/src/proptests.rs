//! Property tests of selection on random forests built the way the builder saturates
//! them: errors maxed bottom-up (so they never grow toward the leaves) and saturated
//! spheres enclosing the children's (so they are nested). Under those two rules every
//! cut must cover each root's subtree exactly once (without culling) and the view
//! decision must be monotone.

use glam::DVec3;
use proptest::prelude::*;
use tessera_format::{Header, NodeRecord, NO_NODE};

use crate::select::tests::{assert_at_most_once, assert_covers_once};
use crate::{
    prefetch_set, select_cut, select_resident, should_unload, Camera, Criterion, NodeView,
    PrefetchOptions, Selection, ViewParams,
};

/// splitmix64: a deterministic stream from the proptest-chosen seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn dir(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// A random saturated forest in breadth-first order (children after parents).
fn random_forest(seed: u64, max_nodes: usize) -> (Header, Vec<NodeRecord>) {
    let max_depth = 1 + (Rng(seed ^ 0xdead_beef).next() % 9) as u8;
    random_forest_with(seed, max_nodes, max_depth)
}

fn random_forest_with(seed: u64, max_nodes: usize, max_depth: u8) -> (Header, Vec<NodeRecord>) {
    let mut rng = Rng(seed);
    let root_count = 1 + (rng.next() % 6) as usize;
    let mut nodes: Vec<NodeRecord> = Vec::new();
    let mut centers: Vec<DVec3> = Vec::new();
    let mut radii: Vec<f64> = Vec::new();
    for _ in 0..root_count {
        centers.push(DVec3::new(
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
        ));
        radii.push(rng.range(5.0, 30.0));
        nodes.push(NodeRecord {
            children: [NO_NODE; 2],
            parent: NO_NODE,
            ..NodeRecord::default()
        });
    }
    // Breadth-first growth.
    let mut i = 0;
    while i < nodes.len() {
        let level = nodes[i].level;
        let roll = rng.next() % 10;
        let want = if level >= max_depth || roll < 2 {
            0
        } else if roll < 4 {
            1
        } else {
            2
        };
        let slots: &[usize] = match want {
            0 => &[],
            1 if rng.next() & 1 == 0 => &[0],
            1 => &[1],
            _ => &[0, 1],
        };
        for &slot in slots {
            if nodes.len() >= max_nodes {
                break;
            }
            let c = centers[i] + rng.dir() * rng.range(0.0, 0.6 * radii[i]);
            centers.push(c);
            radii.push(radii[i] * rng.range(0.4, 0.8));
            let child = nodes.len() as u32;
            nodes[i].children[slot] = child;
            nodes.push(NodeRecord {
                children: [NO_NODE; 2],
                parent: i as u32,
                level: level + 1,
                root: nodes[i].root,
                ..NodeRecord::default()
            });
        }
        i += 1;
    }
    // Own values, then saturation bottom-up (reverse breadth-first order).
    let mut sat_err = vec![0f64; nodes.len()];
    let mut sat_c = centers.clone();
    let mut sat_r = radii.clone();
    for i in (0..nodes.len()).rev() {
        let kids: Vec<usize> = nodes[i]
            .children
            .iter()
            .filter(|&&c| c != NO_NODE)
            .map(|&c| c as usize)
            .collect();
        let own_err = if kids.is_empty() {
            0.0
        } else {
            rng.range(0.0, 5.0)
        };
        sat_err[i] = kids.iter().fold(own_err, |e, &k| e.max(sat_err[k]));
        let mut r = radii[i];
        for &k in &kids {
            r = r.max((sat_c[k] - centers[i]).length() + sat_r[k]);
        }
        // Round outward so the f32 spheres stay nested.
        sat_r[i] = r * (1.0 + 1e-5) + 1e-4;
        sat_c[i] = centers[i];
        let axis = rng.dir();
        let n = &mut nodes[i];
        n.error = sat_err[i] as f32;
        n.tight_sphere = [
            centers[i].x as f32,
            centers[i].y as f32,
            centers[i].z as f32,
            radii[i] as f32,
        ];
        n.saturated_sphere = [
            sat_c[i].x as f32,
            sat_c[i].y as f32,
            sat_c[i].z as f32,
            sat_r[i] as f32,
        ];
        n.normal_cone = [
            axis.x as f32,
            axis.y as f32,
            axis.z as f32,
            rng.range(-1.0, 1.0) as f32,
        ];
        n.triangle_count = 1 + (rng.next() % 1000) as u32;
    }
    let mut header = <Header as bytemuck::Zeroable>::zeroed();
    header.root_count = root_count as u32;
    header.cube_origin = [1000.0, -2000.0, 5.0];
    (header, nodes)
}

fn camera_strategy() -> impl Strategy<Value = Option<Camera>> {
    (
        prop::array::uniform3(-150.0f64..250.0),
        prop::array::uniform3(-50.0f64..150.0),
        prop::array::uniform3(-1.0f64..1.0),
        5.0f64..170.0,
        1u32..4000,
        1u32..4000,
    )
        .prop_map(|(eye, target, up, fov, w, h)| {
            // Cameras are placed relative to the model's local frame.
            let origin = [1000.0, -2000.0, 5.0];
            let model = |p: [f64; 3]| [p[0] + origin[0], p[1] + origin[1], p[2] + origin[2]];
            Camera::new(model(eye), model(target), up, fov, w, h).ok()
        })
}

/// A random forest (and its seed) seen by a random camera at a random tolerance: what the
/// view-dependent properties are checked on.
#[derive(Debug)]
struct ViewCase {
    seed: u64,
    h: Header,
    nodes: Vec<NodeRecord>,
    camera: Camera,
    tolerance_px: f32,
}

/// [`ViewCase`]s of 400-node forests; `None` where the camera is degenerate (the case
/// passes).
fn view_case() -> impl Strategy<Value = Option<ViewCase>> {
    (any::<u64>(), camera_strategy(), 0.05f32..50.0).prop_map(|(seed, camera, tolerance_px)| {
        let camera = camera?;
        let (h, nodes) = random_forest(seed, 400);
        Some(ViewCase {
            seed,
            h,
            nodes,
            camera,
            tolerance_px,
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn max_error_cuts_cover_every_root_once(seed in any::<u64>(), max_error in -1.0f32..6.0) {
        let (h, nodes) = random_forest(seed, 400);
        let cut = select_cut(&h, &nodes, &Criterion::MaxError { max_error });
        assert_covers_once(&h, &nodes, &cut.nodes);
        for &i in &cut.nodes {
            let n = &nodes[i as usize];
            prop_assert!(n.error <= max_error || crate::is_leaf(i, &nodes));
        }
        let tris: u64 = cut.nodes.iter().map(|&i| u64::from(nodes[i as usize].triangle_count)).sum();
        prop_assert_eq!(tris, cut.triangles);
        prop_assert!(cut.visited <= nodes.len());
    }

    #[test]
    fn view_cuts_cover_once_without_culling_and_culling_only_removes(
        case in view_case(),
    ) {
        let Some(ViewCase { h, nodes, camera, tolerance_px, .. }) = case else { return Ok(()); };
        let all = select_cut(&h, &nodes, &Criterion::View { camera: camera.clone(), tolerance_px, cull: false });
        assert_covers_once(&h, &nodes, &all.nodes);
        let culled = select_cut(&h, &nodes, &Criterion::View { camera, tolerance_px, cull: true });
        assert_at_most_once(&h, &nodes, &culled.nodes, false);
        for i in &culled.nodes {
            prop_assert!(all.nodes.contains(i), "culling selected {} that the full cut does not hold", i);
        }
        prop_assert!(culled.triangles <= all.triangles);
        prop_assert!(culled.visited <= all.visited);
    }

    #[test]
    fn view_refinement_is_monotone(
        case in view_case(),
    ) {
        let Some(ViewCase { h, nodes, camera, tolerance_px, .. }) = case else { return Ok(()); };
        let p = ViewParams::new(&camera, h.cube_origin, tolerance_px, false);
        for (i, parent) in nodes.iter().enumerate() {
            if p.needs_refinement(parent) {
                continue;
            }
            for &c in parent.children.iter().filter(|&&c| c != NO_NODE) {
                prop_assert!(!p.needs_refinement(&nodes[c as usize]),
                    "node {} is fine but its child {} wants refinement", i, c);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// With everything resident the residency-aware traversal (plane masking included)
    /// draws exactly `select_cut`'s cut; with a random resident set it draws only
    /// resident nodes, never two on one root-leaf path, and asks only for missing ones.
    #[test]
    fn select_resident_matches_select_cut_and_respects_residency(
        case in view_case(),
        cull in any::<bool>(),
        keep in 0u64..8,
    ) {
        let Some(ViewCase { seed, h, nodes, camera, tolerance_px }) = case else { return Ok(()); };
        let nv = NodeView::new(&h, &nodes);
        let view = ViewParams::new(&camera, h.cube_origin, tolerance_px, cull);
        let mut sel = Selection::default();
        select_resident(&nv, &view, &|_| true, &mut sel);
        let cut = select_cut(&h, &nodes, &Criterion::View { camera, tolerance_px, cull });
        prop_assert_eq!(&sel.draw, &cut.nodes);
        prop_assert!(sel.missing.is_empty());
        // Pseudo-random residency: roughly keep/8 of the nodes missing.
        let resident = |i: u32| (u64::from(i).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ seed) % 8 >= keep;
        select_resident(&nv, &view, &resident, &mut sel);
        assert_at_most_once(&h, &nodes, &sel.draw, false);
        for &i in &sel.draw {
            prop_assert!(resident(i));
        }
        for &(i, p) in &sel.missing {
            prop_assert!(!resident(i) && p >= 0.0);
        }
    }

    /// Nothing the current view needs, and nothing in the prefetch set of the current
    /// camera, is unloadable with a larger growth.
    #[test]
    fn prefetch_and_unload_thresholds_nest(
        case in view_case(),
        cull in any::<bool>(),
        growth in 1.0f32..3.0,
        extra in 0.0f32..2.0,
    ) {
        let Some(ViewCase { h, nodes, camera, tolerance_px, .. }) = case else { return Ok(()); };
        let nv = NodeView::new(&h, &nodes);
        let view = ViewParams::new(&camera, h.cube_origin, tolerance_px, cull);
        let mut sel = Selection::default();
        select_resident(&nv, &view, &|_| true, &mut sel);
        let mut pre = Vec::new();
        prefetch_set(&nv, &view, &PrefetchOptions { sphere_growth: growth, predicted: None }, &mut pre);
        for &(i, _) in &pre {
            prop_assert!(!sel.draw.contains(&i));
            prop_assert!(!should_unload(&nv, i, &view, growth + extra), "prefetched {} unloadable", i);
        }
        for &i in &sel.draw {
            prop_assert!(!should_unload(&nv, i, &view, growth + extra), "drawn {} unloadable", i);
        }
    }
}

/// Timing of the view traversal on 10^5 nodes (target: <= 1 ms per frame in release).
/// Ignored by default (timings in a shared debug build are noise); run with
/// `cargo test -p tessera-select -- --ignored --nocapture select_timing`.
#[test]
#[ignore]
fn select_timing_100k_nodes() {
    let (h, nodes) = random_forest_with(7, 100_000, 40);
    assert_eq!(nodes.len(), 100_000);
    let camera = Camera::new(
        [1050.0, -1950.0, 60.0],
        [1050.0, -1950.0, 0.0],
        [0.0, 1.0, 0.0],
        60.0,
        1920,
        1080,
    )
    .unwrap();
    for (tolerance_px, cull) in [(1.0, true), (1.0, false), (0.0, false)] {
        let criterion = Criterion::View {
            camera: camera.clone(),
            tolerance_px,
            cull,
        };
        let mut cut = crate::Cut::default();
        let runs = 50;
        let start = std::time::Instant::now();
        for _ in 0..runs {
            crate::select_cut_into(&h, &nodes, &criterion, &mut cut);
        }
        let per = start.elapsed() / runs;
        // Lower bound for comparison: every decision in table order, no traversal.
        let params = ViewParams::new(&camera, h.cube_origin, tolerance_px, cull);
        let start = std::time::Instant::now();
        let mut refined = 0usize;
        for _ in 0..runs {
            refined += nodes
                .iter()
                .filter(|n| params.decide(n) == crate::Decision::Refine)
                .count();
        }
        let linear = start.elapsed() / runs;
        println!(
            "tolerance {tolerance_px} px, cull {cull}: visited {} selected {} in {per:?} per frame \
             (all decisions in table order: {linear:?}, {} refine)",
            cut.visited,
            cut.nodes.len(),
            refined / runs as usize
        );
    }
}
