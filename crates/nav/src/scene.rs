//! What a front end knows of a model's shape before any detail arrives: the vertices of
//! its roots (the coarsest level, a few thousand triangles of the whole model), read
//! once at start. They frame the home view by the model's extent as seen from the
//! camera ([`home_navigator`]: the window, the browser and the three.js adapter alike)
//! and `tessera render --orbit`'s cameras ([`orbit_path`]), and the tallest axis of
//! their box is the guessed up axis.

use glam::DVec3;
use tessera_format::{Grid, PatchReader, NO_NODE};

/// Root vertices in model coordinates and their box.
#[derive(Clone, Debug)]
pub struct ScenePoints {
    pub points: Vec<DVec3>,
    pub min: DVec3,
    pub max: DVec3,
}

impl ScenePoints {
    /// Points kept from `all` (at most `max_points`, evenly strided) and the box around
    /// all of them; none at all: the box of `fallback` (a bounding sphere: centre,
    /// radius) stands in.
    pub fn from_points(all: &[DVec3], max_points: usize, fallback: [f64; 4]) -> ScenePoints {
        let all: Vec<DVec3> = if all.is_empty() {
            let c = DVec3::new(fallback[0], fallback[1], fallback[2]);
            let r = DVec3::splat(fallback[3]);
            vec![c - r, c + r]
        } else {
            all.to_vec()
        };
        let stride = all.len().div_ceil(max_points.max(2));
        let points: Vec<DVec3> = all.iter().step_by(stride.max(1)).copied().collect();
        let (min, max) = all.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        ScenePoints { points, min, max }
    }

    /// The scene of several models: their root vertices together (models share model
    /// coordinates) and the box around all of them.
    pub fn union(parts: &[ScenePoints]) -> ScenePoints {
        let mut points = Vec::new();
        let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in parts {
            points.extend_from_slice(&p.points);
            min = min.min(p.min);
            max = max.max(p.max);
        }
        ScenePoints { points, min, max }
    }

    /// These points where `placement` puts their model (the box: around the placed
    /// corners of the old one, which holds every point).
    pub fn placed(&self, placement: &tessera_select::Placement) -> ScenePoints {
        if placement.is_identity() {
            return self.clone();
        }
        let points = self.points.iter().map(|&p| placement.to_world(p)).collect();
        let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { self.min.x } else { self.max.x },
                if k & 2 == 0 { self.min.y } else { self.max.y },
                if k & 4 == 0 { self.min.z } else { self.max.z },
            );
            let w = placement.to_world(c);
            min = min.min(w);
            max = max.max(w);
        }
        ScenePoints { points, min, max }
    }

    /// The up axis guessed from the box: the axis it is tallest along.
    pub fn guess_up(&self) -> crate::UpAxis {
        crate::guess_up(self.min.to_array(), self.max.to_array())
    }
}

/// Each placed model's framing points ([`scene_points`], `per_model` at most), placed
/// where it stands; a reader placed several times (the same `Arc`) is decoded once.
pub fn placed_scene_points(
    models: &[(std::sync::Arc<dyn PatchReader>, tessera_select::Placement)],
    per_model: usize,
) -> Vec<ScenePoints> {
    let mut decoded: Vec<(*const (), ScenePoints)> = Vec::new();
    models
        .iter()
        .map(|(m, placement)| {
            let key = std::sync::Arc::as_ptr(m) as *const ();
            let own = match decoded.iter().find(|(k, _)| *k == key) {
                Some((_, p)) => p.clone(),
                None => {
                    let p = scene_points(m.as_ref(), per_model);
                    decoded.push((key, p.clone()));
                    p
                }
            };
            own.placed(placement)
        })
        .collect()
}

/// Decodes the roots of `model` (at most `max_points` vertices kept, evenly strided).
/// Roots that fail to decode are skipped; with none left, the header's bounding sphere's
/// box stands in.
pub fn scene_points(model: &dyn PatchReader, max_points: usize) -> ScenePoints {
    let index = model.index();
    let grid = Grid::of_header(index.header());
    let roots: Vec<usize> = index
        .nodes()
        .iter()
        .enumerate()
        .filter(|(_, n)| n.parent == NO_NODE)
        .map(|(i, _)| i)
        .collect();
    let mut all = Vec::new();
    for p in model.decode_patches(&roots).into_iter().flatten() {
        all.extend(p.positions.iter().map(|&q| DVec3::from(grid.position(q))));
    }
    ScenePoints::from_points(&all, max_points, index.header().bounding_sphere)
}

/// The up axis most of `parts` guess from their own extent (ties: the first part's;
/// none: +z): models side by side make their union wide, not tall.
pub fn majority_up(parts: &[ScenePoints]) -> crate::UpAxis {
    let guesses: Vec<crate::UpAxis> = parts.iter().map(ScenePoints::guess_up).collect();
    let count = |a: &crate::UpAxis| guesses.iter().filter(|g| *g == a).count();
    let best = guesses.iter().map(count).max().unwrap_or(0);
    guesses
        .iter()
        .copied()
        .find(|g| count(g) == best)
        .unwrap_or(crate::UpAxis::PosZ)
}

/// The navigation every front end starts with: turntable about `up` over the scene's
/// box, the home view framed by its points, and a closest approach of 4 quantisation
/// steps (`quant_step`, the finest of the scene's models), never closer than a copied
/// camera could be written (its target must lie at least 1e-9 x its coordinates from
/// the eye: georeferenced scenes).
pub fn home_navigator(
    scene: &ScenePoints,
    up: crate::UpAxis,
    quant_step: f64,
    width: u32,
    height: u32,
) -> crate::Navigator {
    let mut nav = crate::Navigator::new(crate::Aabb::new(scene.min, scene.max), up, width, height);
    nav.home_points(&scene.points);
    let far_coordinate = scene.min.abs().max(scene.max.abs()).max_element();
    nav.set_min_distance((quant_step * 4.0).max(far_coordinate * 4e-9));
    nav
}

/// An orbit of `frames` cameras around `up` that frames the model by its extent as
/// seen from each direction (`tessera_nav::frame` on the root vertices), 20 degrees
/// above the horizon: one pivot (the mean of the per-direction targets) and one
/// distance (the largest any direction needs), so the orbit turns without zooming.
/// Cameras are computed one at a time ([`OrbitCameras::camera`]): an orbit of 10^9
/// frames costs no memory.
#[derive(Clone, Debug)]
pub struct OrbitCameras {
    pivot: DVec3,
    distance: f64,
    up: DVec3,
    basis: (DVec3, DVec3),
    frames: u32,
    width: u32,
    height: u32,
}

const ORBIT_FOV_DEG: f64 = 45.0;
const ORBIT_ELEVATION_DEG: f64 = 20.0;

impl OrbitCameras {
    /// Frames of the orbit.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Unit direction from the eye toward the pivot at azimuth `az` (radians).
    fn view_dir(up: DVec3, (a, b): (DVec3, DVec3), az: f64) -> DVec3 {
        let el = ORBIT_ELEVATION_DEG.to_radians();
        -((a * az.cos() + b * az.sin()) * el.cos() + up * el.sin())
    }

    /// The camera of frame `i` (`0..frames`; later frames wrap around).
    pub fn camera(&self, i: u32) -> tessera_select::Camera {
        let az = std::f64::consts::TAU * f64::from(i % self.frames) / f64::from(self.frames);
        let d = Self::view_dir(self.up, self.basis, az);
        tessera_select::Camera {
            position: (self.pivot - d * self.distance).to_array(),
            target: self.pivot.to_array(),
            up: self.up.to_array(),
            fov_y_deg: ORBIT_FOV_DEG,
            width: self.width,
            height: self.height,
        }
    }
}

/// The orbit of `frames` frames around `up` (see [`OrbitCameras`]).
pub fn orbit_path(
    scene: &ScenePoints,
    up: crate::UpAxis,
    frames: u32,
    width: u32,
    height: u32,
) -> Result<OrbitCameras, crate::FrameError> {
    let u = up.vector();
    let basis = u.any_orthonormal_pair();
    // 64 directions around the circle give the pivot and the distance, whatever
    // `frames` is (between them the extent changes smoothly; the 8% margin covers it).
    let mut pivot = DVec3::ZERO;
    let mut distance = 0.0f64;
    const PROBES: u32 = 64;
    for i in 0..PROBES {
        let az = std::f64::consts::TAU * f64::from(i) / f64::from(PROBES);
        let d = OrbitCameras::view_dir(u, basis, az);
        let c = crate::frame(&scene.points, d, u, ORBIT_FOV_DEG, width, height, 0.08)?;
        let t = DVec3::from(c.target);
        pivot += t;
        distance = distance.max((DVec3::from(c.position) - t).length());
    }
    pivot /= f64::from(PROBES);
    Ok(OrbitCameras {
        pivot,
        distance,
        up: u,
        basis,
        frames: frames.max(1),
        width,
        height,
    })
}
