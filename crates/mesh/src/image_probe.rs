//! The size of a texture image, from its header only (PNG or JPEG, through the `image`
//! crate), with bounded memory: the importers describe every texture
//! ([`crate::TextureSource::size`]) without decoding its pixels, and a texture of
//! hundreds of megabytes costs a few kilobytes at import.
//!
//! The header is looked for in a prefix of the bytes that grows (64 KiB, 1 MiB, 16 MiB)
//! while it is not found: the `image` crate's JPEG reader copies its whole input before
//! it reads the header, so it is only ever given a prefix. A PNG's header is its first
//! chunk, a JPEG's frame header comes after its metadata segments (EXIF, ICC profiles:
//! rarely more than a megabyte).

use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::Path;

use crate::assets::open_regular;

/// Prefix lengths tried in turn.
const PREFIX_STEPS: [u64; 3] = [64 << 10, 1 << 20, 16 << 20];

/// Why an image's size is not known.
#[derive(Debug)]
pub(crate) enum ProbeError {
    /// The file cannot be opened or read.
    Missing(std::io::Error),
    /// The bytes are an image in a format other than PNG or JPEG (its MIME type).
    Unsupported(String),
    /// The bytes are there but are no PNG or JPEG whose header reads.
    Unreadable(String),
}

/// The width and height of the PNG or JPEG file at `path`.
pub(crate) fn probe_file(path: &Path) -> Result<[u32; 2], ProbeError> {
    let file = open_regular(path).map_err(ProbeError::Missing)?;
    let meta = file.metadata().map_err(ProbeError::Missing)?;
    if !meta.is_file() {
        return Err(ProbeError::Missing(std::io::Error::other(
            "not a regular file",
        )));
    }
    match probe_reader(file, meta.len()) {
        // No magic number (TGA has none): the extension may still tell the format.
        Err(ProbeError::Unreadable(why)) => match image::ImageFormat::from_path(path) {
            Ok(f) if !matches!(f, image::ImageFormat::Png | image::ImageFormat::Jpeg) => {
                Err(ProbeError::Unsupported(f.to_mime_type().to_string()))
            }
            _ => Err(ProbeError::Unreadable(why)),
        },
        r => r,
    }
}

/// The width and height of the image in bytes `offset..offset + len` of the file at
/// `path` (a glTF buffer view).
pub(crate) fn probe_file_range(path: &Path, offset: u64, len: u64) -> Result<[u32; 2], ProbeError> {
    let mut file = open_regular(path).map_err(ProbeError::Missing)?;
    let size = file.metadata().map_err(ProbeError::Missing)?.len();
    match offset.checked_add(len) {
        Some(end) if end <= size => {}
        _ => {
            return Err(ProbeError::Unreadable(format!(
                "bytes {offset}..{} lie beyond the end of {} ({size} bytes)",
                offset.saturating_add(len),
                path.display()
            )))
        }
    }
    file.seek(SeekFrom::Start(offset))
        .map_err(ProbeError::Missing)?;
    probe_reader(file, len)
}

/// The width and height of the image held in `bytes`.
pub(crate) fn probe_bytes(bytes: &[u8]) -> Result<[u32; 2], ProbeError> {
    probe_reader(Cursor::new(bytes), bytes.len() as u64)
}

/// Read growing prefixes of the `len` bytes of `r` until the header is found.
fn probe_reader(mut r: impl Read, len: u64) -> Result<[u32; 2], ProbeError> {
    let mut buf = Vec::new();
    let mut why = ProbeError::Unreadable("empty".to_string());
    for step in PREFIX_STEPS {
        let want = len.min(step);
        let have = buf.len() as u64;
        if want > have {
            (&mut r)
                .take(want - have)
                .read_to_end(&mut buf)
                .map_err(ProbeError::Missing)?;
        }
        match header_size(&buf) {
            Ok(size) => return Ok(size),
            Err(e @ ProbeError::Unsupported(_)) => return Err(e),
            Err(e) => why = e,
        }
        // The whole image was there (or the file ended early): a longer prefix would
        // not help.
        if (buf.len() as u64) < want || want == len {
            break;
        }
    }
    Err(why)
}

/// The size in the header at the start of `bytes` (which may stop anywhere after it).
fn header_size(bytes: &[u8]) -> Result<[u32; 2], ProbeError> {
    use image::ImageFormat;
    let bad = |why: String| ProbeError::Unreadable(why);
    if bytes.is_empty() {
        return Err(bad("empty".to_string()));
    }
    let reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    match reader.format() {
        Some(ImageFormat::Png | ImageFormat::Jpeg) => {}
        Some(other) => return Err(ProbeError::Unsupported(other.to_mime_type().to_string())),
        None => return Err(bad("not a PNG or JPEG image".to_string())),
    }
    let (w, h) = reader.into_dimensions().map_err(|e| bad(e.to_string()))?;
    Ok([w, h])
}

impl std::fmt::Display for ProbeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProbeError::Missing(e) => write!(f, "{e}"),
            ProbeError::Unsupported(mime) => {
                write!(f, "a {mime} image (only PNG and JPEG are read)")
            }
            ProbeError::Unreadable(why) => write!(f, "{why}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(w: u32, h: u32) -> Vec<u8> {
        let img = image::RgbImage::new(w, h);
        let mut out = Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    }

    #[test]
    fn sizes_of_png_and_jpeg_and_garbage() {
        assert_eq!(probe_bytes(&png(7, 3)).unwrap(), [7, 3]);
        let mut jpeg = Cursor::new(Vec::new());
        image::RgbImage::new(5, 9)
            .write_to(&mut jpeg, image::ImageFormat::Jpeg)
            .unwrap();
        assert_eq!(probe_bytes(jpeg.get_ref()).unwrap(), [5, 9]);
        assert!(matches!(
            probe_bytes(b"hello, world"),
            Err(ProbeError::Unreadable(_))
        ));
        assert!(matches!(probe_bytes(&[]), Err(ProbeError::Unreadable(_))));
        // A PNG cut inside its header.
        assert!(matches!(
            probe_bytes(&png(7, 3)[..20]),
            Err(ProbeError::Unreadable(_))
        ));
    }

    #[test]
    fn a_header_after_a_big_segment_is_found_in_a_longer_prefix() {
        // A JPEG with a 200 KB comment (COM segments of 64 KB) before its frame header.
        let mut jpeg = Cursor::new(Vec::new());
        image::RgbImage::new(4, 6)
            .write_to(&mut jpeg, image::ImageFormat::Jpeg)
            .unwrap();
        let jpeg = jpeg.into_inner();
        let mut big = jpeg[..2].to_vec();
        for _ in 0..4 {
            big.extend_from_slice(&[0xFF, 0xFE, 0xFF, 0xFF]);
            big.extend(std::iter::repeat_n(b'x', 0xFFFF - 2));
        }
        big.extend_from_slice(&jpeg[2..]);
        assert_eq!(probe_bytes(&big).unwrap(), [4, 6]);
    }
}
