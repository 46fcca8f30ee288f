//! A chosen cut as one mesh: decode its patches, weld them, count its edges, write it.
//!
//! Why it exists: `tessera extract`, exports and tests all want a cut (from
//! `tessera_select::select_cut` or `tessera_select::uniform_level_cut`)
//! as a single mesh. The patches are decoded in parallel (rayon) through the format
//! crate's checked decoder, merged by welding bit-identical vertices
//! ([`merge_patches`]), and the edge report ([`edge_report`]) of the result is the crack
//! check: on a closed input any cut must be a closed manifold. [`write_cut_ply`] writes
//! it as a binary PLY in model coordinates; [`crate::gltf_write`] writes it as glTF.

use rayon::prelude::*;
use std::path::Path;
use tessera_format::{FormatError, Grid, NodeRecord, PatchData, PatchReader};
use tessera_mesh::{Attributes, MeshError, PlyWriter, PlyWriterOptions, Vertex};

use tessera_select::{edge_report, merge_patches, CutMesh, EdgeReport, PatchRef};

/// A selected, decoded and merged cut.
pub struct Extracted {
    /// Selected node indices.
    pub nodes: Vec<u32>,
    /// The merged mesh (grid positions).
    pub mesh: CutMesh,
    /// Edge counts of `mesh`.
    pub edges: EdgeReport,
}

impl Extracted {
    /// The selection `nodes` merged into `mesh`, with its edge report.
    fn of(nodes: &[u32], mesh: CutMesh) -> Extracted {
        let edges = edge_report(&mesh.indices, &mesh.positions);
        Extracted {
            nodes: nodes.to_vec(),
            mesh,
            edges,
        }
    }

    /// The largest saturated error of the selected nodes (0 for an empty cut).
    pub fn max_node_error<M: PatchReader + ?Sized>(&self, m: &M) -> f32 {
        self.records(m).map(|n| n.error).fold(0.0f32, f32::max)
    }

    /// The shallowest and deepest level of the selected nodes; `None` for an empty cut.
    pub fn level_range<M: PatchReader + ?Sized>(&self, m: &M) -> Option<(u8, u8)> {
        self.records(m).map(|n| n.level).fold(None, |r, l| {
            Some(r.map_or((l, l), |(lo, hi): (u8, u8)| (lo.min(l), hi.max(l))))
        })
    }

    /// The node records of the selection (indices outside `m`'s table are skipped).
    fn records<'m, M: PatchReader + ?Sized>(
        &'m self,
        m: &'m M,
    ) -> impl Iterator<Item = &'m NodeRecord> + 'm {
        let all = m.index().nodes();
        self.nodes.iter().filter_map(move |&i| all.get(i as usize))
    }
}

/// Patches read per [`PatchReader::decode_patches`] call (a remote model fetches the
/// adjacent ones of each call together).
const READ_CHUNK: usize = 16;

/// Decodes the patches of `nodes` (node indices of `m`, a local or remote model; in
/// parallel, [`READ_CHUNK`] per read), in the order given. A patch that fails its
/// checksum or does not decode fails the whole call; the error names the node. An index
/// outside the node table is an error too.
pub fn decode_nodes<M: PatchReader + ?Sized>(
    m: &M,
    nodes: &[u32],
) -> Result<Vec<PatchData>, FormatError> {
    nodes
        .par_chunks(READ_CHUNK)
        .flat_map_iter(|chunk| {
            let ids: Vec<usize> = chunk.iter().map(|&i| i as usize).collect();
            m.decode_patches(&ids)
        })
        .collect()
}

/// Decodes the patches of `nodes` ([`decode_nodes`]) and merges them into one mesh in
/// the order given.
pub fn extract_nodes<M: PatchReader + ?Sized>(
    m: &M,
    nodes: &[u32],
) -> Result<Extracted, FormatError> {
    let patches = decode_nodes(m, nodes)?;
    let mesh = merge(&patches);
    drop(patches);
    Ok(Extracted::of(nodes, mesh))
}

/// [`extract_nodes`] that also returns the decoded patches (one per node, in the order
/// given): a textured cut's glTF writes each patch with its own texture.
pub fn extract_nodes_keeping<M: PatchReader + ?Sized>(
    m: &M,
    nodes: &[u32],
) -> Result<(Extracted, Vec<PatchData>), FormatError> {
    let patches = decode_nodes(m, nodes)?;
    let mesh = merge(&patches);
    Ok((Extracted::of(nodes, mesh), patches))
}

/// The welded mesh of decoded patches ([`merge_patches`]).
fn merge(patches: &[PatchData]) -> CutMesh {
    merge_patches(patches.iter().map(PatchRef::from))
}

/// Writes a merged cut as a binary PLY in model coordinates (grid points through `grid`,
/// the model's [`Grid::of_header`]), atomically: nothing appears at `path` unless the
/// whole file was written. `comments` go into the header.
pub fn write_cut_ply(
    grid: &Grid,
    mesh: &CutMesh,
    path: &Path,
    comments: Vec<String>,
) -> Result<(), MeshError> {
    let attributes = Attributes {
        normals: !mesh.normals.is_empty(),
        colors: !mesh.colors.is_empty(),
        uvs: !mesh.uvs.is_empty(),
        textures: false,
    };
    let opts = PlyWriterOptions {
        attributes,
        vertex_count: mesh.positions.len() as u64,
        face_count: mesh.triangle_count() as u64,
        comments,
    };
    let mut w = PlyWriter::create(path, &opts)?;
    for (i, &q) in mesh.positions.iter().enumerate() {
        let p = grid.position(q);
        let mut v = Vertex {
            position: [p[0] as f32, p[1] as f32, p[2] as f32],
            ..Vertex::default()
        };
        if attributes.normals {
            v.normal = mesh.normals[i];
        }
        if attributes.colors {
            v.color = mesh.colors[i];
        }
        if attributes.uvs {
            v.uv = mesh.uvs[i];
        }
        w.write_vertex(&v)?;
    }
    for t in mesh.indices.chunks_exact(3) {
        w.write_triangle([t[0], t[1], t[2]])?;
    }
    w.finish()
}
