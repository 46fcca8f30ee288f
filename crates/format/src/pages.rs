//! The paged node index (format version 2): node records packed into compressed pages
//! that a reader fetches one at a time, like patches.
//!
//! Layout after the header (every byte in `docs/format.md`):
//!
//! ```text
//! block table   block_count x u32      CRC-32 of each directory block
//! directory     page_count x PageEntry one 16-byte entry per page (offset, bytes, CRC)
//! pages         page_count zstd frames each `page_nodes` nodes (the last fewer), columnar
//! ```
//!
//! The directory is cut into blocks of [`DIRECTORY_BLOCK_PAGES`] entries so a reader
//! needs only the block that names the page it wants: whatever the model's size, the
//! first frame reads the header, the block table (4 bytes per 2M nodes), one block and
//! the first page (the roots and the levels under them).
//!
//! A page is columnar (all flags, then all levels, ...) with small integers as LEB128
//! deltas from the previous node and floats split into byte planes, then zstd: sibling
//! and neighbouring records differ little, and diamond mates (near each other in the
//! level's Morton order) share their error and saturated sphere, stored once per page.
//! Written by hand because the layout is Tessera's own; zstd does the entropy coding.

use bytemuck::{Pod, Zeroable};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::error::FormatError;
use crate::records::{NodeRecord, MAX_TEXTURE_DIM, NODE_FLAG_LEAF, NO_NODE};

/// Nodes per index page the writer uses unless told otherwise.
pub const DEFAULT_PAGE_NODES: u32 = 512;
/// Largest `page_nodes` a reader accepts.
pub const MAX_PAGE_NODES: u32 = 1 << 16;
/// Directory entries per directory block.
pub const DIRECTORY_BLOCK_PAGES: u64 = 4096;
/// Bytes of one directory entry.
pub const PAGE_ENTRY_BYTES: u64 = 16;
/// zstd level of index pages (they are small and read far more often than written).
const PAGE_ZSTD_LEVEL: i32 = 19;
/// Upper bound of one node's uncompressed page bytes (see the column list).
/// (The columns need at most 113 bytes a node; `docs/format.md` states 128.)
const MAX_NODE_PAGE_BYTES: usize = 128;

/// Page flags bits (per node, column 0). Bit 0 is [`NODE_FLAG_LEAF`].
const PF_CHILD0: u8 = 2;
const PF_CHILD1: u8 = 4;
const PF_PARENT: u8 = 8;
const PF_DIAMOND_DATA: u8 = 16;
const PF_TIGHT_IS_SATURATED: u8 = 32;
const PF_KNOWN: u8 =
    NODE_FLAG_LEAF | PF_CHILD0 | PF_CHILD1 | PF_PARENT | PF_DIAMOND_DATA | PF_TIGHT_IS_SATURATED;

/// The normal cone a model stores for `cone` (`[axis, cos half-angle]`): the axis in
/// 16-bit octahedral coordinates and the cosine rounded down to a multiple of 1/65535,
/// widened by the axis' rounding, so the stored cone contains the given one. A cone of
/// half-angle 90 degrees or more (cos <= 0) never culls (`tessera_select` needs
/// cos > 0) and is stored as "none", `[0, 0, 0, -1]`. Exact on every platform: the
/// decoder uses only IEEE `+ - * /` and `sqrt`.
pub fn stored_cone(cone: [f32; 4]) -> [f32; 4] {
    decode_cone(encode_cone(cone))
}

const NO_CONE: [f32; 4] = [0.0, 0.0, 0.0, -1.0];

fn decode_cone(code: [u16; 3]) -> [f32; 4] {
    if code[2] == 0 {
        return NO_CONE;
    }
    let x = (code[0] as i16) as f32 / 32767.0;
    let y = (code[1] as i16) as f32 / 32767.0;
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        let sx = if x >= 0.0 { 1.0 } else { -1.0 };
        let sy = if y >= 0.0 { 1.0 } else { -1.0 };
        ((1.0 - y.abs()) * sx, (1.0 - x.abs()) * sy)
    } else {
        (x, y)
    };
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len, code[2] as f32 / 65535.0]
}

/// The angle between direction `a` (unit) and axis `b`, measured by the chord of the
/// unit vectors (stable for tiny angles, where `acos` of a dot product is not).
fn turn(a: [f64; 3], b: [f32; 4]) -> f64 {
    let l = (0..3)
        .map(|k| b[k] as f64 * b[k] as f64)
        .sum::<f64>()
        .sqrt();
    let chord = (0..3)
        .map(|k| (a[k] - b[k] as f64 / l).powi(2))
        .sum::<f64>()
        .sqrt();
    2.0 * (chord / 2.0).min(1.0).asin()
}

fn encode_cone(cone: [f32; 4]) -> [u16; 3] {
    let [ax, ay, az, c] = cone.map(|v| v as f64);
    let len = (ax * ax + ay * ay + az * az).sqrt();
    if !(c > 0.0 && len > 0.0 && cone.iter().all(|v| v.is_finite())) {
        return [0, 0, 0];
    }
    let (ax, ay, az) = (ax / len, ay / len, az / len);
    let l1 = ax.abs() + ay.abs() + az.abs();
    let (mut ox, mut oy) = (ax / l1, ay / l1);
    if az < 0.0 {
        let (fx, fy) = (ox, oy);
        ox = (1.0 - fy.abs()) * if fx >= 0.0 { 1.0 } else { -1.0 };
        oy = (1.0 - fx.abs()) * if fy >= 0.0 { 1.0 } else { -1.0 };
    }
    let q = |v: f64| ((v * 32767.0).round().clamp(-32767.0, 32767.0) as i16) as u16;
    let (qx, qy) = (q(ox), q(oy));
    // The decoded axis and how far it turned; widen the cone by that (and a margin for
    // the f32 arithmetic of the test).
    let a = decode_cone([qx, qy, 1]);
    let angle = c.min(1.0).acos() + turn([ax, ay, az], a) + 1e-5;
    if angle >= std::f64::consts::FRAC_PI_2 {
        return [0, 0, 0];
    }
    let mut code = (angle.cos() * 65535.0).floor() as u32;
    while code > 0 && (code as f32 / 65535.0) as f64 > angle.cos() {
        code -= 1;
    }
    [qx, qy, code as u16]
}

/// Where one index page lies: an entry of the directory.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PageEntry {
    /// Absolute file offset of the page's zstd frame.
    pub offset: u64,
    /// Length of the frame in bytes.
    pub bytes: u32,
    /// CRC-32 of the frame.
    pub crc32: u32,
}

const _: () = assert!(std::mem::size_of::<PageEntry>() as u64 == PAGE_ENTRY_BYTES);

/// Where the parts of a paged index lie, from the header's counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexLayout {
    /// Nodes per page (the last page may hold fewer).
    pub page_nodes: u32,
    /// Number of pages.
    pub page_count: u64,
    /// Number of directory blocks.
    pub block_count: u64,
    /// Offset of the block table (right after the header).
    pub block_table_offset: u64,
    /// Offset of the directory.
    pub directory_offset: u64,
    /// Offset of the first page.
    pub pages_offset: u64,
}

impl IndexLayout {
    /// The layout of `node_count` nodes in pages of `page_nodes`, after a header of
    /// `header_bytes`. `page_nodes` must be at least 1.
    pub fn new(node_count: u64, page_nodes: u32, header_bytes: u64) -> IndexLayout {
        let page_count = node_count.div_ceil(page_nodes.max(1) as u64);
        let block_count = page_count.div_ceil(DIRECTORY_BLOCK_PAGES);
        let directory_offset = header_bytes + 4 * block_count;
        IndexLayout {
            page_nodes,
            page_count,
            block_count,
            block_table_offset: header_bytes,
            directory_offset,
            pages_offset: directory_offset + PAGE_ENTRY_BYTES * page_count,
        }
    }

    /// Byte range of the block table.
    pub fn block_table_range(&self) -> std::ops::Range<u64> {
        self.block_table_offset..self.directory_offset
    }

    /// Byte range of directory block `b`.
    pub fn block_range(&self, b: u64) -> std::ops::Range<u64> {
        let first = b * DIRECTORY_BLOCK_PAGES;
        let last = ((b + 1) * DIRECTORY_BLOCK_PAGES).min(self.page_count);
        self.directory_offset + PAGE_ENTRY_BYTES * first
            ..self.directory_offset + PAGE_ENTRY_BYTES * last
    }

    /// The page holding node `i`.
    pub fn page_of(&self, i: u64) -> u64 {
        i / self.page_nodes as u64
    }

    /// The nodes of page `p`: `first..end`, given the node count.
    pub fn page_nodes_range(&self, p: u64, node_count: u64) -> std::ops::Range<u64> {
        let first = p * self.page_nodes as u64;
        first.min(node_count)..(first + self.page_nodes as u64).min(node_count)
    }
}

fn corrupt(page: u64, detail: impl Into<String>) -> FormatError {
    FormatError::CorruptIndexPage {
        page,
        detail: detail.into(),
    }
}

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

fn put_leb(out: &mut Vec<u8>, mut v: u64) {
    loop {
        let b = (v & 0x7f) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

/// Signed difference of two u32 link values as the encoder stores it.
fn link_delta(v: u32, pred: u32) -> u64 {
    zigzag(v as i64 - pred as i64)
}

fn put_f32_planes(out: &mut Vec<u8>, values: &[f32]) {
    for plane in 0..4 {
        out.extend(values.iter().map(|v| v.to_le_bytes()[plane]));
    }
}

/// Encodes the nodes of one page as a zstd frame; `patch_base` is the offset of the
/// first node's patch relative to the patch data (the nodes' `patch_offset`s are not
/// read: the page's patches follow each other). Panics only on caller bugs (zstd failing in memory).
pub fn encode_page(nodes: &[NodeRecord], patch_base: u64) -> Vec<u8> {
    let n = nodes.len();
    let mut out = Vec::with_capacity(8 + n * 64);
    out.extend_from_slice(&patch_base.to_le_bytes());
    let mut seen: FxHashSet<u32> = FxHashSet::default();
    let mut flags = Vec::with_capacity(n);
    let mut diamond_nodes = Vec::new();
    for node in nodes {
        let mut f = node.flags & NODE_FLAG_LEAF;
        if node.children[0] != NO_NODE {
            f |= PF_CHILD0;
        }
        if node.children[1] != NO_NODE {
            f |= PF_CHILD1;
        }
        if node.parent != NO_NODE {
            f |= PF_PARENT;
        }
        if seen.insert(node.diamond) {
            f |= PF_DIAMOND_DATA;
            diamond_nodes.push(*node);
        }
        if node.tight_sphere == node.saturated_sphere {
            f |= PF_TIGHT_IS_SATURATED;
        }
        flags.push(f);
    }
    out.extend_from_slice(&flags);
    out.extend(nodes.iter().map(|n| n.level));
    out.extend(nodes.iter().map(|n| n.root));
    for n in nodes {
        put_leb(&mut out, n.patch_bytes as u64);
    }
    for n in nodes {
        put_leb(&mut out, n.vertex_count as u64);
    }
    for n in nodes {
        put_leb(&mut out, n.triangle_count as u64);
    }
    let mut child_pred = 0u32;
    for n in nodes {
        for &c in n.children.iter().filter(|&&c| c != NO_NODE) {
            put_leb(&mut out, link_delta(c, child_pred));
            child_pred = c.wrapping_add(1);
        }
    }
    let mut parent_pred = 0u32;
    for n in nodes.iter().filter(|n| n.parent != NO_NODE) {
        put_leb(&mut out, link_delta(n.parent, parent_pred));
        parent_pred = n.parent;
    }
    let mut diamond_pred = 0u32;
    for n in nodes {
        put_leb(&mut out, link_delta(n.diamond, diamond_pred));
        diamond_pred = n.diamond;
    }
    for n in nodes {
        put_leb(&mut out, n.tet_path);
    }
    for n in nodes {
        out.extend_from_slice(&n.patch_crc32.to_le_bytes());
    }
    for axis in 0..3 {
        let mut pred = 0u32;
        for n in nodes {
            put_leb(&mut out, link_delta(n.quant_min[axis], pred));
            pred = n.quant_min[axis];
        }
    }
    put_f32_planes(
        &mut out,
        &diamond_nodes.iter().map(|n| n.error).collect::<Vec<_>>(),
    );
    for k in 0..4 {
        let col: Vec<f32> = diamond_nodes
            .iter()
            .map(|n| n.saturated_sphere[k])
            .collect();
        put_f32_planes(&mut out, &col);
    }
    let own_tight: Vec<&NodeRecord> = nodes
        .iter()
        .filter(|n| n.tight_sphere != n.saturated_sphere)
        .collect();
    for k in 0..4 {
        let col: Vec<f32> = own_tight.iter().map(|n| n.tight_sphere[k]).collect();
        put_f32_planes(&mut out, &col);
    }
    let cones: Vec<[u16; 3]> = nodes.iter().map(|n| encode_cone(n.normal_cone)).collect();
    for k in 0..3 {
        out.extend(cones.iter().map(|c| c[k] as u8));
        out.extend(cones.iter().map(|c| (c[k] >> 8) as u8));
    }
    // Column 18: texture size, LEB128 width then height per node (two zero bytes a node
    // in models without textures, which zstd squeezes to nothing).
    for n in nodes {
        for d in n.texture_size {
            put_leb(&mut out, d as u64);
        }
    }
    zstd::bulk::compress(&out, PAGE_ZSTD_LEVEL).expect("zstd compression in memory")
}

/// A cursor over a decompressed page; every read checks the bounds.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    page: u64,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], FormatError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| corrupt(self.page, "page ends early"))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn leb(&mut self, max_bits: u32) -> Result<u64, FormatError> {
        let mut v = 0u64;
        let mut shift = 0u32;
        loop {
            let b = *self
                .bytes
                .get(self.at)
                .ok_or_else(|| corrupt(self.page, "page ends inside a number"))?;
            self.at += 1;
            if shift >= max_bits || (shift > 0 && ((b & 0x7f) as u64) >> (max_bits - shift) != 0) {
                return Err(corrupt(self.page, "number too large"));
            }
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
            shift += 7;
        }
    }

    fn leb_u32(&mut self) -> Result<u32, FormatError> {
        Ok(self.leb(32)? as u32)
    }

    /// A u32 link from its delta to `pred`; must land in u32.
    fn link(&mut self, pred: u32) -> Result<u32, FormatError> {
        let d = unzigzag(self.leb(34)?);
        u32::try_from(pred as i64 + d).map_err(|_| corrupt(self.page, "link out of range"))
    }

    fn f32_planes(&mut self, m: usize) -> Result<Vec<f32>, FormatError> {
        let planes = self.take(4 * m)?;
        Ok((0..m)
            .map(|i| {
                f32::from_le_bytes([
                    planes[i],
                    planes[m + i],
                    planes[2 * m + i],
                    planes[3 * m + i],
                ])
            })
            .collect())
    }
}

/// Decodes page `page` (its zstd `frame`, CRC already checked) holding `count` nodes into
/// records; `patch_data_offset` turns the page's relative patch offsets into absolute
/// ones. Every malformed byte is an error naming the page, never a panic.
pub fn decode_page(
    page: u64,
    frame: &[u8],
    count: usize,
    patch_data_offset: u64,
) -> Result<(Vec<NodeRecord>, u64), FormatError> {
    let cap = 8 + count * MAX_NODE_PAGE_BYTES;
    let raw = zstd::bulk::decompress(frame, cap).map_err(|e| {
        corrupt(
            page,
            format!("not a zstd frame of at most {cap} bytes: {e}"),
        )
    })?;
    let mut c = Cursor {
        bytes: &raw,
        at: 0,
        page,
    };
    let base = u64::from_le_bytes(c.take(8)?.try_into().expect("8 bytes"));
    let mut nodes = vec![NodeRecord::zeroed(); count];
    let flags = c.take(count)?.to_vec();
    if let Some(f) = flags.iter().find(|&&f| f & !PF_KNOWN != 0) {
        return Err(corrupt(page, format!("unknown node flag bits {f:#x}")));
    }
    for (n, &f) in nodes.iter_mut().zip(&flags) {
        n.flags = f & NODE_FLAG_LEAF;
    }
    let levels = c.take(count)?.to_vec();
    let roots = c.take(count)?.to_vec();
    for ((n, l), r) in nodes.iter_mut().zip(levels).zip(roots) {
        n.level = l;
        n.root = r;
    }
    for n in nodes.iter_mut() {
        n.patch_bytes = c.leb_u32()?;
    }
    for n in nodes.iter_mut() {
        n.vertex_count = c.leb_u32()?;
    }
    for n in nodes.iter_mut() {
        n.triangle_count = c.leb_u32()?;
    }
    let mut child_pred = 0u32;
    for (n, &f) in nodes.iter_mut().zip(&flags) {
        for (k, bit) in [PF_CHILD0, PF_CHILD1].into_iter().enumerate() {
            n.children[k] = if f & bit != 0 {
                let v = c.link(child_pred)?;
                child_pred = v.wrapping_add(1);
                v
            } else {
                NO_NODE
            };
        }
    }
    let mut parent_pred = 0u32;
    for (n, &f) in nodes.iter_mut().zip(&flags) {
        n.parent = if f & PF_PARENT != 0 {
            parent_pred = c.link(parent_pred)?;
            parent_pred
        } else {
            NO_NODE
        };
    }
    let mut diamond_pred = 0u32;
    for n in nodes.iter_mut() {
        diamond_pred = c.link(diamond_pred)?;
        n.diamond = diamond_pred;
    }
    for n in nodes.iter_mut() {
        n.tet_path = c.leb(64)?;
    }
    for n in nodes.iter_mut() {
        n.patch_crc32 = u32::from_le_bytes(c.take(4)?.try_into().expect("4 bytes"));
    }
    for axis in 0..3 {
        let mut pred = 0u32;
        for n in nodes.iter_mut() {
            pred = c.link(pred)?;
            n.quant_min[axis] = pred;
        }
    }
    // Diamond data: once per diamond new to this page, in order of first appearance.
    let with_data: Vec<usize> = (0..count)
        .filter(|&i| flags[i] & PF_DIAMOND_DATA != 0)
        .collect();
    let m = with_data.len();
    let errors = c.f32_planes(m)?;
    let mut sat = [vec![], vec![], vec![], vec![]];
    for col in sat.iter_mut() {
        *col = c.f32_planes(m)?;
    }
    let mut first_of: FxHashMap<u32, usize> = FxHashMap::default();
    let mut data_slot = 0usize;
    for i in 0..count {
        let d = nodes[i].diamond;
        if flags[i] & PF_DIAMOND_DATA != 0 {
            if first_of.insert(d, i).is_some() {
                return Err(corrupt(page, format!("diamond {d} carries its data twice")));
            }
            nodes[i].error = errors[data_slot];
            nodes[i].saturated_sphere = [0, 1, 2, 3].map(|k| sat[k][data_slot]);
            data_slot += 1;
        } else {
            let Some(&j) = first_of.get(&d) else {
                return Err(corrupt(
                    page,
                    format!("node {i} of the page refers to diamond {d}, not described before it"),
                ));
            };
            nodes[i].error = nodes[j].error;
            nodes[i].saturated_sphere = nodes[j].saturated_sphere;
        }
    }
    let own_tight: Vec<usize> = (0..count)
        .filter(|&i| flags[i] & PF_TIGHT_IS_SATURATED == 0)
        .collect();
    for n in nodes.iter_mut() {
        n.tight_sphere = n.saturated_sphere;
    }
    for k in 0..4 {
        for (&i, v) in own_tight.iter().zip(c.f32_planes(own_tight.len())?) {
            nodes[i].tight_sphere[k] = v;
        }
    }
    let mut cones = vec![[0u16; 3]; count];
    for k in 0..3 {
        let lo = c.take(count)?.to_vec();
        let hi = c.take(count)?;
        for ((cone, l), h) in cones.iter_mut().zip(lo).zip(hi) {
            cone[k] = l as u16 | (*h as u16) << 8;
        }
    }
    for (n, code) in nodes.iter_mut().zip(cones) {
        n.normal_cone = decode_cone(code);
    }
    for n in nodes.iter_mut() {
        for k in 0..2 {
            let d = c.leb_u32()?;
            if d > MAX_TEXTURE_DIM {
                return Err(corrupt(
                    page,
                    format!("texture size {d} exceeds {MAX_TEXTURE_DIM}"),
                ));
            }
            n.texture_size[k] = d as u16;
        }
    }
    if c.at != raw.len() {
        return Err(corrupt(
            page,
            format!("{} bytes after the last column", raw.len() - c.at),
        ));
    }
    // Patch offsets: contiguous from the page's base.
    let mut offset = patch_data_offset
        .checked_add(base)
        .ok_or_else(|| corrupt(page, "patch base out of range"))?;
    for n in nodes.iter_mut() {
        n.patch_offset = offset;
        offset = offset
            .checked_add(n.patch_bytes as u64)
            .ok_or_else(|| corrupt(page, "patch offsets overflow"))?;
    }
    Ok((nodes, offset))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle(a: [f32; 4], b: [f32; 4]) -> f64 {
        let l = (0..3)
            .map(|k| a[k] as f64 * a[k] as f64)
            .sum::<f64>()
            .sqrt();
        turn([0, 1, 2].map(|k| a[k] as f64 / l), b)
    }

    /// The stored cone holds every direction the given cone holds: its half-angle
    /// covers the given half-angle plus the turn of the axis.
    #[test]
    fn stored_cones_contain_the_given_ones() {
        let mut seed = 0x2545f4914f6cdd1du64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut culling = 0;
        for i in 0..20_000 {
            let v = [rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let c = if i % 7 == 0 { 1.0 } else { rnd() * 1.2 - 0.2 };
            let cone = [
                (v[0] / l) as f32,
                (v[1] / l) as f32,
                (v[2] / l) as f32,
                c as f32,
            ];
            let s = stored_cone(cone);
            if s == NO_CONE {
                assert!(
                    c <= 0.0 || (c as f32).acos() as f64 > 1.5,
                    "{cone:?} lost its cone"
                );
                continue;
            }
            culling += 1;
            let need = (cone[3] as f64).min(1.0).acos() + angle(cone, s);
            assert!((s[3] as f64).acos() >= need, "{cone:?} -> {s:?}");
            // cos steps of 1/65535 are 0.32 degree wide at cos = 1.
            assert!(
                (s[3] as f64).acos() <= need + 6e-3,
                "{cone:?} -> {s:?} widened too much"
            );
            let len: f64 = (0..3)
                .map(|k| s[k] as f64 * s[k] as f64)
                .sum::<f64>()
                .sqrt();
            assert!((len - 1.0).abs() < 1e-6);
        }
        assert!(culling > 10_000);
        assert_eq!(stored_cone(NO_CONE), NO_CONE);
        assert_eq!(stored_cone([0.0, 0.0, 1.0, f32::NAN]), NO_CONE);
    }

    fn node(i: u32) -> NodeRecord {
        let f = i as f32;
        NodeRecord {
            patch_offset: 0,
            tet_path: (i as u64 * 0x9e37_79b9) & ((1 << (i % 40)) - 1),
            patch_bytes: 40 + i % 300,
            patch_crc32: i.wrapping_mul(0x01000193),
            vertex_count: i % 5000,
            triangle_count: i % 9000,
            children: if i.is_multiple_of(3) {
                [NO_NODE, NO_NODE]
            } else {
                [
                    2 * i + 1,
                    if i.is_multiple_of(5) {
                        NO_NODE
                    } else {
                        2 * i + 2
                    },
                ]
            },
            parent: if i < 6 { NO_NODE } else { (i - 6) / 2 },
            diamond: i / 3,
            level: (i / 100) as u8,
            root: (i % 6) as u8,
            flags: i.is_multiple_of(3) as u8,
            error: (i / 3) as f32 * 0.5,
            tight_sphere: [f, -f, 0.25 * f, 1.0 + f],
            saturated_sphere: [(i / 3) as f32, 1.0, 2.0, 1e3 + (i / 3) as f32],
            normal_cone: NO_CONE,
            quant_min: [i * 7, u32::MAX - i, i % 3],
            texture_size: [(i % 7) as u16 * 300, (i % 5) as u16 * 17],
            reserved: [0; 2],
            pad: 0,
        }
    }

    #[test]
    fn pages_round_trip_and_reject_damage() {
        let mut nodes: Vec<NodeRecord> = (0..700).map(node).collect();
        for n in nodes.iter_mut().step_by(4) {
            n.tight_sphere = n.saturated_sphere;
        }
        // Diamond data is shared within a page: give mates the same error and sphere.
        let mut at = 0u64;
        for n in nodes.iter_mut() {
            n.patch_offset = at;
            at += n.patch_bytes as u64;
        }
        for page in nodes.chunks(300) {
            let base = page[0].patch_offset;
            let frame = encode_page(page, base);
            let (got, end) = decode_page(3, &frame, page.len(), 1000).unwrap();
            assert_eq!(
                end,
                1000 + base + page.iter().map(|n| n.patch_bytes as u64).sum::<u64>()
            );
            for (g, w) in got.iter().zip(page) {
                let mut w = *w;
                w.patch_offset += 1000;
                assert_eq!(g, &w);
            }
            // Wrong node count, truncated frames, a frame of other bytes: errors.
            assert!(decode_page(3, &frame, page.len() + 1, 0).is_err());
            assert!(decode_page(3, &frame, page.len() - 1, 0).is_err());
            assert!(decode_page(3, &frame[..frame.len() / 2], page.len(), 0).is_err());
            let junk = zstd::bulk::compress(&vec![0xffu8; 4000], 1).unwrap();
            let e = decode_page(3, &junk, page.len(), 0).unwrap_err();
            assert!(e.to_string().contains("index page 3"), "{e}");
        }
    }
}
