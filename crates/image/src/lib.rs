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

/// Pixels of `img` that are not its corner pixel's colour (the background) by more than
/// 24 in the sum of the three channel differences: the silhouette, a mask (rows top to
/// bottom).
pub fn coverage(img: &Image) -> Vec<bool> {
    let bg = img.pixel(0, 0);
    img.rgba
        .chunks_exact(4)
        .map(|p| (0..3).map(|c| u32::from(p[c].abs_diff(bg[c]))).sum::<u32>() > 24)
        .collect()
}

/// Intersection over union of two masks of one size (0 when both are empty).
pub fn iou(a: &[bool], b: &[bool]) -> f64 {
    assert_eq!(a.len(), b.len(), "masks of different sizes");
    let both = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let either = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    both as f64 / either.max(1) as f64
}

/// Pinholes: pixels of colour `background` that are not connected (4-neighbourhood,
/// through background pixels) to the image border. On a closed surface seen from
/// outside with back faces culled, every such pixel is a hole in the surface.
pub fn enclosed_background_pixels(img: &Image, background: [u8; 3]) -> usize {
    enclosed_background_mask(img, background)
        .iter()
        .filter(|&&e| e)
        .count()
}

/// Per pixel (rows top to bottom), whether it is one of the
/// [`enclosed_background_pixels`]: where the holes are, to compare with another frame's.
pub fn enclosed_background_mask(img: &Image, background: [u8; 3]) -> Vec<bool> {
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
    (0..w * h).map(|i| is_bg(i) && !reached[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5x5 frame of background 0 with a 3x3 block of 200 in the middle, its centre
    /// pixel background again (a pinhole).
    fn frame() -> Image {
        let mut rgba = vec![0u8; 5 * 5 * 4];
        for y in 1..4 {
            for x in 1..4 {
                if (x, y) != (2, 2) {
                    rgba[4 * (y * 5 + x)..4 * (y * 5 + x) + 3].copy_from_slice(&[200; 3]);
                }
            }
        }
        Image {
            width: 5,
            height: 5,
            rgba,
        }
    }

    #[test]
    fn the_pinhole_is_enclosed_and_the_border_background_is_not() {
        // Why: crack tests compare where holes are, so the mask must mark exactly the
        // background pixels the surface encloses.
        let m = enclosed_background_mask(&frame(), [0; 3]);
        assert_eq!(m.iter().filter(|&&e| e).count(), 1);
        assert!(m[2 * 5 + 2]);
        assert_eq!(enclosed_background_pixels(&frame(), [0; 3]), 1);
    }

    #[test]
    fn coverage_and_iou_of_shifted_silhouettes() {
        let a = coverage(&frame());
        assert_eq!(a.iter().filter(|&&c| c).count(), 8);
        assert_eq!(iou(&a, &a), 1.0);
        let shifted: Vec<bool> = (0..25).map(|i| i % 5 >= 1 && a[i - 1]).collect();
        // 8 and 8 pixels, 4 in common: 4 / 12.
        assert!((iou(&a, &shifted) - 4.0 / 12.0).abs() < 1e-12);
        assert_eq!(iou(&[false; 4], &[false; 4]), 0.0);
    }
}
