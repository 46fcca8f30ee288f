//! Properties of the bisection forest that the whole of Tessera leans on: children tile
//! their parent, refinement edges are longest edges, uniform refinements are conforming,
//! diamonds found by probing equal diamonds found by brute force, point location is right.

use super::*;
use proptest::prelude::*;
use std::collections::HashMap;

fn orient(a: Point, b: Point, c: Point, d: Point) -> i128 {
    let u = sub(b, a);
    let v = sub(c, a);
    let w = sub(d, a);
    let x = cross(u, v);
    x[0] * w[0] as i128 + x[1] * w[1] as i128 + x[2] * w[2] as i128
}

fn volume6(t: &Tet) -> i128 {
    orient(t.v[0], t.v[1], t.v[2], t.v[3]).abs()
}

fn contains(t: &Tet, p: Point) -> bool {
    let full = orient(t.v[0], t.v[1], t.v[2], t.v[3]);
    let s = full.signum();
    let parts = [
        orient(p, t.v[1], t.v[2], t.v[3]),
        orient(t.v[0], p, t.v[2], t.v[3]),
        orient(t.v[0], t.v[1], p, t.v[3]),
        orient(t.v[0], t.v[1], t.v[2], p),
    ];
    parts.iter().all(|x| *x == 0 || x.signum() == s)
}

fn uniform(level: u8) -> Vec<Tet> {
    let mut tets: Vec<Tet> = Tet::roots().to_vec();
    for _ in 0..level {
        tets = tets.iter().flat_map(|t| t.children()).collect();
    }
    tets
}

fn len2(a: Point, b: Point) -> i64 {
    let d = sub(a, b);
    dot(d, d)
}

#[test]
fn roots_tile_the_cube() {
    // volume6 is six times the volume: each Kuhn tetrahedron is a sixth of the cube.
    for t in Tet::roots() {
        assert_eq!(volume6(&t), (CUBE as i128).pow(3));
    }
}

#[test]
fn children_tile_parent_and_refinement_edge_is_longest() {
    // Why: the partition must cover space exactly once at every level, and ATP's
    // "longest-edge bisection" is what keeps the tetrahedra well shaped.
    for t in uniform(7) {
        let [a, b] = t.children();
        assert!(volume6(&a) > 0 && volume6(&b) > 0);
        assert_eq!(volume6(&a) + volume6(&b), volume6(&t));
        let (p, q) = t.refinement_edge();
        let l = len2(p, q);
        for i in 0..4 {
            for j in i + 1..4 {
                assert!(
                    len2(t.v[i], t.v[j]) <= l,
                    "refinement edge not longest in {t:?}"
                );
            }
        }
        assert_eq!(a.parent(), Some(t));
        assert_eq!(b.parent(), Some(t));
    }
}

#[test]
fn uniform_refinements_are_conforming() {
    // Why: ATP's crack-freeness rests on conforming tetrahedral meshes: every interior
    // face is shared by exactly two tetrahedra (no hanging vertices).
    for level in 0..=9u8 {
        let mut faces: HashMap<[Point; 3], u32> = HashMap::new();
        for t in uniform(level) {
            for skip in 0..4 {
                let mut f: Vec<Point> = (0..4).filter(|&i| i != skip).map(|i| t.v[i]).collect();
                f.sort();
                *faces.entry([f[0], f[1], f[2]]).or_default() += 1;
            }
        }
        for (f, n) in faces {
            let on_boundary =
                (0..3).any(|ax| f.iter().all(|p| p[ax] == 0) || f.iter().all(|p| p[ax] == CUBE));
            let expect = if on_boundary { 1 } else { 2 };
            assert_eq!(n, expect, "level {level}: face {f:?} shared by {n}");
        }
    }
}

#[test]
fn diamonds_by_probing_match_brute_force() {
    // Why: the builder simplifies diamonds as units and the conformity closure enumerates
    // diamond mates by probing; a missed mate would break crack-freeness.
    for level in 0..=10u8 {
        let tets = uniform(level);
        let mut groups: HashMap<DiamondKey, Vec<(u8, u64)>> = HashMap::new();
        for t in &tets {
            groups
                .entry(t.diamond())
                .or_default()
                .push((t.root, t.path));
        }
        for t in &tets {
            let mates: Vec<(u8, u64)> =
                t.diamond_mates().iter().map(|m| (m.root, m.path)).collect();
            let mut expect = groups[&t.diamond()].clone();
            expect.sort();
            assert_eq!(mates, expect, "level {level} tet {t:?}");
        }
        // Interior diamonds have 6, 4, 8 tetrahedra by level mod 3; at levels 1 and 2 every
        // refinement edge lies on the cube's boundary, so diamonds there are halves.
        let full = [6, 4, 8][(level % 3) as usize];
        let max = groups.values().map(|g| g.len()).max().unwrap_or(0);
        if level == 0 || level >= 4 {
            assert_eq!(max, full, "level {level}");
        }
        assert!(groups.values().all(|g| g.len() <= full));
    }
}

#[test]
fn deep_diamonds_are_found() {
    // Why: probing must keep working at the deepest levels, where tetrahedra are a few
    // lattice units across.
    let p = [CUBE / 3 + 7, CUBE / 2 - 5, CUBE / 5 + 11];
    for level in (30..=MAX_LEVEL).step_by(3) {
        for off in 0..3u8 {
            let lv = (level + off).min(MAX_LEVEL);
            let t = Tet::locate_scaled(p, 1, lv).expect("inside");
            let mates = t.diamond_mates();
            let full = [6, 4, 8][(lv % 3) as usize];
            assert_eq!(mates.len(), full, "level {lv}");
            assert!(mates.iter().all(|m| m.diamond() == t.diamond()));
        }
    }
}

#[test]
fn dfs_keys_nest() {
    for t in uniform(6) {
        let (s, e) = dfs_range(t.root, t.level, t.path);
        for c in t.children() {
            let (cs, ce) = dfs_range(c.root, c.level, c.path);
            assert!(s <= cs && ce <= e);
        }
    }
}

proptest! {
    #[test]
    fn located_tet_contains_point(x in 0..=CUBE, y in 0..=CUBE, z in 0..=CUBE, level in 0u8..40) {
        let t = Tet::locate_scaled([x, y, z], 1, level).expect("inside the cube");
        prop_assert!(contains(&t, [x, y, z]));
        prop_assert_eq!(Tet::from_path(t.root, t.level, t.path), Some(t));
    }

    #[test]
    fn locator_agrees_with_locate(pts in prop::collection::vec((0..CUBE, 0..CUBE, 0..CUBE), 1..40), depth in 0u8..40, jitter in 0i64..5000) {
        // Why: the partition keys every triangle with the incremental locator; it must give
        // exactly the tetrahedron the plain descent gives, for near and far jumps alike.
        let mut loc = Locator::new(depth, 3);
        for (i, &(x, y, z)) in pts.iter().enumerate() {
            for p in [[3 * x, 3 * y, 3 * z], [3 * x + (i as i64 % 3) * jitter % 7, 3 * y + 1, (3 * z - 2).max(0)]] {
                let expect = Tet::locate_scaled(p, 3, depth).map(|t| t.dfs_key());
                prop_assert_eq!(loc.locate(p), expect);
            }
        }
    }

    #[test]
    fn locator_agrees_with_locate_on_walks(start in (0..CUBE, 0..CUBE, 0..CUBE), steps in prop::collection::vec((-3i64..=3, -3i64..=3, -3i64..=3), 1..200), unit in 0u32..18, depth in 1u8..30) {
        // Why: consecutive triangles of a mesh are neighbours, so most queries hit the
        // locator's strictly-inside shortcut; points on faces and planes (a walk on a
        // coarse lattice of the cube) must still get the plain descent's tie-breaking.
        let mut loc = Locator::new(depth, 3);
        let u = 1i64 << unit;
        let mut p = [start.0, start.1, start.2].map(|c| (c / u) * u * 3);
        for (dx, dy, dz) in steps {
            p = [p[0] + dx * u, p[1] + dy * u, p[2] + dz * u].map(|c| c.clamp(0, 3 * CUBE));
            let expect = Tet::locate_scaled(p, 3, depth).map(|t| t.dfs_key());
            prop_assert_eq!(loc.locate(p), expect);
        }
    }

    #[test]
    fn scaled_location_agrees(x in 0..CUBE, y in 0..CUBE, z in 0..CUBE, level in 0u8..30) {
        let a = Tet::locate_scaled([x, y, z], 1, level).unwrap();
        let b = Tet::locate_scaled([3 * x, 3 * y, 3 * z], 3, level).unwrap();
        prop_assert_eq!(a, b);
    }
}
