//! The patch texture encoders (BC7 with its mip chain, PNG, JPEG) and the baked texture
//! they produce: what the hierarchy stores with a patch, and what a re-cut parent bakes
//! from ([`crate::recut`] reads it, so it lives here, below both texture paths).

use tessera_format::{texels, PatchTexture, TextureChart, TextureCodec};

use crate::BuildError;

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

/// Encodes a `w` x `h` RGBA8 patch texture with `codec` (`quality`: JPEG's, 1..=100).
pub(crate) fn encode_texture(
    w: u32,
    h: u32,
    rgba: &[u8],
    codec: TextureCodec,
    quality: u8,
) -> Result<PatchTexture, BuildError> {
    Ok(match codec {
        TextureCodec::Bc7 => encode_bc7(w, h, rgba)?,
        codec => PatchTexture::encode(w, h, rgba, codec, quality)?,
    })
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
