//! Entry points of the fuzz targets (`fuzz/fuzz_targets/{model,paged_index}.rs`) and of
//! their replay as ordinary tests (`tests/corpus.rs`): one function per target, so the
//! two cannot drift apart.
//!
//! Compiled always rather than behind a feature: the module has no dependency of its
//! own and costs a few dozen lines, while a feature that only the tests and the fuzz
//! crate turn on would be one more configuration to build (and to forget) in CI, and
//! would be unified into every build of the workspace anyway. It is hidden from the
//! docs and is not an API.
//!
//! The bytes are the model file, read through the in-memory [`ByteSource`] of `[u8]`
//! (the same reader the memory map and HTTP sources feed). Every CRC of a model makes
//! a mutated input fail at the first check, so each target runs twice: on the bytes as
//! they are, and on a copy whose header, block table, directory and page checksums are
//! recomputed ([`fix_checksums`]), so the fuzzer's mutations reach the checks behind
//! them. Patch bytes are decoded both through the CRC check and, when that fails,
//! straight through the codec, so mutated patch data reaches the decoder too.
//! Errors are the expected outcome and are returned; a broken promise (a decoded patch
//! of the wrong shape, a paged read that disagrees with the whole read, ...) panics,
//! which the fuzzer reports as a crash.

use crate::codec::{decode_patch, PatchData};
use crate::error::FormatError;
use crate::index::{ByteSource, ModelIndex, HEADER_BYTES};
use crate::pages::{IndexLayout, PageEntry, MAX_PAGE_NODES, PAGE_ENTRY_BYTES};
use crate::records::{header_crc32, Header, ATTR_COLORS, ATTR_NORMALS, ATTR_UVS, NO_NODE};
use crate::verify::{verify_index, VerifyReport};

/// `data` with every checksum of the header and the paged index recomputed where the
/// header's counts let the parts be found inside `data` (patch CRCs, which live inside
/// the compressed pages, are left alone). Bytes it cannot place are left as they are.
pub fn fix_checksums(data: &[u8]) -> Vec<u8> {
    let mut b = data.to_vec();
    let Some(head) = b.get(..HEADER_BYTES as usize) else {
        return b;
    };
    let mut h: Header = bytemuck::pod_read_unaligned(head);
    if (1..=MAX_PAGE_NODES).contains(&h.page_nodes) && h.node_count < NO_NODE as u64 {
        let layout = IndexLayout::new(h.node_count, h.page_nodes, HEADER_BYTES);
        // Pages: each directory entry's CRC from the frame it points at.
        for p in 0..layout.page_count {
            let at = layout.directory_offset + p * PAGE_ENTRY_BYTES;
            let Some(raw) = slice(&b, at, PAGE_ENTRY_BYTES) else {
                break;
            };
            let mut e: PageEntry = bytemuck::pod_read_unaligned(raw);
            if let Some(frame) = slice(&b, e.offset, e.bytes as u64) {
                e.crc32 = crc32fast::hash(frame);
                put(&mut b, at, bytemuck::bytes_of(&e));
            }
        }
        // Directory blocks: their CRCs in the block table.
        for k in 0..layout.block_count {
            let r = layout.block_range(k);
            let Some(block) = slice(&b, r.start, r.end - r.start) else {
                break;
            };
            let crc = crc32fast::hash(block);
            put(
                &mut b,
                layout.block_table_offset + 4 * k,
                &crc.to_le_bytes(),
            );
        }
        let r = layout.block_table_range();
        if let Some(table) = slice(&b, r.start, r.end - r.start) {
            h.block_table_crc32 = crc32fast::hash(table);
        }
    }
    h.header_crc32 = header_crc32(&h);
    put(&mut b, 0, bytemuck::bytes_of(&h));
    b
}

fn slice(b: &[u8], at: u64, n: u64) -> Option<&[u8]> {
    let end = at.checked_add(n)?;
    b.get(usize::try_from(at).ok()?..usize::try_from(end).ok()?)
}

fn put(b: &mut [u8], at: u64, bytes: &[u8]) {
    let at = at as usize;
    if let Some(dst) = b.get_mut(at..at + bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}

/// What a decoded patch promises: counts as its node says, indices in range, one value
/// of each attribute the model has per vertex, finite unit normals.
fn check_decoded(index: &ModelIndex, i: usize, p: &PatchData) {
    let n = &index.nodes()[i];
    let attrs = index.header().attributes;
    let nv = p.positions.len();
    assert_eq!(nv, n.vertex_count as usize, "node {i}: vertex count");
    assert_eq!(p.indices.len(), 3 * n.triangle_count as usize, "node {i}");
    assert!(p.indices.iter().all(|&k| (k as usize) < nv), "node {i}");
    let per_vertex = |bit: u32| if attrs & bit != 0 { nv } else { 0 };
    assert_eq!(
        p.normals.len(),
        per_vertex(ATTR_NORMALS),
        "node {i}: normals"
    );
    assert_eq!(p.colors.len(), per_vertex(ATTR_COLORS), "node {i}: colours");
    assert_eq!(p.uvs.len(), per_vertex(ATTR_UVS), "node {i}: uvs");
    assert!(
        p.morph_targets.is_empty() || p.morph_targets.len() == nv,
        "node {i}: {} morph targets for {nv} vertices",
        p.morph_targets.len()
    );
    for nrm in &p.normals {
        let l = nrm.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!(
            (l - 1.0).abs() < 1e-3,
            "node {i}: normal {nrm:?} is not unit"
        );
    }
}

fn check_report(r: &VerifyReport) {
    assert!(r.problem_count >= r.problems.len());
    for m in &r.problems {
        assert!(!m.trim().is_empty() && !m.contains('\n'), "problem {m:?}");
    }
}

fn check_error(e: &FormatError) {
    let m = e.to_string();
    assert!(!m.trim().is_empty() && !m.contains('\n'), "error {m:?}");
}

/// Opens the model in `data`, decodes every patch and verifies it: the `model` target
/// on one byte string. Returns the verification report of a model that opens.
pub fn check_model(data: &[u8]) -> Result<VerifyReport, FormatError> {
    let index = ModelIndex::read(data).inspect_err(check_error)?;
    let h = *index.header();
    assert!(index.is_complete());
    assert_eq!(index.nodes().len() as u64, h.node_count);
    for i in 0..index.nodes().len() {
        let range = index.patch_range(i).expect("a node of the index");
        let bytes = data
            .read(range)
            .expect("patch ranges are checked on opening");
        match index.decode_patch(i, &bytes) {
            Ok(p) => check_decoded(&index, i, &p),
            Err(FormatError::PatchChecksum { .. }) => {
                // The decoder on bytes its CRC does not vouch for.
                match decode_patch(&bytes, h.attributes, (&index.nodes()[i]).into()) {
                    Ok(p) => check_decoded(&index, i, &p),
                    Err(e) => check_error(&e),
                }
            }
            Err(e) => check_error(&e),
        }
    }
    assert!(index.node(index.nodes().len()).is_err());
    let _ = index.grid().position([0, 0, 0]);
    let report = verify_index(&index, data);
    check_report(&report);
    Ok(report)
}

/// Reads the model's index page by page (`read_top` with one page, then `grown`
/// doubling the pages) and checks it against the whole read: the `paged_index` target
/// on one byte string. Returns the complete index.
pub fn check_paged(data: &[u8]) -> Result<ModelIndex, FormatError> {
    let whole = ModelIndex::read(data);
    let agree = |e: FormatError| {
        check_error(&e);
        if let Ok(w) = &whole {
            panic!(
                "the paged read fails ({e}) where the whole read accepts {} nodes",
                w.nodes().len()
            );
        }
        e
    };
    let mut index = ModelIndex::read_top(data, 1).map_err(agree)?;
    loop {
        let h = index.header();
        let shown = index.nodes();
        assert!(shown.len() as u64 <= h.node_count);
        assert!(
            index.is_complete() || shown.len() >= h.root_count as usize,
            "read_top shows {} nodes, fewer than the {} roots",
            shown.len(),
            h.root_count
        );
        for i in 0..shown.len() {
            index.patch_range(i).expect("a shown node");
        }
        assert!(index.node(shown.len()).is_err());
        if index.is_complete() {
            break;
        }
        let pages = index.loaded_pages();
        let next = index.grown(data, 2 * pages).map_err(agree)?;
        assert!(next.loaded_pages() > pages, "grown read no page");
        assert!(
            bytes(next.nodes()).starts_with(bytes(index.nodes())),
            "growing the index changed or hid nodes it showed"
        );
        index = next;
    }
    match whole {
        Ok(w) => assert!(
            bytes(w.nodes()) == bytes(index.nodes()),
            "paged and whole reads differ"
        ),
        Err(e) => panic!("the whole read fails ({e}) where the paged read accepts every page"),
    }
    Ok(index)
}

/// Records as bytes (NaN fields compare equal to themselves).
fn bytes(nodes: &[crate::NodeRecord]) -> &[u8] {
    bytemuck::cast_slice(nodes)
}

/// `check` on `data` and, when recomputing its checksums changes it, on that copy too.
/// Returns both results (the second `None` when the checksums were right).
fn twice<T>(
    data: &[u8],
    check: impl Fn(&[u8]) -> Result<T, FormatError>,
) -> (Result<T, FormatError>, Option<Result<T, FormatError>>) {
    let raw = check(data);
    let fixed = fix_checksums(data);
    let again = (fixed != data).then(|| check(&fixed));
    (raw, again)
}

/// The `model` target: [`check_model`] on the bytes and on their checksum-fixed copy.
pub fn fuzz_model(
    data: &[u8],
) -> (
    Result<VerifyReport, FormatError>,
    Option<Result<VerifyReport, FormatError>>,
) {
    twice(data, check_model)
}

/// The `paged_index` target: [`check_paged`] on the bytes and on their checksum-fixed
/// copy.
pub fn fuzz_paged_index(
    data: &[u8],
) -> (
    Result<ModelIndex, FormatError>,
    Option<Result<ModelIndex, FormatError>>,
) {
    twice(data, check_paged)
}
