//! The patch codec: one node's mesh patch <-> bytes.
//!
//! Patches dominate the file size (the target is about 6 bytes per input triangle for the
//! whole multiresolution model), and they are decoded at render time, so the codec is
//! built on meshoptimizer's fast index and vertex codecs, optionally followed by zstd.
//! Positions are integers on the global grid, stored as offsets from the node's
//! `quant_min`; decoding is exact, so vertices shared between patches stay bit-identical.
//! The byte layout is specified in `docs/format.md` ("Patch encoding").

use std::borrow::Cow;

mod morph;
mod normals;
pub mod texels;

use morph::{decode_morph, encode_morph};
use normals::{decode_normals, encode_normals};
pub use normals::{oct_decode, oct_encode};

use crate::error::FormatError;
use crate::records::{
    NodeRecord, ATTR_COLORS, ATTR_NORMALS, ATTR_TEXTURE, ATTR_UVS, MAX_TEXTURE_DIM, NO_NODE,
};

/// Version of the patch encoding (byte 8 of every patch header).
pub const PATCH_CODEC_VERSION: u8 = 4;
/// Bytes of the fixed patch header that precedes the section payload.
pub const PATCH_HEADER_BYTES: usize = 48;
/// Patch flag: the section payload is one zstd frame.
pub const PATCH_FLAG_ZSTD: u8 = 1;
/// Patch flag: the patch carries morph targets.
pub const PATCH_FLAG_MORPH: u8 = 2;
/// Largest vertex count a patch may have (decoders reject more before allocating).
pub const MAX_PATCH_VERTICES: u32 = 1 << 22;
/// Largest triangle count a patch may have (decoders reject more before allocating).
pub const MAX_PATCH_TRIANGLES: u32 = 1 << 23;

/// All `ATTR_*` bits this version knows.
const ATTR_ALL: u32 = ATTR_NORMALS | ATTR_COLORS | ATTR_UVS | ATTR_TEXTURE;
/// meshopt vertex codec version and level used by the encoder (the decoder reads any).
const VERTEX_CODEC_VERSION: i32 = 1;
/// Level 2 (meshoptimizer's default): on whole builds level 3 gave the same bytes on the
/// 10M sphere and 0.1% more on the Dragon, for ~8% more encoding time.
const VERTEX_CODEC_LEVEL: i32 = 2;
/// zstd level for the section payload. Measured on whole builds: level 5 gave 0.6%
/// fewer bytes (10M sphere 4.75 vs 4.78 B/triangle, Dragon 5.90 vs 5.93) for ~8% more
/// encoding time; without zstd the files are 20-38% larger.
const ZSTD_LEVEL: i32 = 3;

/// Section order in the payload (and in the header's length table).
const SEC_INDICES: usize = 0;
const SEC_POSITIONS: usize = 1;
const SEC_NORMALS: usize = 2;
const SEC_COLORS: usize = 3;
const SEC_UVS: usize = 4;
const SEC_MORPH: usize = 5;
const SEC_CHARTS: usize = 6;
const SECTION_COUNT: usize = 7;
/// Bytes of one chart record in the charts section.
const CHART_BYTES: usize = 20;
/// Bytes of a re-cut chart's plane after the chart ids.
const PLANE_BYTES: usize = 32;
/// Bytes of the texture block's own header (codec, reserved, width, height).
const TEXTURE_HEADER_BYTES: usize = 12;
/// Most charts a patch may have (chart ids are u16).
pub const MAX_PATCH_CHARTS: usize = u16::MAX as usize;

/// How a patch texture's image is encoded (byte 0 of the texture block, and the
/// header's `texture_codec`: every patch of a model uses the same).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TextureCodec {
    /// PNG, lossless: the finest patches keep the source's texels exactly. Readers make
    /// the mip chain at load.
    Png = 1,
    /// Baseline JPEG. Readers make the mip chain at load.
    Jpeg = 2,
    /// BC7 (`Bc7RgbaUnorm`: 16 bytes a 4x4 block, 1 byte a texel), the whole mip chain
    /// stored, the blocks of all levels zstd-compressed together. What GPUs sample
    /// directly: a quarter of RGBA8's GPU memory and no image decode at load; readers
    /// without BC7 sampling decode the blocks to RGBA8 ([`PatchTexture::decode_rgba`]).
    /// Width and height are multiples of 4.
    Bc7 = 3,
}

impl TextureCodec {
    /// The codec of byte `b` (the texture block's byte 0, the header's `texture_codec`).
    pub fn from_byte(b: u8) -> Option<TextureCodec> {
        match b {
            1 => Some(TextureCodec::Png),
            2 => Some(TextureCodec::Jpeg),
            3 => Some(TextureCodec::Bc7),
            _ => None,
        }
    }

    /// The `image` crate's format (PNG and JPEG).
    fn format(self) -> Option<image::ImageFormat> {
        match self {
            TextureCodec::Png => Some(image::ImageFormat::Png),
            TextureCodec::Jpeg => Some(image::ImageFormat::Jpeg),
            TextureCodec::Bc7 => None,
        }
    }

    /// The name `tessera build --texture-codec` takes and `info` prints.
    pub fn name(self) -> &'static str {
        match self {
            TextureCodec::Png => "png",
            TextureCodec::Jpeg => "jpeg",
            TextureCodec::Bc7 => "bc7",
        }
    }
}

/// One chart of a patch texture: the affine map from a vertex's source UV (as the input
/// file gave it) into the patch texture, `t = uv * scale + offset` per axis, in the
/// patch texture's normalised coordinates (0..1, origin at the top-left texel's corner,
/// v down as in glTF and WebGPU). A chart is a region of one source image (or, with
/// `scale` 0, one solid colour texel for untextured vertices).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TextureChart {
    /// Index of the source texture (the importer's `TextureSource`), `u32::MAX` for a
    /// solid-colour chart, [`RECUT_IMAGE`] for a chart of the patch's own
    /// parametrisation.
    pub image: u32,
    pub scale: [f32; 2],
    pub offset: [f32; 2],
}

/// [`TextureChart::image`] of a *re-cut* chart: the patch was parametrised afresh and its
/// texture baked from its children (a coarse patch of a fragmented atlas), so its
/// vertices' "source UVs" are their coordinates in the chart's own plane (model units
/// from its corner), not UVs of a source image. A vertex of such a chart morphs towards
/// the UV of the vertex at its target's position in the same chart of the same patch.
pub const RECUT_IMAGE: u32 = u32::MAX - 1;

impl TextureChart {
    /// Where `uv` lands in the patch texture.
    #[inline]
    pub fn map(&self, uv: [f32; 2]) -> [f32; 2] {
        [
            uv[0] * self.scale[0] + self.offset[0],
            uv[1] * self.scale[1] + self.offset[1],
        ]
    }
}

/// A patch's texture: `encoded` (what the file stores) and/or its decoded texels:
/// `rgba` (RGBA8, rows top to bottom, `4 * width * height` bytes) or, for
/// [`TextureCodec::Bc7`], `blocks`. [`decode_patch`] with texels fills `rgba` for PNG
/// and JPEG and `blocks` for BC7, and leaves `encoded` empty; [`encode_patch`] writes
/// `encoded`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchTexture {
    pub width: u32,
    pub height: u32,
    pub codec: Option<TextureCodec>,
    pub encoded: Vec<u8>,
    pub rgba: Vec<u8>,
    /// Mip levels 1, 2, .. of `rgba` (RGBA8, each half the last, down to 1x1), when
    /// they were made before the upload (the browser's decode workers make them off
    /// the main thread; [`PatchTexture::decode_rgba`] of a BC7 texture decodes the
    /// stored ones); empty: the GPU cache makes them when it uploads. Never stored in a
    /// file.
    pub mips: Vec<Vec<u8>>,
    /// BC7 blocks of every mip level, level 0 first, down to 1x1
    /// ([`texels::bc7_level_bytes`] each): a BC7 texture as the GPU takes it.
    pub blocks: Vec<Vec<u8>>,
}

/// zstd level of BC7 blocks. Measured by `bench_texcodecs` on a 1024x1024 crop of the
/// scissors' photo with the builder's encoder (one thread): level 3 stores 0.93 bytes a
/// texel (mips included) at 24 Mtexel/s of encoding and zstd together; level 9 0.88 at
/// 14 Mtexel/s, level 1 1.02 at 29. On `scripts/bench-textures` (2.0 GiB of source
/// texels, 2 cores, alternated runs): level 3 builds in 47-54 s for 818 MB, level 9 in
/// 64-70 s for 761 MB (PNG: 42 s, 863 MB). 3: 7% more bytes cost less than a third
/// more build time. Decoding runs at 550-800 Mtexel/s whatever the level.
pub const BC7_ZSTD_LEVEL: i32 = 3;

impl PatchTexture {
    /// Encodes RGBA8 texels with `codec` (`quality` 1..=100 for JPEG; JPEG drops alpha).
    /// BC7 textures are made from their encoded blocks ([`PatchTexture::from_bc7`]):
    /// the encoder is the builder's.
    pub fn encode(
        width: u32,
        height: u32,
        rgba: &[u8],
        codec: TextureCodec,
        quality: u8,
    ) -> Result<PatchTexture, FormatError> {
        let mut encoded = Vec::new();
        let err = |e: image::ImageError| corrupt(format!("texture encoder: {e}"));
        match codec {
            TextureCodec::Png => {
                use image::ImageEncoder;
                image::codecs::png::PngEncoder::new_with_quality(
                    &mut encoded,
                    image::codecs::png::CompressionType::Fast,
                    image::codecs::png::FilterType::Adaptive,
                )
                .write_image(rgba, width, height, image::ExtendedColorType::Rgba8)
                .map_err(err)?;
            }
            TextureCodec::Jpeg => {
                let rgb: Vec<u8> = rgba
                    .chunks_exact(4)
                    .flat_map(|p| [p[0], p[1], p[2]])
                    .collect();
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut encoded, quality)
                    .encode(&rgb, width, height, image::ExtendedColorType::Rgb8)
                    .map_err(err)?;
            }
            TextureCodec::Bc7 => {
                return Err(corrupt(
                    "BC7 textures are made from their blocks (PatchTexture::from_bc7)",
                ))
            }
        }
        Ok(PatchTexture {
            width,
            height,
            codec: Some(codec),
            encoded,
            ..Default::default()
        })
    }

    /// A BC7 texture from the blocks of its whole mip chain (`levels[0]` the
    /// `width` x `height` level, each next one half the last down to 1x1, each
    /// [`texels::bc7_level_bytes`] long), compressed with zstd for the file. Width and
    /// height must be multiples of 4 (so every GPU takes level 0).
    pub fn from_bc7(
        width: u32,
        height: u32,
        levels: Vec<Vec<u8>>,
    ) -> Result<PatchTexture, FormatError> {
        check_bc7(width, height, &levels)?;
        let encoded = zstd::bulk::compress(&levels.concat(), BC7_ZSTD_LEVEL)
            .map_err(|e| corrupt(format!("texture: zstd: {e}")))?;
        Ok(PatchTexture {
            width,
            height,
            codec: Some(TextureCodec::Bc7),
            encoded,
            blocks: levels,
            ..Default::default()
        })
    }

    /// Decodes a BC7 texture's `encoded` into `blocks` (every level; no texel decode).
    /// Nothing for PNG and JPEG, or when `blocks` are there already.
    pub fn decode_blocks(&mut self) -> Result<(), FormatError> {
        if self.codec != Some(TextureCodec::Bc7) || !self.blocks.is_empty() {
            return Ok(());
        }
        let (w, h) = (self.width, self.height);
        if w % 4 != 0
            || h % 4 != 0
            || w == 0
            || h == 0
            || w > MAX_TEXTURE_DIM
            || h > MAX_TEXTURE_DIM
        {
            return Err(corrupt(format!(
                "BC7 texture of {w}x{h} texels (multiples of 4 up to {MAX_TEXTURE_DIM})"
            )));
        }
        let want = texels::bc7_chain_bytes(w, h);
        let raw = zstd::bulk::decompress(&self.encoded, want)
            .map_err(|e| corrupt(format!("texture: zstd: {e}")))?;
        if raw.len() != want {
            return Err(corrupt(format!(
                "BC7 texture holds {} bytes of blocks, its {w}x{h} mip chain {want}",
                raw.len()
            )));
        }
        let mut at = 0;
        self.blocks = (0..texels::mip_level_count(w, h))
            .map(|l| {
                let (lw, lh) = texels::level_size(w, h, l);
                let n = texels::bc7_level_bytes(lw, lh);
                at += n;
                raw[at - n..at].to_vec()
            })
            .collect();
        self.encoded = Vec::new();
        Ok(())
    }

    /// Decodes the texture to RGBA8 `rgba`, checking it is `width` x `height`: PNG and
    /// JPEG from `encoded`; BC7 from its blocks (`encoded` or `blocks`), level 0 into
    /// `rgba` and the stored levels below it into `mips` (`blocks` are kept).
    pub fn decode_rgba(&mut self) -> Result<(), FormatError> {
        let codec = self
            .codec
            .ok_or_else(|| corrupt("texture without a codec"))?;
        let Some(format) = codec.format() else {
            self.decode_blocks()?;
            let (w, h) = (self.width, self.height);
            let mut levels = self.blocks.iter().enumerate().map(|(l, b)| {
                let (lw, lh) = texels::level_size(w, h, l as u32);
                texels::bc7_to_rgba(b, lw, lh)
            });
            self.rgba = levels.next().unwrap_or_default();
            self.mips = levels.collect();
            return Ok(());
        };
        let mut reader =
            image::ImageReader::with_format(std::io::Cursor::new(&self.encoded[..]), format);
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_DIM);
        limits.max_image_height = Some(MAX_TEXTURE_DIM);
        limits.max_alloc = Some(4 * u64::from(MAX_TEXTURE_DIM).pow(2) + (1 << 20));
        reader.limits(limits);
        let img = reader
            .decode()
            .map_err(|e| corrupt(format!("texture: {e}")))?;
        if img.width() != self.width || img.height() != self.height {
            return Err(corrupt(format!(
                "texture decodes to {}x{}, the patch says {}x{}",
                img.width(),
                img.height(),
                self.width,
                self.height
            )));
        }
        self.rgba = img.into_rgba8().into_raw();
        self.encoded = Vec::new();
        Ok(())
    }
}

/// Checks BC7 `levels` are the whole chain of a `width` x `height` texture (multiples
/// of 4, at most [`MAX_TEXTURE_DIM`]).
fn check_bc7(width: u32, height: u32, levels: &[Vec<u8>]) -> Result<(), FormatError> {
    if !width.is_multiple_of(4)
        || !height.is_multiple_of(4)
        || !(1..=MAX_TEXTURE_DIM).contains(&width)
        || !(1..=MAX_TEXTURE_DIM).contains(&height)
    {
        return Err(corrupt(format!(
            "BC7 texture of {width}x{height} texels (multiples of 4 up to {MAX_TEXTURE_DIM})"
        )));
    }
    let count = texels::mip_level_count(width, height) as usize;
    let sizes_fit = levels.iter().enumerate().all(|(l, b)| {
        let (lw, lh) = texels::level_size(width, height, l as u32);
        b.len() == texels::bc7_level_bytes(lw, lh)
    });
    if levels.len() != count || !sizes_fit {
        return Err(corrupt(format!(
            "BC7 texture of {width}x{height} needs {count} levels of whole blocks"
        )));
    }
    Ok(())
}

/// One node's decoded mesh patch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchData {
    /// Absolute global grid coordinates, one per vertex.
    pub positions: Vec<[u32; 3]>,
    /// Unit normals; empty when the model has no [`ATTR_NORMALS`].
    pub normals: Vec<[f32; 3]>,
    /// RGBA8 colours; empty unless [`ATTR_COLORS`].
    pub colors: Vec<[u8; 4]>,
    /// Texture coordinates; empty unless [`ATTR_UVS`].
    pub uvs: Vec<[f32; 2]>,
    /// Per vertex: grid position of the vertex it moves to in the parent's
    /// simplification (itself if it survived or was locked); empty for roots.
    pub morph_targets: Vec<[u32; 3]>,
    /// Triangle list, 3 indices per triangle.
    pub indices: Vec<u32>,
    /// The charts of the patch texture ([`ATTR_TEXTURE`]); empty otherwise.
    pub charts: Vec<TextureChart>,
    /// Per vertex: its chart (an index into `charts`); empty unless [`ATTR_TEXTURE`].
    pub chart_ids: Vec<u16>,
    /// The patch texture ([`ATTR_TEXTURE`], patches with vertices).
    pub texture: Option<PatchTexture>,
    /// Per chart, when any chart is re-cut ([`RECUT_IMAGE`]; else empty): the re-cut
    /// chart's plane, `[tu_x, tu_y, tu_z, cu, tv_x, tv_y, tv_z, cv]`, from which its
    /// vertices' UVs follow (`u = (q - quant_min) . tu + cu`, likewise v, in f64 and
    /// rounded to f32; see [`chart_plane_uv`]), so they are not stored; zeros for the
    /// other charts.
    pub chart_planes: Vec<[f32; 8]>,
}

impl PatchData {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// Encodes a patch. `attributes` are the model's `ATTR_*` bits; `quant_min` is the
/// node's `quant_min` (component-wise minimum of `patch.positions`, or any lower point).
///
/// # Panics
/// On inconsistent input, which is a bug in the caller: an attribute array whose length
/// is not the vertex count (or not empty when its `ATTR_*` bit is clear), an index count
/// that is not a multiple of 3, an index out of range, a position below `quant_min`, or
/// more than [`MAX_PATCH_VERTICES`] / [`MAX_PATCH_TRIANGLES`].
pub fn encode_patch(patch: &PatchData, attributes: u32, quant_min: [u32; 3]) -> Vec<u8> {
    let n = patch.positions.len();
    let expect_len = |bit: u32| if attributes & bit != 0 { n } else { 0 };
    assert!(
        attributes & !ATTR_ALL == 0,
        "unknown attribute bits {attributes:#x}"
    );
    assert!(
        n <= MAX_PATCH_VERTICES as usize,
        "patch has {n} vertices, max {MAX_PATCH_VERTICES}"
    );
    assert_eq!(
        patch.normals.len(),
        expect_len(ATTR_NORMALS),
        "normals length"
    );
    assert_eq!(patch.colors.len(), expect_len(ATTR_COLORS), "colors length");
    assert_eq!(patch.uvs.len(), expect_len(ATTR_UVS), "uvs length");
    assert!(
        patch.morph_targets.is_empty() || patch.morph_targets.len() == n,
        "morph_targets length {} for {n} vertices",
        patch.morph_targets.len()
    );
    assert!(
        patch.indices.len().is_multiple_of(3),
        "index count not a multiple of 3"
    );
    let triangles = patch.indices.len() / 3;
    assert!(
        triangles <= MAX_PATCH_TRIANGLES as usize,
        "patch has {triangles} triangles, max {MAX_PATCH_TRIANGLES}"
    );
    assert!(
        patch.indices.iter().all(|&i| (i as usize) < n),
        "index out of range"
    );

    let textured = attributes & ATTR_TEXTURE != 0;
    assert!(
        !textured || attributes & ATTR_UVS != 0,
        "ATTR_TEXTURE without ATTR_UVS"
    );
    if textured && n > 0 {
        assert_eq!(patch.chart_ids.len(), n, "chart_ids length");
        assert!(
            !patch.charts.is_empty() && patch.charts.len() <= MAX_PATCH_CHARTS,
            "{} charts",
            patch.charts.len()
        );
        assert!(
            patch
                .chart_ids
                .iter()
                .all(|&c| (c as usize) < patch.charts.len()),
            "chart id out of range"
        );
        let recut = patch.charts.iter().any(|c| c.image == RECUT_IMAGE);
        assert!(
            !recut
                || (patch.chart_planes.len() == patch.charts.len()
                    && patch.chart_planes.iter().flatten().all(|v| v.is_finite())),
            "re-cut charts without their planes"
        );
        let t = patch
            .texture
            .as_ref()
            .expect("a textured patch has a texture");
        assert!(
            (1..=MAX_TEXTURE_DIM).contains(&t.width)
                && (1..=MAX_TEXTURE_DIM).contains(&t.height)
                && t.codec.is_some()
                && !t.encoded.is_empty(),
            "texture {}x{} with {} encoded bytes",
            t.width,
            t.height,
            t.encoded.len()
        );
    } else {
        assert!(
            patch.charts.is_empty() && patch.chart_ids.is_empty() && patch.texture.is_none(),
            "texture data in a patch without texture"
        );
    }

    let mut sections: [Vec<u8>; SECTION_COUNT] = Default::default();
    if n > 0 {
        if triangles > 0 {
            sections[SEC_INDICES] =
                meshopt::encode_index_buffer(&patch.indices, n).expect("meshopt index encoder");
        }
        let rel: Vec<[u32; 3]> = patch
            .positions
            .iter()
            .map(|p| {
                let r = [
                    p[0].checked_sub(quant_min[0]),
                    p[1].checked_sub(quant_min[1]),
                    p[2].checked_sub(quant_min[2]),
                ];
                match r {
                    [Some(x), Some(y), Some(z)] => [x, y, z],
                    _ => panic!("position {p:?} below quant_min {quant_min:?}"),
                }
            })
            .collect();
        sections[SEC_POSITIONS] = encode_vertices(&rel);
        if attributes & ATTR_NORMALS != 0 {
            sections[SEC_NORMALS] = encode_normals(patch);
        }
        if attributes & ATTR_COLORS != 0 {
            sections[SEC_COLORS] = encode_vertices(&patch.colors);
        }
        if textured {
            // In the patch texture's space (see [`TEXEL_UV_FRACTIONS`]).
            let t = patch.texture.as_ref().expect("checked");
            let codes: Vec<[u16; 2]> = patch
                .uvs
                .iter()
                .zip(&patch.chart_ids)
                .map(|(&uv, &c)| texel_uv_code(uv, &patch.charts[c as usize], t.width, t.height))
                .collect();
            sections[SEC_UVS] = encode_vertices(&codes);
        } else if attributes & ATTR_UVS != 0 {
            let codes: Vec<[u32; 2]> = patch.uvs.iter().map(|uv| uv_code(*uv)).collect();
            sections[SEC_UVS] = encode_vertices(&codes);
        }
        if !patch.morph_targets.is_empty() {
            sections[SEC_MORPH] = encode_morph(&patch.positions, &patch.morph_targets);
        }
        if textured {
            let c = &mut sections[SEC_CHARTS];
            c.extend_from_slice(&(patch.charts.len() as u32).to_le_bytes());
            for ch in &patch.charts {
                c.extend_from_slice(&ch.image.to_le_bytes());
                for f in [ch.scale[0], ch.scale[1], ch.offset[0], ch.offset[1]] {
                    c.extend_from_slice(&f.to_le_bytes());
                }
            }
            for id in &patch.chart_ids {
                c.extend_from_slice(&id.to_le_bytes());
            }
            for (ch, plane) in patch.charts.iter().zip(&patch.chart_planes) {
                if ch.image == RECUT_IMAGE {
                    for f in plane {
                        c.extend_from_slice(&f.to_le_bytes());
                    }
                }
            }
        }
    }
    // The texture block goes after the payload, outside zstd (PNG and JPEG are
    // compressed already).
    let mut texture_block = Vec::new();
    if let Some(t) = patch.texture.as_ref().filter(|_| textured && n > 0) {
        texture_block.push(t.codec.expect("checked") as u8);
        texture_block.extend_from_slice(&[0; 3]);
        texture_block.extend_from_slice(&t.width.to_le_bytes());
        texture_block.extend_from_slice(&t.height.to_le_bytes());
        texture_block.extend_from_slice(&t.encoded);
    }

    let raw: Vec<u8> = sections.concat();
    let mut flags = 0u8;
    if !patch.morph_targets.is_empty() {
        flags |= PATCH_FLAG_MORPH;
    }
    let mut payload = Cow::Borrowed(&raw[..]);
    if !raw.is_empty() {
        if let Ok(z) = zstd_compress(&raw) {
            if z.len() < raw.len() {
                flags |= PATCH_FLAG_ZSTD;
                payload = Cow::Owned(z);
            }
        }
    }

    let mut out = Vec::with_capacity(PATCH_HEADER_BYTES + payload.len() + texture_block.len());
    out.extend_from_slice(&(n as u32).to_le_bytes());
    out.extend_from_slice(&(triangles as u32).to_le_bytes());
    out.push(PATCH_CODEC_VERSION);
    out.push(flags);
    out.push(attributes as u8);
    out.push(0);
    out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
    for s in &sections {
        out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    }
    out.extend_from_slice(&(texture_block.len() as u32).to_le_bytes());
    debug_assert_eq!(out.len(), PATCH_HEADER_BYTES);
    out.extend_from_slice(&payload);
    out.extend_from_slice(&texture_block);
    out
}

thread_local! {
    /// One zstd context per thread: creating one costs more than compressing a small
    /// patch (the builder encodes tens of thousands of patches, the viewer decodes them).
    static ZSTD_C: std::cell::RefCell<Option<zstd::bulk::Compressor<'static>>> =
        const { std::cell::RefCell::new(None) };
    static ZSTD_D: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { std::cell::RefCell::new(None) };
}

fn zstd_compress(raw: &[u8]) -> std::io::Result<Vec<u8>> {
    ZSTD_C.with(|c| {
        let mut c = c.borrow_mut();
        let c = match &mut *c {
            Some(c) => c,
            slot @ None => slot.insert(zstd::bulk::Compressor::new(ZSTD_LEVEL)?),
        };
        c.compress(raw)
    })
}

/// Decompresses one frame of at most `capacity` bytes.
fn zstd_decompress(stored: &[u8], capacity: usize) -> std::io::Result<Vec<u8>> {
    ZSTD_D.with(|d| {
        let mut d = d.borrow_mut();
        let d = match &mut *d {
            Some(d) => d,
            slot @ None => slot.insert(zstd::bulk::Decompressor::new()?),
        };
        d.decompress(stored, capacity)
    })
}

fn encode_vertices<T>(v: &[T]) -> Vec<u8> {
    meshopt::encode_vertex_buffer_level(v, VERTEX_CODEC_LEVEL, Some(VERTEX_CODEC_VERSION))
        .expect("meshopt vertex encoder")
}

/// Texture coordinates are stored on a grid of `2^-UV_FRACTION_BITS` (a 256th of a
/// texel of a 4096-texel image): integers through the vertex codec take about half the
/// bytes of raw f32 bits. Within +-2048 (wider UVs are clamped there).
pub const UV_FRACTION_BITS: u32 = 20;
const UV_LIMIT: f64 = 2048.0;

/// The stored code of a texture coordinate pair: zigzag of `round(uv * 2^20)`.
fn uv_code(uv: [f32; 2]) -> [u32; 2] {
    uv.map(|c| {
        let q = (c as f64).clamp(-UV_LIMIT, UV_LIMIT) * f64::from(1u32 << UV_FRACTION_BITS);
        zigzag(q.round().clamp(i32::MIN as f64, i32::MAX as f64) as i32)
    })
}

fn uv_from_code(c: [u32; 2]) -> [f32; 2] {
    c.map(|z| (unzigzag(z) as f64 / f64::from(1u32 << UV_FRACTION_BITS)) as f32)
}

/// Texture coordinates of textured patches are stored where they land in the patch's
/// own texture (through their chart), on a grid of `1/TEXEL_UV_FRACTIONS` of its texel,
/// as u16 pairs: the GPU samples through 16-bit coordinates anyway (1/16 texel of a
/// 4096-texel texture), and 1/8 texel is far below what filtering shows. On the
/// scissors this stores the UVs in about 55% of the bytes of source UVs on the 2^-20
/// grid. Readers map them back to source UVs through the chart (within 1/16 texel of
/// the patch texture), so the decoded patch has source UVs as before.
pub const TEXEL_UV_FRACTIONS: u32 = 8;

/// The stored code of `uv` of a vertex of `chart` in a `w` x `h` patch texture:
/// `round(chart.map(uv) * size * TEXEL_UV_FRACTIONS)`, clamped to the texture. A
/// solid-colour chart (scale 0) or a re-cut one (its plane gives the UV) stores 0.
fn texel_uv_code(uv: [f32; 2], chart: &TextureChart, w: u32, h: u32) -> [u16; 2] {
    if chart.scale == [0.0, 0.0] || chart.image == RECUT_IMAGE {
        return [0, 0];
    }
    let t = chart.map(uv);
    let q = |v: f32, n: u32| {
        let span = f64::from(n * TEXEL_UV_FRACTIONS);
        (f64::from(v) * span).round().clamp(0.0, span.min(65535.0)) as u16
    };
    [q(t[0], w), q(t[1], h)]
}

/// The source UV a stored code stands for (the inverse of [`texel_uv_code`]'s map; 0
/// on an axis the chart does not scale).
fn uv_from_texel_code(c: [u16; 2], chart: &TextureChart, w: u32, h: u32) -> [f32; 2] {
    let axis = |k: usize, n: u32| {
        let t = f64::from(c[k]) / f64::from(n * TEXEL_UV_FRACTIONS);
        let s = f64::from(chart.scale[k]);
        if s == 0.0 {
            0.0
        } else {
            ((t - f64::from(chart.offset[k])) / s) as f32
        }
    };
    [axis(0, w), axis(1, h)]
}

/// `uv` as a patch of a model without textures stores it (the builder snaps UVs first,
/// so the texture it cuts and the UVs a reader decodes agree exactly; textured patches
/// store them in their texture's space: [`TEXEL_UV_FRACTIONS`]).
pub fn stored_uv(uv: [f32; 2]) -> [f32; 2] {
    uv_from_code(uv_code(uv))
}

fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

fn unzigzag(v: u32) -> i32 {
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// Generous upper bound of a meshopt vertex-codec stream for `n` vertices of `size` bytes.
fn vertex_section_bound(n: u64, size: u64) -> u64 {
    2 * n * size + 4096
}

/// Generous upper bound of a meshopt index-codec stream for `t` triangles.
fn index_section_bound(t: u64) -> u64 {
    16 * t + 64
}

fn corrupt(detail: impl Into<String>) -> FormatError {
    FormatError::CorruptPatch {
        node: NO_NODE,
        detail: detail.into(),
    }
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    // Callers check `b.len() >= PATCH_HEADER_BYTES` first; fall back to 0 defensively.
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .unwrap_or(0)
}

/// What a node record says a patch is: its grid offset and its counts, which the
/// encoded bytes must match (named fields, so the two counts cannot be swapped).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PatchShape {
    pub quant_min: [u32; 3],
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// The node's `texture_size` (`[0, 0]` without [`ATTR_TEXTURE`]).
    pub texture_size: [u16; 2],
}

impl From<&NodeRecord> for PatchShape {
    fn from(n: &NodeRecord) -> PatchShape {
        PatchShape {
            quant_min: n.quant_min,
            vertex_count: n.vertex_count,
            triangle_count: n.triangle_count,
            texture_size: n.texture_size,
        }
    }
}

/// A patch's 48-byte header (`docs/format.md`, "Patch encoding"), read and checked
/// against the model's attribute bits and the node record's shape: every length
/// plausible for the counts, the sections summing to the payload, the texture block
/// fitting the patch. What [`decode_patch_with`] decodes the payload by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PatchHeader {
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// The payload is one zstd frame (flag bit 0).
    pub zstd: bool,
    /// Morph targets are present (flag bit 1).
    pub morph: bool,
    /// Length of the uncompressed payload (the sections' lengths summed).
    pub raw_len: u64,
    /// Uncompressed length of each section, 0 if absent.
    pub section_len: [u64; SECTION_COUNT],
    /// End of the stored payload in the patch's bytes: the texture block follows.
    pub payload_end: usize,
}

impl PatchHeader {
    /// Reads and checks the header of the patch `bytes` of a model with `attributes`
    /// for the node record's `shape`; every inconsistency is a
    /// [`FormatError::CorruptPatch`].
    pub fn parse(
        bytes: &[u8],
        attributes: u32,
        shape: PatchShape,
    ) -> Result<PatchHeader, FormatError> {
        let PatchShape {
            vertex_count,
            triangle_count,
            texture_size,
            ..
        } = shape;
        if bytes.len() < PATCH_HEADER_BYTES {
            return Err(corrupt(format!(
                "{} bytes, shorter than the {PATCH_HEADER_BYTES}-byte patch header",
                bytes.len()
            )));
        }
        let n = le_u32(bytes, 0);
        let t = le_u32(bytes, 4);
        let version = bytes[8];
        let flags = bytes[9];
        let attrs = bytes[10] as u32;
        let reserved = bytes[11];
        let raw_len = le_u32(bytes, 12) as u64;
        let lens: [u64; SECTION_COUNT] = std::array::from_fn(|k| le_u32(bytes, 16 + 4 * k) as u64);
        let texture_bytes = le_u32(bytes, 16 + 4 * SECTION_COUNT as usize) as usize;

        if version != PATCH_CODEC_VERSION {
            return Err(corrupt(format!("unknown patch codec version {version}")));
        }
        if flags & !(PATCH_FLAG_ZSTD | PATCH_FLAG_MORPH) != 0 || reserved != 0 {
            return Err(corrupt(format!(
                "unknown patch flags {flags:#x}/{reserved:#x}"
            )));
        }
        if attrs != attributes {
            return Err(corrupt(format!(
                "patch attributes {attrs:#x} differ from the model's {attributes:#x}"
            )));
        }
        if n != vertex_count || t != triangle_count {
            return Err(corrupt(format!(
                "patch has {n} vertices / {t} triangles, node record says {vertex_count} / {triangle_count}"
            )));
        }
        if n > MAX_PATCH_VERTICES || t > MAX_PATCH_TRIANGLES {
            return Err(corrupt(format!(
                "too many vertices ({n}) or triangles ({t})"
            )));
        }
        if n == 0 && t > 0 {
            return Err(corrupt("triangles without vertices"));
        }
        let morph = flags & PATCH_FLAG_MORPH != 0;
        let textured = attributes & ATTR_TEXTURE != 0;
        if textured && attributes & ATTR_UVS == 0 {
            return Err(corrupt("textures without UVs"));
        }
        let wants_texture = textured && n > 0;
        if wants_texture != (texture_bytes > 0) {
            return Err(corrupt(format!(
                "texture block of {texture_bytes} bytes in a patch that {} one",
                if wants_texture {
                    "needs"
                } else {
                    "has no use for"
                }
            )));
        }
        if (texture_size != [0, 0]) != wants_texture {
            return Err(corrupt(format!(
                "node record's texture size {texture_size:?} does not fit the patch"
            )));
        }
        let n64 = n as u64;
        let present = |on: bool, size: u64| if on && n > 0 { Some(size) } else { None };
        let expected: [Option<u64>; SECTION_COUNT] = [
            if t > 0 { Some(0) } else { None },
            present(true, 12),
            present(attributes & ATTR_NORMALS != 0, 4),
            present(attributes & ATTR_COLORS != 0, 4),
            present(attributes & ATTR_UVS != 0, 8),
            present(morph, 12),
            present(textured, 0),
        ];
        let mut sum = 0u64;
        for (k, (&len, exp)) in lens.iter().zip(expected).enumerate() {
            let bound = match exp {
                None => 0,
                Some(_) if k == SEC_INDICES => index_section_bound(t as u64),
                Some(_) if k == SEC_MORPH => 4 + 5 * n64 + vertex_section_bound(n64, 12),
                Some(_) if k == SEC_CHARTS => {
                    4 + ((CHART_BYTES + PLANE_BYTES) * MAX_PATCH_CHARTS) as u64 + 2 * n64
                }
                Some(size) => vertex_section_bound(n64, size),
            };
            if exp.is_some() && len == 0 || len > bound {
                return Err(corrupt(format!("section {k} has implausible length {len}")));
            }
            sum += len;
        }
        if sum != raw_len {
            return Err(corrupt(format!(
                "section lengths sum to {sum}, header says {raw_len}"
            )));
        }

        let Some(payload_end) = bytes
            .len()
            .checked_sub(texture_bytes)
            .filter(|&e| e >= PATCH_HEADER_BYTES)
        else {
            return Err(corrupt(format!(
                "texture block of {texture_bytes} bytes does not fit a {}-byte patch",
                bytes.len()
            )));
        };
        Ok(PatchHeader {
            vertex_count: n,
            triangle_count: t,
            zstd: flags & PATCH_FLAG_ZSTD != 0,
            morph,
            raw_len,
            section_len: lens,
            payload_end,
        })
    }
}

/// Decodes a patch produced by [`encode_patch`]. `attributes` are the model's `ATTR_*`
/// bits; `shape` comes from the node record and must match the patch. Safe on
/// arbitrary bytes: every inconsistency is a [`FormatError::CorruptPatch`] (with node
/// [`NO_NODE`]; see [`FormatError::with_node`]).
pub fn decode_patch(
    bytes: &[u8],
    attributes: u32,
    shape: PatchShape,
) -> Result<PatchData, FormatError> {
    decode_patch_with(bytes, attributes, shape, true)
}

/// [`decode_patch`], decoding the texture's image only when `texels` (picking and
/// geometry checks need no texels: the texture block is still checked for its header
/// and size, and kept encoded).
pub fn decode_patch_with(
    bytes: &[u8],
    attributes: u32,
    shape: PatchShape,
    texels: bool,
) -> Result<PatchData, FormatError> {
    let PatchHeader {
        vertex_count: n,
        triangle_count: t,
        zstd,
        morph,
        raw_len,
        section_len: lens,
        payload_end,
    } = PatchHeader::parse(bytes, attributes, shape)?;
    let PatchShape {
        quant_min,
        texture_size,
        ..
    } = shape;
    let textured = attributes & ATTR_TEXTURE != 0;
    let stored = &bytes[PATCH_HEADER_BYTES..payload_end];
    let payload: Cow<[u8]> = if zstd {
        let out =
            zstd_decompress(stored, raw_len as usize).map_err(|e| corrupt(format!("zstd: {e}")))?;
        Cow::Owned(out)
    } else {
        Cow::Borrowed(stored)
    };
    if payload.len() as u64 != raw_len {
        return Err(corrupt(format!(
            "payload is {} bytes, header says {raw_len}",
            payload.len()
        )));
    }

    // Split the payload into sections (lengths were summed and checked above).
    let mut secs: [&[u8]; SECTION_COUNT] = [&[]; SECTION_COUNT];
    let mut at = 0usize;
    for (k, &len) in lens.iter().enumerate() {
        let end = at + len as usize;
        secs[k] = payload
            .get(at..end)
            .ok_or_else(|| corrupt("section out of payload"))?;
        at = end;
    }

    let nu = n as usize;
    let mut patch = PatchData::default();
    if t > 0 {
        let indices: Vec<u32> = meshopt::decode_index_buffer(secs[SEC_INDICES], t as usize * 3)
            .map_err(|e| corrupt(format!("index codec: {e}")))?;
        if let Some(bad) = indices.iter().find(|&&i| i >= n) {
            return Err(corrupt(format!("index {bad} >= vertex count {n}")));
        }
        patch.indices = indices;
    }
    if n == 0 {
        return Ok(patch);
    }
    let rel: Vec<[u32; 3]> = decode_vertices(secs[SEC_POSITIONS], nu, "positions")?;
    let mut positions = Vec::with_capacity(nu);
    for r in &rel {
        match [
            r[0].checked_add(quant_min[0]),
            r[1].checked_add(quant_min[1]),
            r[2].checked_add(quant_min[2]),
        ] {
            [Some(x), Some(y), Some(z)] => positions.push([x, y, z]),
            _ => return Err(corrupt("position overflows the grid")),
        }
    }
    if attributes & ATTR_NORMALS != 0 {
        patch.normals = decode_normals(secs[SEC_NORMALS], &positions, &patch.indices)?;
    }
    if attributes & ATTR_COLORS != 0 {
        patch.colors = decode_vertices(secs[SEC_COLORS], nu, "colors")?;
    }
    if textured {
        (patch.charts, patch.chart_ids, patch.chart_planes) = decode_charts(secs[SEC_CHARTS], nu)?;
        let [w, h] = texture_size.map(u32::from);
        let codes: Vec<[u16; 2]> = decode_vertices(secs[SEC_UVS], nu, "uvs")?;
        patch.uvs = codes
            .iter()
            .zip(&patch.chart_ids)
            .zip(&rel)
            .map(|((&c, &id), r)| {
                let chart = &patch.charts[id as usize];
                if chart.image == RECUT_IMAGE {
                    chart_plane_uv(&patch.chart_planes[id as usize], *r)
                } else {
                    uv_from_texel_code(c, chart, w, h)
                }
            })
            .collect();
        if patch.uvs.iter().flatten().any(|v| !v.is_finite()) {
            return Err(corrupt("a chart maps texture coordinates to infinity"));
        }
    } else if attributes & ATTR_UVS != 0 {
        let codes: Vec<[u32; 2]> = decode_vertices(secs[SEC_UVS], nu, "uvs")?;
        patch.uvs = codes.iter().map(|c| uv_from_code(*c)).collect();
    }
    if morph {
        patch.morph_targets = decode_morph(secs[SEC_MORPH], &positions)?;
    }
    if textured {
        let mut t = decode_texture_block(&bytes[payload_end..], texture_size)?;
        if texels {
            if t.codec == Some(TextureCodec::Bc7) {
                t.decode_blocks()?;
            } else {
                t.decode_rgba()?;
            }
        }
        patch.texture = Some(t);
    }
    patch.positions = positions;
    Ok(patch)
}

/// The UV of a vertex of a re-cut chart with `plane` at `rel`, its grid position less
/// the patch's `quant_min` (see [`PatchData::chart_planes`]).
pub fn chart_plane_uv(plane: &[f32; 8], rel: [u32; 3]) -> [f32; 2] {
    chart_plane_at(plane, rel.map(f64::from)).map(|c| c as f32)
}

/// [`chart_plane_uv`] before its rounding to f32, at any `rel` (the builder also
/// projects points outside the patch's box, below its `quant_min`): the one formula the
/// builder's UVs and every reader's share, so they agree exactly.
pub fn chart_plane_at(plane: &[f32; 8], r: [f64; 3]) -> [f64; 2] {
    let axis = |k: usize| {
        let p = &plane[4 * k..4 * k + 4];
        r[0] * f64::from(p[0]) + r[1] * f64::from(p[1]) + r[2] * f64::from(p[2]) + f64::from(p[3])
    };
    [axis(0), axis(1)]
}

/// Charts, chart ids and planes: what [`decode_charts`] reads.
type Charts = (Vec<TextureChart>, Vec<u16>, Vec<[f32; 8]>);

/// The charts section: `u32 count`, `count` charts, `n` u16 chart ids, then the plane of
/// every re-cut chart (8 f32 each, in chart order).
fn decode_charts(sec: &[u8], n: usize) -> Result<Charts, FormatError> {
    let count = le_u32(sec, 0) as usize;
    if sec.len() < 4 || count == 0 || count > MAX_PATCH_CHARTS {
        return Err(corrupt(format!("{count} texture charts")));
    }
    let images_end = 4 + CHART_BYTES * count;
    if sec.len() < images_end {
        return Err(corrupt(format!(
            "charts section of {} bytes for {count} charts",
            sec.len()
        )));
    }
    let recut = (0..count)
        .filter(|k| le_u32(sec, 4 + CHART_BYTES * k) == RECUT_IMAGE)
        .count();
    if sec.len() != images_end + 2 * n + PLANE_BYTES * recut {
        return Err(corrupt(format!(
            "charts section of {} bytes for {count} charts and {n} vertices",
            sec.len()
        )));
    }
    let f = |at: usize| f32::from_le_bytes(sec[at..at + 4].try_into().expect("4 bytes"));
    let charts: Vec<TextureChart> = (0..count)
        .map(|k| {
            let at = 4 + CHART_BYTES * k;
            TextureChart {
                image: le_u32(sec, at),
                scale: [f(at + 4), f(at + 8)],
                offset: [f(at + 12), f(at + 16)],
            }
        })
        .collect();
    if charts
        .iter()
        .any(|c| !(c.scale.iter().chain(&c.offset).all(|v| v.is_finite())))
    {
        return Err(corrupt("non-finite texture chart"));
    }
    let ids_at = 4 + CHART_BYTES * count;
    let planes_at = ids_at + 2 * n;
    let ids: Vec<u16> = sec[ids_at..planes_at]
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    if let Some(bad) = ids.iter().find(|&&c| c as usize >= count) {
        return Err(corrupt(format!("chart id {bad} of {count} charts")));
    }
    let mut planes = Vec::new();
    if recut > 0 {
        let mut at = planes_at;
        for c in &charts {
            let mut p = [0f32; 8];
            if c.image == RECUT_IMAGE {
                for (k, v) in p.iter_mut().enumerate() {
                    *v = f(at + 4 * k);
                }
                at += PLANE_BYTES;
                if !p.iter().all(|v| v.is_finite()) {
                    return Err(corrupt("non-finite re-cut chart plane"));
                }
            }
            planes.push(p);
        }
    }
    Ok((charts, ids, planes))
}

/// The texture block: codec byte, 3 zero bytes, width, height, the encoded image.
fn decode_texture_block(b: &[u8], size: [u16; 2]) -> Result<PatchTexture, FormatError> {
    if b.len() <= TEXTURE_HEADER_BYTES {
        return Err(corrupt(format!("texture block of {} bytes", b.len())));
    }
    let codec = TextureCodec::from_byte(b[0])
        .filter(|_| b[1..4] == [0; 3])
        .ok_or_else(|| corrupt(format!("unknown texture codec {}", b[0])))?;
    let (width, height) = (le_u32(b, 4), le_u32(b, 8));
    if [width, height] != [u32::from(size[0]), u32::from(size[1])] {
        return Err(corrupt(format!(
            "texture is {width}x{height}, the node record says {}x{}",
            size[0], size[1]
        )));
    }
    Ok(PatchTexture {
        width,
        height,
        codec: Some(codec),
        encoded: b[TEXTURE_HEADER_BYTES..].to_vec(),
        ..Default::default()
    })
}

fn decode_vertices<T: Clone + Default>(
    section: &[u8],
    n: usize,
    what: &str,
) -> Result<Vec<T>, FormatError> {
    meshopt::decode_vertex_buffer(section, n).map_err(|e| corrupt(format!("{what} codec: {e}")))
}
