//! Patch codec: round trips, size measurement, robustness on garbage.

mod common;

use std::time::Instant;

use common::{quant_min, terrain_patch};
use tessera_format::*;

fn section_lengths(bytes: &[u8]) -> Vec<u32> {
    (0..6)
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
            std::hint::black_box(decode_patch(&bytes, ATTR_NORMALS, qmin, verts, tris).unwrap());
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
        let back = decode_patch(&bytes, ATTR_NORMALS, qmin, verts, tris).unwrap();
        assert_eq!(back.positions, patch.positions);
        assert_eq!(back.morph_targets, patch.morph_targets);
    }
}

use proptest::prelude::*;

fn rotate_min_first(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks(3)
        .map(|t| {
            // Lexicographically smallest rotation: canonical even for degenerate triangles.
            (0..3)
                .map(|m| [t[m], t[(m + 1) % 3], t[(m + 2) % 3]])
                .min()
                .unwrap()
        })
        .collect()
}

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
        let back = decode_patch(&bytes, attrs, qmin, v, t).unwrap();
        prop_assert_eq!(&back.positions, &p.positions);
        prop_assert_eq!(&back.colors, &p.colors);
        prop_assert_eq!(&back.uvs, &p.uvs);
        prop_assert_eq!(&back.morph_targets, &p.morph_targets);
        let oct: Vec<[f32; 3]> = p.normals.iter().map(|&n| oct_decode(oct_encode(n))).collect();
        prop_assert_eq!(&back.normals, &oct);
        prop_assert_eq!(rotate_min_first(&back.indices), rotate_min_first(&p.indices));
        // Wrong expectations are errors, not panics.
        prop_assert!(decode_patch(&bytes, attrs ^ ATTR_COLORS, qmin, v, t).is_err());
        prop_assert!(decode_patch(&bytes, attrs, qmin, v + 1, t).is_err());
        // Every truncation fails cleanly.
        for cut in [0, bytes.len() / 2, bytes.len().saturating_sub(1)] {
            if cut < bytes.len() {
                prop_assert!(decode_patch(&bytes[..cut], attrs, qmin, v, t).is_err());
            }
        }
    }

    #[test]
    fn corrupted_patches_never_panic((p, attrs, qmin) in arb_patch(), at in any::<usize>(), xor in 1u8..=255) {
        let mut bytes = encode_patch(&p, attrs, qmin);
        let at = at % bytes.len();
        bytes[at] ^= xor;
        let _ = decode_patch(&bytes, attrs, qmin, p.vertex_count() as u32, p.triangle_count() as u32);
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
        let _ = decode_patch(&bytes, attrs, [5, 6, 7], v, t);
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
