//! RGBA8 frames as every front end and test sees them: PNG in and out (through the
//! `image` crate; feature `png`, default), and the image metrics the tests and
//! benchmarks judge frames by (PSNR, pixel differences, pinholes). Pure CPU.

#[cfg(feature = "png")]
use std::path::Path;

/// A PNG that could not be read or written, with its path.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ImageError(pub String);

/// An RGBA8 image, rows top to bottom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel at (x, y).
    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    /// Writes a PNG atomically (temporary file beside `path`, then rename).
    #[cfg(feature = "png")]
    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        let err = |e: &dyn std::fmt::Display| ImageError(format!("{}: {e}", path.display()));
        let mut file =
            tessera_format::AtomicFile::create(path, 1 << 16).map_err(|e| err(&e.source))?;
        image::write_buffer_with_format(
            &mut file,
            &self.rgba,
            self.width,
            self.height,
            image::ExtendedColorType::Rgba8,
            image::ImageFormat::Png,
        )
        .map_err(|e| err(&e))?;
        file.commit().map_err(|e| err(&e.source))
    }

    /// Reads a PNG (any colour type, converted to RGBA8).
    #[cfg(feature = "png")]
    pub fn load_png(path: &Path) -> Result<Image, ImageError> {
        let img = image::open(path)
            .map_err(|e| ImageError(format!("{}: {e}", path.display())))?
            .to_rgba8();
        Ok(Image {
            width: img.width(),
            height: img.height(),
            rgba: img.into_raw(),
        })
    }
}

/// Peak signal-to-noise ratio in dB over the RGB channels (alpha ignored), 8-bit peak.
/// Infinite for identical images; `None` when the sizes differ.
pub fn psnr(a: &Image, b: &Image) -> Option<f64> {
    if a.width != b.width || a.height != b.height || a.rgba.len() != b.rgba.len() {
        return None;
    }
    let mut sum = 0u64;
    for (pa, pb) in a.rgba.chunks_exact(4).zip(b.rgba.chunks_exact(4)) {
        for c in 0..3 {
            let d = i64::from(pa[c]) - i64::from(pb[c]);
            sum += (d * d) as u64;
        }
    }
    let n = (a.width as u64 * a.height as u64 * 3).max(1);
    if sum == 0 {
        return Some(f64::INFINITY);
    }
    let mse = sum as f64 / n as f64;
    Some(10.0 * (255.0f64 * 255.0 / mse).log10())
}

/// Differences between two same-sized images: pixels whose largest channel difference
/// exceeds `threshold`, and the largest difference seen.
pub fn diff_stats(a: &Image, b: &Image, threshold: u8) -> Option<(usize, u8)> {
    if a.width != b.width || a.height != b.height || a.rgba.len() != b.rgba.len() {
        return None;
    }
    let mut count = 0;
    let mut max = 0u8;
    for (pa, pb) in a.rgba.chunks_exact(4).zip(b.rgba.chunks_exact(4)) {
        let d = (0..3).map(|c| pa[c].abs_diff(pb[c])).max().unwrap_or(0);
        max = max.max(d);
        if d > threshold {
            count += 1;
        }
    }
    Some((count, max))
}

/// Pinholes: pixels of colour `background` that are not connected (4-neighbourhood,
/// through background pixels) to the image border. On a closed surface seen from
/// outside with back faces culled, every such pixel is a hole in the surface.
pub fn enclosed_background_pixels(img: &Image, background: [u8; 3]) -> usize {
    let (w, h) = (img.width as usize, img.height as usize);
    let is_bg = |i: usize| img.rgba[i * 4..i * 4 + 3] == background;
    let mut reached = vec![false; w * h];
    let mut stack = Vec::new();
    for x in 0..w {
        stack.push(x);
        stack.push((h - 1) * w + x);
    }
    for y in 0..h {
        stack.push(y * w);
        stack.push(y * w + w - 1);
    }
    while let Some(i) = stack.pop() {
        if reached[i] || !is_bg(i) {
            continue;
        }
        reached[i] = true;
        let (x, y) = (i % w, i / w);
        if x > 0 {
            stack.push(i - 1);
        }
        if x + 1 < w {
            stack.push(i + 1);
        }
        if y > 0 {
            stack.push(i - w);
        }
        if y + 1 < h {
            stack.push(i + w);
        }
    }
    (0..w * h).filter(|&i| is_bg(i) && !reached[i]).count()
}
