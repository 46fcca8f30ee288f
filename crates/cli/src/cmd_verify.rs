//! `tessera verify`: the format's structural checks plus the geometric rules of the
//! forest that need `tessera-tetra`: nodes that share a diamond id really share a
//! refinement edge, and every internal node of a diamond carries the same saturated error.

use anyhow::Context;
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::ExitCode;
use tessera_format::{verify_structure, Model, NODE_FLAG_LEAF};
use tessera_tetra::{DiamondKey, Tet};

#[derive(clap::Args)]
pub struct Args {
    model: PathBuf,
}

/// Problems found by the geometric checks.
pub fn verify_diamonds(m: &Model) -> Vec<String> {
    let mut problems = Vec::new();
    let mut by_id: HashMap<u32, (DiamondKey, f32, usize)> = HashMap::new();
    let mut by_key: HashMap<DiamondKey, (f32, [f32; 4], usize)> = HashMap::new();
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
                Some((e, s, first)) => {
                    if *e != n.error || *s != n.saturated_sphere {
                        problems.push(format!("node {i}: diamond mate of node {first} with another saturated error or sphere"));
                    }
                }
                None => {
                    by_key.insert(key, (n.error, n.saturated_sphere, i));
                }
            }
        }
    }
    problems
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let m = Model::open(&a.model).with_context(|| format!("{}", a.model.display()))?;
    let r = verify_structure(&m);
    let mut problems = r.problems.clone();
    let mut count = r.problem_count;
    let geo = verify_diamonds(&m);
    count += geo.len();
    problems.extend(geo.into_iter().take(100));
    if count == 0 {
        println!(
            "{}: valid ({} nodes checked)",
            a.model.display(),
            r.checked_nodes
        );
        return Ok(ExitCode::SUCCESS);
    }
    for p in &problems {
        println!("{}: {p}", a.model.display());
    }
    eprintln!("error: {}: INVALID, {count} problem(s)", a.model.display());
    Ok(ExitCode::FAILURE)
}
