//! Shared test fixtures: deterministic pseudo-random data and a realistic terrain patch.
#![allow(dead_code)]

pub mod model;

use tessera_format::PatchData;

pub use tessera_testkit::Rng;

/// The triangles of `indices`, each rotated to start at its smallest vertex (meshopt's
/// index codec may rotate a triangle's vertices).
pub fn rotate_min_first(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks(3)
        .map(|t| {
            // Lexicographically smallest rotation: canonical even for degenerate triangles.
            (0..3)
                .map(|m| [t[m], t[(m + 1) % 3], t[(m + 2) % 3]])
                .min()
                .unwrap()
        })
        .collect()
}

fn normalize(v: [f64; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
}

/// A `cells` x `cells` terrain patch (2 triangles per cell) on a 2^16 grid: vertex
/// spacing `spacing` grid cells, gentle hills plus +-2 cells of noise, normals from the
/// surface, vertex-cache and vertex-fetch optimised like the builder does. With `morph`,
/// every vertex with odd (i + j) moves to its +x neighbour (about half the vertices).
pub fn terrain_patch(cells: usize, spacing: f64, morph: bool, seed: u64) -> PatchData {
    let mut rng = Rng(seed | 1);
    let side = cells + 1;
    let origin = [21000.0, 33000.0, 30000.0];
    let height = |x: f64, y: f64| {
        180.0 * (x * 0.004).sin() * (y * 0.003).cos() + 60.0 * (x * 0.011 + y * 0.007).sin()
    };
    let mut positions = Vec::with_capacity(side * side);
    let mut normals = Vec::with_capacity(side * side);
    for j in 0..side {
        for i in 0..side {
            let (x, y) = (i as f64 * spacing, j as f64 * spacing);
            let z = height(x, y);
            let p = [
                (origin[0] + x) as i64 + rng.jitter(2),
                (origin[1] + y) as i64 + rng.jitter(2),
                (origin[2] + z) as i64 + rng.jitter(2),
            ];
            positions.push([p[0] as u32, p[1] as u32, p[2] as u32]);
            let e = 0.5;
            let dx = (height(x + e, y) - height(x - e, y)) / (2.0 * e);
            let dy = (height(x, y + e) - height(x, y - e)) / (2.0 * e);
            normals.push(normalize([-dx + 0.05 * (rng.unit() - 0.5), -dy, 1.0]));
        }
    }
    let mut indices = Vec::with_capacity(cells * cells * 6);
    for j in 0..cells {
        for i in 0..cells {
            let cell = tessera_gen::grid_cell_triangles(side as u64, i as u64, j as u64);
            indices.extend(cell.into_iter().flatten());
        }
    }
    let morph_targets: Vec<[u32; 3]> = if morph {
        (0..side * side)
            .map(|v| {
                let (i, j) = (v % side, v / side);
                if (i + j) % 2 == 1 {
                    let n = if i + 1 < side { v + 1 } else { v - 1 };
                    positions[n]
                } else {
                    positions[v]
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    let n = positions.len();
    let indices = meshopt::optimize_vertex_cache(&indices, n);
    let remap = meshopt::optimize_vertex_fetch_remap(&indices, n);
    let indices = meshopt::remap_index_buffer(Some(&indices), n, &remap);
    let positions = meshopt::remap_vertex_buffer(&positions, n, &remap);
    let normals = meshopt::remap_vertex_buffer(&normals, n, &remap);
    let morph_targets = if morph {
        meshopt::remap_vertex_buffer(&morph_targets, n, &remap)
    } else {
        morph_targets
    };
    PatchData {
        positions,
        normals,
        colors: Vec::new(),
        uvs: Vec::new(),
        morph_targets,
        indices,
        ..Default::default()
    }
}

/// Component-wise minimum of the positions.
pub fn quant_min(p: &PatchData) -> [u32; 3] {
    let mut m = [u32::MAX; 3];
    for q in &p.positions {
        for k in 0..3 {
            m[k] = m[k].min(q[k]);
        }
    }
    if p.positions.is_empty() {
        [0; 3]
    } else {
        m
    }
}
