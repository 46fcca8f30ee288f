//! How a decoded patch is drawn, for every renderer (the GPU cache of `tessera-render`,
//! the browser's three.js adapter): which vertex each vertex morphs toward and where
//! its target's attributes come from ([`morph_targets`]), whether a patch draws its
//! texture ([`patch_is_textured`]), and the texel sizes a patch morphing in samples its
//! texture by ([`patch_texel_size`], [`texel_lod`]). CPU only, so a renderer with no
//! GPU crate (three.js through `tessera-web`'s `Stream`) shares them.

use rustc_hash::FxHashMap;

use crate::{PatchData, TextureChart};

/// Whether `p`'s vertices are drawn with its texture: it has charts (a patch of a
/// textured model; see [`GpuCache::set_textured`] for the model's own switch).
pub fn patch_is_textured(p: &PatchData) -> bool {
    !p.chart_ids.is_empty() || p.texture.is_some()
}

/// A vertex's morph target: the surviving vertex of the parent's simplification it
/// moves onto ([`morph_targets`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MorphTarget<'a> {
    /// The target position (quantised, as the patch's positions).
    pub position: [u32; 3],
    /// The vertex lending the target its normal and colour: the first vertex at the
    /// target position in the patch, else in one of the siblings. None: found nowhere
    /// (the vertex keeps its own attributes while it moves).
    pub donor: Option<(&'a PatchData, usize)>,
    /// Textured: the source uv of the vertex of this patch at the target position in the
    /// vertex's own chart (the nearest to the vertex's own uv if several), so the uv it
    /// morphs along stays in its chart's rectangle. None: no such vertex (the target
    /// keeps the vertex's own uv, and the texture slides a little while it morphs).
    pub uv: Option<[f32; 2]>,
}

/// The source uv of vertex `i` of `p` (0, 0 when the patch has none).
pub fn source_uv(p: &PatchData, i: usize) -> [f32; 2] {
    match p.uvs.get(i) {
        Some(&uv) if p.uvs.len() == p.positions.len() => uv,
        _ => [0.0, 0.0],
    }
}

/// The chart of vertex `i` of `p`, if it has one.
pub fn vertex_chart(p: &PatchData, i: usize) -> Option<&TextureChart> {
    if p.chart_ids.len() != p.positions.len() {
        return None;
    }
    p.charts.get(usize::from(p.chart_ids[i]))
}

/// The morph target of every vertex of `p` (see `tessera_select::morph`), its
/// attributes looked up in `p` and its `siblings` (the other patches of its residency
/// group: about 8% of the moving vertices of the Bunny and the Dragon move onto a
/// survivor of a sibling); one hash lookup per moving vertex. None for a vertex whose
/// target is itself (survivors, locked borders); an empty list when no vertex of `p`
/// moves. `textured` also looks up the target's uv ([`MorphTarget::uv`]). Shared by the
/// GPU cache (`tessera_render::gpu_vertices_as`) and the browser's three.js adapter, so both morph
/// the same way.
pub fn morph_targets<'a>(
    p: &'a PatchData,
    siblings: &[&'a PatchData],
    textured: bool,
) -> Vec<Option<MorphTarget<'a>>> {
    let morphs = p.morph_targets.len() == p.positions.len()
        && p.morph_targets
            .iter()
            .zip(&p.positions)
            .any(|(t, q)| t != q);
    if !morphs {
        return Vec::new();
    }
    let sources: Vec<&PatchData> = std::iter::once(p).chain(siblings.iter().copied()).collect();
    // Where each position is: this patch first (source 0), then the siblings. Every
    // vertex at a position, in that order, as a list (head in `at`, links in
    // `entries`: (source, vertex, next entry or u32::MAX)), built back to front.
    let mut at: FxHashMap<[u32; 3], u32> = FxHashMap::default();
    let mut entries: Vec<(u32, u32, u32)> = Vec::new();
    for (k, s) in sources.iter().enumerate().rev() {
        for (i, q) in s.positions.iter().enumerate().rev() {
            let e = entries.len() as u32;
            let next = at.insert(*q, e).unwrap_or(u32::MAX);
            entries.push((k as u32, i as u32, next));
        }
    }
    p.positions
        .iter()
        .zip(&p.morph_targets)
        .enumerate()
        .map(|(i, (q, t))| {
            if t == q {
                return None;
            }
            let mut target = MorphTarget {
                position: *t,
                donor: None,
                uv: None,
            };
            let Some(&head) = at.get(t) else {
                return Some(target);
            };
            let (k, j, _) = entries[head as usize];
            target.donor = Some((sources[k as usize], j as usize));
            if let (true, Some(_)) = (textured, vertex_chart(p, i)) {
                let own_uv = source_uv(p, i);
                let mut best: Option<(f32, [f32; 2])> = None;
                let mut e = head;
                // Only a vertex of the same chart of this patch: its UV lies in the
                // chart's rectangle of this patch's texture (a vertex at the same
                // position in another chart may sample anywhere in the atlas, and a
                // re-cut chart's UVs are its own plane's).
                let own_chart = p.chart_ids[i];
                while e != u32::MAX {
                    let (k, j, next) = entries[e as usize];
                    if k == 0 && p.chart_ids[j as usize] == own_chart {
                        let u = source_uv(p, j as usize);
                        let d = (u[0] - own_uv[0]).powi(2) + (u[1] - own_uv[1]).powi(2);
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, u));
                        }
                    }
                    e = next;
                }
                target.uv = best.map(|(_, u)| u);
            }
            Some(target)
        })
        .collect()
}

/// Mip levels between a patch's texels (`texel_size`, model space) and its parent's
/// (`parent_texel`, 0 when unknown: then the texel the parent's `parent_error` allows,
/// the builder's coarsest texel at most the error, a level of which lies between half
/// the error and the error): `log2(parent / own)`, 0..8, 0 when unknown. Drawn at morph
/// ratio `r`, a textured patch samples no finer than level `r * texel_lod`
/// (`tessera_render::Slot::texel_lod`; the three.js adapter's shader does the same).
pub fn texel_lod(texel_size: f32, parent_texel: f32, parent_error: f32) -> f32 {
    if texel_size <= 0.0 {
        return 0.0;
    }
    let parent = if parent_texel > 0.0 {
        parent_texel
    } else {
        parent_error * std::f32::consts::FRAC_1_SQRT_2
    };
    let l = (parent / texel_size).log2();
    if l.is_finite() {
        l.clamp(0.0, 8.0)
    } else {
        0.0
    }
}

/// The model-space size of a texel of `patch`'s `width` x `height` texture: the square
/// root of the model area over the texel area of its textured triangles (each vertex's
/// uv mapped through its chart); 0 without such triangles.
pub fn patch_texel_size(patch: &PatchData, width: u32, height: u32, quant_step: f64) -> f32 {
    let n = patch.positions.len();
    if patch.uvs.len() != n || patch.chart_ids.len() != n || width == 0 || height == 0 {
        return 0.0;
    }
    let (mut model_area, mut texel_area) = (0.0f64, 0.0f64);
    for t in patch.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
        if a >= n || b >= n || c >= n {
            continue;
        }
        let chart = patch.chart_ids[a];
        let Some(ch) = patch.charts.get(chart as usize) else {
            continue;
        };
        if ch.image == u32::MAX || patch.chart_ids[b] != chart || patch.chart_ids[c] != chart {
            continue;
        }
        let p = [a, b, c].map(|i| patch.positions[i].map(|x| f64::from(x) * quant_step));
        let e1 = [0, 1, 2].map(|k| p[1][k] - p[0][k]);
        let e2 = [0, 1, 2].map(|k| p[2][k] - p[0][k]);
        let cr = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        model_area += 0.5 * (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
        let u = [a, b, c].map(|i| {
            let m = ch.map(patch.uvs[i]);
            [
                f64::from(m[0]) * f64::from(width),
                f64::from(m[1]) * f64::from(height),
            ]
        });
        texel_area += 0.5
            * ((u[1][0] - u[0][0]) * (u[2][1] - u[0][1])
                - (u[2][0] - u[0][0]) * (u[1][1] - u[0][1]))
                .abs();
    }
    if model_area > 0.0 && texel_area > 0.0 {
        (model_area / texel_area).sqrt() as f32
    } else {
        0.0
    }
}
