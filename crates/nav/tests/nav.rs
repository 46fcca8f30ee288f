//! Tests of tessera-nav: up axes, boxes, framing, the navigator's motions (distances
//! kept, cursor-locked pan and zoom, limits, inertia and animations independent of the
//! frame rate), camera round trips and clip planes.

use glam::{DVec2, DVec3, Vec3};
use tessera_nav::*;
use tessera_select::Camera;

// ----- helpers -----

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

fn dv(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// NDC (x, y) and view depth of `p`, in f64 from the camera's basis.
fn ndc(cam: &Camera, p: DVec3) -> (f64, f64, f64) {
    let b = cam.basis();
    let q = p - dv(cam.position);
    let depth = q.dot(b.forward);
    let t = (0.5 * cam.fov_y_rad()).tan();
    (
        q.dot(b.right) / (depth * t * cam.aspect()),
        q.dot(b.up) / (depth * t),
        depth,
    )
}

/// NDC through the renderer's own matrices (f32, local frame at the eye).
fn ndc_f32(cam: &Camera, p: DVec3) -> (f64, f64) {
    let view = cam.view_matrix_local(cam.position);
    let proj = cam.projection_matrix(1e-3, 1e3);
    let local = (p - dv(cam.position)).as_vec3();
    let clip = proj * view.transform_point3(local).extend(1.0);
    let n: Vec3 = clip.truncate() / clip.w;
    (f64::from(n.x), f64::from(n.y))
}

/// Pixel coordinates (x right, y down) of `p`.
fn pixel(cam: &Camera, p: DVec3) -> DVec2 {
    let (x, y, _) = ndc(cam, p);
    DVec2::new(
        (x + 1.0) * 0.5 * f64::from(cam.width),
        (1.0 - y) * 0.5 * f64::from(cam.height),
    )
}

fn max_abs_ndc(cam: &Camera, points: &[DVec3]) -> (f64, f64) {
    points.iter().fold((0.0f64, 0.0f64), |(mx, my), p| {
        let (x, y) = ndc_f32(cam, *p);
        (mx.max(x.abs()), my.max(y.abs()))
    })
}

fn statue() -> Aabb {
    // A 10 m statue, +Z up, away from the origin.
    Aabb::new(v(100.0, 200.0, 0.0), v(102.0, 203.0, 10.0))
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
    (dv(a) - dv(b)).length() <= tol
}

fn assert_same_camera(a: &Camera, b: &Camera, tol: f64, what: &str) {
    assert!(
        close(a.position, b.position, tol)
            && close(a.target, b.target, tol)
            && close(a.up, b.up, tol),
        "{what}: {a:?} vs {b:?}"
    );
}

/// A deterministic pseudo-random sequence in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn vec(&mut self) -> DVec3 {
        v(
            self.next() * 2.0 - 1.0,
            self.next() * 2.0 - 1.0,
            self.next() * 2.0 - 1.0,
        )
    }
}

fn run(nav: &mut Navigator, seconds: f64, fps: f64) {
    let frames = (seconds * fps).round() as usize;
    for _ in 0..frames {
        nav.update(1.0 / fps);
    }
}

// ----- UpAxis -----

#[test]
fn up_axis_parses_displays_and_cycles() {
    for (text, axis) in [
        ("+x", UpAxis::PosX),
        ("x", UpAxis::PosX),
        ("-x", UpAxis::NegX),
        ("y", UpAxis::PosY),
        ("-y", UpAxis::NegY),
        ("+Z", UpAxis::PosZ),
        (" Z ", UpAxis::PosZ),
        ("-Z", UpAxis::NegZ),
    ] {
        assert_eq!(text.parse::<UpAxis>().unwrap(), axis, "{text}");
    }
    for a in UP_AXES {
        assert_eq!(a.to_string().parse::<UpAxis>().unwrap(), a);
    }
    assert_eq!(UpAxis::PosZ.to_string(), "+z");
    assert_eq!(UpAxis::NegY.to_string(), "-y");
    assert_eq!(UpAxis::NegZ.vector(), v(0.0, 0.0, -1.0));
    assert_eq!(UpAxis::PosX.vector(), v(1.0, 0.0, 0.0));
    // next() visits all six and comes back.
    let mut a = UpAxis::PosY;
    let mut seen = vec![a];
    for _ in 0..5 {
        a = a.next();
        assert!(!seen.contains(&a), "{a} twice");
        seen.push(a);
    }
    assert_eq!(a.next(), UpAxis::PosY);
    assert_eq!(UpAxis::PosX.next(), UpAxis::NegX);
}

#[test]
fn up_axis_parse_errors_list_the_choices() {
    for bad in ["w", "", "++x", "xy", "up", "+-z"] {
        let e = bad.parse::<UpAxis>().unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "unknown up axis {bad:?}: expected one of +x, -x, +y, -y, +z, -z \
                 (case is ignored; a missing sign means +)"
            )
        );
    }
}

#[test]
fn guess_up_takes_the_tallest_axis_with_documented_ties() {
    assert_eq!(guess_up([0.0; 3], [1.0, 5.0, 2.0]), UpAxis::PosY);
    assert_eq!(guess_up([0.0; 3], [7.0, 5.0, 2.0]), UpAxis::PosX);
    assert_eq!(guess_up([-1.0, -1.0, -3.0], [1.0, 1.0, 3.0]), UpAxis::PosZ);
    // Ties: +Z, then +Y, then +X.
    assert_eq!(guess_up([0.0; 3], [1.0, 1.0, 1.0]), UpAxis::PosZ);
    assert_eq!(guess_up([0.0; 3], [2.0, 2.0, 1.0]), UpAxis::PosY);
    assert_eq!(guess_up([0.0; 3], [2.0, 1.0, 2.0]), UpAxis::PosZ);
    // Degenerate boxes.
    assert_eq!(guess_up([0.0; 3], [0.0; 3]), UpAxis::PosZ);
    assert_eq!(guess_up([f64::NAN; 3], [1.0; 3]), UpAxis::PosZ);
}

// ----- Aabb -----

#[test]
fn aabb_basics() {
    let pts = [v(1.0, 2.0, 3.0), v(-1.0, 4.0, 0.0), v(f64::NAN, 0.0, 0.0)];
    let b = Aabb::from_points(pts);
    assert_eq!(b, Aabb::new(v(-1.0, 2.0, 0.0), v(1.0, 4.0, 3.0)));
    assert!(b.is_valid());
    assert_eq!(b.center(), v(0.0, 3.0, 1.5));
    assert!((b.radius() - 0.5 * (4.0f64 + 4.0 + 9.0).sqrt()).abs() < 1e-15);
    let corners = b.corners();
    assert_eq!(corners[0], b.min);
    assert_eq!(corners[7], b.max);
    assert_eq!(Aabb::from_points(corners.iter()), b);
    assert!(!Aabb::EMPTY.is_valid());
    assert!(!Aabb::from_points(Vec::<DVec3>::new()).is_valid());
    assert_eq!(Aabb::EMPTY.union(&b), b);
    let u = b.union(&Aabb::new(v(5.0, 5.0, 5.0), v(6.0, 6.0, 6.0)));
    assert_eq!(u, Aabb::new(v(-1.0, 2.0, 0.0), v(6.0, 6.0, 6.0)));
    assert!(u.contains(v(5.5, 2.5, 1.0)) && !b.contains(v(5.5, 2.5, 1.0)));
    assert!(!Aabb::new(v(1.0, 0.0, 0.0), v(0.0, 1.0, 1.0)).is_valid());
}

// ----- framing -----

#[test]
fn tall_thin_box_from_the_side_fills_the_height() {
    let b = Aabb::new(v(-0.5, -0.5, 0.0), v(0.5, 0.5, 10.0));
    let cam = frame(&b, v(0.0, 1.0, 0.0), DVec3::Z, 50.0, 1280, 720, 0.05).unwrap();
    let (mx, my) = max_abs_ndc(&cam, &b.corners());
    assert!((0.85..=0.96).contains(&my), "max |ndc y| = {my}");
    assert!(mx < my, "horizontal {mx} should not limit");
    // Exact for perspective: the limiting axis reaches exactly 1 - margin (f64).
    let my64 = b
        .corners()
        .iter()
        .map(|p| ndc(&cam, *p).1.abs())
        .fold(0.0, f64::max);
    assert!((my64 - 0.95).abs() < 1e-9, "{my64}");
    // Centred: the top and bottom extremes are opposite.
    let ys: Vec<f64> = b.corners().iter().map(|p| ndc(&cam, *p).1).collect();
    let (lo, hi) = ys
        .iter()
        .fold((1e9f64, -1e9f64), |(a, c), y| (a.min(*y), c.max(*y)));
    assert!((lo + hi).abs() < 1e-9, "{lo} {hi}");
    assert_eq!(cam.width, 1280);
    assert!(dv(cam.up).z > 0.99);
}

#[test]
fn wide_box_is_limited_horizontally() {
    let b = Aabb::new(v(-20.0, -1.0, -1.0), v(20.0, 1.0, 1.0));
    let cam = frame(&b, v(0.3, -1.0, -0.4), DVec3::Z, 45.0, 800, 800, 0.05).unwrap();
    let (mx, my) = max_abs_ndc(&cam, &b.corners());
    assert!((0.85..=0.96).contains(&mx), "max |ndc x| = {mx}");
    assert!(my < 0.85, "vertical {my}");
    let xs: Vec<f64> = b.corners().iter().map(|p| ndc(&cam, *p).0).collect();
    let (lo, hi) = xs
        .iter()
        .fold((1e9f64, -1e9f64), |(a, c), x| (a.min(*x), c.max(*x)));
    assert!(
        (lo + hi).abs() < 1e-9 && (hi - 0.95).abs() < 1e-9,
        "{lo} {hi}"
    );
    // Vertically centred too (not the limiting axis: centred by bisection).
    let ys: Vec<f64> = b.corners().iter().map(|p| ndc(&cam, *p).1).collect();
    let (lo, hi) = ys
        .iter()
        .fold((1e9f64, -1e9f64), |(a, c), y| (a.min(*y), c.max(*y)));
    assert!((lo + hi).abs() < 1e-9, "{lo} {hi}");
}

#[test]
fn framing_holds_every_point_from_any_direction_and_points_frame_tighter() {
    let mut rng = Lcg(7);
    // Points on a sphere of radius 3 around (1000, -50, 7).
    let c = v(1000.0, -50.0, 7.0);
    let points: Vec<DVec3> = (0..400).map(|_| c + rng.vec().normalize() * 3.0).collect();
    let bbox = Aabb::from_points(&points);
    for i in 0..30 {
        let dir = rng.vec();
        let (w, h) = (300 + 100 * (i % 7), 200 + 90 * (i % 5));
        let fov = 20.0 + 2.5 * f64::from(i);
        let cam_p = frame(&points, dir, DVec3::Y, fov, w, h, 0.1).unwrap();
        let cam_b = frame(&bbox, dir, DVec3::Y, fov, w, h, 0.1).unwrap();
        let corners = bbox.corners();
        for (cam, framed) in [(&cam_p, &points[..]), (&cam_b, &corners[..])] {
            cam.validate().unwrap();
            let (mut mx, mut my) = (0.0f64, 0.0f64);
            for p in framed {
                let (x, y, depth) = ndc(cam, *p);
                assert!(depth > 0.0);
                mx = mx.max(x.abs());
                my = my.max(y.abs());
            }
            assert!(mx <= 0.9 + 1e-9 && my <= 0.9 + 1e-9, "{mx} {my}");
            assert!(mx.max(my) > 0.9 - 1e-9, "not tight: {i} {mx} {my} {cam:?}");
        }
        let dist = |cam: &Camera| (dv(cam.target) - dv(cam.position)).length();
        let eye_gap = |cam: &Camera| (c - dv(cam.position)).length();
        assert!(
            eye_gap(&cam_p) < eye_gap(&cam_b),
            "points frame tighter than their box"
        );
        assert!(dist(&cam_p) > 0.0);
    }
}

#[test]
fn framing_rejects_bad_input_and_survives_degenerate_input() {
    let b = statue();
    let f = |scene: &[DVec3], dir: DVec3, fov: f64, w: u32, m: f64| {
        frame(scene, dir, DVec3::Z, fov, w, 100, m)
    };
    let pts = b.corners();
    assert_eq!(
        f(&[], DVec3::X, 45.0, 100, 0.0).unwrap_err(),
        FrameError::NoPoints
    );
    assert_eq!(
        frame(&Aabb::EMPTY, DVec3::X, DVec3::Z, 45.0, 1, 1, 0.0).unwrap_err(),
        FrameError::NoPoints
    );
    assert!(matches!(
        f(&pts, DVec3::ZERO, 45.0, 100, 0.0),
        Err(FrameError::BadViewDir(_))
    ));
    assert!(matches!(
        f(&pts, DVec3::X, 180.0, 100, 0.0),
        Err(FrameError::BadFov(_))
    ));
    assert!(matches!(
        f(&pts, DVec3::X, 45.0, 0, 0.0),
        Err(FrameError::BadSize(0, 100))
    ));
    assert!(matches!(
        f(&pts, DVec3::X, 45.0, 100, 1.0),
        Err(FrameError::BadMargin(_))
    ));
    let e = f(&[v(0.0, f64::NAN, 0.0)], DVec3::X, 45.0, 100, 0.0).unwrap_err();
    assert_eq!(e.to_string(), "point 0 is not finite: [0.0, NaN, 0.0]");
    // A single point, a segment seen end-on, a view along up: still valid cameras.
    f(&[v(1.0, 2.0, 3.0)], DVec3::X, 45.0, 100, 0.0)
        .unwrap()
        .validate()
        .unwrap();
    f(
        &[v(0.0, 0.0, 0.0), v(5.0, 0.0, 0.0)],
        DVec3::X,
        45.0,
        100,
        0.0,
    )
    .unwrap()
    .validate()
    .unwrap();
    f(&pts, DVec3::NEG_Z, 45.0, 100, 0.0)
        .unwrap()
        .validate()
        .unwrap();
}

// ----- navigator: home, orbit, pan -----

#[test]
fn home_view_looks_from_the_side_and_above_and_frames_the_scene() {
    let nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let cam = nav.camera();
    cam.validate().unwrap();
    let b = cam.basis();
    // 20 degrees above the horizontal plane.
    assert!(
        (b.forward.z + 20f64.to_radians().sin()).abs() < 1e-12,
        "{:?}",
        b.forward
    );
    // 30 degrees around up from the front (-Y for +Z up), toward +X.
    let out = -b.forward;
    let az = out.x.atan2(-out.y).to_degrees();
    assert!((az - 30.0).abs() < 1e-9, "azimuth {az}");
    assert!(b.up.z > 0.9);
    let (mx, my) = max_abs_ndc(&cam, &statue().corners());
    assert!(mx.max(my) > 0.9 && mx.max(my) <= 0.951, "{mx} {my}");
    assert!(!nav.is_moving());
    assert_eq!(nav.home_camera(), cam);

    // +Y up: the front is +Z.
    let nav = Navigator::new(statue(), UpAxis::PosY, 640, 480);
    let out = -nav.camera().basis().forward;
    assert!((out.y - 20f64.to_radians().sin()).abs() < 1e-12);
    assert!((out.x.atan2(out.z).to_degrees() - 30.0).abs() < 1e-9);
}

#[test]
fn orbit_keeps_the_distance_and_turns_around_the_up_axis() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1000, 800);
    let pivot = nav.pivot();
    let d0 = nav.distance();
    let z0 = nav.eye().z;
    let mut rng = Lcg(3);
    for _ in 0..200 {
        nav.drag_orbit(rng.next() * 400.0 - 200.0, 0.0);
        let eye = nav.eye();
        assert!(((eye - pivot).length() - d0).abs() <= 1e-12 * d0);
        assert!((eye.z - z0).abs() < 1e-9, "{} vs {z0}", eye.z);
        assert_eq!(nav.pivot(), pivot);
    }
    // Mixed drags, up to and beyond the pitch clamp: distance kept, camera valid.
    for i in 0..300 {
        nav.drag_orbit(rng.next() * 50.0 - 25.0, if i < 150 { -37.0 } else { 41.0 });
        let cam = nav.camera();
        cam.validate().unwrap();
        assert!(((nav.eye() - pivot).length() - d0).abs() <= 1e-12 * d0);
        let pitch = cam.basis().forward.z.asin().to_degrees();
        assert!(pitch.abs() <= PITCH_LIMIT_DEG + 1e-9, "{pitch}");
        assert!(cam.basis().up.z > 0.0);
        assert!(cam.basis().right.z.abs() < 1e-9, "rolled");
    }
    // At the clamp.
    nav.drag_orbit(0.0, -100_000.0);
    let f = nav.camera().basis().forward;
    assert!((f.z.asin().to_degrees() - PITCH_LIMIT_DEG).abs() < 1e-9);
    nav.drag_orbit(0.0, 100_000.0);
    let f = nav.camera().basis().forward;
    assert!((f.z.asin().to_degrees() + PITCH_LIMIT_DEG).abs() < 1e-9);
    nav.camera().validate().unwrap();
}

#[test]
fn drag_scale_and_directions() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1000, 800);
    let before = nav.forward();
    // Dragging the full viewport height horizontally turns 180 degrees around up.
    nav.drag_orbit(800.0, 0.0);
    let after = nav.forward();
    let h = |f: DVec3| v(f.x, f.y, 0.0).normalize();
    assert!((h(before).dot(h(after)) + 1.0).abs() < 1e-12);
    // Dragging right moves the camera left (the model turns right).
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1000, 800);
    let right = nav.camera().basis().right;
    let eye0 = nav.eye();
    nav.drag_orbit(10.0, 0.0);
    assert!((nav.eye() - eye0).dot(right) < 0.0);
    // Dragging down raises the camera.
    let z0 = nav.eye().z;
    nav.drag_orbit(0.0, 10.0);
    assert!(nav.eye().z > z0);
    // key_orbit is a drag in degrees.
    let mut a = Navigator::new(statue(), UpAxis::PosZ, 1000, 800);
    let mut b = a.clone();
    a.key_orbit(90.0, -10.0);
    b.drag_orbit(400.0, -800.0 / 18.0);
    assert_same_camera(&a.camera(), &b.camera(), 1e-9, "key_orbit");
}

#[test]
fn pan_moves_a_point_at_pivot_depth_with_the_cursor() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    nav.drag_orbit(123.0, -45.0);
    let cam = nav.camera();
    let b = cam.basis();
    let pivot = nav.pivot();
    let probe = pivot + b.right * 0.7 - b.up * 0.4;
    let d0 = nav.distance();
    let f0 = nav.forward();
    let eye0 = nav.eye();
    for (dx, dy) in [(37.0, 0.0), (0.0, -12.5), (-200.0, 90.0)] {
        let p0 = pixel(&nav.camera(), probe);
        let q0 = pixel(&nav.camera(), pivot);
        nav.drag_pan(dx, dy);
        let p1 = pixel(&nav.camera(), probe);
        let q1 = pixel(&nav.camera(), pivot);
        assert!(
            (p1 - p0 - DVec2::new(dx, dy)).length() < 1e-7,
            "{p0} -> {p1}"
        );
        assert!((q1 - q0 - DVec2::new(dx, dy)).length() < 1e-7);
        assert_eq!(nav.distance(), d0);
        assert_eq!(nav.forward(), f0);
    }
    // Eye and pivot moved in the screen plane.
    assert!((nav.eye() - eye0).dot(b.forward).abs() < 1e-9);
    // key_pan is the same motion.
    let mut a = nav.clone();
    let mut c = nav.clone();
    a.key_pan(5.0, 7.0);
    c.drag_pan(5.0, 7.0);
    assert_eq!(a.camera(), c.camera());
}

// ----- zoom -----

#[test]
fn zoom_toward_a_point_keeps_it_under_the_cursor_and_never_reaches_it() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let cam = nav.camera();
    // A point on the statue, off-centre.
    let p = v(101.0, 200.0, 7.5);
    let (x, y, depth) = ndc(&cam, p);
    assert!(x.abs() < 1.0 && y.abs() < 1.0 && depth > 0.0);
    let px0 = pixel(&cam, p);
    let dp0 = (p - nav.eye()).length();
    nav.zoom(1.0, Some(p));
    run(&mut nav, 1.0, 60.0);
    let dp1 = (p - nav.eye()).length();
    assert!((dp1 / dp0 - ZOOM_STEP_FACTOR).abs() < 1e-9, "{}", dp1 / dp0);
    assert!((pixel(&nav.camera(), p) - px0).length() < 1e-6);

    // Thousands of steps: the eye approaches p, stops at min_distance, never passes it.
    let min = 1e-6;
    nav.set_min_distance(min);
    let mut last = dp1;
    for i in 0..3000 {
        nav.zoom(1.0, Some(p));
        nav.update(1.0 / 60.0);
        let cam = nav.camera();
        cam.validate().unwrap();
        let to_p = p - nav.eye();
        let dp = to_p.length();
        assert!(
            dp > 0.0 && dp <= last * (1.0 + 1e-12),
            "step {i}: {dp} after {last}"
        );
        assert!(dp >= min * (1.0 - 1e-6), "step {i}: {dp}");
        assert!(
            to_p.dot(nav.forward()) > 0.0,
            "p went behind the eye at step {i}"
        );
        assert!(nav.distance() > 0.0);
        last = dp;
    }
    assert!(last < min * 1.001, "reached {last}");
    // Still under the cursor (f64 projection; the eye is 1e-6 from p).
    assert!((pixel(&nav.camera(), p) - px0).length() < 1e-3);

    // Zooming out is limited by max_distance.
    for _ in 0..3000 {
        nav.zoom(-1.0, Some(p));
        nav.update(1.0 / 60.0);
    }
    assert!(nav.distance() <= nav.max_distance() * (1.0 + 1e-9));
    assert!(nav.distance() >= nav.max_distance() * 0.99);
    assert!((nav.max_distance() - MAX_DISTANCE_RADII * statue().radius()).abs() < 1e-9);
}

#[test]
fn zoom_is_smoothed_and_without_a_point_goes_to_the_pivot() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    let pivot = nav.pivot();
    let d0 = nav.distance();
    let f0 = nav.forward();
    nav.zoom(2.0, None);
    // Nothing moves before update.
    assert_eq!(nav.distance(), d0);
    assert!(nav.is_moving());
    nav.update(0.15);
    let goal = d0 * ZOOM_STEP_FACTOR.powi(2);
    let done = (nav.distance().ln() - d0.ln()) / (goal.ln() - d0.ln());
    assert!((0.9..1.0).contains(&done), "after 0.15 s: {done}");
    run(&mut nav, 1.0, 60.0);
    assert!((nav.distance() / goal - 1.0).abs() < 1e-9);
    assert_eq!(nav.pivot(), pivot);
    assert_eq!(nav.forward(), f0);
    assert!(!nav.is_moving());
    // A point behind the eye is ignored (zooms toward the pivot).
    let behind = nav.eye() - nav.forward() * 3.0;
    nav.zoom(1.0, Some(behind));
    run(&mut nav, 1.0, 60.0);
    assert_eq!(nav.pivot(), pivot);
    // Toward the pivot, the distance stops at min_distance.
    nav.set_min_distance(0.01);
    nav.key_zoom(500.0);
    run(&mut nav, 1.0, 60.0);
    assert!((nav.distance() - 0.01).abs() < 1e-9, "{}", nav.distance());
}

// ----- fly -----

#[test]
fn fly_speed_scales_with_the_model() {
    let fly = |scale: f64, keys: FlyInput, hint: Option<f64>| {
        let b = Aabb::new(statue().min * scale, statue().max * scale);
        let mut nav = Navigator::new(b, UpAxis::PosZ, 800, 600);
        nav.toggle_fly();
        assert_eq!(nav.mode(), Mode::Fly);
        nav.set_speed_scale(hint);
        let eye0 = nav.eye();
        nav.fly_keys(keys);
        run(&mut nav, 1.0, 60.0);
        (nav.eye() - eye0, nav.forward(), b.radius())
    };
    let w = FlyInput {
        forward: true,
        ..FlyInput::default()
    };
    let (d1, f1, r1) = fly(1.0, w, None);
    let (d10, _, r10) = fly(10.0, w, None);
    assert!(
        (d1.length() - FLY_SPEED_PER_SCALE * r1).abs() < 1e-9 * r1,
        "{}",
        d1.length()
    );
    assert!((d10.length() / d1.length() - 10.0).abs() < 1e-9);
    assert!((r10 / r1 - 10.0).abs() < 1e-12);
    assert!(d1.normalize().dot(f1) > 1.0 - 1e-12);
    // Fast is x4; a close-up hint slows it down.
    let (df, _, _) = fly(1.0, FlyInput { fast: true, ..w }, None);
    assert!((df.length() / d1.length() - FLY_FAST_FACTOR).abs() < 1e-9);
    let (ds, _, _) = fly(1.0, w, Some(0.005));
    assert!((ds.length() - FLY_SPEED_PER_SCALE * 0.005).abs() < 1e-12);
    // Up moves along world +Z, right along the screen right.
    let (du, _, _) = fly(
        1.0,
        FlyInput {
            up: true,
            ..FlyInput::default()
        },
        None,
    );
    assert!(du.x.abs() < 1e-12 && du.y.abs() < 1e-12 && du.z > 0.0);
    // Keys do nothing outside fly mode.
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    let cam = nav.camera();
    nav.fly_keys(w);
    assert!(!nav.is_moving());
    run(&mut nav, 0.5, 60.0);
    assert_eq!(nav.camera(), cam);
}

#[test]
fn fly_look_turns_about_the_eye() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    nav.set_mode(Mode::Fly);
    let eye = nav.eye();
    let z = nav.forward().z;
    nav.drag_orbit(200.0, 0.0);
    assert!((nav.eye() - eye).length() < 1e-12);
    assert!((nav.forward().z - z).abs() < 1e-12);
    nav.drag_look(0.0, 30.0);
    assert!((nav.eye() - eye).length() < 1e-12);
    assert!(nav.forward().z < z, "mouse down looks down");
    // No inertia for look.
    nav.update(1.0 / 60.0);
    nav.release();
    assert!(!nav.is_moving());
}

// ----- up axis changes -----

#[test]
fn set_up_z_levels_the_view_and_orbits_turn_around_z() {
    // A Z-up scan opened as Y-up, then corrected.
    let mut nav = Navigator::new(statue(), UpAxis::PosY, 1280, 720);
    assert!(nav.camera().basis().up.y > 0.9);
    nav.set_up("+z".parse().unwrap());
    assert!(nav.is_moving());
    run(&mut nav, 1.0, 60.0);
    assert!(!nav.is_moving());
    assert_eq!(nav.up(), UpAxis::PosZ);
    let cam = nav.camera();
    assert!(cam.up[2] > 0.9, "{:?}", cam.up);
    assert_same_camera(
        &cam,
        &Navigator::new(statue(), UpAxis::PosZ, 1280, 720).camera(),
        1e-9,
        "home",
    );
    let z0 = nav.eye().z;
    for _ in 0..50 {
        nav.drag_orbit(31.0, 0.0);
        assert!((nav.eye().z - z0).abs() < 1e-9);
    }
    // Away from home, set_up keeps pivot and distance.
    nav.drag_pan(40.0, 10.0);
    nav.zoom(3.0, None);
    run(&mut nav, 1.0, 60.0);
    let (pivot, d) = (nav.pivot(), nav.distance());
    nav.cycle_up();
    assert_eq!(nav.up(), UpAxis::NegZ);
    run(&mut nav, 1.0, 60.0);
    assert!((nav.pivot() - pivot).length() < 1e-12 && (nav.distance() - d).abs() < 1e-12);
    assert!(nav.camera().up[2] < -0.9);
}

#[test]
fn trackball_is_free_and_orbit_mode_levels_it_back() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    nav.set_mode(Mode::Trackball);
    let pivot = nav.pivot();
    let d = nav.distance();
    // Right over the top and beyond: valid cameras throughout, distance kept.
    for _ in 0..26 {
        nav.drag_orbit(7.0, -23.0);
        nav.camera().validate().unwrap();
        assert!(((nav.eye() - pivot).length() - d).abs() < 1e-12 * d);
    }
    assert!(
        nav.camera().basis().up.z < 0.5,
        "trackball should have rolled over"
    );
    nav.set_mode(Mode::Orbit);
    run(&mut nav, 1.0, 60.0);
    let b = nav.camera().basis();
    assert!(b.right.z.abs() < 1e-9 && b.up.z > 0.0);
    assert!(b.forward.z.asin().to_degrees().abs() <= PITCH_LIMIT_DEG + 1e-9);
    assert!((nav.distance() - d).abs() < 1e-12 * d);
}

// ----- camera round trip -----

#[test]
fn set_camera_round_trips() {
    let mut rng = Lcg(11);
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    for i in 0..100 {
        let pos = v(500_000.0, 4_000_000.0, 100.0) + rng.vec() * 50.0;
        let target = pos + rng.vec() * (0.001 + 20.0 * rng.next());
        let dir = (target - pos).normalize();
        let up = dir.cross(rng.vec()).cross(dir).normalize();
        let cam = Camera::new(
            pos.to_array(),
            target.to_array(),
            up.to_array(),
            10.0 + f64::from(i),
            640 + i,
            480,
        )
        .unwrap();
        if i % 3 == 1 {
            nav.set_mode(Mode::Trackball);
        } else if i % 3 == 2 {
            nav.set_mode(Mode::Orbit);
        }
        nav.set_camera(&cam).unwrap();
        let back = nav.camera();
        let scale = (target - pos).length();
        assert!(
            close(back.position, cam.position, 1e-9 * scale),
            "{i}: {back:?} vs {cam:?}"
        );
        assert_eq!(back.target, cam.target);
        assert!(close(back.up, cam.up, 1e-9));
        assert_eq!(
            (back.fov_y_deg, back.width, back.height),
            (cam.fov_y_deg, cam.width, cam.height)
        );
        assert!(!nav.is_moving());
    }
    let mut bad = nav.camera();
    bad.up = bad.position;
    bad.target = bad.position;
    assert!(nav.set_camera(&bad).is_err());
}

// ----- time: stillness, inertia, frame-rate independence -----

#[test]
fn no_input_leaves_the_camera_bit_identical() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    nav.drag_orbit(50.0, 20.0);
    nav.drag_pan(3.0, 4.0);
    nav.release(); // released before any update: no measured velocity, no inertia
    let cam = nav.camera();
    assert!(!nav.is_moving());
    for i in 0..2000 {
        nav.update(if i % 2 == 0 { 1.0 / 144.0 } else { 1.0 / 24.0 });
    }
    assert_eq!(nav.camera(), cam);
    // A drag held still before release does not coast either.
    nav.drag_orbit(80.0, 0.0);
    nav.update(1.0 / 60.0);
    for _ in 0..10 {
        nav.update(1.0 / 60.0);
    }
    nav.release();
    assert!(!nav.is_moving());
    let cam = nav.camera();
    run(&mut nav, 1.0, 60.0);
    assert_eq!(nav.camera(), cam);
}

/// A drag at a constant `speed` (pixels/s) for 1/6 s at `fps`, released, then updated.
fn drag_release(nav: &mut Navigator, fps: f64, speed: DVec2, pan: bool, after: f64) {
    let frames = (fps / 6.0).round() as usize;
    for _ in 0..frames {
        let d = speed / fps;
        if pan {
            nav.drag_pan(d.x, d.y);
        } else {
            nav.drag_orbit(d.x, d.y);
        }
        nav.update(1.0 / fps);
    }
    nav.release();
    run(nav, after, fps);
}

#[test]
fn orbit_and_pan_inertia_coast_and_are_frame_rate_independent() {
    let base = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    for pan in [false, true] {
        for after in [1.0 / 6.0, 1.0] {
            let mut a = base.clone();
            let mut b = base.clone();
            let mut still = base.clone();
            drag_release(&mut a, 30.0, DVec2::new(600.0, -150.0), pan, after);
            drag_release(&mut b, 144.0, DVec2::new(600.0, -150.0), pan, after);
            drag_release(&mut still, 144.0, DVec2::new(600.0, -150.0), pan, 0.0);
            assert_same_camera(&a.camera(), &b.camera(), 1e-9, "30 vs 144 fps");
            // It did coast: about speed * tau more than the drag itself at the end.
            let moved = (a.eye() - still.eye()).length();
            assert!(moved > 1e-3, "no coasting ({pan}, {after}): {moved}");
        }
        // Coasting ends.
        let mut a = base.clone();
        drag_release(&mut a, 60.0, DVec2::new(600.0, 0.0), pan, 0.0);
        assert!(a.is_moving());
        run(&mut a, 3.0, 60.0);
        assert!(!a.is_moving());
        let cam = a.camera();
        run(&mut a, 1.0, 60.0);
        assert_eq!(a.camera(), cam);
    }
    // Orbit inertia adds speed * tau pixels of rotation in total (here as yaw).
    let mut a = base.clone();
    let mut b = base.clone();
    drag_release(&mut a, 60.0, DVec2::new(720.0, 0.0), false, 5.0);
    b.drag_orbit(720.0 / 6.0 + 720.0 * INERTIA_TIME_CONSTANT_S, 0.0);
    // (Coasting stops below 0.05 px/s, leaving ~0.006 px = 3e-4 m here undone.)
    assert_same_camera(&a.camera(), &b.camera(), 1e-3, "coast total");
    // Trackball inertia too.
    let mut t = base.clone();
    t.set_mode(Mode::Trackball);
    let mut a = t.clone();
    let mut b = t.clone();
    drag_release(&mut a, 30.0, DVec2::new(300.0, 500.0), false, 0.5);
    drag_release(&mut b, 144.0, DVec2::new(300.0, 500.0), false, 0.5);
    assert_same_camera(&a.camera(), &b.camera(), 1e-9, "trackball");
}

type Scenario = Box<dyn Fn(&mut Navigator)>;

#[test]
fn zoom_recentre_fly_and_auto_rotate_are_frame_rate_independent() {
    let base = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let p = v(101.5, 200.2, 8.0);
    let scenarios: Vec<(&str, Scenario)> = vec![
        (
            "zoom toward",
            Box::new(move |n: &mut Navigator| n.zoom(4.5, Some(p))),
        ),
        ("zoom out", Box::new(|n: &mut Navigator| n.zoom(-3.0, None))),
        ("recentre", Box::new(move |n: &mut Navigator| n.recentre(p))),
        (
            "reset",
            Box::new(|n: &mut Navigator| {
                n.drag_orbit(300.0, 100.0);
                n.zoom(10.0, None);
                n.update(1.0);
                n.reset();
            }),
        ),
        (
            "fly",
            Box::new(|n: &mut Navigator| {
                n.set_mode(Mode::Fly);
                n.fly_keys(FlyInput {
                    forward: true,
                    right: true,
                    up: true,
                    ..FlyInput::default()
                });
            }),
        ),
        (
            "auto-rotate",
            Box::new(|n: &mut Navigator| n.set_auto_rotate(Some(40.0))),
        ),
    ];
    for (name, start) in &scenarios {
        for after in [1.0 / 6.0, 1.0] {
            let mut a = base.clone();
            let mut b = base.clone();
            start(&mut a);
            start(&mut b);
            let c0 = a.camera();
            run(&mut a, after, 30.0);
            run(&mut b, after, 144.0);
            assert_same_camera(&a.camera(), &b.camera(), 1e-9, name);
            assert!(
                (dv(a.camera().position) - dv(c0.position)).length() > 1e-3,
                "{name} did not move"
            );
        }
    }
}

#[test]
fn recentre_brings_the_point_to_the_centre_at_its_depth() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let p = v(101.8, 200.0, 2.0);
    let cam0 = nav.camera();
    let px0 = pixel(&cam0, p);
    let depth = ndc(&cam0, p).2;
    let f0 = nav.forward();
    nav.recentre(p);
    assert!(nav.is_moving());
    nav.update(0.15);
    let mid = pixel(&nav.camera(), p);
    let centre = DVec2::new(640.0, 360.0);
    assert!(
        (mid - centre).length() < (px0 - centre).length() * 0.9 && (mid - centre).length() > 1.0
    );
    nav.update(0.2);
    assert!(!nav.is_moving());
    assert_eq!(nav.pivot(), p);
    assert!((pixel(&nav.camera(), p) - centre).length() < 1e-6);
    assert!((nav.forward() - f0).length() < 1e-12, "orientation kept");
    assert!(
        (nav.distance() - depth).abs() < 1e-9,
        "eye slid in the image plane"
    );
    // Orbit now turns around p.
    nav.drag_orbit(100.0, 20.0);
    assert!((pixel(&nav.camera(), p) - centre).length() < 1e-6);
}

#[test]
fn reset_animates_back_home() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let home = nav.camera();
    nav.drag_orbit(300.0, 120.0);
    nav.drag_pan(-50.0, 20.0);
    nav.zoom(25.0, Some(v(101.0, 200.0, 5.0)));
    run(&mut nav, 1.0, 60.0);
    let away = nav.camera();
    assert!((dv(away.position) - dv(home.position)).length() > 1.0);
    nav.reset();
    nav.update(0.2);
    let mid = nav.camera();
    assert!(!close(mid.position, home.position, 1e-3) && !close(mid.position, away.position, 1e-3));
    nav.update(0.21);
    assert!(!nav.is_moving());
    assert_same_camera(&nav.camera(), &home, 1e-12, "reset");
    // After a reset the navigator counts as at home: a resize re-frames it.
    nav.resize(400, 900);
    assert_same_camera(
        &nav.camera(),
        &Navigator::new(statue(), UpAxis::PosZ, 400, 900).camera(),
        1e-9,
        "resize at home",
    );
    // Input during the animation cancels it where it is.
    nav.drag_orbit(200.0, 0.0);
    nav.reset();
    nav.update(0.1);
    nav.drag_pan(1.0, 0.0);
    assert!(!nav.is_moving());
}

#[test]
fn home_points_frame_tighter_and_resize_keeps_a_moved_camera() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let d_box = nav.distance();
    // A cylinder-ish statue inside the box.
    let points: Vec<DVec3> = (0..64)
        .flat_map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / 64.0;
            let c = v(101.0 + 0.9 * a.cos(), 201.5 + 0.9 * a.sin(), 0.0);
            [c, c + v(0.0, 0.0, 10.0)]
        })
        .collect();
    nav.home_points(&points);
    assert!(nav.distance() < d_box);
    let (mx, my) = max_abs_ndc(&nav.camera(), &points);
    assert!(mx.max(my) > 0.9 && mx.max(my) < 0.951);
    // Once moved, resize and fov changes keep pivot and distance.
    nav.drag_orbit(10.0, 0.0);
    let (pivot, d, f) = (nav.pivot(), nav.distance(), nav.forward());
    nav.resize(300, 200);
    nav.set_fov(70.0);
    assert_eq!((nav.pivot(), nav.distance(), nav.forward()), (pivot, d, f));
    assert_eq!(nav.size(), (300, 200));
    assert_eq!(nav.camera().fov_y_deg, 70.0);
    nav.set_fov(500.0);
    assert_eq!(nav.fov_y_deg(), 170.0);
}

#[test]
fn auto_rotate_turns_around_up_and_stops() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    nav.toggle_auto_rotate();
    assert_eq!(nav.auto_rotate(), Some(DEFAULT_AUTO_ROTATE_DEG_S));
    let f0 = nav.forward();
    let z0 = nav.eye().z;
    run(&mut nav, 2.0, 50.0);
    let f1 = nav.forward();
    let angle = v(f0.x, f0.y, 0.0)
        .angle_between(v(f1.x, f1.y, 0.0))
        .to_degrees();
    assert!(
        (angle - 2.0 * DEFAULT_AUTO_ROTATE_DEG_S).abs() < 1e-6,
        "{angle}"
    );
    assert!((nav.eye().z - z0).abs() < 1e-9);
    assert!(nav.is_moving());
    nav.toggle_auto_rotate();
    assert!(!nav.is_moving());
}

// ----- clip planes -----

#[test]
fn clip_planes_for_an_extreme_close_up() {
    // A 10 m model (sphere radius 5 around the origin); the eye 5 mm in front of its
    // surface at x = 5, looking at it.
    let eye = v(5.005, 0.0, 0.0);
    let forward = v(-1.0, 0.0, 0.0);
    let model = (DVec3::ZERO, 5.0);
    // Node spheres: small ones near the eye, and the whole model.
    let spheres = vec![
        (v(4.99, 0.0, 0.0), 0.01),
        (v(4.9, 0.05, 0.0), 0.1),
        (v(3.0, 1.0, 0.0), 2.0),
        (v(-4.0, 0.0, 0.0), 1.0),
        (v(10.0, 0.0, 0.0), 0.5), // behind the eye: ignored
    ];
    let (near, far) = clip_planes(eye, forward, spheres.clone(), model);
    assert!(near > 0.0 && near <= 0.005, "near {near}");
    assert!(far >= 10.005 - 1e-12, "far {far}");
    assert!(far < 10.005 * 1.02);
    assert!(near >= far * MIN_NEAR_RATIO);
    for (c, r) in &spheres {
        let d = (*c - eye).dot(forward);
        if d + r > 0.0 {
            assert!((d - r).max(0.0) >= near || d - r <= 0.0, "{c} {r}");
            assert!(d + r <= far);
        }
    }
    // Nearest sphere in front at 5.005 - 4.99 - 0.01 = 5 mm: near just before it.
    assert!(near > 0.004 && near <= 0.005 * 0.99 + 1e-15, "{near}");
    // The eye inside a sphere: near is the clamp.
    let (near, far) = clip_planes(eye, forward, [(v(5.0, 0.0, 0.0), 0.1), model], model);
    assert!((near - far * MIN_NEAR_RATIO).abs() < 1e-18, "{near} {far}");
    assert!(near <= 0.005);
    // No spheres: the fallback.
    let (near, far) = clip_planes(v(0.0, 0.0, 20.0), DVec3::NEG_Z, [], model);
    assert!((near - 15.0 * 0.99).abs() < 1e-9 && (far - 25.0 * 1.01).abs() < 1e-9);
    // Everything behind the eye: still a usable range.
    let (near, far) = clip_planes(v(0.0, 0.0, 20.0), DVec3::Z, [], model);
    assert!(near > 0.0 && far > near);
    // The navigator's own helper uses its eye and the scene sphere.
    let nav = Navigator::new(statue(), UpAxis::PosZ, 800, 600);
    let (n, f) = nav.clip_planes([]);
    let cam = nav.camera();
    for p in statue().corners() {
        let d = ndc(&cam, p).2;
        assert!(d >= n && d <= f);
    }
}

#[test]
fn ndc_helpers_agree() {
    let nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let cam = nav.camera();
    for p in statue().corners() {
        let (x, y, _) = ndc(&cam, p);
        let (xf, yf) = ndc_f32(&cam, p);
        assert!((x - xf).abs() < 1e-4 && (y - yf).abs() < 1e-4);
    }
}

#[test]
fn pinch_scales_at_once_about_the_point_or_the_pivot() {
    let mut nav = Navigator::new(statue(), UpAxis::PosZ, 1280, 720);
    let pivot = nav.pivot();
    let d0 = nav.distance();
    let f0 = nav.forward();
    // Fingers twice as far apart: half the distance, at once, toward the pivot.
    nav.pinch(2.0, None);
    assert!((nav.distance() / d0 - 0.5).abs() < 1e-12);
    assert_eq!(nav.pivot(), pivot);
    assert_eq!(nav.forward(), f0);
    assert!(!nav.is_moving());
    nav.pinch(0.5, None);
    assert!((nav.distance() / d0 - 1.0).abs() < 1e-12);
    // About a point: it stays under the same pixel, its distance scaled by 1 / scale.
    let p = v(101.0, 200.0, 7.5);
    let px0 = pixel(&nav.camera(), p);
    let dp0 = (p - nav.eye()).length();
    nav.pinch(1.25, Some(p));
    assert!(((p - nav.eye()).length() / dp0 - 0.8).abs() < 1e-9);
    assert!((pixel(&nav.camera(), p) - px0).length() < 1e-6);
    // The same limits as the wheel: never closer than min_distance to the point.
    nav.set_min_distance(1e-3);
    nav.pinch(1e12, Some(p));
    let dp = (p - nav.eye()).length();
    assert!((1e-3 * (1.0 - 1e-9)..1e-2).contains(&dp), "{dp}");
    // Nonsense is ignored.
    let cam = nav.camera();
    for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        nav.pinch(s, None);
    }
    assert_eq!(nav.camera(), cam);
}

#[test]
fn point_at_depth_inverts_the_reversed_z_projection() {
    use tessera_nav::point_at_depth;
    let nav = Navigator::new(statue(), UpAxis::PosZ, 640, 480);
    let cam = nav.camera();
    let (near, far) = (0.5, 4000.0);
    // A point on the ray through the centre of pixel (37, 81), 123.4 units deep.
    let b = cam.basis();
    let tan_y = (0.5 * cam.fov_y_rad()).tan();
    let (nx, ny) = (37.5 / 640.0 * 2.0 - 1.0, 1.0 - 81.5 / 480.0 * 2.0);
    let dir = b.forward + b.right * (nx * tan_y * cam.aspect()) + b.up * (ny * tan_y);
    let z = 123.4;
    let p = DVec3::from(cam.position) + dir * z;
    // Its depth through the renderer's projection (near and far swapped: reversed Z).
    let proj = cam.projection_matrix(far as f32, near as f32);
    let clip = proj * glam::Vec4::new(0.0, 0.0, -z as f32, 1.0);
    let depth = clip.z / clip.w;
    assert!(depth > 0.0 && depth < 1.0, "{depth}");
    let q = point_at_depth(&cam, 37.9, 81.2, depth, (near, far)).unwrap();
    assert!((q - p).length() < 1e-5 * z, "{q} vs {p}");
    assert_eq!(point_at_depth(&cam, 37.0, 81.0, 0.0, (near, far)), None);
    assert_eq!(point_at_depth(&cam, 640.0, 81.0, depth, (near, far)), None);
    assert_eq!(point_at_depth(&cam, -1.0, 81.0, depth, (near, far)), None);
}
