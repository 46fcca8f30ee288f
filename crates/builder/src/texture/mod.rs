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
//! otherwise) whose side never exceeds
//! [`MAX_TEXTURE_DIM`](tessera_format::MAX_TEXTURE_DIM): a patch whose rectangles would
//! not fit takes the next coarser level and is counted as downsampled to fit.
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
//! This module holds the stage's entry points ([`Baker`]: a patch's charts cut, packed,
//! filled and encoded); its parts are below it, each in its own file, and none imports
//! [`crate::recut`] (which imports them): the source pyramids and their spool
//! (`pyramid.rs`), the decode gate (`gate.rs`), the shelf packer (`pack.rs`), the
//! texel-budget planner (`plan.rs`) and the encoders (`encode.rs`).

pub(crate) mod encode;
mod gate;
pub(crate) mod pack;
pub(crate) mod plan;
mod pyramid;

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use rustc_hash::FxHashMap;
use tessera_format::{PatchTexture, TextureChart, TextureCodec, MAX_PATCH_CHARTS};
use tessera_mesh::{TextureSource, Wrap, NO_TEXTURE};

use encode::encode_texture;
pub use encode::BakedTexture;
pub use gate::check_decode_memory;
pub(crate) use pack::codec_align;
use pack::{cell, pack, Rect};
pub use plan::{budgeted_error, TexturePlan, PATCH_TEXELS, SMALL_TEXELS, TEXEL_REDUCTION};
use plan::{chart_rects, find_charts};
use pyramid::{Pyramids, SourcePyramids};

use crate::patch::WorkVertex;
use crate::BuildError;

/// Side of the solid block of one untextured colour.
const SOLID: i64 = 4;
/// Most distinct solid colours a patch keeps; more are quantised to 4 bits a channel.
const MAX_SOLID_COLORS: usize = 1024;

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
    /// [`MAX_TEXTURE_DIM`](tessera_format::MAX_TEXTURE_DIM).
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

/// Cuts the textures of every patch; see the module docs.
pub struct Baker {
    options: TextureOptions,
    /// The source images and their pyramids (decoded on first use).
    images: SourcePyramids,
    report: Mutex<TextureReport>,
    texels: AtomicU64,
    leaf_texels: AtomicU64,
    bytes: AtomicU64,
}

impl Baker {
    /// A baker of the textures `sources`, whose decodes together hold at most about
    /// `memory_bytes` (see the module docs). Its texel spool goes to the system's
    /// temporary directory unless [`Baker::spool_in`] says where.
    pub fn new(sources: Vec<TextureSource>, options: TextureOptions, memory_bytes: u64) -> Baker {
        Baker {
            options,
            images: SourcePyramids::new(sources, memory_bytes),
            report: Mutex::new(TextureReport::default()),
            texels: AtomicU64::new(0),
            leaf_texels: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
        }
    }

    /// Puts the texel spool (4/3 x 4 bytes per source texel) in `dir`, ideally the
    /// build's temporary directory. Call before the first [`Baker::bake`].
    pub fn spool_in(mut self, dir: &Path) -> Baker {
        self.images.spool_in(dir);
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
        let decodes = self.images.decodes();
        r.source_images = decodes.images;
        r.source_texels = decodes.texels;
        r.unreadable_images = decodes.unreadable;
        r
    }

    /// What the texture of a patch with these vertices and triangles would hold, before
    /// its morph targets are known (see [`TexturePlan`]).
    pub fn plan(
        &self,
        vertices: &[WorkVertex],
        indices: &[u32],
        step: f64,
    ) -> Result<TexturePlan<'_>, BuildError> {
        let pyramids = self.images.pyramids_of(vertices)?;
        let (charts, _) = find_charts(vertices, indices, step, &pyramids);
        Ok(TexturePlan {
            sources: &self.images.sources,
            align: codec_align(self.options.codec),
            charts,
            pyramids,
            recut: None,
        })
    }

    /// The plan of a re-cut patch with charts of `extents` (model units) whose
    /// children's finest texel is `floor` (see [`crate::recut`]).
    pub fn plan_recut(&self, extents: Vec<[f64; 2]>, floor: f64) -> TexturePlan<'_> {
        TexturePlan {
            sources: &self.images.sources,
            align: codec_align(self.options.codec),
            charts: Vec::new(),
            pyramids: Pyramids::default(),
            recut: Some((extents, floor)),
        }
    }

    /// Encodes a `w` x `h` RGBA8 patch texture with the baker's codec, counting it.
    fn encode(&self, w: u32, h: u32, rgba: &[u8], leaf: bool) -> Result<PatchTexture, BuildError> {
        let texture = encode_texture(w, h, rgba, self.options.codec, self.options.quality)?;
        let texels = u64::from(w) * u64::from(h);
        self.texels.fetch_add(texels, Ordering::Relaxed);
        if leaf {
            self.leaf_texels.fetch_add(texels, Ordering::Relaxed);
        }
        self.bytes
            .fetch_add(texture.encoded.len() as u64, Ordering::Relaxed);
        Ok(texture)
    }

    /// The texture of a re-cut patch, from its baked texels (`baked.texture` holds the
    /// size only: `crate::recut::RecutTexture::unencoded`).
    pub fn encode_recut(
        &self,
        baked: BakedTexture,
        leaf: bool,
    ) -> Result<BakedTexture, BuildError> {
        let texture = self.encode(baked.texture.width, baked.texture.height, &baked.rgba, leaf)?;
        if let Ok(mut r) = self.report.lock() {
            r.recut += 1;
        }
        Ok(BakedTexture { texture, ..baked })
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
        let pyramids = self.images.pyramids_of(vertices)?;
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
            let (mut rects, rect_of_chart) =
                chart_rects(&self.images.sources, &charts, &levels, &pyramids);
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
                let src = &self.images.sources[r.texture as usize];
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
                        row = self.images.read_row(l, sy, cx0, cx1)?;
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
                    if self.images.sources[r.texture as usize].v_up {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
    }
}
