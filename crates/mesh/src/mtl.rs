//! Wavefront MTL material libraries, as far as Tessera uses them today: each material's
//! diffuse colour `Kd` becomes the colour of the faces that use it (times any `v x y z r
//! g b` vertex colour), so a multi-material model keeps its colours. Diffuse textures
//! (`map_Kd`) are not carried by the build yet: they are named in
//! [`crate::ImportReport::textures_not_used`] and one warning (with the images that are
//! missing on disk), and their faces are drawn in `Kd`, so a model is never silently
//! black. `Kd` is taken as display values (like the sRGB bytes of a PLY), as OBJ viewers
//! show it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::ImportReport;

/// One material of a library.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Material {
    /// Diffuse colour, 0..1 (white when the library gives none).
    pub kd: [f32; 3],
    /// The `map_Kd` image as written (relative to the library's directory).
    pub map_kd: Option<String>,
    /// Where `map_Kd` resolves, and whether a file is there.
    pub map_kd_path: Option<(PathBuf, bool)>,
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
}

/// The materials of every library an OBJ names, by name (a later library or a later
/// `newmtl` of the same name wins, as readers commonly do).
#[derive(Debug, Default)]
pub(crate) struct Library {
    pub materials: HashMap<String, Material>,
}

impl Library {
    /// Load the libraries `names` (as written after `mtllib`) beside `obj`. A library that
    /// cannot be read is a warning (its materials are drawn white), never an error: the
    /// geometry is all there.
    pub fn load(obj: &Path, names: &[String], report: &mut ImportReport) -> Library {
        let dir = obj.parent().unwrap_or(Path::new("."));
        let mut lib = Library::default();
        for name in names {
            for file in library_files(dir, name) {
                match std::fs::read(&file) {
                    Ok(bytes) => lib.parse(&file, &String::from_utf8_lossy(&bytes)),
                    Err(e) => {
                        tracing::warn!(
                            "{}: material library {} cannot be read ({e}): its materials are drawn white",
                            obj.display(),
                            file.display()
                        );
                        report.missing_files.push(file.display().to_string());
                    }
                }
            }
        }
        lib
    }

    fn parse(&mut self, file: &Path, text: &str) {
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
                            map_kd_path: None,
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
                    if let Some(image) = map_file_name(rest) {
                        let p = dir.join(&image);
                        let exists = p.is_file();
                        m.map_kd = Some(image);
                        m.map_kd_path = Some((p, exists));
                    }
                }
                _ => {}
            }
        }
    }

    /// One warning naming the textured materials among `used` (their images are not
    /// used yet), saying which images are missing on disk; the names go to `report`.
    pub fn warn_textures(&self, obj: &Path, used: &[String], report: &mut ImportReport) {
        let mut missing = Vec::new();
        for name in used {
            let Some(m) = self.materials.get(name) else {
                continue;
            };
            let (Some(image), Some((path, exists))) = (&m.map_kd, &m.map_kd_path) else {
                continue;
            };
            report
                .textures_not_used
                .push(format!("{name} (image '{image}')"));
            if !exists {
                missing.push(path.display().to_string());
                report.missing_files.push(path.display().to_string());
            }
        }
        let n = report.textures_not_used.len();
        if n > 0 {
            let s = if n > 1 { "s" } else { "" };
            tracing::warn!(
                "{}: textures are not used yet: the image{s} of {n} textured material{s} ignored: {}; drawn in the material's Kd colour, UVs kept",
                obj.display(),
                report.textures_not_used.join(", "),
            );
        }
        if !missing.is_empty() {
            tracing::warn!(
                "{}: texture image(s) missing: {}",
                obj.display(),
                missing.join(", ")
            );
        }
    }
}

/// The files an `mtllib` line names: the whole rest of the line when such a file exists
/// (names with spaces, as many exporters write them), else its whitespace-separated
/// words (the specification's list of names).
fn library_files(dir: &Path, rest: &str) -> Vec<PathBuf> {
    let whole = dir.join(rest);
    if whole.is_file() || !rest.contains(char::is_whitespace) {
        return vec![whole];
    }
    rest.split_ascii_whitespace().map(|w| dir.join(w)).collect()
}

/// The image of a `map_Kd` statement: what follows its options (`-o u v w`, `-s u v w`,
/// `-bm 1`, `-clamp on`, ...). Options take a fixed number of arguments; the file name
/// is the rest of the line (it may hold spaces).
fn map_file_name(rest: &str) -> Option<String> {
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
        for _ in 0..args {
            match words.peek() {
                Some(a) if args == 1 || a.parse::<f32>().is_ok() => {
                    words.next();
                    consumed += 1;
                }
                _ => break,
            }
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
    (!s.is_empty()).then(|| s.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn kd_tints_and_defaults_to_white() {
        let mut lib = Library::default();
        lib.parse(
            Path::new("/nowhere/m.mtl"),
            "newmtl red\nKd 1 0 0\nnewmtl grey\nKd 0.5\nnewmtl plain\nmap_Kd t.png\n",
        );
        let red = &lib.materials["red"];
        assert_eq!(red.tint([200, 200, 200, 255]), [200, 0, 0, 255]);
        assert_eq!(lib.materials["grey"].kd, [0.5; 3]);
        let plain = &lib.materials["plain"];
        assert!(plain.is_white());
        assert_eq!(plain.map_kd.as_deref(), Some("t.png"));
        assert_eq!(
            plain.map_kd_path,
            Some((PathBuf::from("/nowhere/t.png"), false))
        );
    }
}
