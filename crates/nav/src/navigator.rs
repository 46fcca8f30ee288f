//! The camera controller: turntable orbit, trackball, fly, pan, zoom toward a point,
//! inertia and animations, all frame-rate independent.

use std::collections::VecDeque;

use glam::{DMat3, DQuat, DVec2, DVec3};
use tessera_select::{Camera, CameraError};

use crate::frame::{clip_planes, frame};
use crate::{Aabb, UpAxis};

/// Orbit and fly pitch stop this far from the up axis (degrees), so the view never flips
/// and `up` is never parallel to the view direction.
pub const PITCH_LIMIT_DEG: f64 = 89.5;
/// One wheel step scales the distance to the zoom point by this factor.
pub const ZOOM_STEP_FACTOR: f64 = 0.85;
/// Time constant of the zoom smoothing (s): 95 % of a wheel step is done after three of
/// them (0.15 s).
pub const ZOOM_TIME_CONSTANT_S: f64 = 0.05;
/// Time constant of the decay of orbit and pan inertia after release (s).
pub const INERTIA_TIME_CONSTANT_S: f64 = 0.12;
/// The release velocity is the mean drag velocity over the last frames covering this
/// much time (s).
pub const VELOCITY_WINDOW_S: f64 = 0.06;
/// Inertia below this speed (pixels per second) stops.
pub const INERTIA_STOP_PX_S: f64 = 0.05;
/// Releases slower than this (pixels per second) do not coast.
pub const INERTIA_START_PX_S: f64 = 5.0;
/// Duration of the animation back to the home view (s).
pub const RESET_DURATION_S: f64 = 0.4;
/// Duration of the recentre animation (s).
pub const RECENTRE_DURATION_S: f64 = 0.3;
/// Duration of the re-levelling animation when entering orbit mode (s).
pub const LEVEL_DURATION_S: f64 = 0.3;
/// Fly speed: this many times the length scale per second (scene radius, or less when
/// the caller gives a smaller distance, see [`Navigator::set_speed_scale`]).
pub const FLY_SPEED_PER_SCALE: f64 = 0.5;
/// Fly speed factor while `fast` (shift) is held.
pub const FLY_FAST_FACTOR: f64 = 4.0;
/// Auto-rotation speed [`Navigator::toggle_auto_rotate`] switches on (degrees/s).
pub const DEFAULT_AUTO_ROTATE_DEG_S: f64 = 15.0;
/// The home view looks from this far to the side of the front (degrees around up).
pub const HOME_AZIMUTH_DEG: f64 = 30.0;
/// The home view looks from this far above the plane perpendicular to up (degrees).
pub const HOME_ELEVATION_DEG: f64 = 20.0;
/// Margin of the home framing (fraction of the half-image left free on the limiting
/// axis).
pub const HOME_MARGIN: f64 = 0.05;
/// Vertical field of view of a new navigator (degrees).
pub const DEFAULT_FOV_Y_DEG: f64 = 45.0;
/// Default maximum eye-pivot distance, in scene radii.
pub const MAX_DISTANCE_RADII: f64 = 100.0;
/// Default minimum distance, in scene radii (the viewer should set the model's
/// quantisation step instead, [`Navigator::set_min_distance`]).
pub const MIN_DISTANCE_RADII: f64 = 1e-6;
/// Longest time step `update` honours (s): a longer hitch runs in slow motion rather
/// than teleporting a flying camera.
pub const MAX_DT_S: f64 = 0.25;

/// Remaining zoom below this (natural log of the distance ratio) completes at once.
const ZOOM_STOP_LOG: f64 = 1e-6;
/// An orbit-mode orientation whose right vector leans out of the horizontal plane by
/// more than this (or whose up points down) is levelled first.
const ROLL_EPS: f64 = 1e-9;

/// How mouse drags rotate the camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Turntable: yaw around the world up axis through the pivot, pitch about the
    /// screen's horizontal axis clamped to +-[`PITCH_LIMIT_DEG`]; the horizon stays level
    /// and the view never flips. The default.
    #[default]
    Orbit,
    /// Free rotation about the screen axes through the pivot (for looking under things);
    /// the horizon may roll.
    Trackball,
    /// First person: drags turn the camera about the eye (turntable-style, clamped pitch),
    /// [`FlyInput`] keys move it.
    Fly,
}

/// The fly-mode keys currently held (W, S, A, D, E, Q and shift by default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FlyInput {
    /// Along the view direction (W).
    pub forward: bool,
    /// Against the view direction (S).
    pub back: bool,
    /// Screen left (A).
    pub left: bool,
    /// Screen right (D).
    pub right: bool,
    /// Along the world up axis (E).
    pub up: bool,
    /// Against the world up axis (Q).
    pub down: bool,
    /// Four times faster (shift).
    pub fast: bool,
}

impl FlyInput {
    /// True when a movement key is held (`fast` alone does not move).
    pub fn any_motion(&self) -> bool {
        self.forward || self.back || self.left || self.right || self.up || self.down
    }
}

/// Pivot, orientation (camera to world) and eye-pivot distance.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pose {
    pivot: DVec3,
    orientation: DQuat,
    distance: f64,
}

impl Pose {
    fn forward(&self) -> DVec3 {
        self.orientation * DVec3::NEG_Z
    }
    fn eye(&self) -> DVec3 {
        self.pivot - self.forward() * self.distance
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DragKind {
    /// Orbit / trackball / look, by mode.
    Rotate,
    Pan,
    /// Mouse look about the eye (no inertia).
    Look,
}

#[derive(Clone, Debug)]
struct Drag {
    kind: DragKind,
    /// Pixels dragged since the last `update`.
    pending: DVec2,
    /// (frame time, pixels dragged in that frame), newest last, covering at least
    /// [`VELOCITY_WINDOW_S`].
    samples: VecDeque<(f64, DVec2)>,
}

#[derive(Clone, Copy, Debug)]
struct Inertia {
    kind: DragKind,
    /// Pixels per second.
    velocity: DVec2,
}

#[derive(Clone, Copy, Debug)]
struct Zoom {
    /// Natural log of the distance scale still to apply.
    log: f64,
    /// The point zoomed toward (None: the pivot).
    anchor: Option<DVec3>,
}

#[derive(Clone, Copy, Debug)]
struct Transition {
    from: Pose,
    to: Pose,
    elapsed: f64,
    duration: f64,
    /// Ends at the home view (the navigator then counts as "at home").
    to_home: bool,
}

impl Transition {
    /// The pose at `elapsed`: smoothstep in time; distance interpolated geometrically (a
    /// zoom from 1 mm to 20 m is uniform in scale); the pivot moves in step with the
    /// distance when the distance changes a lot (so a reset from a close-up first backs
    /// off, then slides, and the close-up does not swing away at 1 mm), in step with
    /// time when it does not; orientation by slerp.
    fn pose(&self) -> Pose {
        if self.elapsed >= self.duration {
            return self.to;
        }
        let t = (self.elapsed / self.duration).clamp(0.0, 1.0);
        let s = t * t * (3.0 - 2.0 * t);
        let (d0, d1) = (self.from.distance, self.to.distance);
        let distance = d0 * (d1 / d0).powf(s);
        let w = (d1 - d0).abs() / d0.max(d1);
        let by_distance = if d1 != d0 {
            (distance - d0) / (d1 - d0)
        } else {
            s
        };
        let u = s + (by_distance - s) * w;
        Pose {
            pivot: self.from.pivot + (self.to.pivot - self.from.pivot) * u,
            orientation: self
                .from
                .orientation
                .slerp(self.to.orientation, s)
                .normalize(),
            distance,
        }
    }
}

/// The camera controller shared by the desktop window and the browser. See the crate
/// documentation for which input maps to which method.
///
/// State: the up axis, the pivot (model coordinates), the orientation (a quaternion,
/// camera to world: camera X right, Y up, -Z forward) and the eye-pivot distance, the
/// field of view and viewport, the scene box (for speeds, limits and the home view), the
/// mode, auto-rotation, and the animation state (drag velocity, inertia, pending zoom,
/// transitions). The eye is `pivot - forward * distance`.
#[derive(Clone, Debug)]
pub struct Navigator {
    up: UpAxis,
    scene: Aabb,
    home_points: Option<Vec<DVec3>>,
    home: Pose,
    pose: Pose,
    fov_y_deg: f64,
    width: u32,
    height: u32,
    mode: Mode,
    /// The mode [`Navigator::toggle_fly`] returns to.
    last_non_fly: Mode,
    auto_rotate: Option<f64>,
    min_distance: f64,
    max_distance: f64,
    speed_scale: Option<f64>,
    fly: FlyInput,
    drag: Option<Drag>,
    inertia: Option<Inertia>,
    zoom: Option<Zoom>,
    transition: Option<Transition>,
    at_home: bool,
}

impl Navigator {
    /// A navigator at the home view of `scene` (model coordinates) for the up axis
    /// `up` and a `width x height` pixel viewport: looking at the scene from
    /// [`HOME_AZIMUTH_DEG`] (30 deg) around the up axis from the front and
    /// [`HOME_ELEVATION_DEG`] (20 deg) above the plane perpendicular to up, framed with
    /// [`frame`] (5 % margin), field of view [`DEFAULT_FOV_Y_DEG`]. The front is the side
    /// along `right x up` with right = +X for up along Y or Z, +Y for up along X (+Y up:
    /// from +Z; +Z up: from -Y, like Blender's front view); the home eye is turned
    /// toward +right, so the front and the right side show.
    ///
    /// An invalid box is replaced by the unit cube around the origin, a box of zero size
    /// is grown a little, a zero size becomes 1 pixel.
    pub fn new(scene: Aabb, up: UpAxis, width: u32, height: u32) -> Navigator {
        let scene = sanitize_scene(scene);
        let radius = scene.radius();
        let placeholder = Pose {
            pivot: scene.center(),
            orientation: DQuat::IDENTITY,
            distance: radius,
        };
        let mut nav = Navigator {
            up,
            scene,
            home_points: None,
            home: placeholder,
            pose: placeholder,
            fov_y_deg: DEFAULT_FOV_Y_DEG,
            width: width.max(1),
            height: height.max(1),
            mode: Mode::Orbit,
            last_non_fly: Mode::Orbit,
            auto_rotate: None,
            min_distance: radius * MIN_DISTANCE_RADII,
            max_distance: radius * MAX_DISTANCE_RADII,
            speed_scale: None,
            fly: FlyInput::default(),
            drag: None,
            inertia: None,
            zoom: None,
            transition: None,
            at_home: true,
        };
        nav.home = nav.compute_home();
        nav.pose = nav.home;
        nav
    }

    // ----- reading -----

    /// The current camera (model coordinates). Always valid: the up vector is the
    /// camera's own (from the orientation), orthogonal to the view direction and of unit
    /// length, whatever the mode or pitch.
    pub fn camera(&self) -> Camera {
        self.camera_at(&self.pose)
    }

    fn camera_at(&self, pose: &Pose) -> Camera {
        let camera = Camera {
            position: pose.eye().to_array(),
            target: pose.pivot.to_array(),
            up: (pose.orientation * DVec3::Y).to_array(),
            fov_y_deg: self.fov_y_deg,
            width: self.width,
            height: self.height,
        };
        debug_assert!(camera.validate().is_ok(), "{camera:?}");
        camera
    }

    /// The home camera ([`Navigator::reset`] goes there).
    pub fn home_camera(&self) -> Camera {
        self.camera_at(&self.home)
    }

    /// The eye, model coordinates.
    pub fn eye(&self) -> DVec3 {
        self.pose.eye()
    }
    /// The pivot (orbit centre, the camera's target), model coordinates.
    pub fn pivot(&self) -> DVec3 {
        self.pose.pivot
    }
    /// The eye-pivot distance.
    pub fn distance(&self) -> f64 {
        self.pose.distance
    }
    /// Camera-to-world rotation (camera X right, Y up, -Z forward).
    pub fn orientation(&self) -> DQuat {
        self.pose.orientation
    }
    /// Unit view direction.
    pub fn forward(&self) -> DVec3 {
        self.pose.forward()
    }
    /// The up axis.
    pub fn up(&self) -> UpAxis {
        self.up
    }
    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }
    /// The scene box.
    pub fn scene(&self) -> Aabb {
        self.scene
    }
    /// Vertical field of view, degrees.
    pub fn fov_y_deg(&self) -> f64 {
        self.fov_y_deg
    }
    /// Viewport (width, height) in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    /// The smallest distance zooming gets to the pivot or the zoom point.
    pub fn min_distance(&self) -> f64 {
        self.min_distance
    }
    /// The largest eye-pivot distance zooming out reaches.
    pub fn max_distance(&self) -> f64 {
        self.max_distance
    }
    /// The auto-rotation speed (degrees/s), if on.
    pub fn auto_rotate(&self) -> Option<f64> {
        self.auto_rotate
    }
    /// The fly speed now (model units per second, `fast` included when held).
    pub fn fly_speed(&self) -> f64 {
        let radius = self.scene.radius();
        let scale = self.speed_scale.unwrap_or(self.pose.distance).min(radius);
        let fast = if self.fly.fast { FLY_FAST_FACTOR } else { 1.0 };
        FLY_SPEED_PER_SCALE * scale * fast
    }

    /// True while an animation, inertia, a pending zoom, auto-rotation or fly movement
    /// still moves the camera in `update`. When false (and nothing is dragged), `update`
    /// leaves the camera bit-identical: the viewer may stop rendering or refine.
    pub fn is_moving(&self) -> bool {
        self.transition.is_some()
            || self.inertia.is_some()
            || self.zoom.is_some()
            || self.auto_rotate.is_some_and(|r| r != 0.0)
            || (self.mode == Mode::Fly && self.fly.any_motion())
    }

    /// True between the first `drag_*` and [`Navigator::release`]. The release velocity
    /// is measured over `update` calls, so the window must keep calling `update` every
    /// frame while this is true (even when the mouse rests).
    pub fn is_dragging(&self) -> bool {
        self.drag.is_some()
    }

    /// [`Navigator::is_moving`] or [`Navigator::is_dragging`]: the window should keep
    /// calling `update` every frame.
    pub fn needs_update(&self) -> bool {
        self.is_moving() || self.is_dragging()
    }

    /// [`clip_planes`] for the current eye and view direction, with the scene's bounding
    /// sphere as the fallback.
    pub fn clip_planes(&self, spheres: impl IntoIterator<Item = (DVec3, f64)>) -> (f64, f64) {
        clip_planes(
            self.pose.eye(),
            self.pose.forward(),
            spheres,
            (self.scene.center(), self.scene.radius()),
        )
    }

    // ----- configuration -----

    /// Tighter home framing from points (for example the vertices of the coarse root
    /// patches) instead of the scene box's corners. When the camera is still at home
    /// (no input since `new` or the last reset), it moves to the new home at once.
    pub fn home_points(&mut self, points: &[DVec3]) {
        let points: Vec<DVec3> = points.iter().copied().filter(|p| p.is_finite()).collect();
        self.home_points = (!points.is_empty()).then_some(points);
        self.refresh_home();
    }

    /// Animates back to the home view ([`RESET_DURATION_S`], 0.4 s); stops inertia and
    /// pending zoom. The mode is kept.
    pub fn reset(&mut self) {
        self.stop();
        self.start_transition(self.home, RESET_DURATION_S, true);
    }

    /// Changes the up axis: the home view is recomputed for it, and the camera animates
    /// (0.4 s) to the new home when it was at home, otherwise to the new home's
    /// orientation around the current pivot at the current distance (a close-up stays a
    /// close-up). Either way the new up is screen-up and orbits turn around it.
    pub fn set_up(&mut self, up: UpAxis) {
        self.stop();
        self.up = up;
        self.home = self.compute_home();
        let to = if self.at_home {
            self.home
        } else {
            Pose {
                orientation: self.home.orientation,
                ..self.pose
            }
        };
        let to_home = self.at_home;
        self.start_transition(to, RESET_DURATION_S, to_home);
    }

    /// The next up axis in [`UpAxis::next`] order (the U key).
    pub fn cycle_up(&mut self) {
        self.set_up(self.up.next());
    }

    /// Changes the mode. Entering [`Mode::Orbit`] from a rolled or upside-down
    /// orientation (after trackball) levels it in an animation ([`LEVEL_DURATION_S`])
    /// about the pivot. Stops drags and inertia.
    pub fn set_mode(&mut self, mode: Mode) {
        if mode == self.mode {
            return;
        }
        self.drag = None;
        self.inertia = None;
        if mode != Mode::Fly {
            self.last_non_fly = mode;
        }
        self.mode = mode;
        if mode == Mode::Orbit && self.needs_level(self.pose.orientation) {
            let to = Pose {
                orientation: level(self.pose.orientation, self.up.vector()),
                ..self.pose
            };
            let to_home = self.at_home;
            self.start_transition(to, LEVEL_DURATION_S, to_home);
        }
    }

    /// Fly mode on, or back to the mode before it (the F key).
    pub fn toggle_fly(&mut self) {
        if self.mode == Mode::Fly {
            self.set_mode(self.last_non_fly);
        } else {
            self.set_mode(Mode::Fly);
        }
    }

    /// New viewport size (pixels, at least 1). Pivot, orientation and distance are kept
    /// (the vertical field of view is fixed, so the vertical framing stays); the home
    /// view is re-framed for the new aspect ratio, and taken when the camera is at home.
    pub fn resize(&mut self, width: u32, height: u32) {
        self.width = width.max(1);
        self.height = height.max(1);
        self.refresh_home();
    }

    /// New vertical field of view (degrees, clamped to [1, 170]; NaN ignored). The eye
    /// stays; the home view is re-framed, and taken when the camera is at home.
    pub fn set_fov(&mut self, fov_y_deg: f64) {
        if fov_y_deg.is_nan() {
            return;
        }
        self.fov_y_deg = fov_y_deg.clamp(1.0, 170.0);
        self.refresh_home();
    }

    /// Turntable auto-rotation around the up axis through the pivot, degrees per second
    /// (positive turns the model counter-clockwise seen from above: the camera circles
    /// clockwise); None or 0 stops it. Paused while dragging and during animations.
    pub fn set_auto_rotate(&mut self, deg_per_s: Option<f64>) {
        self.auto_rotate = deg_per_s.filter(|r| r.is_finite() && *r != 0.0);
    }

    /// Auto-rotation at [`DEFAULT_AUTO_ROTATE_DEG_S`] on, or off (the T key).
    pub fn toggle_auto_rotate(&mut self) {
        self.auto_rotate = match self.auto_rotate {
            Some(_) => None,
            None => Some(DEFAULT_AUTO_ROTATE_DEG_S),
        };
    }

    /// The smallest distance zooming reaches, to the pivot and to the zoom point (set it
    /// to about the model's quantisation step; default 1e-6 scene radii). Positive and
    /// finite, else ignored.
    pub fn set_min_distance(&mut self, d: f64) {
        if d.is_finite() && d > 0.0 {
            self.min_distance = d;
        }
    }

    /// The largest eye-pivot distance zooming out reaches (default 100 scene radii).
    /// Positive and finite, else ignored.
    pub fn set_max_distance(&mut self, d: f64) {
        if d.is_finite() && d > 0.0 {
            self.max_distance = d;
        }
    }

    /// The length scale of fly speed: fly moves [`FLY_SPEED_PER_SCALE`] (0.5) times
    /// `min(scene radius, scale)` per second (x4 with `fast`). `Some(d)`: the caller's
    /// distance to the nearest geometry (from picking or the depth buffer) so close-ups
    /// are not flown through in one frame; `None` (default): the eye-pivot distance. At
    /// the home view both give the scene radius, so fly speed scales with the model.
    pub fn set_speed_scale(&mut self, scale: Option<f64>) {
        self.speed_scale = scale.filter(|s| s.is_finite() && *s > 0.0);
    }

    /// Places the camera exactly (a `--camera cam.json`, a saved view): pivot = target,
    /// distance = |target - position|, orientation from the camera's basis, and its field
    /// of view and size. [`Navigator::camera`] then reproduces it (up orthogonalised and
    /// normalised) to ~1e-15 relative; a rolled camera in orbit mode is levelled at the
    /// first orbit drag. Stops every animation; the home view is re-framed for the size
    /// and field of view.
    pub fn set_camera(&mut self, camera: &Camera) -> Result<(), CameraError> {
        camera.validate()?;
        self.stop();
        self.transition = None;
        self.pose = pose_from_camera(camera);
        self.fov_y_deg = camera.fov_y_deg;
        self.width = camera.width;
        self.height = camera.height;
        self.at_home = false;
        self.refresh_home();
        Ok(())
    }

    /// Stops inertia, pending zoom and drags (not animations or auto-rotation).
    pub fn stop(&mut self) {
        self.drag = None;
        self.inertia = None;
        self.zoom = None;
    }

    // ----- mouse -----

    /// The mouse button went down: stops inertia (the user grabs the model). Optional:
    /// the first `drag_*` does the same.
    pub fn press(&mut self) {
        self.inertia = None;
    }

    /// Rotation drag by (dx, dy) pixels (x right, y down): by mode, turntable orbit
    /// around the pivot, trackball around the pivot, or mouse look about the eye (fly). A
    /// drag across the viewport height turns 180 degrees. The eye-pivot distance is kept
    /// exactly. Dragging right turns the model right (the camera circles left); dragging
    /// down tilts its top toward the viewer (the camera rises).
    pub fn drag_orbit(&mut self, dx: f64, dy: f64) {
        self.drag_input(DragKind::Rotate, dx, dy);
    }

    /// Pan drag: eye and pivot move in the screen plane so a point at the pivot's depth
    /// follows the cursor exactly.
    pub fn drag_pan(&mut self, dx: f64, dy: f64) {
        self.drag_input(DragKind::Pan, dx, dy);
    }

    /// Mouse look (any mode): the camera turns about the eye, turntable-style (yaw
    /// around the up axis, clamped pitch); no inertia.
    pub fn drag_look(&mut self, dx: f64, dy: f64) {
        self.drag_input(DragKind::Look, dx, dy);
    }

    /// The mouse button went up: an orbit or pan drag coasts with the mean velocity of
    /// its last [`VELOCITY_WINDOW_S`] of `update` time, decaying with time constant
    /// [`INERTIA_TIME_CONSTANT_S`] (no coasting below [`INERTIA_START_PX_S`]).
    pub fn release(&mut self) {
        let Some(drag) = self.drag.take() else {
            return;
        };
        if drag.kind == DragKind::Look || (drag.kind == DragKind::Rotate && self.mode == Mode::Fly)
        {
            return;
        }
        let time: f64 = drag.samples.iter().map(|s| s.0).sum();
        if time <= 0.0 {
            return;
        }
        let moved: DVec2 = drag.samples.iter().map(|s| s.1).sum();
        let velocity = moved / time;
        if velocity.length() >= INERTIA_START_PX_S {
            self.inertia = Some(Inertia {
                kind: drag.kind,
                velocity,
            });
        }
    }

    /// Zoom by `steps` wheel steps (fractional allowed; positive zooms in): the distance
    /// to the zoom point is scaled by [`ZOOM_STEP_FACTOR`]^steps, smoothly (exponential
    /// approach, time constant [`ZOOM_TIME_CONSTANT_S`], frame-rate independent).
    ///
    /// `toward = Some(p)` (the picked point under the cursor): eye and pivot both move
    /// toward `p` by the same factor (a scaling about `p`, orientation unchanged), so `p`
    /// stays under the cursor and the eye never reaches or passes it. `None`, or a `p`
    /// not in front of the eye: toward the pivot. Distances stop at
    /// [`Navigator::min_distance`] (from the pivot and from `p`) and the eye-pivot
    /// distance at [`Navigator::max_distance`]. Steps accumulate; a new point replaces
    /// the old one for the remaining zoom.
    pub fn zoom(&mut self, steps: f64, toward: Option<DVec3>) {
        if !steps.is_finite() || steps == 0.0 {
            return;
        }
        let anchor = self.begin_zoom(toward);
        let pending = self.zoom.map_or(0.0, |z| z.log);
        let (lo, hi) = self.zoom_bounds(anchor);
        let log = (pending + steps * ZOOM_STEP_FACTOR.ln()).clamp(lo, hi);
        self.zoom = (log != 0.0).then_some(Zoom { log, anchor });
    }

    /// Pinch (two fingers): the fingers' spread grew by `scale` (> 1 zooms in), applied
    /// at once so the model follows the fingers: the same scaling as [`Navigator::zoom`]
    /// (about `toward` when it is in front of the eye, else toward the pivot; the same
    /// limits), by a distance factor of `1 / scale`, without smoothing. A wheel zoom
    /// still pending keeps going.
    pub fn pinch(&mut self, scale: f64, toward: Option<DVec3>) {
        if !(scale.is_finite() && scale > 0.0) || scale == 1.0 {
            return;
        }
        let anchor = self.begin_zoom(toward);
        let (lo, hi) = self.zoom_bounds(anchor);
        self.apply_zoom((-scale.ln()).clamp(lo, hi), anchor);
    }

    /// A zoom starts: any transition stops, the view leaves home, and the anchor is
    /// `toward` when it lies in front of the eye (else None: toward the pivot).
    fn begin_zoom(&mut self, toward: Option<DVec3>) -> Option<DVec3> {
        self.cancel_transition();
        self.at_home = false;
        let (eye, forward) = (self.pose.eye(), self.pose.forward());
        toward.filter(|p| p.is_finite() && (*p - eye).dot(forward) > 0.0)
    }

    /// Double-click on a picked point: the pivot moves to `p` in an animation
    /// ([`RECENTRE_DURATION_S`], 0.3 s) that keeps the orientation and slides the eye
    /// parallel to the image plane, so `p` comes to the screen centre at its current
    /// depth (the new distance) and keeps its apparent size. Chosen over "turn to look
    /// at p" (which changes the viewing and lighting angle of the surface being
    /// inspected) and over "keep the old distance" (which zooms in or out by surprise
    /// when the old pivot was behind the surface): this is MeshLab's and 3DHOP's
    /// "centre on point". A `p` not in front of the eye keeps the distance.
    pub fn recentre(&mut self, p: DVec3) {
        if !p.is_finite() {
            return;
        }
        self.stop();
        self.at_home = false;
        let depth = (p - self.pose.eye()).dot(self.pose.forward());
        let distance = if depth > 0.0 {
            depth
        } else {
            self.pose.distance
        };
        let to = Pose {
            pivot: p,
            distance,
            ..self.pose
        };
        self.start_transition(to, RECENTRE_DURATION_S, false);
    }

    // ----- keyboard -----

    /// Keyboard orbit (arrows): as a rotation drag of `dx_deg` / `dy_deg` degrees
    /// (positive dx turns the model right, positive dy tilts its top toward the viewer),
    /// applied at once, without inertia. Call it per key repeat (e.g. 5 deg), or every
    /// frame with rate * dt while the key is held.
    pub fn key_orbit(&mut self, dx_deg: f64, dy_deg: f64) {
        self.key_input();
        let px_per_deg = f64::from(self.height) / 180.0;
        self.rotate_px(DVec2::new(dx_deg, dy_deg) * px_per_deg);
    }

    /// Keyboard pan: as a pan drag of (dx, dy) pixels, at once, without inertia.
    pub fn key_pan(&mut self, dx: f64, dy: f64) {
        self.key_input();
        self.pan_px(DVec2::new(dx, dy));
    }

    /// Keyboard zoom (+/-): `zoom(steps, None)`, toward the pivot.
    pub fn key_zoom(&mut self, steps: f64) {
        self.zoom(steps, None);
    }

    /// The fly keys held now (call on every key change). They move the camera in
    /// `update` in [`Mode::Fly`] only: along the view direction, screen right, and the
    /// world up axis, at [`Navigator::fly_speed`].
    pub fn fly_keys(&mut self, keys: FlyInput) {
        self.fly = keys;
        if self.mode == Mode::Fly && keys.any_motion() {
            self.cancel_transition();
            self.at_home = false;
        }
    }

    // ----- time -----

    /// Advances animations, inertia, zoom smoothing, auto-rotation and fly movement by
    /// `dt` seconds (once per frame; `dt` above [`MAX_DT_S`] counts as that, non-positive
    /// or NaN as nothing). Every motion is a closed-form function of elapsed time (decays
    /// integrated exactly, rotations about fixed axes), so the result does not depend on
    /// the frame rate.
    pub fn update(&mut self, dt: f64) {
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        let dt = dt.min(MAX_DT_S);

        if let Some(drag) = &mut self.drag {
            drag.samples.push_back((dt, drag.pending));
            drag.pending = DVec2::ZERO;
            // Keep the newest samples covering the window.
            let mut covered = 0.0;
            let mut keep = 0;
            for s in drag.samples.iter().rev() {
                keep += 1;
                covered += s.0;
                if covered >= VELOCITY_WINDOW_S {
                    break;
                }
            }
            let drop = drag.samples.len() - keep;
            drag.samples.drain(..drop);
        }

        if let Some(mut t) = self.transition.take() {
            t.elapsed += dt;
            self.pose = t.pose();
            if t.elapsed >= t.duration {
                self.at_home = t.to_home;
            } else {
                self.transition = Some(t);
            }
        }

        if self.drag.is_none() {
            if let Some(mut inertia) = self.inertia.take() {
                let decay = (-dt / INERTIA_TIME_CONSTANT_S).exp();
                let moved = inertia.velocity * (INERTIA_TIME_CONSTANT_S * (1.0 - decay));
                inertia.velocity *= decay;
                match inertia.kind {
                    DragKind::Rotate => self.rotate_px(moved),
                    DragKind::Pan => self.pan_px(moved),
                    DragKind::Look => {}
                }
                if inertia.velocity.length() >= INERTIA_STOP_PX_S {
                    self.inertia = Some(inertia);
                }
            }
        }

        if let Some(mut z) = self.zoom.take() {
            let alpha = 1.0 - (-dt / ZOOM_TIME_CONSTANT_S).exp();
            let mut step = z.log * alpha;
            if (z.log - step).abs() < ZOOM_STOP_LOG {
                step = z.log;
            }
            let (lo, hi) = self.zoom_bounds(z.anchor);
            let clamped = step.clamp(lo, hi);
            self.apply_zoom(clamped, z.anchor);
            z.log -= step;
            if clamped == step && z.log != 0.0 {
                self.zoom = Some(z);
            }
        }

        if let Some(rate) = self.auto_rotate {
            if self.drag.is_none() && self.transition.is_none() {
                let yaw = -rate.to_radians() * dt;
                self.pose.orientation = (DQuat::from_axis_angle(self.up.vector(), yaw)
                    * self.pose.orientation)
                    .normalize();
            }
        }

        if self.mode == Mode::Fly && self.fly.any_motion() && self.transition.is_none() {
            let k = self.fly;
            let axis = |pos: bool, neg: bool| f64::from(u8::from(pos)) - f64::from(u8::from(neg));
            let q = self.pose.orientation;
            let dir = q * DVec3::NEG_Z * axis(k.forward, k.back)
                + q * DVec3::X * axis(k.right, k.left)
                + self.up.vector() * axis(k.up, k.down);
            let dir = dir.normalize_or_zero();
            self.pose.pivot += dir * (self.fly_speed() * dt);
        }
    }

    // ----- internals -----

    fn drag_input(&mut self, kind: DragKind, dx: f64, dy: f64) {
        if !(dx.is_finite() && dy.is_finite()) {
            return;
        }
        self.cancel_transition();
        self.inertia = None;
        self.at_home = false;
        if self.drag.as_ref().is_none_or(|d| d.kind != kind) {
            self.drag = Some(Drag {
                kind,
                pending: DVec2::ZERO,
                samples: VecDeque::new(),
            });
        }
        let d = DVec2::new(dx, dy);
        if let Some(drag) = &mut self.drag {
            drag.pending += d;
        }
        match kind {
            DragKind::Rotate => self.rotate_px(d),
            DragKind::Pan => self.pan_px(d),
            DragKind::Look => self.look_px(d),
        }
    }

    fn key_input(&mut self) {
        self.cancel_transition();
        self.inertia = None;
        self.at_home = false;
    }

    fn rad_per_px(&self) -> f64 {
        std::f64::consts::PI / f64::from(self.height)
    }

    fn rotate_px(&mut self, d: DVec2) {
        match self.mode {
            Mode::Orbit => {
                let k = self.rad_per_px();
                self.pose.orientation = self.turntable(self.pose.orientation, -d.x * k, -d.y * k);
            }
            Mode::Trackball => {
                let k = self.rad_per_px();
                // A rotation about one fixed screen axis per drag direction, so inertia
                // composes exactly whatever the frame rate.
                let axis = DVec3::new(-d.y * k, -d.x * k, 0.0);
                self.pose.orientation =
                    (self.pose.orientation * DQuat::from_scaled_axis(axis)).normalize();
            }
            Mode::Fly => self.look_px(d),
        }
    }

    fn look_px(&mut self, d: DVec2) {
        let k = self.rad_per_px();
        let eye = self.pose.eye();
        let q = self.turntable(self.pose.orientation, -d.x * k, -d.y * k);
        self.pose.orientation = q;
        self.pose.pivot = eye + (q * DVec3::NEG_Z) * self.pose.distance;
    }

    fn pan_px(&mut self, d: DVec2) {
        let q = self.pose.orientation;
        let world_per_px = 2.0 * self.pose.distance * (0.5 * self.fov_y_deg.to_radians()).tan()
            / f64::from(self.height);
        self.pose.pivot += (q * DVec3::X * -d.x + q * DVec3::Y * d.y) * world_per_px;
    }

    /// Turntable rotation: yaw around the world up (left-multiplied) and pitch about the
    /// camera's right axis (right-multiplied), the pitch clamped so the view direction
    /// stays within [`PITCH_LIMIT_DEG`] of the horizontal. Left and right factors commute
    /// and rotations about one axis add, so any split of a motion into frames composes to
    /// the same rotation.
    fn turntable(&self, q: DQuat, yaw: f64, pitch: f64) -> DQuat {
        let w = self.up.vector();
        let q = if self.needs_level(q) { level(q, w) } else { q };
        let elevation = (q * DVec3::NEG_Z).dot(w).clamp(-1.0, 1.0).asin();
        let limit = PITCH_LIMIT_DEG.to_radians();
        let pitch = (elevation + pitch).clamp(-limit, limit) - elevation;
        (DQuat::from_axis_angle(w, yaw) * q * DQuat::from_rotation_x(pitch)).normalize()
    }

    /// True when `q` is rolled (its right vector out of the horizontal plane) or upside
    /// down, so turntable rotation must level it first.
    fn needs_level(&self, q: DQuat) -> bool {
        let w = self.up.vector();
        (q * DVec3::X).dot(w).abs() > ROLL_EPS || (q * DVec3::Y).dot(w) < 0.0
    }

    /// (min, max) natural-log zoom from the current pose toward `anchor`.
    fn zoom_bounds(&self, anchor: Option<DVec3>) -> (f64, f64) {
        let d = self.pose.distance;
        let eye = self.pose.eye();
        let (near, magnitude) = match anchor {
            Some(p) => ((p - eye).length().min(d), p.abs().max_element()),
            None => (d, 0.0),
        };
        // Never closer than a few ulps of the coordinates, whatever min_distance says.
        let magnitude = magnitude
            .max(self.pose.pivot.abs().max_element())
            .max(eye.abs().max_element());
        let floor = self.min_distance.max(64.0 * f64::EPSILON * magnitude);
        let lo = (floor / near).ln().min(0.0);
        let hi = (self.max_distance / d).ln().max(0.0);
        (lo, hi)
    }

    fn apply_zoom(&mut self, log: f64, anchor: Option<DVec3>) {
        if log == 0.0 {
            return;
        }
        let s = log.exp();
        if let Some(p) = anchor {
            self.pose.pivot = p + (self.pose.pivot - p) * s;
        }
        self.pose.distance *= s;
    }

    fn cancel_transition(&mut self) {
        self.transition = None;
    }

    fn start_transition(&mut self, to: Pose, duration: f64, to_home: bool) {
        self.inertia = None;
        self.zoom = None;
        self.at_home = false;
        self.transition = Some(Transition {
            from: self.pose,
            to,
            elapsed: 0.0,
            duration,
            to_home,
        });
    }

    /// Recomputes the home view (after a change of size, field of view or home points)
    /// and follows it when at home.
    fn refresh_home(&mut self) {
        self.home = self.compute_home();
        if let Some(t) = &mut self.transition {
            if t.to_home {
                t.to = self.home;
            }
        } else if self.at_home {
            self.pose = self.home;
        }
    }

    fn compute_home(&self) -> Pose {
        let w = self.up.vector();
        let right = self.up.front_right();
        let back = right.cross(w);
        let (az, el) = (
            HOME_AZIMUTH_DEG.to_radians(),
            HOME_ELEVATION_DEG.to_radians(),
        );
        let out = (back * az.cos() + right * az.sin()) * el.cos() + w * el.sin();
        let framed = match &self.home_points {
            Some(points) => frame(
                points.as_slice(),
                -out,
                w,
                self.fov_y_deg,
                self.width,
                self.height,
                HOME_MARGIN,
            ),
            None => frame(
                &self.scene,
                -out,
                w,
                self.fov_y_deg,
                self.width,
                self.height,
                HOME_MARGIN,
            ),
        };
        match framed {
            Ok(camera) => pose_from_camera(&camera),
            Err(_) => {
                // Unreachable with a sanitized scene; a bounding-sphere view otherwise.
                let radius = self.scene.radius();
                let half = 0.5 * self.fov_y_deg.to_radians();
                Pose {
                    pivot: self.scene.center(),
                    orientation: look_rotation(-out, w),
                    distance: radius / half.sin(),
                }
            }
        }
    }
}

fn sanitize_scene(scene: Aabb) -> Aabb {
    let scene = if scene.is_valid() {
        scene
    } else {
        Aabb::new(DVec3::splat(-1.0), DVec3::splat(1.0))
    };
    let c = scene.center();
    let tiny = 1e-6 * (1.0 + c.abs().max_element());
    if scene.radius() < tiny {
        Aabb::new(scene.min - tiny, scene.max + tiny)
    } else {
        scene
    }
}

/// The rotation whose -Z is `forward` and whose Y is `up` made orthogonal to it.
fn look_rotation(forward: DVec3, up: DVec3) -> DQuat {
    let f = forward.normalize();
    let mut r = f.cross(up);
    if r.length() < 1e-12 {
        r = f.any_orthonormal_vector();
    }
    let r = r.normalize();
    let u = r.cross(f);
    DQuat::from_mat3(&DMat3::from_cols(r, u, -f)).normalize()
}

fn pose_from_camera(camera: &Camera) -> Pose {
    let b = camera.basis();
    let target = DVec3::from_array(camera.target);
    Pose {
        pivot: target,
        orientation: DQuat::from_mat3(&DMat3::from_cols(b.right, b.up, -b.forward)).normalize(),
        distance: (target - DVec3::from_array(camera.position)).length(),
    }
}

/// `q` with its view direction's pitch clamped to +-[`PITCH_LIMIT_DEG`] and no roll
/// (right horizontal, up on the side of the world up `w`). Looking straight along `w`,
/// the heading comes from the camera's up vector (where the top of the screen points).
fn level(q: DQuat, w: DVec3) -> DQuat {
    let f = q * DVec3::NEG_Z;
    let s = f.dot(w).clamp(-1.0, 1.0);
    let limit = PITCH_LIMIT_DEG.to_radians();
    let pitch = s.asin().clamp(-limit, limit);
    let mut h = f - w * s;
    if h.length() < 1e-9 {
        let u = q * DVec3::Y;
        let u = if s < 0.0 { u } else { -u };
        h = u - w * u.dot(w);
        if h.length() < 1e-9 {
            h = w.any_orthonormal_vector();
        }
    }
    let h = h.normalize();
    let forward = h * pitch.cos() + w * pitch.sin();
    look_rotation(forward, w)
}
