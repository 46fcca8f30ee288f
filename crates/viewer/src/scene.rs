//! What the viewer knows of a model's shape before any detail arrives: the vertices of
//! its roots (the coarsest level, a few thousand triangles of the whole model), read
//! once at start. They frame the home view by the model's extent as seen from the
//! camera, and the tallest axis of their box is the guessed up axis.

use glam::DVec3;
use tessera_format::{Grid, PatchReader, NO_NODE};

/// Root vertices in model coordinates and their box.
#[derive(Clone, Debug)]
pub struct ScenePoints {
    pub points: Vec<DVec3>,
    pub min: DVec3,
    pub max: DVec3,
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
    if all.is_empty() {
        let b = index.header().bounding_sphere;
        let c = DVec3::new(b[0], b[1], b[2]);
        let r = DVec3::splat(b[3]);
        all = vec![c - r, c + r];
    }
    let stride = all.len().div_ceil(max_points.max(2));
    let points: Vec<DVec3> = all.iter().step_by(stride.max(1)).copied().collect();
    let (min, max) = all.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    ScenePoints { points, min, max }
}

/// An orbit of `frames` cameras around `up` that frames the model by its extent as
/// seen from each direction (`tessera_nav::frame` on the root vertices), 20 degrees
/// above the horizon: one pivot (the mean of the per-direction targets) and one
/// distance (the largest any direction needs), so the orbit turns without zooming.
pub fn orbit_path(
    scene: &ScenePoints,
    up: tessera_nav::UpAxis,
    frames: u32,
    width: u32,
    height: u32,
) -> Result<tessera_select::CameraPath, tessera_nav::FrameError> {
    const FOV: f64 = 45.0;
    let n = frames.max(1);
    let u = up.vector();
    let (a, b) = u.any_orthonormal_pair();
    let elevation = 20f64.to_radians();
    let dirs: Vec<DVec3> = (0..n)
        .map(|i| {
            let az = std::f64::consts::TAU * f64::from(i) / f64::from(n);
            // From the eye toward the model: down by the elevation.
            -((a * az.cos() + b * az.sin()) * elevation.cos() + u * elevation.sin())
        })
        .collect();
    // Sample at least 16 directions for the pivot and the distance, whatever `frames`.
    let probe: Vec<DVec3> = (0..16)
        .map(|i| {
            let az = std::f64::consts::TAU * f64::from(i) / 16.0;
            -((a * az.cos() + b * az.sin()) * elevation.cos() + u * elevation.sin())
        })
        .chain(dirs.iter().copied())
        .collect();
    let mut pivot = DVec3::ZERO;
    let mut dist = 0.0f64;
    for d in &probe {
        let c = tessera_nav::frame(&scene.points, *d, u, FOV, width, height, 0.08)?;
        let t = DVec3::from(c.target);
        pivot += t;
        dist = dist.max((DVec3::from(c.position) - t).length());
    }
    pivot /= probe.len() as f64;
    let keyframes = dirs
        .iter()
        .map(|d| tessera_select::Camera {
            position: (pivot - *d * dist).to_array(),
            target: pivot.to_array(),
            up: u.to_array(),
            fov_y_deg: FOV,
            width,
            height,
        })
        .collect();
    Ok(tessera_select::CameraPath {
        keyframes,
        frames: n,
        closed: false,
        times: None,
        duration_s: None,
    })
}
