//! Navigation for Tessera viewers: the camera controller shared by the desktop window
//! and (later) the browser client. CPU only, no windowing types, builds for wasm32.
//!
//! The window translates mouse and keyboard events into calls on a [`Navigator`], calls
//! [`Navigator::update`] once per frame with the frame time, and reads
//! [`Navigator::camera`] (a [`tessera_select::Camera`] in model coordinates, the format
//! every Tessera tool shares). Everything is sized in pixels and seconds, and every
//! motion (inertia, zoom smoothing, animations, fly movement, auto-rotation) is a
//! closed-form function of elapsed time, so 30 fps and 144 fps end at the same camera.
//!
//! Users come from MeshLab, 3DHOP, Sketchfab and Blender and inspect scans of statues,
//! buildings and terrain: an overview, then fast zooms toward the point under the cursor
//! down to extreme close-ups (a 1 mm detail of a 10 m statue), then away. Hence: zoom is
//! multiplicative and aimed at the picked point (never reaching it), the pan and fly
//! speeds scale with the distance, the turntable orbit keeps the model's up axis up, and
//! near/far planes follow the visible geometry ([`clip_planes`]).
//!
//! - [`UpAxis`] (`+x` ... `-z`, parsed, displayed, cycled) and [`guess_up`].
//! - [`Aabb`]: boxes in model coordinates.
//! - [`frame`]: the tightest perspective framing of a box or of points from a direction.
//! - [`Navigator`]: the controller ([`Mode::Orbit`] turntable, [`Mode::Trackball`],
//!   [`Mode::Fly`]).
//! - [`clip_planes`]: near and far planes for a reversed-Z depth buffer.
//!
//! # Input mapping (what the window calls)
//!
//! | input | call |
//! | --- | --- |
//! | left drag | [`Navigator::drag_orbit`]`(dx, dy)` (turntable; trackball in trackball mode; mouse look in fly mode) |
//! | right or middle drag, shift + left drag | [`Navigator::drag_pan`]`(dx, dy)` |
//! | mouse button down / up | [`Navigator::press`] (optional, stops coasting) / [`Navigator::release`] (starts inertia) |
//! | wheel | [`Navigator::zoom`]`(steps, Some(picked point under the cursor))`, or `None` when nothing is hit (toward the pivot) |
//! | double-click | [`Navigator::recentre`]`(picked point)` |
//! | F | [`Navigator::toggle_fly`] |
//! | W A S D, Q E, shift (fly mode) | [`Navigator::fly_keys`]`(`[`FlyInput`]`)` on every key change: forward, left, back, right, down, up, fast (x4) |
//! | T | [`Navigator::toggle_auto_rotate`] (turntable spin, 15 deg/s) |
//! | R or Home | [`Navigator::reset`] (animated back to the home view) |
//! | U | [`Navigator::cycle_up`] (+x, -x, +y, -y, +z, -z) |
//! | arrows | [`Navigator::key_orbit`]`(+-5, 0)` / `(0, +-5)` degrees per press or repeat |
//! | + / - | [`Navigator::key_zoom`]`(+1.0)` / `(-1.0)` |
//! | window resized | [`Navigator::resize`]`(width, height)` |
//! | every frame | [`Navigator::update`]`(dt)`, then [`Navigator::camera`]; keep rendering while [`Navigator::needs_update`] |
//!
//! Pixel deltas are in window coordinates: x to the right, y DOWN (winit's convention).
//! A drag across the viewport height turns 180 degrees; a pan moves a point at the
//! pivot's depth exactly with the cursor; one wheel step scales the distance by 0.85.
//!
//! The viewer sets [`Navigator::set_min_distance`] to about the model's quantisation
//! step, gives [`Navigator::home_points`] the coarse root mesh's vertices for a tighter
//! home framing, and may give [`Navigator::set_speed_scale`] the distance to the nearest
//! geometry for flying. No velocity hint is exported: the streaming core predicts the
//! camera from its previous frames.

mod aabb;
mod frame;
mod navigator;
mod scene;
mod up;

pub use aabb::Aabb;
pub use frame::{clip_planes, frame, point_at_depth, FrameError, FrameTarget, MIN_NEAR_RATIO};
pub use navigator::{
    FlyInput, Mode, Navigator, DEFAULT_AUTO_ROTATE_DEG_S, DEFAULT_FOV_Y_DEG, FLY_FAST_FACTOR,
    FLY_SPEED_PER_SCALE, HOME_AZIMUTH_DEG, HOME_ELEVATION_DEG, HOME_MARGIN, INERTIA_START_PX_S,
    INERTIA_STOP_PX_S, INERTIA_TIME_CONSTANT_S, LEVEL_DURATION_S, MAX_DISTANCE_RADII, MAX_DT_S,
    MIN_DISTANCE_RADII, PITCH_LIMIT_DEG, RECENTRE_DURATION_S, RESET_DURATION_S, VELOCITY_WINDOW_S,
    ZOOM_STEP_FACTOR, ZOOM_TIME_CONSTANT_S,
};
pub use scene::{
    home_navigator, majority_up, orbit_path, placed_scene_points, scene_points, OrbitCameras,
    ScenePoints,
};
pub use up::{guess_up, UpAxis, UpAxisParseError, UP_AXES};
