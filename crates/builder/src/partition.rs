//! Stage 2: partition the triangles among the leaves of the tetrahedra forest (ATP
//! section 5.1), with bounded memory.
//!
//! ATP inserts triangles one by one and splits a leaf when its bucket overflows. We get
//! the same adaptive, conforming forest from three sequential passes over flat files,
//! which needs no per-leaf buffers and parallelises: (1) locate every triangle's centroid
//! in the forest down to a fixed depth and write its depth-first key; (2) count keys per
//! node, a few levels of the tree per pass, only below nodes that are still too full;
//! split every over-full node together with its whole diamond (and, recursively, what
//! those splits need to exist: the conformity closure); (3) route each triangle to its
//! leaf's contiguous range of a bucket file, whose offsets the counts give.

use crate::import::{Imported, RecordStore};
use crate::MAX_QUANT_BITS;
use crate::{BuildError, BuildOptions, Progress};
use rayon::prelude::*;
use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use tessera_tetra::{dfs_key, dfs_range, Locator, Tet, CUBE_BITS, MAX_LEVEL};

/// The global quantisation grid: `2^bits` cells along each edge of the bounding cube (the
/// format's [`tessera_format::Grid`], re-exported here where the partition makes it).
pub use tessera_format::Grid;

/// 3x the centroid of a triangle of grid points in tetra lattice units (use with scale 3).
pub fn centroid3(grid: &Grid, q: [[u32; 3]; 3]) -> [i64; 3] {
    let shift = CUBE_BITS - grid.bits;
    std::array::from_fn(|i| (q[0][i] as i64 + q[1][i] as i64 + q[2][i] as i64) << shift)
}

/// Every input vertex's grid position (12 bytes each), in a memory-mapped temporary
/// file: the key passes read three per triangle, a third of the bytes of the full vertex
/// store and no quantisation arithmetic (each vertex is quantised once, not once per
/// triangle that uses it).
pub type QuantStore = RecordStore<[u32; 3]>;

/// Quantises the whole vertex store into `path`, in parallel chunks.
pub fn quantize_vertices(
    imp: &Imported,
    grid: &Grid,
    path: &Path,
) -> Result<QuantStore, BuildError> {
    const CHUNK: u64 = 1 << 20;
    let mut w = BufWriter::with_capacity(
        1 << 20,
        File::create(path).map_err(|e| BuildError::io(path, e))?,
    );
    let mut at = 0u64;
    while at < imp.vertex_count {
        let n = (imp.vertex_count - at).min(CHUNK);
        let q: Vec<[u32; 3]> = (at..at + n)
            .into_par_iter()
            .map(|i| grid.quantize(imp.vertices.get(i as u32).position))
            .collect();
        w.write_all(bytemuck::cast_slice(&q))
            .map_err(|e| BuildError::io(path, e))?;
        at += n;
        imp.vertices.release();
    }
    w.into_inner()
        .map_err(|e| BuildError::io(path, e.into_error()))?;
    QuantStore::open(path)
}

/// A node of the forest by name: root, level, path (as in `tessera_tetra::Tet`).
pub type TetId = (u8, u8, u64);

pub fn tet_id(t: &Tet) -> TetId {
    (t.root, t.level, t.path)
}

/// The parent's name, computed from the path alone.
pub fn parent_id(id: TetId) -> Option<TetId> {
    let (r, l, p) = id;
    (l > 0).then(|| (r, l - 1, p & ((1u64 << (l - 1)) - 1)))
}

/// A leaf of the partition and its bucket.
#[derive(Clone, Debug)]
pub struct Leaf {
    pub id: TetId,
    /// First face of the leaf in the bucket file.
    pub first_face: u64,
    pub face_count: u64,
}

/// The result of stage 2.
pub struct Partition {
    pub grid: Grid,
    /// Every input vertex's grid position (the leaves read theirs from it).
    pub quantized: QuantStore,
    /// Every tetrahedron that is split (has children), conforming.
    pub split: HashSet<TetId>,
    /// Non-empty leaves, in depth-first order.
    pub leaves: Vec<Leaf>,
    /// Faces (3 x u32 global vertex indices) grouped by leaf.
    pub buckets: PathBuf,
    /// Leaves that stayed over the triangle limit because the key depth ran out.
    pub oversized_leaves: u64,
    /// Depth of the keys (deepest possible leaf).
    pub key_depth: u8,
    /// Estimated mean edge length of the input (model units).
    pub mean_edge: f64,
}

/// Grid bits for a cell of at most 1/16 of the mean edge length (see
/// `BuildOptions::quant_bits`), between 8 and 21.
pub fn auto_quant_bits(cube_size: f64, mean_edge: f64) -> u32 {
    if !(mean_edge > 0.0 && mean_edge.is_finite()) {
        return 16;
    }
    ((cube_size * 16.0 / mean_edge).log2().ceil() as i64).clamp(8, MAX_QUANT_BITS as i64) as u32
}

/// At most this many bits beyond [`auto_quant_bits`] are spent to keep the shortest
/// sampled edge (each bit costs ~0.2 bytes per triangle, 3-5% of a model; see
/// [`default_quant_bits`]).
pub const MAX_EXTRA_BITS: u32 = 6;

/// The fewest bits (at most [`MAX_QUANT_BITS`]) whose grid keeps two points `edge`
/// apart on distinct grid points: points round to the nearest grid point, so two share
/// one only when closer than a cell's diagonal, `sqrt(3)` cells.
pub fn bits_for_edge(cube_size: f64, edge: f64) -> u32 {
    if !(edge > 0.0 && edge.is_finite() && cube_size > 0.0) {
        return MAX_QUANT_BITS;
    }
    ((cube_size * 3f64.sqrt() / edge).log2().ceil() as i64).clamp(1, MAX_QUANT_BITS as i64) as u32
}

/// The default grid: fine enough for the sampling density ([`auto_quant_bits`]) and for
/// the shortest edge of the sampled triangles that have an area ([`bits_for_edge`]), so
/// no input triangle collapses onto shared grid points, with at most
/// [`MAX_EXTRA_BITS`] spent on the latter (a single sliver must not double a model's
/// size; what still collapses is counted and reported by the build). Scans with a
/// narrow range of triangle sizes keep the mean-edge grid.
pub fn default_quant_bits(cube_size: f64, mean_edge: f64, shortest_edge: f64) -> u32 {
    let by_mean = auto_quant_bits(cube_size, mean_edge);
    if !(shortest_edge > 0.0 && shortest_edge.is_finite()) {
        return by_mean;
    }
    let by_short = bits_for_edge(cube_size, shortest_edge).min(by_mean + MAX_EXTRA_BITS);
    by_mean.max(by_short).min(MAX_QUANT_BITS)
}

/// Faces sampled for the mean edge length and the key depth.
const SAMPLES: u64 = 1 << 16;

/// At most [`SAMPLES`] faces, evenly spread over the face list (all of them if fewer).
fn sample_faces(imp: &Imported) -> Result<Vec<[u32; 3]>, BuildError> {
    // Read through the face list's own record store: one page fault per few samples
    // instead of one system call per sample.
    let faces = RecordStore::<[u32; 3]>::open(&imp.faces_path)?;
    let stride = (imp.face_count / SAMPLES).max(1);
    let mut out = Vec::with_capacity(imp.face_count.min(SAMPLES + 1) as usize);
    for (n, f) in (0..imp.face_count).step_by(stride as usize).enumerate() {
        out.push(faces.get_at(f));
        release_every_samples(n, || faces.release());
    }
    faces.release();
    Ok(out)
}

/// Samples are spread over whole stores, a page or more apart: without releasing the
/// pages now and then, a 65k-sample pass would leave hundreds of MiB resident (the
/// 100M-triangle build peaked at 1.3 GiB before this).
fn release_every_samples(n: usize, release: impl FnOnce()) {
    if n % (1 << 12) == (1 << 12) - 1 {
        release();
    }
}

/// Mean edge length of the sampled faces, and the shortest edge of those of them with
/// an area (in the input's coordinates; +inf when none).
fn edge_lengths(imp: &Imported, sample: &[[u32; 3]]) -> (f64, f64) {
    let mut sum = 0.0f64;
    let mut shortest = f64::INFINITY;
    for (n, t) in sample.iter().enumerate() {
        let p = t.map(|i| imp.vertices.get(i).position.map(|c| c as f64));
        let mut least = f64::INFINITY;
        for k in 0..3 {
            let e = crate::bounds::dist2(p[k], p[(k + 1) % 3]).sqrt();
            sum += e;
            least = least.min(e);
        }
        if least > 0.0 && has_area(&p) {
            shortest = shortest.min(least);
        }
        release_every_samples(n, || imp.vertices.release());
    }
    imp.vertices.release();
    let mean = if sample.is_empty() {
        0.0
    } else {
        sum / (3 * sample.len()) as f64
    };
    (mean, shortest)
}

/// Whether a triangle has a non-zero area (exact for the f32 inputs' products).
pub(crate) fn has_area(p: &[[f64; 3]; 3]) -> bool {
    let (u, v) = (
        [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]],
        [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]],
    );
    u[1] * v[2] != u[2] * v[1] || u[2] * v[0] != u[0] * v[2] || u[0] * v[1] != u[1] * v[0]
}

/// Faces per chunk in passes that read the memory-mapped vertex store: small enough that
/// the pages touched between two releases stay at a few tens of MiB.
const VERTEX_PASS_FACES: usize = 1 << 18;

/// Faces processed per chunk; bounded memory whatever the input size.
fn chunk_faces(opts: &BuildOptions) -> usize {
    ((opts.memory_bytes / 16 / 32) as usize).clamp(1 << 14, 1 << 21)
}

fn read_chunk<T: bytemuck::Pod>(
    r: &mut impl Read,
    n: usize,
    path: &Path,
) -> Result<Vec<T>, BuildError> {
    let mut v = vec![T::zeroed(); n];
    r.read_exact(bytemuck::cast_slice_mut(&mut v))
        .map_err(|e| BuildError::io(path, e))?;
    Ok(v)
}

pub fn partition(
    imp: &Imported,
    tmp: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<Partition, BuildError> {
    let size = Grid::new(imp.bounds.min, imp.bounds.max, 1).size;
    let sample = sample_faces(imp)?;
    let (mean_edge, shortest_edge) = edge_lengths(imp, &sample);
    let bits = opts
        .quant_bits
        .unwrap_or_else(|| default_quant_bits(size, mean_edge, shortest_edge));
    let grid = Grid::new(imp.bounds.min, imp.bounds.max, bits);
    let keys_path = tmp.join("keys.bin");
    let t = std::time::Instant::now();
    let qpath = tmp.join("quantized.bin");
    let qs = quantize_vertices(imp, &grid, &qpath)?;
    let (shallow, deep) = key_depths(&qs, &grid, &sample, imp.face_count, opts);
    let pass = KeyPass {
        imp,
        qs: &qs,
        grid: &grid,
        keys: &keys_path,
        opts,
        progress,
    };
    write_keys(&pass, shallow)?;
    let crowded = crowded_cells(&keys_path, imp.face_count, shallow, opts)?;
    let key_depth = if crowded.is_empty() { shallow } else { deep };
    deepen_keys(&pass, shallow, deep, &crowded)?;
    tracing::info!(
        seconds = t.elapsed().as_secs_f64(),
        shallow,
        key_depth,
        peak_rss_mib = crate::peak_rss_mib(),
        "partition: keys"
    );
    let t = std::time::Instant::now();
    let split = choose_splits(&keys_path, imp.face_count, key_depth, opts, progress)?;
    // The conformity closure can split cells below `shallow` that were not crowded; their
    // faces need deep keys too, or routing would put them all in the cell's first leaf.
    let closure_cells: HashSet<u64> = split
        .iter()
        .filter(|id| id.1 >= shallow)
        .map(|&(r, l, p)| prefix(dfs_key(r, l, p), shallow))
        .filter(|c| !crowded.contains(c))
        .collect();
    deepen_keys(&pass, shallow, deep, &closure_cells)?;
    tracing::info!(
        seconds = t.elapsed().as_secs_f64(),
        splits = split.len(),
        peak_rss_mib = crate::peak_rss_mib(),
        "partition: counts and closure"
    );
    let t = std::time::Instant::now();
    let mut leaves = leaves_of(&split);
    let buckets = tmp.join("buckets.bin");
    let oversized = route(imp, &keys_path, &mut leaves, &buckets, opts, progress)?;
    tracing::info!(
        seconds = t.elapsed().as_secs_f64(),
        leaves = leaves.len(),
        peak_rss_mib = crate::peak_rss_mib(),
        "partition: routing"
    );
    let _ = std::fs::remove_file(&keys_path);
    Ok(Partition {
        grid,
        quantized: qs,
        split,
        leaves,
        buckets,
        oversized_leaves: oversized,
        key_depth,
        mean_edge,
    })
}

/// How deep to key triangles: `(shallow, deep)`. Every triangle is keyed at `shallow`;
/// only triangles in cells still over the leaf limit there are keyed again at `deep`, 12
/// levels deeper (density contrasts of ~250x at full leaf size). Deeper keys cost time on
/// every triangle (the locator's shortcut hits less often as cells shrink), so `shallow`
/// is measured on the sample: the shallowest depth at which at most 1/16 of the
/// triangles lie in cells estimated over half a leaf (at least 12). On the 10M sphere
/// that is 19 levels, where the fixed `1.5 log2(N / cap) + 6` used before gave 23, and
/// the key pass went from 1.9 s to 0.9-1.1 s; a margin of 1 or 2 more levels was
/// measured slower and found the same splits.
fn key_depths(
    qs: &QuantStore,
    grid: &Grid,
    sample: &[[u32; 3]],
    faces: u64,
    opts: &BuildOptions,
) -> (u8, u8) {
    let limit = 36.min(3 * grid.bits).min(MAX_LEVEL as u32) as u8;
    let mut loc = Locator::new(limit, 3);
    let mut keys: Vec<u64> = Vec::with_capacity(sample.len());
    for (n, t) in sample.iter().enumerate() {
        keys.extend(loc.locate(centroid3(grid, t.map(|i| qs.get(i)))));
        release_every_samples(n, || qs.release());
    }
    qs.release();
    keys.sort_unstable();
    let per_sample = faces as f64 / keys.len().max(1) as f64;
    let half_leaf = opts.leaf_triangles as f64 / 2.0;
    // Share of the sampled faces that lie in cells over half a leaf at `depth` (keys are
    // sorted, so cells are runs).
    let crowded_share = |depth: u8| -> f64 {
        let mut crowded = 0usize;
        let mut start = 0;
        for i in 1..=keys.len() {
            if i == keys.len() || prefix(keys[i], depth) != prefix(keys[start], depth) {
                if (i - start) as f64 * per_sample > half_leaf {
                    crowded += i - start;
                }
                start = i;
            }
        }
        crowded as f64 / keys.len().max(1) as f64
    };
    // A few dense spots (the poles of a latitude-longitude sphere, a close-up scan
    // merged into a survey) are left to the deep pass rather than keying everything deep.
    let fits = (0..=limit)
        .find(|&d| crowded_share(d) <= 1.0 / 16.0)
        .unwrap_or(limit);
    let shallow = fits.clamp(12.min(limit), limit);
    let deep = (shallow + 12).min(limit);
    (shallow, deep)
}

/// Cells at depth `shallow` that hold more than a leaf's worth of triangles.
fn crowded_cells(
    keys: &Path,
    faces: u64,
    shallow: u8,
    opts: &BuildOptions,
) -> Result<HashSet<u64>, BuildError> {
    let chunk = chunk_faces(opts);
    let mut counts: HashMap<u64, u64> = HashMap::default();
    let mut r = BufReader::with_capacity(
        1 << 20,
        File::open(keys).map_err(|e| BuildError::io(keys, e))?,
    );
    let mut done = 0u64;
    while done < faces {
        let n = ((faces - done) as usize).min(chunk);
        for key in read_chunk::<u64>(&mut r, n, keys)? {
            *counts.entry(prefix(key, shallow)).or_default() += 1;
        }
        done += n as u64;
    }
    let cap = opts.leaf_triangles as u64;
    Ok(counts
        .into_iter()
        .filter(|&(_, c)| c > cap)
        .map(|(p, _)| p)
        .collect())
}

/// What the key passes read and write: the imported faces, their quantised vertices,
/// the grid, the key file (one `u64` per face), the options and the progress sink.
struct KeyPass<'a> {
    imp: &'a Imported,
    qs: &'a QuantStore,
    grid: &'a Grid,
    keys: &'a Path,
    opts: &'a BuildOptions,
    progress: &'a dyn Progress,
}

/// Re-key at `deep` the faces whose cell at depth `shallow` is in `cells`. Deeper keys
/// extend shallower ones (same descent), so the other keys stay valid.
fn deepen_keys(
    pass: &KeyPass<'_>,
    shallow: u8,
    deep: u8,
    cells: &HashSet<u64>,
) -> Result<(), BuildError> {
    let KeyPass {
        imp,
        qs,
        grid,
        keys,
        opts,
        progress,
    } = *pass;
    if deep <= shallow || cells.is_empty() {
        return Ok(());
    }
    let crowded = cells;
    let chunk = chunk_faces(opts).min(VERTEX_PASS_FACES);
    let faces = imp.face_count;
    progress.stage("locate (deeper)", faces);
    let kf = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(keys)
        .map_err(|e| BuildError::io(keys, e))?;
    let fp = &imp.faces_path;
    let ff = File::open(fp).map_err(|e| BuildError::io(fp, e))?;
    let mut done = 0u64;
    while done < faces {
        let n = ((faces - done) as usize).min(chunk);
        let mut k = vec![0u64; n];
        kf.read_exact_at(bytemuck::cast_slice_mut(&mut k), done * 8)
            .map_err(|e| BuildError::io(keys, e))?;
        if k.iter().any(|&key| crowded.contains(&prefix(key, shallow))) {
            let mut f = vec![[0u32; 3]; n];
            ff.read_exact_at(bytemuck::cast_slice_mut(&mut f), done * 12)
                .map_err(|e| BuildError::io(fp, e))?;
            k.par_chunks_mut(4096)
                .zip(f.par_chunks(4096))
                .for_each(|(ks, fs)| {
                    let mut loc = Locator::new(deep, 3);
                    for (key, t) in ks.iter_mut().zip(fs) {
                        if crowded.contains(&prefix(*key, shallow)) {
                            *key = loc
                                .locate(centroid3(grid, t.map(|i| qs.get(i))))
                                .unwrap_or(*key);
                        }
                    }
                });
            kf.write_all_at(bytemuck::cast_slice(&k), done * 8)
                .map_err(|e| BuildError::io(keys, e))?;
            qs.release();
        }
        done += n as u64;
        progress.advance(n as u64);
        if progress.cancelled() {
            return Err(BuildError::Interrupted);
        }
    }
    progress.finish_stage();
    Ok(())
}

/// Pass 1: one depth-first key per face.
fn write_keys(pass: &KeyPass<'_>, depth: u8) -> Result<(), BuildError> {
    let KeyPass {
        imp,
        qs,
        grid,
        keys: out,
        opts,
        progress,
    } = *pass;
    progress.stage("locate", imp.face_count);
    let fp = &imp.faces_path;
    let mut faces =
        BufReader::with_capacity(1 << 20, File::open(fp).map_err(|e| BuildError::io(fp, e))?);
    let mut keys = BufWriter::with_capacity(
        1 << 20,
        File::create(out).map_err(|e| BuildError::io(out, e))?,
    );
    // Small chunks: the vertex store's pages are released after each (see
    // `VertexStore::release`), and each fault maps up to 16 neighbouring pages.
    let chunk = chunk_faces(opts).min(VERTEX_PASS_FACES);
    let mut done = 0u64;
    while done < imp.face_count {
        let n = ((imp.face_count - done) as usize).min(chunk);
        let f: Vec<[u32; 3]> = read_chunk(&mut faces, n, fp)?;
        // Consecutive faces of a mesh file are usually close in space: each worker keeps
        // its last root-to-leaf chain and re-descends only where the new centroid leaves it.
        let k: Vec<u64> = f
            .par_chunks(4096)
            .flat_map_iter(|faces| {
                let mut loc = Locator::new(depth, 3);
                faces
                    .iter()
                    .map(move |t| {
                        loc.locate(centroid3(grid, t.map(|i| qs.get(i))))
                            .unwrap_or(0)
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        keys.write_all(bytemuck::cast_slice(&k))
            .map_err(|e| BuildError::io(out, e))?;
        done += n as u64;
        progress.advance(n as u64);
        if progress.cancelled() {
            return Err(BuildError::Interrupted);
        }
        qs.release();
    }
    keys.into_inner()
        .map_err(|e| BuildError::io(out, e.into_error()))?;
    progress.finish_stage();
    Ok(())
}

/// Prefix of a depth-first key at `depth` (root bits included).
fn prefix(key: u64, depth: u8) -> u64 {
    key >> (MAX_LEVEL - depth)
}

fn id_of_prefix(p: u64, depth: u8) -> TetId {
    let root = (p >> depth) as u8;
    let mut path = 0u64;
    for i in 0..depth {
        path |= ((p >> (depth - 1 - i)) & 1) << i;
    }
    (root, depth, path)
}

/// Pass 2: counts, a band of levels at a time, then the conforming set of splits.
fn choose_splits(
    keys: &Path,
    faces: u64,
    depth: u8,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<HashSet<TetId>, BuildError> {
    // 12 levels per pass keeps the count maps small (a few million entries at most).
    const BAND: u8 = 12;
    let cap = opts.leaf_triangles as u64;
    let chunk = chunk_faces(opts);
    let mut over_full: Vec<TetId> = Vec::new();
    // Prefixes (at `from`) whose subtrees must be counted deeper.
    let mut heavy: HashSet<u64> = HashSet::default();
    let mut from = 0u8;
    loop {
        let to = (from + BAND).min(depth);
        progress.stage(&format!("count levels {from}..{to}"), faces);
        let mut counts: HashMap<u64, u64> = HashMap::default();
        let mut r = BufReader::with_capacity(
            1 << 20,
            File::open(keys).map_err(|e| BuildError::io(keys, e))?,
        );
        let mut done = 0u64;
        while done < faces {
            let n = ((faces - done) as usize).min(chunk);
            let k: Vec<u64> = read_chunk(&mut r, n, keys)?;
            for key in k {
                if from == 0 || heavy.contains(&prefix(key, from)) {
                    *counts.entry(prefix(key, to)).or_default() += 1;
                }
            }
            done += n as u64;
            progress.advance(n as u64);
            if progress.cancelled() {
                return Err(BuildError::Interrupted);
            }
        }
        progress.finish_stage();
        // Aggregate upwards within the band; nodes over the cap must split.
        let mut level_counts = counts;
        let mut next_heavy = HashSet::default();
        for d in (from..=to).rev() {
            if d < depth {
                for (&p, &c) in &level_counts {
                    if c > cap {
                        over_full.push(id_of_prefix(p, d));
                        if d == to {
                            next_heavy.insert(p);
                        }
                    }
                }
            }
            if d > from {
                let mut up: HashMap<u64, u64> = HashMap::with_capacity_and_hasher(
                    level_counts.len() / 2 + 1,
                    Default::default(),
                );
                for (p, c) in level_counts {
                    *up.entry(p >> 1).or_default() += c;
                }
                // One level up in the tree is one bit less, except at the roots where the
                // prefix is the root index itself: handled by `p >> 1` only when d > 0.
                level_counts = up;
            }
        }
        if next_heavy.is_empty() || to >= depth {
            break;
        }
        heavy = next_heavy;
        from = to;
    }
    // Conformity closure, coarse to fine.
    over_full.sort_by_key(|id| (id.1, id.0, id.2));
    over_full.dedup();
    let mut split = HashSet::default();
    for id in over_full {
        if let Some(t) = Tet::from_path(id.0, id.1, id.2) {
            ensure_split(&t, &mut split);
        }
    }
    Ok(split)
}

/// Split `t` with its whole diamond, first splitting whatever must exist for every
/// tetrahedron of that diamond to exist.
fn ensure_split(t: &Tet, split: &mut HashSet<TetId>) {
    if split.contains(&tet_id(t)) {
        return;
    }
    let mates = t.diamond_mates();
    for m in &mates {
        if let Some(p) = m.parent() {
            ensure_split(&p, split);
        }
    }
    for m in &mates {
        split.insert(tet_id(m));
    }
}

/// Children of split tetrahedra that are not split themselves, plus unsplit roots, in
/// depth-first order (empty ones are dropped after routing).
fn leaves_of(split: &HashSet<TetId>) -> Vec<Leaf> {
    let mut ids: Vec<TetId> = (0..6u8)
        .map(|r| (r, 0u8, 0u64))
        .filter(|id| !split.contains(id))
        .collect();
    for &(r, l, p) in split {
        for c in 0..2u64 {
            let id = (r, l + 1, p | (c << l));
            if !split.contains(&id) {
                ids.push(id);
            }
        }
    }
    ids.sort_by_key(|&(r, l, p)| dfs_key(r, l, p));
    ids.into_iter()
        .map(|id| Leaf {
            id,
            first_face: 0,
            face_count: 0,
        })
        .collect()
}

/// Pass 3: each face's leaf (found once, by binary search over the leaves' key ranges,
/// and kept in a temporary file of `u32`s) and the count per leaf; then the faces,
/// grouped by leaf with a counting sort per chunk, one positional write per run.
fn route(
    imp: &Imported,
    keys: &Path,
    leaves: &mut Vec<Leaf>,
    out: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
) -> Result<u64, BuildError> {
    let starts: Vec<u64> = leaves
        .iter()
        .map(|l| dfs_key(l.id.0, l.id.1, l.id.2))
        .collect();
    let ends: Vec<u64> = leaves
        .iter()
        .map(|l| dfs_range(l.id.0, l.id.1, l.id.2).1)
        .collect();
    let find = |key: u64| -> u32 {
        let i = starts.partition_point(|&s| s <= key);
        debug_assert!(i > 0 && key < ends[i - 1], "leaves tile the key space");
        i.saturating_sub(1) as u32
    };
    let chunk = chunk_faces(opts);
    let faces = imp.face_count;
    let ids_path = keys.with_extension("leaves");
    // Count, and remember each face's leaf.
    progress.stage("route (count)", faces);
    let mut counts = vec![0u64; leaves.len()];
    {
        let mut r = BufReader::with_capacity(
            1 << 20,
            File::open(keys).map_err(|e| BuildError::io(keys, e))?,
        );
        let mut w = BufWriter::with_capacity(
            1 << 20,
            File::create(&ids_path).map_err(|e| BuildError::io(&ids_path, e))?,
        );
        let mut done = 0u64;
        while done < faces {
            let n = ((faces - done) as usize).min(chunk);
            let k: Vec<u64> = read_chunk(&mut r, n, keys)?;
            let ids: Vec<u32> = k.par_iter().map(|&key| find(key)).collect();
            for &id in &ids {
                counts[id as usize] += 1;
            }
            w.write_all(bytemuck::cast_slice(&ids))
                .map_err(|e| BuildError::io(&ids_path, e))?;
            done += n as u64;
            progress.advance(n as u64);
            if progress.cancelled() {
                return Err(BuildError::Interrupted);
            }
        }
        w.into_inner()
            .map_err(|e| BuildError::io(&ids_path, e.into_error()))?;
    }
    progress.finish_stage();
    let mut cursor = vec![0u64; leaves.len()];
    let mut acc = 0u64;
    for (i, l) in leaves.iter_mut().enumerate() {
        l.first_face = acc;
        l.face_count = counts[i];
        cursor[i] = acc;
        acc += counts[i];
    }
    // Write.
    progress.stage("route (write)", faces);
    let file = File::create(out).map_err(|e| BuildError::io(out, e))?;
    file.set_len(faces * 12)
        .map_err(|e| BuildError::io(out, e))?;
    let fp = &imp.faces_path;
    let mut ir = BufReader::with_capacity(
        1 << 20,
        File::open(&ids_path).map_err(|e| BuildError::io(&ids_path, e))?,
    );
    let mut fr =
        BufReader::with_capacity(1 << 20, File::open(fp).map_err(|e| BuildError::io(fp, e))?);
    // Per-chunk counting sort: counts of the leaves this chunk touches (reset after
    // each chunk through `touched`, so the cost is per face, not per leaf).
    let mut in_chunk = vec![0u32; leaves.len()];
    let mut touched: Vec<u32> = Vec::new();
    let mut grouped: Vec<[u32; 3]> = Vec::new();
    let mut done = 0u64;
    while done < faces {
        let n = ((faces - done) as usize).min(chunk);
        let ids: Vec<u32> = read_chunk(&mut ir, n, &ids_path)?;
        let f: Vec<[u32; 3]> = read_chunk(&mut fr, n, fp)?;
        for &id in &ids {
            if in_chunk[id as usize] == 0 {
                touched.push(id);
            }
            in_chunk[id as usize] += 1;
        }
        touched.sort_unstable();
        // `in_chunk` becomes each touched leaf's next slot in `grouped`.
        let mut at = 0u32;
        for &id in &touched {
            let c = in_chunk[id as usize];
            in_chunk[id as usize] = at;
            at += c;
        }
        grouped.clear();
        grouped.resize(n, [0; 3]);
        for (&id, face) in ids.iter().zip(&f) {
            let slot = &mut in_chunk[id as usize];
            grouped[*slot as usize] = *face;
            *slot += 1;
        }
        // Each touched leaf's run now ends at its slot; runs are in leaf order.
        let mut start = 0usize;
        for &id in &touched {
            let end = in_chunk[id as usize] as usize;
            let leaf = id as usize;
            file.write_all_at(
                bytemuck::cast_slice(&grouped[start..end]),
                cursor[leaf] * 12,
            )
            .map_err(|e| BuildError::io(out, e))?;
            cursor[leaf] += (end - start) as u64;
            in_chunk[leaf] = 0;
            start = end;
        }
        touched.clear();
        done += n as u64;
        progress.advance(n as u64);
        if progress.cancelled() {
            return Err(BuildError::Interrupted);
        }
    }
    progress.finish_stage();
    let _ = std::fs::remove_file(&ids_path);
    let cap = opts.leaf_triangles as u64;
    let oversized = leaves.iter().filter(|l| l.face_count > cap).count() as u64;
    leaves.retain(|l| l.face_count > 0);
    Ok(oversized)
}

/// Read one leaf's faces from the bucket file.
pub fn read_leaf_faces(
    buckets: &File,
    path: &Path,
    leaf: &Leaf,
) -> Result<Vec<[u32; 3]>, BuildError> {
    let mut v = vec![[0u32; 3]; leaf.face_count as usize];
    buckets
        .read_exact_at(bytemuck::cast_slice_mut(&mut v), leaf.first_face * 12)
        .map_err(|e| BuildError::io(path, e))?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefix_ids_match_tetra_paths() {
        // Why: the counting pass names nodes by key prefixes, the closure by paths; they
        // must agree or the wrong tetrahedra get split.
        let p = [123_456, 654_321, 1_000_001];
        for depth in [0u8, 1, 5, 17, 33, 45] {
            let t = Tet::locate_scaled(p, 1, 45).unwrap();
            let id = id_of_prefix(prefix(t.dfs_key(), depth), depth);
            let anc = Tet::locate_scaled(p, 1, depth).unwrap();
            assert_eq!(id, tet_id(&anc), "depth {depth}");
        }
    }

    #[test]
    fn closure_splits_whole_diamonds_and_their_parents() {
        // Why: a split tetrahedron whose diamond mates do not exist breaks the diamond
        // rule that crack-free cuts rest on.
        let t = Tet::locate_scaled([700_001, 300_003, 200_002], 1, 12).unwrap();
        let mut split = HashSet::default();
        ensure_split(&t, &mut split);
        for &(r, l, p) in &split {
            let s = Tet::from_path(r, l, p).unwrap();
            for m in s.diamond_mates() {
                assert!(split.contains(&tet_id(&m)), "mate of split tet not split");
            }
            if let Some(pid) = parent_id((r, l, p)) {
                assert!(split.contains(&pid), "split tet whose parent is not split");
            }
        }
        // Leaves tile the cube: their volumes (as key ranges) cover everything once.
        let leaves = leaves_of(&split);
        let mut expect = 0u64;
        for l in &leaves {
            let (s, e) = dfs_range(l.id.0, l.id.1, l.id.2);
            assert_eq!(s, expect);
            expect = e;
        }
        assert_eq!(expect, 6u64 << MAX_LEVEL);
    }

    /// A wavy grid surface, dense in one corner (so some cells crowd and need deep keys,
    /// and the conformity closure splits cells that do not).
    fn write_uneven_grid(path: &Path, n: u32) {
        use tessera_mesh::{Attributes, PlyWriter, PlyWriterOptions, Vertex};
        let opts = PlyWriterOptions {
            attributes: Attributes::default(),
            vertex_count: ((n + 1) * (n + 1)) as u64,
            face_count: (2 * n * n) as u64,
            comments: vec![],
        };
        let mut w = PlyWriter::create(path, &opts).unwrap();
        for j in 0..=n {
            for i in 0..=n {
                // Squaring the parameter crowds vertices towards 0.
                let (u, v) = ((i as f32 / n as f32).powi(3), (j as f32 / n as f32).powi(3));
                let z = 0.05 * (7.0 * u).sin() * (5.0 * v).cos();
                w.write_vertex(&Vertex {
                    position: [u, v, z],
                    ..Default::default()
                })
                .unwrap();
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                w.write_triangle([a, a + 1, a + n + 1]).unwrap();
                w.write_triangle([a + 1, a + n + 2, a + n + 1]).unwrap();
            }
        }
        w.finish().unwrap();
    }

    #[test]
    fn every_face_lands_in_the_leaf_holding_its_centroid() {
        // Why: two-depth keying must route faces of cells that the conformity closure
        // splits (but that were not crowded) to their true leaf, not the cell's first.
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("grid.ply");
        write_uneven_grid(&input, 120);
        let opts = BuildOptions {
            leaf_triangles: 64,
            node_triangles: 32,
            ..Default::default()
        };
        let imp =
            crate::import::import(&input, dir.path(), &Default::default(), &crate::NoProgress)
                .unwrap();
        let part = partition(&imp, dir.path(), &opts, &crate::NoProgress).unwrap();
        assert!(part.leaves.len() > 50);
        let buckets = File::open(&part.buckets).unwrap();
        let mut total = 0;
        let mut max_level = 0;
        for leaf in &part.leaves {
            let faces = read_leaf_faces(&buckets, &part.buckets, leaf).unwrap();
            total += faces.len() as u64;
            max_level = max_level.max(leaf.id.1);
            for f in faces {
                let q = f.map(|i| part.grid.quantize(imp.vertices.get(i).position));
                let t = Tet::locate_scaled(centroid3(&part.grid, q), 3, leaf.id.1).unwrap();
                assert_eq!(tet_id(&t), leaf.id, "face {f:?} routed to the wrong leaf");
            }
        }
        assert_eq!(total, imp.face_count);
        assert!(
            max_level > part.key_depth.min(60) / 2,
            "want deep leaves, got {max_level}"
        );
    }
}
