//! Atomic file output: write under a temporary name beside the destination, fsync, rename.
//!
//! Why it exists: every file Tessera writes (models, PLY meshes, PNG frames, stats) must
//! either appear complete at its path or not at all, whatever fails or kills the writer in
//! between; a file already at the path stays as it was until the rename replaces it. The
//! temporary file lives in the destination's directory (a rename is atomic only within one
//! file system) and is named `.NAME.tmp-PID-N`, so leftovers are easy to recognise. The
//! model writer, the PLY writer and the renderer's image and stats output all use
//! [`AtomicFile`].

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// An I/O error and the file it concerns: the temporary file for creating, writing and
/// syncing, the destination for the final rename.
#[derive(Debug)]
pub struct AtomicFileError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

impl std::fmt::Display for AtomicFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.source)
    }
}

/// No `source()`: the message already ends with the cause, and a chain printer
/// (anyhow's `{:#}`) would print it twice. The I/O error is the public `source` field.
impl std::error::Error for AtomicFileError {}

impl From<AtomicFileError> for crate::FormatError {
    fn from(e: AtomicFileError) -> Self {
        crate::FormatError::io(e.path, e.source)
    }
}

/// A buffered file that appears at its path only when [`AtomicFile::commit`] succeeds.
/// Dropped without a successful commit (an error, a panic), it removes its temporary
/// file. Write to it through [`Write`] (and [`Seek`], for encoders that need it).
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    tmp_path: PathBuf,
    /// `None` only once committed.
    out: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Creates the temporary file beside `path` with a write buffer of `buffer_bytes`.
    /// Fails if `path` has no file name or its directory cannot be written.
    pub fn create(path: &Path, buffer_bytes: usize) -> Result<AtomicFile, AtomicFileError> {
        let Some(name) = path.file_name() else {
            return Err(AtomicFileError {
                path: path.to_path_buf(),
                source: std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "output path has no file name",
                ),
            });
        };
        // pid + a per-process counter: concurrent writers never share a temporary file;
        // a stale one left by a dead process with the same pid is skipped.
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let mut attempts = 0;
        loop {
            let mut tmp_name = std::ffi::OsString::from(".");
            tmp_name.push(name);
            let n = NEXT.fetch_add(1, Ordering::Relaxed);
            tmp_name.push(format!(".tmp-{}-{n}", std::process::id()));
            let tmp_path = path.with_file_name(tmp_name);
            match File::options().write(true).create_new(true).open(&tmp_path) {
                Ok(file) => {
                    return Ok(AtomicFile {
                        path: path.to_path_buf(),
                        tmp_path,
                        out: Some(BufWriter::with_capacity(buffer_bytes, file)),
                    })
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempts < 16 => {
                    attempts += 1;
                }
                Err(source) => {
                    return Err(AtomicFileError {
                        path: tmp_path,
                        source,
                    })
                }
            }
        }
    }

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary file being written (for error messages about writes).
    pub fn tmp_path(&self) -> &Path {
        &self.tmp_path
    }

    /// Flushes, fsyncs and closes the temporary file, renames it onto the destination and
    /// syncs the directory (best effort: a complete file is not undone if that fails).
    /// On error the temporary file is removed and the destination is untouched.
    pub fn commit(mut self) -> Result<(), AtomicFileError> {
        let tmp_err = |source| AtomicFileError {
            path: self.tmp_path.clone(),
            source,
        };
        let out = self.out.take().ok_or_else(|| tmp_err(committed()))?;
        let file = out.into_inner().map_err(|e| tmp_err(e.into_error()))?;
        file.sync_all().map_err(tmp_err)?;
        // Closed before the rename (Windows cannot rename an open file).
        drop(file);
        if let Err(source) = std::fs::rename(&self.tmp_path, &self.path) {
            let _ = std::fs::remove_file(&self.tmp_path);
            return Err(AtomicFileError {
                path: self.path.clone(),
                source,
            });
        }
        #[cfg(unix)]
        {
            let dir = match self.path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }

    fn out(&mut self) -> std::io::Result<&mut BufWriter<File>> {
        self.out.as_mut().ok_or_else(committed)
    }
}

/// The error of a write after `commit` (which consumes the file, so this is unreachable
/// through the public API).
fn committed() -> std::io::Error {
    std::io::Error::other("atomic file already committed")
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out()?.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.out()?.write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out()?.flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.out()?.seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            // Close before removing (required on Windows); errors are irrelevant here.
            drop(self.out.take());
            let _ = std::fs::remove_file(&self.tmp_path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn appears_only_on_commit_and_replaces_the_old_file() {
        // Why: a reader of `path` must see the old file or the complete new one, never a
        // prefix, and the temporary name must be recognisable as a leftover.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        std::fs::write(&path, b"old").unwrap();
        let mut f = AtomicFile::create(&path, 4).unwrap();
        f.write_all(b"new contents").unwrap();
        let tmp = f
            .tmp_path()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        assert!(tmp.starts_with(".out.bin.tmp-"), "{tmp}");
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        f.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new contents");
        assert_eq!(names(dir.path()), ["out.bin"]);
    }

    #[test]
    fn dropped_without_commit_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let mut f = AtomicFile::create(&path, 1 << 10).unwrap();
        f.write_all(&[7; 5000]).unwrap();
        drop(f);
        assert!(names(dir.path()).is_empty());
    }

    #[test]
    fn errors_name_the_file_they_concern() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no/such/dir/out.bin");
        let e = AtomicFile::create(&missing, 16).unwrap_err();
        assert!(e.path.starts_with(dir.path().join("no/such/dir")), "{e}");
        // A directory in the way: the rename fails, naming the destination.
        let blocked = dir.path().join("blocked");
        std::fs::create_dir_all(blocked.join("child")).unwrap();
        let mut f = AtomicFile::create(&blocked, 16).unwrap();
        f.write_all(b"x").unwrap();
        let e = f.commit().unwrap_err();
        assert_eq!(e.path, blocked);
        assert_eq!(names(dir.path()), ["blocked"]);
        assert!(AtomicFile::create(Path::new("/"), 16).is_err());
    }
}
