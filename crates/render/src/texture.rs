//! Patch textures on the GPU (models with `ATTR_TEXTURE`): one wgpu texture per
//! resident patch, sampled through bind group 1 of the textured pipeline. BC7 textures
//! go up as their stored blocks and mips ([`BC7_TEXTURE_FORMAT`]) where the device has
//! `TEXTURE_COMPRESSION_BC`, else decoded to RGBA8 with their stored mips; PNG and JPEG
//! textures as RGBA8 with a full mip chain made on the CPU at upload.
//!
//! Format: `Rgba8Unorm`, not the sRGB variant. The texels are sRGB-encoded like vertex
//! colours, and the untextured path treats vertex colours as plain values (Unorm8x4
//! attributes, interpolated and lit as they are); sampling a Unorm texture gives the same
//! values, so a textured patch looks exactly like the same colours given per vertex. The
//! mips are box-filtered over the same plain values, as the rasteriser interpolates
//! vertex colours.
//!
//! Everything here works on WebGL2 (wgpu's downlevel WebGL2 limits): 2D textures with
//! mips (non-power-of-two sizes allowed in GL ES 3.0), a filtering sampler, one texture
//! and one sampler binding. A texture larger than the device's limit (the format
//! guarantees at most 4096, WebGL2's guaranteed minimum is 2048) starts at the first
//! mip level that fits.

/// Format of every patch texture (see the module docs for why not sRGB).
pub const PATCH_TEXTURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

use tessera_format::texels::{bc7_level_bytes, first_level};
pub use tessera_format::texels::{
    bc7_uploads_as_blocks, downsample, level_size, mip_chain, mip_level_count,
};

/// Format of BC7 patch textures (`TextureCodec::Bc7`), Unorm like
/// [`PATCH_TEXTURE_FORMAT`] and for the same reason.
pub const BC7_TEXTURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Bc7RgbaUnorm;

/// GPU bytes of a `width` x `height` RGBA8 patch texture with its mip chain (about 4/3 of
/// `4 * width * height`), as uploaded to a device whose largest texture is `max_dim`
/// texels (the levels above it are not uploaded). 0 when either size is 0 (no texture).
pub fn texture_gpu_bytes(width: u32, height: u32, max_dim: u32) -> u64 {
    texture_gpu_bytes_as(width, height, max_dim, false)
}

/// [`texture_gpu_bytes`] of a texture uploaded as BC7 blocks (`bc7`: 1 byte a texel,
/// whole 4x4 blocks) or as RGBA8.
pub fn texture_gpu_bytes_as(width: u32, height: u32, max_dim: u32, bc7: bool) -> u64 {
    if width == 0 || height == 0 {
        return 0;
    }
    (first_level(width, height, max_dim)..mip_level_count(width, height))
        .map(|l| {
            let (w, h) = level_size(width, height, l);
            if bc7 {
                bc7_level_bytes(w, h) as u64
            } else {
                4 * u64::from(w) * u64::from(h)
            }
        })
        .sum()
}

/// Whether `mips` are the whole chain below a `width` x `height` level 0, each of its
/// level's size.
fn mips_fit(width: u32, height: u32, mips: &[Vec<u8>]) -> bool {
    mips.len() as u32 + 1 == mip_level_count(width, height)
        && mips.iter().enumerate().all(|(i, m)| {
            let (w, h) = level_size(width, height, i as u32 + 1);
            m.len() as u64 == 4 * u64::from(w) * u64::from(h)
        })
}

/// Copies one level of `texture` (its mip `mip_level`, `size` texels: whole 4x4 blocks
/// for BC7) from `data`, `rows[1]` rows of `rows[0]` bytes.
fn write_level(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    mip_level: u32,
    data: &[u8],
    rows: [u32; 2],
    size: [u32; 2],
) {
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(rows[0]),
            rows_per_image: Some(rows[1]),
        },
        wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        },
    );
}

/// The bind group layout of a patch texture (group 1 of the textured pipeline): the
/// texture at binding 0, its sampler at binding 1.
pub fn texture_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("tessera patch texture layout"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    })
}

/// A bind group of [`texture_bind_group_layout`]: `view` and `sampler`.
pub(crate) fn texture_bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    view: &wgpu::TextureView,
    sampler: &wgpu::Sampler,
    label: &str,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(view),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    })
}

/// A patch texture as the GPU cache holds it (in its [`crate::Slot`]): the texture and
/// the bind group the textured pipeline draws it with. Dropped (freed) with its slot.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlotTexture {
    pub texture: wgpu::Texture,
    pub bind_group: wgpu::BindGroup,
    /// GPU bytes of the texture, mips included; 0 for the shared grey stand-in of a
    /// textured patch that came without its texture.
    pub bytes: u64,
}

/// What the GPU cache needs for textures, made at its first textured upload (models
/// without textures never pay for it): the bind group layout, one sampler shared by
/// every patch, and the 1x1 grey stand-in.
pub(crate) struct TextureKit {
    pub layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    grey: Option<SlotTexture>,
}

impl TextureKit {
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> TextureKit {
        let layout = texture_bind_group_layout(device);
        // Linear, trilinear between mips, clamped: the builder puts gutters around the
        // charts, so a footprint that reaches past a chart's edge reads its own colours.
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("tessera patch texture sampler"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let mut kit = TextureKit {
            layout,
            sampler,
            grey: None,
        };
        let mut grey = kit.upload(device, queue, 1, 1, &[128, 128, 128, 255], &[], 1 << 14);
        grey.bytes = 0;
        kit.grey = Some(grey);
        kit
    }

    /// The 1x1 grey stand-in for a textured patch that came without its texture
    /// (shared: 0 bytes in the slots that use it).
    pub fn grey(&self) -> SlotTexture {
        self.grey.clone().expect("made with the kit")
    }

    /// A texture for the levels of a `width` x `height` image from the first that fits
    /// `max_dim` down; returns it, that first level and the whole chain's level count.
    fn create(
        device: &wgpu::Device,
        width: u32,
        height: u32,
        max_dim: u32,
        format: wgpu::TextureFormat,
    ) -> (wgpu::Texture, u32, u32) {
        let first = first_level(width, height, max_dim);
        let levels = mip_level_count(width, height);
        let (w0, h0) = level_size(width, height, first);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("tessera patch texture"),
            size: wgpu::Extent3d {
                width: w0,
                height: h0,
                depth_or_array_layers: 1,
            },
            mip_level_count: levels - first,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        (texture, first, levels)
    }

    /// Uploads `rgba` (`width` x `height`, rows top to bottom, `4 * width * height`
    /// bytes) with its mip chain, from the first level that fits `max_dim`. `mips` are
    /// levels 1.. when made ahead ([`mip_chain`], the browser's decode workers); when
    /// they are not the whole chain of the right sizes they are made here.
    #[allow(clippy::too_many_arguments)]
    pub fn upload(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        width: u32,
        height: u32,
        rgba: &[u8],
        mips: &[Vec<u8>],
        max_dim: u32,
    ) -> SlotTexture {
        let (texture, first, levels) =
            Self::create(device, width, height, max_dim, PATCH_TEXTURE_FORMAT);
        let made = mips_fit(width, height, mips);
        let mut level: std::borrow::Cow<[u8]> = std::borrow::Cow::Borrowed(rgba);
        let (mut w, mut h) = (width, height);
        let mut bytes = 0;
        for l in 0..levels {
            if l > 0 {
                if made {
                    level = std::borrow::Cow::Borrowed(&mips[l as usize - 1]);
                    (w, h) = level_size(width, height, l);
                } else {
                    let (next, nw, nh) = downsample(&level, w, h);
                    (level, w, h) = (std::borrow::Cow::Owned(next), nw, nh);
                }
            }
            if l < first {
                continue;
            }
            write_level(queue, &texture, l - first, &level, [4 * w, h], [w, h]);
            bytes += 4 * u64::from(w) * u64::from(h);
        }
        self.bind(device, texture, bytes)
    }

    /// Uploads a BC7 texture's `blocks` (every level, level 0 first) from the first
    /// level that fits `max_dim`, as blocks: the device has BC sampling, and that level
    /// has whole blocks ([`bc7_uploads_as_blocks`]).
    pub fn upload_bc7(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        width: u32,
        height: u32,
        blocks: &[Vec<u8>],
        max_dim: u32,
    ) -> SlotTexture {
        let (texture, first, levels) =
            Self::create(device, width, height, max_dim, BC7_TEXTURE_FORMAT);
        let mut bytes = 0;
        for l in first..levels {
            let (w, h) = level_size(width, height, l);
            // Whole blocks: a level smaller than a block is stored (and copied) as one.
            let (bw, bh) = (w.div_ceil(4), h.div_ceil(4));
            let data = &blocks[l as usize];
            debug_assert_eq!(data.len(), bc7_level_bytes(w, h));
            write_level(
                queue,
                &texture,
                l - first,
                data,
                [16 * bw, bh],
                [4 * bw, 4 * bh],
            );
            bytes += data.len() as u64;
        }
        self.bind(device, texture, bytes)
    }

    /// The slot texture of `texture` (`bytes` on the GPU): its view and bind group.
    fn bind(&self, device: &wgpu::Device, texture: wgpu::Texture, bytes: u64) -> SlotTexture {
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("tessera patch texture view"),
            ..Default::default()
        });
        let bind_group = texture_bind_group(
            device,
            &self.layout,
            &view,
            &self.sampler,
            "tessera patch texture bind group",
        );
        SlotTexture {
            texture,
            bind_group,
            bytes,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mip_chain_bytes() {
        assert_eq!(mip_level_count(1, 1), 1);
        assert_eq!(mip_level_count(64, 64), 7);
        assert_eq!(mip_level_count(5, 3), 3);
        assert_eq!(texture_gpu_bytes(64, 64, 4096), 4 * 5461);
        // 5x3 -> 2x1 -> 1x1.
        assert_eq!(texture_gpu_bytes(5, 3, 4096), 4 * (15 + 2 + 1));
        // A device whose largest texture is 32 starts at level 1.
        assert_eq!(texture_gpu_bytes(64, 64, 32), 4 * (5461 - 4096));
        assert_eq!(texture_gpu_bytes(0, 7, 4096), 0);
        // About 4/3 of the base level.
        let b = texture_gpu_bytes(1000, 600, 4096) as f64 / (4.0 * 1000.0 * 600.0);
        assert!((b - 4.0 / 3.0).abs() < 0.01, "{b}");
    }

    #[test]
    fn box_filter_keeps_means() {
        // 2x2 -> 1x1: the mean.
        let src = [
            0, 0, 0, 255, 100, 0, 0, 255, 0, 200, 0, 255, 100, 200, 40, 255,
        ];
        let (d, w, h) = downsample(&src, 2, 2);
        assert_eq!((w, h), (1, 1));
        assert_eq!(d, vec![50, 100, 10, 255]);
        // 3x1 -> 1x1: every texel weighs a third.
        let src = [30, 0, 0, 0, 60, 0, 0, 0, 90, 0, 0, 0];
        let (d, w, h) = downsample(&src, 3, 1);
        assert_eq!((w, h), (1, 1));
        assert_eq!(d, vec![60, 0, 0, 0]);
        // 5x1 -> 2x1: 2.5 texels each, the middle one shared.
        let src: Vec<u8> = [10u8, 20, 30, 40, 50]
            .iter()
            .flat_map(|&v| [v, v, v, v])
            .collect();
        let (d, w, _) = downsample(&src, 5, 1);
        assert_eq!(w, 2);
        // (10 + 20) * 0.4 + 30 * 0.2 and 30 * 0.2 + (40 + 50) * 0.4.
        assert_eq!(d[0], 18);
        assert_eq!(d[4], 42);
    }

    #[test]
    fn mip_chain_is_the_upload_chain() {
        // 5x3: levels 2x1, 1x1, each the downsample of the last.
        let src: Vec<u8> = (0..5 * 3 * 4).map(|i| (i * 7 % 251) as u8).collect();
        let chain = mip_chain(&src, 5, 3);
        assert_eq!(chain.len(), 2);
        let (l1, w1, h1) = downsample(&src, 5, 3);
        assert_eq!((w1, h1), (2, 1));
        assert_eq!(chain[0], l1);
        assert_eq!(chain[1], downsample(&l1, 2, 1).0);
        assert!(mips_fit(5, 3, &chain));
        // Anything else is made again at upload.
        assert!(!mips_fit(5, 3, &chain[..1]));
        assert!(!mips_fit(5, 3, &[chain[0].clone(), vec![0; 8]]));
        assert!(mips_fit(1, 1, &[]));
        assert!(mip_chain(&[1, 2, 3, 4], 1, 1).is_empty());
    }
}
