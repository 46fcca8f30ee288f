//! The vocabulary shared by every importer: what a vertex holds and how a reader hands
//! the mesh over.

use std::collections::BTreeMap;

use crate::MeshError;

/// Which optional per-vertex attributes a mesh carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Attributes {
    pub normals: bool,
    pub colors: bool,
    pub uvs: bool,
}

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
    /// Texture coordinates (u, v) as in the file.
    pub uv: [f32; 2],
}

impl Default for Vertex {
    fn default() -> Self {
        Vertex {
            position: [0.0; 3],
            normal: [0.0; 3],
            color: [255; 4],
            uv: [0.0; 2],
        }
    }
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
    /// Textured materials whose images the build does not use yet (glTF, OBJ's
    /// `map_Kd`), each as `name (image 'x')`: they are drawn in their base colour factor
    /// or `Kd` (x vertex colour) and their UVs are kept. Also logged once as a warning.
    pub textures_not_used: Vec<String>,
    /// Files the input refers to that could not be read (an OBJ's material libraries,
    /// their texture images), as paths; each also a warning. The geometry is complete.
    pub missing_files: Vec<String>,
    /// OBJ `usemtl` names no material library defines (drawn white), with counts.
    pub unknown_materials: BTreeMap<String, u64>,
}
