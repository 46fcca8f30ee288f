//! The one camera every Tessera command shares, and its JSON file format
//! (`docs/camera.md` is the manual; keep the two in step).
//!
//! Why it lives here: selection is the first consumer of a camera (the refinement test
//! needs the eye, the field of view and the image height; culling needs the frustum), and
//! every later consumer (renderer, image-repository builder, server, browser) reads the
//! same JSON. Parsing goes through [`serde_json::Value`] rather than a plain derive so
//! that every error names the offending field (serde's derive says "invalid type" without
//! saying where) and the file it came from.
//!
//! Coordinates: a camera is given in MODEL coordinates, `f64`, because models may be
//! georeferenced far from the origin. Node geometry in the model file is stored relative
//! to `Header::cube_origin` in `f32`; the `*_local` helpers subtract that origin in `f64`
//! first and only then round to `f32`, so nothing loses precision.
//!
//! View space follows glam's right-handed convention: X right, Y up, looking down -Z.

use std::fmt;
use std::path::{Path, PathBuf};

use glam::{DVec3, Mat4, Vec3, Vec4};
use serde::{Deserialize, Deserializer, Serialize};
use serde_json::Value;

/// The JSON field names of a camera, in the order they are written.
pub const CAMERA_FIELDS: [&str; 6] = ["position", "target", "up", "fov_y_deg", "width", "height"];

/// `up` counts as parallel to the view direction when the sine of the angle between them
/// is below this: at 1e-6 the derived right vector would carry about six significant
/// digits, and any sane camera is many orders of magnitude away from it.
const PARALLEL_SIN_EPS: f64 = 1e-6;

/// Largest coordinate of a camera's position or target (models lie within +-1e15).
pub const MAX_COORDINATE: f64 = 1e15;

/// Smallest distance between position and target, relative to their coordinates:
/// 1e-9 keeps the view direction within ~1e-6 rad of what was meant.
pub const MIN_RELATIVE_DISTANCE: f64 = 1e-9;

/// A pinhole camera in model coordinates. Build it with [`Camera::from_json_str`],
/// [`Camera::from_json_file`], [`Camera::new`] or [`Camera::orbit`], all of which
/// validate; the fields are public for reading and for tools that tweak a valid camera
/// (call [`Camera::validate`] after editing).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Camera {
    /// Eye position, model coordinates.
    pub position: [f64; 3],
    /// Point looked at, model coordinates; must differ from `position`.
    pub target: [f64; 3],
    /// Approximate up direction; non-zero, not parallel to `target - position`. Only its
    /// direction matters (it is orthogonalised against the view direction).
    pub up: [f64; 3],
    /// Full vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f64,
    /// Image width in pixels, at least 1.
    pub width: u32,
    /// Image height in pixels, at least 1; the screen-space error is measured in these
    /// pixels.
    pub height: u32,
}

/// An orthonormal view basis in model space (right-handed: `right x up = -forward`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewBasis {
    /// Screen +X.
    pub right: DVec3,
    /// Screen +Y: `up` made orthogonal to `forward`.
    pub up: DVec3,
    /// Unit direction from the eye to the target.
    pub forward: DVec3,
}

/// The view frustum in a model's LOCAL frame (model coordinates minus `cube_origin`),
/// without a far plane. Each plane is `(n, d)` with `n` a unit inward normal: a point `p`
/// is inside when `n . p + d >= 0` for every plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    /// Left, right, bottom, top, and the plane through the eye facing forward (so
    /// everything behind the eye is outside).
    pub planes: [Vec4; 5],
}

impl Frustum {
    /// True when the sphere (`center`, `radius`) lies entirely outside one of the planes.
    /// Conservative: a sphere near a frustum corner may be reported inside.
    #[inline]
    pub fn sphere_outside(&self, center: Vec3, radius: f32) -> bool {
        self.planes
            .iter()
            .any(|p| p.x * center.x + p.y * center.y + p.z * center.z + p.w < -radius)
    }
}

/// Parameters of [`Camera::orbit`]: a camera on a sphere around `center`, looking at it.
#[derive(Clone, Debug, PartialEq)]
pub struct Orbit {
    /// Point looked at, model coordinates.
    pub center: [f64; 3],
    /// Distance from the eye to `center`, model units (> 0).
    pub radius: f64,
    /// Rotation around `up`, degrees. 0 is a fixed but arbitrary direction perpendicular
    /// to `up` (`DVec3::any_orthonormal_pair`); increasing values turn counter-clockwise
    /// seen from above.
    pub azimuth_deg: f64,
    /// Angle above the plane perpendicular to `up`, degrees; clamped to +-89.9 so `up`
    /// never becomes parallel to the view direction.
    pub elevation_deg: f64,
    /// The world up direction (default +Y).
    pub up: [f64; 3],
    /// Vertical field of view, degrees (default 60).
    pub fov_y_deg: f64,
    /// Image width, pixels (default 1280).
    pub width: u32,
    /// Image height, pixels (default 720).
    pub height: u32,
}

impl Default for Orbit {
    fn default() -> Self {
        Orbit {
            center: [0.0; 3],
            radius: 1.0,
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
            width: 1280,
            height: 720,
        }
    }
}

/// What went wrong with a camera, without the where (see [`CameraError`]).
#[derive(Debug, thiserror::Error)]
pub enum CameraErrorKind {
    /// The file could not be read.
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    /// The text is not JSON.
    #[error("not valid JSON: {0}")]
    Json(serde_json::Error),
    /// The JSON is not an object.
    #[error("expected a JSON object with fields position, target, up, fov_y_deg, width, height; got {0}")]
    NotAnObject(String),
    /// A required field is absent.
    #[error("missing (a camera needs position, target, up, fov_y_deg, width, height)")]
    Missing,
    /// A field that is not part of the format (most likely a typo).
    #[error("unknown field (a camera has position, target, up, fov_y_deg, width, height)")]
    Unknown,
    /// The field has the wrong JSON type or shape.
    #[error("expected {expected}, got {got}")]
    WrongType {
        /// What the format wants.
        expected: &'static str,
        /// What the file has.
        got: String,
    },
    /// The field has the right type but an unusable value.
    #[error("{0}")]
    Invalid(String),
}

/// A camera that could not be loaded or is unusable, with the file (when there is one)
/// and the field (when one is to blame). Displays as
/// `cam.json: field `fov_y_deg`: must be in (0, 180), got 190`.
#[derive(Debug)]
pub struct CameraError {
    /// The file the camera came from, if any.
    pub origin: Option<PathBuf>,
    /// The offending field, e.g. `fov_y_deg` (or `keyframes[2].up` once a caller has
    /// added a prefix with [`CameraError::with_field_prefix`]).
    pub field: Option<String>,
    /// What is wrong.
    pub kind: CameraErrorKind,
}

impl CameraError {
    fn new(field: Option<&str>, kind: CameraErrorKind) -> Self {
        CameraError {
            origin: None,
            field: field.map(str::to_owned),
            kind,
        }
    }

    fn invalid(field: &str, message: String) -> Self {
        Self::new(Some(field), CameraErrorKind::Invalid(message))
    }

    /// Attaches the file name shown in front of the message.
    pub fn with_origin(mut self, origin: impl Into<PathBuf>) -> Self {
        self.origin = Some(origin.into());
        self
    }

    /// Qualifies the field for cameras nested in a larger document (camera paths):
    /// `fov_y_deg` becomes `keyframes[2].fov_y_deg`; an error with no field gets the
    /// prefix as its field.
    pub fn with_field_prefix(mut self, prefix: &str) -> Self {
        self.field = Some(match self.field.take() {
            Some(f) => format!("{prefix}.{f}"),
            None => prefix.to_owned(),
        });
        self
    }
}

impl fmt::Display for CameraError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(origin) = &self.origin {
            write!(f, "{}: ", origin.display())?;
        }
        if let Some(field) = &self.field {
            write!(f, "field `{field}`: ")?;
        }
        write!(f, "{}", self.kind)
    }
}

// The underlying io/json error is already part of the message, so `source` stays empty:
// an error chain printer would otherwise show it twice.
impl std::error::Error for CameraError {}

/// A short description of a JSON value for error messages.
fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".to_owned(),
        Value::Bool(b) => format!("boolean {b}"),
        Value::Number(n) => format!("number {n}"),
        Value::String(s) if s.len() <= 40 => format!("string {s:?}"),
        Value::String(_) => "a string".to_owned(),
        Value::Array(a) => format!("an array of {} elements", a.len()),
        Value::Object(_) => "an object".to_owned(),
    }
}

fn get_vec3(obj: &serde_json::Map<String, Value>, field: &str) -> Result<[f64; 3], CameraError> {
    const EXPECTED: &str = "an array of 3 numbers [x, y, z]";
    let v = obj
        .get(field)
        .ok_or_else(|| CameraError::new(Some(field), CameraErrorKind::Missing))?;
    let wrong = |got: String| {
        CameraError::new(
            Some(field),
            CameraErrorKind::WrongType {
                expected: EXPECTED,
                got,
            },
        )
    };
    let arr = v.as_array().ok_or_else(|| wrong(describe(v)))?;
    if arr.len() != 3 {
        return Err(wrong(describe(v)));
    }
    let mut out = [0.0; 3];
    for (i, e) in arr.iter().enumerate() {
        out[i] = e
            .as_f64()
            .ok_or_else(|| wrong(format!("element {i} is {}", describe(e))))?;
    }
    Ok(out)
}

fn get_f64(obj: &serde_json::Map<String, Value>, field: &str) -> Result<f64, CameraError> {
    let v = obj
        .get(field)
        .ok_or_else(|| CameraError::new(Some(field), CameraErrorKind::Missing))?;
    v.as_f64().ok_or_else(|| {
        CameraError::new(
            Some(field),
            CameraErrorKind::WrongType {
                expected: "a number",
                got: describe(v),
            },
        )
    })
}

fn get_pixels(obj: &serde_json::Map<String, Value>, field: &str) -> Result<u32, CameraError> {
    let v = obj
        .get(field)
        .ok_or_else(|| CameraError::new(Some(field), CameraErrorKind::Missing))?;
    let n = v.as_u64().ok_or_else(|| {
        CameraError::new(
            Some(field),
            CameraErrorKind::WrongType {
                expected: "a positive integer (pixels)",
                got: describe(v),
            },
        )
    })?;
    u32::try_from(n)
        .map_err(|_| CameraError::invalid(field, format!("must be at most {}, got {n}", u32::MAX)))
}

fn dvec(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

impl Camera {
    /// A validated camera from its parts.
    pub fn new(
        position: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
        fov_y_deg: f64,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let camera = Camera {
            position,
            target,
            up,
            fov_y_deg,
            width,
            height,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// Parses a camera from JSON text (see `docs/camera.md`). Errors name the field but
    /// no file; [`Camera::from_json_file`] adds the file.
    pub fn from_json_str(text: &str) -> Result<Camera, CameraError> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| CameraError::new(None, CameraErrorKind::Json(e)))?;
        Camera::from_json_value(&value)
    }

    /// Reads and parses a camera file; every error starts with the path.
    pub fn from_json_file(path: impl AsRef<Path>) -> Result<Camera, CameraError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|e| CameraError::new(None, CameraErrorKind::Io(e)).with_origin(path))?;
        Camera::from_json_str(&text).map_err(|e| e.with_origin(path))
    }

    /// Builds a camera from an already parsed JSON value (a camera nested in a larger
    /// document, such as a keyframe of a camera path).
    pub fn from_json_value(value: &Value) -> Result<Camera, CameraError> {
        let obj = value
            .as_object()
            .ok_or_else(|| CameraError::new(None, CameraErrorKind::NotAnObject(describe(value))))?;
        if let Some(unknown) = obj.keys().find(|k| !CAMERA_FIELDS.contains(&k.as_str())) {
            return Err(CameraError::new(Some(unknown), CameraErrorKind::Unknown));
        }
        let camera = Camera {
            position: get_vec3(obj, "position")?,
            target: get_vec3(obj, "target")?,
            up: get_vec3(obj, "up")?,
            fov_y_deg: get_f64(obj, "fov_y_deg")?,
            width: get_pixels(obj, "width")?,
            height: get_pixels(obj, "height")?,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// The camera as pretty JSON in the documented format.
    pub fn to_json_string(&self) -> String {
        // Serialising plain arrays and numbers cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks every rule of the format; the error names the field to blame.
    pub fn validate(&self) -> Result<(), CameraError> {
        for (field, v) in [
            ("position", self.position),
            ("target", self.target),
            ("up", self.up),
        ] {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(CameraError::invalid(
                    field,
                    format!("coordinates must be finite, got {v:?}"),
                ));
            }
            // Models lie within +-1e15 (the header's bound); beyond it differences of
            // coordinates lose the precision a view direction needs (and squares
            // overflow: 1e300 read as "target equals position").
            if field != "up" && v.iter().any(|c| c.abs() > MAX_COORDINATE) {
                return Err(CameraError::invalid(
                    field,
                    format!("coordinates must lie within +-1e15 (where models are), got {v:?}"),
                ));
            }
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(CameraError::invalid(
                "fov_y_deg",
                format!("must be in (0, 180), got {}", self.fov_y_deg),
            ));
        }
        for (field, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 {
                return Err(CameraError::invalid(
                    field,
                    "must be at least 1, got 0".into(),
                ));
            }
        }
        let dir = dvec(self.target) - dvec(self.position);
        let dir_len = dir.length();
        if !(dir_len > 0.0 && dir_len.is_finite()) {
            return Err(CameraError::invalid(
                "target",
                "equals position, so there is no view direction".into(),
            ));
        }
        // The direction comes from a difference of coordinates: a target a few ulps from
        // the position gives a direction off by degrees (a view of nothing).
        let scale = dvec(self.position)
            .abs()
            .max(dvec(self.target).abs())
            .max_element();
        if dir_len < scale * MIN_RELATIVE_DISTANCE {
            return Err(CameraError::invalid(
                "target",
                format!(
                    "is only {dir_len:e} from position: at coordinates of {scale:e} the view \
                     direction is not defined that finely (keep them at least {:e} apart)",
                    scale * MIN_RELATIVE_DISTANCE
                ),
            ));
        }
        let up = dvec(self.up);
        let up_len = up.length();
        if up_len == 0.0 {
            return Err(CameraError::invalid("up", "has zero length".into()));
        }
        if !up_len.is_finite() {
            return Err(CameraError::invalid(
                "up",
                format!(
                    "is too long to normalise, got {:?} (only its direction matters)",
                    self.up
                ),
            ));
        }
        let sin = ((dir / dir_len).cross(up / up_len)).length();
        if sin.is_nan() || sin < PARALLEL_SIN_EPS {
            return Err(CameraError::invalid(
                "up",
                format!(
                    "is parallel to the view direction (target - position = {:?})",
                    dir.to_array()
                ),
            ));
        }
        Ok(())
    }

    /// A camera on a sphere around `orbit.center`, looking at it (turntables, tests,
    /// image-repository grids).
    pub fn orbit(orbit: &Orbit) -> Result<Camera, CameraError> {
        let up = dvec(orbit.up);
        let up_len = up.length();
        if up_len.is_nan() || up_len <= 0.0 {
            return Err(CameraError::invalid("up", "has zero length".into()));
        }
        if !(orbit.radius > 0.0 && orbit.radius.is_finite()) {
            return Err(CameraError::invalid(
                "radius",
                format!("must be positive and finite, got {}", orbit.radius),
            ));
        }
        let up = up.normalize();
        let (e1, e2) = up.any_orthonormal_pair();
        let az = orbit.azimuth_deg.to_radians();
        let el = orbit.elevation_deg.clamp(-89.9, 89.9).to_radians();
        let dir_out = (e1 * az.cos() + e2 * az.sin()) * el.cos() + up * el.sin();
        let center = dvec(orbit.center);
        Camera::new(
            (center + dir_out * orbit.radius).to_array(),
            orbit.center,
            orbit.up,
            orbit.fov_y_deg,
            orbit.width,
            orbit.height,
        )
    }

    /// Width / height.
    pub fn aspect(&self) -> f64 {
        f64::from(self.width) / f64::from(self.height)
    }

    /// Full vertical field of view in radians.
    pub fn fov_y_rad(&self) -> f64 {
        self.fov_y_deg.to_radians()
    }

    /// Pixels covered by one model unit seen face-on at distance one:
    /// `height / (2 tan(fov_y / 2))`. A length `e` at distance `d` spans about
    /// `e * projection_scale_px() / d` pixels.
    pub fn projection_scale_px(&self) -> f64 {
        f64::from(self.height) / (2.0 * (0.5 * self.fov_y_rad()).tan())
    }

    /// The point drawn at pixel (`x`, `y`) (pixel units, top-left origin; the pixel's
    /// centre is taken) of a frame of this camera whose reversed-Z depth buffer holds
    /// `depth` there (1 at `near`, 0 at `far`, as the renderer's projection makes it), in
    /// model coordinates. None for the background (`depth <= 0`), a pixel outside the
    /// image or a non-finite input. The inverse of the reversed perspective projection:
    /// view depth `z = near * far / (depth * (far - near) + near)`, along the pixel's
    /// ray. One formula for every front end: the desktop viewer's depth readback and the
    /// browser's one-pixel pick both unproject through it.
    pub fn point_at_depth(
        &self,
        x: f64,
        y: f64,
        depth: f32,
        (near, far): (f64, f64),
    ) -> Option<DVec3> {
        let d = f64::from(depth);
        if !(d > 0.0 && d.is_finite() && near > 0.0 && far > near)
            || !(x >= 0.0 && y >= 0.0 && x < f64::from(self.width) && y < f64::from(self.height))
        {
            return None;
        }
        let z = near * far / (d * (far - near) + near);
        let b = self.basis();
        let tan_y = (0.5 * self.fov_y_rad()).tan();
        let ndc_x = (x.floor() + 0.5) / f64::from(self.width) * 2.0 - 1.0;
        let ndc_y = 1.0 - (y.floor() + 0.5) / f64::from(self.height) * 2.0;
        let dir = b.forward + b.right * (ndc_x * tan_y * self.aspect()) + b.up * (ndc_y * tan_y);
        let p = dvec(self.position) + dir * z;
        p.is_finite().then_some(p)
    }

    /// The orthonormal view basis (model space).
    pub fn basis(&self) -> ViewBasis {
        let forward = (dvec(self.target) - dvec(self.position)).normalize();
        let right = forward.cross(dvec(self.up)).normalize();
        let up = right.cross(forward);
        ViewBasis { right, up, forward }
    }

    /// The eye in the model's local frame (`position - cube_origin`, subtracted in f64).
    pub fn eye_local(&self, cube_origin: [f64; 3]) -> Vec3 {
        (dvec(self.position) - dvec(cube_origin)).as_vec3()
    }

    /// The view matrix (local frame -> right-handed view space, -Z forward), built in
    /// f64 and rounded to f32.
    pub fn view_matrix_local(&self, cube_origin: [f64; 3]) -> Mat4 {
        let b = self.basis();
        let eye = dvec(self.position) - dvec(cube_origin);
        glam::dcamera::rh::view::look_to_mat4(eye, b.forward, b.up).as_mat4()
    }

    /// A perspective projection with depth mapped to [0, 1] (WebGPU / wgpu convention).
    pub fn projection_matrix(&self, near: f32, far: f32) -> Mat4 {
        glam::camera::rh::proj::directx::perspective(
            self.fov_y_rad() as f32,
            self.aspect() as f32,
            near,
            far,
        )
    }

    /// The frustum planes in the model's local frame (computed in f64, stored as f32).
    pub fn frustum_local(&self, cube_origin: [f64; 3]) -> Frustum {
        let b = self.basis();
        let eye = dvec(self.position) - dvec(cube_origin);
        let tan_y = (0.5 * self.fov_y_rad()).tan();
        let tan_x = tan_y * self.aspect();
        // A point p (relative to the eye) with x = p.right, y = p.up, z = p.forward is
        // inside the left plane when x >= -z tan_x, i.e. p . (right + forward tan_x) >= 0;
        // the other side planes follow by symmetry.
        let normals = [
            b.right + b.forward * tan_x,
            -b.right + b.forward * tan_x,
            b.up + b.forward * tan_y,
            -b.up + b.forward * tan_y,
            b.forward,
        ];
        let planes = normals.map(|n| {
            let n = n.normalize();
            Vec4::new(n.x as f32, n.y as f32, n.z as f32, (-n.dot(eye)) as f32)
        });
        Frustum { planes }
    }
}

impl<'de> Deserialize<'de> for Camera {
    /// Goes through [`Camera::from_json_value`], so a camera embedded in any serde
    /// document gets the same validation and field-naming errors.
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let value = Value::deserialize(deserializer)?;
        Camera::from_json_value(&value).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"{"position": [0, 0, 10], "target": [0, 0, 0], "up": [0, 1, 0],
        "fov_y_deg": 60, "width": 640, "height": 480}"#;

    fn with(field: &str, value: &str) -> String {
        let mut v: Value = serde_json::from_str(GOOD).unwrap();
        v[field] = serde_json::from_str(value).unwrap();
        v.to_string()
    }

    fn without(field: &str) -> String {
        let mut v: Value = serde_json::from_str(GOOD).unwrap();
        v.as_object_mut().unwrap().remove(field);
        v.to_string()
    }

    fn err(text: &str) -> String {
        Camera::from_json_str(text).unwrap_err().to_string()
    }

    #[test]
    fn parses_the_documented_example() {
        let c = Camera::from_json_str(GOOD).unwrap();
        assert_eq!(c.position, [0.0, 0.0, 10.0]);
        assert_eq!(c.fov_y_deg, 60.0);
        assert_eq!((c.width, c.height), (640, 480));
    }

    #[test]
    fn json_round_trips_and_serde_deserialize_validates() {
        let c = Camera::from_json_str(GOOD).unwrap();
        let back = Camera::from_json_str(&c.to_json_string()).unwrap();
        assert_eq!(c, back);
        let via_serde: Camera = serde_json::from_str(GOOD).unwrap();
        assert_eq!(c, via_serde);
        // Nested inside another document, the field is still named.
        let e = serde_json::from_str::<Vec<Camera>>(&format!("[{}]", with("fov_y_deg", "190")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("field `fov_y_deg`: must be in (0, 180), got 190"),
            "{e}"
        );
    }

    #[test]
    fn file_errors_name_the_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cam.json");
        std::fs::write(&path, with("fov_y_deg", "190")).unwrap();
        let e = Camera::from_json_file(&path).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "{}: field `fov_y_deg`: must be in (0, 180), got 190",
                path.display()
            )
        );
        let missing = dir.path().join("nope.json");
        let e = Camera::from_json_file(&missing).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: cannot read:", missing.display())),
            "{e}"
        );
        std::fs::write(&path, "{ not json").unwrap();
        let e = Camera::from_json_file(&path).unwrap_err().to_string();
        assert!(e.contains("cam.json: not valid JSON"), "{e}");
    }

    #[test]
    fn missing_unknown_and_wrong_type_fields_are_named() {
        for f in CAMERA_FIELDS {
            let e = err(&without(f));
            assert!(e.starts_with(&format!("field `{f}`: missing")), "{e}");
        }
        assert!(err(&with("fov", "60")).starts_with("field `fov`: unknown field"));
        assert_eq!(
            err(&with("fov_y_deg", "\"60\"")),
            "field `fov_y_deg`: expected a number, got string \"60\""
        );
        assert!(err(&with("up", "[0, 1]")).starts_with("field `up`: expected an array of 3"));
        assert!(err(&with("position", "[0, \"a\", 1]")).contains("element 1 is string"));
        assert!(
            err(&with("width", "1.5")).starts_with("field `width`: expected a positive integer")
        );
        assert!(
            err(&with("height", "-3")).starts_with("field `height`: expected a positive integer")
        );
        assert!(err("[1, 2]").starts_with("expected a JSON object"));
    }

    #[test]
    fn bad_values_are_named() {
        assert_eq!(
            err(&with("width", "0")),
            "field `width`: must be at least 1, got 0"
        );
        assert_eq!(
            err(&with("height", "0")),
            "field `height`: must be at least 1, got 0"
        );
        assert!(err(&with("fov_y_deg", "0")).starts_with("field `fov_y_deg`: must be in (0, 180)"));
        assert_eq!(err(&with("up", "[0, 0, 0]")), "field `up`: has zero length");
        assert!(err(&with("up", "[0, 0, -3]")).starts_with("field `up`: is parallel"));
        assert!(err(&with("target", "[0, 0, 10]")).starts_with("field `target`: equals position"));
        assert!(err(&with("width", "5000000000")).starts_with("field `width`: must be at most"));
    }

    #[test]
    fn field_prefix_for_nested_cameras() {
        let e = Camera::from_json_str(&with("up", "[0, 0, 0]"))
            .unwrap_err()
            .with_field_prefix("keyframes[2]")
            .with_origin("path.json");
        assert_eq!(
            e.to_string(),
            "path.json: field `keyframes[2].up`: has zero length"
        );
    }

    #[test]
    fn basis_is_orthonormal_and_right_handed() {
        let c = Camera::new(
            [1.0, 2.0, 3.0],
            [4.0, -1.0, 0.5],
            [0.2, 1.0, 0.1],
            45.0,
            10,
            10,
        )
        .unwrap();
        let b = c.basis();
        for v in [b.right, b.up, b.forward] {
            assert!((v.length() - 1.0).abs() < 1e-12);
        }
        assert!(b.right.dot(b.up).abs() < 1e-12 && b.right.dot(b.forward).abs() < 1e-12);
        assert!((b.right.cross(b.up) + b.forward).length() < 1e-12);
    }

    #[test]
    fn view_matrix_maps_target_to_minus_z_in_local_frame() {
        // A georeferenced camera: large coordinates, small local offsets.
        let origin = [500_000.0, 4_000_000.0, 100.0];
        let c = Camera::new(
            [500_010.0, 4_000_000.0, 110.0],
            [500_010.0, 4_000_005.0, 110.0],
            [0.0, 0.0, 1.0],
            60.0,
            100,
            100,
        )
        .unwrap();
        let view = c.view_matrix_local(origin);
        let target_local = Vec3::new(10.0, 5.0, 10.0);
        let t = view.transform_point3(target_local);
        assert!((t - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-5, "{t}");
        assert_eq!(c.eye_local(origin), Vec3::new(10.0, 0.0, 10.0));
        // The projection puts the target at the screen centre, depth in (0, 1).
        let clip = c.projection_matrix(0.1, 100.0) * t.extend(1.0);
        let ndc = clip.truncate() / clip.w;
        assert!(ndc.x.abs() < 1e-6 && ndc.y.abs() < 1e-6 && ndc.z > 0.0 && ndc.z < 1.0);
    }

    #[test]
    fn frustum_planes_classify_points() {
        let c = Camera::new(
            [0.0, 0.0, 10.0],
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            90.0,
            200,
            100,
        )
        .unwrap();
        let f = c.frustum_local([0.0; 3]);
        // At distance 10 the half-height is 10 and the half-width 20 (aspect 2).
        assert!(!f.sphere_outside(Vec3::ZERO, 0.0));
        assert!(!f.sphere_outside(Vec3::new(19.0, 0.0, 0.0), 0.0));
        assert!(f.sphere_outside(Vec3::new(21.0, 0.0, 0.0), 0.0));
        assert!(!f.sphere_outside(Vec3::new(21.0, 0.0, 0.0), 1.0));
        assert!(f.sphere_outside(Vec3::new(0.0, 11.0, 0.0), 0.1));
        assert!(!f.sphere_outside(Vec3::new(0.0, 9.0, 0.0), 0.0));
        // Behind the eye.
        assert!(f.sphere_outside(Vec3::new(0.0, 0.0, 12.0), 1.0));
        assert!(!f.sphere_outside(Vec3::new(0.0, 0.0, 12.0), 3.0));
        // Shifting the origin shifts the planes.
        let g = c.frustum_local([100.0, 0.0, 0.0]);
        assert!(!g.sphere_outside(Vec3::new(-100.0, 0.0, 0.0), 0.0));
        assert!(g.sphere_outside(Vec3::ZERO, 0.0));
    }

    #[test]
    fn orbit_looks_at_center_from_radius() {
        let c = Camera::orbit(&Orbit {
            center: [1.0, 2.0, 3.0],
            radius: 5.0,
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Orbit::default()
        })
        .unwrap();
        let d = dvec(c.position) - dvec(c.target);
        assert!((d.length() - 5.0).abs() < 1e-9);
        assert!((d.normalize().dot(DVec3::Y) - 20f64.to_radians().sin()).abs() < 1e-9);
        // Straight overhead is clamped rather than parallel to up.
        assert!(Camera::orbit(&Orbit {
            elevation_deg: 90.0,
            ..Orbit::default()
        })
        .is_ok());
        assert!(Camera::orbit(&Orbit {
            radius: 0.0,
            ..Orbit::default()
        })
        .is_err());
    }

    #[test]
    fn projection_scale_matches_definition() {
        let c = Camera::new([0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 90.0, 100, 1000).unwrap();
        assert!((c.projection_scale_px() - 500.0).abs() < 1e-9);
    }

    #[test]
    fn extreme_coordinates_and_near_targets_are_refused_clearly() {
        let cam = |p: [f64; 3], t: [f64; 3], up: [f64; 3]| Camera {
            position: p,
            target: t,
            up,
            fov_y_deg: 45.0,
            width: 64,
            height: 64,
        };
        let err = |c: Camera| c.validate().expect_err("refused").to_string();
        let e = err(cam([1e300, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]));
        assert!(e.contains("position") && e.contains("1e15"), "{e}");
        let e = err(cam([0.0; 3], [0.0, -2e15, 0.0], [0.0, 0.0, 1.0]));
        assert!(e.contains("target") && e.contains("1e15"), "{e}");
        // A few ulps apart at coordinates of 700: the direction would be degrees off.
        let e = err(cam(
            [0.0, -700.0, 100.0],
            [1e-12, -700.0, 100.0],
            [0.0, 0.0, 1.0],
        ));
        assert!(e.contains("target") && e.contains("only"), "{e}");
        let e = err(cam([0.0, -5.0, 0.0], [0.0; 3], [0.0, 0.0, 1e300]));
        assert!(e.contains("up") && e.contains("too long"), "{e}");
        // Tiny but precise: a micro-scale model near the origin.
        cam([0.0, -1e-12, 0.0], [0.0; 3], [0.0, 0.0, 1.0])
            .validate()
            .expect("a 1e-12 view at the origin is exact");
        cam([0.0, -1e14, 0.0], [0.0, 1e14, 0.0], [0.0, 0.0, 1.0])
            .validate()
            .expect("georeferenced coordinates within the bound");
    }
}

/// Near and far planes around `spheres` (centre, radius; model or any frame shared with
/// `eye`), measured along the view direction `forward` (unit), as the depth buffer
/// measures: far just beyond the deepest sphere, near just before the nearest one, but
/// never below `far * 1e-6`. (Distances alone would clip the near side of whatever is off
/// axis: a sphere at distance `d` off the axis reaches the view depth
/// `(c - eye) . forward - r`, less than `d - r`.) Depth is stored reversed (1 at near, 0
/// at far) in a 32-bit float buffer, whose precision is then nearly uniform in
/// `log(depth)`: a ratio of 1e6 between far and near still separates surfaces 1e-5 of
/// their distance apart, so a millimetre detail seen from a few millimetres on a 10 m
/// statue neither clips nor z-fights. No spheres: `(1e-6, 1)`.
pub fn clip_planes_along(
    eye: DVec3,
    forward: DVec3,
    spheres: impl IntoIterator<Item = (DVec3, f64)>,
) -> (f64, f64) {
    let (mut near, mut far) = (f64::INFINITY, 0.0f64);
    for (c, r) in spheres {
        let z = (c - eye).dot(forward);
        far = far.max(z + r);
        near = near.min(z - r);
    }
    if far <= 0.0 || !far.is_finite() {
        return (1e-6, 1.0);
    }
    let far = far * 1.01;
    let near = (near * 0.99).max(far * 1e-6);
    (near, far)
}
