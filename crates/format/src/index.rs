//! A model's index parsed from bytes, independent of where the bytes come from.
//!
//! [`ModelIndex`] is the header and node table of a model, validated; it knows where
//! every patch lies ([`ModelIndex::patch_range`]) and decodes a patch from its bytes
//! ([`ModelIndex::decode_patch`], CRC checked). It does no I/O: the bytes come from a
//! [`ByteSource`] (a memory map, a byte slice, next an HTTP range client), so the same
//! reader runs natively and in WebAssembly.
//!
//! Reading a model is two steps: the first [`HEADER_BYTES`] give the [`Header`]
//! ([`ModelIndex::parse_header`], which needs the total length of the source to check
//! it), the header says how long the node table is ([`Header::index_bytes`]), and the
//! table gives the index ([`ModelIndex::from_parts`]). [`ModelIndex::read`] does both
//! over a [`ByteSource`].

use std::borrow::Cow;
use std::ops::Range;

use bytemuck::Zeroable;

use crate::codec::{self, PatchData};
use crate::error::FormatError;
use crate::grid::Grid;
use crate::records::{header_crc32, Header, NodeRecord, FORMAT_VERSION, MAGIC, NO_NODE};

/// Bytes of the header.
pub const HEADER_BYTES: u64 = std::mem::size_of::<Header>() as u64;
/// Bytes of one node record.
pub const NODE_BYTES: u64 = std::mem::size_of::<NodeRecord>() as u64;

/// Random-access bytes of a model: the one kind of I/O the reader needs.
///
/// Implemented for byte slices and vectors here, for the memory map by [`crate::Model`]
/// (feature `mmap`); a remote source (HTTP ranges) implements it the same way.
pub trait ByteSource {
    /// Total length in bytes.
    fn len(&self) -> u64;
    /// True when the source is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The bytes of `range`; an error (never a short answer) if it is not all there.
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError>;
}

impl ByteSource for [u8] {
    fn len(&self) -> u64 {
        <[u8]>::len(self) as u64
    }
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        let (start, end) = (range.start, range.end);
        usize::try_from(start)
            .ok()
            .zip(usize::try_from(end).ok())
            .and_then(|(s, e)| self.get(s..e))
            .map(Cow::Borrowed)
            .ok_or(FormatError::Truncated {
                expected_bytes: end,
                actual_bytes: <[u8]>::len(self) as u64,
            })
    }
}

impl ByteSource for Vec<u8> {
    fn len(&self) -> u64 {
        self.as_slice().len() as u64
    }
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        self.as_slice().read(range)
    }
}

/// A model whose patches any thread can read: its index and a blocking read + decode
/// of one node's patch. What loader threads work on; implemented by the memory-mapped
/// [`crate::Model`] (feature `mmap`) and by remote models (HTTP ranges).
pub trait PatchReader: Send + Sync {
    /// The model's index.
    fn index(&self) -> &ModelIndex;
    /// Reads, checks and decodes node `i`'s patch (blocking).
    fn decode_patch(&self, i: usize) -> Result<PatchData, FormatError>;
    /// Reads, checks and decodes the patches of `nodes` (blocking); one result per node,
    /// in the order given. Readers whose reads have a high fixed cost (HTTP) override it
    /// to fetch patches adjacent in the file with one read. Default: one by one.
    fn decode_patches(&self, nodes: &[usize]) -> Vec<Result<PatchData, FormatError>> {
        nodes.iter().map(|&i| self.decode_patch(i)).collect()
    }
    /// A hint that node `i`'s patch will be read soon (e.g. kernel read-ahead).
    /// Default: nothing.
    fn advise(&self, i: usize) {
        let _ = i;
    }
}

fn invalid_header(detail: impl Into<String>) -> FormatError {
    FormatError::InvalidHeader {
        detail: detail.into(),
    }
}

impl Header {
    /// Bytes from the start of the file to the end of the node table: what a reader
    /// needs before it can decode any patch.
    pub fn index_bytes(&self) -> u64 {
        HEADER_BYTES.saturating_add(self.node_count.saturating_mul(NODE_BYTES))
    }
}

/// A validated header and node table. See the module docs.
#[derive(Clone, Debug)]
pub struct ModelIndex {
    header: Header,
    nodes: Vec<NodeRecord>,
}

impl ModelIndex {
    /// Parses and checks the header from the first bytes of a model (`prefix` at least
    /// [`HEADER_BYTES`] long, or the whole source if shorter) whose source is
    /// `total_bytes` long: magic, version, checksum, and every layout field against the
    /// others and against `total_bytes`.
    pub fn parse_header(prefix: &[u8], total_bytes: u64) -> Result<Header, FormatError> {
        let Some(header_slice) = prefix.get(..HEADER_BYTES as usize) else {
            // Say "not a model" rather than "truncated" when even the magic is wrong.
            if prefix.len() >= MAGIC.len() && prefix[..MAGIC.len()] != MAGIC {
                return Err(FormatError::BadMagic);
            }
            return Err(FormatError::Truncated {
                expected_bytes: HEADER_BYTES,
                actual_bytes: total_bytes.min(prefix.len() as u64),
            });
        };
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
        if total_bytes < header.file_bytes {
            return Err(FormatError::Truncated {
                expected_bytes: header.file_bytes,
                actual_bytes: total_bytes,
            });
        }
        if total_bytes > header.file_bytes {
            return Err(invalid_header(format!(
                "file is {total_bytes} bytes but the header says {}",
                header.file_bytes
            )));
        }
        check_header(&header)?;
        Ok(header)
    }

    /// The index from a checked `header` (from [`ModelIndex::parse_header`]) and the
    /// node table's bytes (`header.node_count` records, from offset
    /// `header.node_table_offset`): checks the table's CRC, every patch range and every
    /// link index.
    pub fn from_parts(header: Header, table: &[u8]) -> Result<ModelIndex, FormatError> {
        let table_len = header.node_count.saturating_mul(NODE_BYTES);
        if table.len() as u64 != table_len {
            return Err(invalid_header(format!(
                "node table is {} bytes, expected {table_len}",
                table.len()
            )));
        }
        if crc32fast::hash(table) != header.node_table_crc32 {
            return Err(FormatError::NodeTableChecksum);
        }
        // The table's length was checked against the file length by `parse_header`, so
        // this allocation is bounded by the source's size.
        let mut nodes = vec![NodeRecord::zeroed(); header.node_count as usize];
        bytemuck::cast_slice_mut::<NodeRecord, u8>(&mut nodes).copy_from_slice(table);
        check_nodes(&header, &nodes)?;
        Ok(ModelIndex { header, nodes })
    }

    /// Reads the header and node table from `source` (two reads) and validates them.
    pub fn read<S: ByteSource + ?Sized>(source: &S) -> Result<ModelIndex, FormatError> {
        let total = source.len();
        let prefix = source.read(0..HEADER_BYTES.min(total))?;
        let header = Self::parse_header(&prefix, total)?;
        let table = source.read(header.node_table_offset..header.index_bytes())?;
        Self::from_parts(header, &table)
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The node table.
    pub fn nodes(&self) -> &[NodeRecord] {
        &self.nodes
    }

    /// Node `i`'s record, or an error naming the node.
    pub fn node(&self, i: usize) -> Result<&NodeRecord, FormatError> {
        self.nodes.get(i).ok_or_else(|| FormatError::InvalidNode {
            node: i as u32,
            detail: format!("no such node (model has {})", self.nodes.len()),
        })
    }

    /// Byte range of node `i`'s encoded patch in the model file.
    pub fn patch_range(&self, i: usize) -> Result<Range<u64>, FormatError> {
        let n = self.node(i)?;
        Ok(n.patch_offset..n.patch_offset + u64::from(n.patch_bytes))
    }

    /// Checks `bytes` (node `i`'s encoded patch) against the node's CRC.
    pub fn check_patch(&self, i: usize, bytes: &[u8]) -> Result<(), FormatError> {
        let n = self.node(i)?;
        if bytes.len() as u64 != u64::from(n.patch_bytes) {
            return Err(FormatError::PatchOutOfRange { node: i as u32 });
        }
        if crc32fast::hash(bytes) != n.patch_crc32 {
            return Err(FormatError::PatchChecksum { node: i as u32 });
        }
        Ok(())
    }

    /// Checks and decodes node `i`'s patch from its encoded `bytes`.
    pub fn decode_patch(&self, i: usize, bytes: &[u8]) -> Result<PatchData, FormatError> {
        self.check_patch(i, bytes)?;
        codec::decode_patch(bytes, self.header.attributes, (&self.nodes[i]).into())
            .map_err(|e| e.with_node(i as u32))
    }

    /// Reads node `i`'s patch from `source` and decodes it.
    pub fn read_patch<S: ByteSource + ?Sized>(
        &self,
        source: &S,
        i: usize,
    ) -> Result<PatchData, FormatError> {
        let bytes = source.read(self.patch_range(i)?)?;
        self.decode_patch(i, &bytes)
    }

    /// The quantisation grid of the model's positions.
    pub fn grid(&self) -> Grid {
        Grid::of_header(&self.header)
    }
}

/// Checks the header's layout fields against each other (`file_bytes` is already known
/// to equal the source's length).
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

/// Every patch inside the patch data, every link a valid index other than the node's own.
fn check_nodes(h: &Header, nodes: &[NodeRecord]) -> Result<(), FormatError> {
    let count = h.node_count;
    let patch_start = h.patch_data_offset;
    let patch_end = h.patch_data_offset + h.patch_data_bytes;
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
    Ok(())
}
