//! Replays the fuzz corpora of the model reader (`fuzz/corpus/{model,paged_index}/`,
//! small models built with `tessera build`) and every crash the fuzzers found
//! (`fuzz/regressions/<target>/`, minimised) through the fuzz targets' own bodies
//! (`tessera_format::fuzzing`), on stable: no panic, errors as clear one-line messages,
//! and for each regression the error its fix gives. Then an adversarial corpus of
//! corrupted models: truncations, byte flips (caught by the CRCs), byte flips with the
//! CRCs recomputed, header fields and node records changed behind valid CRCs.

use bytemuck::Zeroable;
use tessera_format::fuzzing::{
    check_model, check_paged, fix_checksums, fuzz_model, fuzz_paged_index,
};
use tessera_format::{
    header_crc32, replace_index, FormatError, Header, ModelIndex, NodeRecord, NO_NODE,
};
use tessera_testkit::fuzz::{fuzz_dir, fuzz_files, read_bytes, regressions, Regression};
use tessera_testkit::Rng;

/// Each regression file (target, name) and a piece of the error its fix gives.
const REGRESSIONS: &[(&str, &str, &str)] = &[
    // A page whose node has a lower level than the one before it: the paged reader
    // showed 7 nodes after 8 pages and 6 after 16 (it shows the complete levels read).
    (
        "paged_index",
        "levels_out_of_order.tsr",
        "the table is not sorted by level",
    ),
];

fn seeds() -> Vec<(String, Vec<u8>)> {
    let v: Vec<_> = fuzz_files("corpus", "model")
        .iter()
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                read_bytes(p),
            )
        })
        .collect();
    assert!(v.len() >= 3, "fuzz/corpus/model has {} models", v.len());
    v
}

fn assert_clear(e: &FormatError) {
    let m = e.to_string();
    assert!(m.len() > 10 && !m.contains('\n'), "unclear error: {m:?}");
}

#[test]
fn seed_models_are_valid() {
    for (name, b) in seeds() {
        let r = check_model(&b).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(r.is_valid(), "{name}: {:?}", r.problems);
        let paged = check_paged(&b).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(paged.is_complete());
        assert_eq!(
            fix_checksums(&b),
            b,
            "{name}: fix_checksums changed a valid model"
        );
    }
}

#[test]
fn corpora_replay_without_panics() {
    for target in ["model", "paged_index"] {
        assert!(fuzz_files("corpus", target).len() >= 3);
        for f in fuzz_files("corpus", target)
            .iter()
            .chain(&fuzz_files("regressions", target))
        {
            let b = read_bytes(f);
            match target {
                "model" => {
                    let (raw, fixed) = fuzz_model(&b);
                    for r in std::iter::once(raw).chain(fixed) {
                        if let Err(e) = r {
                            assert_clear(&e);
                        }
                    }
                }
                _ => {
                    let (raw, fixed) = fuzz_paged_index(&b);
                    for r in std::iter::once(raw).chain(fixed) {
                        if let Err(e) = r {
                            assert_clear(&e);
                        }
                    }
                }
            }
        }
    }
}

/// The first error (raw, then checksum-fixed) or verification problem of `b`.
fn first_complaint(b: &[u8]) -> Option<String> {
    let (raw, fixed) = fuzz_model(b);
    for r in std::iter::once(raw).chain(fixed) {
        match r {
            Err(e) => return Some(e.to_string()),
            Ok(rep) if !rep.is_valid() => return Some(rep.problems.join("; ")),
            Ok(_) => {}
        }
    }
    None
}

#[test]
fn regressions_give_their_errors() {
    for target in ["model", "paged_index"] {
        for Regression { name, bytes, want } in regressions(target, REGRESSIONS) {
            let b = bytes;
            // Every complaint, on the bytes and on their checksum-fixed copy.
            let got: Vec<String> = match target {
                "model" => {
                    let (raw, fixed) = fuzz_model(&b);
                    std::iter::once(raw)
                        .chain(fixed)
                        .filter_map(|r| match r {
                            Err(e) => Some(e.to_string()),
                            Ok(rep) => (!rep.is_valid()).then(|| rep.problems.join("; ")),
                        })
                        .collect()
                }
                _ => {
                    let (raw, fixed) = fuzz_paged_index(&b);
                    std::iter::once(raw)
                        .chain(fixed)
                        .filter_map(|r| r.err().map(|e| e.to_string()))
                        .collect()
                }
            };
            assert!(
                got.iter().any(|m| m.contains(want)),
                "{target}/{name}: expected {want:?}, got {got:?}"
            );
        }
    }
}

/// A node table not sorted by level is refused by the whole read and by the paged read
/// at the page that breaks the order, before any view could show fewer nodes than the
/// pages read before it showed (fuzz/regressions/paged_index/levels_out_of_order.tsr).
#[test]
fn paged_read_refuses_levels_out_of_order() {
    let b = read_bytes(&fuzz_dir().join("corpus/model/s300p1.tsr"));
    let bad = with_node(&b, |v| {
        let i = v.len() - 1;
        v[7].level = 9;
        v[i].level = v[i].level.max(9);
    });
    let e = ModelIndex::read(&bad[..]).expect_err("unsorted levels");
    assert!(
        e.to_string()
            .contains("invalid node 8: level 1 after a node of level 9"),
        "{e}"
    );
    let top = ModelIndex::read_top(&bad[..], 1).expect("the first 8 pages are in order");
    let mut grown = top.grown(&bad[..], 8);
    assert!(grown.is_ok());
    grown = grown.unwrap().grown(&bad[..], 16);
    let e = grown.expect_err("page 8 breaks the order");
    assert!(
        e.to_string().contains("the table is not sorted by level"),
        "{e}"
    );
}

#[test]
fn truncated_and_flipped_models_are_refused() {
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let mut count = 0;
    for (name, b) in seeds() {
        // Truncated anywhere: refused on opening (the header states the file's length).
        for k in 0..40 {
            let cut = b.len() * k / 40 + rng.below(b.len() / 40);
            let e = check_model(&b[..cut.min(b.len() - 1)]).expect_err("truncated model");
            assert_clear(&e);
            assert!(check_paged(&b[..cut.min(b.len() - 1)]).is_err());
            count += 1;
        }
        // One byte changed anywhere: a CRC says so, on opening or in verification.
        for _ in 0..40 {
            let mut c = b.clone();
            let at = rng.below(c.len());
            c[at] ^= 1 + rng.below(255) as u8;
            match check_model(&c) {
                Err(e) => assert_clear(&e),
                Ok(r) => assert!(!r.is_valid(), "{name}: byte {at} changed, still valid"),
            }
            let _ = check_paged(&c);
            count += 1;
        }
    }
    eprintln!("{count} truncated or flipped models, all refused");
}

#[test]
fn models_corrupted_behind_valid_checksums_do_not_panic() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut count, mut caught) = (0, 0);
    for (_, b) in seeds() {
        for _ in 0..40 {
            let mut c = b.clone();
            for _ in 0..1 + rng.below(3) {
                let at = rng.below(c.len());
                c[at] = rng.next_u64() as u8;
            }
            let fixed = fix_checksums(&c);
            count += 1;
            match check_model(&fixed) {
                Err(e) => {
                    assert_clear(&e);
                    caught += 1;
                }
                Ok(r) if !r.is_valid() => caught += 1,
                Ok(_) => {}
            }
            let _ = check_paged(&fixed);
        }
    }
    eprintln!("{count} models with random bytes and recomputed CRCs: {caught} refused");
    assert!(caught * 2 > count);
}

fn header_of(b: &[u8]) -> Header {
    bytemuck::pod_read_unaligned(&b[..256])
}

fn with_header(b: &[u8], edit: impl FnOnce(&mut Header)) -> Vec<u8> {
    let mut h = header_of(b);
    edit(&mut h);
    h.header_crc32 = header_crc32(&h);
    let mut c = b.to_vec();
    c[..256].copy_from_slice(bytemuck::bytes_of(&h));
    c
}

fn with_node(b: &[u8], edit: impl FnOnce(&mut [NodeRecord])) -> Vec<u8> {
    let index = ModelIndex::read(b).expect("seed model");
    let mut nodes = index.nodes().to_vec();
    edit(&mut nodes);
    replace_index(b, &nodes).expect("re-encoded index")
}

type Edit = (&'static str, Box<dyn Fn(&[u8]) -> Vec<u8>>);

/// Edits that change nothing in a model of roots only.
const NEEDS_TREE: [&str; 3] = [
    "parent cut",
    "children of a root dropped",
    "tet path changed",
];

/// Corruptions a reader or `verify` must catch: header fields and node records changed
/// behind valid checksums.
fn must_catch() -> Vec<Edit> {
    let h = |name, f: fn(&mut Header)| -> Edit { (name, Box::new(move |b| with_header(b, f))) };
    let n = |name, f: fn(&mut [NodeRecord])| -> Edit { (name, Box::new(move |b| with_node(b, f))) };
    vec![
        // Diamond ids are numbered in order of first appearance (docs/format.md).
        n("diamond id 999", |v| v[1].diamond = 999),
        n("diamond id max", |v| v[2].diamond = u32::MAX),
        // The deepest node's first bisection choice flipped: it no longer extends its
        // parent's path.
        n("tet path changed", |v| {
            let i = v.len() - 1;
            v[i].tet_path ^= 1;
        }),
        h("sphere radius inf", |h| {
            h.bounding_sphere[3] = f64::INFINITY
        }),
        h("sphere radius 1e300", |h| h.bounding_sphere[3] = 1e300),
        h("sphere radius NaN", |h| h.bounding_sphere[3] = f64::NAN),
        h("sphere radius negative", |h| h.bounding_sphere[3] = -1.0),
        h("sphere centre NaN", |h| h.bounding_sphere[0] = f64::NAN),
        h("sphere centre 1e39", |h| h.bounding_sphere[1] = 1e39),
        h("cube origin 1e300", |h| h.cube_origin[2] = 1e300),
        h("cube size 0", |h| h.cube_size = 0.0),
        h("cube size NaN", |h| h.cube_size = f64::NAN),
        h("quant bits 0", |h| h.quant_bits = 0),
        h("quant bits 33", |h| h.quant_bits = 33),
        h("root count 7", |h| h.root_count = 7),
        h("unknown attribute", |h| h.attributes |= 0x80),
        h("attributes dropped", |h| h.attributes = 0),
        h("page nodes 0", |h| h.page_nodes = 0),
        h("page nodes changed", |h| {
            h.page_nodes = if h.page_nodes == 1 { 2 } else { 1 }
        }),
        h("node count + 1", |h| h.node_count += 1),
        h("node count - 1", |h| h.node_count -= 1),
        h("file bytes + 1", |h| h.file_bytes += 1),
        h("patch data offset - 1", |h| h.patch_data_offset -= 1),
        h("max error doubled", |h| {
            h.max_error = 2.0 * h.max_error + 1.0
        }),
        h("level count + 1", |h| h.level_count += 1),
        h("version 1", |h| h.version = 1),
        h("version 2", |h| h.version = 2),
        h("version 3", |h| h.version = 3),
        h("version 4", |h| h.version = 4),
        h("version 6", |h| h.version = 6),
        h("texture codec 9", |h| h.texture_codec = 9),
        h("leaf triangles max 0", |h| h.leaf_triangles_max = 0),
        // Fewer than the leaves hold.
        h("input triangles 1", |h| h.input_triangles = 1),
        h("reserved non-zero", |h| h.reserved[3] = 7),
        // The header sphere must hold every vertex (it bounds the input).
        h("sphere radius 1e-6", |h| h.bounding_sphere[3] = 1e-6),
        n("error NaN", |v| v[0].error = f32::NAN),
        n("saturated sphere inf", |v| {
            v[0].saturated_sphere[3] = f32::INFINITY
        }),
        n("tight radius negative", |v| v[2].tight_sphere[3] = -1.0),
        n("tight sphere moved away", |v| v[0].tight_sphere[0] += 1e3),
        n("child error above parent", |v| {
            let i = v.len() - 1;
            v[i].error = 1e6;
        }),
        n("parent cut", |v| {
            let i = v.len() - 1;
            v[i].parent = NO_NODE;
        }),
        n("parent of another", |v| {
            let i = v.len() - 1;
            v[i].parent = 0;
            v[i].root = v[0].root;
        }),
        n("children of a root dropped", |v| {
            v[0].children = [NO_NODE; 2]
        }),
        n("child link to itself", |v| v[0].children[0] = 0),
        n("child out of range", |v| v[0].children[1] = 1 << 30),
        n("leaf flag flipped", |v| v[0].flags ^= 1),
        n("level raised", |v| {
            let i = v.len() - 1;
            v[i].level += 1;
        }),
        n("root id 6", |v| v[0].root = 6),
        n("vertex count + 1", |v| v[0].vertex_count += 1),
        n("triangle count - 1", |v| v[1].triangle_count -= 1),
        n("patch CRC flipped", |v| v[2].patch_crc32 ^= 1),
        n("patch bytes swapped", |v| v.swap(0, 1)),
        n("quant min shifted", |v| v[0].quant_min[0] += 1 << 20),
        n("all zero record", |v| v[0] = NodeRecord::zeroed()),
        // The cone must hold the geometric normal of every triangle of the patch.
        n("normal cone garbage", |v| {
            v[0].normal_cone = [1.0, 0.0, 0.0, 0.999]
        }),
    ]
}

/// Corruptions the current checks may miss (`verify` in `tessera-build` adds the
/// diamond rules); counted and listed, never a panic. `input_triangles` can only be
/// checked from above (the leaves hold at most the input's triangles: the builder drops
/// triangles that quantisation makes degenerate), and the paged index does not store a
/// node's reserved fields (the edit changes nothing).
fn may_miss() -> Vec<Edit> {
    let h = |name, f: fn(&mut Header)| -> Edit { (name, Box::new(move |b| with_header(b, f))) };
    let n = |name, f: fn(&mut [NodeRecord])| -> Edit { (name, Box::new(move |b| with_node(b, f))) };
    vec![
        h("input triangles + 1", |h| h.input_triangles += 1),
        h("input triangles 2^62", |h| h.input_triangles = 1 << 62),
        n("reserved fields", |v| v[0].reserved = [1, 2]),
    ]
}

#[test]
fn models_corrupted_behind_valid_checksums_are_refused() {
    let mut count = 0;
    for (name, b) in seeds() {
        let tree = header_of(&b).level_count > 1;
        for (what, edit) in must_catch() {
            if !tree && NEEDS_TREE.contains(&what) {
                continue;
            }
            let c = edit(&b);
            count += 1;
            match first_complaint(&c) {
                Some(m) => assert!(m.len() > 10, "{name}, {what}: {m:?}"),
                None => panic!("{name}, {what}: accepted as valid"),
            }
            let _ = check_paged(&c);
        }
    }
    let mut missed = Vec::new();
    for (name, b) in seeds() {
        for (what, edit) in may_miss() {
            let c = edit(&b);
            count += 1;
            if first_complaint(&c).is_none() {
                missed.push(format!("{name}: {what}"));
            }
        }
    }
    eprintln!(
        "{count} models corrupted behind valid checksums; not caught by tessera-format: {}",
        if missed.is_empty() {
            "none".into()
        } else {
            missed.join(", ")
        }
    );
}
