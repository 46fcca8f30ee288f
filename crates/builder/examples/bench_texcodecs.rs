//! Issue 11 ("GPU formats"): measures candidate codecs for patch textures.
//!
//! ```text
//! cargo run --release -p tessera-build --example bench_texcodecs -- \
//!     [--sizes 256,1024,2048,full] [--only SUBSTRING] [IMAGE ...]
//! ```
//!
//! For every input image (default: the YCB scissors scan's 4096x4096 texture in
//! `../shared/data`) and for square crops of typical patch sizes (of each size the most
//! covered crop, a texel counting as covered when one of its channels exceeds 16: the scan's
//! atlas is about three quarters black background, a patch texture mostly charts) it
//! encodes with every codec and prints one row per codec. `A -> B`: stored as A, turned
//! into B at load; `+zstd9`: the stored bytes zstd-compressed at level 9 (KTX2/Basis
//! Universal, measured with the `basis-universal` 0.3 crate, is left out: its C++ encoder
//! takes minutes to build on every fresh test build). Columns:
//!
//! - `stored`: bytes per texel of what the file would hold (mips included where the
//!   format stores them: the block formats do, PNG and JPEG store level 0 only),
//! - `gpu`: bytes per texel on the GPU with the full mip chain (RGBA8 5.33, BC7 1.33,
//!   BC1 0.67),
//! - `enc`: encode speed at build time in Mtexel/s of level-0 texels, one thread, making
//!   the mip chain included where the stored form holds one,
//! - `dec`: decode or transcode to what the GPU gets, Mtexel/s of level-0 texels, one
//!   thread; `load` adds the CPU box-filtered mip chain that the renderer builds for RGBA8
//!   (crates/render/src/texture.rs); for formats that store mips `load` = `dec`,
//! - `psnr`: PSNR (RGB, 8 bits) of level 0 as the GPU samples it (block formats decoded
//!   with `bcdec_rs`) against the source texels, over all texels, and `psnr-cov` over the
//!   covered texels only.
//!
//! Timings are CPU time of the calling thread (every codec runs on it alone), the best of repeated runs (at least 0.3 s in all, one run for slow ones).

use std::time::Instant;

// intel_tex_2's ISPC kernels are C++ objects: unoptimised builds keep their references to
// the C++ runtime (`__gxx_personality_v0`), which Rust does not link by itself.
#[link(name = "stdc++")]
extern "C" {}

/// An RGBA8 image, rows top to bottom.
struct Image {
    w: u32,
    h: u32,
    rgba: Vec<u8>,
}

/// What the GPU gets.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum GpuFormat {
    Rgba8,
    Bc7,
    Bc1,
}

impl GpuFormat {
    fn name(self) -> &'static str {
        match self {
            GpuFormat::Rgba8 => "rgba8",
            GpuFormat::Bc7 => "bc7",
            GpuFormat::Bc1 => "bc1",
        }
    }

    /// Bytes of one 4x4 block (RGBA8: of one texel).
    fn unit_bytes(self) -> usize {
        match self {
            GpuFormat::Rgba8 => 4,
            GpuFormat::Bc7 => 16,
            GpuFormat::Bc1 => 8,
        }
    }

    /// Bytes of a `w` x `h` level.
    fn level_bytes(self, w: u32, h: u32) -> usize {
        match self {
            GpuFormat::Rgba8 => 4 * w as usize * h as usize,
            _ => self.unit_bytes() * w.div_ceil(4) as usize * h.div_ceil(4) as usize,
        }
    }
}

/// A texture as uploaded: `levels[0]` is the full-size level.
struct GpuTexture {
    format: GpuFormat,
    levels: Vec<Vec<u8>>,
}

/// Source image to the stored bytes.
type EncodeFn = Box<dyn Fn(&Image) -> Vec<u8>>;
type DecodeFn = Box<dyn Fn(&[u8], u32, u32) -> GpuTexture>;

struct Codec {
    name: &'static str,
    /// Build time.
    encode: EncodeFn,
    /// Stored bytes to what the GPU gets (load time); RGBA8 codecs return level 0 only.
    decode: DecodeFn,
    /// Whether loading adds the CPU mip chain after `decode`.
    cpu_mips: bool,
}

fn main() {
    let mut sizes: Vec<Option<u32>> = vec![None, Some(2048), Some(1024), Some(256)];
    let mut only: Vec<String> = Vec::new();
    let mut inputs: Vec<String> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--sizes" => {
                let list = args
                    .next()
                    .expect("--sizes needs a list, e.g. 256,1024,full");
                sizes = list
                    .split(',')
                    .map(|s| match s {
                        "full" => None,
                        n => Some(n.parse().expect("a size is a number or `full`")),
                    })
                    .collect();
            }
            "--only" => only.push(args.next().expect("--only needs a substring")),
            "-h" | "--help" => {
                println!(
                    "bench_texcodecs [--sizes 256,1024,2048,full] [--only SUBSTRING] [IMAGE ...]"
                );
                return;
            }
            _ => inputs.push(arg),
        }
    }
    if inputs.is_empty() {
        inputs.push(
            concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../../shared/data/ycb-scissors/texture_map.png"
            )
            .to_string(),
        );
    }
    let codecs: Vec<Codec> = codecs()
        .into_iter()
        .filter(|c| only.is_empty() || only.iter().any(|o| c.name.contains(o.as_str())))
        .collect();
    println!(
        "one thread, speeds in Mtexel/s of level-0 texels per CPU second of this thread; \
         stored/gpu in bytes per texel"
    );
    for path in &inputs {
        let t = Instant::now();
        let full = image::open(path)
            .unwrap_or_else(|e| panic!("{path}: {e}"))
            .to_rgba8();
        let full = Image {
            w: full.width(),
            h: full.height(),
            rgba: full.into_raw(),
        };
        println!(
            "\n{path}: {}x{} (decoded in {:.2} s)",
            full.w,
            full.h,
            t.elapsed().as_secs_f64()
        );
        for &size in &sizes {
            let (img, label) = match size {
                None => (
                    Image {
                        w: full.w,
                        h: full.h,
                        rgba: full.rgba.clone(),
                    },
                    "full image".to_string(),
                ),
                Some(s) if s <= full.w && s <= full.h => {
                    let (x, y, _) = best_crop(&full, s);
                    (crop(&full, x, y, s), format!("crop at ({x}, {y})"))
                }
                Some(_) => continue,
            };
            let covered = covered_mask(&img);
            let cov = covered.iter().filter(|&&c| c).count() as f64 / covered.len() as f64;
            println!(
                "\n{}x{} {label} ({:.0}% of texels covered)",
                img.w,
                img.h,
                100.0 * cov
            );
            println!(
                "{:<33} {:>5} {:>7} {:>6} {:>8} {:>8} {:>8} {:>7} {:>8}",
                "codec", "fmt", "stored", "gpu", "enc", "dec", "load", "psnr", "psnr-cov"
            );
            for codec in &codecs {
                bench(codec, &img, &covered);
            }
        }
    }
}

fn bench(codec: &Codec, img: &Image, covered: &[bool]) {
    let texels = f64::from(img.w) * f64::from(img.h);
    let (stored, enc_s) = best_time(|| (codec.encode)(img));
    let (tex, dec_s) = best_time(|| (codec.decode)(&stored, img.w, img.h));
    let (tex, load_s) = if codec.cpu_mips {
        let (levels, mip_s) = best_time(|| rgba_mip_chain(&tex.levels[0], img.w, img.h));
        (
            GpuTexture {
                format: tex.format,
                levels,
            },
            dec_s + mip_s,
        )
    } else {
        (tex, dec_s)
    };
    let gpu_bytes: usize = tex.levels.iter().map(Vec::len).sum();
    let expect: usize = level_sizes(img.w, img.h)
        .map(|(w, h)| tex.format.level_bytes(w, h))
        .sum();
    assert_eq!(gpu_bytes, expect, "{}: GPU bytes", codec.name);
    let got = level0_rgba(&tex, img.w, img.h);
    let mtx = |s: f64| texels / s / 1e6;
    println!(
        "{:<33} {:>5} {:>7.3} {:>6.2} {:>8.2} {:>8.1} {:>8.1} {:>7.2} {:>8.2}",
        codec.name,
        tex.format.name(),
        stored.len() as f64 / texels,
        gpu_bytes as f64 / texels,
        mtx(enc_s),
        mtx(dec_s),
        mtx(load_s),
        psnr(&img.rgba, &got, None),
        psnr(&img.rgba, &got, Some(covered)),
    );
}

/// Runs `f` until 0.3 s of CPU time have passed (at least once, at most 20 times); the last
/// result and the best time in seconds.
fn best_time<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let t = thread_cpu_seconds();
    let mut out = f();
    let mut best = thread_cpu_seconds() - t;
    let mut total = best;
    let mut runs = 1;
    while total < 0.3 && runs < 20 {
        let t = thread_cpu_seconds();
        out = f();
        let e = thread_cpu_seconds() - t;
        best = best.min(e);
        total += e;
        runs += 1;
    }
    (out, best)
}

/// CPU time of this thread, in seconds: every codec measured runs on the calling thread
/// only, and on a shared machine wall time also counts other processes.
fn thread_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid clock id and a valid pointer to a timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime");
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

// ---------------------------------------------------------------- the codecs

fn codecs() -> Vec<Codec> {
    use image::codecs::png::CompressionType;
    use intel_tex_2::bc7;
    let mut v = vec![
        rgba8_codec("png fast (builder today)", move |img| {
            png(img, CompressionType::Fast)
        }),
        rgba8_codec("png default", move |img| png(img, CompressionType::Default)),
        rgba8_codec("jpeg q90", move |img| jpeg(img, 90)),
        rgba8_codec("jpeg q75", move |img| jpeg(img, 75)),
    ];
    let ispc_bc7 = |settings: fn() -> bc7::EncodeSettings| {
        move |rgba: &[u8], w: u32, h: u32| {
            let surface = intel_tex_2::RgbaSurface {
                data: rgba,
                width: w,
                height: h,
                stride: 4 * w,
            };
            bc7::compress_blocks(&settings(), &surface)
        }
    };
    let ispc_bc1 = |rgba: &[u8], w: u32, h: u32| {
        let surface = intel_tex_2::RgbaSurface {
            data: rgba,
            width: w,
            height: h,
            stride: 4 * w,
        };
        intel_tex_2::bc1::compress_blocks(&surface)
    };
    let texpresso_bc1 = |algorithm: texpresso::Algorithm| {
        move |rgba: &[u8], w: u32, h: u32| {
            let format = texpresso::Format::Bc1;
            let mut out = vec![0; format.compressed_size(w as usize, h as usize)];
            let params = texpresso::Params {
                algorithm,
                ..Default::default()
            };
            format.compress(rgba, w as usize, h as usize, params, &mut out);
            out
        }
    };
    v.push(block_codec(
        "bc7 ispc ultra_fast",
        GpuFormat::Bc7,
        None,
        ispc_bc7(bc7::opaque_ultra_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc fast",
        GpuFormat::Bc7,
        None,
        ispc_bc7(bc7::opaque_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc very_fast +zstd9",
        GpuFormat::Bc7,
        Some(9),
        ispc_bc7(bc7::opaque_very_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc fast +zstd9",
        GpuFormat::Bc7,
        Some(9),
        ispc_bc7(bc7::opaque_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc ultra_fast +zstd9",
        GpuFormat::Bc7,
        Some(9),
        ispc_bc7(bc7::opaque_ultra_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc ultra_fast +zstd3",
        GpuFormat::Bc7,
        Some(3),
        ispc_bc7(bc7::opaque_ultra_fast_settings),
    ));
    v.push(block_codec(
        "bc7 ispc ultra_fast +zstd1",
        GpuFormat::Bc7,
        Some(1),
        ispc_bc7(bc7::opaque_ultra_fast_settings),
    ));

    v.push(block_codec(
        "bc7 ispc basic",
        GpuFormat::Bc7,
        None,
        ispc_bc7(bc7::opaque_basic_settings),
    ));
    v.push(block_codec(
        "bc7 ispc basic +zstd9",
        GpuFormat::Bc7,
        Some(9),
        ispc_bc7(bc7::opaque_basic_settings),
    ));
    v.push(block_codec_to(
        "bc7 basic +zstd9 -> rgba8 bcdec",
        GpuFormat::Bc7,
        Some(9),
        true,
        ispc_bc7(bc7::opaque_basic_settings),
    ));
    v.push(block_codec(
        "bc7 ispc slow",
        GpuFormat::Bc7,
        None,
        ispc_bc7(bc7::opaque_slow_settings),
    ));
    v.push(block_codec("bc1 ispc", GpuFormat::Bc1, None, ispc_bc1));
    v.push(block_codec(
        "bc1 ispc +zstd9",
        GpuFormat::Bc1,
        Some(9),
        ispc_bc1,
    ));
    v.push(block_codec(
        "bc1 texpresso range",
        GpuFormat::Bc1,
        None,
        texpresso_bc1(texpresso::Algorithm::RangeFit),
    ));
    v.push(block_codec(
        "bc1 texpresso cluster",
        GpuFormat::Bc1,
        None,
        texpresso_bc1(texpresso::Algorithm::ClusterFit),
    ));
    // JPEG stored, a block format made in the client at load.
    v.push(Codec {
        name: "jpeg q90 -> bc7 ultra at load",
        encode: Box::new(|img| jpeg(img, 90)),
        decode: Box::new(move |data, w, h| {
            let rgba = decode_image(data, image::ImageFormat::Jpeg, w, h);
            encode_chain(
                &rgba,
                w,
                h,
                GpuFormat::Bc7,
                &ispc_bc7(bc7::opaque_ultra_fast_settings),
            )
        }),
        cpu_mips: false,
    });
    v.push(Codec {
        name: "jpeg q90 -> bc1 range at load",
        encode: Box::new(|img| jpeg(img, 90)),
        decode: Box::new(move |data, w, h| {
            let rgba = decode_image(data, image::ImageFormat::Jpeg, w, h);
            encode_chain(
                &rgba,
                w,
                h,
                GpuFormat::Bc1,
                &texpresso_bc1(texpresso::Algorithm::RangeFit),
            )
        }),
        cpu_mips: false,
    });
    v
}

/// A codec whose file holds level 0 only and whose GPU texture is RGBA8 with CPU mips.
fn rgba8_codec(name: &'static str, encode: impl Fn(&Image) -> Vec<u8> + 'static) -> Codec {
    Codec {
        name,
        encode: Box::new(encode),
        decode: Box::new(|data, w, h| {
            let format = image::guess_format(data).expect("png or jpeg");
            GpuTexture {
                format: GpuFormat::Rgba8,
                levels: vec![decode_image(data, format, w, h)],
            }
        }),
        cpu_mips: true,
    }
}

fn png(img: &Image, compression: image::codecs::png::CompressionType) -> Vec<u8> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        compression,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(&img.rgba, img.w, img.h, image::ExtendedColorType::Rgba8)
    .expect("png encoder");
    out
}

/// As `PatchTexture::encode`: alpha dropped.
fn jpeg(img: &Image, quality: u8) -> Vec<u8> {
    let rgb: Vec<u8> = img
        .rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
        .encode(&rgb, img.w, img.h, image::ExtendedColorType::Rgb8)
        .expect("jpeg encoder");
    out
}

fn decode_image(data: &[u8], format: image::ImageFormat, w: u32, h: u32) -> Vec<u8> {
    let img = image::load_from_memory_with_format(data, format)
        .expect("decodes")
        .to_rgba8();
    assert_eq!((img.width(), img.height()), (w, h));
    img.into_raw()
}

/// A block format stored with its mip chain (made at build time), optionally zstd-compressed.
/// `encode_level` gets RGBA8 whose size is a multiple of 4.
fn block_codec(
    name: &'static str,
    format: GpuFormat,
    zstd_level: Option<i32>,
    encode_level: impl Fn(&[u8], u32, u32) -> Vec<u8> + 'static,
) -> Codec {
    block_codec_to(name, format, zstd_level, false, encode_level)
}

/// `block_codec`, and with `to_rgba8` every level decoded to RGBA8 at load with `bcdec_rs`
/// (the fallback for a GPU without the block format).
fn block_codec_to(
    name: &'static str,
    format: GpuFormat,
    zstd_level: Option<i32>,
    to_rgba8: bool,
    encode_level: impl Fn(&[u8], u32, u32) -> Vec<u8> + 'static,
) -> Codec {
    Codec {
        name,
        encode: Box::new(move |img| {
            let tex = encode_chain(&img.rgba, img.w, img.h, format, &encode_level);
            let raw = tex.levels.concat();
            match zstd_level {
                Some(l) => zstd::bulk::compress(&raw, l).expect("zstd"),
                None => raw,
            }
        }),
        decode: Box::new(move |data, w, h| {
            let raw;
            let data = match zstd_level {
                Some(_) => {
                    raw = zstd::decode_all(data).expect("zstd");
                    &raw[..]
                }
                None => data,
            };
            let mut levels = Vec::new();
            let mut at = 0;
            for (lw, lh) in level_sizes(w, h) {
                let n = format.level_bytes(lw, lh);
                let blocks = &data[at..at + n];
                levels.push(if to_rgba8 {
                    blocks_to_rgba(format, blocks, lw, lh)
                } else {
                    blocks.to_vec()
                });
                at += n;
            }
            assert_eq!(at, data.len());
            let format = if to_rgba8 { GpuFormat::Rgba8 } else { format };
            GpuTexture { format, levels }
        }),
        cpu_mips: false,
    }
}

/// The box-filtered mip chain of `rgba`, every level block-encoded (padded to whole blocks
/// by repeating the last row and column).
fn encode_chain(
    rgba: &[u8],
    w: u32,
    h: u32,
    format: GpuFormat,
    encode_level: &dyn Fn(&[u8], u32, u32) -> Vec<u8>,
) -> GpuTexture {
    let mut levels = Vec::new();
    let mut level = std::borrow::Cow::Borrowed(rgba);
    let (mut lw, mut lh) = (w, h);
    loop {
        let (padded, pw, ph) = pad4(&level, lw, lh);
        levels.push(encode_level(&padded[..], pw, ph));
        if lw == 1 && lh == 1 {
            break;
        }
        let (next, nw, nh) = downsample(&level, lw, lh);
        (level, lw, lh) = (std::borrow::Cow::Owned(next), nw, nh);
    }
    GpuTexture { format, levels }
}

fn pad4(rgba: &[u8], w: u32, h: u32) -> (std::borrow::Cow<'_, [u8]>, u32, u32) {
    let (pw, ph) = (w.div_ceil(4) * 4, h.div_ceil(4) * 4);
    if (pw, ph) == (w, h) {
        return (std::borrow::Cow::Borrowed(rgba), w, h);
    }
    let mut out = Vec::with_capacity(4 * pw as usize * ph as usize);
    for y in 0..ph {
        let row = &rgba[4 * (w * y.min(h - 1)) as usize..][..4 * w as usize];
        out.extend_from_slice(row);
        for _ in w..pw {
            out.extend_from_slice(&row[row.len() - 4..]);
        }
    }
    (std::borrow::Cow::Owned(out), pw, ph)
}

// ---------------------------------------------------------------- mips, blocks, PSNR

/// Sizes of the full mip chain, down to 1x1.
fn level_sizes(w: u32, h: u32) -> impl Iterator<Item = (u32, u32)> {
    let n = 32 - w.max(h).leading_zeros();
    (0..n).map(move |l| ((w >> l).max(1), (h >> l).max(1)))
}

/// 2x2 box filter to `max(1, w / 2)` x `max(1, h / 2)` (an odd last row or column is
/// dropped: exact for the power-of-two sizes measured here; the renderer weighs odd sizes).
fn downsample(src: &[u8], w: u32, h: u32) -> (Vec<u8>, u32, u32) {
    let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
    let (w, nw_us) = (w as usize, nw as usize);
    let mut out = vec![0u8; 4 * nw_us * nh as usize];
    for y in 0..nh as usize {
        let y0 = (2 * y).min(h as usize - 1);
        let y1 = (2 * y + 1).min(h as usize - 1);
        let (r0, r1) = (&src[4 * w * y0..][..4 * w], &src[4 * w * y1..][..4 * w]);
        let dst = &mut out[4 * nw_us * y..][..4 * nw_us];
        for x in 0..nw_us {
            let x0 = 4 * (2 * x).min(w - 1);
            let x1 = 4 * (2 * x + 1).min(w - 1);
            for c in 0..4 {
                let s = u32::from(r0[x0 + c])
                    + u32::from(r0[x1 + c])
                    + u32::from(r1[x0 + c])
                    + u32::from(r1[x1 + c]);
                dst[4 * x + c] = ((s + 2) / 4) as u8;
            }
        }
    }
    (out, nw, nh)
}

/// The full RGBA8 mip chain of `level0`, as the renderer makes it at upload.
fn rgba_mip_chain(level0: &[u8], w: u32, h: u32) -> Vec<Vec<u8>> {
    let mut levels = vec![level0.to_vec()];
    let (mut lw, mut lh) = (w, h);
    while lw > 1 || lh > 1 {
        let (next, nw, nh) = downsample(levels.last().expect("level 0"), lw, lh);
        levels.push(next);
        (lw, lh) = (nw, nh);
    }
    levels
}

/// Level 0 of `tex` as RGBA8 texels, `w` x `h`.
fn level0_rgba(tex: &GpuTexture, w: u32, h: u32) -> Vec<u8> {
    match tex.format {
        GpuFormat::Rgba8 => tex.levels[0].clone(),
        format => blocks_to_rgba(format, &tex.levels[0], w, h),
    }
}

/// A `w` x `h` level of blocks decoded to RGBA8 texels with `bcdec_rs`.
fn blocks_to_rgba(format: GpuFormat, blocks: &[u8], w: u32, h: u32) -> Vec<u8> {
    let decode_block: fn(&[u8], &mut [u8], usize) = match format {
        GpuFormat::Rgba8 => unreachable!("not a block format"),
        GpuFormat::Bc7 => bcdec_rs::bc7,
        GpuFormat::Bc1 => bcdec_rs::bc1,
    };
    let (bw, bh) = (w.div_ceil(4) as usize, h.div_ceil(4) as usize);
    let pitch = 16 * bw;
    let mut padded = vec![0u8; pitch * 4 * bh];
    let unit = format.unit_bytes();
    for by in 0..bh {
        for bx in 0..bw {
            let block = &blocks[unit * (by * bw + bx)..][..unit];
            decode_block(block, &mut padded[pitch * 4 * by + 16 * bx..], pitch);
        }
    }
    let mut out = Vec::with_capacity(4 * w as usize * h as usize);
    for y in 0..h as usize {
        out.extend_from_slice(&padded[pitch * y..][..4 * w as usize]);
    }
    out
}

/// PSNR over RGB (alpha ignored: the scans are opaque, JPEG drops it) of the texels where
/// `mask` is true (all when `None`); infinite when identical.
fn psnr(a: &[u8], b: &[u8], mask: Option<&[bool]>) -> f64 {
    assert_eq!(a.len(), b.len());
    let (mut sum, mut n) = (0u64, 0u64);
    for (i, (p, q)) in a.chunks_exact(4).zip(b.chunks_exact(4)).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        for c in 0..3 {
            let d = i64::from(p[c]) - i64::from(q[c]);
            sum += (d * d) as u64;
        }
        n += 3;
    }
    if sum == 0 {
        return f64::INFINITY;
    }
    let mse = sum as f64 / n as f64;
    10.0 * (255.0 * 255.0 / mse).log10()
}

// ---------------------------------------------------------------- crops

fn covered_mask(img: &Image) -> Vec<bool> {
    img.rgba
        .chunks_exact(4)
        .map(|p| p[0].max(p[1]).max(p[2]) > 16)
        .collect()
}

/// The `size` x `size` crop (on a grid of `size / 4` steps) with the most covered texels
/// (sampled every 4th texel in both directions): its corner and covered fraction.
fn best_crop(img: &Image, size: u32) -> (u32, u32, f64) {
    let step = (size / 4).max(1) as usize;
    let (w, size_us) = (img.w as usize, size as usize);
    let mut best = (0, 0, -1.0);
    for y in (0..=(img.h - size) as usize).step_by(step) {
        for x in (0..=(img.w - size) as usize).step_by(step) {
            let (mut hit, mut all) = (0u32, 0u32);
            for yy in (y..y + size_us).step_by(4) {
                for xx in (x..x + size_us).step_by(4) {
                    let p = &img.rgba[4 * (yy * w + xx)..][..3];
                    hit += u32::from(p[0].max(p[1]).max(p[2]) > 16);
                    all += 1;
                }
            }
            let cov = f64::from(hit) / f64::from(all);
            if cov > best.2 {
                best = (x as u32, y as u32, cov);
            }
        }
    }
    best
}

fn crop(img: &Image, x: u32, y: u32, size: u32) -> Image {
    let mut rgba = Vec::with_capacity(4 * size as usize * size as usize);
    for row in y..y + size {
        let at = 4 * (row as usize * img.w as usize + x as usize);
        rgba.extend_from_slice(&img.rgba[at..at + 4 * size as usize]);
    }
    Image {
        w: size,
        h: size,
        rgba,
    }
}
