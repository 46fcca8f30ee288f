//! One diamond's step of the bottom-up construction (ATP section 5.2): merge the patches
//! of the children of every tetrahedron in the diamond, lock the diamond's outer border,
//! simplify as one unit with a quadric metric that weighs normals and colours, record
//! where every child vertex goes (GoLD's geomorphing needs it), and split the result
//! back into the diamond's tetrahedra.

use crate::bounds::Sphere;
use crate::patch::{WorkPatch, WorkVertex, Welder};
use std::cmp::Reverse;
use rustc_hash::FxHashMap;
use std::collections::BinaryHeap;

/// Tuning of the simplifier.
#[derive(Clone, Copy, Debug)]
pub struct SimplifyConfig {
    /// Target triangles per parent tetrahedron (ATP: ~2000).
    pub node_triangles: usize,
    /// Quadric weight of normals (unit vectors). 0.5 is meshoptimizer's suggestion for
    /// normals; it keeps silhouettes and creases without starving flat regions.
    pub normal_weight: f32,
    /// Quadric weight of colours (RGB in 0..1). Colour edges in scans matter as much as
    /// shape edges, so the same order as normals.
    pub color_weight: f32,
    pub has_colors: bool,
}

/// The merged mesh of a diamond's children and how to get back to each child.
pub struct Merged {
    pub vertices: Vec<WorkVertex>,
    pub indices: Vec<u32>,
    /// For each child, for each of its vertices, the merged index.
    pub child_maps: Vec<Vec<u32>>,
}

/// Weld the children into one mesh (bit-identical vertices are the same vertex).
pub fn merge(children: &[&WorkPatch]) -> Merged {
    let total: usize = children.iter().map(|c| c.vertices.len()).sum();
    let mut w = Welder::with_capacity(total);
    let mut indices = Vec::with_capacity(children.iter().map(|c| c.indices.len()).sum());
    let mut child_maps = Vec::with_capacity(children.len());
    for c in children {
        let map: Vec<u32> = c.vertices.iter().map(|v| w.add(v)).collect();
        indices.extend(c.indices.iter().map(|&i| map[i as usize]));
        child_maps.push(map);
    }
    Merged { vertices: w.vertices, indices, child_maps }
}

/// Vertices that must not move: every vertex on an edge used by exactly one triangle (or
/// by three or more) of the merged mesh, with vertices welded by position alone so that
/// attribute seams do not count as borders. Those edges are the diamond's outer border
/// (shared with patches of other diamonds) and the model's own open boundary.
pub fn border_locks(vertices: &[WorkVertex], indices: &[u32]) -> Vec<bool> {
    let mut pos_id: FxHashMap<[u32; 3], u32> = FxHashMap::with_capacity_and_hasher(vertices.len(), Default::default());
    let pid: Vec<u32> = vertices
        .iter()
        .map(|v| {
            let n = pos_id.len() as u32;
            *pos_id.entry(v.q).or_insert(n)
        })
        .collect();
    let mut edges: FxHashMap<(u32, u32), u32> = FxHashMap::with_capacity_and_hasher(indices.len(), Default::default());
    for t in indices.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (pid[t[k] as usize], pid[t[(k + 1) % 3] as usize]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut locked_pos = vec![false; pos_id.len()];
    for (&(a, b), &n) in &edges {
        if n != 2 {
            locked_pos[a as usize] = true;
            locked_pos[b as usize] = true;
        }
    }
    pid.iter().map(|&p| locked_pos[p as usize]).collect()
}

/// Simplify the merged mesh towards `target_triangles` with the locks. Returns the new
/// index list (a subset of the merged vertices) and the error in grid units.
pub fn simplify(m: &Merged, locks: &[bool], target_triangles: usize, cfg: &SimplifyConfig) -> (Vec<u32>, f32) {
    if m.indices.len() / 3 <= target_triangles || m.vertices.is_empty() {
        return (m.indices.clone(), 0.0);
    }
    let positions: Vec<[f32; 3]> = m.vertices.iter().map(|v| v.q.map(|c| c as f32)).collect();
    let stride = if cfg.has_colors { 6 } else { 3 };
    let mut attrs = Vec::with_capacity(m.vertices.len() * stride);
    for v in &m.vertices {
        attrs.extend_from_slice(&v.normal);
        if cfg.has_colors {
            attrs.extend(v.color[..3].iter().map(|&c| c as f32 / 255.0));
        }
    }
    let mut weights = vec![cfg.normal_weight; 3];
    if cfg.has_colors {
        weights.extend_from_slice(&[cfg.color_weight; 3]);
    }
    let bytes: &[u8] = bytemuck::cast_slice(&positions);
    let Ok(adapter) = meshopt::VertexDataAdapter::new(bytes, 12, 0) else {
        return (m.indices.clone(), 0.0);
    };
    let mut err = 0.0f32;
    let out = meshopt::simplify_with_attributes_and_locks(
        &m.indices,
        &adapter,
        &attrs,
        &weights,
        stride * 4,
        locks,
        target_triangles * 3,
        f32::MAX,
        meshopt::SimplifyOptions::ErrorAbsolute,
        Some(&mut err),
    );
    (out, if err.is_finite() { err } else { 0.0 })
}

/// For every merged vertex, the surviving vertex it moves to: itself if it survived,
/// else the nearest survivor along the mesh's edges (multi-source Dijkstra with
/// Euclidean edge lengths). meshoptimizer does not report its collapse chains; collapses
/// follow edges to nearby survivors, so the nearest survivor by edge path is the vertex
/// the removed one was folded into or its neighbour on the same chain. Vertices with no
/// survivor in their component stay where they are.
pub fn morph_destinations(m: &Merged, simplified: &[u32]) -> Vec<u32> {
    let n = m.vertices.len();
    let mut dest: Vec<u32> = (0..n as u32).collect();
    let mut dist = vec![f64::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for &i in simplified {
        if dist[i as usize] != 0.0 {
            dist[i as usize] = 0.0;
            heap.push(Reverse((0u64, i)));
        }
    }
    // Adjacency (CSR).
    let mut deg = vec![0u32; n + 1];
    for t in m.indices.chunks_exact(3) {
        for k in 0..3 {
            deg[t[k] as usize] += 2;
        }
    }
    let mut start = vec![0usize; n + 1];
    for i in 0..n {
        start[i + 1] = start[i] + deg[i] as usize;
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for t in m.indices.chunks_exact(3) {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            adj[fill[a as usize]] = b;
            adj[fill[a as usize] + 1] = c;
            fill[a as usize] += 2;
        }
    }
    let pos = |i: u32| m.vertices[i as usize].q.map(|c| c as f64);
    while let Some(Reverse((d_bits, v))) = heap.pop() {
        let d = f64::from_bits(d_bits);
        if d > dist[v as usize] {
            continue;
        }
        let pv = pos(v);
        for &u in &adj[start[v as usize]..start[v as usize + 1]] {
            let pu = pos(u);
            let nd = d + crate::bounds::dist2(pv, pu).sqrt();
            if nd < dist[u as usize] {
                dist[u as usize] = nd;
                dest[u as usize] = dest[v as usize];
                // Non-negative f64 order equals the order of their bit patterns.
                heap.push(Reverse((nd.to_bits(), u)));
            }
        }
    }
    dest
}

/// Split simplified triangles among the diamond's tetrahedra: `owner(centroid)` says
/// which (index into the diamond's list). Each part gets compact vertices.
pub fn split(m: &Merged, simplified: &[u32], parts: usize, mut owner: impl FnMut([[u32; 3]; 3]) -> usize) -> Vec<WorkPatch> {
    let mut remaps: Vec<FxHashMap<u32, u32>> = vec![FxHashMap::default(); parts];
    let mut out: Vec<WorkPatch> = vec![WorkPatch::default(); parts];
    for t in simplified.chunks_exact(3) {
        let q = [t[0], t[1], t[2]].map(|i| m.vertices[i as usize].q);
        let o = owner(q).min(parts - 1);
        let p = &mut out[o];
        for &i in t {
            let next = p.vertices.len() as u32;
            let id = *remaps[o].entry(i).or_insert(next);
            if id == next {
                p.vertices.push(m.vertices[i as usize]);
            }
            p.indices.push(id);
        }
    }
    out
}

/// Saturated sphere of a diamond: contains the tight spheres of its new patches and the
/// saturated spheres of all its children.
pub fn saturated_sphere(tight: &[Sphere], children: &[Sphere]) -> Sphere {
    let all: Vec<Sphere> = tight.iter().chain(children).copied().filter(|s| s.radius > 0.0 || s.center != [0.0; 3]).collect();
    Sphere::of_balls(&all)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_patch(n: u32, x0: u32) -> WorkPatch {
        // An n x n grid of quads in the z=0 plane starting at x = x0.
        let mut p = WorkPatch::default();
        for j in 0..=n {
            for i in 0..=n {
                p.vertices.push(WorkVertex { q: [x0 + i * 10, j * 10, 0], normal: [0.0, 0.0, 1.0], ..Default::default() });
            }
        }
        let w = n + 1;
        for j in 0..n {
            for i in 0..n {
                let a = j * w + i;
                p.indices.extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
            }
        }
        p
    }

    #[test]
    fn merge_welds_shared_border() {
        // Why: two patches meeting along x = 100 must become one connected mesh, or the
        // diamond's internal border would be locked and never simplified.
        let a = grid_patch(10, 0);
        let b = grid_patch(10, 100);
        let m = merge(&[&a, &b]);
        assert_eq!(m.vertices.len(), 2 * 121 - 11);
        let locks = border_locks(&m.vertices, &m.indices);
        // Only the outer rectangle is locked: 2*(20+10) border vertices.
        assert_eq!(locks.iter().filter(|&&l| l).count(), 60);
    }

    #[test]
    fn simplify_keeps_locked_border_and_hits_target() {
        let a = grid_patch(20, 0);
        let m = merge(&[&a]);
        let locks = border_locks(&m.vertices, &m.indices);
        let cfg = SimplifyConfig { node_triangles: 100, normal_weight: 0.5, color_weight: 0.5, has_colors: false };
        let (out, err) = simplify(&m, &locks, 100, &cfg);
        assert!(out.len() / 3 < 800);
        assert!(err >= 0.0 && err < 1.0, "flat grid simplifies with ~zero error, got {err}");
        let used: std::collections::HashSet<u32> = out.iter().copied().collect();
        for (i, &l) in locks.iter().enumerate() {
            if l {
                assert!(used.contains(&(i as u32)), "locked vertex {i} removed");
            }
        }
        let dest = morph_destinations(&m, &out);
        for (i, &d) in dest.iter().enumerate() {
            assert!(used.contains(&d), "destination of {i} is not a survivor");
            if used.contains(&(i as u32)) {
                assert_eq!(d, i as u32, "survivors stay put");
            }
        }
    }

    #[test]
    fn split_assigns_every_triangle_once() {
        let a = grid_patch(4, 0);
        let m = merge(&[&a]);
        let parts = split(&m, &m.indices, 2, |q| if q[0][0] + q[1][0] + q[2][0] < 60 { 0 } else { 1 });
        assert_eq!(parts.iter().map(|p| p.triangle_count()).sum::<usize>(), 32);
        assert!(parts.iter().all(|p| p.triangle_count() > 0));
    }
}
