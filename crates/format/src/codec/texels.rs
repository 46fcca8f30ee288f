//! Texel arithmetic shared by the builder, the renderers and the browser: mip chains of
//! RGBA8 patch textures (the box filter every reader uses, and the builder stores for
//! BC7) and BC7 blocks (sizes, decoding to RGBA8 where a GPU cannot sample them).
//!
//! BC7 decoding is `bcdec_rs` (a port of bcdec, pure Rust, so it builds for the browser
//! too). Encoding needs a real encoder (Intel's ISPC kernels, `intel_tex_2`) and lives
//! in the builder, which is never compiled to WebAssembly.

/// Bytes of one 4x4 BC7 block.
pub const BC7_BLOCK_BYTES: usize = 16;

/// Number of levels of a full mip chain of a `width` x `height` texture (down to 1x1).
pub fn mip_level_count(width: u32, height: u32) -> u32 {
    32 - width.max(height).max(1).leading_zeros()
}

/// Size of mip `level` of a `width` x `height` texture.
#[inline]
pub fn level_size(width: u32, height: u32, level: u32) -> (u32, u32) {
    ((width >> level).max(1), (height >> level).max(1))
}

/// The first mip level of a `width` x `height` texture whose size fits `max_dim` (a
/// device's largest texture: the levels above it are not uploaded).
pub fn first_level(width: u32, height: u32, max_dim: u32) -> u32 {
    let max_dim = max_dim.max(1);
    let mut l = 0;
    while width.max(height) >> l > max_dim {
        l += 1;
    }
    l
}

/// Whether a `width` x `height` BC7 texture can be uploaded as blocks to a device whose
/// largest texture is `max_dim`: the first level that fits has whole blocks (level 0
/// always has; a texture above the device's limit starts lower, at a size that may not
/// be, and is then decoded to RGBA8).
pub fn bc7_uploads_as_blocks(width: u32, height: u32, max_dim: u32) -> bool {
    let (w, h) = level_size(width, height, first_level(width, height, max_dim));
    w % 4 == 0 && h % 4 == 0
}

/// Bytes of the BC7 blocks of a `width` x `height` level (whole 4x4 blocks: a 2x1 level
/// is one block, as GPUs store it).
pub fn bc7_level_bytes(width: u32, height: u32) -> usize {
    width.div_ceil(4) as usize * height.div_ceil(4) as usize * BC7_BLOCK_BYTES
}

/// Bytes of the BC7 blocks of every level of a `width` x `height` texture's full chain.
pub fn bc7_chain_bytes(width: u32, height: u32) -> usize {
    (0..mip_level_count(width, height))
        .map(|l| {
            let (w, h) = level_size(width, height, l);
            bc7_level_bytes(w, h)
        })
        .sum()
}

/// Decodes one level of BC7 `blocks` (`bc7_level_bytes(width, height)` bytes, rows of
/// blocks top to bottom) to `width` x `height` RGBA8 (the texels of partial blocks past
/// the edge are dropped).
pub fn bc7_to_rgba(blocks: &[u8], width: u32, height: u32) -> Vec<u8> {
    let (bw, bh) = (width.div_ceil(4) as usize, height.div_ceil(4) as usize);
    assert_eq!(blocks.len(), bw * bh * BC7_BLOCK_BYTES, "BC7 level size");
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![0u8; 4 * w * h];
    let mut tile = [0u8; 64];
    for by in 0..bh {
        for bx in 0..bw {
            let b = &blocks[(by * bw + bx) * BC7_BLOCK_BYTES..][..BC7_BLOCK_BYTES];
            bcdec_rs::bc7(b, &mut tile, 16);
            for ty in 0..4.min(h - 4 * by) {
                let x0 = 4 * bx;
                let n = 4.min(w - x0);
                let dst = 4 * ((4 * by + ty) * w + x0);
                out[dst..dst + 4 * n].copy_from_slice(&tile[16 * ty..16 * ty + 4 * n]);
            }
        }
    }
    out
}

/// Per destination texel along one axis (`n` source texels onto `m`): the first source
/// texel and the weights of it and the following ones (the exact overlap of the
/// destination texel's footprint with each source texel, summing to 1).
fn axis_weights(n: u32, m: u32) -> Vec<(usize, Vec<f32>)> {
    let s = f64::from(n) / f64::from(m);
    (0..m)
        .map(|x| {
            let (a, b) = (f64::from(x) * s, f64::from(x + 1) * s);
            let i0 = a.floor() as usize;
            let i1 = (b.ceil() as usize).min(n as usize).max(i0 + 1);
            let w = (i0..i1)
                .map(|i| ((b.min(i as f64 + 1.0) - a.max(i as f64)) / s) as f32)
                .collect();
            (i0, w)
        })
        .collect()
}

/// The next mip level of `src` (`w` x `h` RGBA8, rows top to bottom): half the size
/// (rounded down, at least 1), each texel the area-weighted mean of the source texels
/// its footprint covers (a box filter; odd sizes weigh the shared texels by their
/// overlap).
pub fn downsample(src: &[u8], w: u32, h: u32) -> (Vec<u8>, u32, u32) {
    let (dw, dh) = ((w / 2).max(1), (h / 2).max(1));
    let xs = axis_weights(w, dw);
    let ys = axis_weights(h, dh);
    let row_bytes = 4 * w as usize;
    let mut out = Vec::with_capacity(4 * dw as usize * dh as usize);
    let mut acc = vec![0f32; 4 * dw as usize];
    let mut filtered = vec![0f32; 4 * dw as usize];
    for (y0, wy) in &ys {
        acc.iter_mut().for_each(|a| *a = 0.0);
        for (dy, &fy) in wy.iter().enumerate() {
            let row = &src[(y0 + dy) * row_bytes..(y0 + dy + 1) * row_bytes];
            for (d, (x0, wx)) in xs.iter().enumerate() {
                let mut px = [0f32; 4];
                for (dx, &fx) in wx.iter().enumerate() {
                    let s = &row[4 * (x0 + dx)..4 * (x0 + dx) + 4];
                    for c in 0..4 {
                        px[c] += fx * f32::from(s[c]);
                    }
                }
                filtered[4 * d..4 * d + 4].copy_from_slice(&px);
            }
            for (a, f) in acc.iter_mut().zip(&filtered) {
                *a += fy * f;
            }
        }
        out.extend(acc.iter().map(|&v| (v + 0.5).clamp(0.0, 255.0) as u8));
    }
    (out, dw, dh)
}

/// Mip levels 1, 2, .. (down to 1x1) of `rgba` (`width` x `height`), each
/// [`downsample`] of the last: what a reader makes for a PNG or JPEG texture, and what
/// the builder encodes for a BC7 one.
pub fn mip_chain(rgba: &[u8], width: u32, height: u32) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = Vec::new();
    let (mut w, mut h) = (width, height);
    for _ in 1..mip_level_count(width, height) {
        let (next, nw, nh) = downsample(out.last().map_or(rgba, |v| &v[..]), w, h);
        out.push(next);
        (w, h) = (nw, nh);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bc7_sizes_count_whole_blocks() {
        assert_eq!(bc7_level_bytes(4, 4), 16);
        assert_eq!(bc7_level_bytes(1, 1), 16);
        assert_eq!(bc7_level_bytes(8, 5), 2 * 2 * 16);
        // 8x4, 4x2, 2x1, 1x1: one, one, one and one block after the first two.
        assert_eq!(bc7_chain_bytes(8, 4), (2 + 1 + 1 + 1) * 16);
    }

    #[test]
    fn a_bc7_block_of_one_colour_decodes_to_it_and_edges_crop() {
        // Mode 6 (bit 6, LSB first), then every endpoint bit and p-bit set: both
        // endpoints are 255 in all four channels, so every texel is white whatever
        // its index.
        let mut block = [0xFFu8; 16];
        block[0] = 0xC0;
        let rgba = bc7_to_rgba(&block, 3, 2);
        assert_eq!(rgba, vec![255; 4 * 3 * 2]);
        // Two blocks side by side, cropped to 5x4: the second block's first column.
        let mut two = [0u8; 32];
        two[16..].copy_from_slice(&block);
        two[0] = 0x40; // mode 6, all endpoints 0: transparent black
        let rgba = bc7_to_rgba(&two, 5, 4);
        for y in 0..4 {
            assert_eq!(rgba[4 * (5 * y + 3)..4 * (5 * y + 4)], [0, 0, 0, 0]);
            assert_eq!(rgba[4 * (5 * y + 4)..4 * (5 * y + 5)], [255; 4]);
        }
        // An invalid block (mode byte 0) decodes to zeros, never panics.
        let zeros = bc7_to_rgba(&[0u8; 16], 4, 4);
        assert!(zeros.iter().all(|&b| b == 0));
    }
}
