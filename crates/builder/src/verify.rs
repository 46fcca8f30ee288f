//! Full verification of a model: the format's structural checks
//! ([`tessera_format::verify_structure`]) plus the geometric rules of the forest that need
//! `tessera-tetra`, which the format crate does not know: nodes that share a diamond id
//! really share a refinement edge, and every internal node of a diamond carries the same
//! saturated error and sphere. `tessera verify` prints what [`verify_model`] finds.

use std::collections::HashMap;
use tessera_format::{verify_structure, Model, VerifyReport, NODE_FLAG_LEAF};
use tessera_tetra::{DiamondKey, Tet};

/// At most this many messages of the geometric checks are added to the structural ones
/// (all problems are counted).
const MAX_DIAMOND_MESSAGES: usize = 100;

/// Problems found by the geometric checks, one line each, in node order.
pub fn verify_diamonds(m: &Model) -> Vec<String> {
    let mut problems = Vec::new();
    let mut by_id: HashMap<u32, (DiamondKey, f32, usize)> = HashMap::new();
    let mut by_key: HashMap<DiamondKey, (f32, [f32; 4], usize, u32)> = HashMap::new();
    for (i, n) in m.nodes().iter().enumerate() {
        let Some(t) = Tet::from_path(n.root, n.level, n.tet_path) else {
            problems.push(format!(
                "node {i}: impossible tetrahedron (root {}, level {})",
                n.root, n.level
            ));
            continue;
        };
        let key = t.diamond();
        if let Some((k, _, first)) = by_id.get(&n.diamond) {
            if *k != key {
                problems.push(format!(
                    "node {i}: shares diamond id {} with node {first} but not its refinement edge",
                    n.diamond
                ));
            }
        } else {
            by_id.insert(n.diamond, (key, n.error, i));
        }
        if n.flags & NODE_FLAG_LEAF == 0 {
            match by_key.get(&key) {
                Some((e, s, first, id)) => {
                    if *e != n.error || *s != n.saturated_sphere {
                        problems.push(format!("node {i}: diamond mate of node {first} with another saturated error or sphere"));
                    }
                    if *id != n.diamond {
                        problems.push(format!(
                            "node {i}: diamond mate of node {first} with another diamond id ({} and {id})",
                            n.diamond
                        ));
                    }
                }
                None => {
                    by_key.insert(key, (n.error, n.saturated_sphere, i, n.diamond));
                }
            }
        }
    }
    problems
}

/// Everything checkable in `m`: the structural report, with the geometric problems
/// counted in `problem_count` and the first [`MAX_DIAMOND_MESSAGES`] of them appended to
/// `problems`. Never panics on a corrupt model.
pub fn verify_model(m: &Model) -> VerifyReport {
    let mut r = verify_structure(m);
    let geo = verify_diamonds(m);
    r.problem_count += geo.len();
    r.problems
        .extend(geo.into_iter().take(MAX_DIAMOND_MESSAGES));
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build, BuildOptions, NoProgress};
    use tessera_format::NodeRecord;

    /// A small model built from a generated sphere.
    fn built(dir: &std::path::Path) -> std::path::PathBuf {
        let input = dir.join("sphere.ply");
        tessera_gen::write_sphere(
            &input,
            &tessera_gen::SphereOptions {
                triangles: 20_000,
                ..Default::default()
            },
            &tessera_gen::NoProgress,
        )
        .unwrap();
        let out = dir.join("m.tsr");
        let opts = BuildOptions {
            leaf_triangles: 512,
            node_triangles: 256,
            ..Default::default()
        };
        build(&input, &out, &opts, &NoProgress).unwrap();
        out
    }

    #[test]
    fn fresh_build_is_valid_and_a_wrong_diamond_id_is_found() {
        // Why: the structural checks cannot see a diamond id shared by tetrahedra with
        // different refinement edges (the index is re-encoded with valid checksums here, as a
        // buggy writer would), only the tetra geometry can.
        let dir = tempfile::tempdir().unwrap();
        let path = built(dir.path());
        let m = Model::open(&path).unwrap();
        let r = verify_model(&m);
        assert!(r.is_valid(), "{:?}", r.problems);
        assert!(r.checked_nodes > 1);

        let nodes = m.nodes();
        let key = |n: &NodeRecord| Tet::from_path(n.root, n.level, n.tet_path).map(|t| t.diamond());
        let a = 0;
        let b = (1..nodes.len())
            .find(|&b| key(&nodes[b]) != key(&nodes[a]))
            .unwrap();
        let mut table = nodes.to_vec();
        table[b].diamond = table[a].diamond;
        let bytes = tessera_format::replace_index(&std::fs::read(&path).unwrap(), &table).unwrap();
        drop(m);
        let bad = dir.path().join("bad.tsr");
        std::fs::write(&bad, bytes).unwrap();
        let r = verify_model(&Model::open(&bad).unwrap());
        assert!(
            r.problems
                .iter()
                .any(|p| p.contains("but not its refinement edge")),
            "{:?}",
            r.problems
        );
    }
}
