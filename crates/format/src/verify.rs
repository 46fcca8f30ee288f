//! Deep validation of a model: decodes every patch and checks the invariants the
//! renderer relies on (nested saturated spheres and errors, consistent diamonds and
//! links, vertices inside their bounds). `Model::open` only checks what is cheap;
//! this is what `tessera verify` and the builder's tests run.

use crate::codec::PatchData;
use crate::grid::Grid;
use crate::index::{ByteSource, ModelIndex};
#[cfg(feature = "mmap")]
use crate::reader::Model;
use crate::records::{NodeRecord, NODE_FLAG_LEAF, NO_NODE};

/// At most this many problem messages are kept (all are counted).
pub const MAX_PROBLEM_MESSAGES: usize = 100;

/// Result of [`verify_structure`].
#[derive(Clone, Debug, Default)]
pub struct VerifyReport {
    /// Nodes examined.
    pub checked_nodes: usize,
    /// The first [`MAX_PROBLEM_MESSAGES`] problems found, one line each.
    pub problems: Vec<String>,
    /// Number of problems found (may exceed `problems.len()`).
    pub problem_count: usize,
}

impl VerifyReport {
    /// Whether no problem was found.
    pub fn is_valid(&self) -> bool {
        self.problem_count == 0
    }

    fn problem(&mut self, msg: String) {
        self.problem_count += 1;
        if self.problems.len() < MAX_PROBLEM_MESSAGES {
            self.problems.push(msg);
        }
    }
}

fn dist(a: &[f32; 4], b: &[f32; 4]) -> f64 {
    let d = [
        a[0] as f64 - b[0] as f64,
        a[1] as f64 - b[1] as f64,
        a[2] as f64 - b[2] as f64,
    ];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Whether sphere `inner` lies inside sphere `outer`, up to `eps`.
fn sphere_inside(inner: &[f32; 4], outer: &[f32; 4], eps: f64) -> bool {
    dist(inner, outer) + inner[3] as f64 <= outer[3] as f64 + eps
}

/// Checks every node and patch of `model`; see the module docs. Never panics on a
/// corrupt model: every problem becomes a message.
#[cfg(feature = "mmap")]
pub fn verify_structure(model: &Model) -> VerifyReport {
    verify_index(model.index(), model.bytes())
}

/// [`verify_structure`] of a model held by any [`ByteSource`] (`source`, whose index is
/// `index`): a byte slice, a remote model. Never panics on a corrupt model.
pub fn verify_index<S: ByteSource + ?Sized>(index: &ModelIndex, source: &S) -> VerifyReport {
    let mut r = VerifyReport::default();
    let h = index.header();
    let nodes = index.nodes();
    let step = Grid::of_header(h).step();
    let eps = h.cube_size * 1e-5;
    let grid_max = 1u64 << h.quant_bits.min(32);
    let roots = h.root_count as usize;

    let mut max_error = 0f32;
    let mut max_level = 0u8;
    let mut diamonds: std::collections::HashMap<u32, usize> = Default::default();

    for (i, n) in nodes.iter().enumerate() {
        r.checked_nodes += 1;
        max_error = max_error.max(n.error);
        max_level = max_level.max(n.level);
        let floats = n
            .tight_sphere
            .iter()
            .chain(&n.saturated_sphere)
            .chain(&n.normal_cone)
            .chain(std::iter::once(&n.error));
        if !floats.into_iter().all(|v| v.is_finite()) {
            r.problem(format!("node {i}: non-finite error, sphere or cone"));
        }
        if n.error < 0.0 || n.tight_sphere[3] < 0.0 || n.saturated_sphere[3] < 0.0 {
            r.problem(format!("node {i}: negative error or radius"));
        }

        // Table order and roots.
        if i < roots {
            if n.level != 0 || n.parent != NO_NODE {
                r.problem(format!(
                    "node {i}: one of the first {roots} nodes but not a root"
                ));
            }
        } else if n.level == 0 || n.parent == NO_NODE {
            r.problem(format!(
                "node {i}: root outside the first root_count ({roots}) nodes"
            ));
        }
        if i > 0 && nodes[i - 1].level > n.level {
            r.problem(format!("node {i}: table not sorted by level"));
        }
        if n.root >= 6 {
            r.problem(format!("node {i}: root id {} >= 6", n.root));
        }

        // Links.
        let has_children = n.children.iter().any(|&c| c != NO_NODE);
        if has_children == (n.flags & NODE_FLAG_LEAF != 0) {
            r.problem(format!(
                "node {i}: leaf flag {} but {} children",
                n.flags & NODE_FLAG_LEAF != 0,
                if has_children { "has" } else { "no" }
            ));
        }
        if n.flags & NODE_FLAG_LEAF != 0 && n.error != 0.0 {
            r.problem(format!("node {i}: leaf with non-zero error {}", n.error));
        }
        if n.children[0] != NO_NODE && n.children[0] == n.children[1] {
            r.problem(format!(
                "node {i}: both children are node {}",
                n.children[0]
            ));
        }
        for &c in &n.children {
            let Some(child) = nodes.get(c as usize).filter(|_| c != NO_NODE) else {
                continue;
            };
            check_child(&mut r, i, n, c as usize, child, eps);
        }
        if let Some(p) = nodes.get(n.parent as usize).filter(|_| n.parent != NO_NODE) {
            if !p.children.contains(&(i as u32)) {
                r.problem(format!(
                    "node {i}: parent {} does not list it as a child",
                    n.parent
                ));
            }
        }

        // Spheres of one node and its diamond.
        if !sphere_inside(&n.tight_sphere, &n.saturated_sphere, eps) {
            r.problem(format!(
                "node {i}: tight sphere not inside its saturated sphere"
            ));
        }
        let first = *diamonds.entry(n.diamond).or_insert(i);
        let d = &nodes[first];
        if d.error != n.error || d.saturated_sphere != n.saturated_sphere {
            r.problem(format!(
                "node {i}: diamond {} error/saturated sphere differ from node {first}",
                n.diamond
            ));
        }

        // The patch itself.
        match index.read_patch(source, i) {
            Ok(patch) => check_patch(&mut r, i, n, &patch, step, eps, grid_max),
            Err(e) => r.problem(format!("node {i}: {e}")),
        }
    }

    if h.max_error != max_error {
        r.problem(format!(
            "header max_error {} but the largest node error is {max_error}",
            h.max_error
        ));
    }
    if !nodes.is_empty() && h.level_count != max_level as u32 + 1 {
        r.problem(format!(
            "header level_count {} but the deepest level is {max_level}",
            h.level_count
        ));
    }
    if r.problem_count > r.problems.len() {
        let more = r.problem_count - r.problems.len();
        tracing::warn!(more, "verify: problem list truncated");
    }
    r
}

fn check_child(
    r: &mut VerifyReport,
    i: usize,
    n: &NodeRecord,
    c: usize,
    child: &NodeRecord,
    eps: f64,
) {
    if child.parent != i as u32 {
        r.problem(format!(
            "node {c}: child of {i} but its parent is {}",
            child.parent
        ));
    }
    if child.level as u32 != n.level as u32 + 1 {
        r.problem(format!(
            "node {c}: level {} under parent {i} of level {}",
            child.level, n.level
        ));
    }
    if child.root != n.root {
        r.problem(format!(
            "node {c}: root {} differs from parent {i}'s {}",
            child.root, n.root
        ));
    }
    if child.error > n.error {
        r.problem(format!(
            "node {c}: error {} larger than parent {i}'s {}",
            child.error, n.error
        ));
    }
    if !sphere_inside(&child.saturated_sphere, &n.saturated_sphere, eps) {
        r.problem(format!(
            "node {c}: saturated sphere not inside parent {i}'s"
        ));
    }
}

fn check_patch(
    r: &mut VerifyReport,
    i: usize,
    n: &NodeRecord,
    patch: &PatchData,
    step: f64,
    eps: f64,
    grid_max: u64,
) {
    // Counts and index ranges are enforced by the decoder; positions and spheres here.
    let s = &n.tight_sphere;
    let mut outside_grid = 0usize;
    let mut outside_sphere = 0usize;
    for p in &patch.positions {
        if p.iter()
            .zip(&n.quant_min)
            .any(|(&v, &m)| (v as u64) > grid_max || v < m)
        {
            outside_grid += 1;
        }
        let d = [
            p[0] as f64 * step - s[0] as f64,
            p[1] as f64 * step - s[1] as f64,
            p[2] as f64 * step - s[2] as f64,
        ];
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() > s[3] as f64 + eps {
            outside_sphere += 1;
        }
    }
    if outside_grid > 0 {
        r.problem(format!(
            "node {i}: {outside_grid} vertices outside the grid or below quant_min"
        ));
    }
    if outside_sphere > 0 {
        r.problem(format!(
            "node {i}: {outside_sphere} vertices outside the tight sphere"
        ));
    }
    for t in &patch.morph_targets {
        if t.iter().any(|&v| v as u64 > grid_max) {
            r.problem(format!("node {i}: morph target outside the grid"));
            break;
        }
    }
    if n.parent == NO_NODE && !patch.morph_targets.is_empty() {
        r.problem(format!("node {i}: root with morph targets"));
    }
}
