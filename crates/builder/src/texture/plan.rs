//! The texel-budget planner (issue 11): what a coarse patch's texture would hold at a
//! given error, known when the diamond's patches are made, long before they are baked
//! (with their parent, which gives them their morph targets), and [`budgeted_error`],
//! which raises a diamond's error until its patches' textures fit [`PATCH_TEXELS`] each
//! and half their children's texels together ([`TEXEL_REDUCTION`]).
//!
//! Its own module because the planner and the baker must agree on the charts, their
//! pyramid levels and their rectangles (so [`find_charts`] and [`chart_rects`] are here
//! and the baker uses them), and because the re-cut path ([`crate::recut`]) takes its
//! texel per error from here; the re-cut decision itself comes from the caller
//! ([`crate::texture::Baker::plan_recut`]).

use rustc_hash::FxHashMap;
use tessera_mesh::{TextureSource, NO_TEXTURE};

use super::pack::{merge_overlapping, pack, planned_texels, Rect, GUTTER};
use super::pyramid::Pyramids;
use crate::patch::WorkVertex;

/// A coarse patch's texel, in units of its model-space error. 1: at the tolerance that
/// selects the patch, a texel projects to about one tolerance, as its geometry does.
pub(crate) const TEXEL_PER_ERROR: f64 = 1.0;
/// Most texels of a coarse patch's texture: 512 x 512, 1 MiB as RGBA8 (GoLD bounds each
/// patch's "texture unit" to a fixed size). Beyond it the patch takes a coarser level
/// and its error rises to that level's texel. Leaves keep the source texels whatever
/// their size. Measured on `scripts/bench-textures` (issue 11): 256^2 (or 64-128 texels
/// a triangle) makes the runtime draw leaves where coarse patches would do (more GPU
/// bytes and triangles a frame); 1024^2 keeps more texels than the views use.
pub const PATCH_TEXELS: u64 = 512 * 512;
/// A diamond's coarse patches hold at most 1/`TEXEL_REDUCTION` of their children's
/// texels together, so each level of the texture tree holds at most half of the one
/// below and the tree at most about twice its leaves' texels, whatever the source's
/// texel density (small patches, where [`PATCH_TEXELS`] never binds, included). 3 or 4
/// store a little less but make the runtime refine further (measured: more GPU bytes).
pub const TEXEL_REDUCTION: u64 = 2;
/// Textures this small (64 x 64) need not shrink against their children's: the gutters
/// do not shrink with the level, and raising a tiny patch's error to its image's size
/// would, once saturated, raise every ancestor's.
pub const SMALL_TEXELS: u64 = 64 * 64;

/// A chart: a connected set of a patch's vertices that sample one image.
pub(crate) struct Chart {
    pub(crate) texture: u32,
    /// Model-space area of its triangles, and their area in level-0 texels.
    pub(crate) model_area: f64,
    pub(crate) texel_area: f64,
    /// UV bounds of its vertices (and their morph targets).
    pub(crate) umin: [f64; 2],
    pub(crate) umax: [f64; 2],
}

impl Chart {
    /// Model-space size of one source (level-0) texel: `None` when the chart has no
    /// area in the model or in the image.
    fn texel(&self) -> Option<f64> {
        (self.texel_area > 0.0 && self.model_area > 0.0)
            .then(|| (self.model_area / self.texel_area).sqrt())
    }

    /// The pyramid level for a patch of model-space error `error`: the coarsest whose
    /// texel is at most `error * TEXEL_PER_ERROR` (leaves: the source texels).
    pub(crate) fn level_for(&self, error: f64, leaf: bool) -> usize {
        let Some(texel) = self.texel() else {
            return 0;
        };
        if leaf || error <= 0.0 {
            return 0;
        }
        let k = (error * TEXEL_PER_ERROR / texel).log2().floor();
        if k.is_finite() && k > 0.0 {
            k as usize
        } else {
            0
        }
    }
}

/// The charts of a patch (textured vertices only: those whose image can be read) and
/// each vertex's chart (`usize::MAX` for the others). A vertex morphs towards the UV of
/// a vertex of its own chart (`tessera_render::morph_targets`), so its chart's bounds
/// already hold its target's.
pub(crate) fn find_charts(
    vertices: &[WorkVertex],
    indices: &[u32],
    step: f64,
    pyramids: &Pyramids,
) -> (Vec<Chart>, Vec<usize>) {
    let n = vertices.len();
    let textured = |v: &WorkVertex| {
        v.texture != NO_TEXTURE && matches!(pyramids.get(&v.texture), Some(Some(_)))
    };
    // Charts: connected vertex sets of one texture.
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for t in indices.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if vertices[a as usize].texture == vertices[b as usize].texture {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra != rb {
                    parent[ra.max(rb) as usize] = ra.min(rb);
                }
            }
        }
    }
    let roots: Vec<u32> = (0..n as u32).map(|i| find(&mut parent, i)).collect();
    // Per chart: model area, texel area (level 0), UV bounds.
    let mut chart_of_root: FxHashMap<u32, usize> = FxHashMap::default();
    let mut charts: Vec<Chart> = Vec::new();
    let mut vertex_chart = vec![usize::MAX; n];
    for i in 0..n {
        if !textured(&vertices[i]) {
            continue;
        }
        let c = *chart_of_root.entry(roots[i]).or_insert_with(|| {
            charts.push(Chart {
                texture: vertices[i].texture,
                model_area: 0.0,
                texel_area: 0.0,
                umin: [f64::INFINITY; 2],
                umax: [f64::NEG_INFINITY; 2],
            });
            charts.len() - 1
        });
        vertex_chart[i] = c;
        let uv = vertices[i].uv;
        for a in 0..2 {
            charts[c].umin[a] = charts[c].umin[a].min(uv[a] as f64);
            charts[c].umax[a] = charts[c].umax[a].max(uv[a] as f64);
        }
    }
    for t in indices.chunks_exact(3) {
        let c = vertex_chart[t[0] as usize];
        if c == usize::MAX || vertex_chart[t[1] as usize] != c || vertex_chart[t[2] as usize] != c {
            continue;
        }
        let t = [t[0], t[1], t[2]];
        let p = t.map(|i| vertices[i as usize].q.map(|x| x as f64 * step));
        let u = t.map(|i| vertices[i as usize].uv.map(f64::from));
        let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
        let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
        let cr = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        charts[c].model_area += 0.5 * (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
        let size = pyramids[&charts[c].texture]
            .as_ref()
            .map(|p| (p.levels[0].w as f64, p.levels[0].h as f64))
            .unwrap_or((1.0, 1.0));
        let uvc = ((u[1][0] - u[0][0]) * (u[2][1] - u[0][1])
            - (u[2][0] - u[0][0]) * (u[1][1] - u[0][1]))
            .abs();
        charts[c].texel_area += 0.5 * uvc * size.0 * size.1;
    }
    (charts, vertex_chart)
}

/// What a coarse patch's texture would hold at a given error, known when the patch is
/// made (it is baked with its parent, which gives it its morph targets): the hierarchy raises a diamond's error until its patches'
/// textures fit the texel budget (see [`budgeted_error`]).
pub struct TexturePlan<'a> {
    /// The baker's sources, and its codec's packing alignment.
    pub(crate) sources: &'a [TextureSource],
    pub(crate) align: i64,
    pub(crate) charts: Vec<Chart>,
    pub(crate) pyramids: Pyramids,
    /// A re-cut patch's charts instead (see [`crate::recut`]): their extents in model
    /// units, and the children's finest texel.
    pub(crate) recut: Option<(Vec<[f64; 2]>, f64)>,
}

impl TexturePlan<'_> {
    /// Texels of the texture a patch of error `error` would have: its image rectangles
    /// (gutters included, overlaps merged) packed as
    /// [`Baker::bake`](super::Baker::bake) packs them, without the few solid-colour
    /// texels; `u64::MAX` when they would not fit in
    /// [`MAX_TEXTURE_DIM`](tessera_format::MAX_TEXTURE_DIM).
    pub fn texels(&self, error: f64) -> u64 {
        if let Some((extents, floor)) = &self.recut {
            return planned_texels(extents, texel_for(error, *floor), self.align);
        }
        if self.charts.is_empty() {
            return 0;
        }
        let levels: Vec<usize> = self
            .charts
            .iter()
            .map(|c| c.level_for(error, false))
            .collect();
        let (mut rects, _) = chart_rects(self.sources, &self.charts, &levels, &self.pyramids);
        match pack(&mut rects, self.align) {
            Some((w, h)) => (w * h) as u64,
            None => u64::MAX,
        }
    }

    /// The errors at which a chart steps to a coarser level: for every chart and level
    /// `k >= 1` of its image, the least error [`Chart::level_for`] gives `k` for (a
    /// texel of `2^k` source texels is `error * TEXEL_PER_ERROR`), with a margin that
    /// survives the error's rounding to `f32`.
    pub fn steps(&self) -> Vec<f64> {
        let mut steps = Vec::new();
        if let Some((extents, floor)) = &self.recut {
            // Texels shrink continuously with the error: steps of a quarter octave from
            // the children's texel (or the largest chart's 1/4096) up.
            let largest = extents.iter().flatten().fold(0.0f64, |a, &b| a.max(b));
            let base = if floor.is_finite() {
                *floor
            } else {
                largest / 4096.0
            };
            if base > 0.0 {
                for k in 0..=96 {
                    steps.push(base * 2f64.powf(k as f64 / 4.0) / TEXEL_PER_ERROR * (1.0 + 1e-6));
                }
            }
            return steps;
        }
        for c in &self.charts {
            let (Some(texel), Some(Some(p))) = (c.texel(), self.pyramids.get(&c.texture)) else {
                continue;
            };
            for k in 1..p.levels.len() {
                steps.push(texel * (1u64 << k) as f64 / TEXEL_PER_ERROR * (1.0 + 1e-6));
            }
        }
        steps
    }
}

/// The error, at least `error`, to give the coarse patches of one diamond (which share
/// their error) so that their textures fit the texel budget: the least at which every
/// patch's texture holds at most [`PATCH_TEXELS`] and all together at most
/// 1/[`TEXEL_REDUCTION`] of `children_texels`, their children's (or [`SMALL_TEXELS`]
/// each, whichever is more); the coarsest level's when none fits. `plans` are the
/// diamond's patches. Baked at this error, every chart is cut at a level whose texel is
/// at most `error * TEXEL_PER_ERROR`: the runtime refines the patch before its texels
/// would show, as it does before its geometry's error would.
pub fn budgeted_error(plans: &[TexturePlan], error: f64, children_texels: u64) -> f64 {
    let together = (children_texels / TEXEL_REDUCTION).max(SMALL_TEXELS * plans.len() as u64);
    let fits = |t: &[u64]| {
        t.iter().all(|&t| t <= PATCH_TEXELS)
            && t.iter().fold(0u64, |s, &t| s.saturating_add(t)) <= together
    };
    let texels = |e: f64| plans.iter().map(|p| p.texels(e)).collect::<Vec<u64>>();
    if fits(&texels(error)) {
        return error;
    }
    let mut steps: Vec<f64> = plans
        .iter()
        .flat_map(|p| p.steps())
        .filter(|&s| s > error)
        .collect();
    steps.sort_by(f64::total_cmp);
    steps.dedup();
    // Texels only fall as the error grows: the first step that fits, by bisection.
    let (mut lo, mut hi) = (0, steps.len());
    while lo < hi {
        let mid = (lo + hi) / 2;
        if fits(&texels(steps[mid])) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    steps
        .get(lo)
        .or(steps.last())
        .copied()
        .unwrap_or(error)
        .max(error)
}

/// The model-space texel of a re-cut patch of error `error` whose children's finest
/// texel is `floor`: `error` (one texel a tolerance, as the source cuts take), never
/// finer than the children's.
pub fn texel_for(error: f64, floor: f64) -> f64 {
    let e = error * TEXEL_PER_ERROR;
    if floor.is_finite() {
        e.max(floor)
    } else {
        e
    }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// The rectangles of `charts` at `levels` (one per chart, clamped to the coarsest
/// level), merged where they overlap, and each chart's rectangle.
pub(crate) fn chart_rects(
    sources: &[TextureSource],
    charts: &[Chart],
    levels: &[usize],
    pyramids: &Pyramids,
) -> (Vec<Rect>, Vec<usize>) {
    let mut rects: Vec<Rect> = Vec::with_capacity(charts.len());
    let mut rect_of_chart = vec![0usize; charts.len()];
    for (ci, c) in charts.iter().enumerate() {
        let p = pyramids[&c.texture].as_ref().expect("textured");
        let level = levels[ci].min(p.levels.len() - 1);
        let l = &p.levels[level];
        let src = &sources[c.texture as usize];
        let (w, h) = (l.w as f64, l.h as f64);
        let ys = |v: f64| if src.v_up { (1.0 - v) * h } else { v * h };
        let (ya, yb) = (ys(c.umin[1]), ys(c.umax[1]));
        rects.push(Rect {
            texture: c.texture,
            level,
            x0: (c.umin[0] * w).floor() as i64 - GUTTER,
            x1: (c.umax[0] * w).ceil() as i64 + GUTTER,
            y0: ya.min(yb).floor() as i64 - GUTTER,
            y1: ya.max(yb).ceil() as i64 + GUTTER,
            color: [0; 4],
            dx: 0,
            dy: 0,
        });
        rect_of_chart[ci] = rects.len() - 1;
    }
    merge_overlapping(&mut rects, &mut rect_of_chart);
    (rects, rect_of_chart)
}
