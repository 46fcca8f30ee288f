//! The normals sub-codec: octahedral codes predicted from the patch geometry, residuals
//! Rice-coded (byte layout in `docs/format.md`, "Patch encoding").

use super::*;

/// Rice parameters are `0..=MAX_RICE_K`.
const MAX_RICE_K: u32 = 7;
/// A Rice quotient of this many or more is escaped: this many 1 bits, then the value's
/// 8 bits.
const RICE_ESCAPE: u32 = 16;

/// The normals section (see `docs/format.md`): per vertex, the octahedral code minus the
/// code predicted from the patch geometry ([`predict_normals`]), wrapping in `u8`,
/// zigzagged and Rice-coded, all x residuals first, then all y residuals, each stream
/// with its own Rice parameter.
pub(super) fn encode_normals(patch: &PatchData) -> Vec<u8> {
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
pub(super) fn decode_normals(
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
