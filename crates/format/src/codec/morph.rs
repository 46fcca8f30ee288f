//! The morph-target sub-codec: each child vertex's destination in its parent, coded as
//! a reference to a surviving vertex where there is one (byte layout in
//! `docs/format.md`, "Patch encoding").

use super::*;

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
pub(super) fn encode_morph(positions: &[[u32; 3]], targets: &[[u32; 3]]) -> Vec<u8> {
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
pub(super) fn decode_morph(
    section: &[u8],
    positions: &[[u32; 3]],
) -> Result<Vec<[u32; 3]>, FormatError> {
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
