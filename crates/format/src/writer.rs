//! Writing model files: a patch spool for the build, then one atomic `write_model`.
//!
//! The builder produces encoded patches out of order, from many threads, long before it
//! knows the final node order; holding them all in memory would not scale to huge
//! models. So patches go to a [`PatchSpool`] (an append-only temporary file) and
//! [`write_model`] copies them, in node-table order, into the final file. The final file
//! is an [`AtomicFile`]: written under a temporary name and renamed into place, so a crash
//! or error never leaves a half-written model at the destination.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::atomic::AtomicFile;
use crate::error::FormatError;
use crate::pages::{
    encode_page, IndexLayout, PageEntry, DEFAULT_PAGE_NODES, DIRECTORY_BLOCK_PAGES,
    PAGE_ENTRY_BYTES,
};
use crate::records::{header_crc32, Header, NodeRecord, FORMAT_VERSION, MAGIC};

/// Where one patch lies in a [`PatchSpool`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SpooledPatch {
    /// Byte offset in the spool file.
    pub offset: u64,
    /// Length in bytes.
    pub bytes: u32,
    /// CRC-32 of the bytes (checked again when copied into the model).
    pub crc32: u32,
}

/// An append-only temporary file of encoded patches, shared by the builder's threads.
/// Lives in a caller-chosen directory (ideally on the same disk as the output) and is
/// deleted on drop.
#[derive(Debug)]
pub struct PatchSpool {
    file: File,
    path: PathBuf,
    end: AtomicU64,
}

static UNIQUE: AtomicU64 = AtomicU64::new(0);

/// A file name no other process or thread of this process is using.
fn unique_name(prefix: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!(
        "{prefix}.{}.{}.{nanos}.tmp",
        std::process::id(),
        UNIQUE.fetch_add(1, Ordering::Relaxed)
    )
}

impl PatchSpool {
    /// Creates an empty spool file in `dir`.
    pub fn new(dir: &Path) -> Result<PatchSpool, FormatError> {
        let path = dir.join(unique_name(".tessera-spool"));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| FormatError::io(&path, e))?;
        tracing::debug!(path = %path.display(), "created patch spool");
        Ok(PatchSpool {
            file,
            path,
            end: AtomicU64::new(0),
        })
    }

    /// Path of the spool file (deleted on drop).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Total bytes appended so far.
    pub fn len(&self) -> u64 {
        self.end.load(Ordering::Relaxed)
    }

    /// Whether nothing has been appended.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends one encoded patch. Thread-safe: each call reserves its own byte range,
    /// so concurrent appends write in parallel.
    pub fn append(&self, bytes: &[u8]) -> Result<SpooledPatch, FormatError> {
        let len = u32::try_from(bytes.len()).map_err(|_| FormatError::InvalidInput {
            detail: format!("patch of {} bytes exceeds 4 GiB", bytes.len()),
        })?;
        let offset = self.end.fetch_add(len as u64, Ordering::Relaxed);
        write_all_at(&self.file, bytes, offset).map_err(|e| FormatError::io(&self.path, e))?;
        Ok(SpooledPatch {
            offset,
            bytes: len,
            crc32: crc32fast::hash(bytes),
        })
    }

    /// Reads a patch back (without checking its CRC).
    pub fn read(&self, patch: &SpooledPatch) -> Result<Vec<u8>, FormatError> {
        let mut buf = vec![0u8; patch.bytes as usize];
        self.read_into(patch, &mut buf)?;
        Ok(buf)
    }

    fn read_into(&self, patch: &SpooledPatch, buf: &mut [u8]) -> Result<(), FormatError> {
        let in_range = patch
            .offset
            .checked_add(patch.bytes as u64)
            .is_some_and(|end| end <= self.len());
        if !in_range {
            return Err(FormatError::InvalidInput {
                detail: format!(
                    "spooled patch at {}+{} lies beyond the spool's {} bytes",
                    patch.offset,
                    patch.bytes,
                    self.len()
                ),
            });
        }
        read_exact_at(&self.file, buf, patch.offset).map_err(|e| FormatError::io(&self.path, e))
    }
}

impl Drop for PatchSpool {
    fn drop(&mut self) {
        if let Err(e) = std::fs::remove_file(&self.path) {
            tracing::warn!(path = %self.path.display(), error = %e, "could not delete patch spool");
        }
    }
}

#[cfg(unix)]
fn write_all_at(file: &File, buf: &[u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

#[cfg(unix)]
fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(windows)]
fn write_all_at(file: &File, mut buf: &[u8], mut offset: u64) -> std::io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        let n = file.seek_write(buf, offset)?;
        if n == 0 {
            return Err(std::io::ErrorKind::WriteZero.into());
        }
        buf = &buf[n..];
        offset += n as u64;
    }
    Ok(())
}

#[cfg(windows)]
fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> std::io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        let n = file.seek_read(buf, offset)?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        buf = &mut buf[n..];
        offset += n as u64;
    }
    Ok(())
}

/// The complete header and the paged index (block table, directory, pages: the bytes
/// from [`Header::index_offset`] to the patch data) of a model whose node records are
/// `nodes`. Their `patch_offset`s are not read: the patches follow each other in node
/// order from the start of the patch data, so the offsets follow from `patch_bytes`.
/// The header is `header` with the fields [`write_model`] fills in set.
pub fn encode_index(
    header: &Header,
    nodes: &[NodeRecord],
) -> Result<(Header, Vec<u8>), FormatError> {
    let header_bytes = std::mem::size_of::<Header>() as u64;
    let page_nodes = if header.page_nodes == 0 {
        DEFAULT_PAGE_NODES
    } else {
        header.page_nodes
    };
    let layout = IndexLayout::new(nodes.len() as u64, page_nodes, header_bytes);
    // Patches follow each other in node order, so each page stores only the offset of
    // its first patch relative to the patch data (known before the index's own size).
    let mut rel = 0u64;
    let frames: Vec<Vec<u8>> = nodes
        .chunks(page_nodes as usize)
        .map(|page| {
            let base = rel;
            rel += page.iter().map(|n| n.patch_bytes as u64).sum::<u64>();
            encode_page(page, base)
        })
        .collect();
    let mut directory = Vec::with_capacity(frames.len());
    let mut at = layout.pages_offset;
    for f in &frames {
        directory.push(PageEntry {
            offset: at,
            bytes: f.len() as u32,
            crc32: crc32fast::hash(f),
        });
        at += f.len() as u64;
    }
    let directory_bytes: &[u8] = bytemuck::cast_slice(&directory);
    let mut index: Vec<u8> = directory_bytes
        .chunks((DIRECTORY_BLOCK_PAGES * PAGE_ENTRY_BYTES) as usize)
        .flat_map(|b| crc32fast::hash(b).to_le_bytes())
        .collect();

    let mut h = *header;
    h.magic = MAGIC;
    h.version = FORMAT_VERSION;
    h.header_bytes = header_bytes as u32;
    h.node_count = nodes.len() as u64;
    h.index_offset = header_bytes;
    h.page_nodes = page_nodes;
    h.page_count = u32::try_from(layout.page_count).map_err(|_| FormatError::InvalidInput {
        detail: format!("{} index pages", layout.page_count),
    })?;
    h.patch_data_offset = at;
    h.patch_data_bytes = rel;
    h.file_bytes = at + rel;
    h.reserved = [0; 18];
    h.block_table_crc32 = crc32fast::hash(&index);
    h.header_crc32 = header_crc32(&h);
    index.extend_from_slice(directory_bytes);
    for f in &frames {
        index.extend_from_slice(f);
    }
    Ok((h, index))
}

/// `model` (the bytes of a model file, header checked) with its node records replaced
/// by `nodes` (as [`crate::ModelIndex::nodes`] gives them; the patch bytes, counts and
/// CRCs as given, the offsets following from the patch bytes) and the index re-encoded: what a writer with a
/// bug in its records would produce, for tests of the checks downstream.
pub fn replace_index(model: &[u8], nodes: &[NodeRecord]) -> Result<Vec<u8>, FormatError> {
    let h = crate::ModelIndex::parse_header(model, model.len() as u64)?;
    let patches = &model[h.patch_data_offset as usize..];
    let (hh, index) = encode_index(&h, nodes)?;
    let mut b = bytemuck::bytes_of(&hh).to_vec();
    b.extend_from_slice(&index);
    b.extend_from_slice(patches);
    Ok(b)
}

/// Writes a complete model file atomically.
///
/// `nodes[i]`'s patch is `patches[i]` in `spool`. Fills in the header's `magic`,
/// `version`, `header_bytes`, `node_count`, the offsets, `page_count`, `page_nodes`
/// (when 0: [`DEFAULT_PAGE_NODES`]), `patch_data_bytes`, `file_bytes`, both checksums
/// and `reserved`, and each node's `patch_bytes` and `patch_crc32` (its patch offset
/// follows from them);
/// everything else is written as given. The node records go into the paged index
/// (`docs/format.md`).
/// The file appears at `path` only once complete and synced; on error nothing is left
/// behind and a pre-existing file at `path` is untouched.
pub fn write_model(
    path: &Path,
    header: &Header,
    nodes: &[NodeRecord],
    patches: &[SpooledPatch],
    spool: &PatchSpool,
) -> Result<(), FormatError> {
    write_model_until(path, header, nodes, patches, spool, &|| false)
}

/// [`write_model`] that gives up with [`FormatError::Interrupted`] (nothing at `path`,
/// the temporary file removed) when `cancelled` says so: it is asked every 256 patches
/// and once more just before the rename, so a Ctrl-C during the write is never ignored.
pub fn write_model_until(
    path: &Path,
    header: &Header,
    nodes: &[NodeRecord],
    patches: &[SpooledPatch],
    spool: &PatchSpool,
    cancelled: &dyn Fn() -> bool,
) -> Result<(), FormatError> {
    if nodes.len() != patches.len() {
        return Err(FormatError::InvalidInput {
            detail: format!("{} nodes but {} patches", nodes.len(), patches.len()),
        });
    }
    let mut table: Vec<NodeRecord> = nodes.to_vec();
    for (node, patch) in table.iter_mut().zip(patches) {
        node.patch_bytes = patch.bytes;
        node.patch_crc32 = patch.crc32;
    }
    let (h, index) = encode_index(header, &table)?;

    let mut out = AtomicFile::create(path, 8 << 20)?;
    let tmp_path = out.tmp_path().to_path_buf();
    let io = |e: std::io::Error| FormatError::io(&tmp_path, e);
    out.write_all(bytemuck::bytes_of(&h)).map_err(io)?;
    out.write_all(&index).map_err(io)?;
    let mut buf = Vec::new();
    for (i, patch) in patches.iter().enumerate() {
        if i % 256 == 0 && cancelled() {
            return Err(FormatError::Interrupted);
        }
        buf.resize(patch.bytes as usize, 0);
        spool.read_into(patch, &mut buf)?;
        if crc32fast::hash(&buf) != patch.crc32 {
            return Err(FormatError::PatchChecksum { node: i as u32 });
        }
        out.write_all(&buf).map_err(io)?;
    }
    if cancelled() {
        // Dropping `out` removes the temporary file.
        return Err(FormatError::Interrupted);
    }
    out.commit()?;
    tracing::info!(
        path = %path.display(),
        nodes = nodes.len(),
        bytes = h.file_bytes,
        "wrote model"
    );
    Ok(())
}
