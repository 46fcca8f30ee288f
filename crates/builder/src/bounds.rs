//! Bounding volumes for patches: tight spheres, saturated spheres (enclosing balls of
//! balls, ATP section 5.2) and normal cones.
//!
//! ATP uses optimal minimum enclosing balls (Fischer and Gaertner 2003). What the runtime
//! needs for correctness is containment (saturated spheres nested, every vertex inside
//! its tight sphere); optimality only tightens culling and refinement. We use the simple
//! incremental enclosing ball of balls (grow to include each ball in turn), which always
//! contains its inputs and is within a few percent of optimal on patch-shaped inputs, and
//! pad results for `f32` rounding.

/// A sphere: centre and radius, in model units relative to the cube origin.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sphere {
    pub center: [f64; 3],
    pub radius: f64,
}

/// Relative padding applied when a sphere is stored as `f32`, so rounding never makes a
/// contained point or ball fall outside.
const F32_PAD: f64 = 4.0e-6;

impl Sphere {
    /// Smallest sphere centred on the bounding-box centre that holds every point. Empty
    /// input gives a zero sphere at the origin.
    pub fn of_points(points: impl Iterator<Item = [f64; 3]> + Clone) -> Sphere {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut any = false;
        for p in points.clone() {
            any = true;
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        if !any {
            return Sphere::default();
        }
        let center = [
            (lo[0] + hi[0]) * 0.5,
            (lo[1] + hi[1]) * 0.5,
            (lo[2] + hi[2]) * 0.5,
        ];
        let r2 = points.map(|p| dist2(p, center)).fold(0.0, f64::max);
        Sphere {
            center,
            radius: r2.sqrt(),
        }
    }

    /// A sphere that contains every ball in `balls`: the smaller of two enclosing balls,
    /// one centred on the bounding box of the balls, one grown ball by ball. (Growth
    /// alone depends on the order and can be 3x too large; the box centre alone is poor
    /// for elongated sets.)
    pub fn of_balls(balls: &[Sphere]) -> Sphere {
        let mut it = balls.iter();
        let Some(first) = it.next() else {
            return Sphere::default();
        };
        let mut grown = *first;
        for b in it {
            grown = grown.grow_to(b);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for b in balls {
            for i in 0..3 {
                lo[i] = lo[i].min(b.center[i] - b.radius);
                hi[i] = hi[i].max(b.center[i] + b.radius);
            }
        }
        let center = std::array::from_fn(|i| (lo[i] + hi[i]) * 0.5);
        let radius = balls
            .iter()
            .map(|b| dist2(b.center, center).sqrt() + b.radius)
            .fold(0.0, f64::max);
        let boxed = Sphere { center, radius };
        if boxed.radius < grown.radius {
            boxed
        } else {
            grown
        }
    }

    /// The smallest sphere containing `self` and `b`.
    pub fn grow_to(&self, b: &Sphere) -> Sphere {
        let d = dist2(self.center, b.center).sqrt();
        if d + b.radius <= self.radius {
            return *self;
        }
        if d + self.radius <= b.radius {
            return *b;
        }
        let radius = (d + self.radius + b.radius) * 0.5;
        // Move the centre from self.center towards b.center by (radius - self.radius).
        let t = if d > 0.0 {
            (radius - self.radius) / d
        } else {
            0.0
        };
        let center = std::array::from_fn(|i| self.center[i] + (b.center[i] - self.center[i]) * t);
        Sphere { center, radius }
    }

    /// Whether `b` lies inside `self`, allowing `eps` of slack.
    pub fn contains(&self, b: &Sphere, eps: f64) -> bool {
        dist2(self.center, b.center).sqrt() + b.radius <= self.radius + eps
    }

    /// `[cx, cy, cz, r]` as stored in node records, padded for `f32` rounding.
    pub fn to_f32(&self, scale: f64) -> [f32; 4] {
        let pad = F32_PAD * (self.radius + self.center.iter().map(|c| c.abs()).fold(0.0, f64::max))
            + scale * 1e-9;
        [
            self.center[0] as f32,
            self.center[1] as f32,
            self.center[2] as f32,
            (self.radius + pad) as f32,
        ]
    }

    /// Inverse of [`Sphere::to_f32`] (without removing the padding: a stored sphere read
    /// back still contains what it contained).
    pub fn from_f32(s: [f32; 4]) -> Sphere {
        Sphere {
            center: [s[0] as f64, s[1] as f64, s[2] as f64],
            radius: s[3] as f64,
        }
    }
}

/// Normal cone of a set of triangles: `[axis xyz, cos(half angle)]`, or `[0,0,0,-1]`
/// (no backface culling possible) when the normals spread over more than a hemisphere.
pub fn normal_cone(face_normals: &[[f64; 3]]) -> [f32; 4] {
    let mut sum = [0.0f64; 3];
    for n in face_normals {
        for i in 0..3 {
            sum[i] += n[i];
        }
    }
    let len = dist2(sum, [0.0; 3]).sqrt();
    if len <= 0.0 {
        return [0.0, 0.0, 0.0, -1.0];
    }
    let axis = [sum[0] / len, sum[1] / len, sum[2] / len];
    let mut min_cos = 1.0f64;
    for n in face_normals {
        let l = dist2(*n, [0.0; 3]).sqrt();
        if l > 0.0 {
            min_cos = min_cos.min((n[0] * axis[0] + n[1] * axis[1] + n[2] * axis[2]) / l);
        }
    }
    // Slack for f32 storage and quantised normals; below ~0.05 the cone is useless.
    let cos = min_cos - 1e-3;
    if cos <= 0.05 {
        return [0.0, 0.0, 0.0, -1.0];
    }
    [axis[0] as f32, axis[1] as f32, axis[2] as f32, cos as f32]
}

pub(crate) fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ball() -> impl Strategy<Value = Sphere> {
        (
            -100.0..100.0f64,
            -100.0..100.0f64,
            -100.0..100.0f64,
            0.0..50.0f64,
        )
            .prop_map(|(x, y, z, r)| Sphere {
                center: [x, y, z],
                radius: r,
            })
    }

    proptest! {
        // Why: saturated spheres must contain the spheres they saturate, or the runtime's
        // refinement stops being monotone and cuts can crack.
        #[test]
        fn ball_of_balls_contains_all(balls in prop::collection::vec(ball(), 1..20)) {
            let s = Sphere::of_balls(&balls);
            for b in &balls {
                prop_assert!(s.contains(b, 1e-9 * (1.0 + s.radius)));
            }
            let stored = Sphere::from_f32(s.to_f32(1.0));
            for b in &balls {
                prop_assert!(stored.contains(b, 0.0));
            }
        }

        #[test]
        fn sphere_of_points_contains_all(pts in prop::collection::vec((-1e3..1e3f64, -1e3..1e3f64, -1e3..1e3f64), 1..50)) {
            let pts: Vec<[f64; 3]> = pts.into_iter().map(|(x, y, z)| [x, y, z]).collect();
            let s = Sphere::of_points(pts.iter().copied());
            for p in &pts {
                prop_assert!(dist2(*p, s.center).sqrt() <= s.radius * (1.0 + 1e-12) + 1e-12);
            }
        }
    }

    #[test]
    fn cone_of_flat_patch_is_narrow_and_of_closed_shape_is_none() {
        let flat = vec![[0.0, 0.0, 1.0]; 4];
        let c = normal_cone(&flat);
        assert!(c[3] > 0.99 && (c[2] - 1.0).abs() < 1e-6);
        let closed = vec![[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]];
        assert_eq!(normal_cone(&closed)[3], -1.0);
    }
}
