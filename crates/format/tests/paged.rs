//! The paged index read in parts: the top first, then more pages, always a tree cut off
//! at a complete level, and in the end exactly the index read whole.

use std::borrow::Cow;
use std::cell::Cell;
use std::ops::Range;

use tessera_format::*;

/// A byte source that counts what is read.
struct Counting<'a> {
    bytes: &'a [u8],
    read: Cell<u64>,
}

impl ByteSource for Counting<'_> {
    fn len(&self) -> u64 {
        self.bytes.len() as u64
    }
    fn read(&self, range: Range<u64>) -> Result<Cow<'_, [u8]>, FormatError> {
        self.read.set(self.read.get() + (range.end - range.start));
        self.bytes.read(range)
    }
}

/// A synthetic model file of `count` nodes in a binary tree (level = floor(log2(i+1))),
/// patches of zeros (never decoded here), index pages of `page_nodes`.
fn model(count: u32, page_nodes: u32) -> (Vec<u8>, Vec<NodeRecord>) {
    let mut nodes = Vec::new();
    let mut at = 0u64;
    for i in 0..count {
        let kid = |k: u32| {
            if 2 * i + k < count {
                2 * i + k
            } else {
                NO_NODE
            }
        };
        let level = (32 - (i + 1).leading_zeros() - 1) as u8;
        let children = [kid(1), kid(2)];
        let f = i as f32;
        nodes.push(NodeRecord {
            patch_offset: at,
            tet_path: i as u64,
            patch_bytes: 48 + i % 7,
            patch_crc32: i.wrapping_mul(2654435761),
            vertex_count: 3 + i % 11,
            triangle_count: 1 + i % 13,
            children,
            parent: if i == 0 { NO_NODE } else { (i - 1) / 2 },
            diamond: i,
            level,
            root: 0,
            flags: (children == [NO_NODE, NO_NODE]) as u8,
            error: 1.0 / (1.0 + f),
            tight_sphere: [f, 0.5, -f, 1.0],
            saturated_sphere: [f, 0.5, -f, 2.0],
            normal_cone: [0.0, 0.0, 0.0, -1.0],
            quant_min: [i, 2 * i, 3 * i],
            ..NodeRecord::default()
        });
        at += nodes.last().unwrap().patch_bytes as u64;
    }
    let header = Header {
        quant_bits: 16,
        cube_size: 1.0,
        root_count: 1,
        page_nodes,
        ..bytemuck::Zeroable::zeroed()
    };
    let (h, index) = encode_index(&header, &nodes).unwrap();
    let mut bytes = bytemuck::bytes_of(&h).to_vec();
    bytes.extend_from_slice(&index);
    bytes.resize(h.file_bytes as usize, 0);
    (bytes, nodes)
}

#[test]
fn top_then_more_pages_are_complete_levels_and_end_as_the_whole_index() {
    // 9,000 nodes in pages of 2: 4,500 pages, two directory blocks.
    let (bytes, nodes) = model(9_000, 2);
    let whole = ModelIndex::read(bytes.as_slice()).unwrap();
    assert!(whole.is_complete());
    assert_eq!(whole.nodes().len(), nodes.len());
    let src = Counting {
        bytes: &bytes,
        read: Cell::new(0),
    };
    let mut ix = ModelIndex::read_top(&src, 1).unwrap();
    assert_eq!(ix.nodes().len(), 1, "the root, whose level is complete");
    let st = ix.index_stats();
    assert_eq!(src.read.get(), st.first_frame_bytes, "{st:?}");
    assert!(st.first_frame_bytes < 70_000, "{st:?}");
    let mut pages = 1;
    while !ix.is_complete() {
        pages *= 3;
        let before = src.read.get();
        ix = ix.grown(&src, pages).unwrap();
        assert!(src.read.get() > before);
        let shown = ix.nodes();
        assert_eq!(shown, &whole.nodes()[..shown.len()]);
        // A complete level: the next node, if any, starts a new level.
        let n = shown.len();
        if !ix.is_complete() {
            assert_eq!(n + 1, (n + 1).next_power_of_two(), "{n} nodes shown");
        }
    }
    assert_eq!(ix.nodes(), whole.nodes());
    assert_eq!(
        src.read.get(),
        whole.header().index_bytes(),
        "every byte read once"
    );
    assert_eq!(
        ix.patch_range(8_999).unwrap(),
        whole.patch_range(8_999).unwrap()
    );
}

#[test]
fn damage_in_a_later_page_is_found_when_that_page_is_read() {
    let (mut bytes, _) = model(600, 8);
    let h = ModelIndex::parse_header(&bytes, bytes.len() as u64).unwrap();
    let top = ModelIndex::read_top(bytes.as_slice(), 1).unwrap();
    let layout = h.index_layout();
    // Flip a byte in the last page.
    let last_page_start = bytes.len() as u64 - h.patch_data_bytes - 3;
    assert!(last_page_start > layout.pages_offset);
    bytes[last_page_start as usize] ^= 0x40;
    let top2 = ModelIndex::read_top(bytes.as_slice(), 1).unwrap();
    assert_eq!(top2.nodes(), top.nodes());
    let e = top2.grown(bytes.as_slice(), u64::MAX).unwrap_err();
    assert!(matches!(e, FormatError::IndexChecksum { .. }), "{e}");
    assert!(
        e.to_string()
            .contains(&format!("index page {}", layout.page_count - 1)),
        "{e}"
    );
    // Nodes not read yet are named as such.
    let e = top.node(500).unwrap_err();
    assert!(
        e.to_string()
            .contains("not in the part of the index read so far"),
        "{e}"
    );
}
