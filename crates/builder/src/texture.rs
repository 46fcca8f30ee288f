//! Stage 3b: a texture per patch, cut from the source images (GoLD, section 3.3).
//!
//! Each patch's vertices fall into *charts*: the connected pieces of the patch that
//! sample one source image (vertices are split at UV seams and between materials, so a
//! chart is a connected set of vertex indices of one texture). For each chart the
//! builder takes the rectangle of source texels its vertices' UVs cover (a vertex
//! morphs towards the UV of a vertex of its own chart, so geomorphing stays inside it),
//! grown by a gutter so
//! filtering never reads a neighbour, at the pyramid level the patch's error needs:
//! leaves (error 0) take the source texels unaltered, coarser patches the coarsest
//! box-filtered level whose texel is at most their model-space error. That error is
//! part of the texture's budget (issue 11): when a diamond's new patches are made, long
//! before they are baked (with their parent, which gives them their morph targets),
//! [`Baker::plan`] and [`budgeted_error`] raise the diamond's error until the patches'
//! textures fit [`PATCH_TEXELS`] each and half their children's texels together
//! ([`TEXEL_REDUCTION`]). The raised error is then stored and saturated like the
//! geometric one, so the runtime refines a coarse patch before its texels would show,
//! and the texture tree is a pyramid over the leaves (about 2x their texels at most)
//! instead of near-full-resolution crops at every level. The rectangles are packed into
//! one texture per patch (a *crop* when there is one rectangle, an *atlas* of several
//! otherwise) whose side never exceeds [`MAX_TEXTURE_DIM`]: a patch whose rectangles
//! would not fit takes the next coarser level and is counted as downsampled to fit.
//! Each chart's map from source UV to patch texture is stored with the patch
//! ([`TextureChart`]); untextured vertices of a textured model (a material without an
//! image, an image that cannot be read) get solid-colour texels of their vertex colour.
//!
//! Source images are out of core like the geometry: each is decoded once, the first
//! time a patch needs it, into its box-filtered pyramid, which is written level by level
//! as raw RGBA8 rows to a temporary *texel spool* in the build's temporary directory
//! (4/3 x 4 bytes per source texel on disk); patches read back only the rows of their
//! rectangles (positioned reads, which the page cache serves, not the build's memory).
//! No pyramid is held in memory: a coarse patch that spans dozens of images holds only
//! its own rectangles' texels, and no image is decoded twice whatever the order the
//! hierarchy visits them in. Decoding is what needs memory (the decoder's output, its
//! RGBA8 copy and the next level: about 8 bytes per texel of the image at once), so
//! concurrent decodes are limited to what fits the stage's budget (half of `--memory`;
//! one image larger than that decodes alone).
//!
//! The shelf packer and the box filter are written here: they are a few lines each, and
//! the packing crates on crates.io pack into fixed bins or need the whole set at once
//! with rotation, which would break the affine UV maps.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock};

use rustc_hash::FxHashMap;
use tessera_format::{
    texels, PatchSpool, PatchTexture, SpooledPatch, TextureChart, TextureCodec, MAX_PATCH_CHARTS,
    MAX_TEXTURE_DIM,
};
use tessera_mesh::{ImageSource, TextureSource, Wrap, NO_TEXTURE};

use crate::patch::WorkVertex;
use crate::BuildError;

/// Texels of gutter around every chart rectangle (bilinear filtering reads one texel
/// beyond a chart's edge; mip level 1 of the patch texture reads two).
pub(crate) const GUTTER: i64 = 2;
/// Side of the solid block of one untextured colour.
const SOLID: i64 = 4;
/// Most distinct solid colours a patch keeps; more are quantised to 4 bits a channel.
const MAX_SOLID_COLORS: usize = 1024;
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

/// How patch textures are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureOptions {
    pub codec: TextureCodec,
    /// JPEG quality 1..=100 (ignored for PNG and BC7).
    pub quality: u8,
    /// Re-cut the diamonds whose source seams hold their simplification back
    /// ([`crate::recut`]); off: every patch cuts its texture from the source atlas.
    pub recut: bool,
}

impl Default for TextureOptions {
    fn default() -> Self {
        TextureOptions {
            codec: TextureCodec::Bc7,
            quality: 90,
            recut: true,
        }
    }
}

/// What the texture stage did, for the build report.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TextureReport {
    /// Source images read (decoded), and their texels.
    pub source_images: u64,
    pub source_texels: u64,
    /// Patches whose texture is one rectangle of one image (GoLD's crop).
    pub crops: u64,
    /// Patches whose texture packs several rectangles (charts, images, solid colours).
    pub atlases: u64,
    /// Patches whose texture holds solid colours only (no image).
    pub solid_only: u64,
    /// Patches given their own charts and a texture baked from their children (coarse
    /// patches of fragmented atlases: [`crate::recut`]).
    pub recut: u64,
    /// Patches that took a coarser level than their error asked, to fit
    /// [`MAX_TEXTURE_DIM`].
    pub downsampled_to_fit: u64,
    /// Texels of all patch textures, and of the leaves' alone.
    pub texels: u64,
    pub leaf_texels: u64,
    /// Encoded bytes of all patch textures.
    pub bytes: u64,
    /// Images that could not be read, each once as `name: why`; their vertices are drawn
    /// in their vertex colour.
    pub unreadable_images: Vec<String>,
}

/// Decoded bytes per texel a decode holds at once (estimate for the decode gate): the
/// decoder's output (up to 3 bytes a texel for JPEG, 4 for 8-bit PNG), its RGBA8 copy
/// (4) and the next pyramid level (1).
const DECODE_BYTES_PER_TEXEL: u64 = 8;

/// One source image's box-filtered pyramid (level 0 = the source), stored in the texel
/// spool.
struct Pyramid {
    levels: Vec<Level>,
}

/// A pyramid level: `w x h` RGBA8 texels, row-major, at `offset` in the texel spool.
struct Level {
    w: u32,
    h: u32,
    offset: u64,
}

/// Texels in memory (while a pyramid is built).
struct Texels {
    w: u32,
    h: u32,
    rgba: Vec<u8>,
}

/// Builds the pyramid of `level0` one level at a time, handing each to `store` (which
/// returns where it put it) before computing the next from it, so at most two levels
/// are in memory.
fn build_pyramid<E>(
    level0: Texels,
    mut store: impl FnMut(&Texels) -> Result<u64, E>,
) -> Result<Vec<Level>, E> {
    let mut levels = Vec::new();
    let mut l = level0;
    loop {
        levels.push(Level {
            w: l.w,
            h: l.h,
            offset: store(&l)?,
        });
        if l.w <= 1 && l.h <= 1 {
            return Ok(levels);
        }
        l = half(&l);
    }
}

/// The next pyramid level: `ceil(w/2) x ceil(h/2)`, each texel the mean of the (up to)
/// four it covers.
fn half(l: &Texels) -> Texels {
    let (w, h) = (l.w.div_ceil(2), l.h.div_ceil(2));
    let mut rgba = vec![0u8; (w as usize) * (h as usize) * 4];
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0u32; 4];
            let mut n = 0;
            for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (xx, yy) = (2 * x + sx, 2 * y + sy);
                if xx < l.w && yy < l.h {
                    let o = ((yy as usize) * (l.w as usize) + xx as usize) * 4;
                    for c in 0..4 {
                        sum[c] += l.rgba[o + c] as u32;
                    }
                    n += 1;
                }
            }
            let o = ((y as usize) * (w as usize) + x as usize) * 4;
            for c in 0..4 {
                rgba[o + c] = ((sum[c] + n / 2) / n) as u8;
            }
        }
    }
    Texels { w, h, rgba }
}

/// Why an image has no pyramid.
#[derive(Clone, Debug)]
enum Failed {
    /// The image cannot be read or decoded: its faces take their vertex colour.
    Unreadable(String),
    /// The texel spool could not be written: the build fails.
    Spool(String),
}

type Decoded = Result<Arc<Pyramid>, Failed>;

/// Limits the decoded bytes of the images being decoded at once to a budget (one image
/// larger than the budget decodes alone). Holders wait for nothing else, so it cannot
/// deadlock.
struct DecodeGate {
    budget: u64,
    in_flight: Mutex<u64>,
    freed: Condvar,
}

impl DecodeGate {
    fn enter(&self, bytes: u64) -> DecodeTicket<'_> {
        let mut held = self.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        while *held > 0 && *held + bytes > self.budget {
            held = self.freed.wait(held).unwrap_or_else(|e| e.into_inner());
        }
        *held += bytes;
        DecodeTicket { gate: self, bytes }
    }
}

struct DecodeTicket<'a> {
    gate: &'a DecodeGate,
    bytes: u64,
}

impl Drop for DecodeTicket<'_> {
    fn drop(&mut self) {
        let mut held = self
            .gate
            .in_flight
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        *held -= self.bytes;
        self.gate.freed.notify_all();
    }
}

/// Cuts the textures of every patch; see the module docs.
pub struct Baker {
    sources: Vec<TextureSource>,
    options: TextureOptions,
    /// Each image's pyramid, decoded on first use (one thread decodes, the others wait).
    images: Mutex<FxHashMap<ImageSource, Arc<OnceLock<Decoded>>>>,
    /// Where the texel spool goes, and the spool (created by the first decode).
    spool_dir: PathBuf,
    spool: OnceLock<Result<PatchSpool, String>>,
    gate: DecodeGate,
    report: Mutex<TextureReport>,
    texels: AtomicU64,
    leaf_texels: AtomicU64,
    bytes: AtomicU64,
}

/// A patch's texture, ready for the patch encoder.
pub struct BakedTexture {
    pub charts: Vec<TextureChart>,
    pub chart_ids: Vec<u16>,
    pub texture: PatchTexture,
    /// The texels before encoding (RGBA8, `texture.width` x `texture.height`): what a
    /// re-cut parent bakes from.
    pub rgba: Vec<u8>,
    /// Re-cut patches: each chart's plane (`PatchData::chart_planes`); else empty.
    pub planes: Vec<[f32; 8]>,
}

/// A rectangle of one image's pyramid level that some charts share.
#[derive(Clone, Debug)]
pub(crate) struct Rect {
    /// Texture index (into the sources) or `NO_TEXTURE` for a solid colour.
    texture: u32,
    level: usize,
    /// Texel bounds at `level`, gutter included (may extend beyond the image: wrapped).
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
    /// Solid colour (when `texture == NO_TEXTURE`).
    color: [u8; 4],
    /// Placement in the patch texture.
    pub(crate) dx: i64,
    pub(crate) dy: i64,
}

impl Rect {
    /// A `w` x `h` rectangle of a re-cut chart, to be placed by [`pack`].
    pub(crate) fn placed(w: i64, h: i64) -> Rect {
        Rect {
            texture: crate::recut::RECUT,
            level: 0,
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
            color: [0; 4],
            dx: 0,
            dy: 0,
        }
    }
    pub(crate) fn w(&self) -> i64 {
        self.x1 - self.x0
    }
    pub(crate) fn h(&self) -> i64 {
        self.y1 - self.y0
    }
    /// Whether one rectangle around both holds no more texels than the two apart: two
    /// charts sharing texels are cut once, but two neighbours of an atlas whose gutters
    /// touch are not (merged in a chain, a shelf of small charts would become one
    /// rectangle of mostly the atlas's empty space).
    fn union_pays(&self, o: &Rect) -> bool {
        let w = self.x1.max(o.x1) - self.x0.min(o.x0);
        let h = self.y1.max(o.y1) - self.y0.min(o.y0);
        w * h <= self.w() * self.h() + o.w() * o.h()
    }
    fn overlaps(&self, o: &Rect) -> bool {
        self.texture == o.texture
            && self.level == o.level
            && self.x0 < o.x1
            && o.x0 < self.x1
            && self.y0 < o.y1
            && o.y0 < self.y1
    }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Each texture's pyramid (`None`: the image cannot be read).
type Pyramids = FxHashMap<u32, Option<Arc<Pyramid>>>;

/// A chart: a connected set of a patch's vertices that sample one image.
struct Chart {
    texture: u32,
    /// Model-space area of its triangles, and their area in level-0 texels.
    model_area: f64,
    texel_area: f64,
    /// UV bounds of its vertices (and their morph targets).
    umin: [f64; 2],
    umax: [f64; 2],
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
    fn level_for(&self, error: f64, leaf: bool) -> usize {
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
fn find_charts(
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
    baker: &'a Baker,
    charts: Vec<Chart>,
    pyramids: Pyramids,
    /// A re-cut patch's charts instead (see [`crate::recut`]): their extents in model
    /// units, and the children's finest texel.
    recut: Option<(Vec<[f64; 2]>, f64)>,
}

impl TexturePlan<'_> {
    /// Texels of the texture a patch of error `error` would have: its image rectangles
    /// (gutters included, overlaps merged) packed as [`Baker::bake`] packs them, without
    /// the few solid-colour texels; `u64::MAX` when they would
    /// not fit in [`MAX_TEXTURE_DIM`].
    pub fn texels(&self, error: f64) -> u64 {
        if let Some((extents, floor)) = &self.recut {
            let align = codec_align(self.baker.options.codec);
            return crate::recut::planned_texels(
                extents,
                crate::recut::texel_for(error, *floor),
                align,
            );
        }
        if self.charts.is_empty() {
            return 0;
        }
        let levels: Vec<usize> = self
            .charts
            .iter()
            .map(|c| c.level_for(error, false))
            .collect();
        let (mut rects, _) = self
            .baker
            .chart_rects(&self.charts, &levels, &self.pyramids);
        match pack(&mut rects, codec_align(self.baker.options.codec)) {
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

impl Baker {
    /// A baker of the textures `sources`, whose decodes together hold at most about
    /// `memory_bytes` (see the module docs). Its texel spool goes to the system's
    /// temporary directory unless [`Baker::spool_in`] says where.
    pub fn new(sources: Vec<TextureSource>, options: TextureOptions, memory_bytes: u64) -> Baker {
        Baker {
            sources,
            options,
            images: Mutex::new(FxHashMap::default()),
            spool_dir: std::env::temp_dir(),
            spool: OnceLock::new(),
            gate: DecodeGate {
                budget: memory_bytes.max(64 << 20),
                in_flight: Mutex::new(0),
                freed: Condvar::new(),
            },
            report: Mutex::new(TextureReport::default()),
            texels: AtomicU64::new(0),
            leaf_texels: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
        }
    }

    /// Puts the texel spool (4/3 x 4 bytes per source texel) in `dir`, ideally the
    /// build's temporary directory. Call before the first [`Baker::bake`].
    pub fn spool_in(mut self, dir: &Path) -> Baker {
        self.spool_dir = dir.to_path_buf();
        self
    }

    /// Whether diamonds held back by their seams are re-cut.
    pub fn recuts(&self) -> bool {
        self.options.recut
    }

    /// The codec of every texture it bakes.
    pub fn codec(&self) -> TextureCodec {
        self.options.codec
    }

    /// The report so far (call once the hierarchy is built).
    pub fn report(&self) -> TextureReport {
        let mut r = self.report.lock().map(|r| r.clone()).unwrap_or_default();
        r.texels = self.texels.load(Ordering::Relaxed);
        r.leaf_texels = self.leaf_texels.load(Ordering::Relaxed);
        r.bytes = self.bytes.load(Ordering::Relaxed);
        r
    }

    fn spool(&self) -> Result<&PatchSpool, Failed> {
        self.spool
            .get_or_init(|| PatchSpool::new(&self.spool_dir).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|e| Failed::Spool(e.clone()))
    }

    fn spool_error(&self, message: String) -> BuildError {
        BuildError::Io {
            path: self.spool_dir.clone(),
            cause: std::io::Error::other(format!("texel spool: {message}")),
        }
    }

    /// The pyramid of texture `t`'s image, decoding it on first use (one thread decodes,
    /// the others wait for it); `None` when it cannot be read (reported once).
    fn pyramid(&self, t: u32) -> Result<Option<Arc<Pyramid>>, BuildError> {
        let Some(src) = self.sources.get(t as usize) else {
            return Ok(None);
        };
        let cell = {
            let mut images = self
                .images
                .lock()
                .map_err(|_| BuildError::Internal("poisoned image map".into()))?;
            images.entry(src.image.clone()).or_default().clone()
        };
        match cell.get_or_init(|| self.decode(src)) {
            Ok(p) => Ok(Some(p.clone())),
            Err(Failed::Unreadable(_)) => Ok(None),
            Err(Failed::Spool(e)) => Err(self.spool_error(e.clone())),
        }
    }

    fn decode(&self, src: &TextureSource) -> Decoded {
        // An image whose size the importer could not read decodes alone.
        let estimate = match src.size {
            [0, _] | [_, 0] => self.gate.budget,
            [w, h] => u64::from(w) * u64::from(h) * DECODE_BYTES_PER_TEXEL,
        };
        let ticket = self.gate.enter(estimate);
        let result = match read_image(&src.image, src.size) {
            Ok((w, h, rgba)) => {
                let spool = self.spool()?;
                let levels = build_pyramid(Texels { w, h, rgba }, |l| {
                    spool
                        .append(&l.rgba)
                        .map(|sp| sp.offset)
                        .map_err(|e| Failed::Spool(e.to_string()))
                })?;
                Ok(Arc::new(Pyramid { levels }))
            }
            Err(e) => Err(Failed::Unreadable(e)),
        };
        drop(ticket);
        let mut report = self
            .report
            .lock()
            .map_err(|_| Failed::Spool("poisoned report".into()))?;
        match &result {
            Ok(p) => {
                report.source_images += 1;
                report.source_texels += u64::from(p.levels[0].w) * u64::from(p.levels[0].h);
            }
            Err(Failed::Unreadable(e)) => {
                let line = format!("{}: {e}", src.image_name);
                if !report.unreadable_images.contains(&line) {
                    tracing::warn!("texture image {line}; its faces are drawn in their colour");
                    report.unreadable_images.push(line);
                }
            }
            Err(Failed::Spool(_)) => {}
        }
        result
    }

    /// Row `y` of level `l`, texels `x0..x1`, from the spool.
    fn read_row(&self, l: &Level, y: i64, x0: i64, x1: i64) -> Result<Vec<u8>, BuildError> {
        let spool = self.spool().map_err(|e| match e {
            Failed::Spool(m) | Failed::Unreadable(m) => self.spool_error(m),
        })?;
        let bytes = ((x1 - x0) * 4) as u32;
        let offset = l.offset + ((y as u64) * u64::from(l.w) + x0 as u64) * 4;
        Ok(spool.read(&SpooledPatch {
            offset,
            bytes,
            crc32: 0,
        })?)
    }

    /// The pyramids of the textures `vertices` sample (decoding them on first use);
    /// `None` for an image that cannot be read.
    fn pyramids_of(&self, vertices: &[WorkVertex]) -> Result<Pyramids, BuildError> {
        let mut pyramids: Pyramids = FxHashMap::default();
        for v in vertices {
            if v.texture != NO_TEXTURE && !pyramids.contains_key(&v.texture) {
                pyramids.insert(v.texture, self.pyramid(v.texture)?);
            }
        }
        Ok(pyramids)
    }

    /// The rectangles of `charts` at `levels` (one per chart, clamped to the coarsest
    /// level), merged where they overlap, and each chart's rectangle.
    fn chart_rects(
        &self,
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
            let src = &self.sources[c.texture as usize];
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

    /// What the texture of a patch with these vertices and triangles would hold, before
    /// its morph targets are known (see [`TexturePlan`]).
    pub fn plan(
        &self,
        vertices: &[WorkVertex],
        indices: &[u32],
        step: f64,
    ) -> Result<TexturePlan<'_>, BuildError> {
        let pyramids = self.pyramids_of(vertices)?;
        let (charts, _) = find_charts(vertices, indices, step, &pyramids);
        Ok(TexturePlan {
            baker: self,
            charts,
            pyramids,
            recut: None,
        })
    }

    /// The plan of a re-cut patch with charts of `extents` (model units) whose
    /// children's finest texel is `floor` (see [`crate::recut`]).
    pub fn plan_recut(&self, extents: Vec<[f64; 2]>, floor: f64) -> TexturePlan<'_> {
        TexturePlan {
            baker: self,
            charts: Vec::new(),
            pyramids: Pyramids::default(),
            recut: Some((extents, floor)),
        }
    }

    /// Encodes a `w` x `h` RGBA8 patch texture with the baker's codec, counting it.
    fn encode(&self, w: u32, h: u32, rgba: &[u8], leaf: bool) -> Result<PatchTexture, BuildError> {
        let texture = match self.options.codec {
            TextureCodec::Bc7 => encode_bc7(w, h, rgba)?,
            codec => PatchTexture::encode(w, h, rgba, codec, self.options.quality)?,
        };
        let texels = u64::from(w) * u64::from(h);
        self.texels.fetch_add(texels, Ordering::Relaxed);
        if leaf {
            self.leaf_texels.fetch_add(texels, Ordering::Relaxed);
        }
        self.bytes
            .fetch_add(texture.encoded.len() as u64, Ordering::Relaxed);
        Ok(texture)
    }

    /// The texture of a re-cut patch (`vertices` carry their charts in `texture`), from
    /// its baked texels.
    pub fn encode_recut(
        &self,
        vertices: &[WorkVertex],
        baked: crate::recut::RecutTexture,
        leaf: bool,
    ) -> Result<BakedTexture, BuildError> {
        let texture = self.encode(baked.width, baked.height, &baked.rgba, leaf)?;
        if let Ok(mut r) = self.report.lock() {
            r.recut += 1;
        }
        Ok(BakedTexture {
            chart_ids: vertices
                .iter()
                .map(|v| crate::recut::chart_of(v.texture) as u16)
                .collect(),
            charts: baked.charts,
            texture,
            rgba: baked.rgba,
            planes: baked.planes,
        })
    }

    /// The texture of one patch. `error` is the patch's model-space error (0 for leaves)
    /// and `step` the model units per grid step.
    pub fn bake(
        &self,
        vertices: &[WorkVertex],
        indices: &[u32],
        error: f64,
        step: f64,
        leaf: bool,
    ) -> Result<BakedTexture, BuildError> {
        self.cut(vertices, indices, error, step, leaf, true)
    }

    /// The texels [`Baker::bake`] would encode, not encoded nor counted (`texture`
    /// holds the size only): what a re-cut leaf is baked from.
    pub fn texels_of(
        &self,
        vertices: &[WorkVertex],
        indices: &[u32],
        step: f64,
    ) -> Result<BakedTexture, BuildError> {
        self.cut(vertices, indices, 0.0, step, true, false)
    }

    fn cut(
        &self,
        vertices: &[WorkVertex],
        indices: &[u32],
        error: f64,
        step: f64,
        leaf: bool,
        encode: bool,
    ) -> Result<BakedTexture, BuildError> {
        let n = vertices.len();
        // Which textures can be read.
        let pyramids = self.pyramids_of(vertices)?;
        let textured = |v: &WorkVertex| {
            v.texture != NO_TEXTURE && matches!(pyramids.get(&v.texture), Some(Some(_)))
        };
        let (charts, vertex_chart) = find_charts(vertices, indices, step, &pyramids);
        // The level each chart wants.
        let wanted: Vec<usize> = charts.iter().map(|c| c.level_for(error, leaf)).collect();
        // Solid colours of the untextured vertices.
        let mut solid: FxHashMap<[u8; 4], usize> = FxHashMap::default();
        let quantise = vertices.iter().filter(|v| !textured(v)).count() > MAX_SOLID_COLORS && {
            let mut distinct = rustc_hash::FxHashSet::default();
            vertices
                .iter()
                .filter(|v| !textured(v))
                .any(|v| distinct.insert(v.color) && distinct.len() > MAX_SOLID_COLORS)
        };
        let solid_color = |c: [u8; 4]| {
            if quantise {
                c.map(|x| (x & 0xF0) | (x >> 4))
            } else {
                c
            }
        };
        for v in vertices.iter().filter(|v| !textured(v)) {
            let next = solid.len();
            solid.entry(solid_color(v.color)).or_insert(next);
        }
        let mut extra_levels = 0usize;
        let mut downsampled = false;
        loop {
            // Rectangles at this try's levels, merged where they overlap.
            let levels: Vec<usize> = wanted.iter().map(|w| w + extra_levels).collect();
            let (mut rects, rect_of_chart) = self.chart_rects(&charts, &levels, &pyramids);
            let mut solids: Vec<([u8; 4], usize)> = solid.iter().map(|(c, i)| (*c, *i)).collect();
            solids.sort_by_key(|s| s.1);
            let solid_base = rects.len();
            for (color, _) in &solids {
                rects.push(Rect {
                    texture: NO_TEXTURE,
                    level: 0,
                    x0: 0,
                    y0: 0,
                    x1: SOLID,
                    y1: SOLID,
                    color: *color,
                    dx: 0,
                    dy: 0,
                });
            }
            if rects.len() > MAX_PATCH_CHARTS {
                return Err(BuildError::Internal(format!(
                    "a patch needs {} texture charts (at most {MAX_PATCH_CHARTS})",
                    rects.len()
                )));
            }
            let align = codec_align(self.options.codec);
            let Some((aw, ah)) = pack(&mut rects, align) else {
                // Too big: one level coarser for every chart.
                let deepest = charts
                    .iter()
                    .enumerate()
                    .map(|(ci, c)| {
                        let p = pyramids[&c.texture].as_ref().expect("textured");
                        (wanted[ci] + extra_levels) < p.levels.len() - 1
                    })
                    .any(|b| b);
                if !deepest {
                    return Err(BuildError::Internal(
                        "patch texture does not fit even at 1 texel per chart".into(),
                    ));
                }
                extra_levels += 1;
                downsampled = true;
                continue;
            };
            // Fill the texture.
            let mut rgba = vec![0u8; (aw * ah * 4) as usize];
            for r in &rects {
                let put = |rgba: &mut [u8], x: i64, y: i64, px: [u8; 4]| {
                    let o = ((y * aw + x) * 4) as usize;
                    rgba[o..o + 4].copy_from_slice(&px);
                };
                // The rectangle's cell: itself, and with `align` its last row and
                // column repeated to whole blocks (see [`pack`]).
                let (cw, ch) = (cell(r.w(), align), cell(r.h(), align));
                if r.texture == NO_TEXTURE {
                    for y in 0..ch {
                        for x in 0..cw {
                            put(&mut rgba, r.dx + x, r.dy + y, r.color);
                        }
                    }
                    continue;
                }
                let src = &self.sources[r.texture as usize];
                let l = &pyramids[&r.texture].as_ref().expect("textured").levels[r.level];
                let tint = src.tint;
                // The source columns the rectangle reads: its own span when it lies inside
                // the level, else (wrapped or clamped beyond an edge) the whole row.
                let (cx0, cx1) = if r.x0 >= 0 && r.x1 <= l.w as i64 {
                    (r.x0, r.x1)
                } else {
                    (0, l.w as i64)
                };
                let mut row: Vec<u8> = Vec::new();
                let mut row_y = -1i64;
                for y in 0..ch {
                    let sy = wrap(r.y0 + y.min(r.h() - 1), l.h as i64, src.wrap[1]);
                    if sy != row_y {
                        row = self.read_row(l, sy, cx0, cx1)?;
                        row_y = sy;
                    }
                    for x in 0..cw {
                        let sx = wrap(r.x0 + x.min(r.w() - 1), l.w as i64, src.wrap[0]);
                        let o = ((sx - cx0) * 4) as usize;
                        let mut px = [row[o], row[o + 1], row[o + 2], row[o + 3]];
                        if tint != [255; 4] {
                            for c in 0..4 {
                                px[c] = ((px[c] as u32 * tint[c] as u32 + 127) / 255) as u8;
                            }
                        }
                        put(&mut rgba, r.dx + x, r.dy + y, px);
                    }
                }
            }
            // Chart maps: one per rectangle.
            let (fw, fh) = (aw as f32, ah as f32);
            let maps: Vec<TextureChart> = rects
                .iter()
                .map(|r| {
                    if r.texture == NO_TEXTURE {
                        return TextureChart {
                            image: u32::MAX,
                            scale: [0.0, 0.0],
                            offset: [
                                (r.dx as f32 + SOLID as f32 / 2.0) / fw,
                                (r.dy as f32 + SOLID as f32 / 2.0) / fh,
                            ],
                        };
                    }
                    let l = &pyramids[&r.texture].as_ref().expect("textured").levels[r.level];
                    let (w, h) = (l.w as f32, l.h as f32);
                    let ox = (r.dx - r.x0) as f32;
                    let oy = (r.dy - r.y0) as f32;
                    if self.sources[r.texture as usize].v_up {
                        TextureChart {
                            image: r.texture,
                            scale: [w / fw, -h / fh],
                            offset: [ox / fw, (h + oy) / fh],
                        }
                    } else {
                        TextureChart {
                            image: r.texture,
                            scale: [w / fw, h / fh],
                            offset: [ox / fw, oy / fh],
                        }
                    }
                })
                .collect();
            let chart_ids: Vec<u16> = (0..n)
                .map(|i| {
                    if vertex_chart[i] != usize::MAX {
                        rect_of_chart[vertex_chart[i]] as u16
                    } else {
                        (solid_base + solid[&solid_color(vertices[i].color)]) as u16
                    }
                })
                .collect();
            if !encode {
                return Ok(BakedTexture {
                    charts: maps,
                    chart_ids,
                    texture: PatchTexture {
                        width: aw as u32,
                        height: ah as u32,
                        ..Default::default()
                    },
                    rgba,
                    planes: Vec::new(),
                });
            }
            let texture = self.encode(aw as u32, ah as u32, &rgba, leaf)?;
            if let Ok(mut r) = self.report.lock() {
                let images = rects.iter().filter(|r| r.texture != NO_TEXTURE).count();
                if images == 0 {
                    r.solid_only += 1;
                } else if rects.len() == 1 {
                    r.crops += 1;
                } else {
                    r.atlases += 1;
                }
                r.downsampled_to_fit += downsampled as u64;
            }
            return Ok(BakedTexture {
                charts: maps,
                chart_ids,
                texture,
                rgba,
                planes: Vec::new(),
            });
        }
    }
}

/// Texel coordinate `i` of an axis of `n` texels under `mode`.
fn wrap(i: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let p = i.rem_euclid(2 * n);
            if p < n {
                p
            } else {
                2 * n - 1 - p
            }
        }
    }
}

/// Merges rectangles of one image level that overlap into their bounding box, until
/// none overlap; `rect_of_chart` follows. Charts that share texels share them once.
fn merge_overlapping(rects: &mut Vec<Rect>, rect_of_chart: &mut [usize]) {
    loop {
        let mut merged_any = false;
        let mut i = 0;
        while i < rects.len() {
            let mut j = i + 1;
            while j < rects.len() {
                if rects[i].overlaps(&rects[j]) && rects[i].union_pays(&rects[j]) {
                    let o = rects.swap_remove(j);
                    let r = &mut rects[i];
                    r.x0 = r.x0.min(o.x0);
                    r.y0 = r.y0.min(o.y0);
                    r.x1 = r.x1.max(o.x1);
                    r.y1 = r.y1.max(o.y1);
                    let moved = rects.len(); // the old index of the rect now at j
                    for c in rect_of_chart.iter_mut() {
                        if *c == j {
                            *c = i;
                        } else if *c == moved {
                            *c = j;
                        }
                    }
                    merged_any = true;
                } else {
                    j += 1;
                }
            }
            i += 1;
        }
        if !merged_any {
            return;
        }
    }
}

/// Shelf packing, tallest first, into a texture about as wide as it is tall. Sets each
/// rectangle's placement; the texture's size, or `None` past [`MAX_TEXTURE_DIM`].
/// With `align` > 1 (4 for BC7) every rectangle takes a cell of whole `align` x `align`
/// blocks at a multiple of `align` ([`cell`]), and the texture's sides are multiples of
/// it: no block holds texels of two rectangles, so a block codec never mixes their
/// colours (the cell's padding repeats the rectangle's last row and column).
pub(crate) fn pack(rects: &mut [Rect], align: i64) -> Option<(i64, i64)> {
    let max = MAX_TEXTURE_DIM as i64;
    let area: i64 = rects
        .iter()
        .map(|r| cell(r.w(), align) * cell(r.h(), align))
        .sum();
    let widest = rects.iter().map(|r| cell(r.w(), align)).max().unwrap_or(1);
    if widest > max || rects.iter().any(|r| cell(r.h(), align) > max) {
        return None;
    }
    let width = cell(
        (((area as f64) * 1.1).sqrt().ceil() as i64).max(widest),
        align,
    )
    .min(max);
    let mut order: Vec<usize> = (0..rects.len()).collect();
    order.sort_by_key(|&i| (-rects[i].h(), -rects[i].w()));
    let (mut x, mut y, mut row_h, mut used_w) = (0i64, 0i64, 0i64, 0i64);
    for i in order {
        let r = &mut rects[i];
        let (w, h) = (cell(r.w(), align), cell(r.h(), align));
        if x + w > width {
            y += row_h;
            x = 0;
            row_h = 0;
        }
        r.dx = x;
        r.dy = y;
        x += w;
        used_w = used_w.max(x);
        row_h = row_h.max(h);
    }
    let height = y + row_h;
    (height <= max).then_some((cell(used_w.max(1), align), cell(height.max(1), align)))
}

/// `n` rounded up to a multiple of `align`.
pub(crate) fn cell(n: i64, align: i64) -> i64 {
    (n + align - 1) / align * align
}

/// The packing alignment of `codec`'s textures: 4 x 4 blocks for BC7, none otherwise.
pub(crate) fn codec_align(codec: TextureCodec) -> i64 {
    match codec {
        TextureCodec::Bc7 => 4,
        TextureCodec::Png | TextureCodec::Jpeg => 1,
    }
}

/// A BC7 texture of `rgba` (`width` x `height`, multiples of 4): the box-filtered mip
/// chain every reader would make ([`texels::mip_chain`]), each level encoded with Intel's
/// ISPC BC7 kernels (`intel_tex_2`, opaque "ultra fast" profile: 53.7 dB on the
/// scissors' photo at 40 Mtexel/s a thread; "basic" adds 2.2 dB at 1/50 of the speed,
/// measured by `bench_texcodecs`). Levels below 4 texels are padded to a whole block by
/// repeating their last row and column.
fn encode_bc7(width: u32, height: u32, rgba: &[u8]) -> Result<PatchTexture, BuildError> {
    use intel_tex_2::bc7;
    let settings = bc7::opaque_ultra_fast_settings();
    let mips = texels::mip_chain(rgba, width, height);
    let mut levels = Vec::with_capacity(mips.len() + 1);
    for (l, level) in std::iter::once(rgba)
        .chain(mips.iter().map(|m| &m[..]))
        .enumerate()
    {
        let (w, h) = texels::level_size(width, height, l as u32);
        let (pw, ph) = (w.div_ceil(4) * 4, h.div_ceil(4) * 4);
        let padded;
        let data = if (pw, ph) == (w, h) {
            level
        } else {
            let mut out = Vec::with_capacity(4 * (pw * ph) as usize);
            for y in 0..ph {
                let row = &level[4 * (w * y.min(h - 1)) as usize..][..4 * w as usize];
                out.extend_from_slice(row);
                for _ in w..pw {
                    out.extend_from_slice(&row[row.len() - 4..]);
                }
            }
            padded = out;
            &padded[..]
        };
        let surface = intel_tex_2::RgbaSurface {
            data,
            width: pw,
            height: ph,
            stride: 4 * pw,
        };
        levels.push(bc7::compress_blocks(&settings, &surface));
    }
    Ok(PatchTexture::from_bc7(width, height, levels)?)
}

/// Refuses, before any work, a texture image whose decode needs more memory than
/// `memory_bytes` (`--memory`) allows: about [`DECODE_BYTES_PER_TEXEL`] bytes a texel
/// (its size is read from its header at import). A small PNG may claim 11000 x 11000
/// texels (968 MB to decode); an image larger than the stage's share of the budget
/// decodes alone, so the whole budget is the bound. The error is the message.
pub fn check_decode_memory(sources: &[TextureSource], memory_bytes: u64) -> Result<(), String> {
    for src in sources {
        let [w, h] = src.size;
        let need = u64::from(w) * u64::from(h) * DECODE_BYTES_PER_TEXEL;
        if need > memory_bytes {
            return Err(format!(
                "texture image '{}' is {w} x {h} texels: decoding it needs about {} MiB \
                 ({DECODE_BYTES_PER_TEXEL} bytes a texel), more than --memory {} MiB allows; \
                 raise --memory to at least {} MiB, or build with --ignore-textures",
                src.image_name,
                need >> 20,
                memory_bytes >> 20,
                need.div_ceil(1 << 20)
            ));
        }
    }
    Ok(())
}

/// Whether the JPEG `bytes` ends its last scan with an end-of-image marker (`FF D9`).
/// A JPEG cut short decodes without an error (the decoder fills the missing rows with
/// grey), so this is the only sign of it. Inside the entropy-coded data every `FF` is
/// followed by `00` or a restart marker, so `FF D9` after the last start-of-scan
/// (`FF DA`) is the real end; an EXIF thumbnail's own markers come before the frame.
fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let last_scan = bytes.windows(2).rposition(|w| w == [0xFF, 0xDA]);
    match last_scan {
        Some(at) => bytes[at..].windows(2).any(|w| w == [0xFF, 0xD9]),
        // No scan at all: the decoder says what is wrong.
        None => true,
    }
}

/// Reads and decodes an image to RGBA8; a truncated JPEG is an error. `size` (from the
/// header read at import; `[0, 0]` when unknown) bounds the decoder: a file that now
/// claims more texels is refused rather than decoded.
fn read_image(src: &ImageSource, size: [u32; 2]) -> Result<(u32, u32, Vec<u8>), String> {
    let regular = |p: &Path| tessera_mesh::open_regular(p).map_err(|e| e.to_string());
    let bytes: Vec<u8> = match src {
        ImageSource::File(p) => {
            let mut b = Vec::new();
            regular(p)?.read_to_end(&mut b).map_err(|e| e.to_string())?;
            b
        }
        ImageSource::FileRange { path, offset, len } => {
            let mut f = regular(path)?;
            f.seek(SeekFrom::Start(*offset))
                .map_err(|e| e.to_string())?;
            let mut b = Vec::new();
            f.take(*len)
                .read_to_end(&mut b)
                .map_err(|e| e.to_string())?;
            if b.len() as u64 != *len {
                return Err(format!("{} of {len} bytes", b.len()));
            }
            b
        }
        ImageSource::Memory { bytes, .. } => bytes.to_vec(),
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(&bytes[..]))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    if reader.format() == Some(image::ImageFormat::Jpeg) && !jpeg_is_complete(&bytes) {
        return Err(
            "the JPEG is truncated (no end-of-image marker after its last scan: \
                    the file was cut short)"
                .to_string(),
        );
    }
    if size[0] > 0 && size[1] > 0 {
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(size[0]);
        limits.max_image_height = Some(size[1]);
        reader.limits(limits);
    }
    let img = reader.decode().map_err(|e| e.to_string())?;
    let (w, h) = (img.width(), img.height());
    Ok((w, h, img.into_rgba8().into_raw()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_truncated_jpeg_is_an_error_not_grey_rows() {
        // Why: issue 29, item 8: a JPEG cut short decoded without an error, the missing
        // rows grey, and was baked into the patches as if whole.
        let mut jpeg = std::io::Cursor::new(Vec::new());
        let img =
            image::RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8 * 4, y as u8 * 4, 7]));
        img.write_to(&mut jpeg, image::ImageFormat::Jpeg).unwrap();
        let whole = jpeg.into_inner();
        let src = |b: &[u8]| ImageSource::Memory {
            key: "t".into(),
            bytes: b.into(),
        };
        assert!(jpeg_is_complete(&whole));
        assert_eq!(read_image(&src(&whole), [64, 64]).unwrap().0, 64);
        let cut = &whole[..whole.len() * 2 / 3];
        // The negative control: the decoder alone takes the cut file without a word.
        assert!(image::load_from_memory(cut).is_ok());
        assert!(!jpeg_is_complete(cut));
        let e = read_image(&src(cut), [64, 64]).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        // Trailing bytes after the end marker are not truncation.
        let mut padded = whole.clone();
        padded.extend_from_slice(&[0; 100]);
        assert!(read_image(&src(&padded), [64, 64]).is_ok());
        // An image that claims more texels than its header said at import is refused.
        assert!(read_image(&src(&whole), [32, 32]).is_err());
    }

    #[test]
    fn images_too_large_for_the_memory_budget_are_refused() {
        // Why: issue 29, item 8: 11000 x 11000 texels cost 575 MB whatever --memory.
        let t = |w, h| TextureSource {
            material: "m".into(),
            image: ImageSource::File("big.png".into()),
            image_name: "big.png".into(),
            tint: [255; 4],
            wrap: [Wrap::Repeat; 2],
            v_up: true,
            size: [w, h],
        };
        let e = check_decode_memory(&[t(11000, 11000)], 256 << 20).unwrap_err();
        assert!(e.contains("more than --memory 256 MiB"), "{e}");
        check_decode_memory(&[t(4096, 4096)], 256 << 20).unwrap();
    }

    fn rect(texture: u32, x0: i64, y0: i64, x1: i64, y1: i64) -> Rect {
        Rect {
            texture,
            level: 0,
            x0,
            y0,
            x1,
            y1,
            color: [0; 4],
            dx: 0,
            dy: 0,
        }
    }

    #[test]
    fn overlapping_rectangles_merge_and_charts_follow() {
        let mut rects = vec![
            rect(0, 0, 0, 10, 10),
            rect(0, 50, 50, 60, 60),
            rect(0, 2, 2, 12, 12),
            rect(1, 0, 0, 10, 10),
            // Overlaps the first two corners only (gutters touching in an atlas): one
            // rectangle around both would hold more texels than the two apart.
            rect(0, 8, 8, 30, 30),
        ];
        let mut of = vec![0, 1, 2, 3, 4];
        merge_overlapping(&mut rects, &mut of);
        assert_eq!(rects.len(), 4);
        assert_eq!(of[0], of[2]);
        let r = &rects[of[0]];
        assert_eq!((r.x0, r.y0, r.x1, r.y1), (0, 0, 12, 12));
        assert_eq!(rects[of[1]].x0, 50);
        assert_eq!(rects[of[3]].texture, 1);
        let r = &rects[of[4]];
        assert_eq!((r.x0, r.y0, r.x1, r.y1), (8, 8, 30, 30));
    }

    #[test]
    fn packing_places_rectangles_apart_within_the_texture() {
        let mut rects: Vec<Rect> = (0..40)
            .map(|i| rect(0, 0, 0, 3 + i % 7 * 5, 2 + i % 5 * 9))
            .collect();
        let (w, h) = pack(&mut rects, 1).expect("fits");
        for (i, a) in rects.iter().enumerate() {
            assert!(a.dx >= 0 && a.dy >= 0 && a.dx + a.w() <= w && a.dy + a.h() <= h);
            for b in &rects[i + 1..] {
                let apart = a.dx + a.w() <= b.dx
                    || b.dx + b.w() <= a.dx
                    || a.dy + a.h() <= b.dy
                    || b.dy + b.h() <= a.dy;
                assert!(apart, "{a:?} overlaps {b:?}");
            }
        }
        let area: i64 = rects.iter().map(|r| r.w() * r.h()).sum();
        assert!(
            (w * h) as f64 <= 2.0 * area as f64,
            "{w}x{h} for {area} texels"
        );
        assert!(pack(&mut [rect(0, 0, 0, 5000, 4)], 1).is_none());
    }

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
    }

    #[test]
    fn pyramid_levels_halve_and_average() {
        let rgba: Vec<u8> = (0..5 * 3).flat_map(|i| [i as u8 * 10, 0, 0, 255]).collect();
        let mut stored: Vec<Vec<u8>> = Vec::new();
        let levels = build_pyramid::<()>(Texels { w: 5, h: 3, rgba }, |l| {
            let at = stored.iter().map(|b| b.len() as u64).sum();
            stored.push(l.rgba.clone());
            Ok(at)
        })
        .unwrap();
        let sizes: Vec<(u32, u32)> = levels.iter().map(|l| (l.w, l.h)).collect();
        assert_eq!(sizes, vec![(5, 3), (3, 2), (2, 1), (1, 1)]);
        assert_eq!(levels[1].offset, 5 * 3 * 4);
        // Texel (0,0) of level 1 = mean of source texels 0, 1, 5, 6 (red 0, 10, 50, 60).
        assert_eq!(stored[1][0], 30);
    }

    #[test]
    fn the_decode_gate_admits_what_fits_and_one_oversized_alone() {
        // Why: concurrent decodes are the texture stage's memory; the gate must bound
        // them without ever refusing an image larger than the whole budget.
        let gate = DecodeGate {
            budget: 100,
            in_flight: Mutex::new(0),
            freed: Condvar::new(),
        };
        let a = gate.enter(60);
        let b = gate.enter(40);
        assert_eq!(*gate.in_flight.lock().unwrap(), 100);
        drop((a, b));
        let big = gate.enter(500);
        assert_eq!(*gate.in_flight.lock().unwrap(), 500);
        let waited = std::sync::atomic::AtomicBool::new(false);
        std::thread::scope(|s| {
            s.spawn(|| {
                let _t = gate.enter(10);
                assert!(
                    waited.load(Ordering::SeqCst),
                    "entered beside an oversized decode"
                );
            });
            std::thread::sleep(std::time::Duration::from_millis(50));
            waited.store(true, Ordering::SeqCst);
            drop(big);
        });
        assert_eq!(*gate.in_flight.lock().unwrap(), 0);
    }
}
