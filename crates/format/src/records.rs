//! On-disk records. Both are `#[repr(C)]` + `Pod` so they are read and written as bytes;
//! every field is little-endian (the only byte order Tessera targets; the reader checks
//! the magic, so a big-endian host fails loudly rather than misreading).

use bytemuck::{Pod, Zeroable};

/// First 8 bytes of every model file.
pub const MAGIC: [u8; 8] = *b"TESSERA\0";
/// The version this code writes. Readers refuse files with a newer version.
pub const FORMAT_VERSION: u32 = 5;
/// `Header::attributes` bit: patches carry per-vertex normals.
pub const ATTR_NORMALS: u32 = 1;
/// `Header::attributes` bit: patches carry per-vertex RGBA8 colours.
pub const ATTR_COLORS: u32 = 2;
/// `Header::attributes` bit: patches carry per-vertex texture coordinates.
pub const ATTR_UVS: u32 = 4;
/// `Header::attributes` bit: every patch carries a texture of its own (cut from the
/// source images at the resolution its error needs), with the charts that map the
/// vertices' source UVs into it (see `PatchData::charts`). Requires [`ATTR_UVS`].
pub const ATTR_TEXTURE: u32 = 8;
/// Largest width or height of a patch texture: the builder never writes larger ones
/// (WebGL2 and wgpu's downlevel limits guarantee 4096 on every device Tessera targets;
/// Nexus issue #72 is textures beyond the GPU's limit).
pub const MAX_TEXTURE_DIM: u32 = 4096;
/// A missing node index (no parent, no child).
pub const NO_NODE: u32 = u32::MAX;
/// `NodeRecord::flags` bit: the node is a leaf of the partition (full-resolution triangles).
pub const NODE_FLAG_LEAF: u8 = 1;

/// The file header, at offset 0. 256 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Header {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`FORMAT_VERSION`] of the writer.
    pub version: u32,
    /// `size_of::<Header>()` (256); lets a reader skip fields it does not know.
    pub header_bytes: u32,
    /// `ATTR_*` bits: which per-vertex attributes every patch carries.
    pub attributes: u32,
    /// Positions are integers on a grid of `2^quant_bits` cells along each edge of the
    /// bounding cube.
    pub quant_bits: u32,
    /// Number of node records.
    pub node_count: u64,
    /// Byte offset of the paged index (256): block table, directory, pages.
    pub index_offset: u64,
    /// Byte offset of the first patch.
    pub patch_data_offset: u64,
    /// Total bytes of patch data.
    pub patch_data_bytes: u64,
    /// Size of the whole file; a truncated file is detected by comparing with this.
    pub file_bytes: u64,
    /// Vertices in the input mesh.
    pub input_vertices: u64,
    /// Triangles in the input mesh (after skipping degenerate ones).
    pub input_triangles: u64,
    /// Model-space minimum corner of the bounding cube. All node geometry (spheres, cones)
    /// is stored relative to this point, in model units, so `f32` keeps precision even for
    /// georeferenced models far from the origin.
    pub cube_origin: [f64; 3],
    /// Edge length of the bounding cube, model units.
    pub cube_size: f64,
    /// Bounding sphere of the model, model space: centre xyz, radius.
    pub bounding_sphere: [f64; 4],
    /// Number of root nodes (the first `root_count` records; at most 6).
    pub root_count: u32,
    /// Number of levels (deepest node level + 1).
    pub level_count: u32,
    /// Largest saturated error of any node (model units).
    pub max_error: f32,
    /// Builder setting: maximum triangles per leaf.
    pub leaf_triangles_max: u32,
    /// Builder setting: target triangles per internal node.
    pub node_triangles_target: u32,
    /// CRC-32 of the directory's block table.
    pub block_table_crc32: u32,
    /// CRC-32 of the header bytes with this field set to zero.
    pub header_crc32: u32,
    /// Nodes per index page (the last page may hold fewer).
    pub page_nodes: u32,
    /// Number of index pages: `node_count` / `page_nodes`, rounded up.
    pub page_count: u32,
    /// The codec of every patch texture (`TextureCodec` as a number: 1 PNG, 2 JPEG,
    /// 3 BC7) in models with [`ATTR_TEXTURE`], 0 otherwise: readers know a texture's
    /// GPU bytes before they read it (since version 4).
    pub texture_codec: u32,
    /// Zero.
    pub reserved: [u32; 18],
}

impl Header {
    /// The codec of the model's patch textures ([`Header::texture_codec`]); `None`
    /// for a model without [`ATTR_TEXTURE`] or an unknown value.
    pub fn patch_texture_codec(&self) -> Option<crate::TextureCodec> {
        if self.attributes & ATTR_TEXTURE == 0 {
            return None;
        }
        u8::try_from(self.texture_codec)
            .ok()
            .and_then(crate::TextureCodec::from_byte)
    }
}

/// One tetrahedron of the forest and its patch, as the reader holds it in memory (128
/// bytes). Since format version 2 the file stores records packed into index pages
/// (`crate::pages`), from which every field here is restored exactly.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct NodeRecord {
    /// Absolute byte offset of the encoded patch in the file.
    pub patch_offset: u64,
    /// Bisection choices from the root: bit `i` (LSB first) is the child taken at depth
    /// `i` (0 = first child, 1 = second). `level` bits are meaningful.
    pub tet_path: u64,
    /// Length of the encoded patch in bytes.
    pub patch_bytes: u32,
    /// CRC-32 of the encoded patch bytes.
    pub patch_crc32: u32,
    /// Vertices in the patch.
    pub vertex_count: u32,
    /// Triangles in the patch.
    pub triangle_count: u32,
    /// Indices of the two children in the node table, [`NO_NODE`] where absent (a leaf,
    /// or a child tetrahedron holding no triangles).
    pub children: [u32; 2],
    /// Index of the parent, [`NO_NODE`] for roots.
    pub parent: u32,
    /// Diamond id: equal for all tetrahedra that share a refinement edge and were
    /// simplified together; they share one saturated error and sphere.
    pub diamond: u32,
    /// Depth in the binary forest (roots are 0).
    pub level: u8,
    /// Which of the 6 root tetrahedra this node descends from (0..6).
    pub root: u8,
    /// `NODE_FLAG_*` bits.
    pub flags: u8,
    /// Zero.
    pub pad: u8,
    /// Saturated model-space error: an upper bound on the distance between this patch and
    /// the full-resolution surface it stands for; equal within a diamond, never smaller
    /// than any descendant's. 0 for leaves.
    pub error: f32,
    /// Tight bounding sphere of the patch: centre (relative to `cube_origin`), radius.
    pub tight_sphere: [f32; 4],
    /// Saturated sphere: contains this node's tight sphere and the saturated spheres of
    /// all descendants; equal within a diamond.
    pub saturated_sphere: [f32; 4],
    /// Normal cone: unit axis xyz and the cosine of the half-angle that contains every
    /// triangle normal; `[0, 0, 0, -1]` means no backface culling is possible.
    pub normal_cone: [f32; 4],
    /// Minimum corner of the patch's vertices on the global grid; positions are encoded
    /// as offsets from it.
    pub quant_min: [u32; 3],
    /// Width and height of the patch's texture in texels, `[0, 0]` when the model has
    /// no [`ATTR_TEXTURE`] (so budgets know a texture's GPU bytes before it is read).
    pub texture_size: [u16; 2],
    /// Zero.
    pub reserved: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<Header>() == 256);
const _: () = assert!(std::mem::size_of::<NodeRecord>() == 128);

/// Computes the header checksum: CRC-32 of the 256 header bytes with `header_crc32`
/// set to zero.
pub fn header_crc32(header: &Header) -> u32 {
    let mut h = *header;
    h.header_crc32 = 0;
    crc32fast::hash(bytemuck::bytes_of(&h))
}
