//! Reading model files: a validated, memory-mapped [`Model`].
//!
//! A model may be far larger than RAM, so patch data stays in the page cache via a
//! memory map and is decoded on demand; the header and node table (small) are copied
//! out once. `Model::open` checks everything that can be checked without touching the
//! patch data (magic, version, checksums of header and node table, sizes, ranges, link
//! indices), so later accesses can trust the structure; each patch's own CRC is checked
//! when it is read.
//!
//! Like any memory-mapped reader, this assumes the file is not truncated or rewritten
//! while mapped (the writer replaces files by rename, which is safe).

use std::fs::File;
use std::path::{Path, PathBuf};

use bytemuck::Zeroable;
use memmap2::{Advice, Mmap};

use crate::codec::{self, PatchData};
use crate::error::FormatError;
use crate::records::{Header, NodeRecord, FORMAT_VERSION, MAGIC, NO_NODE};
use crate::writer::header_crc32;

const HEADER_BYTES: u64 = std::mem::size_of::<Header>() as u64;
const NODE_BYTES: u64 = std::mem::size_of::<NodeRecord>() as u64;

/// An open, structurally validated model file.
#[derive(Debug)]
pub struct Model {
    path: PathBuf,
    map: Mmap,
    header: Header,
    nodes: Vec<NodeRecord>,
}

fn invalid_header(detail: impl Into<String>) -> FormatError {
    FormatError::InvalidHeader {
        detail: detail.into(),
    }
}

impl Model {
    /// Opens and validates a model file (see the module docs for what is checked).
    pub fn open(path: impl AsRef<Path>) -> Result<Model, FormatError> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|e| FormatError::io(&path, e))?;
        let actual = file
            .metadata()
            .map_err(|e| FormatError::io(&path, e))?
            .len();
        if actual < HEADER_BYTES {
            // Say "not a model" rather than "truncated" when even the magic is wrong.
            let mut magic = [0u8; 8];
            if actual >= 8 {
                use std::io::Read;
                (&file)
                    .read_exact(&mut magic)
                    .map_err(|e| FormatError::io(&path, e))?;
                if magic != MAGIC {
                    return Err(FormatError::BadMagic);
                }
            }
            return Err(FormatError::Truncated {
                expected_bytes: HEADER_BYTES,
                actual_bytes: actual,
            });
        }
        // SAFETY: the map is read-only; we rely on the file not being modified while
        // mapped (the writer only ever replaces model files by rename).
        let map = unsafe { Mmap::map(&file) }.map_err(|e| FormatError::io(&path, e))?;
        let header_slice = map
            .get(..HEADER_BYTES as usize)
            .ok_or(FormatError::Truncated {
                expected_bytes: HEADER_BYTES,
                actual_bytes: map.len() as u64,
            })?;
        let header: Header = bytemuck::pod_read_unaligned(header_slice);
        if header.magic != MAGIC {
            return Err(FormatError::BadMagic);
        }
        if header.version == 0 || header.version > FORMAT_VERSION {
            return Err(FormatError::UnsupportedVersion {
                found: header.version,
                supported: FORMAT_VERSION,
            });
        }
        if header_crc32(&header) != header.header_crc32 {
            return Err(FormatError::HeaderChecksum);
        }
        let actual = map.len() as u64;
        if actual < header.file_bytes {
            return Err(FormatError::Truncated {
                expected_bytes: header.file_bytes,
                actual_bytes: actual,
            });
        }
        if actual > header.file_bytes {
            return Err(invalid_header(format!(
                "file is {actual} bytes but the header says {}",
                header.file_bytes
            )));
        }
        check_header(&header)?;

        // Sizes are consistent with the file length, so this allocation is bounded.
        let table_start = header.node_table_offset as usize;
        let table_len = (header.node_count * NODE_BYTES) as usize;
        let table_bytes = map
            .get(table_start..table_start + table_len)
            .ok_or_else(|| invalid_header("node table outside the file"))?;
        if crc32fast::hash(table_bytes) != header.node_table_crc32 {
            return Err(FormatError::NodeTableChecksum);
        }
        let mut nodes = vec![NodeRecord::zeroed(); header.node_count as usize];
        bytemuck::cast_slice_mut::<NodeRecord, u8>(&mut nodes).copy_from_slice(table_bytes);

        let count = header.node_count;
        let patch_start = header.patch_data_offset;
        let patch_end = header.patch_data_offset + header.patch_data_bytes;
        for (i, n) in nodes.iter().enumerate() {
            let node = i as u32;
            let end = n.patch_offset.checked_add(n.patch_bytes as u64);
            if n.patch_offset < patch_start || end.is_none_or(|e| e > patch_end) {
                return Err(FormatError::PatchOutOfRange { node });
            }
            let link_ok = |l: u32| l == NO_NODE || (l as u64) < count;
            if !n.children.iter().all(|&c| link_ok(c) && c != node) {
                return Err(FormatError::InvalidNode {
                    node,
                    detail: format!("child index {:?} out of range", n.children),
                });
            }
            if !link_ok(n.parent) || n.parent == node {
                return Err(FormatError::InvalidNode {
                    node,
                    detail: format!("parent index {} out of range", n.parent),
                });
            }
        }
        tracing::debug!(path = %path.display(), nodes = nodes.len(), bytes = actual, "opened model");
        Ok(Model {
            path,
            map,
            header,
            nodes,
        })
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The node table.
    pub fn nodes(&self) -> &[NodeRecord] {
        &self.nodes
    }

    /// Path the model was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn node(&self, i: usize) -> Result<&NodeRecord, FormatError> {
        self.nodes.get(i).ok_or_else(|| FormatError::InvalidNode {
            node: i as u32,
            detail: format!("no such node (model has {})", self.nodes.len()),
        })
    }

    /// The encoded bytes of node `i`'s patch, CRC-checked.
    pub fn patch_bytes(&self, i: usize) -> Result<&[u8], FormatError> {
        let n = self.node(i)?;
        let bytes = self.raw_patch(i, n)?;
        if crc32fast::hash(bytes) != n.patch_crc32 {
            return Err(FormatError::PatchChecksum { node: i as u32 });
        }
        Ok(bytes)
    }

    fn raw_patch(&self, i: usize, n: &NodeRecord) -> Result<&[u8], FormatError> {
        let start = n.patch_offset as usize;
        self.map
            .get(start..start + n.patch_bytes as usize)
            .ok_or(FormatError::PatchOutOfRange { node: i as u32 })
    }

    /// Reads, checks and decodes node `i`'s patch.
    pub fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError> {
        let n = self.node(i)?;
        let bytes = self.patch_bytes(i)?;
        codec::decode_patch(
            bytes,
            self.header.attributes,
            n.quant_min,
            n.vertex_count,
            n.triangle_count,
        )
        .map_err(|e| e.with_node(i as u32))
    }

    /// Edge length of one grid cell, model units: `cube_size / 2^quant_bits`.
    pub fn quant_step(&self) -> f64 {
        self.header.cube_size / (self.header.quant_bits as f64).exp2()
    }

    /// Model-space position of grid point `q`: `cube_origin + q * quant_step()`.
    pub fn model_position(&self, q: [u32; 3]) -> [f64; 3] {
        let s = self.quant_step();
        let o = self.header.cube_origin;
        [
            o[0] + q[0] as f64 * s,
            o[1] + q[1] as f64 * s,
            o[2] + q[2] as f64 * s,
        ]
    }

    /// Hints the OS to start reading node `i`'s patch into the page cache. Best effort:
    /// errors (including a bad index) are ignored.
    pub fn advise_willneed(&self, i: usize) {
        if let Some(n) = self.nodes.get(i) {
            if n.patch_bytes > 0 {
                let _ = self.map.advise_range(
                    Advice::WillNeed,
                    n.patch_offset as usize,
                    n.patch_bytes as usize,
                );
            }
        }
    }
}

/// Checks the header's layout fields against each other (`file_bytes` is already known
/// to equal the file length).
fn check_header(h: &Header) -> Result<(), FormatError> {
    if h.header_bytes as u64 != HEADER_BYTES {
        return Err(invalid_header(format!(
            "header_bytes is {}, expected {HEADER_BYTES}",
            h.header_bytes
        )));
    }
    if h.node_table_offset != HEADER_BYTES {
        return Err(invalid_header(format!(
            "node table at {}, expected {HEADER_BYTES}",
            h.node_table_offset
        )));
    }
    let table_end = h
        .node_count
        .checked_mul(NODE_BYTES)
        .and_then(|b| b.checked_add(HEADER_BYTES));
    if table_end != Some(h.patch_data_offset) {
        return Err(invalid_header(format!(
            "{} nodes do not end at the patch data offset {}",
            h.node_count, h.patch_data_offset
        )));
    }
    if h.patch_data_offset.checked_add(h.patch_data_bytes) != Some(h.file_bytes) {
        return Err(invalid_header(format!(
            "patch data {}+{} does not end at the file end {}",
            h.patch_data_offset, h.patch_data_bytes, h.file_bytes
        )));
    }
    if !(1..=32).contains(&h.quant_bits) {
        return Err(invalid_header(format!(
            "quant_bits {} not in 1..=32",
            h.quant_bits
        )));
    }
    if h.attributes & !(crate::ATTR_NORMALS | crate::ATTR_COLORS | crate::ATTR_UVS) != 0 {
        return Err(invalid_header(format!(
            "unknown attribute bits {:#x}",
            h.attributes
        )));
    }
    if h.root_count as u64 > h.node_count || h.root_count > 6 {
        return Err(invalid_header(format!(
            "root_count {} (node_count {})",
            h.root_count, h.node_count
        )));
    }
    if !(h.cube_size.is_finite()
        && h.cube_size > 0.0
        && h.cube_origin.iter().all(|v| v.is_finite()))
    {
        return Err(invalid_header("bounding cube is not finite and positive"));
    }
    Ok(())
}
