//! A model's index parsed from bytes, independent of where the bytes come from.
//!
//! [`ModelIndex`] is the header and node records of a model, validated; it knows where
//! every patch lies ([`ModelIndex::patch_range`]) and decodes a patch from its bytes
//! ([`ModelIndex::decode_patch`], CRC checked). It does no I/O: the bytes come from a
//! [`ByteSource`] (a memory map, a byte slice, next an HTTP range client), so the same
//! reader runs natively and in WebAssembly.
//!
//! Reading a model is two steps: the first [`HEADER_BYTES`] give the [`Header`]
//! ([`ModelIndex::parse_header`], which needs the total length of the source to check
//! it), the header says how long the paged index is ([`Header::index_bytes`]), and its
//! bytes give the index ([`ModelIndex::from_parts`]). [`ModelIndex::read`] does both
//! over a [`ByteSource`]. The index's pages (`crate::pages`) can also be read one by
//! one, so a remote reader fetches only the parts of the tree it needs.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::Arc;

use crate::codec::{self, PatchData, PATCH_HEADER_BYTES};
use crate::error::FormatError;
use crate::grid::Grid;
use crate::pages::{
    decode_page, IndexLayout, PageEntry, DIRECTORY_BLOCK_PAGES, MAX_PAGE_NODES, PAGE_ENTRY_BYTES,
};
use crate::records::{header_crc32, Header, NodeRecord, FORMAT_VERSION, MAGIC, NO_NODE};

/// Bytes of the header.
pub const HEADER_BYTES: u64 = std::mem::size_of::<Header>() as u64;
/// Bytes of one node record in memory.
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
    /// A paged index read in part and grown since [`PatchReader::index`] was made: the
    /// latest index (showing at least the nodes `index()` shows). Default: none.
    fn latest_index(&self) -> Option<Arc<ModelIndex>> {
        None
    }
    /// Reads more of a paged index read in part (blocking: run it off the frame's
    /// thread); true when [`PatchReader::latest_index`] then shows more nodes. Default:
    /// false (the index is whole).
    fn grow_index(&self) -> bool {
        false
    }
    /// For a model read over a network: bytes and requests transferred so far.
    /// Default: none (a local file).
    fn transfer(&self) -> Option<(u64, u64)> {
        None
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
    /// Bytes from the start of the file to the end of the paged index (header, block
    /// table, directory, pages): everything a reader holding the whole index reads before
    /// any patch.
    pub fn index_bytes(&self) -> u64 {
        self.patch_data_offset
    }

    /// Where the parts of the paged index lie.
    pub fn index_layout(&self) -> IndexLayout {
        IndexLayout::new(self.node_count, self.page_nodes, HEADER_BYTES)
    }
}

/// Sizes of a model's paged index, for reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexStats {
    /// Bytes of the whole index, header included.
    pub index_bytes: u64,
    /// Bytes a paged reader reads before it can draw the roots: header, block table,
    /// the first directory block and the first page.
    pub first_frame_bytes: u64,
    /// Nodes per page.
    pub page_nodes: u32,
    /// Pages.
    pub page_count: u64,
}

impl IndexStats {
    /// Index bytes per node.
    pub fn bytes_per_node(&self, node_count: u64) -> f64 {
        self.index_bytes as f64 / node_count.max(1) as f64
    }
}

/// A validated header and the node records of its paged index. See the module docs.
#[derive(Clone, Debug)]
pub struct ModelIndex {
    header: Header,
    /// Every record read so far, in node order.
    nodes: Vec<NodeRecord>,
    /// How many of them the index shows: all when every page is read, else the nodes of
    /// the complete levels among them (a tree cut off at a level).
    visible: usize,
    stats: IndexStats,
    /// CRCs of the directory blocks, the directory entries read so far (whole blocks)
    /// and where the last read page's patches end.
    blocks: Vec<u32>,
    entries: Vec<PageEntry>,
    patch_end: u64,
}

/// Bytes of the paged index held as a slice starting at file offset `start`.
struct IndexSlice<'a> {
    bytes: &'a [u8],
    start: u64,
}

impl ByteSource for IndexSlice<'_> {
    fn len(&self) -> u64 {
        self.start + self.bytes.len() as u64
    }
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        let shifted = range.start.saturating_sub(self.start)..range.end.saturating_sub(self.start);
        if range.start < self.start {
            return Err(invalid_header("index read before the index"));
        }
        self.bytes.read(shifted)
    }
}

/// Checks the block table's CRC and returns the CRC of each directory block.
pub(crate) fn parse_block_table(header: &Header, bytes: &[u8]) -> Result<Vec<u32>, FormatError> {
    let layout = header.index_layout();
    let range = layout.block_table_range();
    if bytes.len() as u64 != range.end - range.start {
        return Err(invalid_header(format!(
            "block table is {} bytes, expected {}",
            bytes.len(),
            range.end - range.start
        )));
    }
    if crc32fast::hash(bytes) != header.block_table_crc32 {
        return Err(FormatError::IndexChecksum {
            part: "directory block table".into(),
        });
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect())
}

/// Checks directory block `b` against its CRC and returns its entries, each checked to
/// lie inside the pages section; the first must start at `start` (where the previous
/// block's last page ends, or the first page's offset), each next where the previous
/// ends.
pub(crate) fn parse_directory_block(
    header: &Header,
    b: u64,
    bytes: &[u8],
    crc: u32,
    start: u64,
) -> Result<Vec<PageEntry>, FormatError> {
    let layout = header.index_layout();
    let range = layout.block_range(b);
    if bytes.len() as u64 != range.end - range.start {
        return Err(invalid_header(format!(
            "directory block {b} is {} bytes, expected {}",
            bytes.len(),
            range.end - range.start
        )));
    }
    if crc32fast::hash(bytes) != crc {
        return Err(FormatError::IndexChecksum {
            part: format!("directory block {b}"),
        });
    }
    let entries: Vec<PageEntry> = bytes
        .chunks_exact(PAGE_ENTRY_BYTES as usize)
        .map(bytemuck::pod_read_unaligned)
        .collect();
    let first_page = b * DIRECTORY_BLOCK_PAGES;
    let mut expected = start;
    for (k, e) in entries.iter().enumerate() {
        let page = first_page + k as u64;
        if e.offset != expected {
            return Err(FormatError::CorruptIndexPage {
                page,
                detail: format!(
                    "starts at {}, the previous part ends at {expected}",
                    e.offset
                ),
            });
        }
        let end = e.offset.checked_add(e.bytes as u64);
        if e.offset < layout.pages_offset || end.is_none_or(|end| end > header.patch_data_offset) {
            return Err(FormatError::CorruptIndexPage {
                page,
                detail: format!(
                    "directory puts it at {}+{}, outside the pages {}..{}",
                    e.offset, e.bytes, layout.pages_offset, header.patch_data_offset
                ),
            });
        }
        expected = e.offset + e.bytes as u64;
    }
    Ok(entries)
}

/// Checks page `p`'s `frame` against its directory `entry` and decodes its nodes; each
/// node's patch is checked to lie in the patch data. Returns the nodes and the absolute
/// offset where the page's last patch ends.
pub(crate) fn parse_page(
    header: &Header,
    p: u64,
    entry: &PageEntry,
    frame: &[u8],
) -> Result<(Vec<NodeRecord>, u64), FormatError> {
    if frame.len() as u64 != entry.bytes as u64 {
        return Err(FormatError::CorruptIndexPage {
            page: p,
            detail: format!("{} bytes, the directory says {}", frame.len(), entry.bytes),
        });
    }
    if crc32fast::hash(frame) != entry.crc32 {
        return Err(FormatError::IndexChecksum {
            part: format!("index page {p}"),
        });
    }
    let layout = header.index_layout();
    let nodes = layout.page_nodes_range(p, header.node_count);
    let (records, end) = decode_page(
        p,
        frame,
        (nodes.end - nodes.start) as usize,
        header.patch_data_offset,
    )?;
    if end > header.file_bytes {
        let last = nodes.end.saturating_sub(1) as u32;
        return Err(FormatError::PatchOutOfRange { node: last });
    }
    Ok((records, end))
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
        if header.version > FORMAT_VERSION {
            return Err(FormatError::UnsupportedVersion {
                found: header.version,
                supported: FORMAT_VERSION,
            });
        }
        if header.version < FORMAT_VERSION {
            return Err(FormatError::OldVersion {
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
    /// bytes of the whole paged index (from offset `header.index_offset` to
    /// `header.patch_data_offset`): checks every CRC of the block table, directory and
    /// pages, that pages and patches follow each other without gaps, every patch range
    /// and every link index.
    pub fn from_parts(header: Header, index: &[u8]) -> Result<ModelIndex, FormatError> {
        let expected = header.patch_data_offset - header.index_offset;
        if index.len() as u64 != expected {
            return Err(invalid_header(format!(
                "index is {} bytes, expected {expected}",
                index.len()
            )));
        }
        let src = IndexSlice {
            bytes: index,
            start: header.index_offset,
        };
        Self::start(header, &src)?.grown(&src, u64::MAX)
    }

    /// Reads the header and the paged index from `source` (two reads) and validates them.
    pub fn read<S: ByteSource + ?Sized>(source: &S) -> Result<ModelIndex, FormatError> {
        let header = Self::read_header(source)?;
        let index = source.read(header.index_offset..header.patch_data_offset)?;
        Self::from_parts(header, &index)
    }

    /// Reads only the top of the index from `source`: the header, the block table and
    /// the first `pages` pages (at least enough for the roots) with the directory blocks
    /// naming them. The index then shows the complete levels among the nodes read (see
    /// [`ModelIndex::is_complete`]); [`ModelIndex::grown`] reads more.
    pub fn read_top<S: ByteSource + ?Sized>(
        source: &S,
        pages: u64,
    ) -> Result<ModelIndex, FormatError> {
        let header = Self::read_header(source)?;
        let mut index = Self::start(header, source)?.grown(source, pages.max(1))?;
        // Pages smaller than the root level: read on until the roots are shown.
        while index.visible < header.root_count as usize && !index.is_complete() {
            let more = 2 * index.loaded_pages();
            index = index.grown(source, more)?;
        }
        Ok(index)
    }

    /// Reads and checks the header of `source`.
    fn read_header<S: ByteSource + ?Sized>(source: &S) -> Result<Header, FormatError> {
        let total = source.len();
        let prefix = source.read(0..HEADER_BYTES.min(total))?;
        Self::parse_header(&prefix, total)
    }

    /// An index with no pages read yet: header and block table.
    fn start<S: ByteSource + ?Sized>(
        header: Header,
        source: &S,
    ) -> Result<ModelIndex, FormatError> {
        let layout = header.index_layout();
        let blocks = parse_block_table(&header, &source.read(layout.block_table_range())?)?;
        let block0 = if layout.block_count > 0 {
            let r = layout.block_range(0);
            r.end - r.start
        } else {
            0
        };
        Ok(ModelIndex {
            header,
            nodes: Vec::new(),
            visible: 0,
            stats: IndexStats {
                index_bytes: header.patch_data_offset,
                first_frame_bytes: layout.directory_offset + block0,
                page_nodes: header.page_nodes,
                page_count: layout.page_count,
            },
            blocks,
            entries: Vec::new(),
            patch_end: header.patch_data_offset,
        })
    }

    /// Pages read so far.
    pub fn loaded_pages(&self) -> u64 {
        self.header
            .index_layout()
            .page_count
            .min((self.nodes.len() as u64).div_ceil(self.header.page_nodes.max(1) as u64))
    }

    /// Whether every page has been read (the index shows every node).
    pub fn is_complete(&self) -> bool {
        self.nodes.len() as u64 == self.header.node_count
    }

    /// This index with pages read up to `pages` (at most all), from `source`: the
    /// directory blocks not read yet in one read, the new pages in another. Every part is
    /// checked as [`ModelIndex::from_parts`] checks it.
    pub fn grown<S: ByteSource + ?Sized>(
        &self,
        source: &S,
        pages: u64,
    ) -> Result<ModelIndex, FormatError> {
        let h = self.header;
        let layout = h.index_layout();
        let target = pages.min(layout.page_count);
        let from = self.loaded_pages();
        let mut next = self.clone();
        if target <= from {
            return Ok(next);
        }
        // Directory blocks.
        let have_blocks = (next.entries.len() as u64).div_ceil(DIRECTORY_BLOCK_PAGES);
        let need_blocks = target.div_ceil(DIRECTORY_BLOCK_PAGES);
        if need_blocks > have_blocks {
            let start = layout.block_range(have_blocks).start;
            let end = layout.block_range(need_blocks - 1).end;
            let bytes = source.read(start..end)?;
            for b in have_blocks..need_blocks {
                let r = layout.block_range(b);
                let slice = &bytes[(r.start - start) as usize..(r.end - start) as usize];
                let after = next
                    .entries
                    .last()
                    .map_or(layout.pages_offset, |e| e.offset + e.bytes as u64);
                let entries = parse_directory_block(&h, b, slice, next.blocks[b as usize], after)?;
                next.entries.extend(entries);
            }
        }
        // Pages, contiguous in the file: one read.
        let first = next.entries[from as usize];
        let last = next.entries[target as usize - 1];
        let pages_end = last.offset + last.bytes as u64;
        let bytes = source.read(first.offset..pages_end)?;
        for p in from..target {
            let e = next.entries[p as usize];
            let slice = &bytes[(e.offset - first.offset) as usize
                ..(e.offset - first.offset + e.bytes as u64) as usize];
            let (records, end) = parse_page(&h, p, &e, slice)?;
            if records
                .first()
                .is_some_and(|r| r.patch_offset != next.patch_end)
            {
                return Err(FormatError::CorruptIndexPage {
                    page: p,
                    detail: "its patches do not start where the previous page's end".into(),
                });
            }
            if p == 0 {
                next.stats.first_frame_bytes += e.bytes as u64;
            }
            next.patch_end = end;
            check_nodes(&h, &records, next.nodes.len(), next.nodes.last())?;
            next.nodes.extend(records);
        }
        if target == layout.page_count {
            if pages_end != h.patch_data_offset {
                return Err(invalid_header(format!(
                    "index pages end at {pages_end}, the patch data starts at {}",
                    h.patch_data_offset
                )));
            }
            if next.patch_end != h.file_bytes {
                return Err(invalid_header(format!(
                    "patches end at {}, the file at {}",
                    next.patch_end, h.file_bytes
                )));
            }
            next.visible = next.nodes.len();
        } else {
            // Show the complete levels: drop the level the last page ends in.
            let last_level = next.nodes.last().map_or(0, |n| n.level);
            next.visible = next.nodes.partition_point(|n| n.level < last_level);
        }
        Ok(next)
    }

    /// Sizes of the paged index.
    pub fn index_stats(&self) -> IndexStats {
        self.stats
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The node records, in node order.
    pub fn nodes(&self) -> &[NodeRecord] {
        &self.nodes[..self.visible]
    }

    /// Node `i`'s record, or an error naming the node.
    pub fn node(&self, i: usize) -> Result<&NodeRecord, FormatError> {
        self.nodes().get(i).ok_or_else(|| FormatError::InvalidNode {
            node: i as u32,
            detail: if self.is_complete() || i as u64 >= self.header.node_count {
                format!("no such node (model has {})", self.header.node_count)
            } else {
                format!(
                    "not in the part of the index read so far ({} nodes)",
                    self.visible
                )
            },
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
        codec::decode_patch(bytes, self.header.attributes, self.node(i)?.into())
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
    if h.index_offset != HEADER_BYTES {
        return Err(invalid_header(format!(
            "index at {}, expected {HEADER_BYTES}",
            h.index_offset
        )));
    }
    if !(1..=MAX_PAGE_NODES).contains(&h.page_nodes) {
        return Err(invalid_header(format!(
            "page_nodes {} not in 1..={MAX_PAGE_NODES}",
            h.page_nodes
        )));
    }
    if h.node_count >= NO_NODE as u64 {
        return Err(invalid_header(format!(
            "{} nodes: too many for u32 links",
            h.node_count
        )));
    }
    // Every patch has at least its header, which bounds the node count (and what a
    // reader allocates for it) by the file's length.
    if h.node_count.saturating_mul(PATCH_HEADER_BYTES as u64) > h.patch_data_bytes {
        return Err(invalid_header(format!(
            "{} nodes cannot fit in {} bytes of patch data",
            h.node_count, h.patch_data_bytes
        )));
    }
    let layout = h.index_layout();
    if layout.page_count != h.page_count as u64 {
        return Err(invalid_header(format!(
            "page_count {} but {} nodes in pages of {} make {}",
            h.page_count, h.node_count, h.page_nodes, layout.page_count
        )));
    }
    if layout.pages_offset > h.patch_data_offset {
        return Err(invalid_header(format!(
            "the index directory ends at {}, after the patch data offset {}",
            layout.pages_offset, h.patch_data_offset
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
    if h.attributes & crate::ATTR_TEXTURE != 0 && h.attributes & crate::ATTR_UVS == 0 {
        return Err(invalid_header("textures without UVs".to_string()));
    }
    if h.attributes
        & !(crate::ATTR_NORMALS | crate::ATTR_COLORS | crate::ATTR_UVS | crate::ATTR_TEXTURE)
        != 0
    {
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
    // Model-space coordinates a reader can compute with: origin + q * step in f64, and
    // the camera's f32 frame around the model.
    const MAX_COORD: f64 = 1e15;
    if h.cube_size > MAX_COORD || h.cube_origin.iter().any(|v| v.abs() > MAX_COORD) {
        return Err(invalid_header(format!(
            "bounding cube at {:?} of size {} is beyond +-{MAX_COORD:e}",
            h.cube_origin, h.cube_size
        )));
    }
    // The model's bounding sphere holds points of the cube: its centre lies in the cube
    // (with a margin of one cube) and its radius is at most the cube's diagonal.
    let [cx, cy, cz, r] = h.bounding_sphere;
    let centre_ok = [cx, cy, cz]
        .iter()
        .zip(h.cube_origin)
        .all(|(&c, o)| c.is_finite() && c >= o - h.cube_size && c <= o + 2.0 * h.cube_size);
    if !(centre_ok && r.is_finite() && (0.0..=2.0 * h.cube_size).contains(&r)) {
        return Err(invalid_header(format!(
            "bounding sphere {:?} does not fit the bounding cube at {:?} of size {}",
            h.bounding_sphere, h.cube_origin, h.cube_size
        )));
    }
    Ok(())
}

/// Every patch inside the patch data, every link a valid index other than the node's own,
/// levels in table order (a paged reader shows the complete levels of what it read, so
/// a level out of order would hide nodes it showed). `nodes` are the records of nodes
/// `first..`; `before` is node `first - 1`'s.
fn check_nodes(
    h: &Header,
    nodes: &[NodeRecord],
    first: usize,
    before: Option<&NodeRecord>,
) -> Result<(), FormatError> {
    let count = h.node_count;
    let patch_start = h.patch_data_offset;
    let patch_end = h.patch_data_offset + h.patch_data_bytes;
    let mut level = before.map_or(0, |n| n.level);
    for (i, n) in nodes.iter().enumerate() {
        let node = (first + i) as u32;
        if n.level < level {
            return Err(FormatError::InvalidNode {
                node,
                detail: format!(
                    "level {} after a node of level {level}: the table is not sorted by level",
                    n.level
                ),
            });
        }
        level = n.level;
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
