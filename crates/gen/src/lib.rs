//! Deterministic, streamed generators of large test meshes, written as binary PLY (the
//! textured terrain as OBJ + MTL + images).
//!
//! The out-of-core builder needs inputs from 10^3 to 10^9 triangles for tests and
//! benchmarks. The generators here never hold the mesh: vertices are computed on the fly
//! from their index (in blocks, in parallel) and streamed, then the faces are streamed
//! from pure index arithmetic, so memory is O(1) in the triangle count.
//!
//! Output is a pure function of the arguments: the same options give bit-identical files
//! on every machine. Randomness comes only from an integer hash of `seed`; all geometry is
//! plain IEEE-754 arithmetic (no libm functions such as `sin` whose last bit may vary).
//!
//! * [`write_sphere`]: a watertight, consistently oriented, bumpy closed 2-manifold.
//! * [`write_terrain`]: an open heightfield with a boundary.
//! * [`write_tiled`]: K translated copies of a real (small) scan.
//! * [`write_textured_terrain`]: a terrain over K tiles, OBJ + MTL + one procedural
//!   aerial photo (JPEG or PNG) per tile: source images of any total size for the
//!   builder's texture stage.
//!
//! Each reports one `generate` stage to the [`Progress`] it is given ([`NoProgress`] for
//! none; the textured terrain an `images` stage before it), the same protocol as the
//! builder's (`tessera-mesh`'s trait).

mod noise;
mod sphere;
mod terrain;
mod textured;
mod tile;

pub use sphere::{sphere_resolution, write_sphere, SphereOptions};
pub use terrain::{terrain_resolution, write_terrain, TerrainOptions, MAX_HEIGHT, MIN_HEIGHT};
pub use textured::{
    textured_paths, textured_resolution, tile_grid, write_textured_terrain, ImageFormat,
    TexturedOptions, TexturedReport,
};
pub use tile::{write_tiled, TileOptions};

use tessera_mesh::{Attributes, MeshError, PlyWriterOptions};
pub use tessera_mesh::{NoProgress, Progress};

/// What a generator wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GenReport {
    /// Exact number of vertices in the file.
    pub vertices: u64,
    /// Exact number of triangles in the file (generators round the requested count).
    pub triangles: u64,
}

/// Why a mesh could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    /// Reading the input or writing the output failed (names the file).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The options are out of range (too few or too many triangles, bad amplitude, ...).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// An image could not be encoded (names the file).
    #[error("{}: {message}", path.display())]
    Encode {
        path: std::path::PathBuf,
        message: String,
    },
}

/// Elements (vertices or triangles) between two progress reports.
pub(crate) const PROGRESS_STEP: u64 = 1 << 20;

/// Vertices computed per parallel block.
pub(crate) const VERTEX_BLOCK: usize = 1 << 16;

/// Reports a generator's work as one [`Progress`] stage, `generate`, of `vertices +
/// triangles` units (vertices are all written before the first triangle), advanced about
/// every [`PROGRESS_STEP`] elements and completed by [`Ticker::finish`].
pub(crate) struct Ticker<'a> {
    progress: &'a dyn Progress,
    /// Elements done and not yet reported.
    pending: u64,
}

impl<'a> Ticker<'a> {
    pub(crate) fn new(
        progress: &'a dyn Progress,
        total_vertices: u64,
        total_triangles: u64,
    ) -> Self {
        progress.stage("generate", total_vertices + total_triangles);
        Ticker {
            progress,
            pending: 0,
        }
    }

    #[inline]
    pub(crate) fn add_vertices(&mut self, n: u64) {
        self.add(n);
    }

    #[inline]
    pub(crate) fn add_triangles(&mut self, n: u64) {
        self.add(n);
    }

    #[inline]
    fn add(&mut self, n: u64) {
        self.pending += n;
        if self.pending >= PROGRESS_STEP {
            self.progress.advance(std::mem::take(&mut self.pending));
        }
    }

    pub(crate) fn finish(&mut self) {
        self.progress.advance(std::mem::take(&mut self.pending));
        self.progress.finish_stage();
    }
}

/// The writer options of an untextured PLY: positions, colours when `colors`, no normals
/// or UVs.
pub(crate) fn plain_ply(
    colors: bool,
    vertex_count: u64,
    face_count: u64,
    comment: String,
) -> PlyWriterOptions {
    PlyWriterOptions {
        attributes: Attributes {
            normals: false,
            colors,
            uvs: false,
            textures: false,
        },
        vertex_count,
        face_count,
        comments: vec![comment],
    }
}

/// The two triangles of cell `(i, j)` of a grid with rows of `m` vertices (vertex `j m +
/// i`), counter-clockwise seen from +z: `[v00, v10, v11]` and `[v00, v11, v01]`, where
/// `v10` is the next vertex in the row and `v01` the one in the next row.
pub fn grid_cell_triangles(m: u64, i: u64, j: u64) -> [[u32; 3]; 2] {
    let v00 = (j * m + i) as u32;
    let v10 = v00 + 1;
    let v01 = v00 + m as u32;
    let v11 = v01 + 1;
    [[v00, v10, v11], [v00, v11, v01]]
}

/// [`stream_vertices`] over a grid with rows of `m` vertices `scale` apart: `f` makes the
/// vertex at `(x, y)` = `(idx % m, idx / m) * scale` (row `j` holds vertices `j m .. j m +
/// m`).
pub(crate) fn stream_grid<F, S>(
    count: u64,
    m: u64,
    scale: f64,
    ticker: &mut Ticker<'_>,
    f: F,
    sink: S,
) -> Result<(), GenError>
where
    F: Fn(f64, f64) -> tessera_mesh::Vertex + Sync,
    S: FnMut(&tessera_mesh::Vertex) -> Result<(), MeshError> + Send,
{
    let point = |idx: u64| f((idx % m) as f64 * scale, (idx / m) as f64 * scale);
    stream_vertices(count, ticker, point, sink)
}

/// Compute vertices `0..count` with `f` in parallel blocks and hand them to `sink` in order.
///
/// Two buffers alternate: while block `k` is handed to `sink`, block `k + 1` is computed,
/// so the single-threaded writing overlaps the (parallel) computation.
pub(crate) fn stream_vertices<F, S>(
    count: u64,
    ticker: &mut Ticker<'_>,
    f: F,
    mut sink: S,
) -> Result<(), GenError>
where
    F: Fn(u64) -> tessera_mesh::Vertex + Sync,
    S: FnMut(&tessera_mesh::Vertex) -> Result<(), MeshError> + Send,
{
    use rayon::prelude::*;
    let block = VERTEX_BLOCK.min(count as usize) as u64;
    let compute = |start: u64, buf: &mut Vec<tessera_mesh::Vertex>| {
        let len = (count - start).min(block) as usize;
        buf.clear();
        buf.resize(len, tessera_mesh::Vertex::default());
        buf.par_iter_mut()
            .with_min_len(1024)
            .enumerate()
            .for_each(|(k, v)| *v = f(start + k as u64));
    };
    let mut ready = Vec::with_capacity(block as usize);
    let mut next = Vec::with_capacity(block as usize);
    compute(0, &mut ready);
    let mut start = 0u64;
    while start < count {
        let len = ready.len() as u64;
        let following = start + len;
        let (_, written) = rayon::join(
            || {
                if following < count {
                    compute(following, &mut next);
                }
            },
            || ready.iter().try_for_each(&mut sink),
        );
        written?;
        std::mem::swap(&mut ready, &mut next);
        start = following;
        ticker.add_vertices(len);
    }
    Ok(())
}
