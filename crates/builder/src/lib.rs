//! The Adaptive TetraPuzzles builder: any triangle mesh in, a `.tsr` multiresolution
//! model out, out of core and in parallel.
//!
//! Stages, each in its own module:
//! 1. [`import`]: stream the input into a flat vertex store and face list (bounded RAM);
//!    compute vertex normals when the input has none.
//! 2. [`partition`]: locate triangles in the binary forest of tetrahedra, choose the
//!    conforming adaptive set of splits (leaves of at most `leaf_triangles`), route
//!    triangles into per-leaf buckets on disk.
//! 3. [`hierarchy`]: bottom up, level by level, every diamond in parallel
//!    ([`diamond`]): merge children, lock the outer border, simplify, record morph
//!    destinations, split into the parent tetrahedra; saturate errors and spheres.
//! 4. Write the model atomically through `tessera_format`.
//!
//! [`verify`] checks a finished model: the format's structural checks plus the forest's
//! geometric rules (diamonds), which need `tessera-tetra`.
//!
//! Peak memory is bounded by the chunk sizes derived from [`BuildOptions::memory_bytes`]
//! and by the working set of the diamonds in flight, not by the input size.

pub mod bounds;
pub mod diamond;
mod distribute;
mod hierarchy;
pub mod import;
#[cfg(feature = "mpi")]
pub mod mpi_peers;
pub mod partition;
pub mod patch;
pub mod peers;
pub mod recut;
pub mod texture;
mod timing;
pub mod verify;

use std::path::{Path, PathBuf};
use std::time::Instant;
use tessera_format::FormatError;
use tessera_mesh::{ImportReport, MeshError};

pub use distribute::{LevelStats, RankStats};

/// Finest quantisation grid: `2^21` cells along the cube's edge (grid coordinates stay
/// below `2^22`, which the exact integer predicates of the builder need).
pub const MAX_QUANT_BITS: u32 = 21;

/// Everything the builder can be asked to do differently. `Default` is what
/// `tessera build` uses.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Memory budget in bytes for the build's own buffers (default 1 GiB).
    pub memory_bytes: u64,
    /// Worker threads; `None` = all cores.
    pub threads: Option<usize>,
    /// Quantisation: `2^quant_bits` grid cells along the bounding cube's edge (at most
    /// [`MAX_QUANT_BITS`]). The largest position error is `sqrt(3)/2` cells. `None` (the
    /// default) picks the bits from the input
    /// ([`partition::default_quant_bits`]): a cell of at most 1/16 of the mean edge
    /// length, so the position error stays under ~5% of an edge whatever the size of the
    /// model, and finer (by up to [`partition::MAX_EXTRA_BITS`] bits) where the shortest
    /// sampled edge needs it to keep every triangle.
    pub quant_bits: Option<u32>,
    /// Most triangles in a leaf (ATP: 4000).
    pub leaf_triangles: u32,
    /// Target triangles per internal node (ATP: 2000).
    pub node_triangles: u32,
    /// Where temporary files go (default: beside the output).
    pub tmp_dir: Option<PathBuf>,
    /// Nodes per index page (default [`tessera_format::DEFAULT_PAGE_NODES`]): smaller
    /// pages let a remote reader fetch less of the tree it does not need, larger ones
    /// compress better.
    pub index_page_nodes: u32,
    /// Quadric weight of vertex colours (RGB in 0..1) when simplifying; 0 lets colour
    /// play no part in which edges collapse (it is still stored and interpolated).
    pub color_weight: f32,
    /// Build as if the input had no vertex colours (all white, nothing stored).
    pub ignore_colors: bool,
    /// Build as if the input had no textures (faces in their material's colour).
    pub ignore_textures: bool,
    /// How patch textures are stored.
    pub texture: texture::TextureOptions,
    /// Where the files the input names (glTF buffers and images, MTL libraries and
    /// textures) may be read from: `None` (the default), only regular files under the
    /// input's folder; else under it or under this folder (`--asset-root`).
    pub asset_root: Option<PathBuf>,
    /// Most triangles the input may have, checked against what its header declares
    /// before anything is spooled, and as triangles arrive (`--max-input-triangles`;
    /// default [`DEFAULT_MAX_INPUT_TRIANGLES`]).
    pub max_input_triangles: u64,
}

/// [`BuildOptions::max_input_triangles`] by default: 2^32 - 1. Vertices are indexed
/// with 32 bits, so 2^32 - 1 vertices is the largest input the builder takes; a mesh
/// has about twice as many triangles as vertices, so this admits any input of up to
/// ~2^31 vertices (a 4-billion-triangle scan: a ~170 GB import spool) while a file that
/// claims more triangles than it could index vertices for (a 269-byte glTF claiming
/// 10^10) is refused at once. Raise it for larger inputs.
pub const DEFAULT_MAX_INPUT_TRIANGLES: u64 = u32::MAX as u64;

/// [`BuildOptions::color_weight`] by default: the order of the normals' weight (0.5,
/// meshoptimizer's suggestion for unit normals), as colour edges in scans matter as
/// much as shape edges (measured by `scripts/bench-appearance`).
pub const DEFAULT_COLOR_WEIGHT: f32 = 0.5;

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            memory_bytes: 1 << 30,
            threads: None,
            quant_bits: None,
            leaf_triangles: 4000,
            node_triangles: 2000,
            tmp_dir: None,
            index_page_nodes: tessera_format::DEFAULT_PAGE_NODES,
            color_weight: DEFAULT_COLOR_WEIGHT,
            ignore_colors: false,
            ignore_textures: false,
            texture: texture::TextureOptions::default(),
            asset_root: None,
            max_input_triangles: DEFAULT_MAX_INPUT_TRIANGLES,
        }
    }
}

/// The progress protocol (`tessera_mesh`'s, shared with the generators). The builder
/// polls [`Progress::cancelled`] between units of work and returns
/// [`BuildError::Interrupted`], so temporary files are removed.
pub use tessera_mesh::{NoProgress, Progress};

#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("{0}")]
    Input(MeshError),
    /// The cause is in the message, not also the `source()` (printed twice in a chain).
    #[error("{}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: the mesh has no triangles", .0.display())]
    EmptyInput(PathBuf),
    /// Every input triangle was removed as degenerate (zero area in the input, or its
    /// corners on one grid point): the model would be empty. `why` says how.
    #[error(
        "{}: every one of the {triangles} input triangles is degenerate ({why}): the model \
         would be empty",
        input.display()
    )]
    AllDegenerate {
        input: PathBuf,
        triangles: u64,
        why: String,
    },
    /// The input is within the format's limits but beyond what the options allow (a
    /// texture too large to decode within `--memory`); `detail` says what to change.
    #[error("{}: {detail}", input.display())]
    Limit { input: PathBuf, detail: String },
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error("invalid option: {0}")]
    Options(String),
    #[error("internal error: {0}")]
    Internal(String),
    #[error("interrupted")]
    Interrupted,
    /// Another rank of a distributed build failed; `message` is its error's text (what
    /// a single process would have said).
    #[error("{message}")]
    Peer { rank: usize, message: String },
}

impl BuildError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> BuildError {
        BuildError::Io {
            path: path.to_path_buf(),
            cause: source,
        }
    }
}

/// Refuses, before any work, an input that is not a regular file, and an output that is
/// the input itself (the same file, also through links: the rename at the end would
/// replace the input with the model) or a directory, or whose directory does not exist.
fn check_output(input: &Path, output: &Path) -> Result<(), BuildError> {
    // The importers read their input more than once (PLY/OBJ/STL detection, then the
    // data): a FIFO or a device would hang on the second open or lose what the first read
    // took. Refused before opening it, so nothing blocks.
    if let Ok(m) = std::fs::metadata(input) {
        if !m.is_file() && !m.is_dir() {
            return Err(BuildError::Options(format!(
                "the input {} is not a regular file (a pipe, socket or device): the importers \
                 read a file more than once; write it to a file first (e.g. `cat > mesh.ply`)",
                input.display()
            )));
        }
    }
    let same = |a: &std::fs::Metadata, b: &std::fs::Metadata| {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            a.dev() == b.dev() && a.ino() == b.ino()
        }
        #[cfg(not(unix))]
        {
            let _ = (a, b);
            false
        }
    };
    if let (Ok(i), Ok(o)) = (std::fs::metadata(input), std::fs::metadata(output)) {
        if same(&i, &o) || std::fs::canonicalize(input).ok() == std::fs::canonicalize(output).ok() {
            return Err(BuildError::Options(format!(
                "the output {} is the input: building would replace it; choose another output path",
                output.display()
            )));
        }
        if o.is_dir() {
            return Err(BuildError::Options(format!(
                "the output {} is a directory; give a file path such as {}",
                output.display(),
                output.join("model.tsr").display()
            )));
        }
    }
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(BuildError::Options(format!(
            "the output's directory {} does not exist",
            dir.display()
        )));
    }
    Ok(())
}

/// What a build did, for `--json` and the benchmark.
#[derive(Clone, Debug, Default)]
pub struct BuildReport {
    pub input_vertices: u64,
    pub input_triangles: u64,
    pub import: ImportReport,
    pub normals_computed: bool,
    pub nodes: u64,
    pub leaves: u64,
    pub levels: u32,
    pub output_bytes: u64,
    pub stored_triangles: u64,
    pub degenerate_triangles_removed: u64,
    /// Of `degenerate_triangles_removed`: triangles with a non-zero area in the input's
    /// own coordinates whose corners fell on shared grid points (lost to quantisation:
    /// a finer `quant_bits` keeps them).
    pub triangles_collapsed_by_grid: u64,
    /// When triangles collapsed: the bits whose grid keeps them all apart (the shortest
    /// edge among them over `sqrt(3)` cells, at most [`MAX_QUANT_BITS`]).
    pub quant_bits_to_keep_all: Option<u32>,
    pub duplicate_triangles_removed: u64,
    pub oversized_leaves: u64,
    /// Ears flipped and folded pairs removed after simplification (see `diamond::repair`).
    pub simplifier_repairs: u64,
    /// Bits of the quantisation grid (chosen or given).
    pub quant_bits: u32,
    /// Mean input edge length (model units), estimated from a sample of triangles.
    pub mean_edge: f64,
    /// Model units per grid step.
    pub quant_step: f64,
    /// Largest distance between an input vertex and its stored position.
    pub quant_error_max: f64,
    pub max_error: f64,
    /// The texture stage's figures (textured models).
    pub textures: Option<texture::TextureReport>,
    /// (stage, seconds).
    pub stage_seconds: Vec<(String, f64)>,
    pub seconds: f64,
    /// A distributed build ([`build_distributed`] with more than one rank): what each
    /// rank did, on rank 0 (empty elsewhere and for a single process).
    pub ranks: Vec<RankStats>,
}

impl BuildReport {
    pub fn bytes_per_input_triangle(&self) -> f64 {
        self.output_bytes as f64 / self.input_triangles.max(1) as f64
    }
    pub fn triangles_per_second(&self) -> f64 {
        self.input_triangles as f64 / self.seconds.max(1e-9)
    }
}

/// Peak resident set size of this process so far in bytes (Linux `VmHWM`; `None`
/// elsewhere). Stage logs and the CLI's report use it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Resident set size of this process now, in bytes (Linux `/proc/self/statm`; 0
/// elsewhere). Per-frame statistics use it.
pub fn current_rss_bytes() -> u64 {
    // Second field of /proc/self/statm: resident pages.
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| {
            s.split_whitespace()
                .nth(1)
                .and_then(|v| v.parse::<u64>().ok())
        })
        .map_or(0, |pages| pages * 4096)
}

pub(crate) fn peak_rss_mib() -> u64 {
    peak_rss_bytes().map_or(0, |b| b >> 20)
}

/// Build `output` from the mesh at `input`. Writes atomically: on any error nothing is
/// left at `output` (a file already there stays as it was).
pub fn build(
    input: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<BuildReport, BuildError> {
    build_distributed(input, output, opts, progress, &peers::Solo)
}

/// [`build`] by the ranks of `peers` together, each calling this with the same
/// arguments (a file system they share for `input` and `output`): each imports and
/// partitions the whole input, simplifies its share of every level's diamonds and
/// exchanges the patches (see docs/mpi.md); rank 0 writes `output`, byte for byte the
/// model [`build`] writes. Every rank returns the same outcome: on any rank's failure,
/// each returns it (the text a single process would print) and nothing is written.
pub fn build_distributed(
    input: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
    peers: &dyn peers::Peers,
) -> Result<BuildReport, BuildError> {
    if let Some(bits) = opts.quant_bits {
        if !(1..=MAX_QUANT_BITS).contains(&bits) {
            return Err(BuildError::Options(format!(
                "quantization bits must be 1..={MAX_QUANT_BITS}, got {bits}"
            )));
        }
    }
    if !(opts.color_weight.is_finite() && opts.color_weight >= 0.0) {
        return Err(BuildError::Options(format!(
            "the colour weight must be a finite number >= 0, got {}",
            opts.color_weight
        )));
    }
    if opts.leaf_triangles < 16
        || opts.node_triangles < 8
        || opts.node_triangles > opts.leaf_triangles
    {
        return Err(BuildError::Options(
            "need leaf_triangles >= 16 and 8 <= node_triangles <= leaf_triangles".into(),
        ));
    }
    check_output(input, output)?;
    let pool = {
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(n) = opts.threads {
            b = b.num_threads(n.max(1));
        }
        b.build().map_err(|e| BuildError::Internal(e.to_string()))?
    };
    pool.install(|| build_in_pool(input, output, opts, progress, peers))
}

/// Removes what builds killed before they could clean up (SIGKILL, a second Ctrl-C, a
/// power cut) left in `dir`: `.tessera-build-PID-*` work directories (up to 3.4x the
/// input) and the output's `.NAME.tmp-PID-N` file, when process PID is gone. Builds
/// still running are left alone; each removal is logged as a warning. Linux only (the
/// process test reads /proc); elsewhere nothing is removed.
fn remove_leftovers(dir: &Path, output: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let out_name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp_prefix = format!(".{out_name}.tmp-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let rest = if let Some(r) = name.strip_prefix(".tessera-build-") {
            r
        } else if let Some(r) = name.strip_prefix(&tmp_prefix) {
            r
        } else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists() {
            continue;
        }
        let path = e.path();
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        match removed {
            Ok(()) => tracing::warn!(
                "removed {}, left by an earlier build (process {pid}) that did not finish",
                path.display()
            ),
            Err(err) => tracing::warn!(
                "{} was left by an earlier build (process {pid}) and cannot be removed: {err}",
                path.display()
            ),
        }
    }
}

fn build_in_pool(
    input: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
    peers: &dyn peers::Peers,
) -> Result<BuildReport, BuildError> {
    let started = Instant::now();
    let mut report = BuildReport::default();
    // Import and partition on every rank; they all learn whether each one succeeded
    // before the hierarchy's exchanges begin.
    let prepared = prepare(input, output, opts, progress, &mut report);
    let (tmp, imported, part) = distribute::agree(peers, prepared, &|| progress.cancelled())?;
    let t = Instant::now();
    hierarchy::build_hierarchy(
        &imported,
        &part,
        tmp.path(),
        output,
        opts,
        progress,
        &mut report,
        peers,
    )?;
    report
        .stage_seconds
        .push(("hierarchy+write".to_string(), t.elapsed().as_secs_f64()));
    tracing::info!(
        stage = "hierarchy+write",
        seconds = t.elapsed().as_secs_f64(),
        peak_rss_mib = peak_rss_mib(),
        "stage done"
    );
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The stages before the hierarchy: the temporary directory, import, normals and
/// partition.
fn prepare(
    input: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
    report: &mut BuildReport,
) -> Result<(tempfile::TempDir, import::Imported, partition::Partition), BuildError> {
    let tmp_parent = match &opts.tmp_dir {
        Some(d) => d.clone(),
        None => output
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf(),
    };
    remove_leftovers(&tmp_parent, output);
    // The PID in the name lets a later build tell a dead build's leftovers from a live
    // one's (see `remove_leftovers`).
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".tessera-build-{}-", std::process::id()))
        .tempdir_in(&tmp_parent)
        .map_err(|e| BuildError::io(&tmp_parent, e))?;
    let mut t = Instant::now();
    let mut lap = |name: &str, report: &mut BuildReport| {
        report
            .stage_seconds
            .push((name.to_string(), t.elapsed().as_secs_f64()));
        tracing::info!(
            stage = name,
            seconds = t.elapsed().as_secs_f64(),
            peak_rss_mib = peak_rss_mib(),
            "stage done"
        );
        t = Instant::now();
    };
    let check = || {
        if progress.cancelled() {
            Err(BuildError::Interrupted)
        } else {
            Ok(())
        }
    };
    let limits = import::ImportLimits {
        assets: match &opts.asset_root {
            Some(root) => tessera_mesh::AssetPolicy::under(root),
            None => tessera_mesh::AssetPolicy::input_folder(),
        },
        max_input_triangles: opts.max_input_triangles,
    };
    let mut imported = import::import(input, tmp.path(), &limits, progress)?;
    if opts.ignore_colors {
        imported.attributes.colors = false;
    }
    // Every vertex at one point: every triangle is degenerate, known now. Refused before
    // the partition, which cannot split such an input and would load it as one leaf
    // (3 x 10^7 coincident vertices took 1.1-1.4 GB with --memory 64M; issue 29).
    if imported.bounds.min == imported.bounds.max {
        return Err(BuildError::AllDegenerate {
            input: input.to_path_buf(),
            triangles: imported.face_count,
            why: format!(
                "all {} vertices lie at one point, {:?}",
                imported.vertex_count, imported.bounds.min
            ),
        });
    }
    if imported.attributes.textures && !opts.ignore_textures {
        texture::check_decode_memory(&imported.report.textures, opts.memory_bytes).map_err(
            |detail| BuildError::Limit {
                input: input.to_path_buf(),
                detail,
            },
        )?;
    }
    check()?;
    report.input_vertices = imported.vertex_count;
    report.input_triangles = imported.face_count;
    report.import = imported.report.clone();
    report.normals_computed = imported.normals_computed;
    lap("import", report);
    // Normals (when the input has none) are computed as a task of the worker pool beside
    // the partition (`rayon::join`, so `--threads` still bounds the threads): the
    // partition reads only positions, and the normals are first needed by the hierarchy.
    let failed = std::sync::atomic::AtomicBool::new(false);
    let stop = || progress.cancelled() || failed.load(std::sync::atomic::Ordering::Relaxed);
    let imp = &imported;
    let (part, normals) = rayon::join(
        || {
            let part = partition::partition(imp, tmp.path(), opts, progress);
            if part.is_err() {
                failed.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            part
        },
        || {
            imp.normals_computed
                .then(|| import::compute_normals(imp, tmp.path(), opts.memory_bytes, &stop))
        },
    );
    let part = part?;
    if let Some(n) = normals {
        imported.normals = Some(n?);
    }
    check()?;
    report.oversized_leaves = part.oversized_leaves;
    lap("partition", report);
    Ok((tmp, imported, part))
}
