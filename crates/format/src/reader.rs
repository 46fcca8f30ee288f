//! Reading local model files: a validated, memory-mapped [`Model`] (feature `mmap`).
//!
//! A model may be far larger than RAM, so patch data stays in the page cache via a
//! memory map and is decoded on demand; the header and paged index (small) are parsed
//! once into a [`ModelIndex`], which checks everything that can be checked without
//! touching the patch data (magic, version, checksums of header and index pages, sizes,
//! ranges, link indices), so later accesses can trust the structure; each patch's own
//! CRC is checked when it is read.
//!
//! Like any memory-mapped reader, this assumes the file is not truncated or rewritten
//! while mapped (the writer replaces files by rename, which is safe).

use std::borrow::Cow;
use std::fs::File;
use std::ops::{Deref, Range};
use std::path::{Path, PathBuf};

use memmap2::{Advice, Mmap};

use crate::codec::PatchData;
use crate::error::FormatError;
use crate::index::{ByteSource, ModelIndex, PatchReader};

/// A read-only memory map of a model file, as a [`ByteSource`].
#[derive(Debug)]
pub struct MappedFile {
    map: Mmap,
}

impl MappedFile {
    /// Maps `file` read-only.
    pub fn new(file: &File) -> std::io::Result<MappedFile> {
        // SAFETY: the map is read-only; we rely on the file not being modified while
        // mapped (the writer only ever replaces model files by rename).
        let map = unsafe { Mmap::map(file) }?;
        Ok(MappedFile { map })
    }

    /// The bytes of `range`, borrowed from the map.
    pub fn slice(&self, range: Range<u64>) -> Option<&[u8]> {
        let s = usize::try_from(range.start).ok()?;
        let e = usize::try_from(range.end).ok()?;
        self.map.get(s..e)
    }
}

impl ByteSource for MappedFile {
    fn len(&self) -> u64 {
        self.map.len() as u64
    }
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        self.map[..].read(range)
    }
}

/// An open, structurally validated local model file: a [`ModelIndex`] (which it derefs
/// to: header, nodes, quantisation) over a memory map.
#[derive(Debug)]
pub struct Model {
    path: PathBuf,
    map: MappedFile,
    index: ModelIndex,
}

impl Deref for Model {
    type Target = ModelIndex;
    fn deref(&self) -> &ModelIndex {
        &self.index
    }
}

impl Model {
    /// Opens and validates a model file (see the module docs for what is checked).
    pub fn open(path: impl AsRef<Path>) -> Result<Model, FormatError> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|e| FormatError::io(&path, e))?;
        let map = MappedFile::new(&file).map_err(|e| FormatError::io(&path, e))?;
        let index = ModelIndex::read(&map)?;
        tracing::debug!(path = %path.display(), nodes = index.nodes().len(), bytes = map.len(), "opened model");
        Ok(Model { path, map, index })
    }

    /// The parsed index.
    pub fn index(&self) -> &ModelIndex {
        &self.index
    }

    /// The mapped bytes.
    pub fn bytes(&self) -> &MappedFile {
        &self.map
    }

    /// Path the model was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The encoded bytes of node `i`'s patch, CRC-checked.
    pub fn patch_bytes(&self, i: usize) -> Result<&[u8], FormatError> {
        let range = self.index.patch_range(i)?;
        let bytes = self
            .map
            .slice(range)
            .ok_or(FormatError::PatchOutOfRange { node: i as u32 })?;
        self.index.check_patch(i, bytes)?;
        Ok(bytes)
    }

    /// Reads, checks and decodes node `i`'s patch.
    pub fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        self.index.read_patch(&self.map, i)
    }

    /// Hints the OS to start reading node `i`'s patch into the page cache. Best effort:
    /// errors (including a bad index) are ignored.
    pub fn advise_willneed(&self, i: usize) {
        if let Ok(r) = self.index.patch_range(i) {
            if r.end > r.start {
                let _ = self.map.map.advise_range(
                    Advice::WillNeed,
                    r.start as usize,
                    (r.end - r.start) as usize,
                );
            }
        }
    }
}

impl PatchReader for Model {
    fn index(&self) -> &ModelIndex {
        &self.index
    }
    fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        Model::decode_patch(self, i)
    }
    fn advise(&self, i: usize) {
        self.advise_willneed(i);
    }
}
