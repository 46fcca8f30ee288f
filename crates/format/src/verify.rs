//! Deep validation of a model: decodes every patch and checks the invariants the
//! renderer relies on (nested saturated spheres and errors, consistent diamonds and
//! links, vertices inside their bounds). `Model::open` only checks what is cheap;
//! this is what `tessera verify` and the builder's tests run.

use crate::codec::{PatchData, TextureCodec};
use crate::grid::Grid;
use crate::index::{ByteSource, ModelIndex};
#[cfg(feature = "mmap")]
use crate::reader::Model;
use crate::records::{NodeRecord, ATTR_TEXTURE, NODE_FLAG_LEAF, NO_NODE};

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
    if h.reserved.iter().any(|&v| v != 0) {
        r.problem("header: reserved fields are not zero".into());
    }
    let textured = h.attributes & ATTR_TEXTURE != 0;
    let codec = u8::try_from(h.texture_codec)
        .ok()
        .and_then(TextureCodec::from_byte);
    if textured && codec.is_none() {
        r.problem(format!(
            "header: texture codec {} in a textured model",
            h.texture_codec
        ));
    } else if !textured && h.texture_codec != 0 {
        r.problem(format!(
            "header: texture codec {} in a model without textures",
            h.texture_codec
        ));
    }
    if h.leaf_triangles_max == 0 {
        r.problem("header: leaf_triangles_max is 0".into());
    }
    let bounds = Bounds {
        step,
        eps,
        grid_max,
        origin: h.cube_origin,
        sphere: h.bounding_sphere,
    };
    let mut leaf_triangles = 0u64;

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
        if n.reserved.iter().any(|&v| v != 0) {
            r.problem(format!("node {i}: reserved fields are not zero"));
        }
        let textured = h.attributes & ATTR_TEXTURE != 0;
        let has_texture = n.texture_size != [0, 0];
        if textured && n.vertex_count > 0 && n.texture_size.contains(&0) {
            r.problem(format!(
                "node {i}: texture size {:?} in a textured model",
                n.texture_size
            ));
        } else if !textured && has_texture {
            r.problem(format!(
                "node {i}: texture size {:?} in a model without textures",
                n.texture_size
            ));
        }
        if n.flags & NODE_FLAG_LEAF != 0 {
            leaf_triangles += u64::from(n.triangle_count);
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
        if n.level < 64 && n.tet_path >> n.level != 0 {
            r.problem(format!(
                "node {i}: tet_path {:#x} has bits beyond its level {}",
                n.tet_path, n.level
            ));
        }
        for (k, &c) in n.children.iter().enumerate() {
            let Some(child) = nodes.get(c as usize).filter(|_| c != NO_NODE) else {
                continue;
            };
            check_child(&mut r, i, n, c as usize, child, eps);
            // Child slot `k` is bisection choice `k` at depth `n.level` (records.rs).
            if n.level < 63 && child.tet_path != n.tet_path | (k as u64) << n.level {
                r.problem(format!(
                    "node {}: tet_path {:#x} does not extend parent {i}'s {:#x} by choice {k}",
                    c, child.tet_path, n.tet_path
                ));
            }
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
        let seen = diamonds.len();
        let first = *diamonds.entry(n.diamond).or_insert(i);
        if first == i && n.diamond as usize != seen {
            r.problem(format!(
                "node {i}: diamond id {} out of order (ids are numbered by first \
                 appearance: {seen} expected)",
                n.diamond
            ));
        } else if first != i && n.flags & NODE_FLAG_LEAF != 0 {
            r.problem(format!(
                "node {i}: leaf shares diamond id {} with node {first} (leaves have their own)",
                n.diamond
            ));
        }
        let d = &nodes[first];
        if d.error != n.error || d.saturated_sphere != n.saturated_sphere {
            r.problem(format!(
                "node {i}: diamond {} error/saturated sphere differ from node {first}",
                n.diamond
            ));
        }

        // The patch itself.
        match index.read_patch(source, i) {
            Ok(patch) => {
                check_patch(&mut r, i, n, &patch, &bounds);
                if let Some(t) = patch.texture.as_ref().filter(|t| t.codec != codec) {
                    r.problem(format!(
                        "node {i}: texture codec {:?}, the header says {:?}",
                        t.codec, codec
                    ));
                }
            }
            Err(e) => r.problem(format!("node {i}: {e}")),
        }
    }

    if leaf_triangles > h.input_triangles {
        r.problem(format!(
            "header input_triangles {} but the leaves hold {leaf_triangles}",
            h.input_triangles
        ));
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

/// What a patch's vertices must lie within.
struct Bounds {
    step: f64,
    eps: f64,
    grid_max: u64,
    /// The header's cube origin and bounding sphere (model coordinates).
    origin: [f64; 3],
    sphere: [f64; 4],
}

fn check_patch(r: &mut VerifyReport, i: usize, n: &NodeRecord, patch: &PatchData, b: &Bounds) {
    let (step, eps, grid_max) = (b.step, b.eps, b.grid_max);
    // Counts and index ranges are enforced by the decoder; positions and spheres here.
    let s = &n.tight_sphere;
    let mut outside_grid = 0usize;
    let mut outside_sphere = 0usize;
    // The header's sphere bounds the input, whose grid points are within half a cell
    // diagonal (< one step) of it.
    let mut outside_model = 0usize;
    for p in &patch.positions {
        let m: [f64; 3] = std::array::from_fn(|k| b.origin[k] + p[k] as f64 * step - b.sphere[k]);
        let dm = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        if !(dm <= b.sphere[3] + step + eps) {
            outside_model += 1;
        }
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
    if outside_model > 0 {
        r.problem(format!(
            "node {i}: {outside_model} vertices outside the header's bounding sphere"
        ));
    }
    // The normal cone holds the geometric normal of every triangle (the builder's
    // definition, from the grid positions; the slack covers the axis stored in f32).
    let c = n.normal_cone;
    if c[3] > -1.0 && c.iter().all(|v| v.is_finite()) {
        let axis = [c[0] as f64, c[1] as f64, c[2] as f64];
        let min_cos = c[3] as f64 - 1e-4;
        let q = |v: u32| patch.positions.get(v as usize).map(|p| p.map(|x| x as f64));
        let mut outside_cone = 0usize;
        for t in patch.indices.chunks_exact(3) {
            let (Some(a), Some(b), Some(d)) = (q(t[0]), q(t[1]), q(t[2])) else {
                continue;
            };
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
            let f = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let len = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            if len > 0.0 && (f[0] * axis[0] + f[1] * axis[1] + f[2] * axis[2]) / len < min_cos {
                outside_cone += 1;
            }
        }
        if outside_cone > 0 {
            r.problem(format!(
                "node {i}: {outside_cone} triangles face outside the normal cone"
            ));
        }
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
