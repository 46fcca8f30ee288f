//! Wavefront MTL material libraries, as far as Tessera uses them: each material's
//! diffuse colour `Kd` becomes the colour of the faces that use it (times any `v x y z r
//! g b` vertex colour), so a multi-material model keeps its colours; its diffuse texture
//! `map_Kd` becomes a [`crate::TextureSource`] that the vertices of its faces sample
//! (with `Kd` as the fallback colour; the image is not tinted by it). `Kd` is taken as display values
//! (like the sRGB bytes of a PLY), as OBJ viewers show it.
//!
//! Of `map_Kd`'s options, `-clamp on` sets the wrap mode, `-o u v` and `-s u v` (offset
//! and scale of the texture) are applied to the UVs (`u' = s u + o`, as three.js and
//! Blender read them, and as `KHR_texture_transform` is applied to glTF's UVs); the
//! others (`-bm`, `-mm`, `-t`, `-blendu`, ...) do not change which texel a vertex
//! samples and are ignored. Images are looked up relative to the library's directory,
//! names may hold spaces; their headers are read (for their size) once per image.
//! Libraries and images are read only where [`crate::AssetPolicy`] allows (regular
//! files under the input's folder by default), libraries up to [`MAX_LIBRARY_BYTES`].

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::assets::{folder_of, open_regular, AssetError, Assets};
use crate::gltf_import::clip;
use crate::image_probe::{probe_file, ProbeError};
use crate::{ImageSource, ImportReport, MeshError, TextureSource, Wrap};

/// One material of a library.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Material {
    /// Diffuse colour, 0..1 (white when the library gives none).
    pub kd: [f32; 3],
    /// The diffuse texture.
    pub map_kd: Option<MapKd>,
}

/// A `map_Kd` statement.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct MapKd {
    /// The image as written (relative to the library's directory).
    pub name: String,
    /// Where it resolves.
    pub path: PathBuf,
    /// `-clamp on`.
    pub clamp: bool,
    /// `-s su sv` and `-o ou ov` as `[su, sv, ou, ov]` (`u' = su u + ou`), `None` when
    /// they change nothing.
    pub uv_transform: Option<[f32; 4]>,
}

impl MapKd {
    /// `uv` through the `-o` / `-s` options.
    pub fn transform(&self, uv: [f32; 2]) -> [f32; 2] {
        match self.uv_transform {
            Some([su, sv, ou, ov]) => [su * uv[0] + ou, sv * uv[1] + ov],
            None => uv,
        }
    }
}

/// What reading an image's header gave.
#[derive(Clone, Debug)]
pub(crate) enum ImageState {
    /// Its width and height.
    Size([u32; 2]),
    /// No file there (or it cannot be opened): the message.
    Missing(String),
    /// An image format other than PNG or JPEG: the message.
    Unsupported(String),
    /// The file is there, its header does not read: why.
    Unreadable(String),
}

impl Material {
    /// The RGBA8 colour a vertex of `color` takes under this material.
    pub fn tint(&self, color: [u8; 4]) -> [u8; 4] {
        let k = |c: u8, kd: f32| (f32::from(c) * kd.clamp(0.0, 1.0)).round() as u8;
        [
            k(color[0], self.kd[0]),
            k(color[1], self.kd[1]),
            k(color[2], self.kd[2]),
            color[3],
        ]
    }

    /// Whether the material changes a colour at all.
    pub fn is_white(&self) -> bool {
        self.kd.iter().all(|&c| c >= 1.0)
    }

    /// The texture of material `name` whose image is `size` big.
    pub fn texture_source(&self, name: &str, size: [u32; 2]) -> Option<TextureSource> {
        let map = self.map_kd.as_ref()?;
        Some(TextureSource {
            material: name.to_string(),
            image: ImageSource::File(map.path.clone()),
            image_name: map.name.clone(),
            // The image as it is: `Kd` beside a `map_Kd` is mostly an exporter's default
            // (Blender writes 0.64, 0.8 squared), and Blender's and MeshLab's importers
            // show the image unmodified; scans must keep their measured colours. `Kd`
            // stays the colour of the material's faces where the image is not used.
            tint: [255; 4],
            wrap: [if map.clamp {
                Wrap::ClampToEdge
            } else {
                Wrap::Repeat
            }; 2],
            v_up: true,
            size,
        })
    }
}

/// The materials of every library an OBJ names, by name (a later library or a later
/// `newmtl` of the same name wins, as readers commonly do).
#[derive(Debug, Default)]
pub(crate) struct Library {
    pub materials: HashMap<String, Material>,
    /// Images whose header was read, by path.
    images: HashMap<PathBuf, ImageState>,
}

impl Library {
    /// Load the libraries `names` (as written after `mtllib`) beside `obj`, under the
    /// policy `assets` (`None`: no file is opened, every library is missing). A library
    /// that is missing or cannot be read is a warning (its materials are drawn white):
    /// the geometry is all there. A library or texture the policy refuses (outside the
    /// allowed root, not a regular file, a library over [`MAX_LIBRARY_BYTES`]) is an
    /// error.
    pub fn load(
        obj: &Path,
        assets: Option<&Assets>,
        names: &[String],
        report: &mut ImportReport,
    ) -> Result<Library, MeshError> {
        let dir = folder_of(obj);
        let mut lib = Library::default();
        let refused = |detail: String| MeshError::Refused {
            path: obj.to_path_buf(),
            detail,
        };
        for name in names {
            for file in library_files(dir, name) {
                let missing = |shown: &Path, why: &dyn std::fmt::Display, r: &mut ImportReport| {
                    tracing::warn!(
                        "{}: material library {} cannot be read ({why}): its materials are drawn white",
                        obj.display(),
                        shown.display()
                    );
                    r.missing_files.push(shown.display().to_string());
                };
                let Some(assets) = assets else {
                    missing(&dir.join(&file), &"no file may be opened", report);
                    continue;
                };
                let what = format!("material library (mtllib) '{}'", clip(&file));
                let resolved = match assets.resolve(dir, &file, &what) {
                    Ok(p) => p,
                    Err(AssetError::Missing { resolved, cause }) => {
                        missing(&resolved, &cause, report);
                        continue;
                    }
                    Err(AssetError::Refused(why)) => return Err(refused(why)),
                };
                match read_library(&resolved) {
                    Ok(bytes) => {
                        // Its textures are named relative to the folder it is named in
                        // (a symlinked library's, not its target's), as before.
                        let text = String::from_utf8_lossy(&bytes);
                        lib.parse(&dir.join(&file), &text, Some(assets))
                            .map_err(refused)?;
                    }
                    Err(LibraryError::TooLarge(size)) => {
                        return Err(refused(format!(
                            "{what} ({}) has {size} bytes, more than the {} MiB a material \
                             library may have",
                            resolved.display(),
                            MAX_LIBRARY_BYTES >> 20
                        )))
                    }
                    Err(LibraryError::Io(e)) => missing(&resolved, &e, report),
                }
            }
        }
        Ok(lib)
    }

    /// Parse the library `file` (its text), its `map_Kd` images resolved under `assets`
    /// (`None`: joined to its folder, unchecked, for tests); a refused image is an
    /// error (the message).
    pub(crate) fn parse(
        &mut self,
        file: &Path,
        text: &str,
        assets: Option<&Assets>,
    ) -> Result<(), String> {
        let dir = file.parent().unwrap_or(Path::new("."));
        let mut current: Option<String> = None;
        for line in text.lines() {
            let line = line.split('#').next().unwrap_or("").trim();
            let Some((key, rest)) = line
                .split_once(|c: char| c.is_ascii_whitespace())
                .map(|(k, r)| (k, r.trim()))
                .or(Some((line, "")))
            else {
                continue;
            };
            match key {
                "newmtl" => {
                    let name = rest.to_string();
                    self.materials.insert(
                        name.clone(),
                        Material {
                            kd: [1.0; 3],
                            map_kd: None,
                        },
                    );
                    current = Some(name);
                }
                "Kd" => {
                    let Some(m) = current.as_ref().and_then(|n| self.materials.get_mut(n)) else {
                        continue;
                    };
                    let v: Vec<f32> = rest
                        .split_ascii_whitespace()
                        .filter_map(|w| w.parse().ok())
                        .filter(|x: &f32| x.is_finite())
                        .collect();
                    // `Kd r` alone means grey; `Kd spectral` / `Kd xyz` are left white.
                    match v.len() {
                        1 => m.kd = [v[0]; 3],
                        3.. => m.kd = [v[0], v[1], v[2]],
                        _ => {}
                    }
                }
                "map_Kd" => {
                    let Some(m) = current.as_ref().and_then(|n| self.materials.get_mut(n)) else {
                        continue;
                    };
                    if let Some((name, options)) = parse_map(rest) {
                        let what = format!("texture (map_Kd) '{}'", clip(&name));
                        let path = match assets.map(|a| a.resolve(dir, &name, &what)) {
                            Some(Ok(p)) => p,
                            Some(Err(AssetError::Refused(why))) => {
                                return Err(format!("material library {}: {why}", file.display()))
                            }
                            // Missing: the image probe says so, with a warning.
                            Some(Err(AssetError::Missing { .. })) | None => dir.join(&name),
                        };
                        m.map_kd = Some(MapKd {
                            path,
                            name,
                            clamp: options.clamp,
                            uv_transform: options.uv_transform(),
                        });
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// What the header of `path` gives, read the first time it is asked for.
    pub fn image(&mut self, path: &Path) -> &ImageState {
        self.images
            .entry(path.to_path_buf())
            .or_insert_with(|| match probe_file(path) {
                Ok(size) => ImageState::Size(size),
                Err(e @ ProbeError::Missing(_)) => ImageState::Missing(e.to_string()),
                Err(e @ ProbeError::Unsupported(_)) => ImageState::Unsupported(e.to_string()),
                Err(e) => ImageState::Unreadable(e.to_string()),
            })
    }

    /// The image size of material `name` when it is textured and its image reads.
    pub fn texture_size(&mut self, name: &str) -> Option<[u32; 2]> {
        let path = self.materials.get(name)?.map_kd.as_ref()?.path.clone();
        match self.image(&path) {
            ImageState::Size(s) => Some(*s),
            _ => None,
        }
    }

    /// Report the images of the textured materials among `used` that are missing,
    /// unreadable or in another format (each image once, one warning per kind), and the
    /// faces of textured materials without texture coordinates.
    pub fn warn_textures(&mut self, obj: &Path, used: &[String], report: &mut ImportReport) {
        let mut missing = Vec::new();
        let mut unreadable = Vec::new();
        let mut seen = Vec::new();
        for name in used {
            let Some(map) = self.materials.get(name).and_then(|m| m.map_kd.clone()) else {
                continue;
            };
            let shown = map.path.display().to_string();
            match self.image(&map.path).clone() {
                ImageState::Size(_) => {}
                ImageState::Unsupported(why) => report
                    .textures_not_used
                    .push(format!("{name} (image '{}'): {why}", map.name)),
                _ if seen.contains(&map.path) => {}
                ImageState::Missing(why) => {
                    missing.push(format!("{shown} ({why})"));
                    report.missing_files.push(shown);
                }
                ImageState::Unreadable(why) => {
                    unreadable.push(format!("{shown} ({why})"));
                    report.unreadable_images.push(shown);
                }
            }
            seen.push(map.path);
        }
        let p = obj.display();
        if !report.textures_not_used.is_empty() {
            tracing::warn!(
                "{p}: texture image(s) not used: {}; drawn in the material's Kd colour, UVs kept",
                report.textures_not_used.join(", "),
            );
        }
        if !missing.is_empty() {
            tracing::warn!(
                "{p}: texture image(s) missing: {}; drawn in the material's Kd colour, UVs kept",
                missing.join(", ")
            );
        }
        if !unreadable.is_empty() {
            tracing::warn!(
                "{p}: texture image(s) whose header cannot be read: {}; drawn in the material's Kd colour, UVs kept",
                unreadable.join(", ")
            );
        }
        if report.untextured_faces > 0 {
            tracing::warn!(
                "{p}: {} face(s) of textured materials have no texture coordinates (vt) on every corner: drawn untextured, in the material's Kd colour",
                report.untextured_faces
            );
        }
    }
}

/// The file names an `mtllib` line gives: the whole rest of the line when such a file
/// exists in `dir` (names with spaces, as many exporters write them), else its
/// whitespace-separated words (the specification's list of names).
fn library_files(dir: &Path, rest: &str) -> Vec<String> {
    if dir.join(rest).is_file() || !rest.contains(char::is_whitespace) {
        return vec![rest.to_string()];
    }
    rest.split_ascii_whitespace().map(str::to_string).collect()
}

/// The largest material library read: 64 MiB. A library is text, tens of bytes per
/// statement; the largest real ones (CAD exports with thousands of materials) are a few
/// MB. It is read whole (and copied once more if it is not UTF-8), so the limit bounds
/// what a hostile `mtllib` costs in memory, far above any real library.
pub(crate) const MAX_LIBRARY_BYTES: u64 = 64 << 20;

enum LibraryError {
    /// Its size in bytes, over [`MAX_LIBRARY_BYTES`].
    TooLarge(u64),
    Io(std::io::Error),
}

/// The bytes of the (regular, already resolved) library file `path`, at most
/// [`MAX_LIBRARY_BYTES`] of them.
fn read_library(path: &Path) -> Result<Vec<u8>, LibraryError> {
    let file = open_regular(path).map_err(LibraryError::Io)?;
    let size = file.metadata().map_err(LibraryError::Io)?.len();
    if size > MAX_LIBRARY_BYTES {
        return Err(LibraryError::TooLarge(size));
    }
    let mut bytes = Vec::with_capacity(size as usize);
    // `take`: the file may grow after the size was read.
    file.take(MAX_LIBRARY_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(LibraryError::Io)?;
    if bytes.len() as u64 > MAX_LIBRARY_BYTES {
        return Err(LibraryError::TooLarge(bytes.len() as u64));
    }
    Ok(bytes)
}

/// The options of a `map_Kd` statement that change how the image is sampled.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MapOptions {
    clamp: bool,
    /// `-o u v w` (0 where not given).
    offset: [f32; 3],
    /// `-s u v w` (1 where not given).
    scale: [f32; 3],
}

impl MapOptions {
    /// `[su, sv, ou, ov]`, `None` for the identity (w, the third coordinate of 3D
    /// textures, is ignored).
    fn uv_transform(&self) -> Option<[f32; 4]> {
        let t = [self.scale[0], self.scale[1], self.offset[0], self.offset[1]];
        (t != [1.0, 1.0, 0.0, 0.0] && t.iter().all(|x| x.is_finite())).then_some(t)
    }
}

/// The image of a `map_Kd` statement and its options (`-o u v w`, `-s u v w`, `-bm 1`,
/// `-clamp on`, ...). Options take a fixed number of arguments (`-o`, `-s` and `-t` up to
/// three numbers); the file name is the rest of the line (it may hold spaces).
fn parse_map(rest: &str) -> Option<(String, MapOptions)> {
    let mut options = MapOptions {
        clamp: false,
        offset: [0.0; 3],
        scale: [1.0; 3],
    };
    let mut words = rest.split_ascii_whitespace().peekable();
    let mut consumed = 0usize;
    while let Some(&w) = words.peek() {
        let args = match w {
            "-o" | "-s" | "-t" => 3,
            "-mm" => 2,
            "-blendu" | "-blendv" | "-cc" | "-clamp" | "-bm" | "-boost" | "-texres"
            | "-imfchan" => 1,
            _ => break,
        };
        words.next();
        consumed += 1;
        // `-o u [v [w]]`: take numeric arguments up to the count.
        let mut numbers = Vec::new();
        for _ in 0..args {
            match words.peek() {
                Some(a) if args == 1 || a.parse::<f32>().is_ok() => {
                    if w == "-clamp" {
                        options.clamp = *a == "on";
                    }
                    numbers.extend(a.parse::<f32>().ok());
                    words.next();
                    consumed += 1;
                }
                _ => break,
            }
        }
        let target = match w {
            "-o" => &mut options.offset,
            "-s" => &mut options.scale,
            _ => continue,
        };
        for (slot, x) in target.iter_mut().zip(numbers) {
            *slot = x;
        }
    }
    // The rest of the line after the consumed words, spaces inside kept.
    let mut s = rest;
    for _ in 0..consumed {
        s = s.trim_start();
        s = s
            .split_once(|c: char| c.is_ascii_whitespace())
            .map_or("", |(_, r)| r);
    }
    let s = s.trim();
    (!s.is_empty()).then(|| (s.to_string(), options))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map_file_name(rest: &str) -> Option<String> {
        parse_map(rest).map(|(name, _)| name)
    }

    #[test]
    fn map_kd_options_are_skipped_and_spaces_kept() {
        assert_eq!(map_file_name("tex.png").as_deref(), Some("tex.png"));
        assert_eq!(
            map_file_name("-s 1 1 1 -o 0 0 my photo.jpg").as_deref(),
            Some("my photo.jpg")
        );
        assert_eq!(
            map_file_name("-clamp on -bm 0.5 a.png").as_deref(),
            Some("a.png")
        );
        assert_eq!(map_file_name("-o 0.5 b.png").as_deref(), Some("b.png"));
        assert_eq!(map_file_name(""), None);
    }

    #[test]
    fn map_kd_clamp_offset_and_scale_are_read() {
        let (_, o) = parse_map("-clamp on -bm 0.5 a.png").unwrap();
        assert!(o.clamp);
        assert_eq!(o.uv_transform(), None);
        let (_, o) = parse_map("-clamp off a.png").unwrap();
        assert!(!o.clamp);
        let (name, o) = parse_map("-s 2 3 1 -o 0.5 b c.png").unwrap();
        assert_eq!(name, "b c.png");
        assert_eq!(o.uv_transform(), Some([2.0, 3.0, 0.5, 0.0]));
        let (_, o) = parse_map("-s 1 1 1 -o 0 0 0 d.png").unwrap();
        assert_eq!(o.uv_transform(), None);
        let map = MapKd {
            name: String::new(),
            path: PathBuf::new(),
            clamp: false,
            uv_transform: Some([2.0, 3.0, 0.5, 0.0]),
        };
        assert_eq!(map.transform([1.0, 1.0]), [2.5, 3.0]);
    }

    #[test]
    fn kd_tints_and_defaults_to_white() {
        let mut lib = Library::default();
        lib.parse(
            Path::new("/nowhere/m.mtl"),
            "newmtl red\nKd 1 0 0\nnewmtl grey\nKd 0.5\nnewmtl plain\nmap_Kd t.png\n",
            None,
        )
        .unwrap();
        let red = &lib.materials["red"];
        assert_eq!(red.tint([200, 200, 200, 255]), [200, 0, 0, 255]);
        assert_eq!(lib.materials["grey"].kd, [0.5; 3]);
        let plain = &lib.materials["plain"];
        assert!(plain.is_white());
        let map = plain.map_kd.as_ref().unwrap();
        assert_eq!(map.name, "t.png");
        assert_eq!(map.path, PathBuf::from("/nowhere/t.png"));
        assert!(!map.clamp);
        assert!(matches!(
            lib.image(Path::new("/nowhere/t.png")),
            ImageState::Missing(_)
        ));
        assert_eq!(lib.texture_size("plain"), None);
    }
}
