//! Deterministic scenes of placed copies of real scans (`tessera gen scene`): a square
//! grid on the ground plane (perpendicular to the scene's up axis), each cell one copy,
//! the scans taken in turn, each turned upright (its own up onto the scene's), sized to
//! a unit diameter times a random factor, turned about the up axis by a random angle,
//! and set on the ground. The same options give the same file on every machine.

use glam::{DQuat, DVec3};
use tessera_nav::UpAxis;
use tessera_select::Placement;

use crate::{Scene, SceneModel};

/// What [`copies`] places.
#[derive(Clone, Debug)]
pub struct CopiesOptions {
    /// The scans, taken in turn: the model reference written in the scene, its bounding
    /// sphere (centre, radius; model coordinates) and its up axis.
    pub models: Vec<(String, [f64; 4], UpAxis)>,
    /// How many copies.
    pub count: usize,
    /// The scene's up axis.
    pub up: UpAxis,
    /// Grid cell size in copy diameters (a copy is about 1 unit across).
    pub spacing: f64,
    /// Each copy's size is its unit diameter times a factor in `[1 - v, 1 + v]`.
    pub size_variation: f64,
    pub seed: u64,
}

impl Default for CopiesOptions {
    fn default() -> Self {
        CopiesOptions {
            models: Vec::new(),
            count: 16,
            up: UpAxis::PosZ,
            spacing: 1.5,
            size_variation: 0.3,
            seed: 1,
        }
    }
}

/// A uniform number in [0, 1) for copy `k`'s `channel`th choice: MurmurHash3's 64-bit
/// finaliser over the seed, the copy and the channel. Stateless, so copy k's placement
/// depends on nothing but the seed and k (a scene of more copies keeps the first ones
/// where they were), and the same on every platform, which a crate's generator does
/// not promise across its versions.
fn unit(seed: u64, k: u64, channel: u64) -> f64 {
    let mut h = seed ^ k.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ channel.rotate_left(47);
    for _ in 0..2 {
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^= h >> 33;
    }
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// The scene of `opts.count` placed copies (see the module docs). Errors when there is
/// no scan, no copy, or a scan's bounding sphere is empty.
pub fn copies(opts: &CopiesOptions) -> Result<Scene, String> {
    if opts.models.is_empty() {
        return Err("give at least one model to copy".into());
    }
    if opts.count == 0 || opts.count > crate::MAX_MODELS {
        return Err(format!(
            "the number of copies must be between 1 and {}",
            crate::MAX_MODELS
        ));
    }
    if !(opts.spacing.is_finite() && opts.spacing > 0.0) {
        return Err("the spacing must be a positive number".into());
    }
    if !(0.0..1.0).contains(&opts.size_variation) {
        return Err("the size variation must be in [0, 1)".into());
    }
    for (name, b, _) in &opts.models {
        if !(b.iter().all(|v| v.is_finite()) && b[3] > 0.0) {
            return Err(format!("{name}: its bounding sphere is empty"));
        }
    }
    let up = opts.up.vector();
    let (e1, e2) = ground_axes(up);
    let side = (opts.count as f64).sqrt().ceil() as usize;
    let offset = (side as f64 - 1.0) * 0.5;
    let mut models = Vec::with_capacity(opts.count);
    for k in 0..opts.count {
        let (reference, b, model_up) = &opts.models[k % opts.models.len()];
        let r = |c| unit(opts.seed, k as u64, c);
        let size = 1.0 + opts.size_variation * (2.0 * r(0) - 1.0);
        let yaw = r(1) * std::f64::consts::TAU;
        // Jitter within the cell, leaving room for the copy.
        let (jx, jy) = (r(2) - 0.5, r(3) - 0.5);
        let slack = (opts.spacing - size).max(0.0) * 0.5;
        let (i, j) = ((k % side) as f64, (k / side) as f64);
        let spot = e1 * ((i - offset) * opts.spacing + jx * slack)
            + e2 * ((j - offset) * opts.spacing + jy * slack);
        let scale = size / (2.0 * b[3]);
        let rotation =
            DQuat::from_axis_angle(up, yaw) * DQuat::from_rotation_arc(model_up.vector(), up);
        // The scan's bounding-sphere centre over the spot, its sphere resting on the
        // ground plane.
        let center = DVec3::new(b[0], b[1], b[2]);
        let translation = spot + up * (size * 0.5) - rotation * (center * scale);
        models.push(SceneModel {
            name: format!("copy-{k:05}"),
            model: reference.clone(),
            placement: Placement::new(translation, rotation, scale)?,
        });
    }
    Ok(Scene {
        up: Some(opts.up),
        models,
    })
}

/// Two unit axes spanning the plane perpendicular to `up`.
fn ground_axes(up: DVec3) -> (DVec3, DVec3) {
    let a = if up.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = (a - up * a.dot(up)).normalize();
    (e1, up.cross(e1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_are_deterministic_upright_on_the_ground_and_apart() {
        let opts = CopiesOptions {
            models: vec![
                ("bunny.tsr".into(), [-0.02, 0.1, 0.0, 0.08], UpAxis::PosY),
                (
                    "statue.tsr".into(),
                    [10.0, 20.0, 300.0, 250.0],
                    UpAxis::PosZ,
                ),
            ],
            count: 10,
            ..CopiesOptions::default()
        };
        let a = copies(&opts).unwrap();
        assert_eq!(a.to_json_string(), copies(&opts).unwrap().to_json_string());
        assert_eq!(a.models.len(), 10);
        let other = copies(&CopiesOptions {
            seed: 2,
            ..opts.clone()
        })
        .unwrap();
        assert_ne!(a.to_json_string(), other.to_json_string());
        let mut centers = Vec::new();
        for (k, m) in a.models.iter().enumerate() {
            let (_, b, model_up) = &opts.models[k % 2];
            let p = m.placement;
            // Upright: the scan's up is the scene's (+z).
            let u = p.direction_to_world(model_up.vector());
            assert!((u - DVec3::Z).length() < 1e-9, "{u}");
            // Its sphere rests on z = 0, about a unit across.
            let (c, r) = p.sphere_to_world(DVec3::new(b[0], b[1], b[2]), b[3]);
            assert!(
                (c.z - r).abs() < 1e-9 && (0.35..=0.65).contains(&r),
                "{c} {r}"
            );
            centers.push(c);
        }
        // No two copies overlap (cells 1.5 apart, copies at most 1.3 across).
        for i in 0..centers.len() {
            for j in i + 1..centers.len() {
                let d = (centers[i] - centers[j]).truncate().length();
                assert!(d > 1.0, "copies {i} and {j} are {d} apart");
            }
        }
        assert!(copies(&CopiesOptions {
            count: 0,
            ..opts.clone()
        })
        .is_err());
        assert!(copies(&CopiesOptions {
            models: vec![],
            ..opts
        })
        .is_err());
    }
}
