//! Entry points of the fuzz targets (`fuzz/fuzz_targets/{camera,camera_path}.rs`) and of
//! their replay as ordinary tests (`tests/corpus.rs`): one function per target, so the
//! two cannot drift apart.
//!
//! Compiled always rather than behind a feature: the module has no dependency of its
//! own and costs a few dozen lines, while a feature that only the tests and the fuzz
//! crate turn on would be one more configuration to build (and to forget) in CI. It is
//! hidden from the docs and is not an API.
//!
//! The bytes are the JSON text (invalid UTF-8 replaced, as a lenient reader would).
//! Errors are the expected outcome and are returned; a camera that parses but then
//! yields a non-finite view basis, an invalid interpolated camera, or a document whose
//! own serialisation does not parse back, panics, which the fuzzer reports as a crash.

use std::path::Path;

use crate::camera::{Camera, CameraError};
use crate::path::{CameraPath, PathError};

/// The name fuzz inputs carry in error messages.
pub const FUZZ_PATH: &str = "fuzz-input.json";
/// The image size a path's keyframes get.
const SIZE: (u32, u32) = (64, 48);

/// What a valid camera promises its users: a finite orthonormal basis, a finite
/// projection scale, finite frustum planes around its own eye.
fn check_camera(c: &Camera, what: &str) {
    if let Err(e) = c.validate() {
        panic!("{what}: accepted camera {c:?} fails validation: {e}");
    }
    let b = c.basis();
    for (name, v) in [("right", b.right), ("up", b.up), ("forward", b.forward)] {
        assert!(
            v.is_finite() && (v.length() - 1.0).abs() < 1e-6,
            "{what}: basis {name} {v:?} of {c:?}"
        );
    }
    assert!(b.right.dot(b.forward).abs() < 1e-6 && b.up.dot(b.forward).abs() < 1e-6);
    let s = c.projection_scale_px();
    assert!(s.is_finite() && s > 0.0, "{what}: projection scale {s}");
    let f = c.frustum_local(c.position);
    assert!(
        f.planes.iter().all(|p| p.is_finite()),
        "{what}: frustum {f:?} of {c:?}"
    );
}

/// The `camera` target: the bytes as a camera file.
pub fn fuzz_camera(data: &[u8]) -> Result<Camera, CameraError> {
    let text = String::from_utf8_lossy(data);
    let c = Camera::from_json_str(&text)?;
    check_camera(&c, "camera");
    let again = Camera::from_json_str(&c.to_json_string());
    if let Err(e) = again {
        panic!("the camera's own JSON does not parse: {e}");
    }
    Ok(c)
}

/// The `camera_path` target: the bytes as a camera path file.
pub fn fuzz_camera_path(data: &[u8]) -> Result<CameraPath, PathError> {
    let text = String::from_utf8_lossy(data);
    let p = CameraPath::from_json_str(&text, Path::new(FUZZ_PATH), SIZE.0, SIZE.1)?;
    assert!(!p.keyframes.is_empty() && p.frames >= 1);
    for (i, k) in p.keyframes.iter().enumerate() {
        check_camera(k, &format!("keyframe {i}"));
        assert_eq!((k.width, k.height), SIZE);
    }
    if p.frames <= 64 {
        for (i, c) in p.cameras().iter().enumerate() {
            check_camera(c, &format!("frame {i}"));
        }
    }
    let d = p.playback_seconds();
    assert!(d.is_finite() && d >= 0.0, "playback of {d} s");
    for t in [
        0.0,
        0.25 * d,
        0.5 * d,
        0.7 * d,
        d,
        2.0 * d,
        -1.0,
        f64::NAN,
        f64::INFINITY,
    ] {
        check_camera(&p.camera_at(t), &format!("time {t}"));
    }
    Ok(p)
}
