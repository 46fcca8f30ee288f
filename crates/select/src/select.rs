//! Cut selection: the stateless top-down traversal of ATP section 4.
//!
//! Why it exists: every consumer of a model (renderer, prefetcher, headless renderer,
//! image-repository builder, browser) decides which patches to draw the same way. Each
//! node is tested in order: (1) if culling is on, a node whose tight sphere is outside the
//! view frustum, or whose normal cone shows the whole patch facing away from the eye, is
//! dropped with its whole branch; (2) otherwise the node is selected when its saturated
//! error is small enough (or it has no children), else its existing children are visited.
//!
//! Saturated errors are equal inside a diamond and never grow toward the leaves, and
//! saturated spheres are nested, so the refinement decision is monotone (a child never
//! needs refinement when its parent does not) and the cut is conforming by construction;
//! no neighbour finding is needed.
//!
//! Speed: the traversal allocates only its small explicit stack and the output; the
//! per-camera constants (local eye, frustum planes, pixels per unit over tolerance) are
//! computed once in [`ViewParams::new`]; per node the refinement test is one subtraction,
//! one square root and one multiply-compare.
//!
//! Robustness: node tables come from disk. Child indices that are out of range, or not
//! greater than their parent's index (the table is ordered by level, so a real child
//! always comes after its parent), are treated as absent: a corrupt table cannot make the
//! traversal panic or loop.

use glam::Vec3;
use tessera_format::{Header, NodeRecord, NO_NODE};

use crate::camera::{Camera, Frustum};

/// Initial stack capacity: depth-first with both children pushed needs at most
/// (depth + roots) entries; 256 covers any forest a 64-bit `tet_path` can describe, so the
/// stack is allocated once per call and never grows in practice.
const STACK_CAPACITY: usize = 256;

/// How to choose the cut.
#[derive(Clone, Debug, PartialEq)]
pub enum Criterion {
    /// View-independent: select a node when its saturated model-space error is at most
    /// `max_error` (model units).
    MaxError {
        /// Largest acceptable saturated error, model units.
        max_error: f32,
    },
    /// View-dependent: select a node when its projected saturated error is at most
    /// `tolerance_px` pixels; with `cull`, drop branches outside the frustum or entirely
    /// backfacing.
    View {
        /// The camera, model coordinates.
        camera: Camera,
        /// Largest acceptable screen-space error, pixels of the camera's image height.
        tolerance_px: f32,
        /// Apply frustum and backface culling.
        cull: bool,
    },
}

/// The result of a selection.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Cut {
    /// Selected node indices, in depth-first order (roots in table order, first child
    /// before second).
    pub nodes: Vec<u32>,
    /// Sum of the selected nodes' `triangle_count`.
    pub triangles: u64,
    /// Nodes examined (selected, refined or culled): the traversal's cost.
    pub visited: usize,
}

/// A per-node decision of a traversal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Drop the node and its whole branch.
    Cull,
    /// Put the node in the cut.
    Select,
    /// Visit its existing children instead (a node with no children is selected).
    Refine,
}

/// The refinement test of ATP section 4, once the closest point of the saturated sphere
/// is known: refine when `error * error_scale > closest_distance`, where
/// `error_scale = (height_px / (2 tan(fov_y / 2))) / tolerance_px`; this is
/// `projected_error_px > tolerance_px` with the division multiplied out. A non-positive
/// `closest_distance` (eye inside the saturated sphere) always refines. An error of 0
/// never refines, even with an infinite `error_scale` (tolerance 0). NaN inputs do not
/// refine (the node is selected), so a broken camera cannot make the cut explode.
#[inline]
pub fn needs_refinement(error: f32, closest_distance: f32, error_scale: f32) -> bool {
    closest_distance <= 0.0 || (error > 0.0 && error * error_scale > closest_distance)
}

/// Distance from `eye` to the closest point of `sphere` (`[cx, cy, cz, r]`); negative or
/// zero when the eye is inside.
#[inline]
pub fn closest_distance(eye: Vec3, sphere: [f32; 4]) -> f32 {
    let d = Vec3::new(sphere[0], sphere[1], sphere[2]) - eye;
    d.length() - sphere[3]
}

/// True when every triangle of a patch bounded by `sphere` (`[cx, cy, cz, r]`) with
/// normals inside `cone` (`[axis xyz, cos half-angle]`) faces away from `eye`.
///
/// Standard cone test, conservative for the sphere: the patch is backfacing when the
/// angle between the axis and the direction from the sphere centre to the eye exceeds
/// `90 deg + half_angle + asin(r / D)` (`D` the centre-eye distance; the last term bounds
/// how much that direction can turn over the sphere). Written without trigonometry:
/// with `s = sin(half_angle)`, `c = cos(half_angle)`, `t = sqrt(D^2 - r^2)`, the total
/// angle `half_angle + asin(r/D)` must stay below 90 deg (`c t - s r > 0`), and then
/// `axis . (eye - centre) < -(s t + c r)`. A cone with cos = -1 never culls, nor does an
/// eye inside the sphere.
#[inline]
pub fn is_backfacing(cone: [f32; 4], sphere: [f32; 4], eye: Vec3) -> bool {
    let c = cone[3];
    if c.is_nan() || c <= -1.0 {
        return false;
    }
    let axis = Vec3::new(cone[0], cone[1], cone[2]);
    let to_eye = eye - Vec3::new(sphere[0], sphere[1], sphere[2]);
    let r = sphere[3];
    let d2 = to_eye.length_squared();
    let t2 = d2 - r * r;
    if t2.is_nan() || t2 <= 0.0 {
        return false;
    }
    let t = t2.sqrt();
    let s = (1.0 - c * c).max(0.0).sqrt();
    c * t - s * r > 0.0 && axis.dot(to_eye) < -(s * t + c * r)
}

/// Per-camera constants of the view criterion, computed once per frame in the model's
/// local frame. Also usable on its own (prefetch with a predicted camera, morph ratios).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewParams {
    /// The eye, local frame.
    pub eye: Vec3,
    /// The frustum, local frame.
    pub frustum: Frustum,
    /// `projection_scale_px / tolerance_px`: multiply a model-space error by it and
    /// compare with a distance (see [`needs_refinement`]). Infinite for tolerance <= 0.
    pub error_scale: f32,
    /// `projection_scale_px`: pixels covered by one model unit at distance one, so a
    /// model-space error `e` at distance `d` projects to `e * px_per_unit / d` pixels
    /// (priorities of the residency-aware traversal, [`crate::residency`]).
    pub px_per_unit: f32,
    /// Whether [`ViewParams::decide`] culls.
    pub cull: bool,
}

impl ViewParams {
    /// Precomputes the constants (in f64, relative to `cube_origin`, then f32).
    pub fn new(camera: &Camera, cube_origin: [f64; 3], tolerance_px: f32, cull: bool) -> Self {
        let scale = camera.projection_scale_px();
        let error_scale = if tolerance_px > 0.0 {
            (scale / f64::from(tolerance_px)) as f32
        } else {
            f32::INFINITY
        };
        ViewParams {
            eye: camera.eye_local(cube_origin),
            frustum: camera.frustum_local(cube_origin),
            error_scale,
            px_per_unit: scale as f32,
            cull,
        }
    }

    /// Outside the frustum (tight sphere) or entirely backfacing (normal cone).
    #[inline]
    pub fn is_culled(&self, node: &NodeRecord) -> bool {
        let s = node.tight_sphere;
        self.frustum
            .sphere_outside(Vec3::new(s[0], s[1], s[2]), s[3])
            || is_backfacing(node.normal_cone, s, self.eye)
    }

    /// The projected saturated error exceeds the tolerance.
    #[inline]
    pub fn needs_refinement(&self, node: &NodeRecord) -> bool {
        needs_refinement(
            node.error,
            closest_distance(self.eye, node.saturated_sphere),
            self.error_scale,
        )
    }

    /// The full per-node decision of the view criterion.
    #[inline]
    pub fn decide(&self, node: &NodeRecord) -> Decision {
        if self.cull && self.is_culled(node) {
            Decision::Cull
        } else if self.needs_refinement(node) {
            Decision::Refine
        } else {
            Decision::Select
        }
    }
}

/// A child index worth following (see the module doc on robustness).
#[inline]
fn valid_child(child: u32, parent: u32, len: usize) -> bool {
    child != NO_NODE && child > parent && (child as usize) < len
}

/// True when the node has no child that the traversal would follow.
#[inline]
pub fn is_leaf(index: u32, nodes: &[NodeRecord]) -> bool {
    match nodes.get(index as usize) {
        Some(n) => !n
            .children
            .iter()
            .any(|&c| valid_child(c, index, nodes.len())),
        None => true,
    }
}

/// The generic top-down traversal: starting from the first `header.root_count` records,
/// asks `decide` about each node and fills `cut` (cleared first; its allocations are
/// reused). [`select_cut`] is this with the criterion's decision plugged in.
pub fn traverse_into(
    header: &Header,
    nodes: &[NodeRecord],
    mut decide: impl FnMut(u32, &NodeRecord) -> Decision,
    cut: &mut Cut,
) {
    cut.nodes.clear();
    cut.triangles = 0;
    cut.visited = 0;
    let len = nodes.len();
    let roots = (header.root_count as usize).min(len);
    let mut stack: Vec<u32> = Vec::with_capacity(STACK_CAPACITY.max(roots));
    // Pushed in reverse so roots pop in table order.
    stack.extend((0..roots as u32).rev());
    while let Some(index) = stack.pop() {
        let node = &nodes[index as usize];
        cut.visited += 1;
        let decision = decide(index, node);
        if decision == Decision::Cull {
            continue;
        }
        let [c0, c1] = node.children;
        let (v0, v1) = (valid_child(c0, index, len), valid_child(c1, index, len));
        if decision == Decision::Select || !(v0 || v1) {
            cut.nodes.push(index);
            cut.triangles += u64::from(node.triangle_count);
            continue;
        }
        // Second child first, so the first child's subtree is emitted first.
        if v1 {
            stack.push(c1);
        }
        if v0 {
            stack.push(c0);
        }
    }
}

/// Selects a cut of the forest for `criterion`. See [`select_cut_into`] to reuse the
/// output allocation across frames.
pub fn select_cut(header: &Header, nodes: &[NodeRecord], criterion: &Criterion) -> Cut {
    let mut cut = Cut::default();
    select_cut_into(header, nodes, criterion, &mut cut);
    cut
}

/// [`select_cut`] writing into an existing [`Cut`] (cleared first).
pub fn select_cut_into(
    header: &Header,
    nodes: &[NodeRecord],
    criterion: &Criterion,
    cut: &mut Cut,
) {
    match criterion {
        Criterion::MaxError { max_error } => {
            let max_error = *max_error;
            traverse_into(
                header,
                nodes,
                |_, n| {
                    if n.error <= max_error {
                        Decision::Select
                    } else {
                        Decision::Refine
                    }
                },
                cut,
            );
        }
        Criterion::View {
            camera,
            tolerance_px,
            cull,
        } => {
            let params = ViewParams::new(camera, header.cube_origin, *tolerance_px, *cull);
            traverse_into(header, nodes, |_, n| params.decide(n), cut);
        }
    }
    tracing::trace!(
        selected = cut.nodes.len(),
        triangles = cut.triangles,
        visited = cut.visited,
        "cut selected"
    );
}

/// Every node at `level`, plus the leaves above it (nodes at a smaller level with no
/// children), in table order: the uniform cut used by tests that extract every level.
/// Relies on the `level` field, not on the roots of a header.
pub fn uniform_level_cut(nodes: &[NodeRecord], level: u8) -> Vec<u32> {
    (0..nodes.len() as u32)
        .filter(|&i| {
            let n = &nodes[i as usize];
            n.level == level || (n.level < level && is_leaf(i, nodes))
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use bytemuck::Zeroable;

    pub(crate) fn header(root_count: u32) -> Header {
        let mut h = Header::zeroed();
        h.root_count = root_count;
        h
    }

    pub(crate) fn node(
        level: u8,
        children: [u32; 2],
        error: f32,
        c: [f32; 3],
        r: f32,
        tris: u32,
    ) -> NodeRecord {
        NodeRecord {
            children,
            level,
            error,
            tight_sphere: [c[0], c[1], c[2], r],
            saturated_sphere: [c[0], c[1], c[2], r],
            // Every patch lies in the plane z = 0 facing +z, within 25 degrees.
            normal_cone: [0.0, 0.0, 1.0, 0.9],
            triangle_count: tris,
            ..NodeRecord::default()
        }
    }

    pub(crate) const N: u32 = NO_NODE;

    /// Two roots along the x axis, in the plane z = 0.
    /// Root A (0) spans x in [0, 8]: children 2 and 3 (a diamond, error 2), each with two
    /// leaf children 5, 6 and 7, 8. Root B (1) spans x in [10, 14], error 1, with one
    /// existing child (4, a leaf): the other child tetrahedron held no triangles.
    /// Saturated spheres are nested; the tight spheres equal them.
    pub(crate) fn hierarchy() -> (Header, Vec<NodeRecord>) {
        let nodes = vec![
            node(0, [2, 3], 4.0, [4.0, 0.0, 0.0], 4.5, 1000),
            node(0, [4, N], 1.0, [12.0, 0.0, 0.0], 2.5, 2000),
            node(1, [5, 6], 2.0, [2.0, 0.0, 0.0], 2.3, 100),
            node(1, [7, 8], 2.0, [6.0, 0.0, 0.0], 2.3, 200),
            node(1, [N, N], 0.0, [11.0, 0.0, 0.0], 1.0, 300),
            node(2, [N, N], 0.0, [1.0, 0.0, 0.0], 1.2, 10),
            node(2, [N, N], 0.0, [3.0, 0.0, 0.0], 1.2, 20),
            node(2, [N, N], 0.0, [5.0, 0.0, 0.0], 1.2, 30),
            node(2, [N, N], 0.0, [7.0, 0.0, 0.0], 1.2, 40),
        ];
        (header(2), nodes)
    }

    pub(crate) fn cam(position: [f64; 3], target: [f64; 3], fov_y_deg: f64, height: u32) -> Camera {
        Camera::new(position, target, [0.0, 1.0, 0.0], fov_y_deg, height, height).unwrap()
    }

    fn sorted(mut v: Vec<u32>) -> Vec<u32> {
        v.sort_unstable();
        v
    }

    fn view(camera: Camera, tolerance_px: f32, cull: bool) -> Criterion {
        Criterion::View {
            camera,
            tolerance_px,
            cull,
        }
    }

    #[test]
    fn max_error_cuts_at_each_level() {
        let (h, nodes) = hierarchy();
        let cut = |e: f32| select_cut(&h, &nodes, &Criterion::MaxError { max_error: e });
        let c = cut(4.0);
        assert_eq!(c.nodes, vec![0, 1]);
        assert_eq!((c.triangles, c.visited), (3000, 2));
        // Between the levels: A refines to its diamond, B (error 1) stays.
        let c = cut(2.0);
        assert_eq!(c.nodes, vec![2, 3, 1]);
        assert_eq!(c.triangles, 2300);
        let c = cut(0.5);
        assert_eq!(c.nodes, vec![5, 6, 7, 8, 4]);
        assert_eq!((c.triangles, c.visited), (400, 9));
        assert_eq!(cut(0.0).nodes, vec![5, 6, 7, 8, 4]);
        // A negative or NaN bound still terminates at the leaves.
        assert_eq!(cut(-1.0).nodes, vec![5, 6, 7, 8, 4]);
        assert_eq!(cut(f32::NAN).nodes, vec![5, 6, 7, 8, 4]);
    }

    #[test]
    fn uniform_levels_include_leaves_above() {
        let (_, nodes) = hierarchy();
        assert_eq!(uniform_level_cut(&nodes, 0), vec![0, 1]);
        assert_eq!(uniform_level_cut(&nodes, 1), vec![2, 3, 4]);
        assert_eq!(uniform_level_cut(&nodes, 2), vec![4, 5, 6, 7, 8]);
        assert_eq!(uniform_level_cut(&nodes, 9), vec![4, 5, 6, 7, 8]);
    }

    #[test]
    fn needs_refinement_decision_table() {
        // error 1, scale 100: projected 100/d px over tolerance 1 px <=> 100 > d.
        assert!(needs_refinement(1.0, 50.0, 100.0));
        assert!(!needs_refinement(1.0, 150.0, 100.0));
        assert!(
            !needs_refinement(1.0, 100.0, 100.0),
            "equal to the tolerance is enough"
        );
        // Eye inside or on the saturated sphere: always refine.
        assert!(needs_refinement(0.0, 0.0, 100.0));
        assert!(needs_refinement(1.0, -3.0, 100.0));
        // Zero error never refines from outside, even at tolerance 0 (infinite scale).
        assert!(!needs_refinement(0.0, 1.0, f32::INFINITY));
        assert!(needs_refinement(1e-6, 1e6, f32::INFINITY));
        // NaN selects rather than refining forever.
        assert!(!needs_refinement(f32::NAN, 1.0, 100.0));
        assert!(!needs_refinement(1.0, f32::NAN, 100.0));
    }

    #[test]
    fn projected_error_matches_the_formula() {
        // fov 90, height 200: 100 px per unit at distance 1. A sphere of radius 1 at
        // distance 11 has its closest point at 10; error 0.5 projects to 5 px.
        let c = cam([0.0, 0.0, 11.0], [0.0; 3], 90.0, 200);
        let mut n = node(0, [N, N], 0.5, [0.0; 3], 1.0, 1);
        let p = |tol: f32| ViewParams::new(&c, [0.0; 3], tol, false);
        assert!(p(4.9).needs_refinement(&n));
        assert!(!p(5.1).needs_refinement(&n));
        // The cube origin is subtracted: the same node 1000 units away in model space.
        n.saturated_sphere = [0.0, 0.0, -1000.0, 1.0];
        let far = ViewParams::new(&c, [0.0, 0.0, 1000.0], 4.9, false);
        assert!(far.needs_refinement(&n));
        assert!(!ViewParams::new(&c, [0.0; 3], 4.9, false).needs_refinement(&n));
    }

    #[test]
    fn backface_cone_test() {
        let up = [0.0, 0.0, 1.0, 0.9]; // facing +z within ~25.8 deg
        let s = [0.0, 0.0, 0.0, 1.0];
        assert!(
            !is_backfacing(up, s, Vec3::new(0.0, 0.0, 100.0)),
            "seen from the front"
        );
        assert!(
            is_backfacing(up, s, Vec3::new(0.0, 0.0, -100.0)),
            "seen from behind"
        );
        // From the side, just below the plane: within 90 + 25.8 deg of the axis.
        assert!(!is_backfacing(up, s, Vec3::new(100.0, 0.0, -10.0)));
        // 90 + 25.8 + asin(1/100) ~ 116.4 deg is the limit: 120 deg culls, 113 does not.
        let at = |deg: f32| {
            let a = deg.to_radians();
            Vec3::new(100.0 * a.sin(), 0.0, 100.0 * a.cos())
        };
        assert!(is_backfacing(up, s, at(120.0)));
        assert!(!is_backfacing(up, s, at(113.0)));
        // A big sphere widens the margin: asin(30/100) ~ 17.5 deg more.
        assert!(!is_backfacing(up, [0.0, 0.0, 0.0, 30.0], at(120.0)));
        assert!(is_backfacing(up, [0.0, 0.0, 0.0, 30.0], at(140.0)));
        // Eye inside the sphere, or a cone that allows every direction: never culled.
        assert!(!is_backfacing(
            up,
            [0.0, 0.0, -100.0, 200.0],
            Vec3::new(0.0, 0.0, -100.0)
        ));
        assert!(!is_backfacing(
            [0.0, 0.0, 0.0, -1.0],
            s,
            Vec3::new(0.0, 0.0, -100.0)
        ));
        // A half-angle of 90 deg or more never culls.
        assert!(!is_backfacing(
            [0.0, 0.0, 1.0, 0.0],
            s,
            Vec3::new(0.0, 0.0, -100.0)
        ));
        // A flat patch (half-angle 0) seen from just behind its plane is culled.
        assert!(is_backfacing(
            [0.0, 0.0, 1.0, 1.0],
            [0.0; 4],
            Vec3::new(100.0, 0.0, -1.0)
        ));
    }

    #[test]
    fn far_camera_keeps_roots_near_camera_refines() {
        let (h, nodes) = hierarchy();
        // 1000 units above the middle, fov 60, 1000 px: 866 px per unit at distance 1.
        // Root A: 4 * 866 / ~995.5 = 3.5 px; level 1: 1.7 px.
        let far = cam([7.0, 0.0, 1000.0], [7.0, 0.0, 0.0], 60.0, 1000);
        let sel = |c: &Camera, tol: f32, cull: bool| {
            select_cut(&h, &nodes, &view(c.clone(), tol, cull)).nodes
        };
        assert_eq!(sel(&far, 5.0, true), vec![0, 1]);
        assert_eq!(sel(&far, 2.0, true), vec![2, 3, 1]);
        // Level 1 is 1.7 px; root B (error 1) is 0.87 px, still fine at 1 px.
        assert_eq!(sel(&far, 1.0, true), vec![5, 6, 7, 8, 1]);
        assert_eq!(sel(&far, 0.8, true), vec![5, 6, 7, 8, 4]);
        // Close above the middle: everything refines to the leaves at 5 px.
        let near = cam([7.0, 0.0, 3.0], [7.0, 0.0, 0.0], 60.0, 1000);
        assert_eq!(sorted(sel(&near, 5.0, false)), vec![4, 5, 6, 7, 8]);
    }

    #[test]
    fn grazing_camera_refines_only_the_near_side() {
        let (h, nodes) = hierarchy();
        // Eye left of everything, looking along +x: node 2 is ~4.8 units away (36 px),
        // node 3 ~8.8 (20 px), root B ~14.5 (6 px); tolerance 25 px.
        let c = cam([-5.0, 0.0, 1.0], [20.0, 0.0, 0.0], 60.0, 100);
        for cull in [false, true] {
            let cut = select_cut(&h, &nodes, &view(c.clone(), 25.0, cull));
            assert_eq!(cut.nodes, vec![5, 6, 3, 1], "cull {cull}");
            assert_eq!(cut.triangles, 10 + 20 + 200 + 2000);
        }
    }

    #[test]
    fn looking_away_or_from_behind_culls_everything_unless_cull_is_off() {
        let (h, nodes) = hierarchy();
        let away = cam([4.0, 0.0, 10.0], [4.0, 0.0, 20.0], 60.0, 100);
        let behind = cam([7.0, 0.0, -1000.0], [7.0, 0.0, 0.0], 60.0, 100);
        for c in [away, behind] {
            let culled = select_cut(&h, &nodes, &view(c.clone(), 1.0, true));
            assert!(culled.nodes.is_empty(), "{culled:?}");
            assert_eq!(culled.triangles, 0);
            assert_eq!(culled.visited, 2, "culled at the roots");
            let kept = select_cut(&h, &nodes, &view(c, 1.0, false));
            assert!(!kept.nodes.is_empty());
            assert_covers_once(&h, &nodes, &kept.nodes);
        }
    }

    #[test]
    fn narrow_frustum_keeps_only_what_it_sees() {
        let (h, nodes) = hierarchy();
        // Above x = 1 looking down with a 20 deg field of view: at z = 0 it sees
        // |x - 1| < 0.88 and |y| < 0.88.
        let c = cam([1.0, 0.0, 5.0], [1.0, 0.0, 0.0], 20.0, 1000);
        let cut = select_cut(&h, &nodes, &view(c, 0.5, true)).nodes;
        assert!(cut.contains(&5), "{cut:?}");
        for culled in [7, 8, 4, 1, 3] {
            assert!(!cut.contains(&culled), "{culled} in {cut:?}");
        }
    }

    #[test]
    fn view_decisions_are_monotone_on_the_hand_built_hierarchy() {
        let (_, nodes) = hierarchy();
        // Many eyes on a grid around and inside the model, several tolerances.
        for ix in -4..=8 {
            for iz in -3..=6 {
                let eye = [f64::from(ix) * 2.5, 0.5, f64::from(iz) * 2.0 + 0.3];
                let c = cam(eye, [eye[0] + 1.0, 0.0, 0.0], 60.0, 500);
                for tol in [0.5, 2.0, 10.0, 100.0] {
                    let p = ViewParams::new(&c, [0.0; 3], tol, false);
                    for (i, parent) in nodes.iter().enumerate() {
                        for &child in parent.children.iter().filter(|&&c| c != N) {
                            if !p.needs_refinement(parent) {
                                assert!(
                                    !p.needs_refinement(&nodes[child as usize]),
                                    "eye {eye:?} tol {tol}: {i} coarse enough but child {child} not"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn corrupt_child_indices_neither_panic_nor_loop() {
        let mut nodes = vec![
            node(0, [1, 7], 5.0, [0.0; 3], 1.0, 1), // 7 is out of range
            node(1, [0, 1], 5.0, [0.0; 3], 1.0, 2), // points back at its parent and itself
        ];
        let c = select_cut(&header(1), &nodes, &Criterion::MaxError { max_error: 0.0 });
        assert_eq!(c.nodes, vec![1]);
        // More roots than records: node 1 is then both a root and a child; the cut
        // holds it twice but the traversal stays in bounds and ends.
        let h = header(5);
        let c = select_cut(&h, &nodes, &Criterion::MaxError { max_error: 0.0 });
        assert_eq!(c.nodes, vec![1, 1]);
        nodes.clear();
        assert!(
            select_cut(&h, &nodes, &Criterion::MaxError { max_error: 0.0 })
                .nodes
                .is_empty()
        );
    }

    #[test]
    fn select_cut_into_reuses_the_output() {
        let (h, nodes) = hierarchy();
        let mut cut = select_cut(&h, &nodes, &Criterion::MaxError { max_error: 0.0 });
        select_cut_into(
            &h,
            &nodes,
            &Criterion::MaxError { max_error: 10.0 },
            &mut cut,
        );
        assert_eq!(
            cut,
            Cut {
                nodes: vec![0, 1],
                triangles: 3000,
                visited: 2
            }
        );
    }

    /// Every path from a root to a leaf holds exactly one selected node (so the cut
    /// covers each root's subtree once, and no selected node is another's ancestor), and
    /// the cut has no duplicates.
    pub(crate) fn assert_covers_once(h: &Header, nodes: &[NodeRecord], cut: &[u32]) {
        assert_at_most_once(h, nodes, cut, true);
    }

    /// Like [`assert_covers_once`] but paths may hold no selected node (culled branches).
    pub(crate) fn assert_at_most_once(
        h: &Header,
        nodes: &[NodeRecord],
        cut: &[u32],
        exactly: bool,
    ) {
        let mut selected = vec![false; nodes.len()];
        for &i in cut {
            assert!(!selected[i as usize], "{i} selected twice");
            selected[i as usize] = true;
        }
        let mut reached = 0;
        let mut stack: Vec<(u32, u32)> = (0..h.root_count.min(nodes.len() as u32))
            .map(|r| (r, 0))
            .collect();
        while let Some((i, above)) = stack.pop() {
            let count = above + u32::from(selected[i as usize]);
            if selected[i as usize] {
                reached += 1;
            }
            assert!(count <= 1, "node {i} lies under another selected node");
            if is_leaf(i, nodes) {
                if exactly {
                    assert_eq!(count, 1, "path to leaf {i} holds no selected node");
                }
            } else {
                let n = &nodes[i as usize];
                for &c in &n.children {
                    if valid_child(c, i, nodes.len()) {
                        stack.push((c, count));
                    }
                }
            }
        }
        assert_eq!(reached, cut.len(), "a selected node is not in the forest");
    }
}
