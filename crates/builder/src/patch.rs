//! The builder's in-memory patch: vertices with every attribute at full precision and
//! positions already on the global grid, plus a triangle list. Patches travel between
//! levels through a temporary spool as raw bytes.

use crate::bounds::{normal_cone, Sphere};
use bytemuck::{Pod, Zeroable};
use rustc_hash::{FxHashMap, FxHashSet};

/// One vertex as the builder sees it. Two vertices are the same vertex exactly when their
/// bytes are equal, which is how patches are welded across tetrahedra.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct WorkVertex {
    /// Position on the global quantisation grid.
    pub q: [u32; 3],
    /// Unit normal (zero when the model has none).
    pub normal: [f32; 3],
    /// RGBA8 (opaque white when the model has no colours).
    pub color: [u8; 4],
    /// Texture coordinates (zero when absent).
    pub uv: [f32; 2],
    /// The texture it samples (`tessera_mesh::NO_TEXTURE` when none): vertices of two
    /// textures are two vertices, so simplification keeps their seam.
    pub texture: u32,
}

/// Bytes of a [`WorkVertex`] in the spool.
const WORK_VERTEX_BYTES: usize = std::mem::size_of::<WorkVertex>();
const _: () = assert!(WORK_VERTEX_BYTES == 40);

/// The byte identity of a vertex, used as a hash key for welding.
pub type VertexKey = [u32; 10];

impl WorkVertex {
    pub fn key(&self) -> VertexKey {
        bytemuck::cast(*self)
    }
}

/// Which vertex-cache optimiser [`WorkPatch::optimize`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheOrder {
    /// meshoptimizer's scored cache optimiser (better order, slower).
    Table,
    /// meshoptimizer's FIFO cache optimiser (~3x faster).
    Fifo,
}

/// A mesh patch during the build.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorkPatch {
    pub vertices: Vec<WorkVertex>,
    pub indices: Vec<u32>,
}

impl WorkPatch {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Serialise for the spool: `u32 vertex_count, u32 index_count, vertices, indices`.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            8 + self.vertices.len() * WORK_VERTEX_BYTES + self.indices.len() * 4,
        );
        out.extend_from_slice(&(self.vertices.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.indices.len() as u32).to_le_bytes());
        out.extend_from_slice(bytemuck::cast_slice(&self.vertices));
        out.extend_from_slice(bytemuck::cast_slice(&self.indices));
        out
    }

    /// Inverse of [`WorkPatch::to_bytes`]; `None` if the bytes are not a patch (the spool
    /// is our own temporary file, so this only fails on disk corruption).
    pub fn from_bytes(b: &[u8]) -> Option<WorkPatch> {
        let vc = u32::from_le_bytes(b.get(0..4)?.try_into().ok()?) as usize;
        let ic = u32::from_le_bytes(b.get(4..8)?.try_into().ok()?) as usize;
        let vb = b.get(8..8 + vc * WORK_VERTEX_BYTES)?;
        let at = 8 + vc * WORK_VERTEX_BYTES;
        let ib = b.get(at..at + ic * 4)?;
        // One copy each (the buffer need not be aligned for the element types).
        let vertices = bytemuck::pod_collect_to_vec(vb);
        let indices = bytemuck::pod_collect_to_vec(ib);
        Some(WorkPatch { vertices, indices })
    }

    /// Reorder for the GPU: vertex-cache order for triangles, then vertices in first-use
    /// order (meshoptimizer), which also helps the index and vertex codecs.
    ///
    /// `order` picks meshoptimizer's cache optimiser. [`CacheOrder::Table`] (its default)
    /// costs ~3x the time of [`CacheOrder::Fifo`]. Measured on whole builds (bytes per
    /// input triangle, table everywhere -> FIFO for leaves and table above): Stanford
    /// Dragon 5.66 -> 5.90, 10M sphere 4.93 -> 4.75, gargoyle 6.64 -> 6.75; the leaves'
    /// optimisation went from 1.8 s to 0.4 s of CPU on the 10M sphere. FIFO everywhere
    /// gave the Dragon 6.02, so internal nodes (whose order also seeds their parents'
    /// simplified order) keep the table.
    pub fn optimize(&mut self, order: CacheOrder) {
        if self.indices.is_empty() {
            self.vertices.clear();
            return;
        }
        let n = self.vertices.len();
        let mut idx = match order {
            CacheOrder::Table => meshopt::optimize_vertex_cache(&self.indices, n),
            // 16 entries, as the index codec's vertex FIFO.
            CacheOrder::Fifo => meshopt::optimize_vertex_cache_fifo(&self.indices, n, 16),
        };
        let verts = meshopt::optimize_vertex_fetch(&mut idx, &self.vertices);
        self.indices = idx;
        self.vertices = verts;
    }

    /// Tight sphere, in model units relative to the cube origin.
    pub fn tight_sphere(&self, step: f64) -> Sphere {
        Sphere::of_points(self.vertices.iter().map(move |v| grid_to_local(v.q, step)))
    }

    /// Normal cone of the triangles (geometric normals of the quantised positions).
    pub fn normal_cone(&self) -> [f32; 4] {
        let normals: Vec<[f64; 3]> = self
            .indices
            .chunks_exact(3)
            .map(|t| {
                let p = |i: u32| self.vertices[i as usize].q.map(|c| c as f64);
                face_normal(p(t[0]), p(t[1]), p(t[2]))
            })
            .collect();
        normal_cone(&normals)
    }
}

/// Model units relative to the cube origin.
pub fn grid_to_local(q: [u32; 3], step: f64) -> [f64; 3] {
    [q[0] as f64 * step, q[1] as f64 * step, q[2] as f64 * step]
}

/// Area-weighted (unnormalised) normal of a triangle.
pub fn face_normal(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// Welds vertices with identical bytes into one indexed mesh, remembering where every
/// input vertex went.
#[derive(Default)]
pub struct Welder {
    map: FxHashMap<VertexKey, u32>,
    pub vertices: Vec<WorkVertex>,
}

impl Welder {
    pub fn with_capacity(n: usize) -> Welder {
        Welder {
            map: FxHashMap::with_capacity_and_hasher(n, Default::default()),
            vertices: Vec::with_capacity(n),
        }
    }

    /// Index of `v` in the welded mesh (added if new).
    pub fn add(&mut self, v: &WorkVertex) -> u32 {
        let next = self.vertices.len() as u32;
        let id = *self.map.entry(v.key()).or_insert(next);
        if id == next {
            self.vertices.push(*v);
        }
        id
    }
}

/// Counts of what a patch clean-up removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CleanupCounts {
    pub degenerate: u64,
    pub duplicate: u64,
}

/// Drop degenerate triangles (two corners on one grid point, whatever their attributes)
/// and exact duplicates (same vertices, same orientation); keeps first occurrences in
/// order. Each input triangle lives in exactly one leaf, so the decision is global.
pub fn remove_bad_triangles(indices: &mut Vec<u32>, vertices: &[WorkVertex]) -> CleanupCounts {
    remove_bad_triangles_noting(indices, vertices, |_| {})
}

/// [`remove_bad_triangles`], calling `degenerate(i)` with the ordinal (in the input
/// order) of each triangle dropped as degenerate.
pub fn remove_bad_triangles_noting(
    indices: &mut Vec<u32>,
    vertices: &[WorkVertex],
    mut degenerate: impl FnMut(usize),
) -> CleanupCounts {
    let mut counts = CleanupCounts::default();
    let mut seen = FxHashSet::with_capacity_and_hasher(indices.len() / 3, Default::default());
    let mut out = Vec::with_capacity(indices.len());
    for (i, t) in indices.chunks_exact(3).enumerate() {
        let q = |k: usize| vertices[t[k] as usize].q;
        if t[0] == t[1]
            || t[1] == t[2]
            || t[0] == t[2]
            || q(0) == q(1)
            || q(1) == q(2)
            || q(0) == q(2)
        {
            counts.degenerate += 1;
            degenerate(i);
            continue;
        }
        // Canonical rotation keeps orientation: start at the smallest index.
        let r = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
        let key = [t[r], t[(r + 1) % 3], t[(r + 2) % 3]];
        if !seen.insert(key) {
            counts.duplicate += 1;
            continue;
        }
        out.extend_from_slice(t);
    }
    *indices = out;
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: u32) -> WorkVertex {
        WorkVertex {
            q: [x, 0, 0],
            ..Default::default()
        }
    }

    #[test]
    fn spool_bytes_round_trip() {
        let p = WorkPatch {
            vertices: vec![v(1), v(2), v(3)],
            indices: vec![0, 1, 2],
        };
        assert_eq!(WorkPatch::from_bytes(&p.to_bytes()), Some(p));
        assert_eq!(WorkPatch::from_bytes(&[1, 0, 0]), None);
    }

    #[test]
    fn welder_merges_identical_bytes_only() {
        let mut w = Welder::default();
        assert_eq!(w.add(&v(1)), 0);
        assert_eq!(w.add(&v(2)), 1);
        assert_eq!(w.add(&v(1)), 0);
        let mut c = v(1);
        c.color = [1, 2, 3, 4];
        assert_eq!(
            w.add(&c),
            2,
            "same position, other colour: a seam, not the same vertex"
        );
    }

    #[test]
    fn bad_triangles_removed_orientation_kept() {
        // Why: duplicate faces would make edges non-manifold; a flipped copy is kept because
        // it is real (two-sided) geometry, not a duplicate.
        let verts = [v(1), v(2), v(3), v(3)];
        let mut idx = vec![0, 1, 2, 1, 2, 0, 0, 0, 1, 2, 1, 0, 0, 2, 3];
        let c = remove_bad_triangles(&mut idx, &verts);
        assert_eq!(idx, vec![0, 1, 2, 2, 1, 0]);
        assert_eq!(
            c,
            CleanupCounts {
                degenerate: 2,
                duplicate: 1
            },
            "(0, 2, 3) has two corners on one point"
        );
    }
}
