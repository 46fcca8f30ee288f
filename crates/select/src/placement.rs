//! Where a model stands in a scene: a similarity (uniform scale, rotation, translation)
//! from its model coordinates to the scene's world coordinates.
//!
//! Only similarities: a uniform scale keeps a model's saturated errors and spheres
//! isotropic, so the whole view-dependent machinery can run in the model's own
//! coordinates, unchanged. A camera taken into model coordinates
//! ([`Placement::camera_to_model`]) sees the model exactly as the world camera sees the
//! placed model: angles are kept, so the field of view is the same, and every distance
//! shrinks by the same factor as every error, so a node's projected error in pixels,
//! its culling and its refinement are the same. Near and far planes scale by
//! `1 / scale` ([`Placement::planes_to_model`]), which leaves every depth value as it
//! was (the reversed-Z depth of a point is a ratio of distances): the models of a scene
//! share one depth buffer although each is drawn with its own camera.

use glam::{DMat4, DQuat, DVec3};

use crate::camera::Camera;

/// `world = translation + scale * (rotation * model)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub translation: DVec3,
    /// A unit quaternion.
    pub rotation: DQuat,
    /// Positive.
    pub scale: f64,
}

impl Default for Placement {
    fn default() -> Self {
        Placement::IDENTITY
    }
}

impl Placement {
    /// The model stands where its coordinates say.
    pub const IDENTITY: Placement = Placement {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
        scale: 1.0,
    };

    /// A placement from its parts, checked: finite, `scale > 0`, a non-zero rotation
    /// (normalised here).
    pub fn new(translation: DVec3, rotation: DQuat, scale: f64) -> Result<Placement, String> {
        if !translation.is_finite() {
            return Err("the translation is not finite".into());
        }
        if !(scale.is_finite() && scale > 0.0) {
            return Err(format!("the scale must be a positive number, not {scale}"));
        }
        let len = rotation.length();
        if !(len.is_finite() && len > 1e-12) {
            return Err("the rotation quaternion is zero or not finite".into());
        }
        Ok(Placement {
            translation,
            rotation: rotation / len,
            scale,
        })
    }

    /// The placement of a 4x4 column-major matrix (glTF's and three.js's order), if it
    /// is a similarity: a rotation times a uniform scale, a translation, and a last row
    /// of `0 0 0 1`, each to a relative tolerance of 1e-6.
    pub fn from_matrix(m: &[f64; 16]) -> Result<Placement, String> {
        if m.iter().any(|v| !v.is_finite()) {
            return Err("the matrix has a value that is not finite".into());
        }
        let mat = DMat4::from_cols_array(m);
        if mat.row(3).distance(glam::DVec4::new(0.0, 0.0, 0.0, 1.0)) > 1e-9 {
            return Err("the matrix's last row must be 0 0 0 1 (no projection)".into());
        }
        let cols = [
            mat.x_axis.truncate(),
            mat.y_axis.truncate(),
            mat.z_axis.truncate(),
        ];
        let scale = cols[0].length();
        let tol = 1e-6 * scale.max(1e-300);
        let orthogonal = (cols[0].dot(cols[1])).abs() <= tol * scale
            && (cols[1].dot(cols[2])).abs() <= tol * scale
            && (cols[0].dot(cols[2])).abs() <= tol * scale;
        if !(scale > 0.0)
            || (cols[1].length() - scale).abs() > tol
            || (cols[2].length() - scale).abs() > tol
            || !orthogonal
        {
            return Err(
                "the matrix is not a similarity (a rotation, one uniform scale and a \
                 translation): shears and non-uniform scales are not supported"
                    .into(),
            );
        }
        let rot = glam::DMat3::from_cols(cols[0] / scale, cols[1] / scale, cols[2] / scale);
        if rot.determinant() < 0.0 {
            return Err("the matrix mirrors the model (negative determinant)".into());
        }
        Placement::new(mat.w_axis.truncate(), DQuat::from_mat3(&rot), scale)
    }

    /// Whether this is the identity (to the bit).
    pub fn is_identity(&self) -> bool {
        *self == Placement::IDENTITY
    }

    /// The 4x4 matrix taking model coordinates to world coordinates.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale_rotation_translation(
            DVec3::splat(self.scale),
            self.rotation,
            self.translation,
        )
    }

    /// A model point in world coordinates.
    pub fn to_world(&self, p: DVec3) -> DVec3 {
        self.translation + self.rotation * (p * self.scale)
    }

    /// A world point in model coordinates.
    pub fn to_model(&self, p: DVec3) -> DVec3 {
        self.rotation.inverse() * (p - self.translation) / self.scale
    }

    /// A model direction in world coordinates (unit in, unit out).
    pub fn direction_to_world(&self, d: DVec3) -> DVec3 {
        self.rotation * d
    }

    /// A world direction in model coordinates.
    pub fn direction_to_model(&self, d: DVec3) -> DVec3 {
        self.rotation.inverse() * d
    }

    /// A model sphere (centre, radius) in world coordinates.
    pub fn sphere_to_world(&self, center: DVec3, radius: f64) -> (DVec3, f64) {
        (self.to_world(center), radius * self.scale)
    }

    /// The world `camera` in model coordinates: it sees the model as `camera` sees the
    /// placed model (see the module docs). The identity returns it unchanged.
    pub fn camera_to_model(&self, camera: &Camera) -> Camera {
        if self.is_identity() {
            return camera.clone();
        }
        let up = self.direction_to_model(DVec3::from(camera.up));
        Camera {
            position: self.to_model(DVec3::from(camera.position)).to_array(),
            target: self.to_model(DVec3::from(camera.target)).to_array(),
            up: up.to_array(),
            ..camera.clone()
        }
    }

    /// World near and far planes (distances along the view direction) in model units.
    pub fn planes_to_model(&self, (near, far): (f64, f64)) -> (f64, f64) {
        (near / self.scale, far / self.scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed() -> Placement {
        Placement::new(
            DVec3::new(10.0, -4.0, 2.5),
            DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 1.1),
            2.5,
        )
        .unwrap()
    }

    #[test]
    fn world_and_model_round_trip() {
        let p = placed();
        let x = DVec3::new(0.7, -1.2, 3.0);
        assert!((p.to_model(p.to_world(x)) - x).length() < 1e-12);
        let m = p.matrix();
        assert!((m.transform_point3(x) - p.to_world(x)).length() < 1e-12);
        let back = Placement::from_matrix(&m.to_cols_array()).unwrap();
        assert!((back.to_world(x) - p.to_world(x)).length() < 1e-9);
        assert!((back.scale - 2.5).abs() < 1e-12);
    }

    #[test]
    fn a_model_camera_sees_the_same_angles_and_scaled_distances() {
        let p = placed();
        let world = Camera {
            position: [30.0, 5.0, -8.0],
            target: [10.0, -4.0, 2.5],
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 50.0,
            width: 640,
            height: 480,
        };
        let local = p.camera_to_model(&world);
        // A model point: its world image's direction from the world eye, taken to the
        // model, is its direction from the model eye; distances scale by 1/scale.
        let x = DVec3::new(1.0, 2.0, -0.5);
        let dw = p.to_world(x) - DVec3::from(world.position);
        let dm = x - DVec3::from(local.position);
        assert!((p.direction_to_model(dw.normalize()) - dm.normalize()).length() < 1e-12);
        assert!((dw.length() / p.scale - dm.length()).abs() < 1e-12);
        let (bw, bm) = (world.basis(), local.basis());
        assert!((p.direction_to_model(bw.up) - bm.up).length() < 1e-12);
        assert!((p.direction_to_model(bw.right) - bm.right).length() < 1e-12);
        assert!(Placement::IDENTITY.camera_to_model(&world) == world);
    }

    #[test]
    fn matrices_that_are_not_similarities_are_refused() {
        let mut m = DMat4::from_scale(DVec3::new(1.0, 2.0, 1.0)).to_cols_array();
        assert!(Placement::from_matrix(&m)
            .unwrap_err()
            .contains("not a similarity"));
        m = DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)).to_cols_array();
        assert!(Placement::from_matrix(&m).unwrap_err().contains("mirrors"));
        m = DMat4::IDENTITY.to_cols_array();
        m[3] = 0.5;
        assert!(Placement::from_matrix(&m).unwrap_err().contains("last row"));
        m = DMat4::IDENTITY.to_cols_array();
        m[12] = f64::NAN;
        assert!(Placement::from_matrix(&m)
            .unwrap_err()
            .contains("not finite"));
        assert!(Placement::new(DVec3::ZERO, DQuat::IDENTITY, 0.0).is_err());
        assert!(Placement::new(DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), 1.0).is_err());
    }
}
