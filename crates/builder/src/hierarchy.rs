//! Stage 3: the bottom-up construction, level by level from the deepest, every diamond of
//! a level in parallel (they touch disjoint tetrahedra), then the node table in (level,
//! Morton) order and the atomic write.
//!
//! Patches move between levels through a temporary spool on disk, so memory holds only
//! the diamonds in flight. A child's final, encoded patch is written when its parent's
//! diamond is processed, because only then are its morph destinations known.

use crate::bounds::Sphere;
use crate::diamond::{self, SimplifyConfig};
use crate::distribute::{self, LevelStats, Plan, RankStats, Unwire, Wire};
use crate::import::Imported;
use crate::partition::{centroid3, parent_id, read_leaf_faces, tet_id, Leaf, Partition, TetId};
use crate::patch::{
    grid_to_local, remove_bad_triangles_noting, CacheOrder, Welder, WorkPatch, WorkVertex,
};
use crate::peers::Peers;
use crate::recut::{self, ChildTexels, RecutTexture};
use crate::texture::Baker;
use crate::texture::TextureReport;
use crate::timing::{Phase, Phases};
use crate::{BuildError, BuildOptions, BuildReport, Progress};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::collections::HashSet;
use std::fs::File;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use tessera_format::{
    encode_patch, write_model_until, Header, NodeRecord, PatchData, PatchSpool, SpooledPatch,
    ATTR_COLORS, ATTR_NORMALS, ATTR_TEXTURE, ATTR_UVS, NODE_FLAG_LEAF, NO_NODE,
};
use tessera_tetra::{DiamondKey, Locator, Tet};

/// Everything known about a node before the table is written.
#[derive(Clone, Debug)]
struct NodeInfo {
    id: TetId,
    leaf: bool,
    /// Stored (f32-rounded, padded) spheres, so saturation holds on what is written.
    tight: Sphere,
    sat: Sphere,
    error: f64,
    cone: [f32; 4],
    vertex_count: u32,
    triangle_count: u32,
    /// Unique per diamond (and per leaf) within the build; renumbered in table order
    /// when written. A rank's ids are `k * ranks + rank`, so ranks never collide.
    diamond: u64,
    quant_min: [u32; 3],
    texture_size: [u16; 2],
    /// The builder's patch (until the parent encodes it).
    work: Option<SpooledPatch>,
    /// A re-cut patch's baked texels ([`crate::recut::RecutTexture`], until encoded).
    recut: Option<SpooledPatch>,
    /// The final encoded patch.
    out: Option<SpooledPatch>,
}

struct Ctx<'a> {
    imp: &'a Imported,
    part: &'a Partition,
    buckets: File,
    leaf_of: FxHashMap<TetId, &'a Leaf>,
    internal: HashSet<TetId>,
    work: PatchSpool,
    out: PatchSpool,
    nodes: Mutex<FxHashMap<TetId, NodeInfo>>,
    /// Diamond ids this rank handed out (see [`NodeInfo::diamond`]).
    diamond_ids: AtomicU64,
    rank: u64,
    ranks: u64,
    degenerate: AtomicU64,
    /// Of `degenerate`: triangles with an area in the input, lost to the grid.
    collapsed: AtomicU64,
    /// Shortest input edge of a collapsed triangle (f64 bits; +inf when none).
    collapsed_min_edge: AtomicU64,
    duplicate: AtomicU64,
    leaf_vertices_loaded: AtomicU64,
    /// Largest squared distance (f64 bits; non-negative floats order like their bits)
    /// of a leaf vertex from `box_center`: the model's bounding sphere.
    leaf_far2: AtomicU64,
    /// Centre of the input's bounding box, local frame.
    box_center: [f64; 3],
    repaired: AtomicU64,
    /// Most faces of an ordinary leaf (`--leaf-triangles`): more is an oversized leaf.
    leaf_cap: u32,
    attributes: u32,
    cfg: SimplifyConfig,
    step: f64,
    phases: Phases,
    /// The texture stage, for models with [`ATTR_TEXTURE`].
    baker: Option<Baker>,
    /// Rank 0 of a distributed build: the texture figures of all ranks together.
    all_textures: Mutex<Option<TextureReport>>,
}

/// Leaf vertices read from the memory-mapped vertex store between two releases of its
/// resident pages (each fault maps up to 16 neighbouring cached pages, so 128k scattered
/// vertices can hold a few hundred MiB resident).
const RELEASE_EVERY_VERTICES: u64 = 1 << 17;

/// Below this many triangles a patch is not reduced further: tiny patches cost more in
/// per-node overhead (draw calls, records) than they save.
const MIN_PATCH_TRIANGLES: usize = 256;

/// How much fewer triangles a parent holds than its children together.
///
/// ATP fills leaves to ~4000 and parents to ~2000, so the first level up already divides
/// by ~4. A surface, though, crosses only ~1.59x more tetrahedra per level down (4x per
/// 3 levels, not 8x), so leaves fill to ~1400-2000 triangles on average, and with a
/// constant patch size each level would hold 1/1.59 of the one below: ~2.7x the input
/// stored in all. Dividing by 3 per level bounds the whole hierarchy near 1.5x the input
/// (patches shrink towards [`MIN_PATCH_TRIANGLES`] at the coarse levels, where there are
/// few of them), which is what keeps the file near 6 bytes per input triangle.
const LEVEL_REDUCTION: usize = 3;

/// Triangles a parent tetrahedron keeps when its children hold `children`.
fn parent_target(children: usize, node_triangles: usize) -> usize {
    (children / LEVEL_REDUCTION)
        .max(children.min(MIN_PATCH_TRIANGLES))
        .min(node_triangles)
}

fn stored(s: &Sphere, scale: f64) -> Sphere {
    Sphere::from_f32(s.to_f32(scale))
}

impl Ctx<'_> {
    fn internal_err(&self, what: &str) -> BuildError {
        BuildError::Internal(what.to_string())
    }

    fn next_diamond_id(&self) -> u64 {
        self.diamond_ids.fetch_add(1, Ordering::Relaxed) * self.ranks + self.rank
    }

    fn quantized(&self, v: u32) -> WorkVertex {
        let q = self.part.quantized.get(v);
        match &self.imp.normals {
            // Computed normals and nothing else per vertex: the full 36-byte record is
            // not needed (the importer's defaults stand for the absent attributes).
            Some(normals) if !self.imp.attributes.colors && !self.imp.attributes.uvs => {
                WorkVertex {
                    q,
                    normal: normals.get(v),
                    color: tessera_mesh::Vertex::default().color,
                    uv: tessera_mesh::Vertex::default().uv,
                    texture: tessera_mesh::NO_TEXTURE,
                }
            }
            _ => {
                let s = self.imp.vertices.get(v);
                WorkVertex {
                    q,
                    normal: self.imp.normal(v, &s),
                    // (Colours ignored by option: white, so they split no vertex.)
                    color: if self.imp.attributes.colors {
                        s.color
                    } else {
                        tessera_mesh::Vertex::default().color
                    },
                    uv: tessera_format::stored_uv(s.uv),
                    texture: if self.baker.is_some() {
                        s.texture
                    } else {
                        tessera_mesh::NO_TEXTURE
                    },
                }
            }
        }
    }

    /// Releases the resident pages of every memory-mapped store.
    fn release(&self) {
        self.imp.release();
        self.part.quantized.release();
    }

    /// Whether the input triangle `f` (global vertex indices) has a non-zero area in the
    /// input's own coordinates: if it does and its corners share grid points, the
    /// quantisation grid lost it. Only called for the (rare) degenerate triangles.
    fn has_area_in_input(&self, f: [u32; 3]) -> bool {
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            return false;
        }
        let p = f.map(|g| self.imp.vertices.get(g).position.map(f64::from));
        let shortest = (0..3)
            .map(|k| crate::bounds::dist2(p[k], p[(k + 1) % 3]))
            .fold(f64::INFINITY, f64::min)
            .sqrt();
        let area = crate::partition::has_area(&p);
        if area && shortest > 0.0 {
            // Non-negative floats order like their bits.
            self.collapsed_min_edge
                .fetch_min(shortest.to_bits(), Ordering::Relaxed);
        }
        area
    }

    /// The faces of an oversized leaf without those whose corners share a grid point,
    /// read and tested a chunk at a time (counted as `degenerate`, and `collapsed` when
    /// they have an area in the input, as [`Ctx::load_leaf`] counts them).
    ///
    /// Why: a leaf is over the limit when its faces crowd a cell the partition cannot
    /// split, mostly because their vertices coincide (issue 29: 3 x 10^7 coincident
    /// vertices and one elsewhere made one leaf of 10^7 faces, whose weld tables took
    /// 1.3 GB under `--memory 64M` and aborted). Its degenerate faces would be removed
    /// after the weld; removed first, they cost one chunk. Ordinary leaves (at most
    /// `leaf_triangles` faces) skip this pass: it would only add a grid lookup per face.
    fn oversized_leaf_faces(&self, leaf: &Leaf) -> Result<Vec<[u32; 3]>, BuildError> {
        const CHUNK: u64 = 1 << 16;
        let qs = &self.part.quantized;
        let mut kept = Vec::new();
        let (mut degenerate, mut collapsed) = (0u64, 0u64);
        let mut at = 0u64;
        while at < leaf.face_count {
            let n = CHUNK.min(leaf.face_count - at);
            let part = Leaf {
                id: leaf.id,
                first_face: leaf.first_face + at,
                face_count: n,
            };
            for f in read_leaf_faces(&self.buckets, &self.part.buckets, &part)? {
                let q = f.map(|i| qs.get(i));
                if q[0] == q[1] || q[1] == q[2] || q[0] == q[2] {
                    degenerate += 1;
                    collapsed += u64::from(self.has_area_in_input(f));
                } else {
                    kept.push(f);
                }
            }
            at += n;
            // The stores are memory-mapped: this pass may touch all of them.
            if (at / CHUNK).is_multiple_of(16) {
                self.release();
            }
        }
        self.degenerate.fetch_add(degenerate, Ordering::Relaxed);
        self.collapsed.fetch_add(collapsed, Ordering::Relaxed);
        Ok(kept)
    }

    /// A leaf's patch from its bucket: weld, clean, optimise.
    fn load_leaf(&self, leaf: &Leaf) -> Result<WorkPatch, BuildError> {
        let mut lap = self.phases.lap();
        let faces = if leaf.face_count > u64::from(self.leaf_cap) {
            self.oversized_leaf_faces(leaf)?
        } else {
            read_leaf_faces(&self.buckets, &self.part.buckets, leaf)?
        };
        let mut local: FxHashMap<u32, u32> =
            FxHashMap::with_capacity_and_hasher(faces.len(), Default::default());
        let mut w = Welder::with_capacity(faces.len());
        let mut indices = Vec::with_capacity(faces.len() * 3);
        for f in &faces {
            for &g in f {
                let id = match local.get(&g) {
                    Some(&id) => id,
                    None => {
                        let id = w.add(&self.quantized(g));
                        local.insert(g, id);
                        id
                    }
                };
                indices.push(id);
            }
        }
        // The vertex store is memory-mapped: release its resident pages every few
        // megabytes of leaves, or RSS would grow towards the size of the whole store.
        let loaded = self
            .leaf_vertices_loaded
            .fetch_add(local.len() as u64, Ordering::Relaxed)
            + local.len() as u64;
        if loaded / RELEASE_EVERY_VERTICES != (loaded - local.len() as u64) / RELEASE_EVERY_VERTICES
        {
            self.release();
        }
        let far2 = w
            .vertices
            .iter()
            .map(|v| crate::bounds::dist2(grid_to_local(v.q, self.step), self.box_center))
            .fold(0.0f64, f64::max);
        self.leaf_far2.fetch_max(far2.to_bits(), Ordering::Relaxed);
        lap.mark(Phase::LeafLoad);
        let mut collapsed = 0u64;
        let c = remove_bad_triangles_noting(&mut indices, &w.vertices, |i| {
            if self.has_area_in_input(faces[i]) {
                collapsed += 1;
            }
        });
        self.degenerate.fetch_add(c.degenerate, Ordering::Relaxed);
        self.collapsed.fetch_add(collapsed, Ordering::Relaxed);
        self.duplicate.fetch_add(c.duplicate, Ordering::Relaxed);
        let mut p = WorkPatch {
            vertices: w.vertices,
            indices,
        };
        lap.mark(Phase::LeafClean);
        p.optimize(CacheOrder::Fifo);
        lap.mark(Phase::LeafOptimize);
        Ok(p)
    }

    fn leaf_info(&self, id: TetId, p: &WorkPatch) -> NodeInfo {
        let tight = stored(&p.tight_sphere(self.step), self.part.grid.size);
        NodeInfo {
            id,
            leaf: true,
            tight,
            sat: tight,
            error: 0.0,
            cone: p.normal_cone(),
            vertex_count: p.vertices.len() as u32,
            triangle_count: p.triangle_count() as u32,
            diamond: self.next_diamond_id(),
            quant_min: quant_min(&p.vertices),
            texture_size: [0, 0],
            work: None,
            recut: None,
            out: None,
        }
    }

    /// Encode a node's final patch (with its morph targets) into the output spool. With
    /// `keep` (its parent is re-cut) returns what the parent's bake reads of it.
    fn emit(
        &self,
        id: TetId,
        p: &WorkPatch,
        morph: Vec<[u32; 3]>,
        keep: bool,
    ) -> Result<Option<ChildTexels>, BuildError> {
        let baked = match &self.baker {
            Some(b) if !p.vertices.is_empty() => {
                let (error, leaf, recut) = {
                    let nodes = self
                        .nodes
                        .lock()
                        .map_err(|_| self.internal_err("poisoned node map"))?;
                    let n = nodes
                        .get(&id)
                        .ok_or_else(|| self.internal_err("emit of unknown node"))?;
                    (n.error, n.leaf, n.recut)
                };
                Some(match recut {
                    Some(sp) => {
                        let t = RecutTexture::from_bytes(&self.work.read(&sp)?)
                            .ok_or_else(|| self.internal_err("corrupt temporary texture"))?;
                        b.encode_recut(t.unencoded(&p.vertices), leaf)?
                    }
                    None => b.bake(&p.vertices, &p.indices, error, self.step, leaf)?,
                })
            }
            _ => None,
        };
        let kept = match (&baked, keep) {
            (Some(b), true) => Some(ChildTexels::of(p, b, &morph, self.step)),
            _ => None,
        };
        let texture_size = baked.as_ref().map_or([0, 0], |b| {
            [b.texture.width as u16, b.texture.height as u16]
        });
        let (charts, chart_ids, texture, chart_planes) = match baked {
            Some(b) => (b.charts, b.chart_ids, Some(b.texture), b.planes),
            None => (vec![], vec![], None, vec![]),
        };
        let data = PatchData {
            positions: p.vertices.iter().map(|v| v.q).collect(),
            normals: p.vertices.iter().map(|v| v.normal).collect(),
            colors: if self.attributes & ATTR_COLORS != 0 {
                p.vertices.iter().map(|v| v.color).collect()
            } else {
                vec![]
            },
            uvs: if self.attributes & ATTR_UVS != 0 {
                p.vertices.iter().map(|v| v.uv).collect()
            } else {
                vec![]
            },
            morph_targets: morph,
            indices: p.indices.clone(),
            charts,
            chart_ids,
            texture,
            chart_planes,
        };
        let qmin = quant_min(&p.vertices);
        let sp = self
            .out
            .append(&encode_patch(&data, self.attributes, qmin))?;
        let mut nodes = self
            .nodes
            .lock()
            .map_err(|_| self.internal_err("poisoned node map"))?;
        let n = nodes
            .get_mut(&id)
            .ok_or_else(|| self.internal_err("emit of unknown node"))?;
        n.out = Some(sp);
        n.quant_min = qmin;
        n.texture_size = texture_size;
        n.work = None;
        n.recut = None;
        Ok(kept)
    }

    /// Re-cuts a leaf of a fragmented atlas (see `crate::recut`): its seams welded, its
    /// own charts, a texture at its source texels' density baked from the source cut.
    /// The baked texels' place in the work spool; `None` (the leaf unchanged) when the
    /// leaf has no textured triangles.
    fn recut_leaf(&self, b: &Baker, p: &mut WorkPatch) -> Result<Option<SpooledPatch>, BuildError> {
        let cut = b.texels_of(&p.vertices, &p.indices, self.step)?;
        let source = ChildTexels::of(p, &cut, &[], self.step);
        if !source.texel.is_finite() {
            return Ok(None);
        }
        let w = recut::weld_uv_seams(&diamond::merge(&[&*p]));
        let mut welded = WorkPatch {
            vertices: w.vertices,
            indices: w.indices,
        };
        let frames = recut::parametrise(&mut welded, self.step);
        if frames.len() > tessera_format::MAX_PATCH_CHARTS {
            // Keeps the source cut (a leaf this crumpled is rare and small).
            return Ok(None);
        }
        welded.optimize(CacheOrder::Fifo);
        let align = crate::texture::codec_align(b.codec());
        let baked = recut::bake_fitting(
            &welded,
            &frames,
            std::slice::from_ref(&source),
            source.texel,
            align,
            0.0,
        )
        .map_err(BuildError::Internal)?;
        *p = welded;
        Ok(Some(self.work.append(&baked.to_bytes())?))
    }

    /// Load a child's patch: leaves from their bucket (registering the node), internal
    /// nodes from the work spool.
    fn load_child(&self, id: TetId) -> Result<Option<WorkPatch>, BuildError> {
        if let Some(leaf) = self.leaf_of.get(&id) {
            let mut p = self.load_leaf(leaf)?;
            let recut = match &self.baker {
                Some(b) if b.recuts() && recut::fragmented(&p.vertices) => {
                    self.recut_leaf(b, &mut p)?
                }
                _ => None,
            };
            let mut info = self.leaf_info(id, &p);
            info.recut = recut;
            self.nodes
                .lock()
                .map_err(|_| self.internal_err("poisoned node map"))?
                .insert(id, info);
            return Ok(Some(p));
        }
        if !self.internal.contains(&id) {
            return Ok(None);
        }
        let sp = {
            let nodes = self
                .nodes
                .lock()
                .map_err(|_| self.internal_err("poisoned node map"))?;
            nodes
                .get(&id)
                .and_then(|n| n.work)
                .ok_or_else(|| self.internal_err("child patch missing"))?
        };
        let bytes = self.work.read(&sp)?;
        WorkPatch::from_bytes(&bytes)
            .map(Some)
            .ok_or_else(|| self.internal_err("corrupt temporary patch"))
    }

    /// One diamond (ATP 5.2).
    fn process_diamond(&self, tets: &[Tet]) -> Result<(), BuildError> {
        let mut lap = self.phases.lap();
        // 1. The children of every tetrahedron of the diamond.
        let mut kids: Vec<(TetId, WorkPatch)> = Vec::new();
        let mut per_tet_tris = vec![0usize; tets.len()];
        for (ti, t) in tets.iter().enumerate() {
            for c in t.children() {
                if let Some(p) = self.load_child(tet_id(&c))? {
                    per_tet_tris[ti] += p.triangle_count();
                    kids.push((tet_id(&c), p));
                }
            }
        }
        lap.mark(Phase::Children);
        // 2. Merge, lock the outer border, simplify.
        let refs: Vec<&WorkPatch> = kids.iter().map(|k| &k.1).collect();
        let seamed = diamond::merge(&refs);
        lap.mark(Phase::Merge);
        let target: usize = per_tet_tris
            .iter()
            .map(|&n| parent_target(n, self.cfg.node_triangles))
            .sum();
        // Textured models: a diamond whose source seams hold its simplification back,
        // or whose children were re-cut, is re-cut (see `crate::recut`): simplified with
        // the seams welded, its new patches given charts of their own.
        let child_recut = self.baker.is_some()
            && kids
                .iter()
                .any(|(_, p)| p.vertices.iter().any(|v| recut::is_recut(v.texture)));
        let fragmented = self.baker.as_ref().is_some_and(Baker::recuts)
            && !child_recut
            && recut::fragmented(&seamed.vertices);
        let mut seam_bound = None;
        if !child_recut && !fragmented {
            let locks = diamond::border_locks(&seamed.pid, &seamed.indices);
            lap.mark(Phase::BorderLocks);
            let (raw, err) = diamond::simplify(&seamed, &locks, target, &self.cfg);
            lap.mark(Phase::Simplify);
            seam_bound = Some((locks, raw, err));
        }
        let recut = self.baker.as_ref().is_some_and(Baker::recuts)
            && (child_recut
                || fragmented
                || seam_bound.as_ref().is_some_and(|(_, raw, _)| {
                    recut::held_back(raw.len() / 3, target, seamed.indices.len() / 3)
                }));
        let (welded, locks, raw, err_grid) = match seam_bound {
            Some((locks, raw, err)) if !recut => (None, locks, raw, err),
            _ => {
                let w = recut::weld_uv_seams(&seamed);
                let locks = diamond::border_locks(&w.pid, &w.indices);
                lap.mark(Phase::BorderLocks);
                let (raw, err) = diamond::simplify(&w, &locks, target, &self.cfg);
                lap.mark(Phase::Simplify);
                (Some(w), locks, raw, err)
            }
        };
        let merged = welded.as_ref().unwrap_or(&seamed);
        let mut simplified = raw.clone();
        let fixed = diamond::repair(&merged.vertices, &merged.pid, &mut simplified);
        lap.mark(Phase::Repair);
        self.repaired.fetch_add(
            fixed.flipped + fixed.folded_pairs_removed,
            Ordering::Relaxed,
        );
        // 3. Morph destinations; the children are now complete and can be written.
        let dest = diamond::morph_destinations(merged, &locks, &raw, &simplified);
        drop(raw);
        lap.mark(Phase::Morph);
        let mut child_err = 0.0f64;
        let mut kid_texels = 0u64;
        let mut balls = Vec::new();
        let mut kept: Vec<ChildTexels> = Vec::new();
        for (k, (id, p)) in kids.iter().enumerate() {
            let morph: Vec<[u32; 3]> = merged.child_maps[k]
                .iter()
                .map(|&mi| merged.vertices[dest[mi as usize] as usize].q)
                .collect();
            if let Some(c) = self.emit(*id, p, morph, recut)? {
                kept.push(c);
            }
            let nodes = self
                .nodes
                .lock()
                .map_err(|_| self.internal_err("poisoned node map"))?;
            let n = nodes
                .get(id)
                .ok_or_else(|| self.internal_err("child info missing"))?;
            child_err = child_err.max(n.error);
            kid_texels += u64::from(n.texture_size[0]) * u64::from(n.texture_size[1]);
            balls.push(n.sat);
        }
        lap.mark(Phase::Emit);
        // 4. Split into the parent tetrahedra.
        let level = tets[0].level;
        let grid = self.part.grid;
        let centroids: Vec<[i64; 3]> = tets.iter().map(|t| t.centroid4()).collect();
        let keys: Vec<u64> = tets.iter().map(|t| t.dfs_key()).collect();
        let mut loc = Locator::new(level, 3);
        let owner = |q: [[u32; 3]; 3]| -> usize {
            let c = centroid3(&grid, q);
            if let Some(k) = loc.locate(c) {
                if let Some(i) = keys.iter().position(|&m| m == k) {
                    return i;
                }
            }
            // Outside the diamond (the simplified surface moved a little): nearest
            // tetrahedron centre. Any choice is crack-free, since the tetrahedra of a
            // diamond are always drawn together.
            let d = |i: usize| {
                (0..3)
                    .map(|a| ((c[a] * 4 - centroids[i][a] * 3) as f64).powi(2))
                    .sum::<f64>()
            };
            (0..tets.len())
                .min_by(|&a, &b| d(a).total_cmp(&d(b)))
                .unwrap_or(0)
        };
        let mut parts = diamond::split(merged, &simplified, tets.len(), owner);
        lap.mark(Phase::Split);
        // 5. Bounds and saturation.
        let error = err_grid as f64 * self.step + child_err;
        let frames: Vec<Vec<recut::ChartFrame>> = if recut {
            parts
                .iter_mut()
                .map(|p| recut::parametrise(p, self.step))
                .collect()
        } else {
            Vec::new()
        };
        if let Some(f) = frames
            .iter()
            .find(|f| f.len() > tessera_format::MAX_PATCH_CHARTS)
        {
            return Err(BuildError::Internal(format!(
                "a re-cut patch needs {} texture charts (at most {}): build with \
                 --no-recut or a smaller --node-triangles",
                f.len(),
                tessera_format::MAX_PATCH_CHARTS
            )));
        }
        let mut tights = Vec::with_capacity(parts.len());
        for p in parts.iter_mut() {
            p.optimize(CacheOrder::Table);
            let s = (!p.indices.is_empty()).then(|| stored(&p.tight_sphere(self.step), grid.size));
            if let Some(s) = s {
                balls.push(s);
            }
            tights.push(s);
        }
        // Textured models: raised until the parts' textures fit their texel budget, so
        // that a coarse patch is refined before its texels show (issue 11). Raised here,
        // before the error is stored, so that it is saturated like the rest: the parent
        // adds it to its own through `child_err`, and the diamond's mates share it.
        let floor = kept.iter().map(|c| c.texel).fold(f64::INFINITY, f64::min);
        let error = match &self.baker {
            Some(b) if recut => {
                let plans: Vec<_> = frames
                    .iter()
                    .map(|f| b.plan_recut(f.iter().map(|c| c.extent).collect(), floor))
                    .collect();
                crate::texture::budgeted_error(&plans, error, kid_texels)
            }
            Some(b) => {
                let plans = parts
                    .iter()
                    .map(|p| b.plan(&p.vertices, &p.indices, self.step))
                    .collect::<Result<Vec<_>, _>>()?;
                crate::texture::budgeted_error(&plans, error, kid_texels)
            }
            None => error,
        };
        lap.mark(Phase::Optimize);
        // Re-cut patches: their textures baked now, from the children just emitted.
        let mut recut_textures: Vec<Option<SpooledPatch>> = vec![None; parts.len()];
        if let (Some(b), true) = (&self.baker, recut) {
            let align = crate::texture::codec_align(b.codec());
            for (i, p) in parts.iter().enumerate() {
                if p.indices.is_empty() {
                    continue;
                }
                let texel = recut::texel_for(error, floor);
                let baked = recut::bake_fitting(p, &frames[i], &kept, texel, align, error)
                    .map_err(BuildError::Internal)?;
                recut_textures[i] = Some(self.work.append(&baked.to_bytes())?);
            }
        }
        drop(kept);
        lap.mark(Phase::Recut);
        let sat = stored(&Sphere::of_balls(&balls), grid.size);
        let diamond_id = self.next_diamond_id();
        for ((t, (p, tight)), recut) in tets
            .iter()
            .zip(parts.iter().zip(tights))
            .zip(recut_textures)
        {
            let work = self.work.append(&p.to_bytes())?;
            let info = NodeInfo {
                id: tet_id(t),
                leaf: false,
                tight: tight.unwrap_or(Sphere {
                    center: sat.center,
                    radius: 0.0,
                }),
                sat,
                error: (error as f32) as f64,
                cone: p.normal_cone(),
                vertex_count: p.vertices.len() as u32,
                triangle_count: p.triangle_count() as u32,
                diamond: diamond_id,
                quant_min: quant_min(&p.vertices),
                texture_size: [0, 0],
                work: Some(work),
                recut,
                out: None,
            };
            self.nodes
                .lock()
                .map_err(|_| self.internal_err("poisoned node map"))?
                .insert(tet_id(t), info);
        }
        lap.mark(Phase::Spool);
        Ok(())
    }
}

/// The counters a rank keeps while it simplifies, summed (or min/max-ed) on rank 0.
#[derive(Default)]
struct Counters {
    degenerate: u64,
    collapsed: u64,
    collapsed_min_edge: f64,
    duplicate: u64,
    leaf_far2: f64,
    repaired: u64,
    textures: Option<TextureReport>,
}

impl Counters {
    fn write(&self, w: &mut Wire) {
        w.u64(self.degenerate);
        w.u64(self.collapsed);
        w.f64(self.collapsed_min_edge);
        w.u64(self.duplicate);
        w.f64(self.leaf_far2);
        w.u64(self.repaired);
        match &self.textures {
            None => w.u8(0),
            Some(t) => {
                w.u8(1);
                for v in texture_counts(t) {
                    w.u64(v);
                }
                w.u64(t.unreadable_images.len() as u64);
                for u in &t.unreadable_images {
                    w.str(u);
                }
            }
        }
    }

    fn read(r: &mut Unwire) -> Result<Counters, BuildError> {
        let mut c = Counters {
            degenerate: r.u64()?,
            collapsed: r.u64()?,
            collapsed_min_edge: r.f64()?,
            duplicate: r.u64()?,
            leaf_far2: r.f64()?,
            repaired: r.u64()?,
            textures: None,
        };
        if r.u8()? == 1 {
            let mut v = [0u64; 10];
            for x in v.iter_mut() {
                *x = r.u64()?;
            }
            let mut t = TextureReport {
                source_images: v[0],
                source_texels: v[1],
                crops: v[2],
                atlases: v[3],
                solid_only: v[4],
                recut: v[5],
                downsampled_to_fit: v[6],
                texels: v[7],
                leaf_texels: v[8],
                bytes: v[9],
                ..Default::default()
            };
            for _ in 0..r.u64()? {
                t.unreadable_images.push(r.str()?);
            }
            c.textures = Some(t);
        }
        Ok(c)
    }

    /// Adds another rank's counters (texture decodes add up: each rank decodes the
    /// images its own patches need).
    fn add(&mut self, o: Counters) {
        self.degenerate += o.degenerate;
        self.collapsed += o.collapsed;
        self.collapsed_min_edge = self.collapsed_min_edge.min(o.collapsed_min_edge);
        self.duplicate += o.duplicate;
        self.leaf_far2 = self.leaf_far2.max(o.leaf_far2);
        self.repaired += o.repaired;
        if let (Some(a), Some(b)) = (&mut self.textures, o.textures) {
            let sum: Vec<u64> = texture_counts(a)
                .iter()
                .zip(texture_counts(&b))
                .map(|(x, y)| x + y)
                .collect();
            a.source_images = sum[0];
            a.source_texels = sum[1];
            a.crops = sum[2];
            a.atlases = sum[3];
            a.solid_only = sum[4];
            a.recut = sum[5];
            a.downsampled_to_fit = sum[6];
            a.texels = sum[7];
            a.leaf_texels = sum[8];
            a.bytes = sum[9];
            a.unreadable_images.extend(b.unreadable_images);
            a.unreadable_images.sort();
            a.unreadable_images.dedup();
        }
    }
}

fn texture_counts(t: &TextureReport) -> [u64; 10] {
    [
        t.source_images,
        t.source_texels,
        t.crops,
        t.atlases,
        t.solid_only,
        t.recut,
        t.downsampled_to_fit,
        t.texels,
        t.leaf_texels,
        t.bytes,
    ]
}

impl NodeInfo {
    /// The record and its patches' bytes (`work`, `recut`, `out`: read from this rank's
    /// spools), for another rank.
    fn write(&self, w: &mut Wire, blobs: [Option<&[u8]>; 3]) {
        let (r, l, p) = self.id;
        w.u8(r);
        w.u8(l);
        w.u64(p);
        w.u8(self.leaf as u8);
        for s in [&self.tight, &self.sat] {
            for c in s.center {
                w.f64(c);
            }
            w.f64(s.radius);
        }
        w.f64(self.error);
        for c in self.cone {
            w.f32(c);
        }
        w.u32(self.vertex_count);
        w.u32(self.triangle_count);
        w.u64(self.diamond);
        for q in self.quant_min {
            w.u32(q);
        }
        w.u16(self.texture_size[0]);
        w.u16(self.texture_size[1]);
        for b in blobs {
            w.blob(b);
        }
    }

    /// What [`NodeInfo::write`] wrote, its patches appended to this rank's spools.
    fn read(r: &mut Unwire, work: &PatchSpool, out: &PatchSpool) -> Result<NodeInfo, BuildError> {
        let id = (r.u8()?, r.u8()?, r.u64()?);
        let leaf = r.u8()? != 0;
        let mut sphere = || -> Result<Sphere, BuildError> {
            Ok(Sphere {
                center: [r.f64()?, r.f64()?, r.f64()?],
                radius: r.f64()?,
            })
        };
        let tight = sphere()?;
        let sat = sphere()?;
        let mut n = NodeInfo {
            id,
            leaf,
            tight,
            sat,
            error: r.f64()?,
            cone: [r.f32()?, r.f32()?, r.f32()?, r.f32()?],
            vertex_count: r.u32()?,
            triangle_count: r.u32()?,
            diamond: r.u64()?,
            quant_min: [r.u32()?, r.u32()?, r.u32()?],
            texture_size: [r.u16()?, r.u16()?],
            work: None,
            recut: None,
            out: None,
        };
        n.work = r.blob()?.map(|b| work.append(b)).transpose()?;
        n.recut = r.blob()?.map(|b| work.append(b)).transpose()?;
        n.out = r.blob()?.map(|b| out.append(b)).transpose()?;
        Ok(n)
    }
}

impl Ctx<'_> {
    /// After a level: the messages for every rank. The children this rank's diamonds
    /// just emitted go to rank 0 (which writes them), the diamonds' new nodes to the
    /// rank of their parent's diamond; both leave this rank's node map.
    fn outgoing(&self, mine: &[&Vec<Tet>], plan: &Plan) -> Result<Vec<Vec<u8>>, BuildError> {
        let rank = self.rank as usize;
        let mut out: Vec<Wire> = (0..self.ranks).map(|_| Wire::default()).collect();
        let mut counts = vec![0u64; out.len()];
        let mut nodes = self
            .nodes
            .lock()
            .map_err(|_| self.internal_err("poisoned node map"))?;
        let read = |sp: &Option<SpooledPatch>, spool: &PatchSpool| {
            sp.as_ref().map(|sp| spool.read(sp)).transpose()
        };
        for d in mine {
            for t in d.iter() {
                if rank != 0 {
                    for c in t.children() {
                        if let Some(n) = nodes.remove(&tet_id(&c)) {
                            let bytes = read(&n.out, &self.out)?;
                            n.write(&mut out[0], [None, None, bytes.as_deref()]);
                            counts[0] += 1;
                        }
                    }
                }
                let id = tet_id(t);
                let to = plan.next_owner(id);
                if to != rank {
                    if let Some(n) = nodes.remove(&id) {
                        let work = read(&n.work, &self.work)?;
                        let recut = read(&n.recut, &self.work)?;
                        n.write(&mut out[to], [work.as_deref(), recut.as_deref(), None]);
                        counts[to] += 1;
                    }
                }
            }
        }
        Ok(out
            .into_iter()
            .zip(counts)
            .map(|(w, n)| {
                let mut m = n.to_le_bytes().to_vec();
                m.extend_from_slice(&w.bytes);
                m
            })
            .collect())
    }

    /// The nodes other ranks sent this one after a level, into its node map and spools.
    fn incoming(&self, got: &[Vec<u8>]) -> Result<(), BuildError> {
        let mut nodes = self
            .nodes
            .lock()
            .map_err(|_| self.internal_err("poisoned node map"))?;
        for (from, m) in got.iter().enumerate() {
            if from == self.rank as usize {
                continue;
            }
            let mut r = Unwire::new(m, from);
            for _ in 0..r.u64()? {
                let n = NodeInfo::read(&mut r, &self.work, &self.out)?;
                nodes.insert(n.id, n);
            }
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters {
            degenerate: self.degenerate.load(Ordering::Relaxed),
            collapsed: self.collapsed.load(Ordering::Relaxed),
            collapsed_min_edge: f64::from_bits(self.collapsed_min_edge.load(Ordering::Relaxed)),
            duplicate: self.duplicate.load(Ordering::Relaxed),
            leaf_far2: f64::from_bits(self.leaf_far2.load(Ordering::Relaxed)),
            repaired: self.repaired.load(Ordering::Relaxed),
            textures: self.baker.as_ref().map(Baker::report),
        }
    }

    /// Rank 0: every rank's counters (its own included, sent to itself) into this
    /// context's, and every rank's figures.
    fn absorb_counters(&self, got: &[Vec<u8>]) -> Result<Vec<RankStats>, BuildError> {
        let mut all = Counters {
            collapsed_min_edge: f64::INFINITY,
            textures: self.baker.as_ref().map(|_| TextureReport::default()),
            ..Default::default()
        };
        let mut ranks = Vec::new();
        for (from, m) in got.iter().enumerate() {
            let mut r = Unwire::new(m, from);
            all.add(Counters::read(&mut r)?);
            ranks.push(RankStats::read(&mut r)?);
        }
        self.degenerate.store(all.degenerate, Ordering::Relaxed);
        self.collapsed.store(all.collapsed, Ordering::Relaxed);
        self.collapsed_min_edge
            .store(all.collapsed_min_edge.to_bits(), Ordering::Relaxed);
        self.duplicate.store(all.duplicate, Ordering::Relaxed);
        self.leaf_far2
            .store(all.leaf_far2.to_bits(), Ordering::Relaxed);
        self.repaired.store(all.repaired, Ordering::Relaxed);
        *self
            .all_textures
            .lock()
            .map_err(|_| self.internal_err("poisoned texture report"))? = all.textures;
        Ok(ranks)
    }

    /// The counters into the report (before [`finalize`], which reads some of them).
    fn report_into(&self, report: &mut BuildReport) -> Result<(), BuildError> {
        let c = self.counters();
        report.degenerate_triangles_removed = c.degenerate;
        report.triangles_collapsed_by_grid = c.collapsed;
        report.quant_bits_to_keep_all = (c.collapsed > 0)
            .then(|| crate::partition::bits_for_edge(self.part.grid.size, c.collapsed_min_edge));
        report.duplicate_triangles_removed = c.duplicate;
        report.simplifier_repairs = c.repaired;
        let merged = self
            .all_textures
            .lock()
            .map_err(|_| self.internal_err("poisoned texture report"))?
            .take();
        report.textures = merged.or(c.textures);
        Ok(())
    }
}

fn quant_min(v: &[WorkVertex]) -> [u32; 3] {
    if v.is_empty() {
        return [0; 3];
    }
    std::array::from_fn(|a| v.iter().map(|x| x.q[a]).min().unwrap_or(0))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn build_hierarchy(
    imp: &Imported,
    part: &Partition,
    tmp: &Path,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
    report: &mut BuildReport,
    peers: &dyn Peers,
) -> Result<(), BuildError> {
    let cancelled = || progress.cancelled();
    let made = new_ctx(imp, part, tmp, opts, peers);
    let (ctx, mut by_level) = distribute::agree(peers, made, &cancelled)?;
    // Every level's diamonds in a deterministic order (results do not depend on it,
    // ids do), known to every rank, so that each can tell who owns what.
    let levels: Vec<Vec<Vec<Tet>>> = by_level
        .iter_mut()
        .map(|m| {
            let mut diamonds: Vec<Vec<Tet>> = std::mem::take(m).into_values().collect();
            for d in diamonds.iter_mut() {
                d.sort_by_key(|t| (t.root, t.path));
            }
            diamonds.sort_by_key(|d| (d[0].root, d[0].path));
            diamonds
        })
        .collect();
    drop(by_level);
    let plan = Plan::new(&levels, peers.size());
    let rank = peers.rank();
    let mut stats = RankStats {
        rank: rank as u32,
        stage_seconds: report.stage_seconds.clone(),
        ..Default::default()
    };
    let total_diamonds: usize = levels.iter().map(Vec::len).sum();
    progress.stage("simplify diamonds", total_diamonds as u64);
    // An error of this rank is carried to the next exchange point, so that no rank
    // waits for one that gave up.
    let mut pending: Result<(), BuildError> = Ok(());
    for level in (0..levels.len()).rev() {
        let mine: Vec<&Vec<Tet>> = levels[level]
            .iter()
            .filter(|d| plan.owner(tet_id(&d[0])) == rank)
            .collect();
        let t = std::time::Instant::now();
        pending = pending.and_then(|()| {
            mine.par_iter().try_for_each(|d| {
                if progress.cancelled() {
                    return Err(BuildError::Interrupted);
                }
                let r = ctx.process_diamond(d);
                progress.advance(1);
                r
            })
        });
        // The other ranks' diamonds count as done (their progress is theirs to show).
        progress.advance((levels[level].len() - mine.len()) as u64);
        ctx.release();
        let work_seconds = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let mut level_stats = LevelStats {
            level: level as u32,
            diamonds: mine.len() as u64,
            work_seconds,
            ..Default::default()
        };
        if peers.size() > 1 {
            let out = pending.and_then(|()| ctx.outgoing(&mine, &plan));
            level_stats.bytes_sent = sent_bytes(&out, rank);
            let got = distribute::settle(peers, out, &cancelled)?;
            level_stats.bytes_received = received_bytes(&got, rank);
            pending = ctx.incoming(&got);
        }
        level_stats.exchange_seconds = t.elapsed().as_secs_f64();
        tracing::info!(
            level,
            diamonds = mine.len(),
            seconds = work_seconds,
            exchange_seconds = level_stats.exchange_seconds,
            "diamond level done"
        );
        stats.levels.push(level_stats);
    }
    progress.finish_stage();
    ctx.phases.log();
    // Roots: encode (no morph targets); unsplit roots are leaves, loaded here. Rank 0
    // (which received every root) does it.
    if rank == 0 {
        pending = pending.and_then(|()| {
            for r in 0..6u8 {
                let id = (r, 0u8, 0u64);
                if let Some(p) = ctx.load_child(id)? {
                    ctx.emit(id, &p, Vec::new(), false)?;
                }
            }
            Ok(())
        });
    }
    if peers.size() > 1 {
        // The counters and every rank's figures, to rank 0.
        stats.peak_rss_bytes = crate::peak_rss_bytes().unwrap_or(0);
        let out = pending.map(|()| {
            let mut w = Wire::default();
            ctx.counters().write(&mut w);
            stats.write(&mut w);
            let mut out = vec![Vec::new(); peers.size()];
            out[0] = w.bytes;
            out
        });
        let got = distribute::settle(peers, out, &cancelled)?;
        if rank != 0 {
            // Rank 0 writes; the others learn how that went and return the same.
            return distribute::agree(peers, Ok(()), &cancelled);
        }
        let written = ctx
            .absorb_counters(&got)
            .map(|ranks| report.ranks = ranks)
            .and_then(|()| ctx.report_into(report))
            .and_then(|()| finalize(&ctx, output, opts, progress, report));
        return distribute::agree(peers, written, &cancelled);
    }
    pending?;
    ctx.report_into(report)?;
    finalize(&ctx, output, opts, progress, report)
}

fn sent_bytes(out: &Result<Vec<Vec<u8>>, BuildError>, rank: usize) -> u64 {
    out.as_ref().map_or(0, |o| {
        o.iter()
            .enumerate()
            .filter(|&(r, _)| r != rank)
            .map(|(_, m)| m.len() as u64)
            .sum()
    })
}

fn received_bytes(got: &[Vec<u8>], rank: usize) -> u64 {
    got.iter()
        .enumerate()
        .filter(|&(r, _)| r != rank)
        .map(|(_, m)| m.len() as u64)
        .sum()
}

/// The build's context and its internal tetrahedra by level and diamond.
type Levels = Vec<FxHashMap<DiamondKey, Vec<Tet>>>;

fn new_ctx<'a>(
    imp: &'a Imported,
    part: &'a Partition,
    tmp: &Path,
    opts: &BuildOptions,
    peers: &dyn Peers,
) -> Result<(Ctx<'a>, Levels), BuildError> {
    // Internal nodes: split tetrahedra with at least one triangle below them.
    let mut internal: HashSet<TetId> = HashSet::new();
    for l in &part.leaves {
        let mut id = parent_id(l.id);
        while let Some(p) = id {
            if !internal.insert(p) {
                break;
            }
            id = parent_id(p);
        }
    }
    let mut by_level: Levels = Vec::new();
    for &(r, l, p) in &internal {
        let t = Tet::from_path(r, l, p)
            .ok_or_else(|| BuildError::Internal("bad tetrahedron".into()))?;
        if by_level.len() <= l as usize {
            by_level.resize_with(l as usize + 1, FxHashMap::default);
        }
        by_level[l as usize].entry(t.diamond()).or_default().push(t);
    }
    let textured = imp.attributes.uvs && imp.attributes.textures && !opts.ignore_textures;
    let attributes = ATTR_NORMALS
        | if imp.attributes.colors {
            ATTR_COLORS
        } else {
            0
        }
        | if imp.attributes.uvs { ATTR_UVS } else { 0 }
        | if textured { ATTR_TEXTURE } else { 0 };
    let ctx = Ctx {
        imp,
        part,
        buckets: File::open(&part.buckets).map_err(|e| BuildError::io(&part.buckets, e))?,
        leaf_of: part.leaves.iter().map(|l| (l.id, l)).collect(),
        internal,
        work: PatchSpool::new(tmp)?,
        out: PatchSpool::new(tmp)?,
        nodes: Mutex::new(FxHashMap::default()),
        diamond_ids: AtomicU64::new(0),
        rank: peers.rank() as u64,
        ranks: peers.size() as u64,
        degenerate: AtomicU64::new(0),
        collapsed: AtomicU64::new(0),
        collapsed_min_edge: AtomicU64::new(f64::INFINITY.to_bits()),
        duplicate: AtomicU64::new(0),
        leaf_vertices_loaded: AtomicU64::new(0),
        leaf_far2: AtomicU64::new(0f64.to_bits()),
        box_center: std::array::from_fn(|i| {
            0.5 * (imp.bounds.min[i] + imp.bounds.max[i]) - part.grid.origin[i]
        }),
        repaired: AtomicU64::new(0),
        leaf_cap: opts.leaf_triangles,
        attributes,
        cfg: SimplifyConfig {
            node_triangles: opts.node_triangles as usize,
            normal_weight: 0.5,
            color_weight: opts.color_weight,
            has_colors: imp.attributes.colors,
            use_normals: !imp.normals_computed,
        },
        step: part.grid.step(),
        phases: Phases::default(),
        baker: textured.then(|| {
            Baker::new(
                imp.report.textures.clone(),
                opts.texture,
                opts.memory_bytes / 2,
            )
            .spool_in(tmp)
        }),
        all_textures: Mutex::new(None),
    };
    Ok((ctx, by_level))
}

fn finalize(
    ctx: &Ctx,
    output: &Path,
    opts: &BuildOptions,
    progress: &dyn Progress,
    report: &mut BuildReport,
) -> Result<(), BuildError> {
    progress.stage("write", 0);
    let nodes = std::mem::take(&mut *ctx.nodes.lock().map_err(|_| ctx.internal_err("poisoned"))?);
    let mut infos: Vec<(u64, NodeInfo)> = nodes
        .into_values()
        .map(|n| {
            let m = Tet::from_path(n.id.0, n.id.1, n.id.2)
                .map(|t| t.morton())
                .unwrap_or(0);
            (m, n)
        })
        .collect();
    infos.sort_by_key(|(m, n)| (n.id.1, *m, n.id.0, n.id.2));
    // Diamond ids were handed out in completion order, which varies between runs:
    // renumber them in table order so that a build is reproducible byte for byte.
    let mut diamond_ids: FxHashMap<u64, u64> = FxHashMap::default();
    for (_, n) in infos.iter_mut() {
        let next = diamond_ids.len() as u64;
        n.diamond = *diamond_ids.entry(n.diamond).or_insert(next);
    }
    let index: FxHashMap<TetId, u32> = infos
        .iter()
        .enumerate()
        .map(|(i, (_, n))| (n.id, i as u32))
        .collect();
    let grid = ctx.part.grid;
    let mut records = Vec::with_capacity(infos.len());
    let mut patches = Vec::with_capacity(infos.len());
    let mut max_error = 0.0f32;
    let mut levels = 0u32;
    let mut root_balls = Vec::new();
    let mut leaf_balls = Vec::new();
    for (_, n) in &infos {
        let (r, l, p) = n.id;
        let child = |c: u64| {
            index
                .get(&(r, l + 1, p | (c << l)))
                .copied()
                .unwrap_or(NO_NODE)
        };
        let rec = NodeRecord {
            tet_path: p,
            vertex_count: n.vertex_count,
            triangle_count: n.triangle_count,
            children: [child(0), child(1)],
            parent: parent_id(n.id)
                .and_then(|pid| index.get(&pid).copied())
                .unwrap_or(NO_NODE),
            diamond: u32::try_from(n.diamond)
                .map_err(|_| ctx.internal_err("more than 2^32 diamonds"))?,
            level: l,
            root: r,
            flags: if n.leaf { NODE_FLAG_LEAF } else { 0 },
            error: n.error as f32,
            tight_sphere: n.tight.to_f32(grid.size),
            saturated_sphere: n.sat.to_f32(grid.size),
            normal_cone: n.cone,
            quant_min: n.quant_min,
            texture_size: n.texture_size,
            ..Default::default()
        };
        max_error = max_error.max(rec.error);
        levels = levels.max(l as u32 + 1);
        if l == 0 {
            root_balls.push(n.sat);
        }
        if n.leaf {
            // Leaves hold the full-resolution input: their tight balls give a tight
            // model sphere (the roots' saturated balls are nested, so much looser).
            leaf_balls.push(n.tight);
        }
        report.stored_triangles += n.triangle_count as u64;
        report.leaves += n.leaf as u64;
        records.push(rec);
        patches.push(
            n.out
                .ok_or_else(|| ctx.internal_err("node without an encoded patch"))?,
        );
    }
    let bs = if leaf_balls.is_empty() {
        Sphere::of_balls(&root_balls)
    } else {
        // Two valid spheres around the full-resolution geometry, the smaller wins: the
        // ball of the leaves' balls, and the bounding box's centre with the farthest
        // leaf vertex. Plus the quantisation error, so it holds the input vertices too.
        let qerr = grid.max_error();
        let mut s = Sphere::of_balls(&leaf_balls);
        let far = f64::from_bits(ctx.leaf_far2.load(Ordering::Relaxed)).sqrt();
        if far.is_finite() && far < s.radius {
            s = Sphere {
                center: ctx.box_center,
                radius: far,
            };
        }
        s.radius += qerr;
        s
    };
    let header = Header {
        attributes: ctx.attributes,
        texture_codec: ctx.baker.as_ref().map_or(0, |b| b.codec() as u32),
        quant_bits: grid.bits,
        input_vertices: ctx.imp.vertex_count,
        input_triangles: ctx.imp.face_count,
        cube_origin: grid.origin,
        cube_size: grid.size,
        bounding_sphere: [
            bs.center[0] + grid.origin[0],
            bs.center[1] + grid.origin[1],
            bs.center[2] + grid.origin[2],
            bs.radius,
        ],
        root_count: root_balls.len() as u32,
        level_count: levels,
        max_error,
        leaf_triangles_max: opts.leaf_triangles,
        node_triangles_target: opts.node_triangles,
        page_nodes: opts.index_page_nodes,
        ..bytemuck::Zeroable::zeroed()
    };
    // Every triangle degenerate (coincident vertices, zero areas, corners on one grid
    // point): an empty model is no model (issue 29, item 7). Refused before anything is
    // written, so nothing is left at the output.
    if report.stored_triangles == 0 {
        let finer = report.quant_bits_to_keep_all.filter(|&b| b > grid.bits);
        return Err(BuildError::AllDegenerate {
            input: ctx.imp.input.clone(),
            triangles: ctx.imp.face_count,
            why: format!(
                "two corners on one point of the {}-bit quantisation grid{}",
                grid.bits,
                finer.map_or(String::new(), |b| format!(
                    "; some have an area in the input: --quant-bits {b} keeps them"
                ))
            ),
        });
    }
    match write_model_until(output, &header, &records, &patches, &ctx.out, &|| {
        progress.cancelled()
    }) {
        Err(tessera_format::FormatError::Interrupted) => return Err(BuildError::Interrupted),
        other => other?,
    }
    progress.finish_stage();
    report.nodes = records.len() as u64;
    report.levels = levels;
    report.max_error = max_error as f64;
    report.quant_bits = grid.bits;
    report.mean_edge = ctx.part.mean_edge;
    report.quant_step = grid.step();
    report.quant_error_max = grid.max_error();
    report.output_bytes = std::fs::metadata(output)
        .map_err(|e| BuildError::io(output, e))?
        .len();
    Ok(())
}
