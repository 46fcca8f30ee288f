//! The model's up axis: parsed from the command line, guessed from the bounding box,
//! cycled with a key.

use std::fmt;
use std::str::FromStr;

use glam::DVec3;

/// One of the six signed coordinate axes, used as the model's "up".
///
/// glTF files are +Y up by specification: a caller loading glTF passes [`UpAxis::PosY`]
/// instead of calling [`guess_up`]. Scans and CAD exports are often +Z up; meshes from
/// graphics tools are usually +Y up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UpAxis {
    /// +X.
    PosX,
    /// -X.
    NegX,
    /// +Y.
    PosY,
    /// -Y.
    NegY,
    /// +Z.
    PosZ,
    /// -Z.
    NegZ,
}

/// The six axes in the order [`UpAxis::next`] cycles through them.
pub const UP_AXES: [UpAxis; 6] = [
    UpAxis::PosX,
    UpAxis::NegX,
    UpAxis::PosY,
    UpAxis::NegY,
    UpAxis::PosZ,
    UpAxis::NegZ,
];

impl UpAxis {
    /// The unit vector of the axis.
    pub fn vector(self) -> DVec3 {
        match self {
            UpAxis::PosX => DVec3::X,
            UpAxis::NegX => DVec3::NEG_X,
            UpAxis::PosY => DVec3::Y,
            UpAxis::NegY => DVec3::NEG_Y,
            UpAxis::PosZ => DVec3::Z,
            UpAxis::NegZ => DVec3::NEG_Z,
        }
    }

    /// The next axis in the cycle +X, -X, +Y, -Y, +Z, -Z, +X, ... (the "cycle up axis"
    /// key).
    pub fn next(self) -> UpAxis {
        let i = UP_AXES.iter().position(|&a| a == self).unwrap_or(0);
        UP_AXES[(i + 1) % UP_AXES.len()]
    }

    /// The screen-right direction of the front view for this up (the home view turns
    /// from there): +X for up along Y or Z, +Y for up along X. Together with the up
    /// vector it fixes the front: the eye of the front view lies along `right x up`
    /// (+Z for +Y up, -Y for +Z up as in Blender's front view).
    pub fn front_right(self) -> DVec3 {
        match self {
            UpAxis::PosX | UpAxis::NegX => DVec3::Y,
            _ => DVec3::X,
        }
    }
}

impl fmt::Display for UpAxis {
    /// `+x`, `-x`, `+y`, `-y`, `+z`, `-z` (what [`FromStr`] reads back).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            UpAxis::PosX => "+x",
            UpAxis::NegX => "-x",
            UpAxis::PosY => "+y",
            UpAxis::NegY => "-y",
            UpAxis::PosZ => "+z",
            UpAxis::NegZ => "-z",
        })
    }
}

/// A string that names no axis.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown up axis {input:?}: expected one of +x, -x, +y, -y, +z, -z \
     (case is ignored; a missing sign means +)"
)]
pub struct UpAxisParseError {
    /// The text that was given.
    pub input: String,
}

impl FromStr for UpAxis {
    type Err = UpAxisParseError;

    /// Accepts `x`, `+x`, `-x` (any case, surrounding spaces ignored) and likewise for
    /// y and z.
    fn from_str(s: &str) -> Result<UpAxis, UpAxisParseError> {
        let t = s.trim().to_ascii_lowercase();
        let axis = match t.as_str() {
            "x" | "+x" => UpAxis::PosX,
            "-x" => UpAxis::NegX,
            "y" | "+y" => UpAxis::PosY,
            "-y" => UpAxis::NegY,
            "z" | "+z" => UpAxis::PosZ,
            "-z" => UpAxis::NegZ,
            _ => {
                return Err(UpAxisParseError {
                    input: s.to_string(),
                })
            }
        };
        Ok(axis)
    }
}

/// Guesses the up axis of a model from its bounding box: the POSITIVE axis along which
/// the box is tallest (statues and buildings stand along their longest axis more often
/// than not; a sign cannot be guessed from a box).
///
/// Ties (extents equal within a relative 1e-9) prefer +Z, then +Y, then +X: scans, CAD
/// and GIS data are mostly +Z up. A degenerate or non-finite box gives +Z. glTF files are
/// +Y up by specification: pass [`UpAxis::PosY`] for them instead of guessing.
pub fn guess_up(min: [f64; 3], max: [f64; 3]) -> UpAxis {
    let extent = |i: usize| {
        let e = max[i] - min[i];
        if e.is_finite() && e > 0.0 {
            e
        } else {
            0.0
        }
    };
    // In order of preference; a later axis wins only when clearly taller.
    let candidates = [
        (UpAxis::PosZ, extent(2)),
        (UpAxis::PosY, extent(1)),
        (UpAxis::PosX, extent(0)),
    ];
    let mut best = candidates[0];
    for &c in &candidates[1..] {
        if c.1 > best.1 * (1.0 + 1e-9) {
            best = c;
        }
    }
    best.0
}
