//! The served set: which names map to which files, and what their headers say.
//!
//! Requests are resolved by looking a decoded name up in this set, never by joining a
//! request path onto the file system. The set is built at startup from the inputs
//! (model files and directories) and rebuilt from them by [`Models::rescan`]
//! (periodically, and by [`Models::refresh`] when a served directory or file changed),
//! so new builds in a served directory appear and removed ones disappear.
//!
//! Nothing here may block on what lies in a directory: a FIFO named `x.tsr` blocks a
//! plain `open` until a writer appears (issue 29), so every entry is classified by its
//! directory entry type and `stat` first, and opened with `O_NONBLOCK` and checked
//! again on the descriptor ([`open_regular`]). Every skipped name is warned about once,
//! not on every scan.
//!
//! The catalogue is cached: a request stats the served directories and files (a few
//! system calls) and rescans only when one of them changed; the JSON body is built once
//! per change of the set ([`Models::catalogue_json`]). 1,000 models: a rescan costs
//! tens of milliseconds, a cached catalogue request well under one.

use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::hash::{Hash, Hasher};
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{FileExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, RwLock};
use std::time::{Duration, SystemTime};

use tessera_format::{ModelIndex, HEADER_BYTES};

/// A file's identity: a new build renamed over the old one changes the inode (and
/// usually the size and mtime), an in-place rewrite changes size or mtime.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Identity {
    dev: u64,
    ino: u64,
    size: u64,
    mtime_s: i64,
    mtime_ns: i64,
}

impl Identity {
    pub fn of(meta: &std::fs::Metadata) -> Identity {
        Identity {
            dev: meta.dev(),
            ino: meta.ino(),
            size: meta.size(),
            mtime_s: meta.mtime(),
            mtime_ns: meta.mtime_nsec(),
        }
    }

    pub fn size(&self) -> u64 {
        self.size
    }

    /// The strong entity tag: the size and a hash of the identity (not the raw device
    /// and inode numbers, which are nobody's business), quoted.
    pub fn etag(&self) -> String {
        // SipHash with fixed keys: the same file gives the same tag across restarts.
        #[allow(deprecated)]
        let mut h =
            std::hash::SipHasher::new_with_keys(0x7465_7373_6572_6121, 0x6574_6167_2d76_3101);
        self.hash(&mut h);
        format!("\"{:x}-{:016x}\"", self.size, h.finish())
    }

    /// Modification time, whole seconds (what `Last-Modified` can say).
    pub fn modified(&self) -> SystemTime {
        if self.mtime_s >= 0 {
            SystemTime::UNIX_EPOCH + Duration::from_secs(self.mtime_s as u64)
        } else {
            SystemTime::UNIX_EPOCH - Duration::from_secs(self.mtime_s.unsigned_abs())
        }
    }
}

/// What the catalogue says about a model, from its header.
#[derive(Clone, Debug)]
pub struct ModelInfo {
    pub identity: Identity,
    pub triangles: u64,
    pub bounding_sphere: [f64; 4],
    pub format_version: u32,
    pub nodes: u64,
}

/// One served file.
#[derive(Clone, Debug)]
pub struct Entry {
    /// The file to open for each request. For files found in a served directory, the
    /// canonical path (no symbolic link in it), opened with `O_NOFOLLOW`.
    pub path: PathBuf,
    pub from_dir: bool,
    /// The header as last validated (for the identity it names).
    pub info: ModelInfo,
}

/// The inputs and the current served set, by URL name (the file name).
pub struct Models {
    files: Vec<PathBuf>,
    /// Canonical directory paths.
    dirs: Vec<PathBuf>,
    set: RwLock<BTreeMap<String, Entry>>,
    /// Warnings already logged (so a rescan every few seconds does not repeat them).
    warned: Mutex<HashSet<String>>,
    /// What the inputs looked like when the current set was scanned (taken before the
    /// scan): a refresh rescans only when this changed. Held while a rescan runs, so
    /// concurrent requests wait for one rescan instead of running their own.
    stamp: Mutex<Vec<Option<Stamp>>>,
    /// Bumped whenever the set (or an entry's info) changes.
    generation: AtomicU64,
    /// The catalogue's JSON body and the generation it was built for.
    catalogue: Mutex<Option<(u64, bytes::Bytes)>>,
}

/// What a served directory or file looked like: a directory's mtime changes when an
/// entry is created, removed or renamed into it (a new build lands by rename).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stamp {
    dev: u64,
    ino: u64,
    size: u64,
    mtime_s: i64,
    mtime_ns: i64,
    ctime_s: i64,
    ctime_ns: i64,
}

impl Stamp {
    fn of(p: &Path) -> Option<Stamp> {
        let m = std::fs::metadata(p).ok()?;
        Some(Stamp {
            dev: m.dev(),
            ino: m.ino(),
            size: m.size(),
            mtime_s: m.mtime(),
            mtime_ns: m.mtime_nsec(),
            ctime_s: m.ctime(),
            ctime_ns: m.ctime_nsec(),
        })
    }
}

/// Why the inputs give no served set at all.
#[derive(Debug)]
pub enum StartError {
    Input {
        path: PathBuf,
        source: io::Error,
    },
    NameClash {
        name: String,
        first: PathBuf,
        second: PathBuf,
    },
    NoModels {
        skipped: Vec<String>,
    },
}

/// A name can be served if it is a plain, visible file name: no separators, no control
/// characters, not hidden (the atomic writer's temporary files are `.NAME.tmp-...`).
pub fn servable_name(name: &str) -> bool {
    !name.is_empty()
        && !name.starts_with('.')
        && !name
            .chars()
            .any(|c| c == '/' || c == '\\' || c.is_control())
}

struct Scan {
    set: BTreeMap<String, Entry>,
    /// One line per input file skipped.
    skipped: Vec<String>,
    clashes: Vec<(String, PathBuf, PathBuf)>,
}

impl Models {
    /// Checks the inputs and builds the first served set; an error if an input does not
    /// exist, two models share a name, or no input holds a valid model.
    pub fn open(inputs: &[PathBuf]) -> Result<Models, StartError> {
        let mut files = Vec::new();
        let mut dirs = Vec::new();
        for p in inputs {
            let meta = std::fs::metadata(p).map_err(|source| StartError::Input {
                path: p.clone(),
                source,
            })?;
            if meta.is_dir() {
                let c = std::fs::canonicalize(p).map_err(|source| StartError::Input {
                    path: p.clone(),
                    source,
                })?;
                dirs.push(c);
            } else {
                files.push(p.clone());
            }
        }
        let models = Models {
            files,
            dirs,
            set: RwLock::new(BTreeMap::new()),
            warned: Mutex::new(HashSet::new()),
            stamp: Mutex::new(Vec::new()),
            generation: AtomicU64::new(0),
            catalogue: Mutex::new(None),
        };
        *models.stamp.lock().unwrap_or_else(|e| e.into_inner()) = models.stamps();
        let scan = models.scan(&BTreeMap::new());
        if let Some((name, first, second)) = scan.clashes.into_iter().next() {
            return Err(StartError::NameClash {
                name,
                first,
                second,
            });
        }
        for s in &scan.skipped {
            models.warn_once(s);
        }
        if scan.set.is_empty() && !inputs.is_empty() {
            return Err(StartError::NoModels {
                skipped: scan.skipped,
            });
        }
        *models.set.write().unwrap_or_else(|e| e.into_inner()) = scan.set;
        Ok(models)
    }

    /// The stamps of the inputs now: directories first, then files.
    fn stamps(&self) -> Vec<Option<Stamp>> {
        self.dirs
            .iter()
            .chain(&self.files)
            .map(|p| Stamp::of(p))
            .collect()
    }

    /// Rescans if a served directory or file changed since the last scan (blocking: a
    /// `stat` per input, and the rescan when needed). A change within the same clock
    /// tick as the scan before it is caught by the periodic [`Models::rescan`].
    pub fn refresh(&self) {
        let mut last = self.stamp.lock().unwrap_or_else(|e| e.into_inner());
        let now = self.stamps();
        if *last == now {
            return;
        }
        *last = now;
        self.rescan_now();
    }

    /// Rebuilds the served set from the inputs (blocking: it lists directories and reads
    /// headers of new or changed files).
    pub fn rescan(&self) {
        let mut last = self.stamp.lock().unwrap_or_else(|e| e.into_inner());
        *last = self.stamps();
        self.rescan_now();
    }

    /// The rescan itself (the caller holds `stamp`).
    fn rescan_now(&self) {
        let old = self.snapshot();
        let scan = self.scan(&old);
        for s in &scan.skipped {
            self.warn_once(s);
        }
        for (name, first, second) in &scan.clashes {
            self.warn_once(&format!(
                "{}: not served: a model named {name} is served from {}",
                second.display(),
                first.display()
            ));
        }
        let changed = !same_set(&old, &scan.set);
        *self.set.write().unwrap_or_else(|e| e.into_inner()) = scan.set;
        if changed {
            self.generation.fetch_add(1, Ordering::SeqCst);
        }
    }

    /// The catalogue's JSON body for the current set, built once per change; `build`
    /// makes it from a snapshot.
    pub fn catalogue_json(
        &self,
        build: impl FnOnce(&BTreeMap<String, Entry>) -> Vec<u8>,
    ) -> bytes::Bytes {
        let mut c = self.catalogue.lock().unwrap_or_else(|e| e.into_inner());
        // Read the generation before the set: a change after it rebuilds next time.
        let generation = self.generation.load(Ordering::SeqCst);
        if let Some((g, body)) = c.as_ref() {
            if *g == generation {
                return body.clone();
            }
        }
        let body = bytes::Bytes::from(build(&self.snapshot()));
        *c = Some((generation, body.clone()));
        body
    }

    /// The current set.
    pub fn snapshot(&self) -> BTreeMap<String, Entry> {
        self.set.read().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// The entry served under `name`, if any.
    pub fn lookup(&self, name: &str) -> Option<Entry> {
        self.set
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(name)
            .cloned()
    }

    /// Records that `name` now has `info` (it was revalidated at request time).
    pub fn update(&self, name: &str, info: ModelInfo) {
        if let Some(e) = self
            .set
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .get_mut(name)
        {
            e.info = info;
            self.generation.fetch_add(1, Ordering::SeqCst);
        }
    }

    /// Logs a warning unless the same one was logged before.
    pub fn warn_once(&self, msg: &str) {
        let mut w = self.warned.lock().unwrap_or_else(|e| e.into_inner());
        if w.len() > 10_000 {
            w.clear();
        }
        if w.insert(msg.to_string()) {
            tracing::warn!("{msg}");
        }
    }

    fn scan(&self, old: &BTreeMap<String, Entry>) -> Scan {
        let mut scan = Scan {
            set: BTreeMap::new(),
            skipped: Vec::new(),
            clashes: Vec::new(),
        };
        for f in &self.files {
            let Some(name) = f.file_name().and_then(|n| n.to_str()).map(str::to_string) else {
                scan.skipped
                    .push(format!("{}: skipped: not a UTF-8 file name", f.display()));
                continue;
            };
            if !servable_name(&name) {
                scan.skipped.push(format!(
                    "{}: skipped: hidden or unusable file name",
                    f.display()
                ));
                continue;
            }
            self.consider(&mut scan, old, name, f.clone(), false);
        }
        for d in &self.dirs {
            let entries = match std::fs::read_dir(d) {
                Ok(e) => e,
                Err(e) if is_resource_shortage(&e) => {
                    // Out of descriptors or memory for now: keep serving what was there.
                    scan.skipped.push(format!(
                        "{}: cannot list directory now ({e}); its models are kept",
                        d.display()
                    ));
                    for (name, entry) in old
                        .iter()
                        .filter(|(_, e)| e.from_dir && e.path.starts_with(d))
                    {
                        scan.set.insert(name.clone(), entry.clone());
                    }
                    continue;
                }
                Err(e) => {
                    scan.skipped
                        .push(format!("{}: cannot list directory: {e}", d.display()));
                    continue;
                }
            };
            let mut names: Vec<(String, PathBuf)> = Vec::new();
            for e in entries.flatten() {
                let path = e.path();
                let raw = e.file_name();
                if !raw.as_bytes().ends_with(b".tsr") {
                    continue;
                }
                let Some(name) = raw.to_str().filter(|n| servable_name(n)) else {
                    // Quoted: a name may hold a newline or other control characters.
                    scan.skipped.push(format!(
                        "{:?}: skipped: names with control characters, `\\`, a leading `.` \
                         or invalid UTF-8 are not served",
                        path
                    ));
                    continue;
                };
                // The entry's own type (lstat, no open): a FIFO, socket, device or
                // directory is skipped before anything could block on it; a symbolic
                // link is resolved and checked below.
                match e.file_type() {
                    Ok(t) if t.is_file() || t.is_symlink() => {}
                    Ok(_) => {
                        scan.skipped
                            .push(format!("{path:?}: skipped: not a regular file"));
                        continue;
                    }
                    Err(err) => {
                        scan.skipped.push(format!("{path:?}: skipped: {err}"));
                        continue;
                    }
                }
                names.push((name.to_string(), path));
            }
            names.sort();
            for (name, path) in names {
                // Only what really lies in the directory: a symbolic link is followed
                // only if its target is inside the (canonical) served directory.
                let canonical = match std::fs::canonicalize(&path) {
                    Ok(c) => c,
                    Err(e) => {
                        scan.skipped
                            .push(format!("{}: skipped: {e}", path.display()));
                        continue;
                    }
                };
                if !canonical.starts_with(d) {
                    scan.skipped.push(format!(
                        "{}: skipped: it points outside the served directory {}",
                        path.display(),
                        d.display()
                    ));
                    continue;
                }
                self.consider(&mut scan, old, name, canonical, true);
            }
        }
        scan
    }

    fn consider(
        &self,
        scan: &mut Scan,
        old: &BTreeMap<String, Entry>,
        name: String,
        path: PathBuf,
        from_dir: bool,
    ) {
        if let Some(first) = scan.set.get(&name) {
            if first.path != path {
                scan.clashes.push((name, first.path.clone(), path));
            }
            return;
        }
        let file = match open_model(&path, from_dir) {
            Ok(f) => f,
            Err(e) if is_resource_shortage(&e) => {
                // EMFILE and the like say nothing about the file: keep it as it was.
                if let Some(entry) = old.get(&name).filter(|e| e.path == path) {
                    scan.set.insert(name, entry.clone());
                }
                scan.skipped.push(format!(
                    "{}: cannot check now ({e}); kept as it was",
                    path.display()
                ));
                return;
            }
            Err(e) => {
                scan.skipped
                    .push(format!("{}: skipped: {e}", path.display()));
                return;
            }
        };
        let known = old
            .get(&name)
            .filter(|e| e.path == path)
            .map(|e| e.info.clone());
        match validate(&file, known.as_ref()) {
            Ok(info) => {
                scan.set.insert(
                    name,
                    Entry {
                        path,
                        from_dir,
                        info,
                    },
                );
            }
            Err(why) => scan
                .skipped
                .push(format!("{}: skipped: {why}", path.display())),
        }
    }
}

/// Opens a served file for reading: never through a symbolic link for directory
/// entries (their path is canonical), and only regular files.
pub fn open_model(path: &Path, from_dir: bool) -> io::Result<File> {
    open_regular(path, from_dir)
}

/// Opens `path` for reading if it is a regular file, without ever blocking on what it
/// is: a `stat` first (a FIFO, device or socket is refused before any `open`), then an
/// `open` with `O_NONBLOCK` (a FIFO swapped in between opens at once instead of
/// waiting for a writer) and the descriptor checked again. `no_follow` adds
/// `O_NOFOLLOW` (for canonical paths: a symbolic link swapped in is refused). Reads of
/// a regular file ignore `O_NONBLOCK`.
pub fn open_regular(path: &Path, no_follow: bool) -> io::Result<File> {
    let not_regular = || io::Error::other("not a regular file");
    let meta = if no_follow {
        std::fs::symlink_metadata(path)?
    } else {
        std::fs::metadata(path)?
    };
    if !meta.is_file() {
        return Err(not_regular());
    }
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    let mut flags = libc::O_NONBLOCK;
    if no_follow {
        flags |= libc::O_NOFOLLOW;
    }
    o.custom_flags(flags);
    let f = o.open(path)?;
    if !f.metadata()?.is_file() {
        return Err(not_regular());
    }
    Ok(f)
}

/// Whether `e` is a shortage of the process or system (descriptors, memory) rather than
/// something about the file: a rescan under `ulimit -n 64` must not unpublish models.
fn is_resource_shortage(e: &io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(
            libc::EMFILE | libc::ENFILE | libc::ENOMEM | libc::ENOBUFS | libc::EAGAIN | libc::EINTR
        )
    )
}

/// Whether two sets serve the same names from the same files with the same facts.
fn same_set(a: &BTreeMap<String, Entry>, b: &BTreeMap<String, Entry>) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|((na, ea), (nb, eb))| {
            na == nb && ea.path == eb.path && ea.info.identity == eb.info.identity
        })
}

/// The model's header facts for the file open as `file` (stat and header read from that
/// one descriptor); `known` is reused when the identity has not changed.
pub fn validate(file: &File, known: Option<&ModelInfo>) -> Result<ModelInfo, String> {
    let meta = file.metadata().map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err("not a regular file".into());
    }
    let identity = Identity::of(&meta);
    if let Some(k) = known.filter(|k| k.identity == identity) {
        return Ok(k.clone());
    }
    let want = HEADER_BYTES.min(identity.size) as usize;
    let mut prefix = vec![0u8; want];
    file.read_exact_at(&mut prefix, 0)
        .map_err(|e| format!("reading the header: {e}"))?;
    let h = ModelIndex::parse_header(&prefix, identity.size)
        .map_err(|e| format!("not a valid model: {e}"))?;
    Ok(ModelInfo {
        identity,
        triangles: h.input_triangles,
        bounding_sphere: h.bounding_sphere,
        format_version: h.version,
        nodes: h.node_count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 29: under `ulimit -n 64` a periodic rescan failed to list the served
    /// directory ("cannot list directory: Too many open files") and unpublished every
    /// model in it until descriptors were free again. Now what cannot be checked for
    /// want of descriptors is kept as it was.
    #[test]
    fn a_rescan_out_of_descriptors_keeps_the_models() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("d");
        std::fs::create_dir(&dir).unwrap();
        let ply = tmp.path().join("s.ply");
        let opts = tessera_gen::SphereOptions {
            triangles: 2_000,
            ..Default::default()
        };
        tessera_gen::write_sphere(&ply, &opts, &tessera_gen::NoProgress).unwrap();
        let b = tessera_build::BuildOptions {
            threads: Some(1),
            ..Default::default()
        };
        tessera_build::build(&ply, &dir.join("a.tsr"), &b, &tessera_build::NoProgress).unwrap();
        let single = tmp.path().join("b.tsr");
        std::fs::copy(dir.join("a.tsr"), &single).unwrap();
        let models = Models::open(&[dir, single]).unwrap();
        assert_eq!(models.snapshot().len(), 2);
        // No new descriptor can be opened (0: whatever the numbers of the open ones).
        let old = crate::testing::set_nofile(0);
        models.rescan();
        let kept = models.snapshot().len();
        crate::testing::set_nofile(old);
        assert_eq!(kept, 2, "models unpublished by a rescan out of descriptors");
        models.rescan();
        assert_eq!(models.snapshot().len(), 2);
    }
}
