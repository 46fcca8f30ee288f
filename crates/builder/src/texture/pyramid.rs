//! The source images' box-filtered pyramids, decoded out of core into the texel spool.
//!
//! Each source image is decoded once, the first time a patch needs it, into its
//! box-filtered pyramid, which is written level by level as raw RGBA8 rows to a
//! temporary *texel spool* in the build's temporary directory (4/3 x 4 bytes per source
//! texel on disk); patches read back only the rows of their rectangles (positioned
//! reads, which the page cache serves, not the build's memory). No pyramid is held in
//! memory, and no image is decoded twice whatever the order the hierarchy visits them
//! in; the decodes in flight are bounded by the [`DecodeGate`]. Its own module so that
//! the patch textures ([`super::Baker`]) see only levels and rows, not files.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use rustc_hash::FxHashMap;
use tessera_format::{PatchSpool, SpooledPatch};
use tessera_mesh::{ImageSource, TextureSource, NO_TEXTURE};

use super::gate::{DecodeGate, DECODE_BYTES_PER_TEXEL};
use crate::patch::WorkVertex;
use crate::BuildError;

/// One source image's box-filtered pyramid (level 0 = the source), stored in the texel
/// spool.
pub(crate) struct Pyramid {
    pub(crate) levels: Vec<Level>,
}

/// A pyramid level: `w x h` RGBA8 texels, row-major, at `offset` in the texel spool.
pub(crate) struct Level {
    pub(crate) w: u32,
    pub(crate) h: u32,
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

/// Each texture's pyramid (`None`: the image cannot be read).
pub(crate) type Pyramids = FxHashMap<u32, Option<Arc<Pyramid>>>;

/// What the decodes did, for the build report.
#[derive(Clone, Debug, Default)]
pub(crate) struct Decodes {
    /// Source images read (decoded), and their texels.
    pub(crate) images: u64,
    pub(crate) texels: u64,
    /// Images that could not be read, each once as `name: why`.
    pub(crate) unreadable: Vec<String>,
}

/// The source images of a build and their pyramids, decoded on first use.
pub(crate) struct SourcePyramids {
    pub(crate) sources: Vec<TextureSource>,
    /// Each image's pyramid, decoded on first use (one thread decodes, the others wait).
    images: Mutex<FxHashMap<ImageSource, Arc<OnceLock<Decoded>>>>,
    /// Where the texel spool goes, and the spool (created by the first decode).
    spool_dir: PathBuf,
    spool: OnceLock<Result<PatchSpool, String>>,
    gate: DecodeGate,
    decodes: Mutex<Decodes>,
}

impl SourcePyramids {
    /// The pyramids of `sources`, whose decodes together hold at most about
    /// `memory_bytes`; the texel spool goes to the system's temporary directory unless
    /// [`SourcePyramids::spool_in`] says where.
    pub(crate) fn new(sources: Vec<TextureSource>, memory_bytes: u64) -> SourcePyramids {
        SourcePyramids {
            sources,
            images: Mutex::new(FxHashMap::default()),
            spool_dir: std::env::temp_dir(),
            spool: OnceLock::new(),
            gate: DecodeGate::new(memory_bytes.max(64 << 20)),
            decodes: Mutex::new(Decodes::default()),
        }
    }

    /// Puts the texel spool in `dir` (before the first decode).
    pub(crate) fn spool_in(&mut self, dir: &Path) {
        self.spool_dir = dir.to_path_buf();
    }

    /// What the decodes did so far.
    pub(crate) fn decodes(&self) -> Decodes {
        self.decodes.lock().map(|d| d.clone()).unwrap_or_default()
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
        let mut decodes = self
            .decodes
            .lock()
            .map_err(|_| Failed::Spool("poisoned report".into()))?;
        match &result {
            Ok(p) => {
                decodes.images += 1;
                decodes.texels += u64::from(p.levels[0].w) * u64::from(p.levels[0].h);
            }
            Err(Failed::Unreadable(e)) => {
                let line = format!("{}: {e}", src.image_name);
                if !decodes.unreadable.contains(&line) {
                    tracing::warn!("texture image {line}; its faces are drawn in their colour");
                    decodes.unreadable.push(line);
                }
            }
            Err(Failed::Spool(_)) => {}
        }
        result
    }

    /// Row `y` of level `l`, texels `x0..x1`, from the spool.
    pub(crate) fn read_row(
        &self,
        l: &Level,
        y: i64,
        x0: i64,
        x1: i64,
    ) -> Result<Vec<u8>, BuildError> {
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
    pub(crate) fn pyramids_of(&self, vertices: &[WorkVertex]) -> Result<Pyramids, BuildError> {
        let mut pyramids: Pyramids = FxHashMap::default();
        for v in vertices {
            if v.texture != NO_TEXTURE && !pyramids.contains_key(&v.texture) {
                pyramids.insert(v.texture, self.pyramid(v.texture)?);
            }
        }
        Ok(pyramids)
    }
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
}
