//! Patch codec: round trips, size measurement, robustness on garbage.

mod common;

use std::time::Instant;

use common::{quant_min, rotate_min_first, terrain_patch};
use tessera_format::*;

/// The node-record facts a patch is decoded against.
fn shape(quant_min: [u32; 3], vertex_count: u32, triangle_count: u32) -> PatchShape {
    PatchShape {
        quant_min,
        vertex_count,
        triangle_count,
        texture_size: [0, 0],
    }
}

fn section_lengths(bytes: &[u8]) -> Vec<u32> {
    (0..7)
        .map(|k| u32::from_le_bytes(bytes[16 + 4 * k..20 + 4 * k].try_into().unwrap()))
        .collect()
}

#[test]
fn bytes_per_triangle_on_terrain_patch() {
    for morph in [false, true] {
        let patch = terrain_patch(64, 20.0, morph, 7);
        let qmin = quant_min(&patch);
        let t0 = Instant::now();
        let bytes = encode_patch(&patch, ATTR_NORMALS, qmin);
        let enc = t0.elapsed();
        let tris = patch.triangle_count() as u32;
        let verts = patch.vertex_count() as u32;
        let t0 = Instant::now();
        let reps = 20;
        for _ in 0..reps {
            std::hint::black_box(
                decode_patch(&bytes, ATTR_NORMALS, shape(qmin, verts, tris)).unwrap(),
            );
        }
        let dec = t0.elapsed() / reps;
        println!(
            "terrain 64x64 morph={morph}: {verts} verts {tris} tris, {} bytes = {:.3} B/tri (flags {:#x}, raw sections idx/pos/nrm/col/uv/morph {:?}), encode {:.2} ms, decode {:.3} ms ({:.0} Mtri/s)",
            bytes.len(),
            bytes.len() as f64 / tris as f64,
            bytes[9],
            section_lengths(&bytes),
            enc.as_secs_f64() * 1e3,
            dec.as_secs_f64() * 1e3,
            tris as f64 / dec.as_secs_f64() / 1e6,
        );
        let back = decode_patch(&bytes, ATTR_NORMALS, shape(qmin, verts, tris)).unwrap();
        assert_eq!(back.positions, patch.positions);
        assert_eq!(back.morph_targets, patch.morph_targets);
    }
}

use proptest::prelude::*;

prop_compose! {
    fn arb_patch()(
        n in 0usize..60,
        attrs in 0u32..8,
        morph in any::<bool>(),
        base in [0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20],
        seed in any::<u64>(),
        tris in 0usize..120,
    ) -> (PatchData, u32, [u32; 3]) {
        let mut rng = common::Rng(seed | 1);
        let mut p = PatchData::default();
        for _ in 0..n {
            let q: [u32; 3] = std::array::from_fn(|k| base[k] + (rng.next_u64() % 5000) as u32);
            p.positions.push(q);
            if attrs & ATTR_NORMALS != 0 {
                p.normals.push(std::array::from_fn(|_| rng.unit() as f32 * 2.0 - 1.0));
            }
            if attrs & ATTR_COLORS != 0 {
                p.colors.push((rng.next_u64() as u32).to_le_bytes());
            }
            if attrs & ATTR_UVS != 0 {
                p.uvs.push([rng.unit() as f32 * 4.0 - 2.0, (rng.next_u64() % 7) as f32]);
            }
            if morph {
                let t: [u32; 3] = if rng.next_u64().is_multiple_of(2) { q } else {
                    std::array::from_fn(|k| (q[k] as i64 + rng.jitter(300)).max(0) as u32)
                };
                p.morph_targets.push(t);
            }
        }
        if n > 0 {
            for _ in 0..tris * 3 {
                p.indices.push((rng.next_u64() % n as u64) as u32);
            }
        }
        let qmin = if n == 0 { base } else { common::quant_min(&p) };
        // Sometimes a quant_min below the true minimum (allowed).
        let qmin = if seed % 3 == 0 { qmin.map(|v| v.saturating_sub(7)) } else { qmin };
        (p, attrs, qmin)
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn codec_round_trip((p, attrs, qmin) in arb_patch()) {
        let bytes = encode_patch(&p, attrs, qmin);
        let v = p.vertex_count() as u32;
        let t = p.triangle_count() as u32;
        let back = decode_patch(&bytes, attrs, shape(qmin, v, t)).unwrap();
        prop_assert_eq!(&back.positions, &p.positions);
        prop_assert_eq!(&back.colors, &p.colors);
        // UVs on their 2^-20 grid; stored UVs come back bit for bit.
        let snapped: Vec<[f32; 2]> = p.uvs.iter().map(|&uv| stored_uv(uv)).collect();
        prop_assert_eq!(&back.uvs, &snapped);
        prop_assert!(p.uvs.iter().zip(&back.uvs).all(|(a, b)| (0..2).all(|k| (a[k] - b[k]).abs() <= 1e-6)));
        let again = encode_patch(&PatchData { uvs: snapped, ..p.clone() }, attrs, qmin);
        prop_assert_eq!(decode_patch(&again, attrs, shape(qmin, v, t)).unwrap().uvs, back.uvs.clone());
        prop_assert_eq!(&back.morph_targets, &p.morph_targets);
        let oct: Vec<[f32; 3]> = p.normals.iter().map(|&n| oct_decode(oct_encode(n))).collect();
        prop_assert_eq!(&back.normals, &oct);
        prop_assert_eq!(rotate_min_first(&back.indices), rotate_min_first(&p.indices));
        // Wrong expectations are errors, not panics.
        prop_assert!(decode_patch(&bytes, attrs ^ ATTR_COLORS, shape(qmin, v, t)).is_err());
        prop_assert!(decode_patch(&bytes, attrs, shape(qmin, v + 1, t)).is_err());
        // Every truncation fails cleanly.
        for cut in [0, bytes.len() / 2, bytes.len().saturating_sub(1)] {
            if cut < bytes.len() {
                prop_assert!(decode_patch(&bytes[..cut], attrs, shape(qmin, v, t)).is_err());
            }
        }
    }

    #[test]
    fn corrupted_patches_never_panic((p, attrs, qmin) in arb_patch(), at in any::<usize>(), xor in 1u8..=255) {
        let mut bytes = encode_patch(&p, attrs, qmin);
        let at = at % bytes.len();
        bytes[at] ^= xor;
        let _ = decode_patch(&bytes, attrs, shape(qmin, p.vertex_count() as u32, p.triangle_count() as u32));
    }

    #[test]
    fn random_bytes_never_panic(
        mut bytes in proptest::collection::vec(any::<u8>(), 0..600),
        attrs in 0u32..8, v in 0u32..100, t in 0u32..100, header in any::<bool>(),
    ) {
        // Half the time, a plausible header so the section decoders see the garbage.
        if header && bytes.len() >= PATCH_HEADER_BYTES {
            let payload = (bytes.len() - PATCH_HEADER_BYTES) as u32;
            bytes[..4].copy_from_slice(&v.to_le_bytes());
            bytes[4..8].copy_from_slice(&t.to_le_bytes());
            bytes[8] = PATCH_CODEC_VERSION;
            bytes[9] &= PATCH_FLAG_ZSTD | PATCH_FLAG_MORPH;
            bytes[10] = attrs as u8;
            bytes[11] = 0;
            bytes[12..16].copy_from_slice(&payload.to_le_bytes());
            let mut lens = [0u32; 6];
            lens[0] = if t > 0 { payload / 2 } else { 0 };
            lens[1] = payload - lens[0];
            for (k, l) in lens.iter().enumerate() {
                bytes[16 + 4 * k..20 + 4 * k].copy_from_slice(&l.to_le_bytes());
            }
            bytes[9] &= !PATCH_FLAG_ZSTD;
        }
        let _ = decode_patch(&bytes, attrs, shape([5, 6, 7], v, t));
    }
}

#[test]
fn oct_normals() {
    let mut rng = common::Rng(99);
    let mut worst = 0f64;
    for _ in 0..20000 {
        let v: [f32; 3] = std::array::from_fn(|_| rng.unit() as f32 * 2.0 - 1.0);
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if l < 1e-3 {
            continue;
        }
        let u = v.map(|c| c / l);
        let d = oct_decode(oct_encode(u));
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-5);
        let dot = (u[0] * d[0] + u[1] * d[1] + u[2] * d[2]).clamp(-1.0, 1.0) as f64;
        worst = worst.max(dot.acos().to_degrees());
        // Deterministic: re-encoding a decoded normal is stable.
        assert_eq!(oct_encode(d), oct_encode(oct_decode(oct_encode(d))));
    }
    println!("oct8 worst angular error {worst:.3} degrees");
    assert!(worst < 1.5, "{worst}");
    for bad in [
        [0.0, 0.0, 0.0],
        [f32::NAN, 0.0, 1.0],
        [f32::INFINITY, 1.0, 0.0],
    ] {
        let d = oct_decode(oct_encode(bad));
        assert!(d.iter().all(|c| c.is_finite()));
    }
    for e in 0..=u16::MAX {
        let d = oct_decode(e.to_le_bytes());
        assert!(d.iter().all(|c| c.is_finite()));
    }
    assert_eq!(oct_decode(oct_encode([0.0, 0.0, 1.0])), [0.0, 0.0, 1.0]);
    assert_eq!(oct_decode(oct_encode([0.0, 0.0, -1.0])), [0.0, 0.0, -1.0]);
}

// ---- Morph targets (codec version 2: stays / survivor reference / explicit) ----

/// A small strip patch: `n` vertices on a line, triangles (i, i+1, i+2).
fn strip_patch(n: usize) -> PatchData {
    let positions: Vec<[u32; 3]> = (0..n as u32)
        .map(|i| [100 + 3 * i, 200 + (i % 7), 300 + i / 5])
        .collect();
    let indices = (0..n.saturating_sub(2) as u32)
        .flat_map(|i| [i, i + 1, i + 2])
        .collect();
    PatchData {
        positions,
        indices,
        ..PatchData::default()
    }
}

fn morph_round_trip(p: &PatchData) -> Vec<u8> {
    let qmin = quant_min(p);
    let bytes = encode_patch(p, 0, qmin);
    assert_ne!(bytes[9] & PATCH_FLAG_MORPH, 0);
    let back = decode_patch(
        &bytes,
        0,
        shape(qmin, p.vertex_count() as u32, p.triangle_count() as u32),
    )
    .unwrap();
    assert_eq!(back.positions, p.positions);
    assert_eq!(back.morph_targets, p.morph_targets);
    bytes
}

#[test]
fn morph_targets_round_trip_all_cases() {
    let n = 300;
    let base = strip_patch(n);
    let pos = base.positions.clone();
    let with = |t: Vec<[u32; 3]>| PatchData {
        morph_targets: t,
        ..base.clone()
    };
    // All stay.
    morph_round_trip(&with(pos.clone()));
    // Even vertices stay, odd ones move to a neighbour, a far survivor (multi-byte code)
    // or the first/last survivor.
    morph_round_trip(&with(
        (0..n)
            .map(|i| match (i % 2, i % 10) {
                (0, _) => pos[i],
                (_, 1) => pos[i - 1],
                (_, 3) => pos[(i + 1) % n],
                (_, 5) => pos[((i + 150) % n) & !1],
                (_, 7) => pos[0],
                _ => pos[n - 2],
            })
            .collect(),
    ));
    // All explicit: targets no vertex of the patch sits at, including grid extremes.
    let mut far = with(pos.iter().map(|p| [p[0] + 1, p[1], p[2] + 2]).collect());
    far.morph_targets[0] = [0, 0, 0];
    far.morph_targets[1] = [u32::MAX, 5, u32::MAX];
    morph_round_trip(&far);
    // A target at the position of a vertex that itself moves: stored explicitly.
    let mut chain = with(pos.clone());
    chain.morph_targets[10] = pos[11];
    chain.morph_targets[11] = pos[12];
    morph_round_trip(&chain);
    // Duplicate positions: several survivors (and a mover) at one position.
    let mut dup = base.clone();
    for i in [20, 40, 41, 250] {
        dup.positions[i] = dup.positions[30];
    }
    dup.morph_targets = dup.positions.clone();
    dup.morph_targets[41] = dup.positions[5];
    for i in [21, 39, 42, 249, 251, 299] {
        dup.morph_targets[i] = dup.positions[30];
    }
    morph_round_trip(&dup);
    // Mixed, random.
    let mut rng = common::Rng(5);
    for _ in 0..20 {
        let mut p = base.clone();
        p.morph_targets = (0..n)
            .map(|i| match rng.next_u64() % 4 {
                0 | 1 => pos[i],
                2 => pos[(rng.next_u64() % n as u64) as usize],
                _ => pos[i].map(|c| c.wrapping_add(rng.jitter(1000) as u32)),
            })
            .collect();
        morph_round_trip(&p);
    }
    // Single vertex, morph present.
    let one = PatchData {
        positions: vec![[1, 2, 3]],
        morph_targets: vec![[4, 5, 6]],
        ..PatchData::default()
    };
    morph_round_trip(&one);
}

/// Decompresses an encoded patch, lets `edit` change its sections, and reassembles it
/// uncompressed (section lengths updated).
fn rewrite_sections(bytes: &[u8], edit: impl FnOnce(&mut [Vec<u8>; 6])) -> Vec<u8> {
    let lens = section_lengths(bytes);
    let raw_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let payload = if bytes[9] & PATCH_FLAG_ZSTD != 0 {
        zstd::bulk::decompress(&bytes[PATCH_HEADER_BYTES..], raw_len).unwrap()
    } else {
        bytes[PATCH_HEADER_BYTES..].to_vec()
    };
    let mut secs: [Vec<u8>; 6] = Default::default();
    let mut at = 0;
    for k in 0..6 {
        secs[k] = payload[at..at + lens[k] as usize].to_vec();
        at += lens[k] as usize;
    }
    edit(&mut secs);
    let mut out = bytes[..PATCH_HEADER_BYTES].to_vec();
    out[9] &= !PATCH_FLAG_ZSTD;
    let raw: Vec<u8> = secs.concat();
    out[12..16].copy_from_slice(&(raw.len() as u32).to_le_bytes());
    for k in 0..6 {
        out[16 + 4 * k..20 + 4 * k].copy_from_slice(&(secs[k].len() as u32).to_le_bytes());
    }
    out.extend_from_slice(&raw);
    out
}

#[test]
fn corrupt_morph_codes_are_errors() {
    let mut p = strip_patch(40);
    p.morph_targets = p.positions.clone();
    p.morph_targets[3] = p.positions[2];
    p.morph_targets[7] = [1, 1, 1];
    let bytes = morph_round_trip(&p);
    let qmin = quant_min(&p);
    let (v, t) = (p.vertex_count() as u32, p.triangle_count() as u32);
    // The rewrite itself is faithful.
    let same = rewrite_sections(&bytes, |_| {});
    assert_eq!(
        decode_patch(&same, 0, shape(qmin, v, t)).unwrap(),
        decode_patch(&bytes, 0, shape(qmin, v, t)).unwrap()
    );
    let morph = |edit: &dyn Fn(&mut Vec<u8>)| rewrite_sections(&bytes, |s| edit(&mut s[5]));
    let code_len = |s: &Vec<u8>| u32::from_le_bytes(s[..4].try_into().unwrap()) as usize;
    let cases: Vec<(&str, Vec<u8>)> = vec![
        // Vertex 3's reference (survivor rank -1 -> code 3) pointed past the last survivor.
        ("ref past end", morph(&|s| s[4 + 3] = 2 + 2 * 50)),
        // ... and before the first survivor.
        ("ref before start", morph(&|s| s[4 + 3] = 2 + 2 * 5 + 1)),
        (
            "ref huge",
            morph(&|s| {
                s.splice(4 + 3..4 + 4, [0xff, 0xff, 0xff, 0xff, 0x0f]);
                let l = code_len(s) + 4;
                s[..4].copy_from_slice(&(l as u32).to_le_bytes());
            }),
        ),
        (
            "varint too long",
            morph(&|s| {
                s.splice(4 + 3..4 + 4, [0x80, 0x80, 0x80, 0x80, 0x80, 0x01]);
                let l = code_len(s) + 5;
                s[..4].copy_from_slice(&(l as u32).to_le_bytes());
            }),
        ),
        (
            "code length past section",
            morph(&|s| s[..4].copy_from_slice(&10_000u32.to_le_bytes())),
        ),
        (
            "codes too few",
            morph(&|s| {
                let l = code_len(s) - 1;
                s[..4].copy_from_slice(&(l as u32).to_le_bytes());
            }),
        ),
        (
            "trailing code",
            morph(&|s| {
                let l = code_len(s) + 1;
                s.insert(4 + l - 1, 0);
                s[..4].copy_from_slice(&(l as u32).to_le_bytes());
            }),
        ),
        // Vertex 7's explicit code turned into "stays": explicit stream left over.
        ("explicit without code", morph(&|s| s[4 + 7] = 0)),
        ("section too short", morph(&|s| s.truncate(2))),
    ];
    // Another vertex coded explicit: the explicit stream is too short. The vertex codec
    // may or may not notice; it must not panic.
    let _ = decode_patch(&morph(&|s| s[4 + 9] = 1), 0, shape(qmin, v, t));
    // No explicit stream at all but an explicit code.
    let mut q = p.clone();
    q.morph_targets[7] = q.positions[7];
    let no_explicit = encode_patch(&q, 0, qmin);
    let bad = rewrite_sections(&no_explicit, |s| s[5][4 + 9] = 1);
    assert!(matches!(
        decode_patch(&bad, 0, shape(qmin, v, t)),
        Err(FormatError::CorruptPatch { .. })
    ));
    for (what, bad) in cases {
        match decode_patch(&bad, 0, shape(qmin, v, t)) {
            Err(FormatError::CorruptPatch { .. }) => {}
            other => panic!("{what}: {other:?}"),
        }
    }
}

#[test]
fn morph_section_is_compact_on_terrain() {
    let with = terrain_patch(64, 20.0, true, 3);
    let without = PatchData {
        morph_targets: vec![],
        ..with.clone()
    };
    let qmin = quant_min(&with);
    let a = encode_patch(&with, ATTR_NORMALS, qmin).len();
    let b = encode_patch(&without, ATTR_NORMALS, qmin).len();
    let per_tri = (a - b) as f64 / with.triangle_count() as f64;
    println!("terrain morph section {per_tri:.3} B/tri");
    // Version 1 (zigzag deltas through the vertex codec) needed about 1.5 B/tri.
    assert!(per_tri < 0.4, "{per_tri}");
}

/// Round trip of a patch with normals; returns the encoded bytes.
fn normals_round_trip(p: &PatchData) -> Vec<u8> {
    let qmin = if p.positions.is_empty() {
        [0; 3]
    } else {
        quant_min(p)
    };
    let bytes = encode_patch(p, ATTR_NORMALS, qmin);
    let back = decode_patch(
        &bytes,
        ATTR_NORMALS,
        shape(qmin, p.vertex_count() as u32, p.triangle_count() as u32),
    )
    .unwrap();
    let oct: Vec<[f32; 3]> = p
        .normals
        .iter()
        .map(|&n| oct_decode(oct_encode(n)))
        .collect();
    // Bit for bit (NaN-free, so == on f32 is bitwise here; compare bits anyway).
    let bits = |v: &[[f32; 3]]| v.iter().map(|n| n.map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&back.normals), bits(&oct));
    assert_eq!(back.positions, p.positions);
    bytes
}

fn normals_section(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    rewrite_sections(bytes, |s| out = s[2].clone());
    out
}

#[test]
fn normals_round_trip_edge_cases() {
    let mut rng = common::Rng(5);
    let mut dirs: Vec<[f32; 3]> = vec![
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 0.0],
        [f32::NAN, 0.0, 1.0],
        [0.6, -0.8, -1e-7],
        [-0.6, 0.8, 1e-7],
    ];
    for _ in 0..40 {
        dirs.push(std::array::from_fn(|_| rng.unit() as f32 * 2.0 - 1.0));
    }
    let nd = dirs.len();
    // Vertices in no triangle (prediction +Z), with every kind of normal.
    let lonely = PatchData {
        positions: (0..nd as u32).map(|i| [i, 2 * i, 3 * i]).collect(),
        normals: dirs.clone(),
        ..PatchData::default()
    };
    normals_round_trip(&lonely);
    // Degenerate triangles: repeated corners, collinear corners, opposite faces that
    // cancel (zero sums), plus unused vertices.
    let degenerate = PatchData {
        positions: (0..nd as u32)
            .map(|i| [10 + i, 20 + 2 * i, 30 + 3 * i])
            .collect(),
        normals: dirs.clone(),
        indices: vec![0, 0, 0, 1, 1, 2, 3, 4, 5, 6, 7, 8, 6, 8, 7],
        ..PatchData::default()
    };
    normals_round_trip(&degenerate);
    // Huge coordinates over the whole u32 range: the exact sums need more than 64 bits.
    let mut big = PatchData::default();
    for &d in &dirs {
        big.positions
            .push(std::array::from_fn(|_| rng.next_u64() as u32));
        big.normals.push(d);
    }
    big.positions[0] = [0; 3];
    big.positions[1] = [u32::MAX; 3];
    for _ in 0..300 {
        big.indices
            .extend((0..3).map(|_| (rng.next_u64() % 4) as u32));
    }
    for _ in 0..300 {
        big.indices
            .extend((0..3).map(|_| (rng.next_u64() % nd as u64) as u32));
    }
    normals_round_trip(&big);
    // Every vertex in one triangle fan around vertex 0 with maximal extent.
    let fan = PatchData {
        positions: vec![
            [0, 0, 0],
            [u32::MAX, 0, 0],
            [0, u32::MAX, 0],
            [0, 0, u32::MAX],
        ],
        normals: dirs[..4].to_vec(),
        indices: vec![0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2],
        ..PatchData::default()
    };
    normals_round_trip(&fan);
}

#[test]
fn flat_patch_normals_cost_almost_nothing() {
    // A flat grid with +Z normals: the prediction is exact, every residual is 0, so the
    // section is 2 Rice-parameter bytes plus 2 bits per vertex.
    let n = 40u32;
    let mut p = PatchData::default();
    for j in 0..n {
        for i in 0..n {
            p.positions.push([100 + 7 * i, 50 + 7 * j, 1000]);
            p.normals.push([0.0, 0.0, 1.0]);
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = j * n + i;
            p.indices.extend([v, v + 1, v + n, v + 1, v + n + 1, v + n]);
        }
    }
    let bytes = normals_round_trip(&p);
    let sec = normals_section(&bytes);
    assert_eq!(sec.len(), 2 + (2 * p.vertex_count()).div_ceil(8));
    assert_eq!(&sec[..2], &[0, 0]);
    assert!(sec[2..].iter().all(|&b| b == 0));
    // Flipped winding: predicted -Z, so +Z normals cost more but still round-trip.
    let mut flipped = p.clone();
    for t in flipped.indices.chunks_exact_mut(3) {
        t.swap(1, 2);
    }
    normals_round_trip(&flipped);
}

#[test]
fn smooth_normals_predict_well() {
    // Terrain with normals computed like the builder does (area-weighted sums of face
    // normals, in f32): most residuals are 0 or +-1, far below the 16 bits of raw codes.
    let mut p = terrain_patch(64, 20.0, false, 3);
    let mut sums = vec![[0f32; 3]; p.vertex_count()];
    for t in p.indices.chunks_exact(3) {
        let q = |c: usize| p.positions[t[c] as usize].map(|v| v as f32);
        let (a, b, c) = (q(0), q(1), q(2));
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let f = [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ];
        for &v in t {
            for k in 0..3 {
                sums[v as usize][k] += f[k];
            }
        }
    }
    p.normals = sums;
    let bytes = normals_round_trip(&p);
    let sec = normals_section(&bytes);
    let bits_per_vertex = (sec.len() * 8) as f64 / p.vertex_count() as f64;
    println!("terrain normals: {bits_per_vertex:.2} bits per vertex");
    assert!(bits_per_vertex < 4.5, "{bits_per_vertex} bits per vertex");
}

#[test]
fn corrupt_normal_sections_are_errors() {
    let mut p = strip_patch(30);
    p.normals = (0..p.vertex_count())
        .map(|i| [(i as f32).sin(), (i as f32).cos(), 0.3])
        .collect();
    let qmin = quant_min(&p);
    let bytes = encode_patch(&p, ATTR_NORMALS, qmin);
    let (v, t) = (p.vertex_count() as u32, p.triangle_count() as u32);
    let decode = |b: &[u8]| decode_patch(b, ATTR_NORMALS, shape(qmin, v, t));
    let ok = rewrite_sections(&bytes, |_| {});
    assert!(decode(&ok).is_ok());
    type Edit = Box<dyn Fn(&mut Vec<u8>)>;
    let edits: Vec<(&str, Edit)> = vec![
        ("empty", Box::new(|s| s.clear())),
        ("only the parameters", Box::new(|s| s.truncate(2))),
        ("rice parameter 8", Box::new(|s| s[0] = 8)),
        ("rice parameter 255", Box::new(|s| s[1] = 255)),
        (
            "truncated",
            Box::new(|s| {
                s.pop();
            }),
        ),
        ("extra byte", Box::new(|s| s.push(0))),
        (
            "padding bits set",
            Box::new(|s| {
                let last = s.len() - 1;
                s[last] |= 0x80;
            }),
        ),
        // k = 7 and quotient 2: value 256 does not fit a byte.
        (
            "residual out of range",
            Box::new(|s| {
                s[0] = 7;
                s[2] = 0b011;
            }),
        ),
        ("all ones", Box::new(|s| s[2..].fill(0xff))),
    ];
    for (what, edit) in edits {
        let bad = rewrite_sections(&bytes, |s| edit(&mut s[2]));
        match decode(&bad) {
            Err(FormatError::CorruptPatch { .. }) => {}
            other => panic!("{what}: {other:?}"),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, ..ProptestConfig::default() })]

    /// Random meshes over the whole grid (both the 64-bit and the 128-bit prediction
    /// paths) round-trip their normals exactly, and mangled normal sections never panic.
    #[test]
    fn normals_round_trip_random_meshes(
        n in 1usize..80,
        tris in 0usize..200,
        shift in 0u32..32,
        seed in any::<u64>(),
        at in any::<usize>(),
        xor in 1u8..=255,
    ) {
        let mut rng = common::Rng(seed | 1);
        let mut p = PatchData::default();
        for _ in 0..n {
            p.positions.push(std::array::from_fn(|_| (rng.next_u64() as u32) >> shift));
            p.normals.push(std::array::from_fn(|_| rng.unit() as f32 * 2.0 - 1.0));
        }
        for _ in 0..3 * tris {
            p.indices.push((rng.next_u64() % n as u64) as u32);
        }
        let bytes = normals_round_trip(&p);
        let qmin = quant_min(&p);
        let mangled = rewrite_sections(&bytes, |s| {
            let k = at % s[2].len();
            s[2][k] ^= xor;
        });
        let _ = decode_patch(&mangled, ATTR_NORMALS, shape(qmin, n as u32, tris as u32));
    }
}

/// What a textured patch is stored with: normals, UVs and its texture.
const TEXTURED: u32 = ATTR_NORMALS | ATTR_UVS | ATTR_TEXTURE;

/// A textured patch: a strip of 30 vertices (normals up) that sample two charts of a
/// 24x16 texture.
fn textured_patch(codec: TextureCodec) -> PatchData {
    let mut p = strip_patch(30);
    p.normals = vec![[0.0, 0.0, 1.0]; 30];
    p.uvs = (0..30).map(|i| [i as f32 / 29.0, (i % 2) as f32]).collect();
    p.charts = vec![
        TextureChart {
            image: 0,
            scale: [0.5, -1.0],
            offset: [0.0, 1.0],
        },
        TextureChart {
            image: u32::MAX,
            scale: [0.0, 0.0],
            offset: [0.75, 0.5],
        },
    ];
    p.chart_ids = (0..30).map(|i| (i >= 20) as u16).collect();
    let rgba: Vec<u8> = (0..24 * 16)
        .flat_map(|i| [(i * 7) as u8, (i / 24 * 16) as u8, 200, 255])
        .collect();
    p.texture = Some(PatchTexture::encode(24, 16, &rgba, codec, 95).unwrap());
    p
}

/// A [`textured_patch`] (its texture as given) encoded with [`TEXTURED`], and the
/// node-record shape it decodes against.
fn encode_textured(p: &PatchData) -> (Vec<u8>, PatchShape) {
    let qmin = quant_min(p);
    let bytes = encode_patch(p, TEXTURED, qmin);
    let sh = PatchShape {
        texture_size: [24, 16],
        ..shape(qmin, 30, p.triangle_count() as u32)
    };
    (bytes, sh)
}

#[test]
fn textured_patches_round_trip_and_damage_is_an_error() {
    let attrs = TEXTURED;
    for codec in [TextureCodec::Png, TextureCodec::Jpeg] {
        let p = textured_patch(codec);
        let (bytes, sh) = encode_textured(&p);
        let back = decode_patch(&bytes, attrs, sh).unwrap();
        assert_eq!(back.charts, p.charts);
        assert_eq!(back.chart_ids, p.chart_ids);
        // UVs are stored in the patch texture's space, on a grid of 1/8 texel: each lands
        // within 1/16 texel of where it did (solid-colour charts keep no UV: 0).
        for (v, (a, b)) in back.uvs.iter().zip(&p.uvs).enumerate() {
            let c = p.charts[p.chart_ids[v] as usize];
            if c.scale == [0.0, 0.0] {
                assert_eq!(*a, [0.0, 0.0]);
                continue;
            }
            let (ma, mb) = (c.map(*a), c.map(*b));
            let err = [(ma[0] - mb[0]).abs() * 24.0, (ma[1] - mb[1]).abs() * 16.0];
            assert!(
                err[0] <= 1.0 / 16.0 + 1e-4 && err[1] <= 1.0 / 16.0 + 1e-4,
                "vertex {v}: {err:?} texels"
            );
        }
        let t = back.texture.as_ref().unwrap();
        assert_eq!((t.width, t.height, t.codec), (24, 16, Some(codec)));
        let mut want = p.texture.clone().unwrap();
        want.decode_rgba().unwrap();
        assert_eq!(t.rgba, want.rgba);
        if codec == TextureCodec::Png {
            // Lossless: the texels that went in.
            assert_eq!(t.rgba[4 * 25..4 * 26], [(25 * 7) as u8, 16, 200, 255]);
        }
        // Geometry-only decoding keeps the texture encoded.
        let geo = decode_patch_with(&bytes, attrs, sh, false).unwrap();
        assert!(geo.texture.as_ref().unwrap().rgba.is_empty());
        // The node record's size must match.
        let wrong = PatchShape {
            texture_size: [24, 17],
            ..sh
        };
        assert!(decode_patch(&bytes, attrs, wrong).is_err());
        // A patch of a textured model without a texture block, and damaged blocks.
        assert!(decode_patch(&bytes, attrs & !ATTR_TEXTURE, sh).is_err());
        let tex_at = bytes.len() - p.texture.as_ref().unwrap().encoded.len() - 12;
        let mut bad_codec = bytes.clone();
        bad_codec[tex_at] = 9;
        assert!(decode_patch(&bad_codec, attrs, sh).is_err());
        let mut bad_image = bytes.clone();
        for b in &mut bad_image[tex_at + 12..] {
            *b = 0x5A;
        }
        assert!(decode_patch(&bad_image, attrs, sh).is_err());
        assert!(decode_patch_with(&bad_image, attrs, sh, false).is_ok());
        for cut in [1, 12, bytes.len() - tex_at] {
            assert!(decode_patch(&bytes[..bytes.len() - cut], attrs, sh).is_err());
        }
    }
}

/// BC7 blocks of a whole 24x16 chain (every level, level 0 first), deterministic bytes
/// (any 16 bytes are a block a decoder takes: the test is of the container, not of the
/// encoder, which is the builder's).
fn bc7_levels(w: u32, h: u32) -> Vec<Vec<u8>> {
    (0..texels::mip_level_count(w, h))
        .map(|l| {
            let (lw, lh) = texels::level_size(w, h, l);
            (0..texels::bc7_level_bytes(lw, lh))
                .map(|i| (i * 37 + l as usize * 11) as u8 | 0x40)
                .collect()
        })
        .collect()
}

#[test]
fn bc7_patch_textures_round_trip_as_blocks_and_decode_to_texels() {
    let attrs = TEXTURED;
    let mut p = textured_patch(TextureCodec::Png);
    let levels = bc7_levels(24, 16);
    p.texture = Some(PatchTexture::from_bc7(24, 16, levels.clone()).unwrap());
    let (bytes, sh) = encode_textured(&p);
    // Decoding keeps the blocks as stored: what the GPU takes.
    let back = decode_patch(&bytes, attrs, sh).unwrap();
    let t = back.texture.clone().unwrap();
    assert_eq!(t.codec, Some(TextureCodec::Bc7));
    assert_eq!(t.blocks, levels);
    assert!(t.rgba.is_empty() && t.encoded.is_empty());
    // Texels for readers without BC7: level 0 and the stored levels below it.
    let mut d = t.clone();
    d.decode_rgba().unwrap();
    assert_eq!(d.rgba, texels::bc7_to_rgba(&levels[0], 24, 16));
    assert_eq!(d.mips.len(), levels.len() - 1);
    assert_eq!(d.mips[0], texels::bc7_to_rgba(&levels[1], 12, 8));
    assert_eq!(d.mips.last().unwrap().len(), 4);
    // Sizes that are not whole blocks, and chains that are not whole, are refused.
    assert!(PatchTexture::from_bc7(22, 16, bc7_levels(22, 16)).is_err());
    assert!(PatchTexture::from_bc7(24, 16, levels[..3].to_vec()).is_err());
    // Damage: a zstd frame of the wrong length, or not zstd at all.
    let tex_at = bytes.len() - p.texture.as_ref().unwrap().encoded.len();
    let mut bad = bytes.clone();
    for b in &mut bad[tex_at..] {
        *b = 0x5A;
    }
    let e = decode_patch(&bad, attrs, sh).unwrap_err();
    assert!(e.to_string().contains("zstd"), "{e}");
    let short = PatchTexture::from_bc7(24, 16, levels.clone()).unwrap();
    let mut t = PatchTexture {
        encoded: zstd::bulk::compress(&levels.concat()[16..], 3).unwrap(),
        blocks: Vec::new(),
        ..short
    };
    let e = t.decode_blocks().unwrap_err();
    assert!(
        e.to_string().contains("BC7") || e.to_string().contains("zstd"),
        "{e}"
    );
}
