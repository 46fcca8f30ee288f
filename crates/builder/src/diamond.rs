//! One diamond's step of the bottom-up construction (ATP section 5.2): merge the patches
//! of the children of every tetrahedron in the diamond, lock the diamond's outer border,
//! simplify as one unit with a quadric metric that weighs normals and colours, record
//! where every child vertex goes (GoLD's geomorphing needs it), and split the result
//! back into the diamond's tetrahedra.

use crate::bounds::Sphere;
use crate::patch::{WorkPatch, WorkVertex};
use rustc_hash::FxHashMap;

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
    /// Weigh normals (false when the builder computed them from the geometry: the
    /// position quadrics already measure what such normals would add, at ~25% of the
    /// simplifier's time).
    pub use_normals: bool,
}

/// The merged mesh of a diamond's children and how to get back to each child.
pub struct Merged {
    pub vertices: Vec<WorkVertex>,
    pub indices: Vec<u32>,
    /// For each child, for each of its vertices, the merged index.
    pub child_maps: Vec<Vec<u32>>,
    /// Position id of every merged vertex (see [`position_ids`]).
    pub pid: Vec<u32>,
}

/// Weld the children into one mesh (bit-identical vertices are the same vertex), and
/// number the distinct positions on the way: one hash lookup per child vertex, keyed by
/// position, with the few vertices sharing a position (attribute seams) chained.
pub fn merge(children: &[&WorkPatch]) -> Merged {
    const END: u32 = u32::MAX;
    let total: usize = children.iter().map(|c| c.vertices.len()).sum();
    let mut by_pos: FxHashMap<[u32; 3], u32> =
        FxHashMap::with_capacity_and_hasher(total, Default::default());
    // Per position id its first merged vertex; per merged vertex the next one at the
    // same position.
    let mut first: Vec<u32> = Vec::with_capacity(total);
    let mut next: Vec<u32> = Vec::with_capacity(total);
    let mut vertices: Vec<WorkVertex> = Vec::with_capacity(total);
    let mut pid: Vec<u32> = Vec::with_capacity(total);
    let mut indices = Vec::with_capacity(children.iter().map(|c| c.indices.len()).sum());
    let mut child_maps = Vec::with_capacity(children.len());
    for c in children {
        let map: Vec<u32> = c
            .vertices
            .iter()
            .map(|v| {
                let new = vertices.len() as u32;
                let p = *by_pos.entry(v.q).or_insert_with(|| {
                    first.push(END);
                    first.len() as u32 - 1
                });
                let mut at = first[p as usize];
                let mut last = END;
                while at != END {
                    if vertices[at as usize].key() == v.key() {
                        return at;
                    }
                    last = at;
                    at = next[at as usize];
                }
                if last == END {
                    first[p as usize] = new;
                } else {
                    next[last as usize] = new;
                }
                vertices.push(*v);
                next.push(END);
                pid.push(p);
                new
            })
            .collect();
        indices.extend(c.indices.iter().map(|&i| map[i as usize]));
        child_maps.push(map);
    }
    Merged {
        vertices,
        indices,
        child_maps,
        pid,
    }
}

/// One id per distinct grid position: vertices that differ only in attributes (a normal
/// or colour seam) share it. Border detection and repair weld by it, so attribute seams
/// are not mistaken for borders.
pub fn position_ids(vertices: &[WorkVertex]) -> Vec<u32> {
    let mut pos_id: FxHashMap<[u32; 3], u32> =
        FxHashMap::with_capacity_and_hasher(vertices.len(), Default::default());
    vertices
        .iter()
        .map(|v| {
            let n = pos_id.len() as u32;
            *pos_id.entry(v.q).or_insert(n)
        })
        .collect()
}

/// An undirected edge between two position ids, as one hash key.
fn edge_key(a: u32, b: u32) -> u64 {
    ((a.min(b) as u64) << 32) | a.max(b) as u64
}

/// Vertices that must not move: every vertex on an edge used by exactly one triangle (or
/// by three or more) of the merged mesh, with vertices welded by position alone
/// ([`position_ids`]) so that attribute seams do not count as borders. Those edges are
/// the diamond's outer border (shared with patches of other diamonds) and the model's own
/// open boundary.
pub fn border_locks(pid: &[u32], indices: &[u32]) -> Vec<bool> {
    let mut edges: FxHashMap<u64, u32> =
        FxHashMap::with_capacity_and_hasher(indices.len(), Default::default());
    for t in indices.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (pid[t[k] as usize], pid[t[(k + 1) % 3] as usize]);
            *edges.entry(edge_key(a, b)).or_default() += 1;
        }
    }
    let positions = pid.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
    let mut locked_pos = vec![false; positions];
    for (&e, &n) in &edges {
        if n != 2 {
            locked_pos[(e >> 32) as usize] = true;
            locked_pos[(e & 0xffff_ffff) as usize] = true;
        }
    }
    pid.iter().map(|&p| locked_pos[p as usize]).collect()
}

/// Simplify the merged mesh towards `target_triangles` with the locks. Returns the new
/// index list (a subset of the merged vertices) and the error in grid units.
pub fn simplify(
    m: &Merged,
    locks: &[bool],
    target_triangles: usize,
    cfg: &SimplifyConfig,
) -> (Vec<u32>, f32) {
    if m.indices.len() / 3 <= target_triangles || m.vertices.is_empty() {
        return (m.indices.clone(), 0.0);
    }
    let positions: Vec<[f32; 3]> = m.vertices.iter().map(|v| v.q.map(|c| c as f32)).collect();
    let stride = 3 * (cfg.use_normals as usize + cfg.has_colors as usize);
    let mut attrs = Vec::with_capacity(m.vertices.len() * stride);
    for v in &m.vertices {
        if cfg.use_normals {
            attrs.extend_from_slice(&v.normal);
        }
        if cfg.has_colors {
            attrs.extend(v.color[..3].iter().map(|&c| c as f32 / 255.0));
        }
    }
    let mut weights = Vec::with_capacity(stride);
    if cfg.use_normals {
        weights.extend_from_slice(&[cfg.normal_weight; 3]);
    }
    if cfg.has_colors {
        weights.extend_from_slice(&[cfg.color_weight; 3]);
    }
    let bytes: &[u8] = bytemuck::cast_slice(&positions);
    let Ok(adapter) = meshopt::VertexDataAdapter::new(bytes, 12, 0) else {
        return (m.indices.clone(), 0.0);
    };
    let mut err = 0.0f32;
    if stride == 0 {
        let out = meshopt::simplify_with_locks(
            &m.indices,
            &adapter,
            locks,
            target_triangles * 3,
            f32::MAX,
            meshopt::SimplifyOptions::ErrorAbsolute,
            Some(&mut err),
        );
        return (out, if err.is_finite() { err } else { 0.0 });
    }
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

/// What [`repair`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RepairCounts {
    pub flipped: u64,
    pub folded_pairs_removed: u64,
}

/// Twice the area vector of a triangle of grid points, exactly (coordinates < 2^22).
fn cross_q(a: [u32; 3], b: [u32; 3], c: [u32; 3]) -> [i64; 3] {
    let u = [
        b[0] as i64 - a[0] as i64,
        b[1] as i64 - a[1] as i64,
        b[2] as i64 - a[2] as i64,
    ];
    let v = [
        c[0] as i64 - a[0] as i64,
        c[1] as i64 - a[1] as i64,
        c[2] as i64 - a[2] as i64,
    ];
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// Repairs defects the simplifier can leave, each of which makes an edge used by four
/// triangles once neighbouring patches are put together:
/// - an "ear" `(A, C, B)` whose edges `AC` and `CB` are both on the diamond's border
///   (locked), next to a triangle `(A, B, D)` across `AB`. The neighbouring diamond sees
///   the same border `A-C-B` and can grow the same ear on its side: the two ears are one
///   triangle twice, a zero-volume fin hung on `AB`. Also a zero-area triangle whose
///   middle corner `C` lies on segment `AB`. Flipping `AB` to `CD` gives `(A, C, D)` and
///   `(C, B, D)`: the border edges `AC` and `CB` are kept, `AB` is gone. A flip that would
///   turn a triangle over (against the normal of `(A, B, D)`) is not done.
/// - a folded pair: two triangles on the same three points with opposite orientation
///   (a zero-volume fin inside one diamond); both are removed, which leaves every other
///   edge's count as is.
///
/// Positions decide (vertices welded by grid point), so attribute seams do not hide a
/// defect. Only interior edges change; the locked border stays as it was.
pub fn repair(vertices: &[WorkVertex], pid: &[u32], indices: &mut Vec<u32>) -> RepairCounts {
    let mut counts = RepairCounts::default();
    let q = |i: u32| vertices[i as usize].q;
    let p = |i: u32| pid[i as usize];
    // Folded pairs: triangles on the same three points, keyed by their sorted position
    // ids; per key the first two triangles and how many there are.
    let mut by_set: FxHashMap<[u32; 3], (u32, u32, u32)> =
        FxHashMap::with_capacity_and_hasher(indices.len() / 3, Default::default());
    for (t, tri) in indices.chunks_exact(3).enumerate() {
        let mut k = [p(tri[0]), p(tri[1]), p(tri[2])];
        k.sort_unstable();
        let e = by_set.entry(k).or_insert((t as u32, u32::MAX, 0));
        if e.2 == 1 {
            e.1 = t as u32;
        }
        e.2 += 1;
    }
    let mut drop = vec![false; indices.len() / 3];
    // Canonical rotation (smallest position id first): the same for two triangles on the
    // same points exactly when they have the same orientation.
    let rotation = |t: u32| {
        let t = t as usize;
        let x = [
            p(indices[3 * t]),
            p(indices[3 * t + 1]),
            p(indices[3 * t + 2]),
        ];
        let r = (0..3).min_by_key(|&k| x[k]).unwrap_or(0);
        [x[r], x[(r + 1) % 3], x[(r + 2) % 3]]
    };
    for &(t0, t1, n) in by_set.values() {
        if n == 2 && rotation(t0) != rotation(t1) {
            drop[t0 as usize] = true;
            drop[t1 as usize] = true;
            counts.folded_pairs_removed += 1;
        }
    }
    if counts.folded_pairs_removed > 0 {
        drop_marked(indices, &drop);
    }
    // Ears: directed edge (vertex indices) -> triangle.
    let directed = |a: u32, b: u32| ((a as u64) << 32) | b as u64;
    let mut edge: FxHashMap<u64, usize> =
        FxHashMap::with_capacity_and_hasher(indices.len(), Default::default());
    for (t, tri) in indices.chunks_exact(3).enumerate() {
        for k in 0..3 {
            edge.insert(directed(tri[k], tri[(k + 1) % 3]), t);
        }
    }
    // Border edges: used once, vertices welded by position.
    let mut uses: FxHashMap<u64, u32> =
        FxHashMap::with_capacity_and_hasher(indices.len(), Default::default());
    for tri in indices.chunks_exact(3) {
        for k in 0..3 {
            *uses
                .entry(edge_key(p(tri[k]), p(tri[(k + 1) % 3])))
                .or_default() += 1;
        }
    }
    let border = |a: u32, b: u32| uses.get(&edge_key(p(a), p(b))) == Some(&1);
    let positions = pid.iter().map(|&x| x as usize + 1).max().unwrap_or(0);
    let mut on_border = vec![false; positions];
    for (&e, &n) in &uses {
        if n == 1 {
            on_border[(e >> 32) as usize] = true;
            on_border[(e & 0xffff_ffff) as usize] = true;
        }
    }
    let dist2 = |a: [u32; 3], b: [u32; 3]| {
        (0..3)
            .map(|i| (a[i] as i64 - b[i] as i64).pow(2))
            .sum::<i64>()
    };
    let dot = |a: [i64; 3], b: [i64; 3]| {
        a[0] as i128 * b[0] as i128 + a[1] as i128 * b[1] as i128 + a[2] as i128 * b[2] as i128
    };
    for t in 0..indices.len() / 3 {
        let tri = [indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]];
        let ids = tri.map(p);
        if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
            continue;
        }
        let pts = tri.map(q);
        // Rotate to (A, C, B), directed edge B -> A to be flipped: for a zero-area
        // triangle the longest edge, for a border ear the one edge not on the border.
        let r = if cross_q(pts[0], pts[1], pts[2]) == [0; 3] {
            (0..3)
                .max_by_key(|&k| dist2(pts[(k + 2) % 3], pts[k]))
                .unwrap_or(0)
        } else {
            match (0..3).find(|&k| {
                !border(tri[(k + 2) % 3], tri[k])
                    && border(tri[k], tri[(k + 1) % 3])
                    && border(tri[(k + 1) % 3], tri[(k + 2) % 3])
            }) {
                Some(k) => k,
                None => continue,
            }
        };
        let (a, c, b) = (tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3]);
        let Some(&t2) = edge.get(&directed(a, b)) else {
            continue;
        };
        let tri2 = [indices[3 * t2], indices[3 * t2 + 1], indices[3 * t2 + 2]];
        let k2 = (0..3).find(|&k| tri2[k] == a).unwrap_or(0);
        if tri2[(k2 + 1) % 3] != b {
            continue;
        }
        let d = tri2[(k2 + 2) % 3];
        let n2 = cross_q(q(a), q(b), q(d));
        // A flip towards a border vertex D makes a triangle with three corners on the
        // border, which the neighbour may mirror: only done when the ear is folded (it
        // faces against the surface normal at C), i.e. when it is the wrong one of a pair.
        let n_ear = cross_q(q(a), q(c), q(b));
        let nc = vertices[c as usize].normal;
        let folded = n_ear
            .iter()
            .zip(nc)
            .map(|(&x, y)| x as f64 * y as f64)
            .sum::<f64>()
            < 0.0;
        if d == c
            || n2 == [0; 3]
            || (on_border[p(d) as usize] && !folded)
            || edge.contains_key(&directed(c, d))
            || edge.contains_key(&directed(d, c))
        {
            continue;
        }
        if dot(cross_q(q(a), q(c), q(d)), n2) <= 0 || dot(cross_q(q(c), q(b), q(d)), n2) <= 0 {
            continue;
        }
        for (x, y) in [(a, c), (c, b), (b, a), (a, b), (b, d), (d, a)] {
            edge.remove(&directed(x, y));
        }
        indices[3 * t..3 * t + 3].copy_from_slice(&[a, c, d]);
        indices[3 * t2..3 * t2 + 3].copy_from_slice(&[c, b, d]);
        for (x, y, tt) in [
            (a, c, t),
            (c, d, t),
            (d, a, t),
            (c, b, t2),
            (b, d, t2),
            (d, c, t2),
        ] {
            edge.insert(directed(x, y), tt);
        }
        counts.flipped += 1;
    }
    counts
}

/// Remove the triangles marked in `drop`, keeping the others in order.
fn drop_marked(indices: &mut Vec<u32>, drop: &[bool]) {
    let mut t = 0;
    indices.retain(|_| {
        let keep = !drop[t / 3];
        t += 1;
        keep
    });
}

/// For every merged vertex, the vertex whose position it moves to at a morph ratio of 1
/// (GoLD's geomorphing): itself if it survived or is locked, else a survivor it can be
/// folded into. `raw` is the simplifier's output, `simplified` the final (repaired) one.
///
/// At a ratio of 1 the children must show exactly the parent's surface, or switching
/// between them pops. meshoptimizer's result is its input triangle list with every vertex
/// replaced by the vertex it was finally collapsed into (transitively) and the triangles
/// that became degenerate dropped; so its collapse map sends every input triangle onto an
/// output triangle or to nothing. It does not report that map: [`retraction`] finds one
/// with the same property. Where it cannot (a position with no known neighbour, or whose
/// target the repair removed), the nearest survivor along edges is taken
/// ([`nearest_survivors`]). Positions decide, so vertices that differ only in attributes
/// move together and a position shared by several children has one target. Locked
/// vertices never move (that keeps morphing crack-free across diamonds).
pub fn morph_destinations(m: &Merged, locks: &[bool], raw: &[u32], simplified: &[u32]) -> Vec<u32> {
    let n = m.vertices.len();
    let positions = m.pid.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
    // Per position: a vertex of the final output there (UNSET: none).
    let mut live = vec![UNSET; positions];
    for &i in simplified {
        live[m.pid[i as usize] as usize] = i;
    }
    let mut fixed = vec![false; positions];
    for &i in raw {
        fixed[m.pid[i as usize] as usize] = true;
    }
    for (i, &l) in locks.iter().enumerate() {
        if l {
            fixed[m.pid[i] as usize] = true;
        }
    }
    let mut pos = vec![[0u32; 3]; positions];
    for (v, &p) in m.vertices.iter().zip(&m.pid) {
        pos[p as usize] = v.q;
    }
    let pid_tris = |ix: &[u32]| -> Vec<[u32; 3]> {
        ix.chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]].map(|i| m.pid[i as usize]))
            .collect()
    };
    let ring = Ring::new(&pid_tris(&m.indices), positions);
    let raw_ring = Ring::new(&pid_tris(raw), positions);
    let mut target = retraction(&ring, &raw_ring, &fixed, &pos);
    for (i, &l) in locks.iter().enumerate() {
        if l {
            let p = m.pid[i] as usize;
            target[p] = p as u32;
        }
    }
    if raw != simplified {
        // The border repair re-triangulated a few places: what maps onto them moves to
        // fit the repaired triangles where it can.
        let final_ring = Ring::new(&pid_tris(simplified), positions);
        let changed: Vec<bool> = (0..positions as u32)
            .map(|p| {
                let (x, y) = (raw_ring.of(p), final_ring.of(p));
                x.len() != y.len() || x.iter().any(|t| !y.contains(t))
            })
            .collect();
        let seeds: Vec<bool> = target
            .iter()
            .enumerate()
            .map(|(p, &t)| !fixed[p] && t != UNSET && changed[t as usize])
            .collect();
        fewer_misfits(&ring, &final_ring, &fixed, &mut target, &seeds);
    }
    // Positions left without a live target: the nearest live one along edges.
    let lost = |p: usize, t: u32| t != p as u32 && (t == UNSET || live[t as usize] == UNSET);
    if target.iter().enumerate().any(|(p, &t)| lost(p, t)) {
        let near = nearest_survivors(&ring, &pos, &live);
        for p in 0..positions {
            if lost(p, target[p]) {
                target[p] = near[p];
            }
        }
    }
    (0..n)
        .map(|i| {
            let p = m.pid[i] as usize;
            let t = target[p];
            if t == p as u32 || t == UNSET || live[t as usize] == UNSET {
                i as u32
            } else {
                live[t as usize]
            }
        })
        .collect()
}

const UNSET: u32 = u32::MAX;

/// The triangles around each position `a`, as `[b, c]` for the triangle `(a, b, c)` (CSR).
struct Ring {
    start: Vec<u32>,
    pairs: Vec<[u32; 2]>,
}

impl Ring {
    fn new(tris: &[[u32; 3]], positions: usize) -> Ring {
        let mut start = vec![0u32; positions + 1];
        for t in tris {
            for &p in t {
                start[p as usize + 1] += 1;
            }
        }
        for i in 0..positions {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut pairs = vec![[0u32; 2]; start[positions] as usize];
        for t in tris {
            for k in 0..3 {
                let a = t[k] as usize;
                pairs[fill[a] as usize] = [t[(k + 1) % 3], t[(k + 2) % 3]];
                fill[a] += 1;
            }
        }
        Ring { start, pairs }
    }

    fn of(&self, a: u32) -> &[[u32; 2]] {
        &self.pairs[self.start[a as usize] as usize..self.start[a as usize + 1] as usize]
    }

    /// The apex `x` of the triangle `(a, b, x)`; [`MULTIPLE`] when there are several (a
    /// non-manifold mesh), [`UNSET`] when none.
    fn apex(&self, a: u32, b: u32) -> u32 {
        let mut x = UNSET;
        for &[y, z] in self.of(a) {
            if y == b {
                x = if x == UNSET { z } else { MULTIPLE };
            }
        }
        x
    }

    /// Whether the triangle `(c, a, b)` is degenerate or one of these, `x` being
    /// [`Ring::apex`]`(a, b)`.
    fn fits(&self, c: u32, [a, b, x]: [u32; 3]) -> bool {
        c == a || c == b || c == x || (x == MULTIPLE && self.of(a).contains(&[b, c]))
    }

    /// The triangles `(p, u, v)` of `self` whose other corners have known targets
    /// `a != b`, as `[a, b, output.apex(a, b)]`. `cache` (one entry per pair of `self`,
    /// initially `[UNSET; 3]`) keeps the last apex found for each triangle.
    fn known(
        &self,
        p: usize,
        target: &[u32],
        output: &Ring,
        cache: &mut [[u32; 3]],
        tris: &mut Vec<[u32; 3]>,
    ) {
        tris.clear();
        let first = self.start[p] as usize;
        for (k, &[u, v]) in self.of(p as u32).iter().enumerate() {
            let (a, b) = (target[u as usize], target[v as usize]);
            if a != UNSET && b != UNSET && a != b {
                let c = &mut cache[first + k];
                if c[0] != a || c[1] != b {
                    *c = [a, b, output.apex(a, b)];
                }
                tris.push(*c);
            }
        }
    }
}

/// [`Ring::apex`] of a non-manifold edge.
const MULTIPLE: u32 = u32::MAX - 1;

/// The scratch of [`retraction`]'s search.
#[derive(Default)]
struct Work {
    /// Positions to judge, and which are on the stack.
    stack: Vec<u32>,
    queued: Vec<bool>,
    /// Positions assigned since the last guess.
    trail: Vec<u32>,
    tris: Vec<[u32; 3]>,
    cands: Vec<u32>,
}

/// What is known around a removed position.
enum Verdict {
    /// No triangle with both other corners known.
    Unknown,
    /// No candidate fits.
    Contradiction,
    One(u32),
    /// Several fit (in the candidate list).
    Several,
}

/// A map from positions to surviving positions under which every input triangle
/// vanishes or becomes an output triangle (same three positions, same winding), so that
/// the children at a morph ratio of 1 show exactly the output surface. `input` and
/// `output` are the triangles around each position; `fixed` positions (survivors,
/// locked) map to themselves; [`UNSET`] where nothing fits.
///
/// The simplifier's own collapse map is one such map (see [`morph_destinations`]); this
/// finds one like it. A removed position `p` in an input triangle `(p, u, v)` whose other
/// corners' targets `a != b` are known goes to `a` or `b` (the triangle vanishes) or to
/// the `x` of an output triangle `(x, a, b)`; a candidate that fits all of `p`'s known
/// triangles is *consistent*. Targets spread from the survivors: a position with exactly
/// one consistent candidate takes it. When that stalls, the next position with several
/// takes the one its quadric (the planes of its input triangles, as the simplifier
/// weighs a collapse) likes best, and the spreading goes on; if that leads to a position
/// with no consistent candidate, everything since is undone and the next candidate tried
/// (the position is left for the end when none works). What is left takes the
/// candidate that fits most of its known triangles.
///
/// On the diamonds of real scans (Bunny, Nefertiti) 0.2-0.3% of the child triangles then
/// land neither on a simplifier triangle nor vanish (the nearest survivor along edges:
/// 12-13%).
fn retraction(input: &Ring, output: &Ring, fixed: &[bool], pos: &[[u32; 3]]) -> Vec<u32> {
    let positions = fixed.len();
    let quadric = quadrics(input, fixed, pos);
    let cost = |p: usize, c: u32| quadric_cost(&quadric[p], pos[p], pos[c as usize]);
    let mut target: Vec<u32> = (0..positions as u32)
        .map(|p| if fixed[p as usize] { p } else { UNSET })
        .collect();
    let fits = |c: u32, t: [u32; 3]| output.fits(c, t);
    let cache = std::cell::RefCell::new(vec![[UNSET; 3]; input.pairs.len()]);
    let known = |p: usize, target: &[u32], tris: &mut Vec<[u32; 3]>| {
        input.known(p, target, output, &mut cache.borrow_mut(), tris)
    };
    let judge = |p: usize, target: &[u32], tris: &mut Vec<[u32; 3]>, cands: &mut Vec<u32>| {
        known(p, target, tris);
        if tris.is_empty() {
            return Verdict::Unknown;
        }
        // A consistent candidate fits the first known triangle: one of its corners or
        // its apex.
        cands.clear();
        let [a, b, x] = tris[0];
        for c in [a, b, x] {
            if c < MULTIPLE && tris[1..].iter().all(|&t| fits(c, t)) {
                cands.push(c);
            }
        }
        if x == MULTIPLE {
            for &[y, c] in output.of(a) {
                if y == b && !cands.contains(&c) && tris[1..].iter().all(|&t| fits(c, t)) {
                    cands.push(c);
                }
            }
        }
        match cands.len() {
            0 => Verdict::Contradiction,
            1 => Verdict::One(cands[0]),
            _ => Verdict::Several,
        }
    };
    let mut w = Work {
        queued: vec![false; positions],
        ..Work::default()
    };
    // After `p` got its target: the neighbours that now know one more triangle (the
    // third corner's target is known too).
    let push_neighbours = |p: usize, target: &[u32], w: &mut Work| {
        for &[u, v] in input.of(p as u32) {
            for (x, other) in [(u, v), (v, u)] {
                if target[x as usize] == UNSET
                    && target[other as usize] != UNSET
                    && !w.queued[x as usize]
                {
                    w.queued[x as usize] = true;
                    w.stack.push(x);
                }
            }
        }
    };
    // Spreads what the stack's positions imply, every assignment on the trail; Err(p)
    // when p has no consistent candidate left.
    let spread = |target: &mut Vec<u32>, w: &mut Work, skip: &[bool]| -> Result<(), u32> {
        while let Some(p) = w.stack.pop() {
            let p = p as usize;
            w.queued[p] = false;
            if target[p] != UNSET || skip[p] {
                continue;
            }
            match judge(p, target, &mut w.tris, &mut w.cands) {
                Verdict::One(c) => {
                    target[p] = c;
                    w.trail.push(p as u32);
                    push_neighbours(p, target, w);
                }
                Verdict::Contradiction => {
                    for &u in &w.stack {
                        w.queued[u as usize] = false;
                    }
                    w.stack.clear();
                    return Err(p as u32);
                }
                Verdict::Unknown | Verdict::Several => {}
            }
        }
        Ok(())
    };
    let mut guesses = Vec::new();
    let mut skip = vec![false; positions];
    for p in (0..positions).rev().filter(|&p| !fixed[p]) {
        w.queued[p] = true;
        w.stack.push(p as u32);
    }
    while let Err(p) = spread(&mut target, &mut w, &skip) {
        // Cannot happen for the simplifier's own map; leave such a position for the end.
        skip[p as usize] = true;
        push_neighbours(p as usize, &target, &mut w);
    }
    loop {
        let mut progress = false;
        for p in 0..positions {
            if target[p] != UNSET
                || skip[p]
                || !matches!(
                    judge(p, &target, &mut w.tris, &mut w.cands),
                    Verdict::Several
                )
            {
                continue;
            }
            guesses.clear();
            guesses.extend_from_slice(&w.cands);
            guesses.sort_by(|&x, &y| cost(p, x).total_cmp(&cost(p, y)));
            skip[p] = true;
            for &c in &guesses {
                w.trail.clear();
                target[p] = c;
                w.trail.push(p as u32);
                push_neighbours(p, &target, &mut w);
                if spread(&mut target, &mut w, &skip).is_ok() {
                    skip[p] = false;
                    progress = true;
                    break;
                }
                for &u in &w.trail {
                    target[u as usize] = UNSET;
                }
            }
        }
        if !progress {
            break;
        }
    }
    // What is left (no consistent candidate, or none known): the candidate that fits
    // most of the known triangles; then each of those positions and their neighbours
    // moves to the candidate with the fewest triangles that neither vanish nor are an
    // output triangle, which lowers their number every time, until none does better.
    let mut left: Vec<u32> = Vec::new();
    for _round in 0..4 {
        let mut changed = false;
        for p in 0..positions {
            if target[p] != UNSET {
                continue;
            }
            known(p, &target, &mut w.tris);
            w.cands.clear();
            for &[u, v] in input.of(p as u32) {
                for c in [target[u as usize], target[v as usize]] {
                    if c != UNSET && !w.cands.contains(&c) {
                        w.cands.push(c);
                    }
                }
            }
            for &[_, _, x] in &w.tris {
                if x < MULTIPLE && !w.cands.contains(&x) {
                    w.cands.push(x);
                }
            }
            let score = |c: u32| w.tris.iter().filter(|&&t| fits(c, t)).count();
            let best = w.cands.iter().copied().max_by(|&x, &y| {
                score(x)
                    .cmp(&score(y))
                    .then(cost(p, y).total_cmp(&cost(p, x)))
            });
            if let Some(c) = best {
                target[p] = c;
                left.push(p as u32);
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let mut seeds = vec![false; positions];
    for &p in &left {
        seeds[p as usize] = true;
        for &[u, v] in input.of(p) {
            seeds[u as usize] = true;
            seeds[v as usize] = true;
        }
    }
    fewer_misfits(input, output, fixed, &mut target, &seeds);
    target
}

/// Moves each non-`fixed` position marked in `seeds` to the candidate (a corner's target
/// or the apex of one of its triangles) under which the fewest of its input triangles
/// neither vanish nor are an output triangle, and on to its neighbours when it moved.
/// Every move lowers the number of such triangles, so this ends.
fn fewer_misfits(input: &Ring, output: &Ring, fixed: &[bool], target: &mut [u32], seeds: &[bool]) {
    let mut queued = seeds.to_vec();
    let mut stack: Vec<u32> = (0..seeds.len() as u32)
        .filter(|&p| seeds[p as usize])
        .collect();
    let mut tris = Vec::new();
    let mut cache = vec![[UNSET; 3]; input.pairs.len()];
    while let Some(p) = stack.pop() {
        let p = p as usize;
        queued[p] = false;
        if fixed[p] {
            continue;
        }
        input.known(p, target, output, &mut cache, &mut tris);
        let misfits = |c: u32| tris.iter().filter(|&&t| !output.fits(c, t)).count();
        let mut best = (misfits(target[p]), target[p]);
        if best.0 == 0 {
            continue;
        }
        for &[a, b, x] in &tris {
            for c in [a, b, x] {
                if c < MULTIPLE {
                    let m = misfits(c);
                    if m < best.0 {
                        best = (m, c);
                    }
                }
            }
        }
        if best.1 != target[p] {
            target[p] = best.1;
            for &[u, v] in input.of(p as u32) {
                for w in [u, v] {
                    if !fixed[w as usize] && !queued[w as usize] {
                        queued[w as usize] = true;
                        stack.push(w);
                    }
                }
            }
        }
    }
}

/// Per position `p` that is not `fixed`: the quadric of the planes of its input
/// triangles (all through `p`), each weighted by its area, in coordinates relative to `p`
/// (`[xx, xy, xz, yy, yz, zz]`).
fn quadrics(input: &Ring, fixed: &[bool], pos: &[[u32; 3]]) -> Vec<[f64; 6]> {
    let rel = |x: [u32; 3], o: [u32; 3]| [0, 1, 2].map(|k| x[k] as f64 - o[k] as f64);
    (0..fixed.len())
        .map(|p| {
            let mut q = [0f64; 6];
            if fixed[p] {
                return q;
            }
            for &[b, c] in input.of(p as u32) {
                let (u, v) = (rel(pos[b as usize], pos[p]), rel(pos[c as usize], pos[p]));
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                let len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
                if len2 > 0.0 {
                    // Unit normal, times the area |n| / 2: n n^T / |n|^2 * |n| / 2.
                    let w = 0.5 / len2.sqrt();
                    let t = [
                        n[0] * n[0],
                        n[0] * n[1],
                        n[0] * n[2],
                        n[1] * n[1],
                        n[1] * n[2],
                        n[2] * n[2],
                    ];
                    for (x, y) in q.iter_mut().zip(t) {
                        *x += y * w;
                    }
                }
            }
            q
        })
        .collect()
}

/// The quadric of `p` (see [`quadrics`]) at `c`: area-weighted squared distances of `c`
/// to the planes of `p`'s triangles.
fn quadric_cost(q: &[f64; 6], p: [u32; 3], c: [u32; 3]) -> f64 {
    let [x, y, z] = [0, 1, 2].map(|k| c[k] as f64 - p[k] as f64);
    q[0] * x * x + q[3] * y * y + q[5] * z * z + 2.0 * (q[1] * x * y + q[2] * x * z + q[4] * y * z)
}

/// Per position, the live position (`live[p] != UNSET`) reached in the fewest edge hops
/// (breadth-first from all of them at once; among those reached in the same round, the
/// nearest in space); [`UNSET`] with none in its component.
fn nearest_survivors(ring: &Ring, pos: &[[u32; 3]], live: &[u32]) -> Vec<u32> {
    let n = live.len();
    let mut dest = vec![UNSET; n];
    let mut frontier: Vec<u32> = Vec::new();
    for (p, &l) in live.iter().enumerate() {
        if l != UNSET {
            dest[p] = p as u32;
            frontier.push(p as u32);
        }
    }
    let at = |p: u32| pos[p as usize].map(|c| c as f64);
    let mut settled: Vec<bool> = dest.iter().map(|&d| d != UNSET).collect();
    let mut best = vec![f64::INFINITY; n];
    let mut next: Vec<u32> = Vec::new();
    while !frontier.is_empty() {
        // Every unsettled neighbour of this round's positions takes the nearest of the
        // destinations offered to it this round.
        for &v in &frontier {
            let target = dest[v as usize];
            for &[a, b] in ring.of(v) {
                for u in [a, b] {
                    let ui = u as usize;
                    if settled[ui] {
                        continue;
                    }
                    let d = crate::bounds::dist2(at(u), at(target));
                    if best[ui] == f64::INFINITY {
                        next.push(u);
                    }
                    if d < best[ui] {
                        best[ui] = d;
                        dest[ui] = target;
                    }
                }
            }
        }
        for &u in &next {
            settled[u as usize] = true;
        }
        std::mem::swap(&mut frontier, &mut next);
        next.clear();
    }
    dest
}

/// Split simplified triangles among the diamond's tetrahedra: `owner(centroid)` says
/// which (index into the diamond's list). Each part gets compact vertices.
pub fn split(
    m: &Merged,
    simplified: &[u32],
    parts: usize,
    mut owner: impl FnMut([[u32; 3]; 3]) -> usize,
) -> Vec<WorkPatch> {
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
    let all: Vec<Sphere> = tight
        .iter()
        .chain(children)
        .copied()
        .filter(|s| s.radius > 0.0 || s.center != [0.0; 3])
        .collect();
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
                p.vertices.push(WorkVertex {
                    q: [x0 + i * 10, j * 10, 0],
                    normal: [0.0, 0.0, 1.0],
                    ..Default::default()
                });
            }
        }
        let w = n + 1;
        for j in 0..n {
            for i in 0..n {
                let a = j * w + i;
                p.indices
                    .extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
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
        assert_eq!(m.pid, position_ids(&m.vertices));
        let locks = border_locks(&m.pid, &m.indices);
        // Only the outer rectangle is locked: 2*(20+10) border vertices.
        assert_eq!(locks.iter().filter(|&&l| l).count(), 60);
    }

    #[test]
    fn simplify_keeps_locked_border_and_hits_target() {
        let a = grid_patch(20, 0);
        let m = merge(&[&a]);
        let locks = border_locks(&position_ids(&m.vertices), &m.indices);
        let cfg = SimplifyConfig {
            node_triangles: 100,
            normal_weight: 0.5,
            color_weight: 0.5,
            has_colors: false,
            use_normals: true,
        };
        let (out, err) = simplify(&m, &locks, 100, &cfg);
        assert!(out.len() / 3 < 800);
        assert!(
            err >= 0.0 && err < 1.0,
            "flat grid simplifies with ~zero error, got {err}"
        );
        let used: std::collections::HashSet<u32> = out.iter().copied().collect();
        for (i, &l) in locks.iter().enumerate() {
            if l {
                assert!(used.contains(&(i as u32)), "locked vertex {i} removed");
            }
        }
        let dest = morph_destinations(&m, &locks, &out, &out);
        for (i, &d) in dest.iter().enumerate() {
            assert!(used.contains(&d), "destination of {i} is not a survivor");
            if used.contains(&(i as u32)) {
                assert_eq!(d, i as u32, "survivors stay put");
            }
        }
    }

    #[test]
    fn children_at_ratio_one_are_the_simplified_surface() {
        // Why: GoLD morphs each child vertex to its destination; at a ratio of 1 the
        // children must be the parent's surface exactly, or the switch pops. The nearest
        // survivor along edges left 13-17% of the triangles off it. Two bumpy grids whose
        // shared column differs in normals: one position, two vertices, one target.
        let bumpy = |mut p: WorkPatch, nz: f32| {
            for v in &mut p.vertices {
                let h = (v.q[0].wrapping_mul(73_856_093) ^ v.q[1].wrapping_mul(19_349_663)) % 7;
                v.q[2] = 100 + h;
                v.normal = [0.0, (1.0 - nz * nz).sqrt(), nz];
            }
            p
        };
        let (a, b) = (
            bumpy(grid_patch(20, 0), 1.0),
            bumpy(grid_patch(20, 200), 0.8),
        );
        let m = merge(&[&a, &b]);
        let locks = border_locks(&m.pid, &m.indices);
        let cfg = SimplifyConfig {
            node_triangles: 300,
            normal_weight: 0.5,
            color_weight: 0.5,
            has_colors: false,
            use_normals: true,
        };
        let (out, _) = simplify(&m, &locks, 300, &cfg);
        assert!(out.len() / 3 <= 400, "{} triangles", out.len() / 3);
        let dest = morph_destinations(&m, &locks, &out, &out);
        let q = |i: u32| m.vertices[i as usize].q;
        let canon = |t: [[u32; 3]; 3]| {
            let r = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
            [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
        };
        let parent: std::collections::HashSet<_> = out
            .chunks_exact(3)
            .map(|t| canon([q(t[0]), q(t[1]), q(t[2])]))
            .collect();
        let mut stray = 0;
        for t in m.indices.chunks_exact(3) {
            let img = [0, 1, 2].map(|k| q(dest[t[k] as usize]));
            if img[0] != img[1] && img[1] != img[2] && img[0] != img[2] {
                stray += !parent.contains(&canon(img)) as usize;
            }
        }
        // Measured: 44 of 1600 (a regular grid has many equally good collapses; the
        // diamonds of real scans 0.2-0.3%); the nearest survivor: 205.
        let all = m.indices.len() / 3;
        assert!(
            stray * 25 <= all,
            "{stray} of {all} child triangles off the parent"
        );
        let positions = m.pid.iter().max().map_or(0, |&p| p as usize + 1);
        assert_eq!(
            m.vertices.len(),
            positions + 21,
            "the shared column is a seam"
        );
        let mut target_of = FxHashMap::default();
        for (i, &d) in dest.iter().enumerate() {
            if locks[i] {
                assert_eq!(d, i as u32, "locked vertex {i} moves");
            }
            let seen = *target_of.entry(m.pid[i]).or_insert(q(d));
            assert_eq!(seen, q(d), "one position, two targets");
        }
    }

    #[test]
    fn repair_flips_collinear_ear_and_drops_folded_pair() {
        // Why: issue 2's crack tests found cuts where an edge was used by four triangles:
        // two neighbouring diamonds each kept a zero-area ear (A, C, B) on their shared,
        // locked border, each next to a triangle across AB.
        let v = |x: u32, y: u32| WorkVertex {
            q: [x, y, 0],
            ..Default::default()
        };
        // A C B on a line (the locked border), D an interior vertex fanned by E, F.
        let verts = vec![v(0, 0), v(2, 0), v(4, 0), v(2, 3), v(0, 6), v(4, 6)];
        let (a, c, b, d, e, f) = (0u32, 1, 2, 3, 4, 5);
        let mut idx = vec![a, c, b, a, b, d, b, f, d, f, e, d, e, a, d];
        let r = repair(&verts, &position_ids(&verts), &mut idx);
        assert_eq!(r.flipped, 1);
        assert_eq!(&idx[..6], &[a, c, d, c, b, d]);
        // Border edges A->C and C->B survive; AB is gone.
        let edges: Vec<(u32, u32)> = idx
            .chunks(3)
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .collect();
        assert!(edges.contains(&(a, c)) && edges.contains(&(c, b)) && !edges.contains(&(a, b)));
        // The same ear next to a border vertex D is left alone: flipping would make a
        // triangle with three border corners.
        let mut idx = vec![a, c, b, a, b, d];
        assert_eq!(
            repair(&verts[..4], &position_ids(&verts[..4]), &mut idx).flipped,
            0
        );
        let mut folded = vec![0u32, 1, 3, 0, 3, 1, 1, 2, 3];
        let r = repair(&verts, &position_ids(&verts), &mut folded);
        assert_eq!(r.folded_pairs_removed, 1);
        assert_eq!(folded, vec![1, 2, 3]);
    }

    #[test]
    fn split_assigns_every_triangle_once() {
        let a = grid_patch(4, 0);
        let m = merge(&[&a]);
        let parts = split(&m, &m.indices, 2, |q| {
            if q[0][0] + q[1][0] + q[2][0] < 60 {
                0
            } else {
                1
            }
        });
        assert_eq!(parts.iter().map(|p| p.triangle_count()).sum::<usize>(), 32);
        assert!(parts.iter().all(|p| p.triangle_count() > 0));
    }
}
