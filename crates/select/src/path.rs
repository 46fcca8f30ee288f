//! Camera paths (format in `docs/camera.md`), for `tessera render` and every front end: keyframes in the
//! shared camera format, interpolated over a number of frames; or an orbit around the
//! model's bounding sphere.

use std::path::{Path, PathBuf};

use crate::camera::{Camera, CameraError, Orbit};
use glam::DVec3;
use serde_json::Value;

/// Fields of a path document.
pub const PATH_FIELDS: [&str; 4] = ["frames", "loop", "keyframes", "duration_s"];

/// A camera path that could not be read, with the file and the field to blame.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    #[error("{file}: cannot read: {error}")]
    Io {
        file: PathBuf,
        error: std::io::Error,
    },
    #[error("{file}: not valid JSON: {error}")]
    Json {
        file: PathBuf,
        error: serde_json::Error,
    },
    #[error("{file}: field `{field}`: {message}")]
    Field {
        file: PathBuf,
        field: String,
        message: String,
    },
    #[error("{0}")]
    Camera(CameraError),
}

/// Keyframes and a frame count; see [`CameraPath::cameras`].
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    pub keyframes: Vec<Camera>,
    /// Frames rendered along the whole path (at least 1).
    pub frames: u32,
    /// Go back from the last keyframe to the first (closed loops, turntables).
    pub closed: bool,
    /// Real-time playback (`tessera view --script`): each keyframe's time in seconds
    /// (`time_s` on every keyframe, increasing), or None to spread [`Self::duration_s`]
    /// evenly over the segments.
    pub times: Option<Vec<f64>>,
    /// Real-time playback length in seconds (`duration_s`; default `frames / 30`).
    pub duration_s: Option<f64>,
}

impl CameraPath {
    /// Reads a path file. `width`/`height` are the image size (keyframes may omit them;
    /// when present they must be valid but the image size wins).
    pub fn from_file(file: &Path, width: u32, height: u32) -> Result<CameraPath, PathError> {
        let text = std::fs::read_to_string(file).map_err(|error| PathError::Io {
            file: file.to_owned(),
            error,
        })?;
        Self::from_json_str(&text, file, width, height)
    }

    /// Parses a path document; `file` names it in errors.
    pub fn from_json_str(
        text: &str,
        file: &Path,
        width: u32,
        height: u32,
    ) -> Result<CameraPath, PathError> {
        let value: Value = serde_json::from_str(text).map_err(|error| PathError::Json {
            file: file.to_owned(),
            error,
        })?;
        let field = |field: &str, message: String| PathError::Field {
            file: file.to_owned(),
            field: field.to_owned(),
            message,
        };
        let obj = value.as_object().ok_or_else(|| {
            field(
                "(top level)",
                "expected an object with `frames` and `keyframes`".into(),
            )
        })?;
        if let Some(k) = obj.keys().find(|k| !PATH_FIELDS.contains(&k.as_str())) {
            return Err(field(
                k,
                "unknown field (a path has frames, loop, keyframes)".into(),
            ));
        }
        let frames = match obj.get("frames") {
            None => {
                return Err(field(
                    "frames",
                    "missing (number of frames to render)".into(),
                ))
            }
            Some(v) => match v.as_u64() {
                Some(n) if (1..=1_000_000).contains(&n) => n as u32,
                _ => {
                    return Err(field(
                        "frames",
                        format!("expected an integer from 1 to 1000000, got {v}"),
                    ))
                }
            },
        };
        let closed = match obj.get("loop") {
            None => false,
            Some(Value::Bool(b)) => *b,
            Some(v) => return Err(field("loop", format!("expected true or false, got {v}"))),
        };
        let duration_s = match obj.get("duration_s") {
            None => None,
            Some(v) => match v.as_f64() {
                Some(d) if d.is_finite() && d > 0.0 && d <= 1e7 => Some(d),
                _ => {
                    return Err(field(
                        "duration_s",
                        format!("expected a number of seconds in (0, 1e7], got {v}"),
                    ))
                }
            },
        };
        let list = match obj.get("keyframes") {
            None => return Err(field("keyframes", "missing (a list of cameras)".into())),
            Some(Value::Array(a)) if !a.is_empty() => a,
            Some(v) => {
                return Err(field(
                    "keyframes",
                    format!("expected a non-empty array of cameras, got {v}"),
                ))
            }
        };
        let mut keyframes = Vec::with_capacity(list.len());
        let mut times = Vec::new();
        for (i, k) in list.iter().enumerate() {
            let mut k = k.clone();
            if let Some(o) = k.as_object_mut() {
                // A keyframe's size must agree with the image's: the screen-space error
                // is measured in these pixels, so a silent override would change the cut.
                for (name, size, flag) in
                    [("width", width, "--width"), ("height", height, "--height")]
                {
                    if let Some(v) = o.get(name) {
                        if v.as_u64().is_some_and(|n| n != u64::from(size)) {
                            return Err(field(
                                &format!("keyframes[{i}].{name}"),
                                format!(
                                    "{v} differs from the image {name} {size} ({flag}): leave it out, or give {flag} {v}"
                                ),
                            ));
                        }
                    }
                }
                o.entry("width").or_insert(Value::from(width));
                o.entry("height").or_insert(Value::from(height));
                if let Some(t) = o.remove("time_s") {
                    let name = format!("keyframes[{i}].time_s");
                    match t.as_f64() {
                        Some(t) if (0.0..=1e7).contains(&t) => {
                            if times.last().is_some_and(|&p| t <= p) {
                                return Err(field(
                                    &name,
                                    format!("must be later than the keyframe before, got {t}"),
                                ));
                            }
                            if times.len() != i {
                                return Err(field(
                                    &name,
                                    "give `time_s` on every keyframe or on none".into(),
                                ));
                            }
                            times.push(t);
                        }
                        _ => {
                            return Err(field(
                                &name,
                                format!("expected seconds from 0 to 1e7, got {t}"),
                            ))
                        }
                    }
                } else if !times.is_empty() {
                    return Err(field(
                        &format!("keyframes[{i}].time_s"),
                        "give `time_s` on every keyframe or on none".into(),
                    ));
                }
            }
            let mut cam = Camera::from_json_value(&k).map_err(|e| {
                PathError::Camera(
                    e.with_field_prefix(&format!("keyframes[{i}]"))
                        .with_origin(file),
                )
            })?;
            cam.width = width;
            cam.height = height;
            keyframes.push(cam);
        }
        if closed && !times.is_empty() {
            return Err(field(
                "loop",
                "a looping path cannot have keyframe times (use duration_s)".into(),
            ));
        }
        if !times.is_empty() && duration_s.is_some() {
            return Err(field(
                "duration_s",
                "give keyframe times or a duration, not both".into(),
            ));
        }
        Ok(CameraPath {
            keyframes,
            frames,
            closed,
            times: (!times.is_empty()).then_some(times),
            duration_s,
        })
    }

    /// Seconds a real-time playback of the path lasts: the last keyframe's `time_s`, or
    /// `duration_s`, or `frames / 30`.
    pub fn playback_seconds(&self) -> f64 {
        match (&self.times, self.duration_s) {
            (Some(t), _) => t.last().copied().unwrap_or(0.0),
            (None, Some(d)) => d,
            (None, None) => f64::from(self.frames.max(1)) / 30.0,
        }
    }

    /// The camera at `t_s` seconds into a real-time playback (clamped to the path):
    /// between the keyframes whose times bracket it, interpolated as [`Self::cameras`]
    /// does; without keyframe times the segments share the duration evenly.
    pub fn camera_at(&self, t_s: f64) -> Camera {
        let k = self.keyframes.len();
        if k == 1 {
            return self.keyframes[0].clone();
        }
        let t = if t_s.is_finite() { t_s.max(0.0) } else { 0.0 };
        let (s, f) = match &self.times {
            Some(times) => {
                if t <= times[0] {
                    return self.keyframes[0].clone();
                }
                match times.iter().position(|&x| x > t) {
                    None => return self.keyframes[k - 1].clone(),
                    Some(j) => (j - 1, (t - times[j - 1]) / (times[j] - times[j - 1])),
                }
            }
            None => {
                let segments = if self.closed { k } else { k - 1 };
                let d = self.playback_seconds();
                let u = (t / d).min(1.0) * segments as f64;
                let s = (u.floor() as usize).min(segments - 1);
                (s, u - s as f64)
            }
        };
        lerp_camera(&self.keyframes[s], &self.keyframes[(s + 1) % k], f)
    }

    /// An orbit of `frames` frames around a bounding sphere: the whole sphere in view
    /// (distance so it fills ~80% of the height), 20 degrees above the equator, around
    /// +Y.
    pub fn orbit(bounds: [f64; 4], frames: u32, width: u32, height: u32) -> CameraPath {
        let fov = 45.0f64;
        let r = bounds[3].max(1e-9);
        let dist = r / (0.8 * (fov.to_radians() / 2.0).tan()).max(1e-6) / 1.0;
        let dist = dist.max(r * 1.05);
        let n = frames.max(1);
        let keyframes = (0..n)
            .map(|i| {
                let o = Orbit {
                    center: [bounds[0], bounds[1], bounds[2]],
                    radius: dist,
                    azimuth_deg: 360.0 * f64::from(i) / f64::from(n),
                    elevation_deg: 20.0,
                    up: [0.0, 1.0, 0.0],
                    fov_y_deg: fov,
                    width,
                    height,
                };
                // Valid by construction: positive radius, elevation below 90 degrees.
                Camera::orbit(&o).expect("orbit camera")
            })
            .collect();
        CameraPath {
            keyframes,
            frames: n,
            closed: false,
            times: None,
            duration_s: None,
        }
    }

    /// The camera of every frame. Frames are spread evenly over the keyframe segments
    /// (the first frame is the first keyframe; the last is the last keyframe, or for a
    /// closed path the frame before returning to the first); position and target are
    /// interpolated linearly, `up` linearly then renormalised, the field of view
    /// linearly. A path with as many frames as keyframes renders the keyframes as is.
    pub fn cameras(&self) -> Vec<Camera> {
        (0..self.frames.max(1)).map(|i| self.camera(i)).collect()
    }

    /// The camera of frame `i` (`0..frames`), as [`Self::cameras`] would give it,
    /// computed on its own: a path of 10^9 frames needs no list of them.
    pub fn camera(&self, i: u32) -> Camera {
        let k = self.keyframes.len();
        let n = self.frames.max(1) as usize;
        let i = (i as usize).min(n - 1);
        if k == 1 {
            return self.keyframes[0].clone();
        }
        if n == k && !self.closed {
            return self.keyframes[i].clone();
        }
        let segments = if self.closed { k } else { k - 1 };
        let t = if self.closed {
            i as f64 / n as f64 * segments as f64
        } else if n == 1 {
            0.0
        } else {
            i as f64 / (n - 1) as f64 * segments as f64
        };
        let s = (t.floor() as usize).min(segments - 1);
        let f = t - s as f64;
        lerp_camera(&self.keyframes[s], &self.keyframes[(s + 1) % k], f)
    }
}

fn lerp_camera(a: &Camera, b: &Camera, f: f64) -> Camera {
    let l = |x: [f64; 3], y: [f64; 3]| DVec3::from(x).lerp(DVec3::from(y), f);
    let position = l(a.position, b.position);
    let mut target = l(a.target, b.target);
    if (target - position).length() == 0.0 {
        target = DVec3::from(a.target);
    }
    let up = l(a.up, b.up);
    let up = if up.length() > 0.0 {
        up
    } else {
        DVec3::from(a.up)
    };
    let fov = a.fov_y_deg + (b.fov_y_deg - a.fov_y_deg) * f;
    let candidate = Camera {
        position: position.to_array(),
        target: target.to_array(),
        up: up.to_array(),
        fov_y_deg: fov,
        width: a.width,
        height: a.height,
    };
    // A degenerate in-between (up parallel to the view direction) falls back to the
    // nearer keyframe.
    if candidate.validate().is_ok() {
        candidate
    } else if f < 0.5 {
        a.clone()
    } else {
        b.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CameraPath, PathError> {
        CameraPath::from_json_str(text, Path::new("p.json"), 640, 480)
    }

    const KEY: &str = r#"{"position":[0,0,5],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":45}"#;

    #[test]
    fn interpolates_keyframes() {
        let text = format!(
            r#"{{"frames": 5, "keyframes": [{KEY}, {{"position":[0,0,9],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":65}}]}}"#
        );
        let p = parse(&text).unwrap();
        let c = p.cameras();
        assert_eq!(c.len(), 5);
        assert_eq!(c[0].position, [0.0, 0.0, 5.0]);
        assert_eq!(c[2].position, [0.0, 0.0, 7.0]);
        assert_eq!(c[4].position, [0.0, 0.0, 9.0]);
        assert_eq!(c[2].fov_y_deg, 55.0);
        assert!(c.iter().all(|c| c.width == 640 && c.height == 480));
        let closed = parse(&text.replace("\"frames\": 5", "\"frames\": 4, \"loop\": true"))
            .unwrap()
            .cameras();
        let z: Vec<f64> = closed.iter().map(|c| c.position[2]).collect();
        assert_eq!(z, [5.0, 7.0, 9.0, 7.0]);
    }

    #[test]
    fn errors_name_the_field() {
        let cases = [
            (r#"{"keyframes": []}"#.to_owned(), "`frames`"),
            (r#"{"frames": 3}"#.to_owned(), "`keyframes`"),
            (
                format!(r#"{{"frames": 0, "keyframes": [{KEY}]}}"#),
                "`frames`",
            ),
            (
                format!(r#"{{"frames": 2, "keyframes": [{KEY}], "fps": 3}}"#),
                "`fps`",
            ),
            (
                format!(r#"{{"frames": 2, "loop": 1, "keyframes": [{KEY}]}}"#),
                "`loop`",
            ),
            (
                format!(
                    r#"{{"frames": 2, "keyframes": [{KEY}, {}]}}"#,
                    KEY.replace("45", "\"45\"")
                ),
                "`keyframes[1].fov_y_deg`",
            ),
            (
                format!(
                    r#"{{"frames": 2, "keyframes": [{}]}}"#,
                    KEY.replace("\"up\":[0,1,0],", "")
                ),
                "`keyframes[0].up`",
            ),
            ("[1,2]".to_owned(), "(top level)"),
        ];
        for (text, field) in cases {
            let e = parse(&text).expect_err(&text).to_string();
            assert!(
                e.contains(field) && e.starts_with("p.json"),
                "{text} -> {e}"
            );
        }
        let e = parse("{").unwrap_err().to_string();
        assert!(e.contains("not valid JSON"), "{e}");
    }

    #[test]
    fn keyframe_sizes_must_agree_with_the_image() {
        let with = KEY.replace("45}", "45,\"width\":640,\"height\":480}");
        parse(&format!(r#"{{"frames": 1, "keyframes": [{with}]}}"#)).expect("same size");
        let other = KEY.replace("45}", "45,\"width\":800}");
        let e = parse(&format!(r#"{{"frames": 1, "keyframes": [{other}]}}"#))
            .expect_err("800 != 640")
            .to_string();
        assert!(
            e.contains("keyframes[0].width") && e.contains("--width"),
            "{e}"
        );
    }

    #[test]
    fn real_time_playback_follows_keyframe_times() {
        let b = r#"{"position":[0,0,9],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":45,"time_s":2}"#;
        let a = KEY.replace("45}", "45,\"time_s\":0.5}");
        let p = parse(&format!(r#"{{"frames": 3, "keyframes": [{a}, {b}]}}"#)).unwrap();
        assert_eq!(p.playback_seconds(), 2.0);
        assert_eq!(p.camera_at(0.0).position, [0.0, 0.0, 5.0]);
        assert_eq!(p.camera_at(1.25).position, [0.0, 0.0, 7.0]);
        assert_eq!(p.camera_at(5.0).position, [0.0, 0.0, 9.0]);
        // Even spread over duration_s without times.
        let b2 = b.replace(",\"time_s\":2", "");
        let p = parse(&format!(
            r#"{{"frames": 3, "duration_s": 4, "keyframes": [{KEY}, {b2}]}}"#
        ))
        .unwrap();
        assert_eq!(p.camera_at(2.0).position, [0.0, 0.0, 7.0]);
        assert_eq!(p.playback_seconds(), 4.0);
        // Times on some keyframes only, decreasing times, both times and a duration.
        for bad in [
            format!(r#"{{"frames": 3, "keyframes": [{KEY}, {b}]}}"#),
            format!(
                r#"{{"frames": 3, "keyframes": [{a}, {}]}}"#,
                b.replace(":2}", ":0.1}")
            ),
            format!(r#"{{"frames": 3, "duration_s": 3, "keyframes": [{a}, {b}]}}"#),
            format!(r#"{{"frames": 3, "duration_s": -1, "keyframes": [{KEY}]}}"#),
        ] {
            let e = parse(&bad).expect_err(&bad).to_string();
            assert!(
                e.contains("time_s") || e.contains("duration_s"),
                "{bad} -> {e}"
            );
        }
    }

    #[test]
    fn orbit_circles_the_sphere() {
        let p = CameraPath::orbit([1.0, 2.0, 3.0, 2.0], 8, 320, 200);
        let c = p.cameras();
        assert_eq!(c.len(), 8);
        for cam in &c {
            let d = (DVec3::from(cam.position) - DVec3::new(1.0, 2.0, 3.0)).length();
            assert!(
                d > 2.0
                    && (d - (DVec3::from(c[0].position) - DVec3::new(1.0, 2.0, 3.0)).length())
                        .abs()
                        < 1e-9
            );
            assert_eq!(cam.target, [1.0, 2.0, 3.0]);
        }
    }
}
