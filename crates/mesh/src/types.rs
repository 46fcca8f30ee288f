//! The vocabulary shared by every importer: what a vertex holds and how a reader hands
//! the mesh over.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::MeshError;

/// Which optional per-vertex attributes a mesh carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Attributes {
    pub normals: bool,
    pub colors: bool,
    pub uvs: bool,
    /// Some vertex samples a texture ([`Vertex::texture`] is not [`NO_TEXTURE`]); implies
    /// `uvs`.
    pub textures: bool,
}

/// [`Vertex::texture`] of an untextured vertex.
pub const NO_TEXTURE: u32 = u32::MAX;

/// One vertex with every attribute Tessera keeps. Absent attributes are zero
/// (and `color` is opaque white `[255; 4]` when the file has no colour).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    /// Model-space position.
    pub position: [f32; 3],
    /// Vertex normal as given by the file (not necessarily unit length).
    pub normal: [f32; 3],
    /// RGBA, 8 bits per channel (RGB files get alpha 255; float colours are scaled).
    pub color: [u8; 4],
    /// Texture coordinates (u, v) as in the file (v is never flipped:
    /// [`TextureSource::v_up`] says which way it runs), through the texture transform of
    /// the material where it has one (glTF `KHR_texture_transform`, MTL `-o`/`-s`).
    pub uv: [f32; 2],
    /// The texture the vertex samples: an index into [`ImportReport::textures`], or
    /// [`NO_TEXTURE`]. `color` is then the fallback colour (the material's tint x the
    /// vertex colour), drawn where the texture is not. Vertices of different textures are
    /// never one vertex.
    pub texture: u32,
}

impl Default for Vertex {
    fn default() -> Self {
        Vertex {
            position: [0.0; 3],
            normal: [0.0; 3],
            color: [255; 4],
            uv: [0.0; 2],
            texture: NO_TEXTURE,
        }
    }
}

/// Where a texture's encoded image bytes are.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum ImageSource {
    /// A whole image file (OBJ `map_Kd`, glTF external `uri`).
    File(PathBuf),
    /// Bytes inside a file (a glTF `bufferView` in a `.bin` or a `.glb`): read them
    /// lazily, nothing is copied at import.
    FileRange {
        path: PathBuf,
        offset: u64,
        len: u64,
    },
    /// Bytes held in memory (a glTF `data:` URI), `key` unique per image within the
    /// import (`image 3`).
    Memory { key: String, bytes: Arc<[u8]> },
}

/// How texture coordinates outside 0..1 sample the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wrap {
    Repeat,
    ClampToEdge,
    MirroredRepeat,
}

/// One texture the vertices of an import sample ([`Vertex::texture`] indexes
/// [`ImportReport::textures`]): a material's diffuse / base colour image. Two materials
/// sharing one image are two `TextureSource`s with equal `image`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TextureSource {
    /// The material's name (for messages and for writing the model back out).
    pub material: String,
    pub image: ImageSource,
    /// Human-readable image name for messages: the path as written in the file, or
    /// `image 3 (embedded)`.
    pub image_name: String,
    /// Multiplies the texels: OBJ `Kd`, glTF `baseColorFactor`, as sRGB-encoded RGBA8
    /// like vertex colours.
    pub tint: [u8; 4],
    /// Wrap mode along u and v (OBJ: `Repeat` unless `-clamp on`; glTF: the sampler's
    /// `wrapS` / `wrapT`, default `Repeat`).
    pub wrap: [Wrap; 2],
    /// `true` when v = 0 is the image's bottom row (OBJ convention), `false` when it is
    /// the top row (glTF).
    pub v_up: bool,
    /// Width and height, read from the image header at import (PNG or JPEG). Never
    /// `[0, 0]` from the importers: an image whose header cannot be read is not a
    /// texture (it is named in [`ImportReport::unreadable_images`] and its vertices are
    /// untextured); `[0, 0]` is left for "not known" where a `TextureSource` is made
    /// by other means.
    pub size: [u32; 2],
}

/// What a reader knows before the first vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshHeader {
    pub attributes: Attributes,
    /// Vertex count when the header says it (PLY), `None` otherwise.
    pub vertex_count: Option<u64>,
    /// Face (polygon) count when the header says it (PLY, binary STL), `None` otherwise.
    pub face_count: Option<u64>,
}

/// Receives a mesh as it is read. Returning an error stops the reader, which returns it.
pub trait MeshVisitor {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError>;
    fn vertex(&mut self, vertex: &Vertex) -> Result<(), MeshError>;
    /// A triangle of vertex indices (global, 0-based, all already delivered).
    fn triangle(&mut self, indices: [u32; 3]) -> Result<(), MeshError>;
    /// Whether the reader should stop (Ctrl-C: the builder maps its
    /// [`crate::Progress::cancelled`] here). Readers poll it between chunks of work,
    /// also where they deliver nothing for a long time (a run of skipped faces, an
    /// accessor of zeros), and then return [`MeshError::Interrupted`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// Counts of what a reader delivered and what it skipped (each skip is also logged
/// once with `tracing::warn!`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ImportReport {
    pub vertices: u64,
    pub triangles: u64,
    /// Polygons with more than 3 corners that were fan-triangulated.
    pub polygons_triangulated: u64,
    /// Faces dropped because two or more corners share one vertex index.
    pub degenerate_faces_skipped: u64,
    /// Faces with fewer than 3 corners, dropped.
    pub short_faces_skipped: u64,
    /// Unknown OBJ statements or PLY elements that were ignored.
    pub ignored_statements: u64,
    /// What `ignored_statements` counts, by name: the OBJ keyword (`cstype`, `l`) or the
    /// PLY element (`element camera`), each with its count. At most 32 names are kept
    /// (the keywords of a garbage file could be anything); the rest are counted under
    /// `other names`, so the counts always sum to `ignored_statements`.
    pub ignored_by_name: BTreeMap<String, u64>,
    /// Bytes after the last element a PLY header declares (ASCII: other than
    /// whitespace), ignored: more faces than declared, or garbage.
    pub trailing_bytes_ignored: u64,
    /// The text file ends inside its last line (no newline after it): if it was cut
    /// short there, that line's last number was read incomplete.
    pub unterminated_last_line: bool,
    /// The textures the vertices sample, indexed by [`Vertex::texture`] (in order of first
    /// use; only textures some vertex samples).
    pub textures: Vec<TextureSource>,
    /// Textured materials whose image is still not used, each as `name (image 'x'): why`
    /// (glTF: a texture coordinate set other than `TEXCOORD_0`, an image format other
    /// than PNG or JPEG such as `EXT_texture_webp` or `KHR_texture_basisu`, a remote
    /// URI, a primitive without texture coordinates): their vertices are untextured, drawn
    /// in the base colour factor or `Kd` (x vertex colour), UVs kept. Also logged once as
    /// a warning. Missing and unreadable images are in `missing_files` and
    /// `unreadable_images` instead.
    pub textures_not_used: Vec<String>,
    /// Files the input refers to that could not be read (an OBJ's material libraries,
    /// texture images of OBJ and glTF, the `.bin` of a glTF image), as paths; each also a
    /// warning. The geometry is complete; the vertices of a missing image are untextured.
    pub missing_files: Vec<String>,
    /// Texture images that are there but whose header cannot be read (a corrupt PNG or
    /// JPEG, another format, not an image), each as `name: why`; also a warning. Their
    /// vertices are untextured, drawn in the material's colour.
    pub unreadable_images: Vec<String>,
    /// Faces of a textured material without texture coordinates on every corner (OBJ
    /// `f 1 2 3` or `f 1//1 2//1 3//1` under a `map_Kd` material): drawn untextured in the
    /// material's colour; also a warning.
    pub untextured_faces: u64,
    /// OBJ `usemtl` names no material library defines (drawn white), with counts.
    pub unknown_materials: BTreeMap<String, u64>,
}
