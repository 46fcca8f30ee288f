//! Geomorphing ratios (GoLD section 4.2, on the diamond hierarchy): how far each drawn
//! node is moved toward its parent's shape.
//!
//! A node drawn because its parent diamond `D` was refined carries, per vertex, the
//! position (and attributes) it takes in `D`'s simplified mesh (its morph target). The
//! vertex shader draws `mix(own, target, r)`: at `r = 1` the children of `D` show exactly
//! `D`'s surface, at `r = 0` their own. `r` is one number per **group** (the children of
//! one diamond, `tessera-stream`'s residency group), so every child of `D` moves with the
//! same ratio, and it is computed from errors already in the node table, on the CPU, once
//! per group and frame.
//!
//! ## The ratio
//! With `a` = `D`'s projected saturated error and `b` = the largest projected saturated
//! error of the diamonds of `D`'s children (both in units of the tolerance; `D` refines
//! when `a > 1`, a child diamond when `b > 1`):
//!
//! - `r = 1` at the switch (`a = 1`): the children enter with their parent's shape;
//! - `r = 0` once `a` reaches the window `w` (default 2: the parent's error is twice the
//!   tolerance), **or** once `b` reaches 1, whichever comes first;
//! - in between `r = 1 - ln(a) / min(ln w, ln(a / b))`: linear in the logarithm of the
//!   parent's error, i.e. in the logarithm of the distance on a dolly, so it moves at an
//!   even pace whatever the distance.
//!
//! ## Why it cannot crack
//! The builder locks the outer border of `D` while simplifying it, so every child vertex
//! on that border has itself as target (`r` does not move it), and two children of `D`
//! sharing a vertex share its target (they were one merged vertex) and their ratio. A
//! vertex a child of `D` moves is therefore shared only with other children of `D`
//! drawn with the same `r`... unless one of those children is itself refined: then its
//! children's side of the shared vertex is their diamond's locked border, which does not
//! move. The second exit of the window (`b >= 1` gives `r = 0`) rules that out: a group
//! whose member would refine is unmorphed. GoLD's border rules for two drawn neighbours
//! one level apart ("the finer side fully morphed, the coarser not morphed") are this
//! rule: the finer side's vertices there are locked (fully morphed is unmoved), the
//! coarser side's ratio is 0. Same-level neighbours in different groups share only
//! locked vertices. The property tests check the rule on random cameras; the renderer's
//! pinhole tests check the pixels.
//!
//! Stability: the ratio is a function of the camera alone (no state), so a camera that
//! stops leaves every ratio where it is; continuity at the switch makes refinement and
//! coarsening alike continuous.

use tessera_format::NO_NODE;

use crate::residency::{HotNode, NodeView};
use crate::select::ViewParams;

/// Default morph window: the children reach their own shape when their parent's
/// projected error is twice the tolerance (earlier when a child diamond is about to
/// refine).
pub const DEFAULT_MORPH_WINDOW: f32 = 2.0;

/// A node's projected saturated error in units of the tolerance (`> 1`: the view refines
/// it; the test of [`crate::needs_refinement`] as a ratio). Infinite from inside its
/// saturated sphere, 0 for a zero error.
#[inline]
pub fn refinement_ratio(view: &ViewParams, n: &HotNode) -> f32 {
    let s = n.saturated_sphere;
    let d = (glam::Vec3::new(s[0], s[1], s[2]) - view.eye).length() - s[3];
    if d <= 0.0 {
        f32::INFINITY
    } else if n.error > 0.0 {
        n.error * view.error_scale / d
    } else {
        0.0
    }
}

/// The morph ratio of a group from its parent diamond's refinement ratio `parent` and
/// the largest refinement ratio `child_max` of its members' diamonds (see the module
/// docs), with `window > 1`. Always in `[0, 1]`; 1 at or below the switch, 0 when a
/// member would refine.
pub fn morph_ratio(parent: f32, child_max: f32, window: f32) -> f32 {
    if parent.is_nan() || child_max.is_nan() || child_max >= 1.0 {
        return 0.0;
    }
    if parent <= 1.0 {
        return 1.0;
    }
    let la = parent.ln();
    let span = window.max(1.0).ln().min((parent / child_max).ln());
    if span.is_nan() || span <= 0.0 || !la.is_finite() {
        return 0.0;
    }
    (1.0 - la / span).clamp(0.0, 1.0)
}

/// The view ratio of the group whose members are `members` (children of one diamond),
/// culled or not: [`morph_ratio`] of their parent's and their own refinement ratios.
/// 0 for a group of roots (nothing to morph toward).
pub fn group_ratio(nv: &NodeView, view: &ViewParams, members: &[u32], window: f32) -> f32 {
    let nodes = nv.nodes();
    let Some(first) = members.first().and_then(|&m| nodes.get(m as usize)) else {
        return 0.0;
    };
    if first.parent == NO_NODE {
        return 0.0;
    }
    let parent = refinement_ratio(view, &nodes[first.parent as usize]);
    let mut child_max = 0.0f32;
    for &m in members {
        let n = &nodes[m as usize];
        if n.children != [NO_NODE, NO_NODE] {
            child_max = child_max.max(refinement_ratio(view, n));
        }
    }
    morph_ratio(parent, child_max, window)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratio_ends_and_bounds() {
        let w = DEFAULT_MORPH_WINDOW;
        assert_eq!(morph_ratio(1.0, 0.3, w), 1.0);
        assert_eq!(morph_ratio(0.5, 0.3, w), 1.0);
        assert_eq!(morph_ratio(2.0, 0.3, w), 0.0);
        assert_eq!(morph_ratio(5.0, 0.3, w), 0.0);
        // A member about to refine: unmorphed whatever the parent.
        assert_eq!(morph_ratio(1.2, 1.0, w), 0.0);
        assert_eq!(morph_ratio(1.0001, 1.0, w), 0.0);
        // Halfway in log space.
        assert!((morph_ratio(2f32.sqrt(), 0.1, w) - 0.5).abs() < 1e-6);
        // The child's switch comes first: ratio 0 exactly when b reaches 1.
        let (a, b) = (1.5f32, 0.75f32);
        let r = morph_ratio(a, b, w);
        assert!(r > 0.0 && r < 1.0);
        assert!(morph_ratio(a / b * 0.999, 0.999, w) < 0.01);
        for x in [f32::NAN, f32::INFINITY, -1.0, 0.0] {
            for y in [f32::NAN, f32::INFINITY, -1.0, 0.0, 0.5] {
                let r = morph_ratio(x, y, w);
                assert!((0.0..=1.0).contains(&r), "{x} {y} -> {r}");
            }
        }
    }

    #[test]
    fn ratio_is_continuous_and_monotone_in_the_parent_error() {
        let mut last = 1.0f32;
        for i in 0..=2000 {
            let a = 1.0 + i as f32 * 0.001;
            let r = morph_ratio(a, 0.4, DEFAULT_MORPH_WINDOW);
            assert!(r <= last + 1e-6, "not monotone at {a}");
            assert!(last - r < 0.01, "jump at {a}: {last} -> {r}");
            last = r;
        }
        assert_eq!(last, 0.0);
    }
}
