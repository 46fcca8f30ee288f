//! Which files an input may make Tessera read, in one place (issue 29, item 1).
//!
//! A mesh file names other files: a glTF its buffers and images (URIs), an OBJ its
//! material libraries (`mtllib`), a library its textures (`map_Kd`). Their names come
//! from the input, which may be hostile: `../../secret.bin`, `/etc/passwd`,
//! `..%2f..%2fx`, a symlink in the folder pointing elsewhere, a FIFO, `/dev/zero`. A
//! file read there ends up in the model (as vertex colours, as texels) and is then
//! served. So every referenced file goes through [`Assets::resolve`]:
//!
//! 1. The name (percent-decoded by the caller where it is a URI) is joined to the
//!    folder of the file that names it and canonicalised (symlinks resolved, `..`
//!    removed).
//! 2. The result must lie under an *allowed root*: the canonical folder of the input,
//!    or the folder [`AssetPolicy::root`] adds (`tessera build --asset-root DIR`).
//!    Otherwise the reference is refused with an error naming it and the flag.
//! 3. It must be a regular file: a FIFO would block `open` forever, `/dev/zero` never
//!    ends, a directory or a socket is no asset. Checked with a `stat` before anything
//!    opens it, and again on the opened file ([`open_regular`], which opens with
//!    `O_NONBLOCK` so that a file swapped for a FIFO in between cannot block either).
//!
//! A name that resolves nowhere (no such file) is *missing*, which each importer treats
//! as before (a missing texture or library is a warning, a missing buffer an error); a
//! refusal is always an error, so nothing outside the root is read silently.

use std::fs::File;
use std::path::{Component, Path, PathBuf};

use crate::MeshError;

/// Where referenced files may be read from (see the module docs).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AssetPolicy {
    /// A folder allowed besides the input's own (`None`, the default: only the
    /// input's folder).
    pub root: Option<PathBuf>,
}

impl AssetPolicy {
    /// Only files under the input's own folder (the default).
    pub fn input_folder() -> AssetPolicy {
        AssetPolicy { root: None }
    }

    /// Files under `root` as well as under the input's folder.
    pub fn under(root: impl Into<PathBuf>) -> AssetPolicy {
        AssetPolicy {
            root: Some(root.into()),
        }
    }
}

/// How reading a mesh may differ from [`crate::read_mesh`]'s defaults.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Which referenced files may be read.
    pub assets: AssetPolicy,
}

/// Why a referenced file is not read.
#[derive(Debug)]
pub(crate) enum AssetError {
    /// Nothing there (or the OS refuses to say): `resolved` is where it was looked for.
    Missing {
        resolved: PathBuf,
        cause: std::io::Error,
    },
    /// Refused by the policy (outside the root, not a regular file, too large): the
    /// whole message, naming the reference and what to do.
    Refused(String),
}

impl std::fmt::Display for AssetError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AssetError::Missing { resolved, cause } => {
                write!(f, "{}: {cause}", resolved.display())
            }
            AssetError::Refused(why) => f.write_str(why),
        }
    }
}

/// The policy applied to one input: its allowed roots, canonical.
#[derive(Clone, Debug)]
pub(crate) struct Assets {
    /// The input's folder.
    folder: PathBuf,
    /// [`AssetPolicy::root`] (`--asset-root`).
    root: Option<PathBuf>,
}

impl Assets {
    /// The policy for the input at `input`.
    pub(crate) fn for_input(policy: &AssetPolicy, input: &Path) -> Result<Assets, MeshError> {
        let canonical = |dir: &Path, what: &str| {
            let c = std::fs::canonicalize(dir).map_err(|e| {
                MeshError::io(
                    dir,
                    std::io::Error::new(e.kind(), format!("{what} cannot be resolved ({e})")),
                )
            })?;
            match c.is_dir() {
                true => Ok(c),
                false => Err(MeshError::Usage {
                    path: dir.to_path_buf(),
                    detail: format!("{what} is not a directory"),
                }),
            }
        };
        Ok(Assets {
            folder: canonical(folder_of(input), "the input's folder")?,
            root: match &policy.root {
                Some(r) => Some(canonical(r, "the asset root (--asset-root)")?),
                None => None,
            },
        })
    }

    /// Whether the canonical `path` lies under an allowed root.
    fn allows(&self, path: &Path) -> bool {
        path.starts_with(&self.folder) || self.root.as_ref().is_some_and(|r| path.starts_with(r))
    }

    /// Where `name` (as the input writes it, percent-decoded), named by a file in
    /// `base_dir`, resolves: a canonical path of a regular file under the root, or why
    /// not. `what` names the reference in messages, with the name as the input writes
    /// it (`glTF buffer 0 URI '..%2fx.bin'`).
    pub(crate) fn resolve(
        &self,
        base_dir: &Path,
        name: &str,
        what: &str,
    ) -> Result<PathBuf, AssetError> {
        let joined = base_dir.join(name);
        let resolved = match std::fs::canonicalize(&joined) {
            Ok(c) => c,
            Err(cause) => {
                // Nothing there: a name that would lie outside the root is still
                // refused (what exists outside is none of the input's business).
                let lexical = std::fs::canonicalize(base_dir)
                    .map(|b| lexical_join(&b, name))
                    .unwrap_or_else(|_| joined.clone());
                if !self.allows(&lexical) {
                    return Err(self.outside(&lexical, what));
                }
                return Err(AssetError::Missing {
                    resolved: joined,
                    cause,
                });
            }
        };
        if !self.allows(&resolved) {
            return Err(self.outside(&resolved, what));
        }
        let meta = std::fs::metadata(&resolved).map_err(|cause| AssetError::Missing {
            resolved: resolved.clone(),
            cause,
        })?;
        if !meta.is_file() {
            return Err(not_regular(what, &resolved, &meta));
        }
        Ok(resolved)
    }

    fn outside(&self, resolved: &Path, what: &str) -> AssetError {
        AssetError::Refused(match &self.root {
            Some(root) => format!(
                "{what} resolves to {}, outside the input's folder {} and the asset root {} \
                 (--asset-root): pass a --asset-root DIR that contains it to allow it",
                resolved.display(),
                self.folder.display(),
                root.display()
            ),
            None => format!(
                "{what} resolves to {}, outside the input's folder {} (the allowed \
                 root): pass --asset-root DIR to allow it",
                resolved.display(),
                self.folder.display()
            ),
        })
    }
}

/// The folder of `file`, `.` for a bare file name.
pub(crate) fn folder_of(file: &Path) -> &Path {
    match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// `base` joined with `name`, `.` and `..` removed without looking at the file system
/// (for a name that does not exist, so cannot be canonicalised).
fn lexical_join(base: &Path, name: &str) -> PathBuf {
    let mut out = PathBuf::new();
    for c in base.join(name).components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

/// What kind of file `meta` describes, for messages ("a FIFO").
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "a special file"
    }
}

fn not_regular(what: &str, resolved: &Path, meta: &std::fs::Metadata) -> AssetError {
    AssetError::Refused(format!(
        "{what} ({}) is {}, not a regular file: refused (reading it could block or never \
         end)",
        resolved.display(),
        kind_of(meta)
    ))
}

/// Open `path` for reading if it is a regular file, without ever blocking: opened with
/// `O_NONBLOCK` (a FIFO opens at once instead of waiting for a writer; the flag changes
/// nothing for regular files), then checked on the open file. Anything else is an
/// error of kind `InvalidInput` saying what it is. Every importer and the builder's
/// texture reader open referenced files through this.
pub fn open_regular(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "it is {}, not a regular file (reading it could block or never end)",
                kind_of(&meta)
            ),
        ));
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(r: Result<PathBuf, AssetError>) -> String {
        match r {
            Err(AssetError::Refused(m)) => m,
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    #[test]
    fn names_resolve_under_the_root_only() {
        // Why: the glTF / OBJ references of issue 29 item 1 (traversal, absolute paths,
        // symlinks) must not reach files outside the input's folder.
        let top = tempfile::tempdir().unwrap();
        let dir = top.path().join("model");
        std::fs::create_dir_all(dir.join("tex")).unwrap();
        std::fs::write(dir.join("tex/a.png"), b"x").unwrap();
        std::fs::write(top.path().join("secret.bin"), b"s").unwrap();
        let assets = Assets::for_input(&AssetPolicy::default(), &dir.join("m.gltf")).unwrap();
        let ok = assets.resolve(&dir, "tex/a.png", "image").unwrap();
        assert_eq!(ok, std::fs::canonicalize(dir.join("tex/a.png")).unwrap());
        assert!(assets.resolve(&dir, "tex/../tex/a.png", "image").is_ok());
        let m = refused(assets.resolve(&dir, "../secret.bin", "glTF buffer 0 URI '../secret.bin'"));
        assert!(m.contains("glTF buffer 0 URI '../secret.bin'"), "{m}");
        assert!(m.contains("--asset-root DIR"), "{m}");
        let abs = top.path().join("secret.bin");
        refused(assets.resolve(&dir, abs.to_str().unwrap(), "image"));
        // A missing file outside the root is refused too; inside, it is missing.
        refused(assets.resolve(&dir, "../nothing.bin", "image"));
        assert!(matches!(
            assets.resolve(&dir, "nothing.bin", "image"),
            Err(AssetError::Missing { .. })
        ));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(top.path().join("secret.bin"), dir.join("link.bin"))
                .unwrap();
            refused(assets.resolve(&dir, "link.bin", "image"));
        }
        // Widened: the parent folder is allowed.
        let wide = Assets::for_input(&AssetPolicy::under(top.path()), &dir.join("m.gltf")).unwrap();
        assert!(wide.resolve(&dir, "../secret.bin", "image").is_ok());
        assert!(wide.resolve(&dir, "tex/a.png", "image").is_ok());
        // A root elsewhere adds to the input's folder, it does not replace it.
        let other = tempfile::tempdir().unwrap();
        let beside =
            Assets::for_input(&AssetPolicy::under(other.path()), &dir.join("m.gltf")).unwrap();
        assert!(beside.resolve(&dir, "tex/a.png", "image").is_ok());
        let m = refused(beside.resolve(&dir, "../secret.bin", "image"));
        assert!(m.contains("and the asset root"), "{m}");
    }

    #[cfg(unix)]
    #[test]
    fn non_regular_files_are_refused_before_open() {
        // Why: issue 29 items 2 and 4: /dev/zero exhausted memory, a FIFO blocked open.
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.mtl");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let assets = Assets::for_input(&AssetPolicy::default(), &dir.path().join("m.obj")).unwrap();
        let m = refused(assets.resolve(dir.path(), "f.mtl", "material library"));
        assert!(m.contains("FIFO"), "{m}");
        let m = refused(assets.resolve(dir.path(), ".", "material library"));
        assert!(m.contains("directory"), "{m}");
        let root = Assets::for_input(&AssetPolicy::under("/"), &dir.path().join("m.obj")).unwrap();
        let m = refused(root.resolve(dir.path(), "/dev/zero", "material library"));
        assert!(m.contains("character device"), "{m}");
        // open_regular never blocks on a FIFO.
        let e = open_regular(&fifo).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("FIFO"), "{e}");
        assert!(open_regular(Path::new("/dev/zero")).is_err());
    }
}
