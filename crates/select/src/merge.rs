//! Merging the patches of a cut into one indexed mesh.
//!
//! Why it exists: headless rendering, exports and the crack-freedom tests all want a cut
//! as a single mesh. Positions sit on one global grid, so a vertex on the border between
//! two patches is bit-identical in both; welding vertices that are bit-identical in
//! position AND every attribute joins the patches back into one connected surface without
//! ever merging vertices that differ (a colour seam stays a seam).
//!
//! This module does not decode patches: it takes borrowed slices ([`PatchRef`]) so it
//! works with any source (the format crate's decoder, or hand-built test patches).

use std::collections::HashMap;

use rustc_hash::FxBuildHasher;

/// One decoded patch, borrowed. An attribute slice is either empty (the model does not
/// carry that attribute) or as long as `positions`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PatchRef<'a> {
    /// Grid positions.
    pub positions: &'a [[u32; 3]],
    /// Unit normals, or empty.
    pub normals: &'a [[f32; 3]],
    /// RGBA8 colours, or empty.
    pub colors: &'a [[u8; 4]],
    /// Texture coordinates, or empty.
    pub uvs: &'a [[f32; 2]],
    /// Triangle list into this patch's vertices.
    pub indices: &'a [u32],
}

impl<'a> From<&'a tessera_format::PatchData> for PatchRef<'a> {
    /// A decoded patch's slices.
    fn from(p: &'a tessera_format::PatchData) -> PatchRef<'a> {
        PatchRef {
            positions: &p.positions,
            normals: &p.normals,
            colors: &p.colors,
            uvs: &p.uvs,
            indices: &p.indices,
        }
    }
}

/// A cut as one indexed mesh. Attribute vectors are empty when the patches lack that
/// attribute, else as long as `positions`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CutMesh {
    /// Grid positions (dequantise with the header's cube and `quant_bits`).
    pub positions: Vec<[u32; 3]>,
    /// Normals, or empty.
    pub normals: Vec<[f32; 3]>,
    /// Colours, or empty.
    pub colors: Vec<[u8; 4]>,
    /// Texture coordinates, or empty.
    pub uvs: Vec<[f32; 2]>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

impl CutMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// The welding key: position and attributes as raw bits (so -0.0 and 0.0, or two NaNs
/// with different payloads, stay distinct: only bit-identical vertices weld).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct VertexKey {
    position: [u32; 3],
    normal: [u32; 3],
    color: [u8; 4],
    uv: [u32; 2],
}

/// Merges patches into one mesh, welding vertices that are bit-identical in position and
/// all attributes; vertices keep their first-seen order, triangles their patch order.
///
/// An attribute is kept only if every patch with vertices carries it (a slice as long as
/// its positions): mixing patches with and without normals would otherwise need invented
/// values. Triangles with an index outside their patch are dropped (decoded patches are
/// validated upstream, so this only guards against panics) and reported with a warning.
pub fn merge_patches<'a>(patches: impl IntoIterator<Item = PatchRef<'a>>) -> CutMesh {
    let patches: Vec<PatchRef<'a>> = patches.into_iter().collect();
    let with_vertices = || patches.iter().filter(|p| !p.positions.is_empty());
    let has_normals = with_vertices().all(|p| p.normals.len() == p.positions.len());
    let has_colors = with_vertices().all(|p| p.colors.len() == p.positions.len());
    let has_uvs = with_vertices().all(|p| p.uvs.len() == p.positions.len());
    let vertex_bound: usize = patches.iter().map(|p| p.positions.len()).sum();
    let index_count: usize = patches.iter().map(|p| p.indices.len() / 3 * 3).sum();

    let mut mesh = CutMesh {
        positions: Vec::with_capacity(vertex_bound),
        normals: Vec::with_capacity(if has_normals { vertex_bound } else { 0 }),
        colors: Vec::with_capacity(if has_colors { vertex_bound } else { 0 }),
        uvs: Vec::with_capacity(if has_uvs { vertex_bound } else { 0 }),
        indices: Vec::with_capacity(index_count),
    };
    let mut welded: HashMap<VertexKey, u32, FxBuildHasher> =
        HashMap::with_capacity_and_hasher(vertex_bound, FxBuildHasher);
    let mut remap: Vec<u32> = Vec::new();
    let mut dropped = 0usize;

    for p in &patches {
        remap.clear();
        for (i, &position) in p.positions.iter().enumerate() {
            let key = VertexKey {
                position,
                normal: if has_normals {
                    p.normals[i].map(f32::to_bits)
                } else {
                    [0; 3]
                },
                color: if has_colors { p.colors[i] } else { [0; 4] },
                uv: if has_uvs {
                    p.uvs[i].map(f32::to_bits)
                } else {
                    [0; 2]
                },
            };
            let next = mesh.positions.len() as u32;
            let id = *welded.entry(key).or_insert_with(|| {
                mesh.positions.push(position);
                if has_normals {
                    mesh.normals.push(p.normals[i]);
                }
                if has_colors {
                    mesh.colors.push(p.colors[i]);
                }
                if has_uvs {
                    mesh.uvs.push(p.uvs[i]);
                }
                next
            });
            remap.push(id);
        }
        for tri in p.indices.chunks_exact(3) {
            match (
                remap.get(tri[0] as usize),
                remap.get(tri[1] as usize),
                remap.get(tri[2] as usize),
            ) {
                (Some(&a), Some(&b), Some(&c)) => mesh.indices.extend_from_slice(&[a, b, c]),
                _ => dropped += 1,
            }
        }
    }
    if dropped > 0 {
        tracing::warn!(
            dropped,
            "merge_patches: dropped triangles with out-of-range indices"
        );
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn patch<'a>(
        positions: &'a [[u32; 3]],
        colors: &'a [[u8; 4]],
        indices: &'a [u32],
    ) -> PatchRef<'a> {
        PatchRef {
            positions,
            colors,
            indices,
            ..PatchRef::default()
        }
    }

    const WHITE: [u8; 4] = [255; 4];
    const RED: [u8; 4] = [255, 0, 0, 255];

    #[test]
    fn shared_border_vertices_weld_across_patches() {
        // Two triangles of a square, in separate patches sharing the diagonal.
        let a_pos = [[0, 0, 0], [1, 0, 0], [1, 1, 0]];
        let b_pos = [[1, 1, 0], [0, 1, 0], [0, 0, 0]];
        let cols = [WHITE; 3];
        let m = merge_patches([
            patch(&a_pos, &cols, &[0, 1, 2]),
            patch(&b_pos, &cols, &[0, 1, 2]),
        ]);
        assert_eq!(
            m.positions,
            vec![[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
        );
        assert_eq!(m.indices, vec![0, 1, 2, 2, 3, 0]);
        assert_eq!(m.colors.len(), 4);
        assert!(m.normals.is_empty() && m.uvs.is_empty());
        assert!(crate::edge_report(&m.indices, &m.positions).boundary_edges == 4);
    }

    #[test]
    fn differing_attributes_stay_separate_vertices() {
        // Same position, different colour: a seam, not a weld.
        let pos = [[0, 0, 0], [1, 0, 0], [0, 1, 0]];
        let m = merge_patches([
            patch(&pos, &[WHITE; 3], &[0, 1, 2]),
            patch(&pos, &[RED, WHITE, WHITE], &[0, 1, 2]),
        ]);
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.colors[3], RED);
        assert_eq!(m.indices, vec![0, 1, 2, 3, 1, 2]);
        // Normals differing only in the sign of zero are not bit-identical.
        let n1 = [[0.0, 0.0, 1.0]; 3];
        let n2 = [[-0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]];
        let p = |normals| PatchRef {
            positions: &pos,
            normals,
            indices: &[0, 1, 2],
            ..PatchRef::default()
        };
        let m = merge_patches([p(&n1), p(&n2)]);
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.normals.len(), 4);
    }

    #[test]
    fn attributes_kept_only_when_every_patch_has_them() {
        let pos = [[0, 0, 0], [1, 0, 0], [0, 1, 0]];
        let uvs = [[0.0, 0.0]; 3];
        let with = PatchRef {
            positions: &pos,
            uvs: &uvs,
            indices: &[0, 1, 2],
            ..PatchRef::default()
        };
        let without = PatchRef {
            positions: &pos,
            indices: &[0, 2, 1],
            ..PatchRef::default()
        };
        let m = merge_patches([with, without]);
        assert!(m.uvs.is_empty());
        assert_eq!(
            m.positions.len(),
            3,
            "without uvs the vertices weld by position"
        );
        assert_eq!(m.indices, vec![0, 1, 2, 0, 2, 1]);
        // An empty patch does not veto attributes.
        let m = merge_patches([with, PatchRef::default()]);
        assert_eq!(m.uvs.len(), 3);
    }

    #[test]
    fn first_seen_order_and_in_patch_duplicates() {
        // A patch that repeats a vertex welds it to the first occurrence.
        let pos = [[5, 5, 5], [1, 1, 1], [5, 5, 5], [2, 2, 2]];
        let m = merge_patches([patch(&pos, &[], &[0, 1, 3, 2, 3, 1])]);
        assert_eq!(m.positions, vec![[5, 5, 5], [1, 1, 1], [2, 2, 2]]);
        assert_eq!(m.indices, vec![0, 1, 2, 0, 2, 1]);
    }

    #[test]
    fn out_of_range_indices_and_partial_triangles_are_dropped() {
        let pos = [[0, 0, 0], [1, 0, 0], [0, 1, 0]];
        let m = merge_patches([patch(&pos, &[], &[0, 1, 2, 0, 1, 9, 0, 1])]);
        assert_eq!(m.indices, vec![0, 1, 2]);
        assert_eq!(m.triangle_count(), 1);
        assert_eq!(merge_patches(std::iter::empty()), CutMesh::default());
    }
}
