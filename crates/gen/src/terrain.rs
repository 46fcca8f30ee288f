//! A heightfield terrain: an open grid mesh over the unit square, z up.

use std::path::Path;

use tessera_mesh::{PlyWriter, Vertex};

use crate::noise::{ramp, Fbm};
use crate::{grid_cell_triangles, plain_ply, stream_grid, GenError, GenReport, Progress, Ticker};

/// Amplitude of the fBm part of the height.
const FBM_AMPLITUDE: f64 = 0.1;
/// Amplitude of the ridged part of the height.
const RIDGE_AMPLITUDE: f64 = 0.06;
/// Every height lies in `[MIN_HEIGHT, MAX_HEIGHT]`.
pub const MIN_HEIGHT: f32 = -(FBM_AMPLITUDE as f32);
/// See [`MIN_HEIGHT`].
pub const MAX_HEIGHT: f32 = (FBM_AMPLITUDE + RIDGE_AMPLITUDE) as f32;

/// Options of [`write_terrain`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TerrainOptions {
    /// Requested triangle count; the terrain has `2 (m - 1)^2` triangles on an `m x m`
    /// vertex grid with `m = round(sqrt(triangles / 2)) + 1` (see [`terrain_resolution`]).
    /// At least 2.
    pub triangles: u64,
    /// Seed of the height noise.
    pub seed: u64,
    /// Write per-vertex RGBA colours (by height).
    pub colors: bool,
}

impl Default for TerrainOptions {
    fn default() -> Self {
        TerrainOptions {
            triangles: 1_000_000,
            seed: 0,
            colors: false,
        }
    }
}

/// The vertex grid side `m` used for `triangles` requested triangles:
/// `round(sqrt(triangles / 2)) + 1`, at least 2. The terrain then has `2 (m - 1)^2`
/// triangles and `m^2` vertices. Fails when fewer than 2 triangles are requested or the
/// vertex count would exceed `u32::MAX`.
pub fn terrain_resolution(triangles: u64) -> Result<u64, GenError> {
    if triangles < 2 {
        return Err(GenError::InvalidArgument(format!(
            "a terrain needs at least 2 triangles, {triangles} requested"
        )));
    }
    let m = ((triangles as f64 / 2.0).sqrt().round() as u64).max(1) + 1;
    if (m as u128) * (m as u128) > u128::from(u32::MAX) {
        return Err(GenError::InvalidArgument(format!(
            "{triangles} triangles requested: the terrain would have more than {} vertices",
            u32::MAX
        )));
    }
    Ok(m)
}

/// Write a heightfield terrain to `path` (binary PLY, atomic).
///
/// Contract: an `m x m` grid of vertices (`m` from [`terrain_resolution`]) at `x = i / (m -
/// 1)`, `y = j / (m - 1)` (vertex index `j m + i`), `z` = multi-octave value noise of
/// amplitude 0.1 plus ridged noise of amplitude 0.06, always within
/// [`MIN_HEIGHT`]`..=`[`MAX_HEIGHT`]. Each grid cell is split into two triangles,
/// counter-clockwise seen from above (+z). The mesh is an open 2-manifold disc: its
/// boundary is the `4 (m - 1)` edges of the square's border. Colours (by height, opaque)
/// when `opts.colors`; no normals. The bytes depend only on `opts`; memory use does not
/// depend on the triangle count.
///
/// Reports one `generate` stage to `progress` (see [`crate::Progress`]).
pub fn write_terrain(
    path: &Path,
    opts: &TerrainOptions,
    progress: &dyn Progress,
) -> Result<GenReport, GenError> {
    let m = terrain_resolution(opts.triangles)?;
    let cells = m - 1;
    let vertex_count = m * m;
    let face_count = 2 * cells * cells;

    let height = Height::new(opts.seed, cells);

    let comment = format!(
        "tessera-gen terrain m={m} seed={} colors={}",
        opts.seed, opts.colors
    );
    let writer_opts = plain_ply(opts.colors, vertex_count, face_count, comment);
    let mut w = PlyWriter::create(path, &writer_opts)?;
    let mut ticker = Ticker::new(progress, vertex_count, face_count);

    let colors = opts.colors;
    stream_grid(
        vertex_count,
        m,
        1.0 / cells as f64,
        &mut ticker,
        |x, y| {
            let z = height.at(x, y);
            let mut v = Vertex {
                position: [x as f32, y as f32, z as f32],
                ..Vertex::default()
            };
            if colors {
                v.color = terrain_color(z);
            }
            v
        },
        |v| w.write_vertex(v),
    )?;

    for j in 0..cells {
        for i in 0..cells {
            for t in grid_cell_triangles(m, i, j) {
                w.write_triangle(t)?;
            }
        }
        ticker.add_triangles(2 * cells);
    }
    w.finish()?;
    ticker.finish();
    Ok(GenReport {
        vertices: vertex_count,
        triangles: face_count,
    })
}

/// The relief: `z` at `(x, y)` (model units of the unit square; defined everywhere).
pub(crate) struct Height {
    fbm: Fbm,
    ridges: Fbm,
}

impl Height {
    /// The relief of seed `seed` sampled by a grid of `cells` cells per unit length: the
    /// finest octave's cell spans at least ~4 grid steps (`4 * 2^(k-1) <= cells / 4`).
    pub(crate) fn new(seed: u64, cells: u64) -> Height {
        let mut octaves = 1u32;
        while octaves < 12 && (16u64 << octaves) <= cells {
            octaves += 1;
        }
        Height {
            fbm: Fbm::new(seed, 11, octaves.max(2), 4.0),
            ridges: Fbm::new(seed, 12, 3, 2.0),
        }
    }

    #[inline]
    pub(crate) fn at(&self, x: f64, y: f64) -> f64 {
        let base = FBM_AMPLITUDE * self.fbm.sample([x, y, 0.0]);
        let r = self.ridges.ridged([x, y, 0.5]);
        // Squaring sharpens the crests and flattens the valleys between them.
        let z = base + RIDGE_AMPLITUDE * r * r;
        z.clamp(f64::from(MIN_HEIGHT), f64::from(MAX_HEIGHT))
    }
}

fn terrain_color(z: f64) -> [u8; 4] {
    const STOPS: [(f64, [f64; 3]); 6] = [
        (-0.10, [0.05, 0.15, 0.45]),
        (-0.02, [0.20, 0.45, 0.70]),
        (0.00, [0.80, 0.75, 0.55]),
        (0.03, [0.25, 0.55, 0.20]),
        (0.09, [0.45, 0.35, 0.25]),
        (0.14, [0.95, 0.95, 0.97]),
    ];
    ramp(&STOPS, z)
}
