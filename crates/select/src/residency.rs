//! Residency-aware selection, prefetch and eviction (issue 3, part 1; ATP section 4 with
//! GoLD section 4.1 paging).
//!
//! Why it exists: a renderer holds only part of a model's patches in memory. Each frame it
//! (1) draws the best cut it can from what is resident without ever waiting
//! ([`select_resident`]), reporting which missing nodes would improve the picture and by
//! how many pixels; (2) asks for the nodes a slightly more demanding view would need
//! ([`prefetch_set`]: spheres grown by a factor, i.e. the view seen a bit closer, and
//! optionally a second pass from a linearly predicted camera, [`predict_camera`]); and
//! (3) evicts only nodes that even a clearly more demanding view would not need
//! ([`should_unload`]), so nodes at the edge of the refinement threshold do not load and
//! unload on alternate frames.
//!
//! The thresholds nest: with `1 <= sphere_growth <= unload_growth`, every node the current
//! view needs and every node of the (current-camera) prefetch set fails
//! [`should_unload`], because a grown sphere only ever makes a node look closer (more
//! refinement) and bigger (less frustum and backface culling), and growing nested spheres
//! about their own centres keeps them nested, so the refinement decision stays monotone.
//!
//! Speed: all three run on a [`NodeView`], a compact 64-byte copy of the fields the
//! traversal reads (spheres, cone, error, sanitised children, parent), built once per
//! model: half the memory traffic of the 128-byte [`NodeRecord`]s, one cache line per
//! node. The functions allocate nothing but their outputs and a small stack.
//!
//! Cracks: the cut of [`select_resident`] is conforming only if whole diamonds become
//! resident together. The rule here is per node: a node refines only when ALL its
//! existing (not culled) children are resident, else it is drawn itself. Two tetrahedra
//! of one diamond have different parents, so if one parent's children are resident and
//! the other's are not, the cut would mix levels across the diamond's refinement edge.
//! The loader (renderer issue) must therefore make a diamond's nodes resident, and evict
//! them, as one unit; with that invariant the per-node rule gives the same conforming cut
//! as [`crate::select_cut`] restricted to what is loaded.

use glam::Vec3;
use tessera_format::{Header, NodeRecord, NO_NODE};

use crate::camera::Camera;
use crate::select::{closest_distance, is_backfacing, needs_refinement, ViewParams};

/// The per-node fields the traversals read, 64 bytes, one cache line.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub struct HotNode {
    /// Saturated sphere, centre relative to `cube_origin`, radius.
    pub saturated_sphere: [f32; 4],
    /// Tight sphere of the patch, centre relative to `cube_origin`, radius.
    pub tight_sphere: [f32; 4],
    /// Normal cone: unit axis xyz, cosine of the half-angle.
    pub normal_cone: [f32; 4],
    /// Saturated model-space error.
    pub error: f32,
    /// Children, [`NO_NODE`] where absent or invalid (out of range, or not after the
    /// parent in the table: see the robustness note of [`crate::select`]).
    pub children: [u32; 2],
    /// The node whose (valid) child this is; [`NO_NODE`] for roots and orphans. Derived
    /// from the children links, not from `NodeRecord::parent`.
    pub parent: u32,
}

const _: () = assert!(std::mem::size_of::<HotNode>() == 64);

/// A compact copy of a model's node table for the per-frame traversals, built once per
/// model with [`NodeView::new`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeView {
    nodes: Vec<HotNode>,
    root_count: u32,
    cube_origin: [f64; 3],
}

impl NodeView {
    /// Copies the hot fields of `nodes`; roots are the first `header.root_count` records
    /// (clamped to the table), geometry is relative to `header.cube_origin`.
    pub fn new(header: &Header, nodes: &[NodeRecord]) -> Self {
        let len = nodes.len();
        let mut hot: Vec<HotNode> = nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let valid = |c: u32| c != NO_NODE && c as usize > i && (c as usize) < len;
                let [c0, c1] = n.children;
                HotNode {
                    saturated_sphere: n.saturated_sphere,
                    tight_sphere: n.tight_sphere,
                    normal_cone: n.normal_cone,
                    error: n.error,
                    children: [
                        if valid(c0) { c0 } else { NO_NODE },
                        if valid(c1) { c1 } else { NO_NODE },
                    ],
                    parent: NO_NODE,
                }
            })
            .collect();
        for i in 0..len {
            for c in hot[i].children {
                if c != NO_NODE && hot[c as usize].parent == NO_NODE {
                    hot[c as usize].parent = i as u32;
                }
            }
        }
        NodeView {
            nodes: hot,
            root_count: (header.root_count as usize).min(len) as u32,
            cube_origin: header.cube_origin,
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// True when the table is empty.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Number of roots (the first records).
    pub fn root_count(&self) -> u32 {
        self.root_count
    }

    /// The model's cube origin (camera positions are converted relative to it).
    pub fn cube_origin(&self) -> [f64; 3] {
        self.cube_origin
    }

    /// The hot fields of every node, table order.
    pub fn nodes(&self) -> &[HotNode] {
        &self.nodes
    }
}

/// The result of [`select_resident`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    /// Resident nodes to draw this frame, depth-first order.
    pub draw: Vec<u32>,
    /// Nodes the view needs but that are not resident, with a priority: the screen-space
    /// error (pixels) their absence leaves on screen, bigger is more urgent; infinite for
    /// missing roots (nothing at all can be drawn for them).
    pub missing: Vec<(u32, f32)>,
    /// Nodes examined: the traversal's cost.
    pub visited: usize,
}

/// Options of [`prefetch_set`].
#[derive(Clone, Debug, PartialEq)]
pub struct PrefetchOptions {
    /// Factor (>= 1, e.g. 1.5) by which saturated spheres are grown for the refinement
    /// test and tight spheres for culling: the view as if a bit closer and a bit wider
    /// (GoLD's spatial/resolution prefetch). 1 adds nothing beyond the current view.
    pub sphere_growth: f32,
    /// A predicted camera (ATP's linear prediction, see [`predict_camera`]): a second
    /// pass from it, with the same growth, tolerance and culling.
    pub predicted: Option<Camera>,
}

impl Default for PrefetchOptions {
    fn default() -> Self {
        PrefetchOptions {
            sphere_growth: 1.5,
            predicted: None,
        }
    }
}

const STACK_CAPACITY: usize = 256;

/// Culled with the tight sphere grown by `growth` (frustum or normal cone). Growing only
/// ever culls less.
#[inline]
fn culled(view: &ViewParams, n: &HotNode, growth: f32) -> bool {
    let s = n.tight_sphere;
    let r = s[3] * growth;
    view.frustum
        .sphere_outside(Vec3::new(s[0], s[1], s[2]), r)
        || is_backfacing(n.normal_cone, [s[0], s[1], s[2], r], view.eye)
}

#[inline]
fn grown(s: [f32; 4], growth: f32) -> [f32; 4] {
    [s[0], s[1], s[2], s[3] * growth]
}

/// The projected saturated error of `n`, with the saturated sphere grown by `growth`,
/// exceeds the tolerance. Growing only ever refines more.
#[inline]
fn refines(view: &ViewParams, n: &HotNode, growth: f32) -> bool {
    needs_refinement(
        n.error,
        closest_distance(view.eye, grown(n.saturated_sphere, growth)),
        view.error_scale,
    )
}

/// Pixels of error the parent (`parent_error`) shows over the region of `child`: the
/// parent's error projected at the closest point of the child's (grown) saturated sphere.
/// The child's own error is not used because it is 0 for leaves; this is at most the
/// parent's projected error (nested spheres) and is larger for children nearer the eye.
#[inline]
fn priority(view: &ViewParams, parent_error: f32, child: &HotNode, growth: f32) -> f32 {
    let d = closest_distance(view.eye, grown(child.saturated_sphere, growth));
    if d <= 0.0 {
        f32::INFINITY
    } else {
        let p = parent_error * view.px_per_unit / d;
        if p.is_nan() {
            0.0
        } else {
            p
        }
    }
}

/// Residency-aware selection: the stateless top-down traversal of
/// [`crate::select_cut`] (cull by frustum and normal cone when `view.cull`, refine while
/// the projected saturated error exceeds the tolerance) that draws only resident nodes
/// and never waits.
///
/// - A root that is not resident (and not culled) goes to `missing` with infinite
///   priority and nothing is drawn for it (roots are meant to be loaded first).
/// - A node that needs refinement refines into its children only when ALL its existing,
///   not culled children are resident; otherwise it is drawn itself and each missing,
///   not culled child is queued in `missing` (priority: see [`Selection::missing`]).
/// - Every drawn node is resident; with everything resident the result equals
///   [`crate::select_cut`]'s.
///
/// Crack-free only if diamonds are loaded as a unit: see the module doc. `out` is
/// cleared first; its allocations are reused.
pub fn select_resident(
    nv: &NodeView,
    view: &ViewParams,
    resident: &impl Fn(u32) -> bool,
    out: &mut Selection,
) {
    out.draw.clear();
    out.missing.clear();
    out.visited = 0;
    let nodes = &nv.nodes;
    let roots = nv.root_count;
    let mut stack: Vec<u32> = Vec::with_capacity(STACK_CAPACITY.max(roots as usize));
    stack.extend((0..roots).rev());
    while let Some(index) = stack.pop() {
        let n = &nodes[index as usize];
        out.visited += 1;
        if view.cull && culled(view, n, 1.0) {
            continue;
        }
        // Non-roots are pushed only when resident.
        if index < roots && !resident(index) {
            out.missing.push((index, f32::INFINITY));
            continue;
        }
        let [c0, c1] = n.children;
        if (c0 == NO_NODE && c1 == NO_NODE) || !refines(view, n, 1.0) {
            out.draw.push(index);
            continue;
        }
        let r0 = c0 == NO_NODE || resident(c0);
        let r1 = c1 == NO_NODE || resident(c1);
        if !(r0 && r1) {
            // Missing children that the view would cull are not needed.
            let before = out.missing.len();
            for (c, r) in [(c0, r0), (c1, r1)] {
                if !r {
                    let cn = &nodes[c as usize];
                    if !(view.cull && culled(view, cn, 1.0)) {
                        out.missing.push((c, priority(view, n.error, cn, 1.0)));
                    }
                }
            }
            if out.missing.len() > before {
                out.draw.push(index);
                continue;
            }
        }
        // Second child first, so the first child's subtree is emitted first.
        if c1 != NO_NODE && r1 {
            stack.push(c1);
        }
        if c0 != NO_NODE && r0 {
            stack.push(c0);
        }
    }
}

/// One prefetch pass from `pass` with spheres grown by `growth`; nodes the current view
/// (`cur`, no growth, everything resident) needs are left out. A stack entry carries
/// whether the current view reaches the node's parent and refines it.
fn prefetch_pass(
    nv: &NodeView,
    cur: &ViewParams,
    pass: &ViewParams,
    growth: f32,
    stack: &mut Vec<(u32, bool, f32)>,
    out: &mut Vec<(u32, f32)>,
) {
    let nodes = &nv.nodes;
    stack.clear();
    stack.extend((0..nv.root_count).rev().map(|r| (r, true, f32::INFINITY)));
    while let Some((index, chain, prio)) = stack.pop() {
        let n = &nodes[index as usize];
        if pass.cull && culled(pass, n, growth) {
            continue;
        }
        let in_current = chain && !(cur.cull && culled(cur, n, 1.0));
        if !in_current {
            out.push((index, prio));
        }
        let [c0, c1] = n.children;
        if (c0 == NO_NODE && c1 == NO_NODE) || !refines(pass, n, growth) {
            continue;
        }
        let child_chain = in_current && refines(cur, n, 1.0);
        for c in [c1, c0] {
            if c != NO_NODE {
                let p = priority(pass, n.error, &nodes[c as usize], growth);
                stack.push((c, child_chain, p));
            }
        }
    }
}

/// The prefetch set: nodes that a slightly more demanding view would need (the view with
/// spheres grown by `opts.sphere_growth`, plus the same from `opts.predicted`), minus
/// every node the current view itself needs (what it draws and the nodes refined on the
/// way, everything assumed resident; those belong to [`select_resident`]'s `missing`).
///
/// "Needed" means reached by the traversal and not culled: drawn or refined through,
/// since a node must be resident for its children to be drawn in its place. Each node
/// appears once, with its largest priority (pixels of error its parent shows over its
/// region, seen by the pass that found it; infinite for roots), sorted most urgent first,
/// ties by index. `out` is cleared first.
pub fn prefetch_set(
    nv: &NodeView,
    view: &ViewParams,
    opts: &PrefetchOptions,
    out: &mut Vec<(u32, f32)>,
) {
    out.clear();
    let growth = if opts.sphere_growth.is_nan() {
        1.0
    } else {
        opts.sphere_growth.max(1.0)
    };
    let mut stack = Vec::with_capacity(STACK_CAPACITY);
    prefetch_pass(nv, view, view, growth, &mut stack, out);
    if let Some(camera) = &opts.predicted {
        let tolerance_px = if view.error_scale.is_finite() {
            view.px_per_unit / view.error_scale
        } else {
            0.0
        };
        let predicted = ViewParams::new(camera, nv.cube_origin, tolerance_px, view.cull);
        // Same tolerance exactly (the division above may round).
        let predicted = ViewParams {
            error_scale: view.error_scale * (predicted.px_per_unit / view.px_per_unit),
            ..predicted
        };
        prefetch_pass(nv, view, &predicted, growth, &mut stack, out);
    }
    // Duplicates: the two passes, or a corrupt table naming one child from two parents.
    out.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
    out.dedup_by_key(|e| e.0);
    out.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
}

/// Linear extrapolation of a camera (ATP's motion prediction): position and target move
/// on with their velocity over the last `dt_s` seconds for `lookahead_s` more seconds;
/// up, field of view and image size are `cur`'s. Returns `cur` unchanged when `dt_s` is
/// not positive, a value is not finite, or the extrapolated camera would be invalid
/// (e.g. position and target meet).
pub fn predict_camera(prev: &Camera, cur: &Camera, dt_s: f64, lookahead_s: f64) -> Camera {
    if !(dt_s > 0.0 && dt_s.is_finite() && lookahead_s.is_finite()) {
        return cur.clone();
    }
    let k = lookahead_s / dt_s;
    let step = |p: [f64; 3], c: [f64; 3]| -> [f64; 3] {
        [
            c[0] + (c[0] - p[0]) * k,
            c[1] + (c[1] - p[1]) * k,
            c[2] + (c[2] - p[2]) * k,
        ]
    };
    let next = Camera {
        position: step(prev.position, cur.position),
        target: step(prev.target, cur.target),
        ..cur.clone()
    };
    if next.position.iter().chain(&next.target).all(|v| v.is_finite())
        && next.validate().is_ok()
    {
        next
    } else {
        cur.clone()
    }
}

/// Eviction test with hysteresis: true when node `index` would not be needed even by the
/// view with spheres grown by `unload_growth` (use more than the prefetch growth, e.g.
/// 2.0 against 1.5): its parent would not be refined (saturated sphere grown), or the node
/// itself is culled (tight sphere grown, when `view.cull`). Roots are never unloadable;
/// nodes that are no valid child of anything (orphans) and indices out of range always
/// are.
///
/// With `unload_growth >= sphere_growth >= 1`, nothing the current view needs and nothing
/// in the current-camera prefetch set is unloadable (see the module doc). Only the parent
/// is tested, not every ancestor, so this may keep a node whose grandparent is culled:
/// conservative, never evicting something needed.
pub fn should_unload(nv: &NodeView, index: u32, view: &ViewParams, unload_growth: f32) -> bool {
    let Some(n) = nv.nodes.get(index as usize) else {
        return true;
    };
    if index < nv.root_count {
        return false;
    }
    let growth = if unload_growth.is_nan() {
        1.0
    } else {
        unload_growth.max(1.0)
    };
    if n.parent == NO_NODE {
        return true;
    }
    if view.cull && culled(view, n, growth) {
        return true;
    }
    !refines(view, &nv.nodes[n.parent as usize], growth)
}
