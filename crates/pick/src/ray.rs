//! Rays in model coordinates, the camera's ray through a pixel, and the ray/sphere test
//! the walk down the forest uses.

use glam::DVec3;
use tessera_select::Camera;

use crate::PickError;

/// A half-line in MODEL coordinates (`f64`, like cameras): the points
/// `origin + t * dir` for `t >= 0`. `dir` need not be unit length; distances reported
/// ([`crate::Hit::distance`]) are along the unit direction, in model units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point, model coordinates.
    pub origin: [f64; 3],
    /// Direction; finite and non-zero, any length.
    pub dir: [f64; 3],
}

impl Ray {
    /// The ray from `origin` along `dir`.
    pub fn new(origin: [f64; 3], dir: [f64; 3]) -> Ray {
        Ray { origin, dir }
    }

    /// The ray from `from` through `to`.
    pub fn between(from: [f64; 3], to: [f64; 3]) -> Ray {
        let dir = std::array::from_fn(|i| to[i] - from[i]);
        Ray { origin: from, dir }
    }

    /// The ray from the camera's eye through the point (`x`, `y`) of its image, in pixels
    /// from the top-left corner (pixel centres at `+0.5`; `x` in `0..width`, `y` in
    /// `0..height`, values outside give rays outside the view). It matches the camera's
    /// projection (`Camera::view_matrix_local` and `Camera::projection_matrix`:
    /// right-handed view space looking down -Z, Y up, vertical field of view
    /// `fov_y_deg`, aspect `width / height`): the point `origin + t * dir` for any
    /// `t > 0` projects onto (`x`, `y`).
    pub fn through_pixel(camera: &Camera, x: f64, y: f64) -> Ray {
        let b = camera.basis();
        let tan_y = (0.5 * camera.fov_y_rad()).tan();
        let tan_x = tan_y * camera.aspect();
        let ndc_x = 2.0 * x / f64::from(camera.width) - 1.0;
        let ndc_y = 1.0 - 2.0 * y / f64::from(camera.height);
        let dir = b.forward + b.right * (ndc_x * tan_x) + b.up * (ndc_y * tan_y);
        Ray {
            origin: camera.position,
            dir: dir.to_array(),
        }
    }

    /// The unit direction, or `None` when `dir` is zero or not finite.
    pub fn unit_dir(&self) -> Option<[f64; 3]> {
        let d = DVec3::from_array(self.dir);
        // Scaled by the largest component first, so huge or tiny directions do not
        // overflow or underflow the length.
        let m = d.abs().max_element();
        if !(d.is_finite() && m > 0.0) {
            return None;
        }
        Some((d / m).normalize().to_array())
    }

    /// The point at `distance` along the unit direction (`origin` for an invalid
    /// direction).
    pub fn at(&self, distance: f64) -> [f64; 3] {
        let d = self.unit_dir().unwrap_or([0.0; 3]);
        std::array::from_fn(|i| self.origin[i] + distance * d[i])
    }

    /// The ray in a model's local frame (`origin - cube_origin`, in `f64`) with a unit
    /// direction; an error for a ray that cannot be traced.
    pub(crate) fn local(&self, cube_origin: [f64; 3]) -> Result<LocalRay, PickError> {
        let invalid = || PickError::InvalidRay {
            origin: self.origin,
            dir: self.dir,
        };
        let o = DVec3::from_array(self.origin);
        if !o.is_finite() {
            return Err(invalid());
        }
        let d = DVec3::from_array(self.unit_dir().ok_or_else(invalid)?);
        Ok(LocalRay {
            model_origin: o,
            origin: o - DVec3::from_array(cube_origin),
            dir: d,
        })
    }
}

/// A traceable ray: unit direction, origin in the model's local frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LocalRay {
    /// Origin, model coordinates.
    pub model_origin: DVec3,
    /// Origin, local frame (model minus `cube_origin`).
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
}

impl LocalRay {
    /// Where the ray enters the sphere `s` (centre in the local frame, radius; `f32` as
    /// stored in node records), widened by `pad + 1e-6 * (radius + |centre|)` to cover
    /// the rounding to `f32`: `Some(0)` when the origin is inside, `None` when the ray
    /// misses it or the sphere lies behind the origin. A sphere that is not finite counts
    /// as met at distance 0 (conservative: its patch is tested).
    pub fn sphere_entry(&self, s: [f32; 4], pad: f64) -> Option<f64> {
        let c = DVec3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
        let r = f64::from(s[3]);
        if !(c.is_finite() && r.is_finite()) {
            return Some(0.0);
        }
        let r = r.max(0.0) + pad + 1e-6 * (r.abs() + c.abs().max_element());
        let oc = c - self.origin;
        let along = oc.dot(self.dir);
        // Squared distance from the centre to the line, from the perpendicular itself
        // (no cancellation of |oc|^2 - along^2 far from the sphere).
        let perp = (oc - self.dir * along).length_squared();
        let r2 = r * r;
        if perp > r2 {
            return None;
        }
        let half = (r2 - perp).sqrt();
        if along + half < 0.0 {
            return None;
        }
        Some((along - half).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    fn camera() -> Camera {
        Camera::new(
            [10.0, 3.0, -4.0],
            [1.0, 0.5, 2.0],
            [0.0, 1.0, 0.2],
            50.0,
            640,
            360,
        )
        .unwrap()
    }

    #[test]
    fn through_pixel_projects_back_onto_the_pixel() {
        // Why: the viewer picks where the user clicked; the ray must land on the pixel
        // the renderer draws there, with the renderer's own matrices.
        let cam = camera();
        let origin = [100.0, -50.0, 20.0];
        let vp = cam.projection_matrix(0.01, 1000.0) * cam.view_matrix_local(origin);
        for (x, y) in [(0.5, 0.5), (320.0, 180.0), (639.5, 10.25), (17.0, 359.5)] {
            let ray = Ray::through_pixel(&cam, x, y);
            for t in [0.5, 3.0, 40.0] {
                let p = ray.at(t);
                let local = Vec4::new(
                    (p[0] - origin[0]) as f32,
                    (p[1] - origin[1]) as f32,
                    (p[2] - origin[2]) as f32,
                    1.0,
                );
                let clip = vp * local;
                let ndc = clip / clip.w;
                let px = (f64::from(ndc.x) + 1.0) * 0.5 * 640.0;
                let py = (1.0 - f64::from(ndc.y)) * 0.5 * 360.0;
                assert!(
                    (px - x).abs() < 1e-2 && (py - y).abs() < 1e-2,
                    "pixel ({x}, {y}) at t {t} projects to ({px}, {py})"
                );
                assert!(ndc.z > 0.0 && ndc.z < 1.0, "in front of the camera");
            }
        }
        // The centre of the image looks at the target.
        let c = Ray::through_pixel(&cam, 320.0, 180.0).unit_dir().unwrap();
        let f = cam.basis().forward.to_array();
        assert!((0..3).all(|i| (c[i] - f[i]).abs() < 1e-12));
    }

    #[test]
    fn sphere_entry_cases() {
        let ray = Ray::new([0.0, 0.0, -10.0], [0.0, 0.0, 2.0])
            .local([0.0; 3])
            .unwrap();
        let e = ray.sphere_entry([0.0, 0.0, 0.0, 1.0], 0.0).unwrap();
        assert!((e - 9.0).abs() < 1e-5, "{e}");
        assert_eq!(ray.sphere_entry([0.0, 0.0, -10.0, 1.0], 0.0), Some(0.0));
        assert_eq!(
            ray.sphere_entry([0.0, 0.0, -20.0, 1.0], 0.0),
            None,
            "behind"
        );
        assert_eq!(ray.sphere_entry([0.0, 3.0, 0.0, 1.0], 0.0), None, "beside");
        // Tangent within the padding still counts.
        assert!(ray.sphere_entry([0.0, 1.0, 0.0, 1.0], 0.0).is_some());
        assert_eq!(ray.sphere_entry([f32::NAN, 0.0, 0.0, 1.0], 0.0), Some(0.0));
    }

    #[test]
    fn bad_rays_are_refused() {
        for (o, d) in [
            ([0.0; 3], [0.0; 3]),
            ([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]),
            ([0.0; 3], [f64::INFINITY, 0.0, 0.0]),
        ] {
            assert!(matches!(
                Ray::new(o, d).local([0.0; 3]),
                Err(PickError::InvalidRay { .. })
            ));
        }
    }
}
