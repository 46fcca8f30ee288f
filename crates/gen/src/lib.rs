//! Deterministic, streamed generators of large test meshes, written as binary PLY.
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

mod noise;
mod sphere;
mod terrain;
mod tile;

pub use sphere::{sphere_resolution, write_sphere, write_sphere_with_progress, SphereOptions};
pub use terrain::{
    terrain_resolution, write_terrain, write_terrain_with_progress, TerrainOptions, MAX_HEIGHT,
    MIN_HEIGHT,
};
pub use tile::{write_tiled, write_tiled_with_progress, TileOptions};

use tessera_mesh::MeshError;

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
}

/// Progress of a generator, passed to the optional progress callback.
///
/// The callback is called about every million elements (vertices or triangles) and once
/// at the end, with `vertices == total_vertices` and `triangles == total_triangles`.
/// Vertices are all written before the first triangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GenProgress {
    /// Vertices written so far.
    pub vertices: u64,
    /// Triangles written so far.
    pub triangles: u64,
    /// Vertices the file will hold.
    pub total_vertices: u64,
    /// Triangles the file will hold.
    pub total_triangles: u64,
}

impl GenProgress {
    /// Fraction of the work done, in `[0, 1]` (vertices and triangles weighted equally
    /// per element).
    pub fn fraction(&self) -> f64 {
        let total = self.total_vertices + self.total_triangles;
        if total == 0 {
            1.0
        } else {
            (self.vertices + self.triangles) as f64 / total as f64
        }
    }
}

/// Optional progress callback.
pub type ProgressFn<'a> = Option<&'a dyn Fn(GenProgress)>;

/// Elements (vertices or triangles) between two progress calls.
pub(crate) const PROGRESS_STEP: u64 = 1 << 20;

/// Vertices computed per parallel block.
pub(crate) const VERTEX_BLOCK: usize = 1 << 16;

/// Calls the progress callback every [`PROGRESS_STEP`] elements.
pub(crate) struct Ticker<'a> {
    progress: ProgressFn<'a>,
    state: GenProgress,
    next: u64,
}

impl<'a> Ticker<'a> {
    pub(crate) fn new(progress: ProgressFn<'a>, total_vertices: u64, total_triangles: u64) -> Self {
        Ticker {
            progress,
            state: GenProgress {
                total_vertices,
                total_triangles,
                ..Default::default()
            },
            next: PROGRESS_STEP,
        }
    }

    #[inline]
    pub(crate) fn add_vertices(&mut self, n: u64) {
        self.state.vertices += n;
        self.maybe_call();
    }

    #[inline]
    pub(crate) fn add_triangles(&mut self, n: u64) {
        self.state.triangles += n;
        self.maybe_call();
    }

    #[inline]
    fn maybe_call(&mut self) {
        let done = self.state.vertices + self.state.triangles;
        if done >= self.next {
            if let Some(f) = self.progress {
                f(self.state);
            }
            self.next = (done / PROGRESS_STEP + 1) * PROGRESS_STEP;
        }
    }

    pub(crate) fn finish(&mut self) {
        if let Some(f) = self.progress {
            f(self.state);
        }
    }
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
