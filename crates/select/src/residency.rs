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
//! resident together. The rule here is per node, not per diamond: a node refines only
//! when ALL its existing (not culled) children are resident, else it is drawn itself.
//! The tetrahedra of a diamond share a refinement edge that their children split, so if
//! one of them refines (its children resident) while another stays coarse (some of its
//! children missing), the cut mixes levels across that edge and the patches crack there.
//! The caller must therefore make a diamond's children resident, and evict them, as one
//! unit (and only after the diamonds of its parents): `tessera-stream`'s residency groups
//! and its `resident` predicate do exactly that. With that invariant every node of a
//! diamond takes the same decision and the per-node rule gives a conforming cut:
//! [`crate::select_cut`]'s cut coarsened where children are missing.

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
    /// Children, [`NO_NODE`] where absent or invalid: out of range, or not after the
    /// parent in the table (see the robustness note of [`crate::select`]), or a root, or
    /// already the child of an earlier node. So the links form a forest and every
    /// traversal reaches each node at most once, even on a corrupt table.
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
        let root_count = (header.root_count as usize).min(len) as u32;
        for i in 0..len {
            for k in 0..2 {
                let c = hot[i].children[k];
                if c == NO_NODE {
                    continue;
                }
                if c < root_count || hot[c as usize].parent != NO_NODE {
                    // A corrupt table: a root, or a node some other node already owns.
                    hot[i].children[k] = NO_NODE;
                } else {
                    hot[c as usize].parent = i as u32;
                }
            }
        }
        NodeView {
            nodes: hot,
            root_count,
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

/// Frustum planes a subtree may still cross: bit `k` for `Frustum::planes[k]`.
const ALL_PLANES: u8 = 0b1_1111;

/// Culled with the tight sphere grown by `growth` (frustum or normal cone). Growing only
/// ever culls less.
///
/// Plane masking: only the planes in `mask` are tested, and a plane is removed from
/// `mask` (for the node's subtree) when the node's grown saturated sphere lies strictly
/// inside it: the saturated sphere contains every descendant's tight sphere (and growing
/// both about their centres keeps that), so no descendant can be outside that plane.
/// The per-plane test is the same expression as [`crate::Frustum::sphere_outside`], so
/// results equal the unmasked test.
#[inline]
fn culled(view: &ViewParams, n: &HotNode, growth: f32, mask: &mut u8) -> bool {
    let t = n.tight_sphere;
    let rt = t[3] * growth;
    if *mask != 0 {
        let s = n.saturated_sphere;
        let rs = s[3] * growth;
        for (k, p) in view.frustum.planes.iter().enumerate() {
            let bit = 1u8 << k;
            if *mask & bit == 0 {
                continue;
            }
            if p.x * t[0] + p.y * t[1] + p.z * t[2] + p.w < -rt {
                return true;
            }
            if p.x * s[0] + p.y * s[1] + p.z * s[2] + p.w > rs {
                *mask &= !bit;
            }
        }
    }
    is_backfacing(n.normal_cone, [t[0], t[1], t[2], rt], view.eye)
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

/// Whether the view (with spheres grown by `growth`) would refine node `index`: its
/// projected saturated error exceeds the tolerance. False for an index out of range.
pub fn wants_refinement(nv: &NodeView, index: u32, view: &ViewParams, growth: f32) -> bool {
    nv.nodes
        .get(index as usize)
        .is_some_and(|n| refines(view, n, growth))
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
    let mut stack: Vec<(u32, u8)> = Vec::with_capacity(STACK_CAPACITY.max(roots as usize));
    stack.extend((0..roots).rev().map(|r| (r, ALL_PLANES)));
    while let Some((index, mut mask)) = stack.pop() {
        let n = &nodes[index as usize];
        out.visited += 1;
        if view.cull && culled(view, n, 1.0, &mut mask) {
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
                    if !(view.cull && culled(view, cn, 1.0, &mut mask.clone())) {
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
            stack.push((c1, mask));
        }
        if c0 != NO_NODE && r0 {
            stack.push((c0, mask));
        }
    }
}

/// A node waiting in a prefetch pass.
struct PrefetchEntry {
    index: u32,
    /// The exclusion view reaches the parent and refines it.
    chain: bool,
    /// The parent's saturated error (infinite for roots: top priority).
    parent_error: f32,
    /// Distance from the pass's eye to the centre of the node's saturated sphere, computed
    /// once for the priority and the refinement test.
    centre_distance: f32,
    /// Frustum planes still to test, pass view and exclusion view.
    mask: u8,
    excl_mask: u8,
}

#[inline]
fn centre_distance(eye: glam::Vec3, sphere: [f32; 4]) -> f32 {
    (glam::Vec3::new(sphere[0], sphere[1], sphere[2]) - eye).length()
}

/// One prefetch pass from `pass` with spheres grown by `growth`, appending every node it
/// reaches (not culled: drawn or refined through) except those that `excl` with spheres
/// grown by `excl_growth` reaches too. A stack entry carries whether `excl` reaches the
/// node's parent and refines it, so the exclusion costs no per-model scratch memory.
/// Closest distances are `centre_distance - radius * growth`, the same expression as
/// [`closest_distance`] on a grown sphere, so decisions match [`refines`] exactly.
fn prefetch_pass(
    nv: &NodeView,
    pass: &ViewParams,
    growth: f32,
    excl: &ViewParams,
    excl_growth: f32,
    stack: &mut Vec<PrefetchEntry>,
    out: &mut Vec<(u32, f32)>,
) -> usize {
    let nodes = &nv.nodes;
    let mut visited = 0;
    let same_eye = pass.eye == excl.eye;
    stack.clear();
    stack.extend((0..nv.root_count).rev().map(|r| PrefetchEntry {
        index: r,
        chain: true,
        parent_error: f32::INFINITY,
        centre_distance: centre_distance(pass.eye, nodes[r as usize].saturated_sphere),
        mask: ALL_PLANES,
        excl_mask: ALL_PLANES,
    }));
    while let Some(e) = stack.pop() {
        let PrefetchEntry {
            index,
            chain,
            parent_error,
            centre_distance: len,
            mut mask,
            mut excl_mask,
        } = e;
        visited += 1;
        let n = &nodes[index as usize];
        if pass.cull && culled(pass, n, growth, &mut mask) {
            continue;
        }
        let excluded = chain && !(excl.cull && culled(excl, n, excl_growth, &mut excl_mask));
        let r = n.saturated_sphere[3];
        let d = len - r * growth;
        if !excluded {
            let p = if parent_error == f32::INFINITY || d <= 0.0 {
                f32::INFINITY
            } else {
                let p = parent_error * pass.px_per_unit / d;
                if p.is_nan() {
                    0.0
                } else {
                    p
                }
            };
            out.push((index, p));
        }
        let [c0, c1] = n.children;
        if (c0 == NO_NODE && c1 == NO_NODE) || !needs_refinement(n.error, d, pass.error_scale) {
            continue;
        }
        let child_chain = excluded && {
            let excl_len = if same_eye {
                len
            } else {
                centre_distance(excl.eye, n.saturated_sphere)
            };
            needs_refinement(n.error, excl_len - r * excl_growth, excl.error_scale)
        };
        for c in [c1, c0] {
            if c != NO_NODE {
                stack.push(PrefetchEntry {
                    index: c,
                    chain: child_chain,
                    parent_error: n.error,
                    centre_distance: centre_distance(pass.eye, nodes[c as usize].saturated_sphere),
                    mask,
                    excl_mask,
                });
            }
        }
    }
    visited
}

/// The prefetch set: nodes that a slightly more demanding view would need (the view with
/// spheres grown by `opts.sphere_growth`, plus the same from `opts.predicted`), minus
/// every node the current view itself needs (what it draws and the nodes refined on the
/// way, everything assumed resident; those belong to [`select_resident`]'s `missing`).
///
/// "Needed" means reached by the traversal and not culled: drawn or refined through,
/// since a node must be resident for its children to be drawn in its place. Each node
/// appears once (the predicted pass skips what the first pass found), with the priority
/// of the pass that found it: pixels of error its parent shows over its (grown) region,
/// infinite for roots. Order: depth-first, current camera first, then predicted; not
/// sorted, so a loader can take the most urgent few with `select_nth_unstable_by` or a
/// heap without paying for a full sort. `out` is cleared first. Returns the number of
/// nodes examined (both passes): the cost.
pub fn prefetch_set(
    nv: &NodeView,
    view: &ViewParams,
    opts: &PrefetchOptions,
    out: &mut Vec<(u32, f32)>,
) -> usize {
    out.clear();
    let growth = if opts.sphere_growth.is_nan() {
        1.0
    } else {
        opts.sphere_growth.max(1.0)
    };
    let mut stack = Vec::with_capacity(STACK_CAPACITY);
    let mut visited = prefetch_pass(nv, view, growth, view, 1.0, &mut stack, out);
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
        // Excluding what the first pass reached excludes the current needs too (growth
        // only ever reaches more).
        visited += prefetch_pass(nv, &predicted, growth, view, growth, &mut stack, out);
    }
    visited
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
    if next
        .position
        .iter()
        .chain(&next.target)
        .all(|v| v.is_finite())
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
    if view.cull && culled(view, n, growth, &mut ALL_PLANES.clone()) {
        return true;
    }
    !refines(view, &nv.nodes[n.parent as usize], growth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::select::tests::{assert_covers_once, cam, header, hierarchy, node, N};
    use crate::select::{select_cut, traverse_into, Criterion, Cut, Decision};

    fn params(c: &Camera, tol: f32, cull: bool) -> ViewParams {
        ViewParams::new(c, [0.0; 3], tol, cull)
    }

    fn select(nv: &NodeView, v: &ViewParams, resident: &[u32]) -> Selection {
        let mut s = Selection::default();
        select_resident(nv, v, &|i| resident.contains(&i), &mut s);
        s
    }

    fn ids(v: &[(u32, f32)]) -> Vec<u32> {
        let mut i: Vec<u32> = v.iter().map(|e| e.0).collect();
        i.sort_unstable();
        i
    }

    /// Nodes the ideal (everything resident) traversal reaches and does not cull, with
    /// spheres as stored: drawn or refined through.
    fn needed(h: &Header, nodes: &[NodeRecord], v: &ViewParams) -> Vec<u32> {
        let mut reached = Vec::new();
        let mut cut = Cut::default();
        traverse_into(
            h,
            nodes,
            |i, n| {
                let d = v.decide(n);
                if d != Decision::Cull {
                    reached.push(i);
                }
                d
            },
            &mut cut,
        );
        reached.sort_unstable();
        reached
    }

    fn prefetch(
        nv: &NodeView,
        v: &ViewParams,
        growth: f32,
        predicted: Option<Camera>,
    ) -> Vec<(u32, f32)> {
        let mut out = vec![(99, 1.0)];
        let opts = PrefetchOptions {
            sphere_growth: growth,
            predicted,
        };
        prefetch_set(nv, v, &opts, &mut out);
        out
    }

    /// Eyes around, above, below and inside the hand-built model.
    fn eyes() -> Vec<[f64; 3]> {
        let mut e = Vec::new();
        for ix in -4..=8 {
            for iz in -3..=6 {
                e.push([f64::from(ix) * 2.5, 0.5, f64::from(iz) * 2.0 + 0.3]);
            }
        }
        for h in [10.0, 30.0, 100.0, 300.0, 1000.0] {
            e.push([7.0, 0.0, h]);
        }
        e
    }

    #[test]
    fn node_view_copies_and_sanitises() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        assert_eq!((nv.len(), nv.root_count(), nv.is_empty()), (9, 2, false));
        let n = &nv.nodes()[2];
        assert_eq!(n.children, [5, 6]);
        assert_eq!(n.parent, 0);
        assert_eq!(n.error, 2.0);
        assert_eq!(n.saturated_sphere, nodes[2].saturated_sphere);
        assert_eq!(nv.nodes()[4].parent, 1);
        assert_eq!(nv.nodes()[1].children, [4, N]);
        assert_eq!(nv.nodes()[0].parent, N);
        // Corrupt links are dropped: out of range, backwards, self.
        let bad = vec![
            node(0, [1, 7], 5.0, [0.0; 3], 1.0, 1),
            node(1, [0, 1], 5.0, [0.0; 3], 1.0, 2),
        ];
        let nv = NodeView::new(&header(1), &bad);
        assert_eq!(nv.nodes()[0].children, [1, N]);
        assert_eq!(nv.nodes()[1].children, [N, N]);
        assert_eq!(nv.nodes()[1].parent, 0);
        // More roots than records: node 1 is a root, so no longer node 0's child.
        let nv = NodeView::new(&header(5), &bad);
        assert_eq!(nv.root_count(), 2);
        assert_eq!(nv.nodes()[0].children, [N, N]);
        // Two parents claiming one child: the first keeps it.
        let shared = vec![
            node(0, [1, 2], 5.0, [0.0; 3], 1.0, 1),
            node(1, [2, N], 5.0, [0.0; 3], 1.0, 1),
            node(1, [N, N], 0.0, [0.0; 3], 1.0, 1),
        ];
        let nv = NodeView::new(&header(1), &shared);
        assert_eq!(nv.nodes()[1].children, [N, N]);
        assert_eq!(nv.nodes()[2].parent, 0);
        let far = cam([0.0, 0.0, 100.0], [0.0; 3], 60.0, 100);
        let s = select(&nv, &params(&far, 0.0, false), &[0, 1, 2]);
        assert_eq!(s.draw, vec![1, 2]);
        assert!(NodeView::new(&header(1), &[]).is_empty());
    }

    #[test]
    fn everything_resident_gives_select_cut() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        let mut s = Selection::default();
        for eye in eyes() {
            for target in [[eye[0] + 1.0, 0.0, 0.0], [4.0, 0.0, 0.0]] {
                let Ok(c) = Camera::new(eye, target, [0.0, 1.0, 0.0], 60.0, 500, 500) else {
                    continue;
                };
                for tol in [0.5, 2.0, 10.0, 100.0] {
                    for cull in [false, true] {
                        let v = params(&c, tol, cull);
                        select_resident(&nv, &v, &|_| true, &mut s);
                        let crit = Criterion::View {
                            camera: c.clone(),
                            tolerance_px: tol,
                            cull,
                        };
                        let cut = select_cut(&h, &nodes, &crit);
                        assert_eq!(s.draw, cut.nodes, "eye {eye:?} tol {tol} cull {cull}");
                        assert!(s.missing.is_empty());
                        if !cull {
                            assert_covers_once(&h, &nodes, &s.draw);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn missing_children_keep_the_parent_drawn_with_priorities() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        // 1000 above x = 7: 866 px per unit at distance 1; tolerance 2 refines both roots'
        // A into its diamond (3.5 px), tolerance 0.8 refines everything to the leaves.
        let far = cam([7.0, 0.0, 1000.0], [7.0, 0.0, 0.0], 60.0, 1000);
        let v = params(&far, 2.0, true);
        let s = select(&nv, &v, &[0, 1]);
        assert_eq!(s.draw, vec![0, 1]);
        assert_eq!(ids(&s.missing), vec![2, 3]);
        // Priority: root A's error 4 projected at each child's saturated sphere.
        let scale = far.projection_scale_px() as f32;
        for &(c, p) in &s.missing {
            let sphere = nodes[c as usize].saturated_sphere;
            let d = closest_distance(v.eye, sphere);
            assert!((p - 4.0 * scale / d).abs() < 1e-3, "{c}: {p}");
            assert!(p > 3.0 && p < 3.6, "{c}: {p}");
        }
        let p = |i: u32| s.missing.iter().find(|e| e.0 == i).unwrap().1;
        assert!(p(3) > p(2), "node 3 is nearer the eye");
        // Once resident, the children are drawn.
        let s = select(&nv, &v, &[0, 1, 2, 3]);
        assert_eq!((s.draw, s.missing), (vec![2, 3, 1], vec![]));

        let v = params(&far, 0.8, true);
        let s = select(&nv, &v, &[0, 1, 2, 3, 4]);
        assert_eq!(s.draw, vec![2, 3, 4]);
        assert_eq!(ids(&s.missing), vec![5, 6, 7, 8]);
        // One leaf of a pair missing: its sibling is not drawn either (no mixed levels
        // under one parent).
        let s = select(&nv, &v, &[0, 1, 2, 3, 4, 5, 6, 8]);
        assert_eq!(s.draw, vec![5, 6, 3, 4]);
        assert_eq!(ids(&s.missing), vec![7]);
        let all: Vec<u32> = (0..9).collect();
        let s = select(&nv, &v, &all);
        assert_eq!((s.draw, s.missing), (vec![5, 6, 7, 8, 4], vec![]));
        // A missing node's own subtree is not visited.
        let s = select(&nv, &v, &[0, 1, 4, 5, 6, 7, 8]);
        assert_eq!(s.draw, vec![0, 4]);
        assert_eq!(ids(&s.missing), vec![2, 3]);
        assert_eq!(s.visited, 3);
    }

    #[test]
    fn missing_roots_draw_nothing_and_culled_nodes_are_not_missing() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        let far = cam([7.0, 0.0, 1000.0], [7.0, 0.0, 0.0], 60.0, 1000);
        let s = select(&nv, &params(&far, 0.8, true), &[0, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(s.draw, vec![5, 6, 7, 8]);
        assert_eq!(s.missing, vec![(1, f32::INFINITY)]);
        // Narrow view of x near 1: node 3 and root B are culled, so they are not asked
        // for even though they are not resident.
        let narrow = cam([1.0, 0.0, 5.0], [1.0, 0.0, 0.0], 20.0, 1000);
        let v = params(&narrow, 0.5, true);
        let s = select(&nv, &v, &[0]);
        assert_eq!(s.draw, vec![0]);
        assert_eq!(ids(&s.missing), vec![2]);
        // With 2 resident and 3 still missing but culled, node 0 refines.
        let s = select(&nv, &v, &[0, 2]);
        assert_eq!(s.draw, vec![2]);
        assert_eq!(ids(&s.missing), vec![5, 6]);
        // Without culling node 3 is needed.
        let s = select(&nv, &params(&narrow, 0.5, false), &[0, 1, 2]);
        assert_eq!(s.draw, vec![0, 1]);
        assert_eq!(ids(&s.missing), vec![3, 4]);
    }

    #[test]
    fn drawn_nodes_are_resident_and_missing_are_needed() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        for eye in eyes() {
            let Ok(c) = Camera::new(eye, [4.0, 0.0, 0.0], [0.0, 1.0, 0.0], 60.0, 500, 500) else {
                continue;
            };
            for tol in [0.5, 5.0, 50.0] {
                for cull in [false, true] {
                    let v = params(&c, tol, cull);
                    let need = needed(&h, &nodes, &v);
                    // Every subset of resident nodes (9 nodes: 512 subsets).
                    for mask in 0u32..512 {
                        let res = |i: u32| mask & (1 << i) != 0;
                        let mut s = Selection::default();
                        select_resident(&nv, &v, &res, &mut s);
                        for &d in &s.draw {
                            assert!(res(d) && need.contains(&d));
                        }
                        for &(m, p) in &s.missing {
                            assert!(!res(m) && need.contains(&m) && p >= 0.0);
                        }
                        if !cull && s.missing.is_empty() {
                            assert_covers_once(&h, &nodes, &s.draw);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn predicted_camera_extrapolates_linearly() {
        let up = [0.0, 1.0, 0.0];
        let prev = Camera::new([0.0, 0.0, 10.0], [0.0; 3], up, 60.0, 640, 480).unwrap();
        let cur = Camera::new([1.0, 0.0, 9.0], [1.0, 0.5, 0.0], up, 50.0, 800, 600).unwrap();
        let p = predict_camera(&prev, &cur, 0.1, 0.2);
        assert_eq!(p.position, [3.0, 0.0, 7.0]);
        assert_eq!(p.target, [3.0, 1.5, 0.0]);
        assert_eq!((p.fov_y_deg, p.width, p.height), (50.0, 800, 600));
        assert_eq!(predict_camera(&prev, &cur, 0.1, 0.0), cur);
        assert_eq!(predict_camera(&cur, &cur, 0.1, 5.0), cur, "standing still");
        for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(predict_camera(&prev, &cur, dt, 0.2), cur);
        }
        // Position and target converging: the extrapolation where they meet is refused.
        let a = Camera::new([0.0, 0.0, 2.0], [0.0; 3], up, 60.0, 64, 64).unwrap();
        let b = Camera::new([0.0, 0.0, 1.0], [0.0; 3], up, 60.0, 64, 64).unwrap();
        assert_eq!(predict_camera(&a, &b, 1.0, 1.0), b);
    }

    #[test]
    fn prefetch_covers_a_nearby_view_and_excludes_the_current_one() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        let target = [4.0, 0.0, 0.0];
        let mut covered_something = false;
        for eye in eyes() {
            let Ok(c) = Camera::new(eye, target, [0.0, 1.0, 0.0], 60.0, 500, 500) else {
                continue;
            };
            for tol in [0.5, 5.0, 50.0, 500.0] {
                let v = params(&c, tol, false);
                let cur = needed(&h, &nodes, &v);
                let pre = prefetch(&nv, &v, 1.5, None);
                let set = ids(&pre);
                // Deduplicated, disjoint from the current needs.
                assert!(set.windows(2).all(|w| w[0] < w[1]));
                assert_eq!(set.len(), pre.len());
                assert!(set.iter().all(|i| !cur.contains(i)), "{set:?} {cur:?}");
                // Every saturated sphere has radius >= 1, so growing by 1.5 brings each
                // at least 0.5 closer: any eye moved by up to 0.5 needs nothing more
                // (culling off: sphere growth says nothing about frustum rotation).
                for d in [
                    [0.5, 0.0, 0.0],
                    [-0.3, 0.0, -0.4],
                    [0.0, 0.0, -0.5],
                    [0.0, 0.5, 0.0],
                ] {
                    let moved = [eye[0] + d[0], eye[1] + d[1], eye[2] + d[2]];
                    let Ok(m) = Camera::new(moved, target, [0.0, 1.0, 0.0], 60.0, 500, 500) else {
                        continue;
                    };
                    for n in needed(&h, &nodes, &params(&m, tol, false)) {
                        if !cur.contains(&n) {
                            assert!(set.contains(&n), "eye {eye:?} moved {d:?} tol {tol}: {n}");
                            covered_something = true;
                        }
                    }
                }
                // Growth 1 adds nothing.
                assert!(prefetch(&nv, &v, 1.0, None).is_empty());
            }
        }
        assert!(covered_something);
        // A concrete case: 1000 above, tolerance 1.74 px: the diamond (1.736 px) just
        // passes, so its leaves are not needed; grown enough, it refines and they are
        // prefetched.
        let far = cam([7.0, 0.0, 1000.0], [7.0, 0.0, 0.0], 60.0, 1000);
        let v = params(&far, 1.74, true);
        assert_eq!(needed(&h, &nodes, &v), vec![0, 1, 2, 3]);
        let pre = prefetch(&nv, &v, 1.5, None);
        assert!(
            pre.is_empty(),
            "1.5 x 2.3 is nothing at 1000 units: {pre:?}"
        );
        let pre = prefetch(&nv, &v, 20.0, None);
        assert_eq!(ids(&pre), vec![5, 6, 7, 8]);
    }

    #[test]
    fn prefetch_includes_what_the_predicted_camera_needs() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        let up = [0.0, 1.0, 0.0];
        // Flying towards the model and to the right along x, looking down.
        let prev = Camera::new([-6.0, 0.0, 40.0], [-6.0, 0.0, 0.0], up, 40.0, 500, 500).unwrap();
        let cur = Camera::new([-2.0, 0.0, 30.0], [-2.0, 0.0, 0.0], up, 40.0, 500, 500).unwrap();
        let next = predict_camera(&prev, &cur, 1.0 / 30.0, 2.0 / 30.0);
        assert_eq!(next.position, [6.0, 0.0, 10.0]);
        for cull in [false, true] {
            for tol in [1.0, 10.0, 30.0, 100.0] {
                let v = params(&cur, tol, cull);
                let cur_need = needed(&h, &nodes, &v);
                let next_need = needed(&h, &nodes, &params(&next, tol, cull));
                let set = ids(&prefetch(&nv, &v, 1.0, Some(next.clone())));
                let expect: Vec<u32> = next_need
                    .iter()
                    .copied()
                    .filter(|n| !cur_need.contains(n))
                    .collect();
                assert_eq!(set, expect, "cull {cull} tol {tol}");
                let grown_pre = prefetch(&nv, &v, 1.5, Some(next.clone()));
                assert_eq!(ids(&grown_pre).len(), grown_pre.len(), "deduplicated");
                // Growth adds to it, never removes.
                let grown = ids(&prefetch(&nv, &v, 1.5, Some(next.clone())));
                assert!(set.iter().all(|n| grown.contains(n)));
            }
        }
        // The looking-down camera at x = -2 (sees x < 8.9) culls root B; the predicted
        // one above x = 6 (sees x < 9.6) sees it: so it is prefetched with infinite priority.
        let v = params(&cur, 30.0, true);
        assert!(!needed(&h, &nodes, &v).contains(&1));
        let pre = prefetch(&nv, &v, 1.0, Some(next));
        assert!(pre.contains(&(1, f32::INFINITY)), "{pre:?}");
    }

    #[test]
    fn unload_thresholds_nest_with_prefetch_and_current_needs() {
        let (h, nodes) = hierarchy();
        let nv = NodeView::new(&h, &nodes);
        let mut kept_in_band = false;
        let mut unloaded = false;
        for eye in eyes() {
            for target in [[4.0, 0.0, 0.0], [eye[0] + 1.0, 0.0, 0.0]] {
                let Ok(c) = Camera::new(eye, target, [0.0, 1.0, 0.0], 60.0, 500, 500) else {
                    continue;
                };
                for tol in [0.5, 5.0, 50.0, 500.0] {
                    for cull in [false, true] {
                        let v = params(&c, tol, cull);
                        let cur = needed(&h, &nodes, &v);
                        let pre = ids(&prefetch(&nv, &v, 1.5, None));
                        for i in 0..9u32 {
                            let unload = should_unload(&nv, i, &v, 2.0);
                            if cur.contains(&i) || pre.contains(&i) {
                                assert!(!unload, "eye {eye:?} tol {tol} cull {cull}: {i}");
                            } else if unload {
                                unloaded = true;
                            } else {
                                kept_in_band = true;
                            }
                            // Bigger growth never unloads more.
                            if should_unload(&nv, i, &v, 3.0) {
                                assert!(unload);
                            }
                        }
                    }
                }
            }
        }
        assert!(unloaded && kept_in_band);
        // Concretely: leaf 7 under node 3 (error 2, saturated radius 2.3), looking down
        // from above x = 6 at tolerance 10 px (86.6 px per unit at distance 1): node 3
        // refines when 17.3 > closest distance, i.e. the eye below 19.6; grown by 1.5
        // (2.0) below 20.8 (21.9).
        let at = |z: f64| params(&cam([6.0, 0.0, z], [6.0, 0.0, 0.0], 60.0, 100), 10.0, true);
        let v = at(19.0);
        assert!(needed(&h, &nodes, &v).contains(&7));
        assert!(!should_unload(&nv, 7, &v, 2.0));
        let v = at(20.5);
        assert!(!needed(&h, &nodes, &v).contains(&7));
        assert!(ids(&prefetch(&nv, &v, 1.5, None)).contains(&7));
        assert!(!should_unload(&nv, 7, &v, 2.0));
        let v = at(21.5);
        assert!(!ids(&prefetch(&nv, &v, 1.5, None)).contains(&7));
        assert!(!should_unload(&nv, 7, &v, 2.0), "hysteresis band: kept");
        assert!(should_unload(&nv, 7, &v, 1.5));
        let v = at(23.0);
        assert!(should_unload(&nv, 7, &v, 2.0));
        // Roots stay; out-of-range indices go.
        let behind = params(
            &cam([7.0, 0.0, -1000.0], [7.0, 0.0, 0.0], 60.0, 100),
            1.0,
            true,
        );
        assert!(!should_unload(&nv, 0, &behind, 2.0));
        assert!(should_unload(&nv, 2, &behind, 2.0), "backfacing");
        assert!(should_unload(&nv, 99, &v, 2.0));
    }
}
