//! Edge statistics of an indexed mesh: the crack detector.
//!
//! Why it exists: the central promise of the format is that any cut chosen top-down is a
//! crack-free mesh. A crack between two patches shows up as boundary edges that the input
//! did not have, and a bad weld as edges used three or more times; counting each
//! undirected edge's uses on a merged cut checks that promise without rendering.
//!
//! Vertices are identified by grid POSITION here (two vertices at the same grid point are
//! the same point, whatever their attributes), because a colour or UV seam is not a hole.

use std::collections::HashMap;

use rustc_hash::FxBuildHasher;

/// Counts over the triangles of a mesh, after welding vertices by position.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EdgeReport {
    /// Triangles examined (`indices.len() / 3`).
    pub triangles: u64,
    /// Distinct undirected edges of the non-degenerate triangles.
    pub edges: u64,
    /// Edges used by exactly one triangle (holes, cracks, or the surface's own border).
    pub boundary_edges: u64,
    /// Edges used by three or more triangles.
    pub nonmanifold_edges: u64,
    /// Triangles with zero area: two corners at the same grid position (these contribute
    /// no edges), or three distinct but collinear corners (these still contribute their
    /// edges). Triangles with an out-of-range index are counted here too and skipped.
    pub degenerate_triangles: u64,
}

impl EdgeReport {
    /// No boundary and no non-manifold edges: a closed 2-manifold surface (orientation
    /// is not checked).
    pub fn is_closed_manifold(&self) -> bool {
        self.boundary_edges == 0 && self.nonmanifold_edges == 0
    }
}

/// True when three grid points are collinear (exact: integer cross product in i128).
fn collinear(a: [u32; 3], b: [u32; 3], c: [u32; 3]) -> bool {
    let d = |p: [u32; 3], q: [u32; 3]| {
        [
            i128::from(q[0]) - i128::from(p[0]),
            i128::from(q[1]) - i128::from(p[1]),
            i128::from(q[2]) - i128::from(p[2]),
        ]
    };
    let (u, v) = (d(a, b), d(a, c));
    u[1] * v[2] == u[2] * v[1] && u[2] * v[0] == u[0] * v[2] && u[0] * v[1] == u[1] * v[0]
}

/// Counts edge uses of the triangle list `indices` over `positions`, welding vertices
/// with equal positions first. A trailing partial triangle is ignored.
pub fn edge_report(indices: &[u32], positions: &[[u32; 3]]) -> EdgeReport {
    edge_uses(indices, positions).0
}

/// The boundary edges (used by one triangle) of the mesh [`edge_report`] counts, each as
/// its two grid positions (the smaller first), sorted: where a cut's holes are, to
/// compare with the holes the full-resolution surface has of its own.
pub fn boundary_edges(indices: &[u32], positions: &[[u32; 3]]) -> Vec<[[u32; 3]; 2]> {
    let (_, uses) = edge_uses(indices, positions);
    let mut edges: Vec<[[u32; 3]; 2]> = uses
        .into_iter()
        .filter(|&(_, n)| n == 1)
        .map(|(key, _)| {
            let (a, b) = (
                positions[(key >> 32) as usize],
                positions[key as u32 as usize],
            );
            if a < b {
                [a, b]
            } else {
                [b, a]
            }
        })
        .collect();
    edges.sort_unstable();
    edges
}

/// [`edge_report`] and the use count of every edge (keyed by its two canonical vertex
/// ids, the first vertex at each position).
fn edge_uses(
    indices: &[u32],
    positions: &[[u32; 3]],
) -> (EdgeReport, HashMap<u64, u32, FxBuildHasher>) {
    // Canonical id per vertex: the first vertex with the same position.
    let mut by_position: HashMap<[u32; 3], u32, FxBuildHasher> =
        HashMap::with_capacity_and_hasher(positions.len(), FxBuildHasher);
    let canonical: Vec<u32> = positions
        .iter()
        .enumerate()
        .map(|(i, &p)| *by_position.entry(p).or_insert(i as u32))
        .collect();
    drop(by_position);

    let mut report = EdgeReport::default();
    let mut uses: HashMap<u64, u32, FxBuildHasher> =
        HashMap::with_capacity_and_hasher(indices.len(), FxBuildHasher);
    for tri in indices.chunks_exact(3) {
        report.triangles += 1;
        let ids = [
            canonical.get(tri[0] as usize),
            canonical.get(tri[1] as usize),
            canonical.get(tri[2] as usize),
        ];
        let [Some(&a), Some(&b), Some(&c)] = ids else {
            report.degenerate_triangles += 1;
            continue;
        };
        if a == b || b == c || c == a {
            report.degenerate_triangles += 1;
            continue;
        }
        if collinear(
            positions[a as usize],
            positions[b as usize],
            positions[c as usize],
        ) {
            report.degenerate_triangles += 1;
        }
        for (u, v) in [(a, b), (b, c), (c, a)] {
            let key = (u64::from(u.min(v)) << 32) | u64::from(u.max(v));
            *uses.entry(key).or_insert(0) += 1;
        }
    }
    report.edges = uses.len() as u64;
    for &n in uses.values() {
        match n {
            1 => report.boundary_edges += 1,
            2 => {}
            _ => report.nonmanifold_edges += 1,
        }
    }
    (report, uses)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TET: [[u32; 3]; 4] = [[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]];
    const TET_INDICES: [u32; 12] = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];

    #[test]
    fn boundary_edges_are_listed_by_position() {
        // Why: a cut's holes are judged against the input's own (an open scan): the list
        // must name positions, weld vertices that share one, and match the count.
        let open = &TET_INDICES[..9]; // the tetrahedron without its face 1-2-3
        let mut positions = TET.to_vec();
        positions.push(TET[1]); // a second vertex at position 1, used instead of 1 below
        let idx: Vec<u32> = open.iter().map(|&i| if i == 1 { 4 } else { i }).collect();
        let e = boundary_edges(&idx, &positions);
        let mut want = [[TET[1], TET[2]], [TET[1], TET[3]], [TET[2], TET[3]]].map(|[a, b]| {
            if a < b {
                [a, b]
            } else {
                [b, a]
            }
        });
        want.sort_unstable();
        assert_eq!(e, want);
        assert_eq!(e.len() as u64, edge_report(&idx, &positions).boundary_edges);
        assert!(boundary_edges(&TET_INDICES, &TET).is_empty());
    }

    #[test]
    fn tetrahedron_is_closed() {
        let r = edge_report(&TET_INDICES, &TET);
        assert_eq!(
            r,
            EdgeReport {
                triangles: 4,
                edges: 6,
                boundary_edges: 0,
                nonmanifold_edges: 0,
                degenerate_triangles: 0
            }
        );
        assert!(r.is_closed_manifold());
    }

    #[test]
    fn tetrahedron_with_split_vertices_is_still_closed() {
        // Every face with its own three vertices (as if each were a separate patch with
        // different normals): welding by position recloses it.
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for (i, &v) in TET_INDICES.iter().enumerate() {
            positions.push(TET[v as usize]);
            indices.push(i as u32);
        }
        assert!(edge_report(&indices, &positions).is_closed_manifold());
    }

    #[test]
    fn single_triangle_has_three_boundary_edges() {
        let r = edge_report(&[0, 1, 2], &TET[..3]);
        assert_eq!(
            (r.triangles, r.edges, r.boundary_edges, r.nonmanifold_edges),
            (1, 3, 3, 0)
        );
        assert!(!r.is_closed_manifold());
    }

    #[test]
    fn fan_has_interior_spokes_and_a_boundary_rim() {
        // Centre 0 and a ring of 6 vertices: closed fan of 6 triangles.
        let mut pos = vec![[100, 100, 0]];
        let ring = [
            [200, 100, 0],
            [150, 190, 0],
            [50, 190, 0],
            [0, 100, 0],
            [50, 10, 0],
            [150, 10, 0],
        ];
        pos.extend_from_slice(&ring);
        let closed: Vec<u32> = (0..6).flat_map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect();
        let r = edge_report(&closed, &pos);
        assert_eq!(
            (r.triangles, r.edges, r.boundary_edges, r.nonmanifold_edges),
            (6, 12, 6, 0)
        );
        // An open fan (one wedge missing): two spokes become boundary.
        let open = &closed[..15];
        let r = edge_report(open, &pos);
        assert_eq!((r.triangles, r.edges, r.boundary_edges), (5, 11, 7));
    }

    #[test]
    fn three_triangles_on_one_edge_are_nonmanifold() {
        let pos = [[0, 10, 0], [10, 10, 0], [5, 15, 0], [5, 5, 0], [5, 10, 5]];
        let r = edge_report(&[0, 1, 2, 1, 0, 3, 0, 1, 4], &pos);
        assert_eq!(r.nonmanifold_edges, 1);
        assert_eq!(r.boundary_edges, 6);
        assert_eq!(r.edges, 7);
        assert!(!r.is_closed_manifold());
    }

    #[test]
    fn degenerate_and_invalid_triangles() {
        // Two corners at the same position (distinct indices): no edges counted.
        let pos = [[0, 0, 0], [10, 0, 0], [0, 0, 0], [20, 0, 0]];
        let r = edge_report(&[0, 1, 2], &pos);
        assert_eq!((r.degenerate_triangles, r.edges), (1, 0));
        // Collinear but distinct: degenerate, edges still counted.
        let r = edge_report(&[0, 1, 3], &pos);
        assert_eq!((r.degenerate_triangles, r.edges), (1, 3));
        // Out-of-range index, and a trailing partial triangle.
        let r = edge_report(&[0, 1, 99, 0, 1], &pos);
        assert_eq!((r.triangles, r.degenerate_triangles, r.edges), (1, 1, 0));
        // Extreme grid coordinates do not overflow the area test.
        let big = [[0, 0, 0], [u32::MAX, 0, 0], [0, u32::MAX, u32::MAX]];
        assert_eq!(edge_report(&[0, 1, 2], &big).degenerate_triangles, 0);
    }
}
