//! Framing a model by its extent as seen from the camera, and near/far clip planes.

use std::borrow::Cow;

use glam::DVec3;
use tessera_select::Camera;

use crate::Aabb;

/// Why [`frame`] could not build a camera.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// Nothing to frame (no points, or an invalid box).
    #[error("nothing to frame: no points (or an empty box)")]
    NoPoints,
    /// A point has a NaN or infinite coordinate.
    #[error("point {index} is not finite: {point:?}")]
    NotFinite {
        /// Its index in the input.
        index: usize,
        /// Its coordinates.
        point: [f64; 3],
    },
    /// The view direction is zero or not finite.
    #[error("view direction {0:?} has zero length or is not finite")]
    BadViewDir([f64; 3]),
    /// The up vector is zero or not finite.
    #[error("up {0:?} has zero length or is not finite")]
    BadUp([f64; 3]),
    /// The field of view is outside (0, 180) degrees.
    #[error("fov_y_deg must be in (0, 180), got {0}")]
    BadFov(f64),
    /// Width or height is zero.
    #[error("image size must be at least 1x1, got {0}x{1}")]
    BadSize(u32, u32),
    /// The margin is outside [0, 1).
    #[error("margin must be in [0, 1), got {0}")]
    BadMargin(f64),
}

/// What [`frame`] can frame: a box (its eight corners) or points (for example the
/// vertices of the model's coarse root patches, which frame tighter than their box).
pub trait FrameTarget {
    /// The points that must end up inside the view.
    fn frame_points(&self) -> Cow<'_, [DVec3]>;
}

impl FrameTarget for Aabb {
    fn frame_points(&self) -> Cow<'_, [DVec3]> {
        if self.is_valid() {
            Cow::Owned(self.corners().to_vec())
        } else {
            Cow::Borrowed(&[])
        }
    }
}

impl FrameTarget for [DVec3] {
    fn frame_points(&self) -> Cow<'_, [DVec3]> {
        Cow::Borrowed(self)
    }
}

impl FrameTarget for Vec<DVec3> {
    fn frame_points(&self) -> Cow<'_, [DVec3]> {
        Cow::Borrowed(self)
    }
}

impl<const N: usize> FrameTarget for [DVec3; N] {
    fn frame_points(&self) -> Cow<'_, [DVec3]> {
        Cow::Borrowed(self)
    }
}

/// The camera looking along `view_dir` that frames `scene` as tightly as a perspective
/// view allows: every point lies inside the view frustum, and on the limiting axis
/// (vertical or horizontal, whichever needs the larger distance) the projected extent
/// reaches `1 - margin` of the half-size (`margin = 0.05` leaves 5 % of the half-image
/// free on each side). The projected extent is centred on both axes.
///
/// Exact for perspective (not a bounding-sphere estimate): in the view basis each point
/// `(x, y, z)` gives, for each side of the frustum, a plane the eye must lie behind
/// (`y - ey <= t_y (z - ez)` and its mirror images), so the closest eye on each axis is
/// where the two extreme planes of that axis cross; the farther of the two axes' eyes is
/// kept, and then the eye is shifted sideways (by bisection) until the largest and the
/// smallest projected coordinate are opposite on each axis. Shifting sideways at the
/// farther depth never pushes a point out (the extent is centred, which minimises its
/// largest half).
///
/// The eye never comes closer than 1e-3 of the points' box diagonal in front of the
/// nearest point: degenerate inputs (one point, a segment seen end-on) and very wide
/// fields of view (from which the whole box fits in the frustum seen from one of its own
/// corners) would otherwise put the eye on a point; such framings are not tight.
///
/// `up` fixes screen-up (made orthogonal to `view_dir`; when parallel to it an arbitrary
/// perpendicular is used). The target is on the view axis at the mid-depth of the points
/// (it becomes the orbit pivot). Errors: no points, non-finite input, `fov_y_deg` outside
/// (0, 180), a zero size, `margin` outside [0, 1).
#[allow(clippy::too_many_arguments)]
pub fn frame<T: FrameTarget + ?Sized>(
    scene: &T,
    view_dir: DVec3,
    up: DVec3,
    fov_y_deg: f64,
    width: u32,
    height: u32,
    margin: f64,
) -> Result<Camera, FrameError> {
    if !(view_dir.is_finite() && view_dir.length() > 0.0) {
        return Err(FrameError::BadViewDir(view_dir.to_array()));
    }
    if !(up.is_finite() && up.length() > 0.0) {
        return Err(FrameError::BadUp(up.to_array()));
    }
    if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
        return Err(FrameError::BadFov(fov_y_deg));
    }
    if width == 0 || height == 0 {
        return Err(FrameError::BadSize(width, height));
    }
    if !(0.0..1.0).contains(&margin) {
        return Err(FrameError::BadMargin(margin));
    }
    let points = scene.frame_points();
    if points.is_empty() {
        return Err(FrameError::NoPoints);
    }
    if let Some((index, p)) = points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(FrameError::NotFinite {
            index,
            point: p.to_array(),
        });
    }

    let f = view_dir.normalize();
    let mut r = f.cross(up.normalize());
    if r.length() < 1e-9 {
        r = f.any_orthonormal_vector();
    }
    let r = r.normalize();
    let u = r.cross(f);

    // Work relative to the points' box centre so georeferenced coordinates keep their
    // precision.
    let bbox = Aabb::from_points(points.iter());
    let origin = bbox.center();
    let coords: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let q = *p - origin;
            [q.dot(r), q.dot(u), q.dot(f)]
        })
        .collect();

    let tan_half = (0.5 * fov_y_deg.to_radians()).tan();
    let aspect = f64::from(width) / f64::from(height);
    let ty = tan_half * (1.0 - margin);
    let tx = tan_half * aspect * (1.0 - margin);
    let (mut top, mut bottom, mut right, mut left) = (f64::MIN, f64::MIN, f64::MIN, f64::MIN);
    let (mut z_min, mut z_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for c in &coords {
        top = top.max(c[1] - ty * c[2]);
        bottom = bottom.max(-c[1] - ty * c[2]);
        right = right.max(c[0] - tx * c[2]);
        left = left.max(-c[0] - tx * c[2]);
        z_min = z_min.min(c[2]);
        z_max = z_max.max(c[2]);
    }
    let ez_y = -(top + bottom) / (2.0 * ty);
    let ez_x = -(right + left) / (2.0 * tx);
    // Degenerate inputs (a single point, a segment seen end-on) would put the eye on a
    // point; keep it a little in front of the nearest one.
    let floor = (2.0 * bbox.radius() * 1e-3).max(1e-9 * (1.0 + origin.abs().max_element()));
    let ez = ez_x.min(ez_y).min(z_min - floor);
    let ex = centre_axis(&coords, 0, ez);
    let ey = centre_axis(&coords, 1, ez);
    let position = origin + r * ex + u * ey + f * ez;
    let distance = 0.5 * (z_min + z_max) - ez;
    let target = position + f * distance;
    let camera = Camera {
        position: position.to_array(),
        target: target.to_array(),
        up: u.to_array(),
        fov_y_deg,
        width,
        height,
    };
    debug_assert!(camera.validate().is_ok(), "{camera:?}");
    Ok(camera)
}

/// The lateral eye coordinate on `axis` (0: right, 1: up) at depth `ez` for which the
/// largest and smallest projected coordinate `(c - e) / (z - ez)` are opposite. Their sum
/// decreases strictly with `e`, is >= 0 at the smallest lateral coordinate and <= 0 at the
/// largest: bisection.
fn centre_axis(coords: &[[f64; 3]], axis: usize, ez: f64) -> f64 {
    let skew = |e: f64| {
        let (mut hi, mut lo) = (f64::NEG_INFINITY, f64::INFINITY);
        for c in coords {
            let t = (c[axis] - e) / (c[2] - ez);
            hi = hi.max(t);
            lo = lo.min(t);
        }
        hi + lo
    };
    let (mut a, mut b) = coords
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), c| {
            (a.min(c[axis]), b.max(c[axis]))
        });
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            break;
        }
        if skew(m) > 0.0 {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Near and far planes can differ by this ratio at most: `near >= far * MIN_NEAR_RATIO`.
pub const MIN_NEAR_RATIO: f64 = 1e-6;

/// Near and far distances (along `forward`, the view direction) for the view from `eye`
/// of the given bounding spheres `(centre, radius)` (for example the drawn nodes'
/// spheres): `far` is just beyond (1 %) the deepest point of any sphere, `near` just
/// before (1 %) the nearest point of the nearest sphere in front of the eye, and at least
/// `far * 1e-6` ([`MIN_NEAR_RATIO`]); when the eye is inside a sphere (or a sphere reaches
/// behind the eye plane) `near` is that clamp. Spheres entirely behind the eye and
/// non-finite ones are ignored; when none is left, `fallback` (usually the model's
/// bounding sphere) is used the same way, and when that is behind the eye too, `far` is
/// its distance from the eye plus its radius.
///
/// The 1e6 ratio assumes the renderer's REVERSED-Z depth buffer in f32 (depth 1 at near,
/// 0 at far): floating point keeps its relative precision near 0, so depth resolution is
/// roughly uniform in log depth and a 1e6 ratio still separates surfaces a few parts in
/// 1e5 of their distance apart. A conventional (not reversed) depth buffer would need a
/// far smaller ratio.
pub fn clip_planes(
    eye: DVec3,
    forward: DVec3,
    spheres: impl IntoIterator<Item = (DVec3, f64)>,
    fallback: (DVec3, f64),
) -> (f64, f64) {
    let f = forward.normalize_or_zero();
    // (nearest, deepest) depth of the spheres reaching in front of the eye: along the
    // view axis, or radial when there is no axis.
    let extent = |spheres: &mut dyn Iterator<Item = (DVec3, f64)>| {
        let (mut near, mut far) = (f64::INFINITY, f64::NEG_INFINITY);
        for (c, r) in spheres {
            if !(c.is_finite() && r.is_finite() && r >= 0.0) {
                continue;
            }
            let d = if f == DVec3::ZERO {
                (c - eye).length()
            } else {
                (c - eye).dot(f)
            };
            if d + r > 0.0 {
                near = near.min(d - r);
                far = far.max(d + r);
            }
        }
        (near, far)
    };
    let (mut near, mut far) = extent(&mut spheres.into_iter());
    if far.is_nan() || far <= 0.0 {
        (near, far) = extent(&mut std::iter::once(fallback));
    }
    if far.is_nan() || far <= 0.0 {
        let r = if fallback.1.is_finite() {
            fallback.1.abs()
        } else {
            0.0
        };
        let d = if fallback.0.is_finite() {
            (fallback.0 - eye).length()
        } else {
            0.0
        };
        far = (d + r).max(f64::MIN_POSITIVE / MIN_NEAR_RATIO);
        near = 0.0;
    }
    let far = far * 1.01;
    let near = (near * 0.99).max(far * MIN_NEAR_RATIO);
    (near, far)
}

/// The point drawn at pixel (`x`, `y`) of a frame of `camera` whose reversed-Z depth
/// buffer holds `depth` there: [`Camera::point_at_depth`] (one formula for the desktop
/// and the browser).
pub fn point_at_depth(
    camera: &Camera,
    x: f64,
    y: f64,
    depth: f32,
    planes: (f64, f64),
) -> Option<DVec3> {
    camera.point_at_depth(x, y, depth, planes)
}
