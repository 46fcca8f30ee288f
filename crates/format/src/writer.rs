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

/// Writes a complete model file atomically.
///
/// `nodes[i]`'s patch is `patches[i]` in `spool`. Fills in the header's `magic`,
/// `version`, `header_bytes`, `node_count`, the offsets, `patch_data_bytes`,
/// `file_bytes`, both checksums and `reserved`, and each node's `patch_offset`,
/// `patch_bytes`, `patch_crc32` and `reserved`; everything else is written as given.
/// The file appears at `path` only once complete and synced; on error nothing is left
/// behind and a pre-existing file at `path` is untouched.
pub fn write_model(
    path: &Path,
    header: &Header,
    nodes: &[NodeRecord],
    patches: &[SpooledPatch],
    spool: &PatchSpool,
) -> Result<(), FormatError> {
    if nodes.len() != patches.len() {
        return Err(FormatError::InvalidInput {
            detail: format!("{} nodes but {} patches", nodes.len(), patches.len()),
        });
    }
    let header_bytes = std::mem::size_of::<Header>() as u64;
    let node_table_bytes = (nodes.len() as u64) * std::mem::size_of::<NodeRecord>() as u64;
    let patch_data_offset = header_bytes + node_table_bytes;

    let mut table: Vec<NodeRecord> = nodes.to_vec();
    let mut offset = patch_data_offset;
    for (node, patch) in table.iter_mut().zip(patches) {
        node.patch_offset = offset;
        node.patch_bytes = patch.bytes;
        node.patch_crc32 = patch.crc32;
        node.reserved = [0; 3];
        offset += patch.bytes as u64;
    }
    let table_bytes: &[u8] = bytemuck::cast_slice(&table);

    let mut h = *header;
    h.magic = MAGIC;
    h.version = FORMAT_VERSION;
    h.header_bytes = header_bytes as u32;
    h.node_count = nodes.len() as u64;
    h.node_table_offset = header_bytes;
    h.patch_data_offset = patch_data_offset;
    h.patch_data_bytes = offset - patch_data_offset;
    h.file_bytes = offset;
    h.reserved = [0; 21];
    h.node_table_crc32 = crc32fast::hash(table_bytes);
    h.header_crc32 = header_crc32(&h);

    let mut out = AtomicFile::create(path, 8 << 20)?;
    let tmp_path = out.tmp_path().to_path_buf();
    let io = |e: std::io::Error| FormatError::io(&tmp_path, e);
    out.write_all(bytemuck::bytes_of(&h)).map_err(io)?;
    out.write_all(table_bytes).map_err(io)?;
    let mut buf = Vec::new();
    for (i, patch) in patches.iter().enumerate() {
        buf.resize(patch.bytes as usize, 0);
        spool.read_into(patch, &mut buf)?;
        if crc32fast::hash(&buf) != patch.crc32 {
            return Err(FormatError::PatchChecksum { node: i as u32 });
        }
        out.write_all(&buf).map_err(io)?;
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
