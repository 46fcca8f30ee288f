//! The committed fuzz inputs, for the tests that replay them on stable through the fuzz
//! targets' own bodies (`tests/corpus.rs` of format, mesh and select): the seeds of
//! `fuzz/corpus/<target>/` and the minimised crashes of `fuzz/regressions/<target>/`,
//! each regression with the piece of error its fix gives.

use std::path::{Path, PathBuf};

/// The repository's `fuzz/` folder.
pub fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz")
}

/// The files of `fuzz/<kind>/<target>/` (`kind`: `corpus` or `regressions`), sorted;
/// none when the folder is absent.
pub fn fuzz_files(kind: &str, target: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(fuzz_dir().join(kind).join(target))
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file());
    v.sort();
    v
}

/// The bytes of `p`; panics naming the file.
pub fn read_bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A regression of `fuzz/regressions/<target>/`.
pub struct Regression<'a> {
    /// Its file name.
    pub name: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
    /// A piece of the error its fix gives.
    pub want: &'a str,
}

/// Every regression of `target`, each with its expected error from `table` (target,
/// file name, piece of the error); panics on a file the table does not name, so a new
/// crash is committed with the error its fix gives.
pub fn regressions<'a>(target: &str, table: &[(&str, &str, &'a str)]) -> Vec<Regression<'a>> {
    fuzz_files("regressions", target)
        .into_iter()
        .map(|f| {
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            let Some(&(_, _, want)) = table.iter().find(|(t, n, _)| *t == target && *n == name)
            else {
                panic!("fuzz/regressions/{target}/{name} has no expected error in REGRESSIONS");
            };
            Regression {
                name,
                bytes: read_bytes(&f),
                want,
            }
        })
        .collect()
}
