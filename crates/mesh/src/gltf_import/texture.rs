//! The base colour textures of glTF materials, described for the builder
//! ([`TextureSource`]): where the image's bytes are (a file beside the glTF, a byte range
//! of the `.glb` or of a `.bin`, or the bytes of a `data:` URI), its size from its header
//! (nothing more of it is read), the sampler's wrap modes and the base colour factor.
//!
//! A draw samples its material's texture when the texture uses `TEXCOORD_0` and the
//! primitive has it, and the image is a PNG or JPEG whose header reads. Otherwise its
//! vertices are untextured (drawn in the base colour factor x `COLOR_0`, UVs kept) and
//! the report says why: another texture coordinate set, another image format (a MIME
//! type, or only an `EXT_texture_webp` / `KHR_texture_basisu` source), a remote URI
//! ([`ImportReport::textures_not_used`]); a missing file ([`ImportReport::missing_files`]);
//! a header that does not read ([`ImportReport::unreadable_images`]).

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use ::gltf::json;
use json::texture::WrappingMode;
use json::validation::Checked;

use crate::assets::AssetError;
use crate::image_probe::{probe_bytes, probe_file, probe_file_range, ProbeError};
use crate::{ImageSource, ImportReport, MeshError, TextureSource, Wrap, NO_TEXTURE};

use super::container::{clip, decode_data_uri, External, UriError, URL_REFUSED};
use super::material::srgb8;
use super::Draw;

/// What became of one image.
#[derive(Clone)]
enum ImageUse {
    /// Usable: where its bytes are, and its size.
    Ready(ImageSource, [u32; 2]),
    /// Not used, why (`ImportReport::textures_not_used`).
    NotUsed(String),
    /// Its file (the image, or the `.bin` holding it) is missing.
    Missing,
    /// Its header does not read.
    Unreadable,
}

/// An image found: where its bytes are, its header read, and the name of the file that
/// holds it (for messages).
type Found = (ImageSource, Result<[u32; 2], ProbeError>, String);

/// Why an image in a buffer view has no bytes.
enum ViewError {
    /// Its buffer is a file the asset policy refuses: an error (the message).
    Refused(String),
    /// Otherwise: the image is unreadable (why).
    Unreadable(String),
}

impl From<String> for ViewError {
    fn from(why: String) -> Self {
        ViewError::Unreadable(why)
    }
}

/// Resolves the textures of an import's draws.
pub(super) struct Textures<'a> {
    pub path: &'a Path,
    pub root: &'a json::Root,
    /// The whole glTF or GLB file.
    pub main: &'a [u8],
    /// The GLB binary chunk within `main`.
    pub bin: Option<Range<usize>>,
    /// Where external files are looked up, under which policy (`None`: they are not
    /// opened).
    pub external: Option<External<'a>>,
    /// The texture index of each textured material, once resolved.
    by_material: HashMap<usize, u32>,
    images: HashMap<usize, ImageUse>,
    /// Decoded `data:` URI buffers that images lie in.
    data_buffers: HashMap<usize, Result<Arc<[u8]>, String>>,
    /// For the warnings: missing and unreadable images, with why.
    missing: Vec<String>,
    unreadable: Vec<String>,
}

impl<'a> Textures<'a> {
    pub(super) fn new(
        path: &'a Path,
        root: &'a json::Root,
        main: &'a [u8],
        bin: Option<Range<usize>>,
        external: Option<External<'a>>,
    ) -> Self {
        Textures {
            path,
            root,
            main,
            bin,
            external,
            by_material: HashMap::new(),
            images: HashMap::new(),
            data_buffers: HashMap::new(),
            missing: Vec::new(),
            unreadable: Vec::new(),
        }
    }

    /// The texture index draw `d` samples, or [`NO_TEXTURE`] (the reason recorded in
    /// `report` once); an error when its image is a file the asset policy refuses.
    pub(super) fn of_draw(
        &mut self,
        d: &Draw,
        report: &mut ImportReport,
    ) -> Result<u32, MeshError> {
        let u = &d.material;
        let Some(m) = u.index.filter(|_| u.textured) else {
            return Ok(NO_TEXTURE);
        };
        if u.uv_set != 0 {
            self.not_used(
                m,
                &format!(
                    "the texture reads TEXCOORD_{}; only TEXCOORD_0 is used",
                    u.uv_set
                ),
                report,
            );
            return Ok(NO_TEXTURE);
        }
        if d.uv.is_none() {
            self.not_used(m, &format!("{} has no TEXCOORD_0", d.name), report);
            return Ok(NO_TEXTURE);
        }
        if let Some(&t) = self.by_material.get(&m) {
            return Ok(t);
        }
        let t = self.resolve(m, report)?;
        self.by_material.insert(m, t);
        Ok(t)
    }

    /// The name of material `m` and its image, as `name (image 'x')`.
    fn label(&self, m: usize) -> String {
        let root = self.root;
        let mat = &root.materials[m];
        let image = mat
            .pbr_metallic_roughness
            .base_color_texture
            .as_ref()
            .and_then(|t| root.textures.get(t.index.value()))
            .and_then(|t| {
                root.images
                    .get(t.source.value())
                    .map(|img| (t.source.value(), img))
            })
            .map(|(k, img)| match (&img.name, &img.uri) {
                (Some(n), _) => format!("image '{n}'"),
                (None, Some(u)) if !u.starts_with("data:") => format!("image '{}'", clip(u)),
                _ => format!("image {k}"),
            })
            .unwrap_or_else(|| "no image".to_string());
        format!("{} ({image})", material_name(root, m))
    }

    fn not_used(&self, m: usize, why: &str, report: &mut ImportReport) {
        let entry = format!("{}: {why}", self.label(m));
        if !report.textures_not_used.contains(&entry) {
            report.textures_not_used.push(entry);
        }
    }

    /// The texture of material `m` (used with `TEXCOORD_0`), its source added to
    /// `report.textures` when its image is usable.
    fn resolve(&mut self, m: usize, report: &mut ImportReport) -> Result<u32, MeshError> {
        let root = self.root;
        let mat = &root.materials[m];
        let pbr = &mat.pbr_metallic_roughness;
        let Some(info) = pbr.base_color_texture.as_ref() else {
            return Ok(NO_TEXTURE);
        };
        let k = info.index.value();
        let Some(tex) = root.textures.get(k) else {
            let why = format!(
                "texture {k} does not exist (the file has {})",
                root.textures.len()
            );
            self.not_used(m, &why, report);
            return Ok(NO_TEXTURE);
        };
        let src = tex.source.value();
        if root.images.get(src).is_none() {
            let others: Vec<&str> = tex
                .extensions
                .iter()
                .flat_map(|e| e.others.keys())
                .map(String::as_str)
                .collect();
            let why = match others.is_empty() {
                true => format!("texture {k} has no image"),
                false => format!(
                    "texture {k} has its image through {} only, which is not read (PNG and JPEG are)",
                    others.join(", ")
                ),
            };
            self.not_used(m, &why, report);
            return Ok(NO_TEXTURE);
        }
        let image = match self.images.get(&src) {
            Some(u) => u.clone(),
            None => {
                let u = self.image(src, report)?;
                self.images.insert(src, u.clone());
                u
            }
        };
        let (image, size) = match image {
            ImageUse::Ready(image, size) => (image, size),
            ImageUse::NotUsed(why) => {
                self.not_used(m, &why, report);
                return Ok(NO_TEXTURE);
            }
            ImageUse::Missing | ImageUse::Unreadable => return Ok(NO_TEXTURE),
        };
        let Ok(t) = u32::try_from(report.textures.len()) else {
            return Ok(NO_TEXTURE);
        };
        let wrap = tex
            .sampler
            .and_then(|s| root.samplers.get(s.value()))
            .map_or([Wrap::Repeat; 2], |s| [wrap(&s.wrap_s), wrap(&s.wrap_t)]);
        let f = pbr.base_color_factor.0.map(|x| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                1.0
            }
        });
        report.textures.push(TextureSource {
            material: material_name(root, m),
            image,
            image_name: image_name(root, src),
            tint: [
                srgb8(f[0]),
                srgb8(f[1]),
                srgb8(f[2]),
                (f[3] * 255.0 + 0.5) as u8,
            ],
            wrap,
            v_up: false,
            size,
        });
        Ok(t)
    }

    /// Find image `src`'s bytes and read its header (an error when they are in a file
    /// the asset policy refuses).
    fn image(&mut self, src: usize, report: &mut ImportReport) -> Result<ImageUse, MeshError> {
        let root = self.root;
        let img = &root.images[src];
        let name = image_name(root, src);
        // The format the file says, where it says one.
        let declared = img
            .mime_type
            .as_ref()
            .map(|m| m.0.to_ascii_lowercase())
            .or_else(|| {
                let uri = img.uri.as_deref()?;
                match uri.strip_prefix("data:") {
                    Some(rest) => {
                        let media = rest.split([';', ',']).next()?.to_ascii_lowercase();
                        media.starts_with("image/").then_some(media)
                    }
                    None => {
                        let f = image::ImageFormat::from_path(uri.split(['?', '#']).next()?);
                        f.ok().map(|f| f.to_mime_type().to_string())
                    }
                }
            });
        if let Some(mime) =
            declared.filter(|m| !matches!(m.as_str(), "image/png" | "image/jpeg" | "image/jpg"))
        {
            return Ok(ImageUse::NotUsed(format!(
                "{mime} images are not read (PNG and JPEG are)"
            )));
        }
        let at = format!("image {src}");
        let (source, probe, shown) = if let Some(uri) = &img.uri {
            if let Some(rest) = uri.strip_prefix("data:") {
                let bytes: Arc<[u8]> = match decode_data_uri(rest, u64::MAX) {
                    Ok(b) => b.into(),
                    Err(why) => {
                        return Ok(self.unreadable(&name, &format!("bad data URI: {why}"), report))
                    }
                };
                let probe = probe_bytes(&bytes);
                let source = ImageSource::Memory { key: at, bytes };
                (source, probe, name.clone())
            } else {
                let Some(external) = self.external else {
                    return Ok(ImageUse::NotUsed(format!(
                        "names an external file '{}', which this reader may not open",
                        clip(uri)
                    )));
                };
                let file = match external.resolve(uri, &format!("glTF image {src} URI")) {
                    Ok(file) => file,
                    Err(UriError::Url) => {
                        return Ok(ImageUse::NotUsed(format!(
                            "uri '{}' {URL_REFUSED}",
                            clip(uri)
                        )))
                    }
                    Err(UriError::BadEscape) => {
                        return Ok(self.unreadable(
                            &name,
                            "its uri is badly percent-encoded",
                            report,
                        ))
                    }
                    Err(UriError::Asset(AssetError::Refused(detail))) => {
                        return Err(self.refused(detail))
                    }
                    Err(UriError::Asset(AssetError::Missing { resolved, .. })) => resolved,
                };
                let probe = probe_file(&file);
                let shown = file.display().to_string();
                (ImageSource::File(file), probe, shown)
            }
        } else if let Some(v) = img.buffer_view {
            match self.view_image(v.value(), &at, &name) {
                Ok(found) => found,
                Err(ViewError::Refused(detail)) => return Err(self.refused(detail)),
                Err(ViewError::Unreadable(why)) => return Ok(self.unreadable(&name, &why, report)),
            }
        } else {
            return Ok(self.unreadable(&name, "it has neither a uri nor a bufferView", report));
        };
        Ok(match probe {
            Ok(size) => ImageUse::Ready(source, size),
            Err(ProbeError::Missing(e)) => {
                if !report.missing_files.contains(&shown) {
                    self.missing.push(format!("{shown} ({e})"));
                    report.missing_files.push(shown);
                }
                ImageUse::Missing
            }
            Err(e @ ProbeError::Unsupported(_)) => ImageUse::NotUsed(e.to_string()),
            Err(ProbeError::Unreadable(why)) => self.unreadable(&shown, &why, report),
        })
    }

    fn refused(&self, detail: String) -> MeshError {
        MeshError::Refused {
            path: self.path.to_path_buf(),
            detail,
        }
    }

    /// An image in buffer view `v`: where it is, its header read, and the name of the
    /// file that holds it (for a missing `.bin`).
    fn view_image(&mut self, v: usize, key: &str, name: &str) -> Result<Found, ViewError> {
        let root = self.root;
        let view = root
            .buffer_views
            .get(v)
            .ok_or_else(|| format!("bufferView {v} does not exist"))?;
        let b = view.buffer.value();
        let buffer = root
            .buffers
            .get(b)
            .ok_or_else(|| format!("bufferView {v} reads buffer {b}, which does not exist"))?;
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let len = view.byte_length.0;
        let end = offset
            .checked_add(len)
            .ok_or_else(|| format!("bufferView {v} overflows"))?;
        let beyond = |have: usize| {
            format!("bufferView {v} needs bytes {offset}..{end} of buffer {b}, which has {have}")
        };
        match &buffer.uri {
            None => {
                let bin = self.bin.clone().filter(|_| b == 0).ok_or_else(|| {
                    format!("buffer {b} has no uri and is not a .glb's binary chunk")
                })?;
                if end > bin.len() as u64 {
                    return Err(beyond(bin.len()).into());
                }
                let start = bin.start + offset as usize;
                let probe = probe_bytes(&self.main[start..start + len as usize]);
                let source = ImageSource::FileRange {
                    path: self.path.to_path_buf(),
                    offset: start as u64,
                    len,
                };
                Ok((source, probe, name.to_string()))
            }
            Some(uri) if uri.starts_with("data:") => {
                let bytes = self
                    .data_buffers
                    .entry(b)
                    .or_insert_with(|| {
                        decode_data_uri(&uri["data:".len()..], u64::MAX)
                            .map(Arc::from)
                            .map_err(|why| format!("buffer {b} has a bad data URI: {why}"))
                    })
                    .clone()?;
                if end > bytes.len() as u64 {
                    return Err(beyond(bytes.len()).into());
                }
                let bytes: Arc<[u8]> = Arc::from(&bytes[offset as usize..end as usize]);
                let probe = probe_bytes(&bytes);
                let source = ImageSource::Memory {
                    key: key.to_string(),
                    bytes,
                };
                Ok((source, probe, name.to_string()))
            }
            Some(uri) => {
                let external = self.external.ok_or_else(|| {
                    format!("buffer {b} names an external file, which this reader may not open")
                })?;
                let file = match external.resolve(uri, &format!("glTF buffer {b} URI")) {
                    Ok(file) => file,
                    Err(UriError::Url) => {
                        return Err(format!("buffer {b}'s uri '{}' {URL_REFUSED}", clip(uri)).into())
                    }
                    Err(UriError::BadEscape) => {
                        return Err(format!(
                            "buffer {b}'s uri '{}' is badly percent-encoded",
                            clip(uri)
                        )
                        .into())
                    }
                    Err(UriError::Asset(AssetError::Refused(detail))) => {
                        return Err(ViewError::Refused(detail))
                    }
                    Err(UriError::Asset(AssetError::Missing { resolved, .. })) => resolved,
                };
                let probe = probe_file_range(&file, offset, len);
                let shown = file.display().to_string();
                let source = ImageSource::FileRange {
                    path: file,
                    offset,
                    len,
                };
                Ok((source, probe, shown))
            }
        }
    }

    fn unreadable(&mut self, shown: &str, why: &str, report: &mut ImportReport) -> ImageUse {
        self.unreadable.push(format!("{shown} ({why})"));
        report.unreadable_images.push(shown.to_string());
        ImageUse::Unreadable
    }

    /// One warning per kind of texture not used.
    pub(super) fn warn(&self, report: &ImportReport) {
        let p = self.path.display();
        let fallback = "drawn in the base colour factor x vertex colour, UVs kept";
        if !report.textures_not_used.is_empty() {
            tracing::warn!(
                "{p}: texture(s) not used: {}; {fallback}",
                report.textures_not_used.join(", ")
            );
        }
        if !self.missing.is_empty() {
            tracing::warn!(
                "{p}: texture image(s) missing: {}; {fallback}",
                self.missing.join(", ")
            );
        }
        if !self.unreadable.is_empty() {
            tracing::warn!(
                "{p}: texture image(s) whose header cannot be read: {}; {fallback}",
                self.unreadable.join(", ")
            );
        }
    }
}

/// A material's name, or `material 3`.
fn material_name(root: &json::Root, m: usize) -> String {
    root.materials[m]
        .name
        .clone()
        .unwrap_or_else(|| format!("material {m}"))
}

/// An image's name for messages: its uri as written, or `image 3 (embedded)`.
fn image_name(root: &json::Root, src: usize) -> String {
    match &root.images[src].uri {
        Some(u) if !u.starts_with("data:") => u.clone(),
        _ => format!("image {src} (embedded)"),
    }
}

fn wrap(mode: &Checked<WrappingMode>) -> Wrap {
    match mode {
        Checked::Valid(WrappingMode::ClampToEdge) => Wrap::ClampToEdge,
        Checked::Valid(WrappingMode::MirroredRepeat) => Wrap::MirroredRepeat,
        _ => Wrap::Repeat,
    }
}
