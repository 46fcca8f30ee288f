//! Stage 1: stream the input mesh into two flat temporary files, a vertex store (one
//! fixed-size record per vertex, memory-mapped later for random access) and a face list
//! (three `u32` per triangle), while measuring the bounding box. Nothing proportional to
//! the mesh stays in memory. Inputs without normals get area-weighted vertex normals
//! here, globally, so a vertex shared by two patches has one normal in both.

use crate::{BuildError, Progress};
use bytemuck::{Pod, Zeroable};
use memmap2::{Mmap, MmapMut};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;
use std::time::Instant;
use tessera_mesh::{
    AssetPolicy, Attributes, ImportReport, MeshError, MeshHeader, MeshVisitor, ReadOptions, Vertex,
};

/// A vertex as stored in the temporary vertex store. 40 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct StoredVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub color: [u8; 4],
    pub uv: [f32; 2],
    /// `tessera_mesh::Vertex::texture`.
    pub texture: u32,
}

/// Axis-aligned bounding box of the input positions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// What stage 1 leaves behind.
pub struct Imported {
    /// The input file (for messages).
    pub input: std::path::PathBuf,
    pub vertices: VertexStore,
    pub faces_path: std::path::PathBuf,
    pub face_count: u64,
    pub vertex_count: u64,
    pub attributes: Attributes,
    /// Whether the input had no normals, so they are computed ([`compute_normals`]).
    pub normals_computed: bool,
    /// The computed normals, once [`compute_normals`] has run (`None` when the input
    /// has normals: they are in the vertex store).
    pub normals: Option<RecordStore<[f32; 3]>>,
    pub bounds: Aabb,
    pub report: ImportReport,
}

impl Imported {
    /// Unit normal of vertex `i`, whose stored record is `v`.
    #[inline]
    pub fn normal(&self, i: u32, v: &StoredVertex) -> [f32; 3] {
        self.normals.as_ref().map_or(v.normal, |n| n.get(i))
    }

    /// Releases the resident pages of every store (see [`RecordStore::release`]).
    pub fn release(&self) {
        self.vertices.release();
        if let Some(n) = &self.normals {
            n.release();
        }
    }
}

/// Read-only random access to a temporary file of fixed-size records (the vertex store,
/// the quantised positions) through a memory map. The map's resident pages count towards
/// the process's RSS, so long passes call [`RecordStore::release`] now and then: the
/// pages stay in the page cache, only our mapping forgets them.
pub struct RecordStore<T> {
    map: Option<Mmap>,
    _record: std::marker::PhantomData<T>,
}

/// The vertex store: one [`StoredVertex`] per input vertex.
pub type VertexStore = RecordStore<StoredVertex>;

impl<T: Pod> RecordStore<T> {
    pub fn open(path: &Path) -> Result<RecordStore<T>, BuildError> {
        let file = File::open(path).map_err(|e| BuildError::io(path, e))?;
        let len = file.metadata().map_err(|e| BuildError::io(path, e))?.len();
        let map = if len == 0 {
            None
        } else {
            // SAFETY: the file is our own temporary file; nothing else writes it while
            // mapped.
            let map = unsafe { Mmap::map(&file) }.map_err(|e| BuildError::io(path, e))?;
            // Access is scattered (a leaf's vertices, a face's corners): without this hint
            // the kernel maps 16 neighbouring pages around every fault and RSS balloons.
            let _ = map.advise(memmap2::Advice::Random);
            Some(map)
        };
        Ok(RecordStore {
            map,
            _record: std::marker::PhantomData,
        })
    }

    /// Record `i` (the caller has validated indices at import).
    #[inline]
    pub fn get(&self, i: u32) -> T {
        self.get_at(i as u64)
    }

    /// Record `i` of a store that may hold more than 2^32 records (faces).
    #[inline]
    pub fn get_at(&self, i: u64) -> T {
        let b = self.map.as_deref().unwrap_or(&[]);
        let size = std::mem::size_of::<T>();
        let o = i as usize * size;
        bytemuck::pod_read_unaligned(&b[o..o + size])
    }

    /// Drop this process's resident pages of the map (they remain in the page cache).
    pub fn release(&self) {
        if let Some(m) = &self.map {
            // SAFETY: DONTNEED on a read-only shared file mapping only discards page
            // table entries; later reads fault the same file contents back in.
            let _ = unsafe { m.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) };
        }
    }
}

/// What the import may read and how much it may spool (the parts of
/// [`crate::BuildOptions`] stage 1 needs).
#[derive(Clone, Debug)]
pub struct ImportLimits {
    /// Which files the input may name (glTF buffers and images, MTL libraries and
    /// textures): by default regular files under the input's folder.
    pub assets: AssetPolicy,
    /// Most triangles the input may have ([`crate::DEFAULT_MAX_INPUT_TRIANGLES`]).
    pub max_input_triangles: u64,
}

impl Default for ImportLimits {
    fn default() -> Self {
        ImportLimits {
            assets: AssetPolicy::default(),
            max_input_triangles: crate::DEFAULT_MAX_INPUT_TRIANGLES,
        }
    }
}

/// Bytes the import spools per vertex (a [`StoredVertex`]) and per triangle.
const SPOOL_VERTEX_BYTES: u64 = std::mem::size_of::<StoredVertex>() as u64;
const SPOOL_TRIANGLE_BYTES: u64 = 12;

/// Vertices between two polls of [`Progress::cancelled`] (the triangle sink and the
/// importers poll their own loops): 65536 vertices are 2.5 MiB of spool, a few ms.
const POLL_VERTICES: u64 = 1 << 16;

/// Free bytes for an unprivileged writer on the file system holding `dir` (`None` when
/// it cannot be told: not Unix, or `statvfs` fails).
pub fn free_bytes(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
        // SAFETY: `c` is NUL-terminated, `st` a valid out-parameter.
        if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
            return None;
        }
        Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// The refusal of an input whose declared size will not fit: more triangles than
/// `limits` allow, or an import spool larger than the free space of `tmp` (`free`).
/// `None` when it fits (or nothing is declared).
fn check_declared(
    header: &MeshHeader,
    limits: &ImportLimits,
    tmp: &Path,
    free: Option<u64>,
) -> Option<String> {
    let faces = header.face_count.unwrap_or(0);
    if faces > limits.max_input_triangles {
        return Some(format!(
            "the input declares {faces} triangles, more than --max-input-triangles {} allows \
             (raise it if the input is what you meant to build)",
            limits.max_input_triangles
        ));
    }
    let vertices = header.vertex_count.unwrap_or(0);
    let spool = vertices
        .saturating_mul(SPOOL_VERTEX_BYTES)
        .saturating_add(faces.saturating_mul(SPOOL_TRIANGLE_BYTES));
    match free {
        Some(free) if spool > free => Some(format!(
            "the input declares {vertices} vertices and {faces} triangles: importing them \
             spools {:.1} GB to {}, which has {:.1} GB free (and the later stages need more); \
             free space, or pass --tmp-dir on a larger disk",
            spool as f64 / 1e9,
            tmp.display(),
            free as f64 / 1e9
        )),
        _ => None,
    }
}

struct Sink<'a> {
    /// The input, named in the limits' messages.
    input: &'a Path,
    limits: &'a ImportLimits,
    tmp: &'a Path,
    vertices: BufWriter<File>,
    faces: BufWriter<File>,
    attributes: Attributes,
    vertex_count: u64,
    face_count: u64,
    bounds: Aabb,
    progress: &'a dyn Progress,
    paths: (&'a Path, &'a Path),
}

impl MeshVisitor for Sink<'_> {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError> {
        // Before anything is spooled: a 269-byte glTF may declare 3 x 10^9 vertices, and
        // 20k instances of one mesh 10^8 triangles (issue 29, item 3).
        if let Some(why) = check_declared(header, self.limits, self.tmp, free_bytes(self.tmp)) {
            return Err(MeshError::Visitor(format!(
                "{}: {why}",
                self.input.display()
            )));
        }
        self.attributes = header.attributes;
        if let Some(n) = header.face_count {
            self.progress.stage("import", n);
        }
        Ok(())
    }

    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        if v.position.iter().any(|c| !c.is_finite()) {
            return Err(MeshError::Visitor(format!(
                "vertex {} has a non-finite coordinate",
                self.vertex_count
            )));
        }
        if self.vertex_count >= u32::MAX as u64 {
            return Err(MeshError::Visitor("more than 4294967295 vertices".into()));
        }
        for i in 0..3 {
            let c = v.position[i] as f64;
            self.bounds.min[i] = self.bounds.min[i].min(c);
            self.bounds.max[i] = self.bounds.max[i].max(c);
        }
        let s = StoredVertex {
            position: v.position,
            normal: v.normal,
            color: v.color,
            uv: v.uv,
            texture: v.texture,
        };
        self.vertices
            .write_all(bytemuck::bytes_of(&s))
            .map_err(|e| MeshError::Visitor(format!("{}: {e}", self.paths.0.display())))?;
        self.vertex_count += 1;
        if self.vertex_count.is_multiple_of(POLL_VERTICES) && self.progress.cancelled() {
            return Err(MeshError::Interrupted);
        }
        Ok(())
    }

    fn cancelled(&self) -> bool {
        self.progress.cancelled()
    }

    fn triangle(&mut self, idx: [u32; 3]) -> Result<(), MeshError> {
        self.faces
            .write_all(bytemuck::bytes_of(&idx))
            .map_err(|e| MeshError::Visitor(format!("{}: {e}", self.paths.1.display())))?;
        self.face_count += 1;
        // Inputs that do not declare their size (OBJ, ASCII STL) are held to the limit
        // as they arrive.
        if self.face_count > self.limits.max_input_triangles {
            return Err(MeshError::Visitor(format!(
                "{}: the input has more than {} triangles, the most --max-input-triangles \
                 allows (raise it if the input is what you meant to build)",
                self.input.display(),
                self.limits.max_input_triangles
            )));
        }
        if self.face_count.is_multiple_of(1 << 20) {
            self.progress.advance(1 << 20);
            if self.progress.cancelled() {
                return Err(MeshError::Interrupted);
            }
        }
        Ok(())
    }
}

/// Stage 1. Temporary files go in `tmp`; `limits` says which referenced files may be
/// read and how large the input may be. Stops with [`BuildError::Interrupted`] when
/// `progress` is cancelled.
pub fn import(
    input: &Path,
    tmp: &Path,
    limits: &ImportLimits,
    progress: &dyn Progress,
) -> Result<Imported, BuildError> {
    let vpath = tmp.join("vertices.bin");
    let fpath = tmp.join("faces.bin");
    let create = |p: &Path| File::create(p).map_err(|e| BuildError::io(p, e));
    let mut sink = Sink {
        input,
        limits,
        tmp,
        vertices: BufWriter::with_capacity(1 << 20, create(&vpath)?),
        faces: BufWriter::with_capacity(1 << 20, create(&fpath)?),
        attributes: Attributes::default(),
        vertex_count: 0,
        face_count: 0,
        bounds: Aabb {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        },
        progress,
        paths: (&vpath, &fpath),
    };
    progress.stage("import", 0);
    let parse_started = Instant::now();
    let options = ReadOptions {
        assets: limits.assets.clone(),
    };
    let report = tessera_mesh::read_mesh_with(input, &options, &mut sink).map_err(|e| match e {
        MeshError::Interrupted => BuildError::Interrupted,
        e => BuildError::Input(e),
    })?;
    progress.finish_stage();
    let Sink {
        vertices,
        faces,
        attributes,
        vertex_count,
        face_count,
        bounds,
        ..
    } = sink;
    for (w, p) in [(vertices, &vpath), (faces, &fpath)] {
        w.into_inner()
            .map_err(|e| BuildError::io(p, e.into_error()))?;
    }
    if face_count == 0 {
        return Err(BuildError::EmptyInput(input.to_path_buf()));
    }
    let normals_computed = !attributes.normals;
    tracing::info!(
        seconds = parse_started.elapsed().as_secs_f64(),
        "import: parsed"
    );
    if !normals_computed {
        normalise_given_normals(&vpath)?;
    }
    let attributes = Attributes {
        normals: true,
        ..attributes
    };
    Ok(Imported {
        input: input.to_path_buf(),
        vertices: VertexStore::open(&vpath)?,
        faces_path: fpath,
        face_count,
        vertex_count,
        attributes,
        normals_computed,
        normals: None,
        bounds,
        report,
    })
}

fn map_mut(path: &Path) -> Result<Option<MmapMut>, BuildError> {
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| BuildError::io(path, e))?;
    if file.metadata().map_err(|e| BuildError::io(path, e))?.len() == 0 {
        return Ok(None);
    }
    // SAFETY: our own temporary file, mapped once, by this thread only.
    let map = unsafe { MmapMut::map_mut(&file) }.map_err(|e| BuildError::io(path, e))?;
    let _ = map.advise(memmap2::Advice::Random); // see VertexStore::open
    Ok(Some(map))
}

/// Drop the resident pages of a shared, writable file mapping; dirty pages stay in the
/// page cache and are written back by the kernel, so nothing is lost.
fn release_mut(map: &MmapMut) {
    // SAFETY: see above; for MAP_SHARED file mappings DONTNEED keeps the data.
    let _ = unsafe { map.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) };
}

/// Area-weighted vertex normals for an input without them, accumulated over the face
/// list in one sequential pass (sequential so the sums, and so the output, are
/// deterministic), into their own store `normals.bin` (12 bytes per vertex).
///
/// It only reads the vertex store, so it can run beside the partition, which reads only
/// positions: on the 10M sphere this pass takes ~0.6 s on one core, which the
/// partition's serial stretches leave idle. It stops early with
/// [`BuildError::Interrupted`] when `stop` returns true.
///
/// Copies of one position (an input with texture coordinates splits its vertices at UV
/// seams) share one normal, the sum over all their faces: otherwise each side of a seam
/// is shaded from its own faces only and the seam shows as a crease (a textured cow
/// rendered with sibling normals 70-160 degrees apart). `memory_bytes` bounds the
/// position table that finds the copies ([`first_copies`]).
pub fn compute_normals(
    imp: &Imported,
    tmp: &Path,
    memory_bytes: u64,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<RecordStore<[f32; 3]>, BuildError> {
    let started = Instant::now();
    let copies = if imp.attributes.uvs {
        first_copies(imp, tmp, memory_bytes, stop)?
    } else {
        None
    };
    let npath = tmp.join("normals.bin");
    let file = File::create(&npath).map_err(|e| BuildError::io(&npath, e))?;
    file.set_len(imp.vertex_count * 12)
        .map_err(|e| BuildError::io(&npath, e))?;
    drop(file);
    let fpath = &imp.faces_path;
    if let Some(mut map) = map_mut(&npath)? {
        let mut reader = BufReader::with_capacity(
            1 << 20,
            File::open(fpath).map_err(|e| BuildError::io(fpath, e))?,
        );
        let mut buf = vec![0u8; 12 << 16];
        let mut done = 0u64;
        while done < imp.face_count {
            let n = ((imp.face_count - done) as usize).min(1 << 16);
            reader
                .read_exact(&mut buf[..n * 12])
                .map_err(|e| BuildError::io(fpath, e))?;
            let normals: &mut [[f32; 3]] = bytemuck::cast_slice_mut(&mut map[..]);
            for f in buf[..n * 12].chunks_exact(12) {
                let t: [u32; 3] = bytemuck::pod_read_unaligned(f);
                let p = |i: u32| imp.vertices.get(i).position.map(|c| c as f64);
                let n = crate::patch::face_normal(p(t[0]), p(t[1]), p(t[2]));
                for &i in &t {
                    let i = copies.as_ref().map_or(i, |c| c.get(i));
                    let vn = &mut normals[i as usize];
                    for k in 0..3 {
                        vn[k] += n[k] as f32;
                    }
                }
            }
            done += n as u64;
            if stop() {
                return Err(BuildError::Interrupted);
            }
            // Release often: every fault maps up to 16 neighbouring (cached) pages, so
            // the resident set is an order of magnitude above the pages really touched.
            if done % (1 << 18) < (1 << 16) {
                release_mut(&map);
                imp.vertices.release();
                if let Some(c) = &copies {
                    c.release();
                }
            }
        }
        if let Some(c) = &copies {
            // Each copy takes its first copy's sum (first copies come first: c[i] <= i),
            // 4M vertices at a time between releases of the maps.
            let n = imp.vertex_count as u32;
            for start in (0..n).step_by(1 << 22) {
                let normals: &mut [[f32; 3]] = bytemuck::cast_slice_mut(&mut map[..]);
                for i in start..n.min(start + (1 << 22)) {
                    let f = c.get(i);
                    if f != i {
                        normals[i as usize] = normals[f as usize];
                    }
                }
                release_mut(&map);
                c.release();
            }
        }
        normalise_released(&mut map, |n: &mut [f32; 3]| n);
        map.flush().map_err(|e| BuildError::io(&npath, e))?;
        release_mut(&map);
    }
    tracing::info!(
        seconds = started.elapsed().as_secs_f64(),
        "normals computed"
    );
    RecordStore::open(&npath)
}

/// For every vertex, the index of the first vertex with bit-identical position (itself
/// for most), in a memory-mapped temporary store (4 bytes per vertex); `None` when no
/// position repeats. Vertices go through a position table in `ceil(24 V / (memory/4))`
/// passes, each over the positions whose hash falls in its range, so the table stays
/// within a quarter of `memory_bytes` whatever the input size.
pub fn first_copies(
    imp: &Imported,
    tmp: &Path,
    memory_bytes: u64,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<Option<RecordStore<u32>>, BuildError> {
    let n = imp.vertex_count;
    if n == 0 {
        return Ok(None);
    }
    // ~24 bytes per entry of a hash table of ([u32; 3], u32) at its load factor.
    let per_pass = (memory_bytes / 4 / 24).max(1 << 16);
    let passes = n.div_ceil(per_pass);
    let path = tmp.join("first-copies.bin");
    let file = File::create(&path).map_err(|e| BuildError::io(&path, e))?;
    file.set_len(n * 4).map_err(|e| BuildError::io(&path, e))?;
    drop(file);
    let Some(mut map) = map_mut(&path)? else {
        return Ok(None);
    };
    let hash = |p: &[u32; 3]| {
        let h =
            (u64::from(p[0]) ^ u64::from(p[1]).rotate_left(21) ^ u64::from(p[2]).rotate_left(42))
                .wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h % passes
    };
    let mut repeats = 0u64;
    let mut table: rustc_hash::FxHashMap<[u32; 3], u32> = Default::default();
    for pass in 0..passes {
        table.clear();
        for i in 0..n as u32 {
            if i % (1 << 20) == 0 {
                if stop() {
                    return Err(BuildError::Interrupted);
                }
                imp.vertices.release();
                release_mut(&map);
            }
            let p = imp.vertices.get(i).position.map(f32::to_bits);
            if passes > 1 && hash(&p) != pass {
                continue;
            }
            let f = *table.entry(p).or_insert(i);
            bytemuck::cast_slice_mut::<u8, u32>(&mut map[..])[i as usize] = f;
            repeats += u64::from(f != i);
        }
    }
    drop(table);
    imp.vertices.release();
    tracing::info!(repeats, passes, "normals: copies of a position found");
    if repeats == 0 {
        let _ = std::fs::remove_file(&path);
        return Ok(None);
    }
    map.flush().map_err(|e| BuildError::io(&path, e))?;
    drop(map);
    Ok(Some(RecordStore::open(&path)?))
}

/// Normalise every stored normal, 64 MiB of the map at a time, releasing the pages in
/// between (touching the whole store at once would make it all resident).
fn normalise_released<T: Pod>(map: &mut MmapMut, normal: impl Fn(&mut T) -> &mut [f32; 3]) {
    let size = std::mem::size_of::<T>();
    let slab = size << 21; // 2M records
    let len = map.len() - map.len() % size;
    let mut at = 0;
    while at < len {
        let end = (at + slab).min(len);
        for r in bytemuck::cast_slice_mut::<u8, T>(&mut map[at..end]) {
            unit(normal(r));
        }
        at = end;
        release_mut(map);
    }
}

fn normalise_given_normals(vpath: &Path) -> Result<(), BuildError> {
    let Some(mut map) = map_mut(vpath)? else {
        return Ok(());
    };
    normalise_released(&mut map, |v: &mut StoredVertex| &mut v.normal);
    map.flush().map_err(|e| BuildError::io(vpath, e))?;
    release_mut(&map);
    Ok(())
}

/// Unit length; a zero normal (isolated vertex, degenerate fan) becomes +Z.
fn unit(n: &mut [f32; 3]) {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    *n = if l > 0.0 && l.is_finite() {
        [n[0] / l, n[1] / l, n[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_sizes_over_the_limits_are_refused_before_spooling() {
        // Why: issue 29, item 3: a 269-byte glTF declaring 3 x 10^9 positions spooled
        // until the disk was full.
        let h = MeshHeader {
            vertex_count: Some(3_000_000_000),
            face_count: Some(1_000_000_000),
            ..MeshHeader::default()
        };
        let tmp = Path::new("/tmp");
        let l = ImportLimits::default();
        let why = check_declared(&h, &l, tmp, Some(100_000_000_000)).unwrap();
        assert!(
            why.contains("spools 132.0 GB to /tmp, which has 100.0 GB free"),
            "{why}"
        );
        assert!(check_declared(&h, &l, tmp, Some(200_000_000_000)).is_none());
        assert!(check_declared(&h, &l, tmp, None).is_none());
        let small = ImportLimits {
            max_input_triangles: 1000,
            ..ImportLimits::default()
        };
        let why = check_declared(&h, &small, tmp, None).unwrap();
        assert!(
            why.contains("more than --max-input-triangles 1000"),
            "{why}"
        );
        assert!(free_bytes(tmp).is_some_and(|b| b > 0));
    }

    /// A progress that asks to stop from the start.
    struct Stopped;
    impl Progress for Stopped {
        fn stage(&self, _: &str, _: u64) {}
        fn advance(&self, _: u64) {}
        fn finish_stage(&self) {}
        fn cancelled(&self) -> bool {
            true
        }
    }

    #[test]
    fn cancelling_stops_the_vertex_spool() {
        // Why: issue 29, item 3: Ctrl-C was polled per 2^20 triangles only, after every
        // vertex was spooled (here 10^7 zeros: 400 MB; in the issue 3 x 10^9: the disk).
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("zeros.gltf");
        std::fs::write(
            &input,
            r#"{"asset":{"version":"2.0"},
"accessors":[{"componentType":5126,"count":10000000,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}]}"#,
        )
        .unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let r = import(&input, tmp.path(), &ImportLimits::default(), &Stopped);
        assert!(matches!(r, Err(BuildError::Interrupted)), "{:?}", r.err());
        let spooled = std::fs::metadata(tmp.path().join("vertices.bin"))
            .unwrap()
            .len();
        assert!(
            spooled <= (1 << 16) * 40,
            "{spooled} bytes spooled after the stop"
        );
    }

    fn rss_file_kib() -> Option<u64> {
        let s = std::fs::read_to_string("/proc/self/status").ok()?;
        s.lines()
            .find(|l| l.starts_with("RssFile:"))?
            .split_whitespace()
            .nth(1)?
            .parse()
            .ok()
    }

    #[test]
    fn release_drops_resident_pages_of_the_vertex_store() {
        // Why: the 100M-triangle build must stay under 1 GiB of RSS while it reads a
        // 1.8 GB vertex store through a memory map.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.bin");
        let n = (64 << 20) / std::mem::size_of::<StoredVertex>();
        std::fs::write(&path, vec![1u8; n * std::mem::size_of::<StoredVertex>()]).unwrap();
        let store = VertexStore::open(&path).unwrap();
        let Some(before) = rss_file_kib() else { return }; // not Linux
        let mut sum = 0.0f32;
        for i in 0..n as u32 {
            sum += store.get(i).position[0];
        }
        assert!(sum != 0.0);
        let touched = rss_file_kib().unwrap();
        store.release();
        let after = rss_file_kib().unwrap();
        assert!(
            touched > before + 50_000,
            "reading 64 MiB should make it resident: {before} -> {touched} KiB"
        );
        assert!(
            after + 50_000 < touched,
            "release did not drop the pages: {touched} -> {after} KiB"
        );
        drop(store);
        // The same for the writable map of the normals pass (dirty shared pages).
        let mut map = map_mut(&path).unwrap().unwrap();
        let before = rss_file_kib().unwrap();
        for b in map.iter_mut().step_by(4096) {
            *b = 2;
        }
        let touched = rss_file_kib().unwrap();
        release_mut(&map);
        let after = rss_file_kib().unwrap();
        eprintln!("mut: {before} -> {touched} -> {after} KiB");
        assert!(
            after + 50_000 < touched,
            "release_mut did not drop the pages: {touched} -> {after} KiB"
        );
        map.flush().unwrap();
        assert_eq!(
            std::fs::read(&path).unwrap()[4096],
            2,
            "released dirty pages keep their data"
        );
    }
}
