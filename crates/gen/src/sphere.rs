//! A bumpy cube-sphere: watertight, consistently oriented, no duplicate vertices.
//!
//! The sphere is the surface of the cube `[0, n]^3` of integer lattice points, projected
//! onto the unit sphere. Each of the 6 faces is an `n x n` grid of quads, 2 triangles each,
//! so the mesh has `12 n^2` triangles and `6 n^2 + 2` vertices (8 corners, 12 edges of
//! `n - 1` interior points, 6 faces of `(n - 1)^2` interior points). A surface lattice point
//! has exactly one index ([`CubeIndex::index_of`]), whichever face asks for it, so seams are
//! shared by construction; the inverse ([`CubeIndex::lattice_of`]) lets the vertex pass
//! enumerate unique vertices in index order. Both are O(1) with no tables.

use std::path::Path;

use tessera_mesh::{PlyWriter, Vertex};

use crate::noise::{ramp, Fbm};
use crate::{plain_ply, stream_vertices, GenError, GenReport, Progress, Ticker};

/// Options of [`write_sphere`].
#[derive(Clone, Debug, PartialEq)]
pub struct SphereOptions {
    /// Requested triangle count; the sphere has `12 n^2` triangles with
    /// `n = round(sqrt(triangles / 12))` (see [`sphere_resolution`]). At least 12.
    pub triangles: u64,
    /// Seed of the surface noise (and colours).
    pub seed: u64,
    /// Write per-vertex RGBA colours (a smooth function of position).
    pub colors: bool,
    /// Relative radial amplitude of the noise, in `[0, 1)`: the radius stays within
    /// `1 ± noise`. Default 0.05.
    pub noise: f32,
}

impl Default for SphereOptions {
    fn default() -> Self {
        SphereOptions {
            triangles: 1_000_000,
            seed: 0,
            colors: false,
            noise: 0.05,
        }
    }
}

/// The grid resolution `n` (quads per cube edge) used for `triangles` requested triangles:
/// `round(sqrt(triangles / 12))`, at least 1. The sphere then has `12 n^2` triangles and
/// `6 n^2 + 2` vertices. Fails when fewer than 12 triangles are requested or the vertex
/// count would exceed `u32::MAX`.
pub fn sphere_resolution(triangles: u64) -> Result<u64, GenError> {
    if triangles < 12 {
        return Err(GenError::InvalidArgument(format!(
            "a sphere needs at least 12 triangles, {triangles} requested"
        )));
    }
    let n = ((triangles as f64 / 12.0).sqrt().round() as u64).max(1);
    if 6 * (n as u128) * (n as u128) + 2 > u128::from(u32::MAX) {
        return Err(GenError::InvalidArgument(format!(
            "{triangles} triangles requested: the sphere would have more than {} vertices",
            u32::MAX
        )));
    }
    Ok(n)
}

/// Write a watertight bumpy sphere to `path` (binary PLY, atomic).
///
/// Contract: the mesh is a closed, connected 2-manifold of genus 0 (every edge is shared by
/// exactly two triangles with opposite orientations; `V - E + F = 2`), oriented outwards
/// (counter-clockwise seen from outside), with no two vertices at the same position and no
/// degenerate triangle. It is star-shaped around the origin: the vertex in direction `d`
/// lies at radius `1 + noise * f(d)` with `f` a multi-octave value noise in `[-1, 1]` whose
/// finest octave is a few triangles wide. The triangle count is `12 n^2` with `n` from
/// [`sphere_resolution`]; the report gives the exact counts. All vertices are written
/// before the faces; no normals; colours (opaque) when `opts.colors`. The bytes depend
/// only on `opts`. Memory use does not depend on the triangle count.
///
/// Reports one `generate` stage to `progress` (see [`crate::Progress`]).
pub fn write_sphere(
    path: &Path,
    opts: &SphereOptions,
    progress: &dyn Progress,
) -> Result<GenReport, GenError> {
    if !opts.noise.is_finite() || !(0.0..1.0).contains(&opts.noise) {
        return Err(GenError::InvalidArgument(format!(
            "sphere noise amplitude must be in [0, 1), got {}",
            opts.noise
        )));
    }
    let n = sphere_resolution(opts.triangles)?;
    let cube = CubeIndex::new(n);
    let vertex_count = cube.vertex_count();
    let face_count = 12 * n * n;

    let surface = SphereSurface::new(n, opts.seed, f64::from(opts.noise));
    let comment = format!(
        "tessera-gen sphere n={n} seed={} noise={} colors={}",
        opts.seed, opts.noise, opts.colors
    );
    let writer_opts = plain_ply(opts.colors, vertex_count, face_count, comment);
    let mut w = PlyWriter::create(path, &writer_opts)?;
    let mut ticker = Ticker::new(progress, vertex_count, face_count);

    let colors = opts.colors;
    stream_vertices(
        vertex_count,
        &mut ticker,
        |idx| surface.vertex(cube.lattice_of(idx), colors),
        |v| w.write_vertex(v),
    )?;

    for face in 0..6u32 {
        let axis = (face / 2) as usize;
        let positive = face % 2 == 1;
        let side = if positive { n } else { 0 };
        let lattice = |i: u64, j: u64| {
            let mut l = [0u64; 3];
            l[axis] = side;
            l[(axis + 1) % 3] = i;
            l[(axis + 2) % 3] = j;
            l
        };
        // Indices of grid rows j and j + 1, computed once per vertex: O(n) memory.
        let row = |j: u64, out: &mut Vec<u32>| {
            out.clear();
            out.extend((0..=n).map(|i| cube.index_of(lattice(i, j))));
        };
        let mut lower = Vec::with_capacity(n as usize + 1);
        let mut upper = Vec::with_capacity(n as usize + 1);
        row(0, &mut lower);
        for j in 0..n {
            row(j + 1, &mut upper);
            let low_j = 2 * j + 1 < n;
            for i in 0..n as usize {
                let (v00, v10) = (lower[i], lower[i + 1]);
                let (v01, v11) = (upper[i], upper[i + 1]);
                // The diagonal points at the nearest cube corner, where three quads meet at
                // 120 degrees: splitting them there gives the better-shaped triangles.
                let tris = if (2 * i as u64 + 1 < n) == low_j {
                    [[v00, v10, v11], [v00, v11, v01]]
                } else {
                    [[v00, v10, v01], [v10, v11, v01]]
                };
                for t in tris {
                    // (i, j) axes are (axis+1, axis+2): their cross product is +axis, so the
                    // quad is counter-clockwise seen from the positive side.
                    let t = if positive { t } else { [t[0], t[2], t[1]] };
                    w.write_triangle(t)?;
                }
            }
            std::mem::swap(&mut lower, &mut upper);
            ticker.add_triangles(2 * n);
        }
    }
    w.finish()?;
    ticker.finish();
    Ok(GenReport {
        vertices: vertex_count,
        triangles: face_count,
    })
}

/// Unique indexing of the surface points of the lattice cube `[0, n]^3`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CubeIndex {
    n: u64,
}

impl CubeIndex {
    pub(crate) fn new(n: u64) -> CubeIndex {
        CubeIndex { n }
    }

    /// `6 n^2 + 2`.
    pub(crate) fn vertex_count(&self) -> u64 {
        6 * self.n * self.n + 2
    }

    fn edge_base(&self) -> u64 {
        8
    }

    fn face_base(&self) -> u64 {
        8 + 12 * (self.n - 1)
    }

    /// Index of surface point `l` (at least one coordinate is 0 or `n`).
    ///
    /// Corners: `0..8` by the bits (x = n, y = n, z = n). Edges: `8 + e (n - 1) + t - 1`,
    /// `e = 4 a + b` with `a` the free axis, `t` its coordinate, `b` the bits of the other
    /// two axes `(a + 1) % 3`, `(a + 2) % 3` at `n`. Faces: `face_base + f (n - 1)^2 +
    /// (p - 1)(n - 1) + q - 1` with `f = 2 a + (l[a] == n)`, `p = l[(a + 1) % 3]`,
    /// `q = l[(a + 2) % 3]`.
    #[inline]
    pub(crate) fn index_of(&self, l: [u64; 3]) -> u32 {
        let n = self.n;
        let on = |c: u64| c == 0 || c == n;
        let b = [on(l[0]), on(l[1]), on(l[2])];
        let count = b.iter().filter(|&&x| x).count();
        let idx = match count {
            3 => u64::from(l[0] == n) | (u64::from(l[1] == n) << 1) | (u64::from(l[2] == n) << 2),
            2 => {
                let a = if !b[0] {
                    0
                } else if !b[1] {
                    1
                } else {
                    2
                };
                let bits = u64::from(l[(a + 1) % 3] == n) | (u64::from(l[(a + 2) % 3] == n) << 1);
                self.edge_base() + (4 * a as u64 + bits) * (n - 1) + l[a] - 1
            }
            _ => {
                debug_assert_eq!(count, 1, "not a surface point: {l:?}");
                let a = if b[0] {
                    0
                } else if b[1] {
                    1
                } else {
                    2
                };
                let f = 2 * a as u64 + u64::from(l[a] == n);
                let (p, q) = (l[(a + 1) % 3], l[(a + 2) % 3]);
                self.face_base() + f * (n - 1) * (n - 1) + (p - 1) * (n - 1) + q - 1
            }
        };
        idx as u32
    }

    /// The surface point with index `idx` (inverse of [`CubeIndex::index_of`]).
    #[inline]
    pub(crate) fn lattice_of(&self, idx: u64) -> [u64; 3] {
        let n = self.n;
        let mut l = [0u64; 3];
        if idx < 8 {
            l[0] = (idx & 1) * n;
            l[1] = ((idx >> 1) & 1) * n;
            l[2] = ((idx >> 2) & 1) * n;
        } else if idx < self.face_base() {
            let k = idx - self.edge_base();
            let e = k / (n - 1);
            let t = k % (n - 1) + 1;
            let a = (e / 4) as usize;
            let bits = e % 4;
            l[a] = t;
            l[(a + 1) % 3] = (bits & 1) * n;
            l[(a + 2) % 3] = ((bits >> 1) & 1) * n;
        } else {
            let m = n - 1;
            let k = idx - self.face_base();
            let f = k / (m * m);
            let r = k % (m * m);
            let a = (f / 2) as usize;
            l[a] = (f % 2) * n;
            l[(a + 1) % 3] = r / m + 1;
            l[(a + 2) % 3] = r % m + 1;
        }
        l
    }
}

/// `tan(x * pi / 4)` for `x` in `[-1, 1]` by a (4,4) Padé approximant: pure arithmetic, so
/// bit-identical everywhere, odd, monotone, within 2e-8 of `tan` on this range. It spreads
/// the cube grid evenly in angle (the "tangent-adjusted" cube-sphere).
#[inline]
fn warp(x: f64) -> f64 {
    const QUARTER_PI: f64 = std::f64::consts::FRAC_PI_4;
    let t = x * QUARTER_PI;
    let t2 = t * t;
    t * (945.0 - 105.0 * t2 + t2 * t2) / (945.0 - 420.0 * t2 + 15.0 * t2 * t2)
}

/// Positions (and colours) of the sphere's vertices.
struct SphereSurface {
    n: f64,
    amplitude: f64,
    shape: Fbm,
    tint: Fbm,
}

impl SphereSurface {
    fn new(n: u64, seed: u64, amplitude: f64) -> SphereSurface {
        // The vertex spacing is about (pi / 2) / n; keep the finest octave's lattice cell
        // at least ~4 vertex spacings: 1.5 * 2^(k-1) <= n / 6.
        let mut octaves = 1u32;
        while octaves < 12 && (9u64 << octaves) <= n {
            octaves += 1;
        }
        SphereSurface {
            n: n as f64,
            amplitude,
            shape: Fbm::new(seed, 1, octaves.max(2), 1.5),
            tint: Fbm::new(seed, 2, 3, 1.0),
        }
    }

    #[inline]
    fn vertex(&self, l: [u64; 3], colors: bool) -> Vertex {
        // (2l - n) / n is exactly antisymmetric, so the sphere is exactly symmetric before
        // the noise is applied.
        let c = |k: usize| warp((2.0 * l[k] as f64 - self.n) / self.n);
        let w = [c(0), c(1), c(2)];
        let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let d = [w[0] / len, w[1] / len, w[2] / len];
        let h = self.shape.sample(d);
        let r = 1.0 + self.amplitude * h;
        let mut v = Vertex {
            position: [(d[0] * r) as f32, (d[1] * r) as f32, (d[2] * r) as f32],
            ..Vertex::default()
        };
        if colors {
            v.color = sphere_color(self.tint.sample(d), h);
        }
        v
    }
}

/// A rock/moss palette chosen by a low-frequency noise `t`, shaded by the bump height `h`.
fn sphere_color(t: f64, h: f64) -> [u8; 4] {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (-0.6, [0.76, 0.70, 0.50]),
        (-0.2, [0.45, 0.55, 0.30]),
        (0.1, [0.35, 0.42, 0.45]),
        (0.4, [0.60, 0.35, 0.25]),
        (0.7, [0.90, 0.88, 0.85]),
    ];
    let base = ramp(&STOPS, t);
    let shade = 0.7 + 0.3 * (0.5 + 0.5 * h);
    let s = |c: u8| (f64::from(c) * shade + 0.5).min(255.0) as u8;
    [s(base[0]), s(base[1]), s(base[2]), 255]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_is_a_bijection_on_the_surface() {
        for n in 1..=7u64 {
            let cube = CubeIndex::new(n);
            let count = cube.vertex_count();
            let mut seen = vec![false; count as usize];
            for x in 0..=n {
                for y in 0..=n {
                    for z in 0..=n {
                        let l = [x, y, z];
                        if !l.iter().any(|&c| c == 0 || c == n) {
                            continue;
                        }
                        let i = cube.index_of(l);
                        assert!(u64::from(i) < count, "n={n} {l:?} -> {i}");
                        assert!(!seen[i as usize], "n={n} {l:?} -> {i} twice");
                        seen[i as usize] = true;
                        assert_eq!(cube.lattice_of(u64::from(i)), l, "n={n}");
                    }
                }
            }
            assert!(seen.iter().all(|&s| s), "n={n}");
        }
    }

    #[test]
    fn warp_is_close_to_tan_and_odd() {
        for i in -100..=100 {
            let x = i as f64 / 100.0;
            let exact = (x * std::f64::consts::FRAC_PI_4).tan();
            assert!((warp(x) - exact).abs() < 2e-8, "{x}");
            assert_eq!(warp(-x), -warp(x));
        }
        assert!((warp(1.0) - 1.0).abs() < 2e-8);
    }

    #[test]
    fn resolution() {
        assert_eq!(sphere_resolution(12).unwrap(), 1);
        assert_eq!(sphere_resolution(1200).unwrap(), 10);
        assert_eq!(sphere_resolution(1_000_000_000).unwrap(), 9129);
        assert!(sphere_resolution(11).is_err());
        assert!(sphere_resolution(u64::MAX).is_err());
        assert!(sphere_resolution(9_000_000_000).is_err());
    }
}
