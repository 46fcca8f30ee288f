//! The patch codec: one node's mesh patch <-> bytes.
//!
//! Patches dominate the file size (the target is about 6 bytes per input triangle for the
//! whole multiresolution model), and they are decoded at render time, so the codec is
//! built on meshoptimizer's fast index and vertex codecs, optionally followed by zstd.
//! Positions are integers on the global grid, stored as offsets from the node's
//! `quant_min`; decoding is exact, so vertices shared between patches stay bit-identical.
//! The byte layout is specified in `docs/format.md` ("Patch encoding").

use std::borrow::Cow;

use crate::error::FormatError;
use crate::records::{ATTR_COLORS, ATTR_NORMALS, ATTR_UVS, NO_NODE};

/// Version of the patch encoding (byte 8 of every patch header).
pub const PATCH_CODEC_VERSION: u8 = 3;
/// Bytes of the fixed patch header that precedes the section payload.
pub const PATCH_HEADER_BYTES: usize = 40;
/// Patch flag: the section payload is one zstd frame.
pub const PATCH_FLAG_ZSTD: u8 = 1;
/// Patch flag: the patch carries morph targets.
pub const PATCH_FLAG_MORPH: u8 = 2;
/// Largest vertex count a patch may have (decoders reject more before allocating).
pub const MAX_PATCH_VERTICES: u32 = 1 << 22;
/// Largest triangle count a patch may have (decoders reject more before allocating).
pub const MAX_PATCH_TRIANGLES: u32 = 1 << 23;

/// All `ATTR_*` bits this version knows.
const ATTR_ALL: u32 = ATTR_NORMALS | ATTR_COLORS | ATTR_UVS;
/// meshopt vertex codec version and level used by the encoder (the decoder reads any).
const VERTEX_CODEC_VERSION: i32 = 1;
/// Level 2 (meshoptimizer's default): on whole builds level 3 gave the same bytes on the
/// 10M sphere and 0.1% more on the Dragon, for ~8% more encoding time.
const VERTEX_CODEC_LEVEL: i32 = 2;
/// zstd level for the section payload. Measured on whole builds: level 5 gave 0.6%
/// fewer bytes (10M sphere 4.75 vs 4.78 B/triangle, Dragon 5.90 vs 5.93) for ~8% more
/// encoding time; without zstd the files are 20-38% larger.
const ZSTD_LEVEL: i32 = 3;

/// Section order in the payload (and in the header's length table).
const SEC_INDICES: usize = 0;
const SEC_POSITIONS: usize = 1;
const SEC_NORMALS: usize = 2;
const SEC_COLORS: usize = 3;
const SEC_UVS: usize = 4;
const SEC_MORPH: usize = 5;
const SECTION_COUNT: usize = 6;

/// One node's decoded mesh patch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchData {
    /// Absolute global grid coordinates, one per vertex.
    pub positions: Vec<[u32; 3]>,
    /// Unit normals; empty when the model has no [`ATTR_NORMALS`].
    pub normals: Vec<[f32; 3]>,
    /// RGBA8 colours; empty unless [`ATTR_COLORS`].
    pub colors: Vec<[u8; 4]>,
    /// Texture coordinates; empty unless [`ATTR_UVS`].
    pub uvs: Vec<[f32; 2]>,
    /// Per vertex: grid position of the vertex it moves to in the parent's
    /// simplification (itself if it survived or was locked); empty for roots.
    pub morph_targets: Vec<[u32; 3]>,
    /// Triangle list, 3 indices per triangle.
    pub indices: Vec<u32>,
}

impl PatchData {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// Encodes a patch. `attributes` are the model's `ATTR_*` bits; `quant_min` is the
/// node's `quant_min` (component-wise minimum of `patch.positions`, or any lower point).
///
/// # Panics
/// On inconsistent input, which is a bug in the caller: an attribute array whose length
/// is not the vertex count (or not empty when its `ATTR_*` bit is clear), an index count
/// that is not a multiple of 3, an index out of range, a position below `quant_min`, or
/// more than [`MAX_PATCH_VERTICES`] / [`MAX_PATCH_TRIANGLES`].
pub fn encode_patch(patch: &PatchData, attributes: u32, quant_min: [u32; 3]) -> Vec<u8> {
    let n = patch.positions.len();
    let expect_len = |bit: u32| if attributes & bit != 0 { n } else { 0 };
    assert!(
        attributes & !ATTR_ALL == 0,
        "unknown attribute bits {attributes:#x}"
    );
    assert!(
        n <= MAX_PATCH_VERTICES as usize,
        "patch has {n} vertices, max {MAX_PATCH_VERTICES}"
    );
    assert_eq!(
        patch.normals.len(),
        expect_len(ATTR_NORMALS),
        "normals length"
    );
    assert_eq!(patch.colors.len(), expect_len(ATTR_COLORS), "colors length");
    assert_eq!(patch.uvs.len(), expect_len(ATTR_UVS), "uvs length");
    assert!(
        patch.morph_targets.is_empty() || patch.morph_targets.len() == n,
        "morph_targets length {} for {n} vertices",
        patch.morph_targets.len()
    );
    assert!(
        patch.indices.len().is_multiple_of(3),
        "index count not a multiple of 3"
    );
    let triangles = patch.indices.len() / 3;
    assert!(
        triangles <= MAX_PATCH_TRIANGLES as usize,
        "patch has {triangles} triangles, max {MAX_PATCH_TRIANGLES}"
    );
    assert!(
        patch.indices.iter().all(|&i| (i as usize) < n),
        "index out of range"
    );

    let mut sections: [Vec<u8>; SECTION_COUNT] = Default::default();
    if n > 0 {
        if triangles > 0 {
            sections[SEC_INDICES] =
                meshopt::encode_index_buffer(&patch.indices, n).expect("meshopt index encoder");
        }
        let rel: Vec<[u32; 3]> = patch
            .positions
            .iter()
            .map(|p| {
                let r = [
                    p[0].checked_sub(quant_min[0]),
                    p[1].checked_sub(quant_min[1]),
                    p[2].checked_sub(quant_min[2]),
                ];
                match r {
                    [Some(x), Some(y), Some(z)] => [x, y, z],
                    _ => panic!("position {p:?} below quant_min {quant_min:?}"),
                }
            })
            .collect();
        sections[SEC_POSITIONS] = encode_vertices(&rel);
        if attributes & ATTR_NORMALS != 0 {
            sections[SEC_NORMALS] = encode_normals(patch);
        }
        if attributes & ATTR_COLORS != 0 {
            sections[SEC_COLORS] = encode_vertices(&patch.colors);
        }
        if attributes & ATTR_UVS != 0 {
            let bits: Vec<[u32; 2]> = patch
                .uvs
                .iter()
                .map(|uv| [uv[0].to_bits(), uv[1].to_bits()])
                .collect();
            sections[SEC_UVS] = encode_vertices(&bits);
        }
        if !patch.morph_targets.is_empty() {
            sections[SEC_MORPH] = encode_morph(&patch.positions, &patch.morph_targets);
        }
    }

    let raw: Vec<u8> = sections.concat();
    let mut flags = 0u8;
    if !patch.morph_targets.is_empty() {
        flags |= PATCH_FLAG_MORPH;
    }
    let mut payload = Cow::Borrowed(&raw[..]);
    if !raw.is_empty() {
        if let Ok(z) = zstd_compress(&raw) {
            if z.len() < raw.len() {
                flags |= PATCH_FLAG_ZSTD;
                payload = Cow::Owned(z);
            }
        }
    }

    let mut out = Vec::with_capacity(PATCH_HEADER_BYTES + payload.len());
    out.extend_from_slice(&(n as u32).to_le_bytes());
    out.extend_from_slice(&(triangles as u32).to_le_bytes());
    out.push(PATCH_CODEC_VERSION);
    out.push(flags);
    out.push(attributes as u8);
    out.push(0);
    out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
    for s in &sections {
        out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    }
    debug_assert_eq!(out.len(), PATCH_HEADER_BYTES);
    out.extend_from_slice(&payload);
    out
}

thread_local! {
    /// One zstd context per thread: creating one costs more than compressing a small
    /// patch (the builder encodes tens of thousands of patches, the viewer decodes them).
    static ZSTD_C: std::cell::RefCell<Option<zstd::bulk::Compressor<'static>>> =
        const { std::cell::RefCell::new(None) };
    static ZSTD_D: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { std::cell::RefCell::new(None) };
}

fn zstd_compress(raw: &[u8]) -> std::io::Result<Vec<u8>> {
    ZSTD_C.with(|c| {
        let mut c = c.borrow_mut();
        let c = match &mut *c {
            Some(c) => c,
            slot @ None => slot.insert(zstd::bulk::Compressor::new(ZSTD_LEVEL)?),
        };
        c.compress(raw)
    })
}

/// Decompresses one frame of at most `capacity` bytes.
fn zstd_decompress(stored: &[u8], capacity: usize) -> std::io::Result<Vec<u8>> {
    ZSTD_D.with(|d| {
        let mut d = d.borrow_mut();
        let d = match &mut *d {
            Some(d) => d,
            slot @ None => slot.insert(zstd::bulk::Decompressor::new()?),
        };
        d.decompress(stored, capacity)
    })
}

/// Rice parameters are `0..=MAX_RICE_K`.
const MAX_RICE_K: u32 = 7;
/// A Rice quotient of this many or more is escaped: this many 1 bits, then the value's
/// 8 bits.
const RICE_ESCAPE: u32 = 16;

/// The normals section (see `docs/format.md`): per vertex, the octahedral code minus the
/// code predicted from the patch geometry ([`predict_normals`]), wrapping in `u8`,
/// zigzagged and Rice-coded, all x residuals first, then all y residuals, each stream
/// with its own Rice parameter.
fn encode_normals(patch: &PatchData) -> Vec<u8> {
    let n = patch.positions.len();
    let pred = predict_normals(&patch.positions, &patch.indices);
    let mut z = vec![0u8; 2 * n];
    for (i, (&v, p)) in patch.normals.iter().zip(&pred).enumerate() {
        let e = oct_encode(v);
        z[i] = zigzag(e[0].wrapping_sub(p[0]) as i8 as i32) as u8;
        z[n + i] = zigzag(e[1].wrapping_sub(p[1]) as i8 as i32) as u8;
    }
    let streams = [&z[..n], &z[n..]];
    let ks = streams.map(|st| {
        // The cheapest parameter from a histogram of the residuals: one pass over the
        // stream instead of one per parameter.
        let mut hist = [0u64; 256];
        for &v in st {
            hist[v as usize] += 1;
        }
        (0..=MAX_RICE_K)
            .min_by_key(|&k| {
                hist.iter()
                    .enumerate()
                    .map(|(v, &c)| c * rice_bits(v as u8, k) as u64)
                    .sum::<u64>()
            })
            .unwrap_or(0)
    });
    let mut out = vec![ks[0] as u8, ks[1] as u8];
    let mut w = BitWriter::new(&mut out);
    for (st, k) in streams.iter().zip(ks) {
        for &v in st.iter() {
            let q = v as u32 >> k;
            if q < RICE_ESCAPE {
                // q one bits, a zero bit, then the k low bits of v.
                w.put((1 << q) - 1, q + 1);
                w.put(v as u64 & ((1 << k) - 1), k);
            } else {
                w.put((1 << RICE_ESCAPE) - 1, RICE_ESCAPE);
                w.put(v as u64, 8);
            }
        }
    }
    w.finish();
    out
}

/// Length in bits of `v`'s Rice code with parameter `k`.
fn rice_bits(v: u8, k: u32) -> u32 {
    let q = v as u32 >> k;
    if q < RICE_ESCAPE {
        q + 1 + k
    } else {
        RICE_ESCAPE + 8
    }
}

/// Appends bits LSB-first (bit `i` of the stream is bit `i % 8` of byte `i / 8`).
struct BitWriter<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    bits: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut Vec<u8>) -> Self {
        BitWriter {
            out,
            acc: 0,
            bits: 0,
        }
    }

    /// Appends the `count` (at most 32) low bits of `v`, low bit first.
    fn put(&mut self, v: u64, count: u32) {
        self.acc |= v << self.bits;
        self.bits += count;
        while self.bits >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.bits -= 8;
        }
    }

    /// Flushes the last partial byte, padded with zero bits.
    fn finish(self) {
        if self.bits > 0 {
            self.out.push(self.acc as u8);
        }
    }
}

/// Decodes the normals section (see [`encode_normals`]) given the decoded positions and
/// indices (every index `< positions.len()`).
fn decode_normals(
    section: &[u8],
    positions: &[[u32; 3]],
    indices: &[u32],
) -> Result<Vec<[f32; 3]>, FormatError> {
    let n = positions.len();
    let (ks, bits) = match section {
        [kx, ky, rest @ ..] if (*kx as u32) <= MAX_RICE_K && (*ky as u32) <= MAX_RICE_K => {
            ([*kx as u32, *ky as u32], rest)
        }
        _ => return Err(corrupt("bad normals section header")),
    };
    let total_bits = bits.len() as u64 * 8;
    // Bit position; every code is at most 24 bits, so one 56-bit peek covers it.
    let mut pos = 0u64;
    let peek = |pos: u64| -> u64 {
        let at = (pos / 8) as usize;
        if let Some(w) = bits.get(at..at + 8) {
            let w: [u8; 8] = w.try_into().unwrap_or_default();
            return u64::from_le_bytes(w) >> (pos % 8);
        }
        let mut buf = [0u8; 8];
        let avail = bits.len().saturating_sub(at).min(8);
        buf[..avail].copy_from_slice(&bits[at.min(bits.len())..at.min(bits.len()) + avail]);
        u64::from_le_bytes(buf) >> (pos % 8)
    };
    let mut z = vec![0u8; 2 * n];
    for (c, zc) in z
        .chunks_exact_mut(n.max(1))
        .enumerate()
        .take(if n == 0 { 0 } else { 2 })
    {
        let k = ks[c];
        for v in zc.iter_mut() {
            let word = peek(pos);
            let q = (word.trailing_ones()).min(RICE_ESCAPE);
            if q < RICE_ESCAPE {
                *v = (((q as u64) << k) | ((word >> (q + 1)) & ((1 << k) - 1))) as u8;
                if (q as u64) << k > 255 {
                    return Err(corrupt("normal residual out of range"));
                }
                pos += (q + 1 + k) as u64;
            } else {
                *v = (word >> RICE_ESCAPE) as u8;
                pos += (RICE_ESCAPE + 8) as u64;
            }
            if pos > total_bits {
                return Err(corrupt("truncated normals section"));
            }
        }
    }
    // The stream must end in its last byte, padded with zero bits.
    if pos.div_ceil(8) != bits.len() as u64 || peek(pos) != 0 {
        return Err(corrupt("trailing bits in the normals section"));
    }
    let pred = predict_normals(positions, indices);
    Ok(pred
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let r = [unzigzag(z[i] as u32) as u8, unzigzag(z[n + i] as u32) as u8];
            oct_decode([p[0].wrapping_add(r[0]), p[1].wrapping_add(r[1])])
        })
        .collect())
}

/// Exact integer accumulator for the summed face normals: `i64` when the patch is small
/// enough for it never to overflow, `i128` otherwise. Both give the same integers.
trait Acc:
    Copy
    + Default
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + PartialEq
    + From<i64>
{
    fn to_f64(self) -> f64;
}
impl Acc for i64 {
    fn to_f64(self) -> f64 {
        self as f64
    }
}
impl Acc for i128 {
    fn to_f64(self) -> f64 {
        self as f64
    }
}

/// Octahedral code of a nonzero vector with integer components (exact in f64): L1
/// projection and fold as in [`oct_encode`], but in f64 and rounded to the nearest grid
/// point (`floor(127 v + 0.5)`), which is cheap and easy to reproduce exactly.
fn oct_predict(v: [f64; 3]) -> [u8; 2] {
    let l1 = v[0].abs() + v[1].abs() + v[2].abs();
    let (mut x, mut y) = (v[0] / l1, v[1] / l1);
    if v[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let q = |c: f64| {
        // floor by integer conversion (see `floor_ceil`); exact for these magnitudes.
        let y = c * 127.0 + 0.5;
        let t = y as i32;
        let f = if t as f64 > y { t - 1 } else { t };
        f.clamp(-127, 127) as i8 as u8
    };
    [q(x), q(y)]
}

/// Octahedral code of +Z, the prediction of a vertex whose summed face normal is zero.
const OCT_PLUS_Z: [u8; 2] = [0, 127];

/// Predicted octahedral code of every vertex: the sum of the unnormalised normals
/// `(p1 - p0) x (p2 - p0)` of the triangles using it, computed exactly in integers,
/// then quantised by [`oct_predict`] in f64; [`OCT_PLUS_Z`] for a zero sum. Bit-exact on
/// every platform (the arithmetic is spelled out in `docs/format.md`).
/// Invariant under rotating a triangle's corners (what the index codec may do).
/// `indices` must all be `< positions.len()`.
fn predict_normals(positions: &[[u32; 3]], indices: &[u32]) -> Vec<[u8; 2]> {
    let n = positions.len();
    // Extent of the patch: every coordinate difference is < 2^e in magnitude.
    let mut lo = [u32::MAX; 3];
    let mut hi = [0u32; 3];
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let extent = (0..3)
        .map(|k| hi[k].saturating_sub(lo[k]))
        .max()
        .unwrap_or(0);
    let e = 32 - extent.leading_zeros();
    let tb = 32 - ((indices.len() / 3) as u32).leading_zeros();
    // |component| < 2 * 2^(2e) per triangle, summed over fewer than 2^tb triangles.
    if 2 * e + 1 + tb <= 63 {
        predict_with::<i64>(positions, indices, n)
    } else {
        predict_with::<i128>(positions, indices, n)
    }
}

fn predict_with<T: Acc>(positions: &[[u32; 3]], indices: &[u32], n: usize) -> Vec<[u8; 2]> {
    let mut sums = vec![[T::default(); 3]; n];
    for t in indices.chunks_exact(3) {
        let p = |c: usize| positions[t[c] as usize].map(|v| v as i64);
        let (p0, p1, p2) = (p(0), p(1), p(2));
        let a: [T; 3] = std::array::from_fn(|k| T::from(p1[k] - p0[k]));
        let b: [T; 3] = std::array::from_fn(|k| T::from(p2[k] - p0[k]));
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        for &v in t {
            let s = &mut sums[v as usize];
            for k in 0..3 {
                s[k] = s[k] + c[k];
            }
        }
    }
    let zero = T::default();
    sums.iter()
        .map(|s| {
            if s[0] == zero && s[1] == zero && s[2] == zero {
                return OCT_PLUS_Z;
            }
            oct_predict(s.map(|x| x.to_f64()))
        })
        .collect()
}

/// Morph code of a vertex that stays where it is (target == own position).
const MORPH_STAYS: u32 = 0;
/// Morph code of a vertex whose target is stored explicitly (no surviving patch vertex
/// sits at the target).
const MORPH_EXPLICIT: u32 = 1;
/// Morph codes from this value on reference a surviving vertex: `code - MORPH_REF_BASE`
/// is the zigzagged difference of survivor ranks (see `docs/format.md`).
const MORPH_REF_BASE: u32 = 2;

/// The morph section: `u32` length of the code bytes, one LEB128 code per vertex, then
/// the explicit targets (zigzag `target - position`, `[u32; 3]`, vertex codec) of the
/// vertices coded [`MORPH_EXPLICIT`], absent when there are none.
///
/// Removed vertices almost always move to a surviving vertex of the same patch, usually
/// a mesh neighbour close in the vertex-fetch order, so a reference is coded as the
/// distance between survivor ranks: `rank(ref) - survivors_before(i)`.
fn encode_morph(positions: &[[u32; 3]], targets: &[[u32; 3]]) -> Vec<u8> {
    // Survivors (vertices that stay), sorted by position then rank, for lookups.
    let mut survivors: Vec<([u32; 3], u32)> = Vec::new();
    for (p, t) in positions.iter().zip(targets) {
        if p == t {
            survivors.push((*p, survivors.len() as u32));
        }
    }
    survivors.sort_unstable();
    // Where each position's run of survivors starts in `survivors` (a hash lookup per
    // moving vertex instead of two binary searches, which were most of the encoder's
    // own time).
    let mut first: rustc_hash::FxHashMap<[u32; 3], u32> =
        rustc_hash::FxHashMap::with_capacity_and_hasher(survivors.len(), Default::default());
    for (i, s) in survivors.iter().enumerate().rev() {
        first.insert(s.0, i as u32);
    }
    let mut codes = Vec::with_capacity(positions.len() + 4);
    codes.extend_from_slice(&[0; 4]);
    let mut explicit: Vec<[u32; 3]> = Vec::new();
    let mut before = 0u32; // survivors with a smaller vertex index
    for (p, t) in positions.iter().zip(targets) {
        let code = if p == t {
            before += 1;
            MORPH_STAYS
        } else {
            let lo = first.get(t).map_or(survivors.len(), |&i| i as usize);
            let hi = lo + survivors[lo..].iter().take_while(|s| s.0 == *t).count();
            // Among survivors at the target, the rank closest to this vertex.
            let best = survivors[lo..hi]
                .iter()
                .map(|s| s.1 as i64 - before as i64)
                .min_by_key(|d| (d.abs(), *d));
            match best {
                Some(d) => zigzag(d as i32) + MORPH_REF_BASE,
                None => {
                    explicit.push(std::array::from_fn(|k| {
                        zigzag(t[k].wrapping_sub(p[k]) as i32)
                    }));
                    MORPH_EXPLICIT
                }
            }
        };
        push_varint(&mut codes, code);
    }
    let code_bytes = (codes.len() - 4) as u32;
    codes[..4].copy_from_slice(&code_bytes.to_le_bytes());
    if !explicit.is_empty() {
        codes.extend_from_slice(&encode_vertices(&explicit));
    }
    codes
}

/// Decodes the morph section (see [`encode_morph`]) for `positions`.
fn decode_morph(section: &[u8], positions: &[[u32; 3]]) -> Result<Vec<[u32; 3]>, FormatError> {
    let n = positions.len();
    let code_bytes = section
        .get(..4)
        .map(|_| le_u32(section, 0) as usize)
        .ok_or_else(|| corrupt("morph section too short"))?;
    let mut rest = section
        .get(4..)
        .and_then(|s| s.get(..code_bytes))
        .ok_or_else(|| corrupt("morph codes exceed the section"))?;
    let mut codes = Vec::with_capacity(n);
    let mut survivors: Vec<u32> = Vec::with_capacity(n);
    let mut explicit_count = 0usize;
    for i in 0..n {
        let code = read_varint(&mut rest).ok_or_else(|| corrupt("truncated morph code"))?;
        match code {
            MORPH_STAYS => survivors.push(i as u32),
            MORPH_EXPLICIT => explicit_count += 1,
            _ => {}
        }
        codes.push(code);
    }
    if !rest.is_empty() {
        return Err(corrupt("trailing morph code bytes"));
    }
    let tail = &section[4 + code_bytes..];
    let explicit: Vec<[u32; 3]> = if explicit_count > 0 {
        decode_vertices(tail, explicit_count, "explicit morph targets")?
    } else if tail.is_empty() {
        Vec::new()
    } else {
        return Err(corrupt("explicit morph targets without explicit codes"));
    };
    let mut explicit = explicit.iter();
    let mut targets = Vec::with_capacity(n);
    let mut before = 0i64;
    for (p, &code) in positions.iter().zip(&codes) {
        let t = match code {
            MORPH_STAYS => {
                before += 1;
                *p
            }
            MORPH_EXPLICIT => {
                let d = explicit
                    .next()
                    .ok_or_else(|| corrupt("missing explicit target"))?;
                // Wrapping: every u32 target round-trips, however far from `p`.
                std::array::from_fn(|k| p[k].wrapping_add(unzigzag(d[k]) as u32))
            }
            _ => {
                let rank = before + unzigzag(code - MORPH_REF_BASE) as i64;
                let v = usize::try_from(rank)
                    .ok()
                    .and_then(|r| survivors.get(r))
                    .ok_or_else(|| {
                        corrupt(format!(
                            "morph reference to survivor {rank} of {}",
                            survivors.len()
                        ))
                    })?;
                positions[*v as usize]
            }
        };
        targets.push(t);
    }
    Ok(targets)
}

fn push_varint(out: &mut Vec<u8>, mut v: u32) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Reads one LEB128 `u32` (at most 5 bytes, no bits beyond 32), advancing `b`.
fn read_varint(b: &mut &[u8]) -> Option<u32> {
    let mut v = 0u32;
    for k in 0..5 {
        let (&byte, rest) = b.split_first()?;
        *b = rest;
        if k == 4 && byte > 0x0f {
            return None;
        }
        v |= ((byte & 0x7f) as u32) << (7 * k);
        if byte < 0x80 {
            return Some(v);
        }
    }
    None
}

fn encode_vertices<T>(v: &[T]) -> Vec<u8> {
    meshopt::encode_vertex_buffer_level(v, VERTEX_CODEC_LEVEL, Some(VERTEX_CODEC_VERSION))
        .expect("meshopt vertex encoder")
}

fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

fn unzigzag(v: u32) -> i32 {
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// Generous upper bound of a meshopt vertex-codec stream for `n` vertices of `size` bytes.
fn vertex_section_bound(n: u64, size: u64) -> u64 {
    2 * n * size + 4096
}

/// Generous upper bound of a meshopt index-codec stream for `t` triangles.
fn index_section_bound(t: u64) -> u64 {
    16 * t + 64
}

fn corrupt(detail: impl Into<String>) -> FormatError {
    FormatError::CorruptPatch {
        node: NO_NODE,
        detail: detail.into(),
    }
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    // Callers check `b.len() >= PATCH_HEADER_BYTES` first; fall back to 0 defensively.
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .unwrap_or(0)
}

/// Decodes a patch produced by [`encode_patch`]. `attributes` are the model's `ATTR_*`
/// bits, `quant_min`, `vertex_count` and `triangle_count` come from the node record and
/// must match the patch. Safe on arbitrary bytes: every inconsistency is a
/// [`FormatError::CorruptPatch`] (with node [`NO_NODE`]; see [`FormatError::with_node`]).
pub fn decode_patch(
    bytes: &[u8],
    attributes: u32,
    quant_min: [u32; 3],
    vertex_count: u32,
    triangle_count: u32,
) -> Result<PatchData, FormatError> {
    if bytes.len() < PATCH_HEADER_BYTES {
        return Err(corrupt(format!(
            "{} bytes, shorter than the {PATCH_HEADER_BYTES}-byte patch header",
            bytes.len()
        )));
    }
    let n = le_u32(bytes, 0);
    let t = le_u32(bytes, 4);
    let version = bytes[8];
    let flags = bytes[9];
    let attrs = bytes[10] as u32;
    let reserved = bytes[11];
    let raw_len = le_u32(bytes, 12) as u64;
    let lens: [u64; SECTION_COUNT] = std::array::from_fn(|k| le_u32(bytes, 16 + 4 * k) as u64);

    if version != PATCH_CODEC_VERSION {
        return Err(corrupt(format!("unknown patch codec version {version}")));
    }
    if flags & !(PATCH_FLAG_ZSTD | PATCH_FLAG_MORPH) != 0 || reserved != 0 {
        return Err(corrupt(format!(
            "unknown patch flags {flags:#x}/{reserved:#x}"
        )));
    }
    if attrs != attributes {
        return Err(corrupt(format!(
            "patch attributes {attrs:#x} differ from the model's {attributes:#x}"
        )));
    }
    if n != vertex_count || t != triangle_count {
        return Err(corrupt(format!(
            "patch has {n} vertices / {t} triangles, node record says {vertex_count} / {triangle_count}"
        )));
    }
    if n > MAX_PATCH_VERTICES || t > MAX_PATCH_TRIANGLES {
        return Err(corrupt(format!(
            "too many vertices ({n}) or triangles ({t})"
        )));
    }
    if n == 0 && t > 0 {
        return Err(corrupt("triangles without vertices"));
    }
    let morph = flags & PATCH_FLAG_MORPH != 0;
    let n64 = n as u64;
    let present = |on: bool, size: u64| if on && n > 0 { Some(size) } else { None };
    let expected: [Option<u64>; SECTION_COUNT] = [
        if t > 0 { Some(0) } else { None },
        present(true, 12),
        present(attributes & ATTR_NORMALS != 0, 4),
        present(attributes & ATTR_COLORS != 0, 4),
        present(attributes & ATTR_UVS != 0, 8),
        present(morph, 12),
    ];
    let mut sum = 0u64;
    for (k, (&len, exp)) in lens.iter().zip(expected).enumerate() {
        let bound = match exp {
            None => 0,
            Some(_) if k == SEC_INDICES => index_section_bound(t as u64),
            Some(_) if k == SEC_MORPH => 4 + 5 * n64 + vertex_section_bound(n64, 12),
            Some(size) => vertex_section_bound(n64, size),
        };
        if exp.is_some() && len == 0 || len > bound {
            return Err(corrupt(format!("section {k} has implausible length {len}")));
        }
        sum += len;
    }
    if sum != raw_len {
        return Err(corrupt(format!(
            "section lengths sum to {sum}, header says {raw_len}"
        )));
    }

    let stored = &bytes[PATCH_HEADER_BYTES..];
    let payload: Cow<[u8]> = if flags & PATCH_FLAG_ZSTD != 0 {
        let out =
            zstd_decompress(stored, raw_len as usize).map_err(|e| corrupt(format!("zstd: {e}")))?;
        Cow::Owned(out)
    } else {
        Cow::Borrowed(stored)
    };
    if payload.len() as u64 != raw_len {
        return Err(corrupt(format!(
            "payload is {} bytes, header says {raw_len}",
            payload.len()
        )));
    }

    // Split the payload into sections (lengths were summed and checked above).
    let mut secs: [&[u8]; SECTION_COUNT] = [&[]; SECTION_COUNT];
    let mut at = 0usize;
    for (k, &len) in lens.iter().enumerate() {
        let end = at + len as usize;
        secs[k] = payload
            .get(at..end)
            .ok_or_else(|| corrupt("section out of payload"))?;
        at = end;
    }

    let nu = n as usize;
    let mut patch = PatchData::default();
    if t > 0 {
        let indices: Vec<u32> = meshopt::decode_index_buffer(secs[SEC_INDICES], t as usize * 3)
            .map_err(|e| corrupt(format!("index codec: {e}")))?;
        if let Some(bad) = indices.iter().find(|&&i| i >= n) {
            return Err(corrupt(format!("index {bad} >= vertex count {n}")));
        }
        patch.indices = indices;
    }
    if n == 0 {
        return Ok(patch);
    }
    let rel: Vec<[u32; 3]> = decode_vertices(secs[SEC_POSITIONS], nu, "positions")?;
    let mut positions = Vec::with_capacity(nu);
    for r in &rel {
        match [
            r[0].checked_add(quant_min[0]),
            r[1].checked_add(quant_min[1]),
            r[2].checked_add(quant_min[2]),
        ] {
            [Some(x), Some(y), Some(z)] => positions.push([x, y, z]),
            _ => return Err(corrupt("position overflows the grid")),
        }
    }
    if attributes & ATTR_NORMALS != 0 {
        patch.normals = decode_normals(secs[SEC_NORMALS], &positions, &patch.indices)?;
    }
    if attributes & ATTR_COLORS != 0 {
        patch.colors = decode_vertices(secs[SEC_COLORS], nu, "colors")?;
    }
    if attributes & ATTR_UVS != 0 {
        let bits: Vec<[u32; 2]> = decode_vertices(secs[SEC_UVS], nu, "uvs")?;
        patch.uvs = bits
            .iter()
            .map(|b| [f32::from_bits(b[0]), f32::from_bits(b[1])])
            .collect();
    }
    if morph {
        patch.morph_targets = decode_morph(secs[SEC_MORPH], &positions)?;
    }
    patch.positions = positions;
    Ok(patch)
}

fn decode_vertices<T: Clone + Default>(
    section: &[u8],
    n: usize,
    what: &str,
) -> Result<Vec<T>, FormatError> {
    meshopt::decode_vertex_buffer(section, n).map_err(|e| corrupt(format!("{what} codec: {e}")))
}

/// Octahedral encoding of a unit vector into two signed-normalized bytes (`i8` in
/// -127..=127, stored as two's-complement bytes). Picks, among the four surrounding
/// grid cells, the one whose decoded direction is closest to `n`, so the angular error
/// is minimal for 8 bits. Non-finite or zero input encodes +Z.
pub fn oct_encode(n: [f32; 3]) -> [u8; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1.is_finite() && l1 > 0.0) {
        return [0, 127];
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * sign(ox);
        y = (1.0 - ox.abs()) * sign(oy);
    }
    let (fx, fy) = (x.clamp(-1.0, 1.0) * 127.0, y.clamp(-1.0, 1.0) * 127.0);
    // The candidate whose decoded direction d has the largest cosine with n, compared as
    // the sign-keeping square dot * |dot| / |d|^2: the same order as the cosine, without
    // the square roots and divisions of four full decodes.
    let mut best = [0u8; 2];
    let mut best_score = f32::NEG_INFINITY;
    for qx in floor_ceil(fx) {
        for qy in floor_ceil(fy) {
            let e = [(qx as i8) as u8, (qy as i8) as u8];
            let d = oct_unnormalised(e);
            let dot = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
            let score = dot * dot.abs() / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            if score > best_score {
                best_score = score;
                best = e;
            }
        }
    }
    best
}

/// The direction [`oct_decode`] returns for `e`, before normalisation.
fn oct_unnormalised(e: [u8; 2]) -> [f32; 3] {
    let x = ((e[0] as i8) as f32 / 127.0).max(-1.0);
    let y = ((e[1] as i8) as f32 / 127.0).max(-1.0);
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        [(1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y), z]
    } else {
        [x, y, z]
    }
}

/// Decodes [`oct_encode`]'s bytes into a unit vector. Total on all inputs.
pub fn oct_decode(e: [u8; 2]) -> [f32; 3] {
    let [x, y, z] = oct_unnormalised(e);
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

/// `[v.floor(), v.ceil()]` for `|v| <= 127` by integer conversion: `f32::floor` is a
/// libm call on baseline x86-64, and this runs for every vertex of every patch.
fn floor_ceil(v: f32) -> [f32; 2] {
    let t = v as i32 as f32; // truncates towards zero
    let f = if t > v { t - 1.0 } else { t };
    let c = if f < v { f + 1.0 } else { f };
    [f, c]
}

fn sign(v: f32) -> f32 {
    if v >= 0.0 {
        1.0
    } else {
        -1.0
    }
}
