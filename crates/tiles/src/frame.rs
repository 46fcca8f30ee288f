//! Where a tileset sits on the Earth: `root.transform` as an east-north-up frame.
//!
//! 3D Tiles' world is Earth-centred, Earth-fixed (ECEF, WGS84, metres). A model in local
//! coordinates (metres, +Z up, as 3D Tiles wants) is placed by the local east-north-up
//! frame at a point: model x east, y north, z up, the model's origin at the point. The
//! frame follows Cesium's `Transforms.eastNorthUpToFixedFrame`: up is the ellipsoid's
//! geodetic surface normal there, east `(-y, x, 0)` normalised, north `up x east`.
//! Matrices are column-major 4x4, as `transform` is stored.

/// WGS84 semi-major axis, metres.
const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// Why a frame could not be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FrameError {
    #[error("longitude {0} is not within -180..=180 degrees")]
    Longitude(f64),
    #[error("latitude {0} is not within -90..=90 degrees")]
    Latitude(f64),
    #[error("height {0} is not a finite number of metres")]
    Height(f64),
    #[error("ECEF point {0:?} must be finite and at least 1 km from the Earth's centre")]
    Ecef([f64; 3]),
    #[error("ECEF point {0:?} lies on the polar axis, where east is undefined: use --origin with a longitude")]
    Pole([f64; 3]),
}

/// The identity matrix.
pub const IDENTITY: [f64; 16] = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

/// A translation by `t`.
pub fn translation(t: [f64; 3]) -> [f64; 16] {
    let mut m = IDENTITY;
    m[12..15].copy_from_slice(&t);
    m
}

/// `a * b` (column-major: apply `b` first).
pub fn mul(a: &[f64; 16], b: &[f64; 16]) -> [f64; 16] {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[c * 4 + r] = (0..4).map(|k| a[k * 4 + r] * b[c * 4 + k]).sum();
        }
    }
    m
}

/// `m * (p, 1)`.
pub fn apply(m: &[f64; 16], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / l)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The frame with columns `east`, `north`, `up` at `p`.
fn frame(east: [f64; 3], north: [f64; 3], up: [f64; 3], p: [f64; 3]) -> [f64; 16] {
    [
        east[0], east[1], east[2], 0.0, north[0], north[1], north[2], 0.0, up[0], up[1], up[2],
        0.0, p[0], p[1], p[2], 1.0,
    ]
}

/// The WGS84 point at geodetic longitude and latitude (degrees) and ellipsoidal height
/// (metres), ECEF metres.
pub fn geodetic_to_ecef(lon_deg: f64, lat_deg: f64, height_m: f64) -> [f64; 3] {
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let n = WGS84_A / (1.0 - e2 * lat.sin().powi(2)).sqrt();
    [
        (n + height_m) * lat.cos() * lon.cos(),
        (n + height_m) * lat.cos() * lon.sin(),
        (n * (1.0 - e2) + height_m) * lat.sin(),
    ]
}

/// The east-north-up frame at a geodetic point (`--origin lon,lat,height`).
pub fn enu_at_geodetic(lon_deg: f64, lat_deg: f64, height_m: f64) -> Result<[f64; 16], FrameError> {
    if !(lon_deg.is_finite() && (-180.0..=180.0).contains(&lon_deg)) {
        return Err(FrameError::Longitude(lon_deg));
    }
    if !(lat_deg.is_finite() && (-90.0..=90.0).contains(&lat_deg)) {
        return Err(FrameError::Latitude(lat_deg));
    }
    if !height_m.is_finite() {
        return Err(FrameError::Height(height_m));
    }
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    let up = [lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()];
    let east = [-lon.sin(), lon.cos(), 0.0];
    let north = cross(up, east);
    Ok(frame(
        east,
        north,
        up,
        geodetic_to_ecef(lon_deg, lat_deg, height_m),
    ))
}

/// The east-north-up frame at an ECEF point (`--ecef x,y,z`).
pub fn enu_at_ecef(p: [f64; 3]) -> Result<[f64; 16], FrameError> {
    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    if !(r.is_finite() && r >= 1e3) {
        return Err(FrameError::Ecef(p));
    }
    if p[0].hypot(p[1]) < 1e-3 {
        return Err(FrameError::Pole(p));
    }
    let b = WGS84_A * (1.0 - WGS84_F);
    let up = normalize([
        p[0] / (WGS84_A * WGS84_A),
        p[1] / (WGS84_A * WGS84_A),
        p[2] / (b * b),
    ]);
    let east = normalize([-p[1], p[0], 0.0]);
    let north = cross(up, east);
    Ok(frame(east, north, up, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
    }

    #[test]
    fn known_points_land_where_wgs84_puts_them() {
        // Why: a wrong axis or sign puts the model on the other side of the Earth.
        assert!(close(
            geodetic_to_ecef(0.0, 0.0, 0.0),
            [WGS84_A, 0.0, 0.0],
            1e-6
        ));
        assert!(close(
            geodetic_to_ecef(90.0, 0.0, 10.0),
            [0.0, WGS84_A + 10.0, 0.0],
            1e-6
        ));
        // The pole: the semi-minor axis, 6,356,752.314 m.
        assert!(close(
            geodetic_to_ecef(0.0, 90.0, 0.0),
            [0.0, 0.0, 6_356_752.314_245],
            1e-3
        ));
    }

    #[test]
    fn enu_axes_point_east_north_up_and_both_constructors_agree() {
        // Why: model x must go east, y north, z up; --ecef of the point --origin names
        // must give the same frame (geodetic normal, not the geocentric direction).
        let m = enu_at_geodetic(0.0, 0.0, 0.0).unwrap();
        assert!(
            close(apply(&m, [1.0, 0.0, 0.0]), [WGS84_A, 1.0, 0.0], 1e-6),
            "east is +y at lon 0"
        );
        assert!(
            close(apply(&m, [0.0, 1.0, 0.0]), [WGS84_A, 0.0, 1.0], 1e-6),
            "north is +z on the equator"
        );
        assert!(
            close(apply(&m, [0.0, 0.0, 1.0]), [WGS84_A + 1.0, 0.0, 0.0], 1e-6),
            "up is outward"
        );
        for (lon, lat, h) in [
            (11.25, 47.5, 600.0),
            (-122.4, 37.8, 3.0),
            (151.2, -33.9, 50.0),
        ] {
            let a = enu_at_geodetic(lon, lat, h).unwrap();
            let b = enu_at_ecef(geodetic_to_ecef(lon, lat, h)).unwrap();
            for k in 0..16 {
                // Off the surface the normal of the ellipsoid through the point (what
                // Cesium uses for ECEF points) differs from the geodetic normal by
                // about 2e-7 at 600 m.
                let tol = 1e-6;
                assert!(
                    (a[k] - b[k]).abs() <= tol,
                    "({lon}, {lat}): entry {k}: {} vs {}",
                    a[k],
                    b[k]
                );
            }
        }
    }

    #[test]
    fn bad_points_are_errors() {
        assert_eq!(
            enu_at_geodetic(181.0, 0.0, 0.0),
            Err(FrameError::Longitude(181.0))
        );
        assert_eq!(
            enu_at_geodetic(0.0, -91.0, 0.0),
            Err(FrameError::Latitude(-91.0))
        );
        assert!(enu_at_geodetic(0.0, 0.0, f64::NAN).is_err());
        assert!(enu_at_ecef([0.0, 0.0, 0.0]).is_err());
        assert!(matches!(
            enu_at_ecef([0.0, 0.0, 6.4e6]),
            Err(FrameError::Pole(_))
        ));
    }

    #[test]
    fn products_apply_the_right_matrix_first() {
        let t = translation([1.0, 2.0, 3.0]);
        let m = enu_at_geodetic(0.0, 0.0, 0.0).unwrap();
        let p = [0.5, -0.25, 2.0];
        assert!(close(apply(&mul(&m, &t), p), apply(&m, apply(&t, p)), 1e-9));
    }
}
