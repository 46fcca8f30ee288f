//! Re-cut textures (GoLD, section 3.3): a coarse patch of a fragmented atlas gets its own
//! parametrisation and a texture baked from its children, so it is not bound to the
//! source atlas's seams.
//!
//! A photogrammetry or room-capture atlas cuts the surface into thousands of small
//! charts, and the vertices are split along every chart border. Simplification must keep
//! those seams (dragging a vertex across one would smear texels of another chart over
//! the triangle), so a diamond whose children are mostly seams barely simplifies: on a
//! real room capture the roots kept 60k of 182k triangles. Where that happens the
//! hierarchy *re-cuts* the diamond ([`held_back`]): it welds the seams
//! ([`weld_uv_seams`]) and simplifies the geometry alone, then each new patch is
//! parametrised afresh ([`parametrise`]: charts grown over the patch's triangles while
//! their normals stay within [`MAX_CHART_ANGLE_DEG`] of the chart's mean normal, each
//! projected orthographically onto the plane of that normal and rotated to its principal
//! axes), and its texture is baked ([`bake`]) by projecting the diamond's children, with
//! their own textures, onto every chart: each texel takes the colour of the child
//! surface nearest along the chart's axis, bilinearly sampled from the child's mip level
//! closest to the parent's texel. The children's textures are at hand because the
//! diamond step bakes them just before (their parent gives them their morph targets).
//! Texels no child covers (gutters, slivers) are filled by dilation.
//!
//! Every ancestor of a re-cut patch is re-cut too (its children have no source UVs).
//! Re-cut vertices sample the texture of their own chart of their own patch:
//! `WorkVertex::texture` is [`RECUT`] with the chart's index, and the stored chart's
//! image is [`RECUT_IMAGE`]; the "source UV" a reader decodes is the vertex's position
//! in the chart's plane, in model units from the chart's corner. As for every textured
//! patch, a morph target's UV is that of the vertex at the target's position in the
//! same chart of the same patch (`tessera_render::morph_targets`), so geomorphing never
//! reads another chart.
//!
//! Written here: no crate on crates.io charts and bakes a mesh onto its own
//! simplification out of core (xatlas, through C++ bindings, parametrises but does not
//! bake, and would add a C++ toolchain to the build).

use rustc_hash::FxHashMap;
pub use tessera_format::RECUT_IMAGE;
use tessera_format::{texels, TextureChart, MAX_TEXTURE_DIM};
use tessera_mesh::NO_TEXTURE;

use crate::diamond::{position_ids, Merged};
use crate::patch::{WorkPatch, WorkVertex};
use crate::texture::encode::BakedTexture;
use crate::texture::pack::{cell, pack, Rect, GUTTER};
pub use crate::texture::pack::{chart_cells, planned_texels};
pub use crate::texture::plan::texel_for;

/// `WorkVertex::texture` of a re-cut vertex: this bit with its chart's index in the low
/// 16 bits (source texture indices stay far below it).
pub const RECUT: u32 = 0x8000_0000;

/// Largest angle between a triangle's normal and its chart's mean normal: small enough
/// that no chart folds over itself in its projection, large enough that a smooth
/// surface takes few charts (measured on the fragmented bunny: 40 degrees doubles the
/// charts, 70 lets some fold).
pub const MAX_CHART_ANGLE_DEG: f64 = 55.0;

/// A seam-bound simplification that kept more than this many times its target is held
/// back by the source atlas's seams (see [`held_back`]).
pub const HELD_BACK: f64 = 1.5;

/// A patch whose source seams split more than this share of its vertices (vertices
/// over distinct positions with their normal and colour, minus one) is *fragmented*
/// and re-cut whatever its simplification does ([`fragmented`]); leaves included, whose
/// texture is then resampled at the source's texel density (42.5 dB against the source
/// cut, close up, on the fragmented bunny). Measured over leaves and diamonds: the YCB
/// scissors' atlas 0.00-0.19 (median 0.10), so its leaves keep the source texels
/// unaltered; generated atlases of 200-triangle charts 0.14-0.41 (median 0.26-0.28),
/// of 40-triangle charts 0.44-0.60.
pub const FRAGMENTED: f64 = 0.2;

/// Whether the source seams split more than [`FRAGMENTED`] of `vertices`.
pub fn fragmented(vertices: &[WorkVertex]) -> bool {
    let mut keys: rustc_hash::FxHashSet<[u32; 7]> =
        rustc_hash::FxHashSet::with_capacity_and_hasher(vertices.len(), Default::default());
    for v in vertices {
        keys.insert(weld_key(v));
    }
    vertices.len() as f64 > (1.0 + FRAGMENTED) * keys.len() as f64
}

/// What [`weld_uv_seams`] welds by: position, normal and colour.
fn weld_key(v: &WorkVertex) -> [u32; 7] {
    let n = v.normal.map(f32::to_bits);
    [
        v.q[0],
        v.q[1],
        v.q[2],
        n[0],
        n[1],
        n[2],
        u32::from_le_bytes(v.color),
    ]
}

/// Whether vertex texture `t` is a re-cut chart's.
#[inline]
pub fn is_recut(t: u32) -> bool {
    t != NO_TEXTURE && t & RECUT != 0
}

/// The chart index of re-cut vertex texture `t`.
#[inline]
pub fn chart_of(t: u32) -> usize {
    (t & 0xFFFF) as usize
}

/// Whether a diamond should be re-cut: its seam-bound simplification kept `kept`
/// triangles of `input` for a `target` (more than [`HELD_BACK`] x the target, when the
/// target was below the input).
pub fn held_back(kept: usize, target: usize, input: usize) -> bool {
    target < input && kept as f64 > HELD_BACK * target as f64
}

/// The merged mesh with its UV seams welded: vertices that differ only in UV or texture
/// become one (positions, normals and colours still split vertices). The welded
/// vertices carry no UV yet ([`parametrise`] gives them their charts').
pub fn weld_uv_seams(m: &Merged) -> Merged {
    let mut by_key: FxHashMap<[u32; 7], u32> =
        FxHashMap::with_capacity_and_hasher(m.vertices.len(), Default::default());
    let mut vertices: Vec<WorkVertex> = Vec::with_capacity(m.vertices.len());
    let remap: Vec<u32> = m
        .vertices
        .iter()
        .map(|v| {
            *by_key.entry(weld_key(v)).or_insert_with(|| {
                vertices.push(WorkVertex {
                    uv: [0.0, 0.0],
                    texture: RECUT,
                    ..*v
                });
                vertices.len() as u32 - 1
            })
        })
        .collect();
    let indices = m.indices.iter().map(|&i| remap[i as usize]).collect();
    let child_maps = m
        .child_maps
        .iter()
        .map(|c| c.iter().map(|&i| remap[i as usize]).collect())
        .collect();
    let pid = position_ids(&vertices);
    Merged {
        vertices,
        indices,
        child_maps,
        pid,
    }
}

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
fn unit(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
}

/// One chart of a re-cut patch: the plane it is projected onto.
#[derive(Clone, Debug)]
pub struct ChartFrame {
    /// Unit normal of the plane (the chart's area-weighted mean normal), and the plane's
    /// axes (`t x b = axis`).
    pub axis: V3,
    pub t: V3,
    pub b: V3,
    /// The chart's lowest coordinates along `t` and `b`: a vertex's UV is its
    /// coordinates from there, in model units.
    pub min: [f64; 2],
    /// The chart's size along `t` and `b`, model units.
    pub extent: [f64; 2],
    /// The same map as the file stores it (`PatchData::chart_planes`): UV of grid
    /// position `q` from `q - qmin`, `qmin` the patch's lowest grid corner.
    pub plane: [f32; 8],
    pub qmin: [u32; 3],
    pub step: f64,
}

impl ChartFrame {
    /// Grid position `q` in the chart: plane coordinates (model units from its corner,
    /// as the file's plane gives them) and the height along its axis.
    fn project(&self, q: [u32; 3]) -> (f64, f64, f64) {
        let r = [0, 1, 2].map(|k| f64::from(q[k]) - f64::from(self.qmin[k]));
        let [u, v] = tessera_format::chart_plane_at(&self.plane, r);
        (u, v, dot(q.map(|c| c as f64 * self.step), self.axis))
    }
}

/// Gives patch `p` (its vertices welded across the source seams) its own charts:
/// triangles grown into charts over shared edges while their normals stay within
/// [`MAX_CHART_ANGLE_DEG`] of the chart's mean normal, a triangle its chart's projection
/// would flip moved to a chart of its own; every vertex copied once per chart it is in,
/// with its UV in that chart's plane and texture `RECUT | chart`. Returns the charts.
pub fn parametrise(p: &mut WorkPatch, step: f64) -> Vec<ChartFrame> {
    let pos: Vec<V3> = p
        .vertices
        .iter()
        .map(|v| v.q.map(|c| c as f64 * step))
        .collect();
    let tris: Vec<[usize; 3]> = p
        .indices
        .chunks_exact(3)
        .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
        .collect();
    // Area vectors (twice the area, along the normal).
    let area: Vec<V3> = tris
        .iter()
        .map(|t| cross(sub(pos[t[1]], pos[t[0]]), sub(pos[t[2]], pos[t[0]])))
        .collect();
    // Triangles around every edge (by position, so attribute splits do not cut charts).
    let pid = position_ids(&p.vertices);
    let mut edges: FxHashMap<u64, Vec<u32>> = FxHashMap::default();
    for (ti, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (pid[t[k]], pid[t[(k + 1) % 3]]);
            let key = ((a.min(b) as u64) << 32) | a.max(b) as u64;
            edges.entry(key).or_default().push(ti as u32);
        }
    }
    let cos_max = MAX_CHART_ANGLE_DEG.to_radians().cos();
    const NONE: usize = usize::MAX;
    let mut chart = vec![NONE; tris.len()];
    let mut sums: Vec<V3> = Vec::new();
    let mut queue = std::collections::VecDeque::new();
    for seed in 0..tris.len() {
        if chart[seed] != NONE {
            continue;
        }
        let c = sums.len();
        chart[seed] = c;
        let mut sum = area[seed];
        queue.push_back(seed);
        while let Some(ti) = queue.pop_front() {
            let t = tris[ti];
            for k in 0..3 {
                let (a, b) = (pid[t[k]], pid[t[(k + 1) % 3]]);
                let key = ((a.min(b) as u64) << 32) | a.max(b) as u64;
                for &nb in &edges[&key] {
                    let nb = nb as usize;
                    if chart[nb] != NONE {
                        continue;
                    }
                    let fits = match (unit(area[nb]), unit(sum)) {
                        (Some(n), Some(m)) => dot(n, m) >= cos_max,
                        // A triangle without area fits anywhere; a chart without one
                        // takes the first that has.
                        _ => true,
                    };
                    if fits {
                        chart[nb] = c;
                        sum = [0, 1, 2].map(|i| sum[i] + area[nb][i]);
                        queue.push_back(nb);
                    }
                }
            }
        }
        sums.push(sum);
    }
    // Axes; triangles their chart's projection would flip get charts of their own.
    let mut axes: Vec<V3> = sums
        .iter()
        .map(|&s| unit(s).unwrap_or([0.0, 0.0, 1.0]))
        .collect();
    for ti in 0..tris.len() {
        let c = chart[ti];
        if norm(area[ti]) > 0.0 && dot(area[ti], axes[c]) <= 0.0 {
            chart[ti] = axes.len();
            axes.push(unit(area[ti]).unwrap_or([0.0, 0.0, 1.0]));
        }
    }
    // Vertices of every chart, in first-use order.
    let n_charts = axes.len();
    let mut copy: FxHashMap<(u32, u32), u32> = FxHashMap::default();
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); n_charts];
    let mut vertices: Vec<WorkVertex> = Vec::new();
    let mut indices = Vec::with_capacity(p.indices.len());
    for (ti, t) in tris.iter().enumerate() {
        let c = chart[ti];
        for &v in t {
            let id = *copy.entry((v as u32, c as u32)).or_insert_with(|| {
                members[c].push(v);
                vertices.push(WorkVertex {
                    texture: RECUT | c as u32,
                    ..p.vertices[v]
                });
                vertices.len() as u32 - 1
            });
            indices.push(id);
        }
    }
    // Each chart's plane, rotated to the principal axes of its vertices (a tighter
    // rectangle), and the vertices' UVs in it (through the plane as stored: f32).
    let qmin = p
        .vertices
        .iter()
        .fold([u32::MAX; 3], |m, v| [0, 1, 2].map(|k| m[k].min(v.q[k])));
    let frames: Vec<ChartFrame> = (0..n_charts)
        .map(|c| {
            let axis = axes[c];
            let helper = if axis[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let t0 = unit(cross(axis, helper)).unwrap_or([1.0, 0.0, 0.0]);
            let b0 = cross(axis, t0);
            let pts: Vec<[f64; 2]> = members[c]
                .iter()
                .map(|&v| [dot(pos[v], t0), dot(pos[v], b0)])
                .collect();
            let n = pts.len().max(1) as f64;
            let mean = [0, 1].map(|k| pts.iter().map(|p| p[k]).sum::<f64>() / n);
            let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
            for p in &pts {
                let (x, y) = (p[0] - mean[0], p[1] - mean[1]);
                sxx += x * x;
                syy += y * y;
                sxy += x * y;
            }
            let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
            let (s, co) = angle.sin_cos();
            let t = [0, 1, 2].map(|i| co * t0[i] + s * b0[i]);
            let b = cross(axis, t);
            let mut min = [f64::INFINITY; 2];
            let mut max = [f64::NEG_INFINITY; 2];
            for &v in &members[c] {
                let uv = [dot(pos[v], t), dot(pos[v], b)];
                for k in 0..2 {
                    min[k] = min[k].min(uv[k]);
                    max[k] = max[k].max(uv[k]);
                }
            }
            let o = qmin.map(|c| c as f64 * step);
            let plane = [
                (t[0] * step) as f32,
                (t[1] * step) as f32,
                (t[2] * step) as f32,
                (dot(o, t) - min[0]) as f32,
                (b[0] * step) as f32,
                (b[1] * step) as f32,
                (b[2] * step) as f32,
                (dot(o, b) - min[1]) as f32,
            ];
            ChartFrame {
                axis,
                t,
                b,
                min,
                extent: [max[0] - min[0], max[1] - min[1]],
                plane,
                qmin,
                step,
            }
        })
        .collect();
    for v in vertices.iter_mut() {
        let f = &frames[chart_of(v.texture)];
        let (u, w, _) = f.project(v.q);
        v.uv = [u as f32, w as f32];
    }
    p.vertices = vertices;
    p.indices = indices;
    frames
}

/// A child of a re-cut diamond as the bake reads it: its triangles in model space, each
/// vertex's coordinate in the child's texture and the grid position of its morph target
/// (which says which of the new patches' charts it lands in), and the texture's mip
/// chain.
pub struct ChildTexels {
    /// Grid positions, and the same in model units.
    pub q: Vec<[u32; 3]>,
    pub positions: Vec<V3>,
    pub uvs: Vec<[f32; 2]>,
    pub targets: Vec<[u32; 3]>,
    pub indices: Vec<u32>,
    /// Level 0 and its box-filtered mips: (width, height, RGBA8).
    pub levels: Vec<(u32, u32, Vec<u8>)>,
    /// Model-space size of a level-0 texel (infinite without textured triangles).
    pub texel: f64,
}

impl ChildTexels {
    /// Child patch `p` with its texture `b` and its vertices' morph targets (`targets`;
    /// empty: their own positions).
    pub fn of(p: &WorkPatch, b: &BakedTexture, targets: &[[u32; 3]], step: f64) -> ChildTexels {
        let q: Vec<[u32; 3]> = p.vertices.iter().map(|v| v.q).collect();
        ChildTexels::new(
            q.clone(),
            step,
            p.vertices
                .iter()
                .zip(&b.chart_ids)
                .map(|(v, &c)| b.charts[c as usize].map(v.uv))
                .collect(),
            if targets.len() == q.len() {
                targets.to_vec()
            } else {
                q
            },
            p.indices.clone(),
            b.texture.width,
            b.texture.height,
            b.rgba.clone(),
        )
    }

    /// `q` (grid positions, `step` model units apart), `uvs` (in the texture, 0..1),
    /// `targets`, `indices` and the child's `width` x `height` RGBA8 texture.
    #[allow(clippy::too_many_arguments)]
    fn new(
        q: Vec<[u32; 3]>,
        step: f64,
        uvs: Vec<[f32; 2]>,
        targets: Vec<[u32; 3]>,
        indices: Vec<u32>,
        width: u32,
        height: u32,
        rgba: Vec<u8>,
    ) -> ChildTexels {
        let positions: Vec<V3> = q.iter().map(|p| p.map(|c| c as f64 * step)).collect();
        let (mut model_area, mut texel_area) = (0.0, 0.0);
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
            let u = [a, b, c].map(|i| {
                [
                    uvs[i][0] as f64 * width as f64,
                    uvs[i][1] as f64 * height as f64,
                ]
            });
            let ta = ((u[1][0] - u[0][0]) * (u[2][1] - u[0][1])
                - (u[2][0] - u[0][0]) * (u[1][1] - u[0][1]))
                .abs();
            // Solid-colour charts map a triangle to a point.
            if ta > 1e-9 {
                texel_area += ta;
                model_area += norm(cross(
                    sub(positions[b], positions[a]),
                    sub(positions[c], positions[a]),
                ));
            }
        }
        let texel = if texel_area > 0.0 && model_area > 0.0 {
            (model_area / texel_area).sqrt()
        } else {
            f64::INFINITY
        };
        let mut levels = vec![(width, height, rgba)];
        for (l, m) in texels::mip_chain(&levels[0].2, width, height)
            .into_iter()
            .enumerate()
        {
            let (w, h) = texels::level_size(width, height, l as u32 + 1);
            levels.push((w, h, m));
        }
        ChildTexels {
            q,
            positions,
            uvs,
            targets,
            indices,
            levels,
            texel,
        }
    }

    /// Trilinear sample at texture coordinate `uv` for a footprint of `texel` model
    /// units: the mip chain at level `log2(texel / own texel)`, as the GPU samples the
    /// child while it morphs in at its parent's texel detail (docs/morph.md), so the
    /// parent's texture shows what the child does at that moment.
    fn sample(&self, uv: [f64; 2], texel: f64) -> [f32; 4] {
        let top = (self.levels.len() - 1) as f64;
        let level = if self.texel.is_finite() && texel > self.texel {
            (texel / self.texel).log2().clamp(0.0, top)
        } else {
            0.0
        };
        let l0 = level.floor() as usize;
        let f = (level - l0 as f64) as f32;
        let a = self.bilinear(l0, uv);
        if f <= 0.0 || l0 + 1 >= self.levels.len() {
            return a;
        }
        let b = self.bilinear(l0 + 1, uv);
        [0, 1, 2, 3].map(|k| a[k] + (b[k] - a[k]) * f)
    }

    /// Bilinear sample of mip `level` at texture coordinate `uv` (edges clamped).
    fn bilinear(&self, level: usize, uv: [f64; 2]) -> [f32; 4] {
        let (w, h, px) = &self.levels[level];
        let (w, h) = (*w as i64, *h as i64);
        let x = uv[0] * w as f64 - 0.5;
        let y = uv[1] * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let at = |xi: i64, yi: i64| {
            let o = 4 * (yi.clamp(0, h - 1) * w + xi.clamp(0, w - 1)) as usize;
            [0, 1, 2, 3].map(|c| px[o + c] as f32)
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (a, b, c, d) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        [0, 1, 2, 3].map(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            top + (bottom - top) * fy
        })
    }
}

/// A re-cut patch's baked texture: RGBA8 and the chart maps (one per chart, in chart
/// order), before encoding.
#[derive(Clone, Debug, PartialEq)]
pub struct RecutTexture {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
    pub charts: Vec<TextureChart>,
    /// Each chart's plane ([`ChartFrame::plane`]).
    pub planes: Vec<[f32; 8]>,
}

impl RecutTexture {
    /// For the work spool: width, height, chart count (u32 each), charts (scale, offset
    /// and plane as f32), RGBA8.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(12 + self.charts.len() * 48 + self.rgba.len());
        for x in [self.width, self.height, self.charts.len() as u32] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for (c, p) in self.charts.iter().zip(&self.planes) {
            for f in [c.scale[0], c.scale[1], c.offset[0], c.offset[1]]
                .iter()
                .chain(p)
            {
                b.extend_from_slice(&f.to_le_bytes());
            }
        }
        b.extend_from_slice(&self.rgba);
        b
    }

    /// The texels of re-cut patch `vertices` (which carry their charts in `texture`),
    /// not yet encoded (`texture` holds the size only), for
    /// [`crate::texture::Baker::encode_recut`].
    pub fn unencoded(self, vertices: &[WorkVertex]) -> BakedTexture {
        BakedTexture {
            chart_ids: vertices
                .iter()
                .map(|v| chart_of(v.texture) as u16)
                .collect(),
            charts: self.charts,
            texture: tessera_format::PatchTexture {
                width: self.width,
                height: self.height,
                ..Default::default()
            },
            rgba: self.rgba,
            planes: self.planes,
        }
    }

    pub fn from_bytes(b: &[u8]) -> Option<RecutTexture> {
        let u = |i: usize| -> Option<u32> {
            Some(u32::from_le_bytes(
                b.get(4 * i..4 * i + 4)?.try_into().ok()?,
            ))
        };
        let (width, height, n) = (u(0)?, u(1)?, u(2)? as usize);
        let f = |c: usize, k: usize| u(3 + 12 * c + k).map(f32::from_bits);
        let charts = (0..n)
            .map(|c| {
                Some(TextureChart {
                    image: RECUT_IMAGE,
                    scale: [f(c, 0)?, f(c, 1)?],
                    offset: [f(c, 2)?, f(c, 3)?],
                })
            })
            .collect::<Option<Vec<_>>>()?;
        let planes = (0..n)
            .map(|c| {
                let mut p = [0f32; 8];
                for (k, v) in p.iter_mut().enumerate() {
                    *v = f(c, 4 + k)?;
                }
                Some(p)
            })
            .collect::<Option<Vec<_>>>()?;
        let rgba = b.get(12 + 48 * n..)?.to_vec();
        (rgba.len() == 4 * width as usize * height as usize).then_some(RecutTexture {
            width,
            height,
            rgba,
            charts,
            planes,
        })
    }
}

/// Bakes the texture of re-cut patch `p` (parametrised: `frames` are its charts) at
/// `texel` model units from the diamond's `children`; `align` is the codec's block
/// (charts on whole blocks), `error` the patch's
/// model-space error (how far a child's surface may lie from it). `None` when the
/// charts do not fit [`MAX_TEXTURE_DIM`] at this texel (take a coarser one:
/// [`bake_fitting`]).
fn bake(
    p: &WorkPatch,
    frames: &[ChartFrame],
    children: &[ChildTexels],
    texel: f64,
    align: i64,
    error: f64,
) -> Option<RecutTexture> {
    let mut rects: Vec<Rect> = frames
        .iter()
        .map(|f| {
            let [w, h] = chart_cells(f.extent, texel);
            Rect::placed(w, h)
        })
        .collect();
    let (aw, ah) = pack(&mut rects, align)?;
    let (aw_u, ah_u) = (aw as usize, ah as usize);
    let g = GUTTER as f64;
    // Per texel: the parent's height along its chart's axis (NaN: no parent triangle),
    // how far the best child sample so far lay from it, and its colour.
    let mut height = vec![f32::NAN; aw_u * ah_u];
    let mut best = vec![f32::INFINITY; aw_u * ah_u];
    let mut color = vec![[0f32; 4]; aw_u * ah_u];
    let to_texel = |f: &ChartFrame, r: &Rect, q: [u32; 3]| -> (f64, f64, f64) {
        let (u, v, d) = f.project(q);
        (r.dx as f64 + g + u / texel, r.dy as f64 + g + v / texel, d)
    };
    // Rasterises the triangle of texel-space corners `c` over the texels of rectangle
    // `r`, calling `f(texel index, barycentrics)` at every texel centre inside.
    fn raster(c: [(f64, f64, f64); 3], r: &Rect, aw: usize, mut f: impl FnMut(usize, [f64; 3])) {
        let (x0, x1) = (r.dx, r.dx + r.w());
        let (y0, y1) = (r.dy, r.dy + r.h());
        let minx = c.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let maxx = c.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let miny = c.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let maxy = c.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let det = (c[1].0 - c[0].0) * (c[2].1 - c[0].1) - (c[2].0 - c[0].0) * (c[1].1 - c[0].1);
        if det.abs() < 1e-12 || !det.is_finite() {
            return;
        }
        let xa = ((minx - 0.5).floor() as i64).max(x0);
        let xb = ((maxx - 0.5).ceil() as i64).min(x1 - 1);
        let ya = ((miny - 0.5).floor() as i64).max(y0);
        let yb = ((maxy - 0.5).ceil() as i64).min(y1 - 1);
        for y in ya..=yb {
            for x in xa..=xb {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let l1 =
                    ((px - c[0].0) * (c[2].1 - c[0].1) - (c[2].0 - c[0].0) * (py - c[0].1)) / det;
                let l2 =
                    ((c[1].0 - c[0].0) * (py - c[0].1) - (px - c[0].0) * (c[1].1 - c[0].1)) / det;
                let l0 = 1.0 - l1 - l2;
                const EPS: f64 = -1e-6;
                if l0 >= EPS && l1 >= EPS && l2 >= EPS {
                    f(y as usize * aw + x as usize, [l0, l1, l2]);
                }
            }
        }
    }
    for t in p.indices.chunks_exact(3) {
        let c = chart_of(p.vertices[t[0] as usize].texture);
        let (f, r) = (&frames[c], &rects[c]);
        let corners = [t[0], t[1], t[2]].map(|i| to_texel(f, r, p.vertices[i as usize].q));
        raster(corners, r, aw_u, |i, l| {
            height[i] = (l[0] * corners[0].2 + l[1] * corners[1].2 + l[2] * corners[2].2) as f32;
        });
    }
    // The charts each grid position is in.
    let mut charts_at: FxHashMap<[u32; 3], Vec<u32>> = FxHashMap::default();
    for v in &p.vertices {
        let list = charts_at.entry(v.q).or_default();
        let c = chart_of(v.texture) as u32;
        if !list.contains(&c) {
            list.push(c);
        }
    }
    let reach = (4.0 * error).max(4.0 * texel) as f32;
    let mut targets: Vec<u32> = Vec::new();
    for child in children {
        for t in child.indices.chunks_exact(3) {
            let t = [t[0], t[1], t[2]].map(|i| i as usize);
            targets.clear();
            for &i in &t {
                for q in [child.targets[i], child.q[i]] {
                    if let Some(list) = charts_at.get(&q) {
                        for &c in list {
                            if !targets.contains(&c) {
                                targets.push(c);
                            }
                        }
                    }
                }
            }
            let pos = t.map(|i| child.positions[i]);
            let n = cross(sub(pos[1], pos[0]), sub(pos[2], pos[0]));
            for &c in &targets {
                let (f, r) = (&frames[c as usize], &rects[c as usize]);
                // Only the side of the surface that faces the chart.
                if dot(n, f.axis) <= 0.0 {
                    continue;
                }
                let corners = t.map(|i| to_texel(f, r, child.q[i]));
                raster(corners, r, aw_u, |i, l| {
                    if height[i].is_nan() {
                        return;
                    }
                    let d =
                        (l[0] * corners[0].2 + l[1] * corners[1].2 + l[2] * corners[2].2) as f32;
                    let off = (d - height[i]).abs();
                    if off >= best[i] || off > reach {
                        return;
                    }
                    best[i] = off;
                    let uv = [0, 1].map(|k| {
                        l[0] * child.uvs[t[0]][k] as f64
                            + l[1] * child.uvs[t[1]][k] as f64
                            + l[2] * child.uvs[t[2]][k] as f64
                    });
                    color[i] = child.sample(uv, texel);
                });
            }
        }
    }
    // Texels without a sample (gutters, block padding, slivers no child reached) take
    // the mean of their filled neighbours, ring by ring, within each chart's cell.
    let mut filled: Vec<bool> = best.iter().map(|b| b.is_finite()).collect();
    for r in &rects {
        let (x0, y0) = (r.dx as usize, r.dy as usize);
        let (x1, y1) = (
            (r.dx + cell(r.w(), align)) as usize,
            (r.dy + cell(r.h(), align)) as usize,
        );
        let mut pending: Vec<usize> = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| y * aw_u + x))
            .filter(|&i| !filled[i])
            .collect();
        let mut ring = Vec::new();
        while !pending.is_empty() {
            ring.clear();
            for &i in &pending {
                let (x, y) = (i % aw_u, i / aw_u);
                let mut sum = [0f32; 4];
                let mut k = 0;
                for (dx, dy) in [
                    (-1i64, 0i64),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (1, -1),
                    (-1, 1),
                    (1, 1),
                ] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < x0 as i64 || ny < y0 as i64 || nx >= x1 as i64 || ny >= y1 as i64 {
                        continue;
                    }
                    let j = ny as usize * aw_u + nx as usize;
                    if filled[j] {
                        for c in 0..4 {
                            sum[c] += color[j][c];
                        }
                        k += 1;
                    }
                }
                if k > 0 {
                    ring.push((i, sum.map(|s| s / k as f32)));
                }
            }
            if ring.is_empty() {
                // Nothing in this chart was reached at all: mid grey.
                for &i in &pending {
                    color[i] = [128.0, 128.0, 128.0, 255.0];
                    filled[i] = true;
                }
                break;
            }
            for &(i, c) in &ring {
                color[i] = c;
                filled[i] = true;
            }
            pending.retain(|&i| !filled[i]);
        }
    }
    let rgba: Vec<u8> = color
        .iter()
        .flat_map(|c| c.map(|x| (x + 0.5).clamp(0.0, 255.0) as u8))
        .collect();
    let (fw, fh) = (aw as f64, ah as f64);
    let charts = rects
        .iter()
        .map(|r| TextureChart {
            image: RECUT_IMAGE,
            scale: [(1.0 / (texel * fw)) as f32, (1.0 / (texel * fh)) as f32],
            offset: [
                ((r.dx as f64 + g) / fw) as f32,
                ((r.dy as f64 + g) / fh) as f32,
            ],
        })
        .collect();
    debug_assert!(aw as u32 <= MAX_TEXTURE_DIM && ah as u32 <= MAX_TEXTURE_DIM);
    Some(RecutTexture {
        width: aw as u32,
        height: ah as u32,
        rgba,
        charts,
        planes: frames.iter().map(|f| f.plane).collect(),
    })
}

/// [`bake`] at `texel` model units, or the first of its doublings at which the charts
/// fit [`MAX_TEXTURE_DIM`]; a `texel` that is not a positive number (a patch of error 0
/// whose children have no textured triangles: solid colours only) starts from 1/64 of
/// its largest chart instead. Errs (rather than loop) if nothing fits.
pub fn bake_fitting(
    p: &WorkPatch,
    frames: &[ChartFrame],
    children: &[ChildTexels],
    texel: f64,
    align: i64,
    error: f64,
) -> Result<RecutTexture, String> {
    let largest = frames.iter().flat_map(|f| f.extent).fold(0.0f64, f64::max);
    let mut texel = if texel.is_finite() && texel > 0.0 {
        texel
    } else if largest > 0.0 {
        largest / 64.0
    } else {
        1.0
    };
    for _ in 0..64 {
        if let Some(t) = bake(p, frames, children, texel, align, error) {
            return Ok(t);
        }
        texel *= 2.0;
    }
    Err(format!(
        "a re-cut patch's {} charts do not fit a {MAX_TEXTURE_DIM}-texel texture",
        frames.len()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bumpy disc-like grid (a heightfield folded up at one end, so charts must split).
    fn bumpy(n: u32) -> WorkPatch {
        let mut p = WorkPatch::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                // Rises steeply past x = 0.6: more than MAX_CHART_ANGLE_DEG from flat.
                let z = 0.1 * (6.0 * y).sin() + if x > 0.6 { 3.0 * (x - 0.6) } else { 0.0 };
                p.vertices.push(WorkVertex {
                    q: [
                        (x * 1000.0) as u32,
                        (y * 1000.0) as u32,
                        (z * 1000.0) as u32 + 100,
                    ],
                    normal: [0.0, 0.0, 1.0],
                    color: [255; 4],
                    uv: [x as f32, y as f32],
                    texture: 0,
                });
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                p.indices.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                p.indices.extend([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        p
    }

    #[test]
    fn charts_never_flip_a_triangle_and_split_vertices_only_at_their_borders() {
        let mut p = bumpy(24);
        let before = p.clone();
        let frames = parametrise(&mut p, 1e-3);
        assert!(
            frames.len() >= 2,
            "the fold needs two charts: {}",
            frames.len()
        );
        assert_eq!(p.indices.len(), before.indices.len());
        let cos_max = (MAX_CHART_ANGLE_DEG + 15.0).to_radians().cos();
        for (t, old) in p
            .indices
            .chunks_exact(3)
            .zip(before.indices.chunks_exact(3))
        {
            // The same triangle, of one chart.
            for k in 0..3 {
                assert_eq!(
                    p.vertices[t[k] as usize].q,
                    before.vertices[old[k] as usize].q
                );
            }
            let c = chart_of(p.vertices[t[0] as usize].texture);
            assert!(t.iter().all(|&v| {
                let v = &p.vertices[v as usize];
                is_recut(v.texture) && chart_of(v.texture) == c
            }));
            // Counter-clockwise in its chart's plane, as in the model.
            let t = [t[0], t[1], t[2]];
            let uv = t.map(|v| p.vertices[v as usize].uv.map(f64::from));
            let area = (uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1])
                - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]);
            assert!(area > 0.0, "flipped in chart {c}: {uv:?}");
            // Within the chart's rectangle, and not far from its axis.
            let f = &frames[c];
            for u in uv {
                assert!(u[0] >= -1e-6 && u[1] >= -1e-6);
                assert!(u[0] <= f.extent[0] + 1e-6 && u[1] <= f.extent[1] + 1e-6);
            }
            let pos = t.map(|v| p.vertices[v as usize].q.map(|c| c as f64 * 1e-3));
            let n = unit(cross(sub(pos[1], pos[0]), sub(pos[2], pos[0]))).unwrap();
            assert!(
                dot(n, f.axis) >= cos_max,
                "{} degrees",
                dot(n, f.axis).acos().to_degrees()
            );
        }
        // Copies only where charts meet: far fewer than one per triangle corner.
        let extra = p.vertices.len() - before.vertices.len();
        assert!(extra < before.vertices.len() / 4, "{extra} copies");
    }

    #[test]
    fn a_patch_of_error_zero_over_solid_colours_still_gets_a_finite_texture() {
        // No textured child (texel infinite) and no error: texel_for gives 0.
        let mut p = bumpy(8);
        let frames = parametrise(&mut p, 1e-3);
        let t = bake_fitting(&p, &frames, &[], texel_for(0.0, f64::INFINITY), 4, 0.0).unwrap();
        assert!(t.width <= MAX_TEXTURE_DIM && t.height <= MAX_TEXTURE_DIM);
        assert_eq!(t.rgba.len(), 4 * (t.width * t.height) as usize);
        assert!(t.charts.iter().all(|c| c
            .scale
            .iter()
            .chain(&c.offset)
            .all(|v| v.is_finite() && *v >= 0.0)));
        assert!(t.planes.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn welding_joins_uv_seams_only() {
        let a = WorkVertex {
            q: [1, 2, 3],
            normal: [0.0, 0.0, 1.0],
            color: [255; 4],
            uv: [0.1, 0.2],
            texture: 0,
        };
        let seam = WorkVertex {
            uv: [0.7, 0.9],
            texture: 1,
            ..a
        };
        let crease = WorkVertex {
            normal: [1.0, 0.0, 0.0],
            ..a
        };
        let m = Merged {
            vertices: vec![a, seam, crease],
            indices: vec![0, 1, 2],
            child_maps: vec![vec![0, 1], vec![2]],
            pid: vec![0, 0, 0],
        };
        let w = weld_uv_seams(&m);
        assert_eq!(w.vertices.len(), 2);
        assert_eq!(w.indices, vec![0, 0, 1]);
        assert_eq!(w.child_maps, vec![vec![0, 0], vec![1]]);
        assert_eq!(w.pid, vec![0, 0]);
        assert!(fragmented(&m.vertices[..2]));
        assert!(!fragmented(&m.vertices[..1]));
        assert!(
            held_back(400, 200, 1000) && !held_back(300, 200, 1000) && !held_back(400, 200, 150)
        );
    }

    #[test]
    fn a_baked_texture_goes_through_the_work_spool_unchanged() {
        let t = RecutTexture {
            width: 4,
            height: 8,
            rgba: (0..128).map(|i| i as u8).collect(),
            charts: vec![
                TextureChart {
                    image: RECUT_IMAGE,
                    scale: [2.0, 3.0],
                    offset: [0.25, 0.5],
                },
                TextureChart {
                    image: RECUT_IMAGE,
                    scale: [1.0, 1.5],
                    offset: [0.0, 0.125],
                },
            ],
            planes: vec![[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0], [0.5; 8]],
        };
        let b = t.to_bytes();
        assert_eq!(RecutTexture::from_bytes(&b), Some(t));
        assert_eq!(RecutTexture::from_bytes(&b[..b.len() - 1]), None);
    }
}
