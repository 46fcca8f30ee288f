//! Writer + reader + verifier: round trips, atomic writes, corruption detection.

mod common;

use common::model::{list, Fixture};
use common::rotate_min_first;
use proptest::prelude::*;
use tessera_format::*;

fn assert_patch_eq(got: &PatchData, want: &PatchData) {
    assert_eq!(got.positions, want.positions);
    assert_eq!(got.morph_targets, want.morph_targets);
    assert_eq!(got.colors, want.colors);
    assert_eq!(got.uvs, want.uvs);
    let oct: Vec<[f32; 3]> = want
        .normals
        .iter()
        .map(|&n| oct_decode(oct_encode(n)))
        .collect();
    assert_eq!(got.normals, oct);
    assert_eq!(
        rotate_min_first(&got.indices),
        rotate_min_first(&want.indices)
    );
}

#[test]
fn round_trip() {
    let f = Fixture::new();
    let m = Model::open(&f.path).unwrap();
    let h = m.header();
    assert_eq!(h.magic, MAGIC);
    assert_eq!(h.version, FORMAT_VERSION);
    assert_eq!(h.node_count, 4);
    assert_eq!(h.file_bytes, std::fs::metadata(&f.path).unwrap().len());
    assert_eq!(h.cube_origin, f.header.cube_origin);
    assert_eq!(h.max_error, 0.5);
    assert_eq!(m.nodes().len(), f.nodes.len());
    for (i, (got, want)) in m.nodes().iter().zip(&f.nodes).enumerate() {
        assert_eq!(got.patch_bytes, f.spooled[i].bytes);
        assert_eq!(got.patch_crc32, f.spooled[i].crc32);
        let mut g = *got;
        g.patch_offset = 0;
        g.patch_bytes = 0;
        g.patch_crc32 = 0;
        assert_eq!(&g, want, "node {i}");
        let raw = m.patch_bytes(i).unwrap();
        assert_eq!(raw, f.spool.read(&f.spooled[i]).unwrap());
        assert_patch_eq(&m.decode_patch(i).unwrap(), &f.patches[i]);
        m.advise_willneed(i);
    }
    assert!((m.grid().step() - 0.001).abs() < 1e-15);
    assert_eq!(m.grid().position([0, 1000, 5000]), [1000.0, 2001.0, 0.0]);
    let report = verify_structure(&m);
    assert!(report.is_valid(), "{:?}", report.problems);
    assert_eq!(report.checked_nodes, 4);
    // Only the model and the spool in the directory: no temp files left.
    assert_eq!(f.files_in_dir().len(), 2, "{:?}", f.files_in_dir());
    assert!(m.patch_bytes(4).is_err());
}

#[test]
fn spool_is_deleted_on_drop_and_thread_safe() {
    let dir = tempfile::tempdir().unwrap();
    let spool = PatchSpool::new(dir.path()).unwrap();
    let path = spool.path().to_path_buf();
    let results: Vec<(Vec<u8>, SpooledPatch)> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..4u8)
            .map(|t| {
                let spool = &spool;
                s.spawn(move || {
                    (0..50u8)
                        .map(|k| {
                            let bytes = vec![t ^ k; 100 + k as usize * 7];
                            let sp = spool.append(&bytes).unwrap();
                            (bytes, sp)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        hs.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    for (bytes, sp) in &results {
        assert_eq!(&spool.read(sp).unwrap(), bytes);
        assert_eq!(sp.crc32, crc32fast::hash(bytes));
    }
    assert!(path.exists());
    drop(spool);
    assert!(!path.exists());
    assert!(list(dir.path()).is_empty());
}

#[test]
fn failed_write_leaves_nothing_and_keeps_old_file() {
    let f = Fixture::new();
    let before = f.bytes();
    let files_before = f.files_in_dir();
    // A patch beyond the spool's end: the copy fails midway.
    let mut bad = f.spooled.clone();
    bad[2].offset = f.spool.len() + 10;
    let err = write_model(&f.path, &f.header, &f.nodes, &bad, &f.spool).unwrap_err();
    assert!(matches!(err, FormatError::InvalidInput { .. }), "{err}");
    assert_eq!(f.bytes(), before);
    assert_eq!(f.files_in_dir(), files_before);
    // A patch whose CRC does not match the spool bytes.
    let mut bad = f.spooled.clone();
    bad[3].crc32 ^= 1;
    let err = write_model(&f.path, &f.header, &f.nodes, &bad, &f.spool).unwrap_err();
    assert!(
        matches!(err, FormatError::PatchChecksum { node: 3 }),
        "{err}"
    );
    assert_eq!(f.bytes(), before);
    assert_eq!(f.files_in_dir(), files_before);
    // A fresh destination stays absent.
    let fresh = f.dir.path().join("fresh.tsr");
    assert!(write_model(&fresh, &f.header, &f.nodes, &bad, &f.spool).is_err());
    assert!(!fresh.exists());
    assert_eq!(f.files_in_dir(), files_before);
    // Mismatched lengths.
    assert!(write_model(&fresh, &f.header, &f.nodes[..2], &f.spooled, &f.spool).is_err());
    assert!(!fresh.exists());
}

/// Issue 14, failure 10: a Ctrl-C that arrived once the write had begun was ignored (the
/// model was completed, exit 0). A cancelled write stops, leaving nothing behind, and
/// an old file in place.
#[test]
fn cancelled_write_leaves_nothing_and_keeps_old_file() {
    let f = Fixture::new();
    let before = f.bytes();
    let files_before = f.files_in_dir();
    let err = write_model_until(&f.path, &f.header, &f.nodes, &f.spooled, &f.spool, &|| true)
        .unwrap_err();
    assert!(matches!(err, FormatError::Interrupted), "{err}");
    assert_eq!(f.bytes(), before);
    assert_eq!(f.files_in_dir(), files_before);
    // Cancelled only at the end (after every patch was copied): still nothing written.
    let calls = std::cell::Cell::new(0usize);
    let fresh = f.dir.path().join("fresh.tsr");
    let late = || {
        calls.set(calls.get() + 1);
        calls.get() > f.spooled.len().div_ceil(256)
    };
    let err =
        write_model_until(&fresh, &f.header, &f.nodes, &f.spooled, &f.spool, &late).unwrap_err();
    assert!(matches!(err, FormatError::Interrupted), "{err}");
    assert!(!fresh.exists());
    assert_eq!(f.files_in_dir(), files_before);
}

fn flip(bytes: &[u8], at: usize) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[at] ^= 0x10;
    b
}

#[test]
fn corruption_is_detected() {
    let f = Fixture::new();
    let good = f.bytes();
    let m = Model::open(&f.path).unwrap();
    let h = *m.header();

    let e = f.open_bytes("magic", &flip(&good, 1)).unwrap_err();
    assert!(matches!(e, FormatError::BadMagic), "{e}");
    let e = f.open_bytes("hdr", &flip(&good, 100)).unwrap_err();
    assert!(matches!(e, FormatError::HeaderChecksum), "{e}");
    // Every part of the paged index is checked: block table, directory, a page.
    let layout = h.index_layout();
    for (part, at) in [
        ("directory block table", layout.block_table_offset + 1),
        ("directory block 0", layout.directory_offset + 9),
        ("index page 0", layout.pages_offset + 5),
    ] {
        let e = f
            .open_bytes("index", &flip(&good, at as usize))
            .unwrap_err();
        assert!(
            matches!(&e, FormatError::IndexChecksum { part: p } if p == part),
            "{part}: {e}"
        );
    }

    // Newer version, with and without a recomputed header CRC.
    let mut b = good.clone();
    b[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let e = f.open_bytes("ver1", &b).unwrap_err();
    assert!(
        matches!(
            e,
            FormatError::UnsupportedVersion {
                found: 6,
                supported: 5
            }
        ),
        "{e}"
    );
    let mut hh = h;
    hh.version = FORMAT_VERSION + 1;
    hh.header_crc32 = header_crc32(&hh);
    b[..256].copy_from_slice(bytemuck::bytes_of(&hh));
    let e = f.open_bytes("ver2", &b).unwrap_err();
    assert!(matches!(e, FormatError::UnsupportedVersion { .. }), "{e}");
    assert!(e.to_string().contains("newer Tessera"), "{e}");

    // An older version (1: a flat node table of 128-byte records) says to rebuild.
    let mut hh = h;
    hh.version = 1;
    hh.header_crc32 = header_crc32(&hh);
    b[..256].copy_from_slice(bytemuck::bytes_of(&hh));
    let e = f.open_bytes("ver0", &b).unwrap_err();
    assert!(
        matches!(
            e,
            FormatError::OldVersion {
                found: 1,
                supported: 5
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("rebuild"), "{e}");
    // Version 3 (no header texture codec, no BC7) too.
    let mut hh = h;
    hh.version = 3;
    hh.header_crc32 = header_crc32(&hh);
    b[..256].copy_from_slice(bytemuck::bytes_of(&hh));
    let e = f.open_bytes("ver3", &b).unwrap_err();
    assert!(
        matches!(
            e,
            FormatError::OldVersion {
                found: 3,
                supported: 5
            }
        ) && e.to_string().contains("rebuild"),
        "{e}"
    );

    // Truncations.
    for cut in [0, 7, 8, 100, 255, 256, 300, good.len() - 1] {
        let e = f.open_bytes("trunc", &good[..cut]).unwrap_err();
        assert!(matches!(e, FormatError::Truncated { .. }), "cut {cut}: {e}");
    }
    let mut longer = good.clone();
    longer.push(0);
    assert!(f.open_bytes("long", &longer).is_err());

    // A flipped patch byte: open succeeds, that patch fails its CRC, others are fine.
    let n2 = m.nodes()[2];
    let at = n2.patch_offset as usize + n2.patch_bytes as usize / 2;
    let bad = f.open_bytes("patch", &flip(&good, at)).unwrap();
    assert!(matches!(
        bad.patch_bytes(2),
        Err(FormatError::PatchChecksum { node: 2 })
    ));
    assert!(matches!(
        bad.decode_patch(2),
        Err(FormatError::PatchChecksum { node: 2 })
    ));
    assert!(bad.decode_patch(1).is_ok());
    let report = verify_structure(&bad);
    assert_eq!(report.problem_count, 1, "{:?}", report.problems);

    // Child index out of range.
    let mut nodes = m.nodes().to_vec();
    nodes[0].children[1] = 77;
    let e = f
        .open_bytes("child", &with_nodes(&good, &h, &nodes))
        .unwrap_err();
    assert!(matches!(e, FormatError::InvalidNode { node: 0, .. }), "{e}");

    // Node counts that disagree with the patch: a decode error naming the node.
    let mut nodes = m.nodes().to_vec();
    nodes[3].triangle_count += 1;
    let cm = f
        .open_bytes("counts", &with_nodes(&good, &h, &nodes))
        .unwrap();
    let e = cm.decode_patch(3).unwrap_err();
    assert!(
        matches!(e, FormatError::CorruptPatch { node: 3, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("node 3"), "{e}");
}

/// Replaces the node records of a valid file (patches kept) and re-encodes its index.
fn with_nodes(good: &[u8], _h: &Header, nodes: &[NodeRecord]) -> Vec<u8> {
    replace_index(good, nodes).unwrap()
}

#[test]
fn verify_flags_structural_problems() {
    let f = Fixture::new();
    let check = |nodes: &[NodeRecord], header: Option<Header>, expect: &str| {
        let path = f.dir.path().join("v.tsr");
        let h = header.unwrap_or(f.header);
        write_model(&path, &h, nodes, &f.spooled, &f.spool).unwrap();
        let m = Model::open(&path).unwrap();
        let r = verify_structure(&m);
        assert!(!r.is_valid(), "expected a problem containing {expect:?}");
        assert!(
            r.problems.iter().any(|p| p.contains(expect)),
            "expected {expect:?} in {:?}",
            r.problems
        );
    };
    let mut n = f.nodes.clone();
    n[2].error = 0.6;
    check(&n, None, "larger than parent 0");
    let mut n = f.nodes.clone();
    n[3].saturated_sphere[3] *= 100.0;
    check(&n, None, "saturated sphere not inside parent");
    let mut n = f.nodes.clone();
    n[1].tight_sphere[3] *= 0.5;
    n[1].saturated_sphere = n[1].tight_sphere;
    check(&n, None, "outside the tight sphere");
    let mut n = f.nodes.clone();
    // An index page stores a diamond's error and sphere once, so a node moved into
    // another diamond takes that diamond's sphere, which no longer holds its patch.
    n[3].diamond = n[2].diamond;
    check(&n, None, "node 3: 7 vertices outside the tight sphere");
    let mut n = f.nodes.clone();
    n[3].flags = 0;
    check(&n, None, "leaf flag");
    let mut n = f.nodes.clone();
    n[3].root = 1;
    check(&n, None, "root 1 differs");
    let mut n = f.nodes.clone();
    n[0].children = [2, NO_NODE];
    check(&n, None, "does not list it");
    let mut n = f.nodes.clone();
    n[2].quant_min[0] += 5000; // decoded positions move with quant_min
    check(&n, None, "outside the tight sphere");
    let mut h = f.header;
    h.max_error = 0.25;
    check(&f.nodes, Some(h), "max_error");
    // A single child is fine.
    let mut n = f.nodes.clone();
    n[0].children = [NO_NODE, 3];
    n[2].parent = 1;
    n[2].root = 1;
    n[1].children = [2, NO_NODE];
    n[1].flags = 0;
    n[1].error = 0.5;
    n[1].saturated_sphere = n[0].saturated_sphere;
    n[1].saturated_sphere[3] *= 4.0;
    let path = f.dir.path().join("single.tsr");
    write_model(&path, &f.header, &n, &f.spooled, &f.spool).unwrap();
    let r = verify_structure(&Model::open(&path).unwrap());
    assert!(r.is_valid(), "{:?}", r.problems);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any truncation or single-byte change of a valid file is an error somewhere
    /// (open, patch read, or verify), never a panic.
    #[test]
    fn damaged_files_never_panic(cut in 0usize..100_000, at in 0usize..100_000, xor in 1u8..=255) {
        let f = Fixture::new();
        let good = f.bytes();
        let cut = cut % good.len();
        prop_assert!(f.open_bytes("cut", &good[..cut]).is_err());
        let mut b = good.clone();
        let at = at % good.len();
        b[at] ^= xor;
        match f.open_bytes("flip", &b) {
            Err(_) => {}
            Ok(m) => {
                let r = verify_structure(&m);
                prop_assert!(!r.is_valid(), "byte {} flip {:#x} went unnoticed", at, xor);
            }
        }
    }

    #[test]
    fn random_files_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000), magic in any::<bool>()) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.tsr");
        let mut bytes = bytes;
        if magic && bytes.len() >= 8 {
            bytes[..8].copy_from_slice(&MAGIC);
        }
        std::fs::write(&p, &bytes).unwrap();
        prop_assert!(Model::open(&p).is_err());
    }
}

/// Keeps docs/format.md's offset tables honest.
#[test]
fn documented_offsets() {
    use std::mem::offset_of;
    assert_eq!(offset_of!(Header, quant_bits), 20);
    assert_eq!(offset_of!(Header, file_bytes), 56);
    assert_eq!(offset_of!(Header, cube_origin), 80);
    assert_eq!(offset_of!(Header, bounding_sphere), 112);
    assert_eq!(offset_of!(Header, root_count), 144);
    assert_eq!(offset_of!(Header, index_offset), 32);
    assert_eq!(offset_of!(Header, block_table_crc32), 164);
    assert_eq!(offset_of!(Header, header_crc32), 168);
    assert_eq!(offset_of!(Header, page_nodes), 172);
    assert_eq!(offset_of!(Header, page_count), 176);
    assert_eq!(offset_of!(Header, texture_codec), 180);
    assert_eq!(offset_of!(Header, reserved), 184);
    assert_eq!(offset_of!(PageEntry, bytes), 8);
    assert_eq!(offset_of!(PageEntry, crc32), 12);
    assert_eq!(offset_of!(NodeRecord, patch_bytes), 16);
    assert_eq!(offset_of!(NodeRecord, children), 32);
    assert_eq!(offset_of!(NodeRecord, level), 48);
    assert_eq!(offset_of!(NodeRecord, error), 52);
    assert_eq!(offset_of!(NodeRecord, tight_sphere), 56);
    assert_eq!(offset_of!(NodeRecord, normal_cone), 88);
    assert_eq!(offset_of!(NodeRecord, quant_min), 104);
    assert_eq!(offset_of!(NodeRecord, texture_size), 116);
    assert_eq!(offset_of!(NodeRecord, reserved), 120);
}

/// Issue 14, failure 1: a header with a valid CRC but a bounding sphere that is not
/// finite or does not fit the cube (radius inf or 1e300, centre NaN or 1e39) made
/// `render` panic or draw blank frames; such a header is now refused at open.
#[test]
fn header_with_a_bad_bounding_sphere_is_refused() {
    let f = Fixture::new();
    let good = f.bytes();
    let h: Header = bytemuck::pod_read_unaligned(&good[..256]);
    let mut bad_spheres = Vec::new();
    for r in [f64::INFINITY, 1e300, f64::NAN, -1.0, 1e39] {
        bad_spheres.push([
            h.bounding_sphere[0],
            h.bounding_sphere[1],
            h.bounding_sphere[2],
            r,
        ]);
    }
    for c in [f64::NAN, 1e39, -1e39, f64::INFINITY] {
        bad_spheres.push([
            c,
            h.bounding_sphere[1],
            h.bounding_sphere[2],
            h.bounding_sphere[3],
        ]);
    }
    for sphere in bad_spheres {
        let mut hh = h;
        hh.bounding_sphere = sphere;
        hh.header_crc32 = header_crc32(&hh);
        let mut b = good.clone();
        b[..256].copy_from_slice(bytemuck::bytes_of(&hh));
        let e = f.open_bytes("sphere", &b).unwrap_err();
        assert!(e.to_string().contains("bounding sphere"), "{sphere:?}: {e}");
    }
    for origin in [1e300, -1e16] {
        let mut hh = h;
        hh.cube_origin[1] = origin;
        hh.bounding_sphere[1] = origin;
        hh.header_crc32 = header_crc32(&hh);
        let mut b = good.clone();
        b[..256].copy_from_slice(bytemuck::bytes_of(&hh));
        let e = f.open_bytes("origin", &b).unwrap_err();
        assert!(e.to_string().contains("bounding cube"), "{origin}: {e}");
    }
}
