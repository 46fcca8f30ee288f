//! Wavefront OBJ importer, streamed where the format allows it.
//!
//! OBJ is the lingua franca of scanned and hand-made models (the bunny, Nefertiti). Its
//! faces index positions, texture coordinates and normals separately, while Tessera's
//! vertices carry all three, so the reader works in one of two modes, chosen by a cheap
//! first pass over the file (line prefixes only, stopping early when it can):
//!
//! * **direct**: no face references a `vt` or `vn`. Every `v` is delivered as a vertex
//!   the moment it is read (vertex index = position index) and memory stays O(1) besides
//!   the line buffer. Unreferenced `vt`/`vn` statements are ignored.
//! * **combined**: some face corner references a `vt` or `vn`. The output vertices are the
//!   distinct (v, vt, vn) combinations, created when a face first uses them. This keeps
//!   every position, uv and normal in memory plus a hash map from combination to output
//!   index, so memory grows with the mesh (roughly 60 bytes per distinct corner); OBJ's
//!   separate indexing makes that unavoidable without a second, random-access pass.
//!
//! Vertex colours follow the common `v x y z r g b` extension (floats in 0..1).
//!
//! Materials: the libraries named by `mtllib` lines met before the first face with
//! texture coordinates or normals (where the first pass may stop; exporters write them
//! at the top) are read ([`crate::mtl`]). When a material has a diffuse colour `Kd`
//! other than white, faces take their `usemtl` material's `Kd` (times the vertex colour):
//! the reader then works in combined mode with the material in each combination, so a
//! position shared by two materials becomes two vertices.
//!
//! Textures: the vertices of a face with texture coordinates whose material has a
//! `map_Kd` image (PNG or JPEG, whose header reads) sample it: `Vertex::texture` is the
//! index of the material's [`crate::TextureSource`] in the report, its UVs are the file's
//! (through `map_Kd`'s `-o` / `-s`), its colour `Kd` x the vertex colour (the fallback).
//! Combinations then key the material too (textured and untextured vertices are never
//! one vertex). A face of a textured material without `vt` on every corner is untextured
//! (counted, a warning); a missing library or image, an unreadable image, is a warning.
//! Whether any vertex will be textured is known before the first vertex (the header
//! says it): when some material is textured, one more pass over the line prefixes looks
//! for a face with texture coordinates under a textured material whose image reads
//! (stopping at the first, which exporters write near the top).

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::assets::Assets;
use crate::common::{finish_report, note_ignored, PolygonEmitter};
use crate::mtl::{Library, Material};
use crate::source::{ReadErr, Source};
use crate::{
    Attributes, ImportReport, MeshError, MeshHeader, MeshVisitor, ReadOptions, Vertex, NO_TEXTURE,
};

/// Longest (joined) line accepted: a polygon with ~a million corners.
const MAX_LINE: usize = 16 << 20;

/// The forms of a `v` statement this reader accepts, for messages.
const V_FORMS: &str = "x y z, x y z w, x y z r g b or x y z r g b a";

/// Marker for "no vt / vn" in a combination key.
const NONE: u32 = u32::MAX;

/// Read the OBJ file at `path` into `visitor`.
pub(crate) fn read_obj(
    path: &Path,
    options: &ReadOptions,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    read_obj_from(path, Some(options), || open(path), visitor)
}

/// Read OBJ data from the streams `open` returns (called twice: the first pass, then
/// the second); `path` is only used in messages and to find the material libraries,
/// which are read under `options`' policy (`None`: no other file is opened, as when
/// fuzzing: every library is missing).
pub(crate) fn read_obj_from<R: Read>(
    path: &Path,
    options: Option<&ReadOptions>,
    mut open: impl FnMut() -> Result<R, MeshError>,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let scan = prescan(path, open()?)?;
    let mut report = ImportReport::default();
    let assets = match options {
        Some(o) if !scan.mtllibs.is_empty() => Some(Assets::for_input(&o.assets, path)?),
        _ => None,
    };
    let mut library = Library::load(path, assets.as_ref(), &scan.mtllibs, &mut report)?;
    let material_colors = library.materials.values().any(|m| !m.is_white());
    let map_kd = library.materials.values().any(|m| m.map_kd.is_some());
    // Only faces with texture coordinates sample a texture; the pass stops at the first.
    let textures = scan.uses_vt && map_kd && texture_scan(path, open()?, &mut library)?;
    let attributes = Attributes {
        normals: scan.uses_vn,
        colors: scan.colors || material_colors,
        uvs: scan.uses_vt,
        textures,
    };
    visitor.header(&MeshHeader {
        attributes,
        vertex_count: None,
        face_count: None,
    })?;
    // Materials tell vertices apart when they colour them, or (with UVs) when they may
    // texture them or transform their UVs.
    let key_materials = material_colors || (scan.uses_vt && map_kd);
    let combined = scan.uses_vt || scan.uses_vn || key_materials;
    let mut reader = ObjReader::new(path, combined);
    reader.report = report;
    reader.vertex_colors = scan.colors;
    reader.library = library;
    reader.key_materials = key_materials;
    reader.textures = textures;
    let mut src = Source::new(open()?);
    let mut line = Vec::new();
    let mut last_statement = false;
    let mut part = Vec::new();
    while reader.next_line(&mut src, &mut line, &mut part)? {
        reader.statement(&line, visitor)?;
        last_statement = !line.trim_ascii().is_empty();
    }
    // A last statement the file ends inside may have been cut short ("f 55 64 6" of
    // "f 55 64 65"): it reads as valid, so say so.
    reader.report.unterminated_last_line = src.unterminated && last_statement;
    reader
        .library
        .warn_textures(path, &reader.used_materials, &mut reader.report);

    if !reader.report.unknown_materials.is_empty() {
        let names: Vec<String> = reader
            .report
            .unknown_materials
            .iter()
            .map(|(n, c)| format!("{n} ({c})"))
            .collect();
        tracing::warn!(
            "{}: usemtl names no material library defines (drawn white): {}",
            path.display(),
            names.join(", ")
        );
    }
    finish_report(path, reader.report)
}

fn open(path: &Path) -> Result<File, MeshError> {
    File::open(path).map_err(|e| MeshError::io(path, e))
}

// ---------------------------------------------------------------------------------------
// First pass
// ---------------------------------------------------------------------------------------

/// What the first pass learns.
#[derive(Debug, Default)]
struct Scan {
    /// Some face corner references a texture coordinate.
    uses_vt: bool,
    /// Some face corner references a normal.
    uses_vn: bool,
    /// The first `v` statement carries a colour.
    colors: bool,
    /// The `mtllib` lines seen (the rest of each line).
    mtllibs: Vec<String>,
}

/// Look at line prefixes only; stop as soon as faces are known to use both vt and vn.
fn prescan<R: Read>(path: &Path, reader: R) -> Result<Scan, MeshError> {
    let mut src = Source::new(reader);
    let mut line = Vec::new();
    let mut scan = Scan::default();
    let mut seen_v = false;
    loop {
        let more = src
            .line_into(&mut line, MAX_LINE)
            .map_err(|e| read_error(path, &src, e))?;
        if !more {
            return Ok(scan);
        }
        match line.trim_ascii_start() {
            [b'm', b't', b'l', b'l', b'i', b'b', b' ' | b'\t', rest @ ..] => {
                let name = String::from_utf8_lossy(strip_comment(rest))
                    .trim()
                    .to_string();
                if !name.is_empty() {
                    scan.mtllibs.push(name);
                }
            }
            [b'v', b' ' | b'\t', rest @ ..] if !seen_v => {
                seen_v = true;
                scan.colors = words(strip_comment(rest)).count() >= 6;
            }
            [b'f', b' ' | b'\t', rest @ ..] if line.contains(&b'/') => {
                for corner in words(rest) {
                    let mut parts = corner.split(|&b| b == b'/').skip(1);
                    scan.uses_vt |= parts.next().is_some_and(|p| !p.is_empty());
                    scan.uses_vn |= parts.next().is_some_and(|p| !p.is_empty());
                }
                if scan.uses_vt && scan.uses_vn && seen_v {
                    return Ok(scan);
                }
            }
            _ => {}
        }
    }
}

/// Whether some face with texture coordinates on every corner lies under a textured
/// material whose image reads, i.e. whether some vertex will sample a texture. Reads
/// logical lines (continuations joined) up to the first such face.
fn texture_scan<R: Read>(path: &Path, reader: R, library: &mut Library) -> Result<bool, MeshError> {
    let mut src = Source::new(reader);
    let (mut line, mut part) = (Vec::new(), Vec::new());
    let mut textured = false;
    while logical_line(path, &mut src, &mut line, &mut part)?.is_some() {
        // As `ObjReader::statement` reads the line.
        let mut w = words(&line);
        match w.next() {
            Some(b"usemtl") => textured = library.texture_size(&usemtl_name(&line)).is_some(),
            Some(b"f" | b"fo") if textured => {
                let mut corners = w.peekable();
                if corners.peek().is_some()
                    && corners.all(|c| {
                        c.split(|&b| b == b'/')
                            .nth(1)
                            .is_some_and(|vt| !vt.is_empty())
                    })
                {
                    return Ok(true);
                }
            }
            _ => {}
        }
    }
    Ok(false)
}

/// The name of a `usemtl NAME` statement (the rest of the line: names may hold spaces).
fn usemtl_name(line: &[u8]) -> String {
    let rest = line.trim_ascii();
    String::from_utf8_lossy(rest.get(6..).unwrap_or(&[]).trim_ascii()).into_owned()
}

/// Read the next logical line into `line` (joining `\` continuations; `part` is
/// scratch), its comment stripped. Returns the number of its first physical line, `None`
/// at the end of the file.
fn logical_line<R: Read>(
    path: &Path,
    src: &mut Source<R>,
    line: &mut Vec<u8>,
    part: &mut Vec<u8>,
) -> Result<Option<u64>, MeshError> {
    let mut first = None;
    line.clear();
    loop {
        let more = src
            .line_into(part, MAX_LINE)
            .map_err(|e| read_error(path, src, e))?;
        if !more {
            return Ok(first);
        }
        let no = *first.get_or_insert(src.line.saturating_sub(1));
        match part.strip_suffix(b"\\") {
            Some(head) => line.extend_from_slice(head),
            None => {
                line.extend_from_slice(part);
                let keep = strip_comment(line).len();
                line.truncate(keep);
                return Ok(first);
            }
        }
        if line.len() > MAX_LINE {
            return Err(MeshError::malformed(
                path,
                format!("line {no}"),
                format!("line longer than {MAX_LINE} bytes"),
            ));
        }
    }
}

fn read_error<R: Read>(path: &Path, src: &Source<R>, e: ReadErr) -> MeshError {
    match e {
        ReadErr::Io(e) => MeshError::io(path, e),
        ReadErr::Eof => MeshError::truncated(path, "unexpected end of file"),
        ReadErr::Parse(m) => MeshError::malformed(path, format!("line {}", src.line), m),
        ReadErr::BadIndex(i) => {
            MeshError::malformed(path, format!("line {}", src.line), format!("bad index {i}"))
        }
        // Only the PLY reader reads lists.
        ReadErr::BadListCount { count, why, .. } => MeshError::malformed(
            path,
            format!("line {}", src.line),
            format!("list count {count} {why}"),
        ),
    }
}

fn strip_comment(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

fn words(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|w| !w.is_empty())
}

// ---------------------------------------------------------------------------------------
// Second pass
// ---------------------------------------------------------------------------------------

/// The in-memory tables of combined mode (see the module docs for the memory cost).
#[derive(Default)]
struct Combined {
    positions: Vec<[f32; 3]>,
    colors: Vec<[u8; 4]>,
    uvs: Vec<[f32; 2]>,
    normals: Vec<[f32; 3]>,
    /// (v, vt, vn, material) 0-based, `NONE` when absent → output vertex index.
    map: HashMap<[u32; 4], u32>,
}

struct ObjReader<'p> {
    path: &'p Path,
    /// 1-based number of the current line.
    line_no: u64,
    v_count: u64,
    vt_count: u64,
    vn_count: u64,
    /// `Some` in combined mode.
    combined: Option<Combined>,
    /// Output vertices delivered so far.
    delivered: u64,
    corners: Vec<u32>,
    emitter: PolygonEmitter,
    report: ImportReport,
    /// `v` statements carry colours.
    vertex_colors: bool,
    library: Library,
    /// Combinations key the material (it colours the faces, or textures them).
    key_materials: bool,
    /// The materials of the `usemtl` names met, by index; the current one.
    materials: Vec<UsedMaterial>,
    material_index: HashMap<String, u32>,
    current_material: u32,
    /// Names of the materials `usemtl` chose, in order of first use.
    used_materials: Vec<String>,
    /// The corners of the face being read.
    parsed: Vec<(u32, u32, u32)>,
    /// The header says some vertex is textured: faces may be (else none is, whatever
    /// the second pass meets: it cannot contradict the header).
    textures: bool,
}

/// A material `usemtl` chose.
struct UsedMaterial {
    name: String,
    material: Material,
    /// The image size, when the material is textured and its image reads.
    texture_size: Option<[u32; 2]>,
    /// Its index in `ImportReport::textures`, once a vertex samples it.
    texture: Option<u32>,
}

impl<'p> ObjReader<'p> {
    fn new(path: &'p Path, combined: bool) -> Self {
        ObjReader {
            path,
            line_no: 0,
            v_count: 0,
            vt_count: 0,
            vn_count: 0,
            combined: combined.then(Combined::default),
            delivered: 0,
            corners: Vec::new(),
            emitter: PolygonEmitter::default(),
            report: ImportReport::default(),
            vertex_colors: false,
            library: Library::default(),
            key_materials: false,
            materials: Vec::new(),
            material_index: HashMap::new(),
            current_material: NONE,
            used_materials: Vec::new(),
            parsed: Vec::new(),
            textures: false,
        }
    }

    /// Read the next logical line (joining `\` continuations), comment stripped.
    fn next_line<R: Read>(
        &mut self,
        src: &mut Source<R>,
        line: &mut Vec<u8>,
        part: &mut Vec<u8>,
    ) -> Result<bool, MeshError> {
        match logical_line(self.path, src, line, part)? {
            Some(no) => {
                self.line_no = no;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    fn malformed(&self, detail: impl Into<String>) -> MeshError {
        MeshError::malformed(self.path, format!("line {}", self.line_no), detail)
    }

    fn statement(&mut self, line: &[u8], visitor: &mut dyn MeshVisitor) -> Result<(), MeshError> {
        let mut w = words(line);
        let Some(keyword) = w.next() else {
            return Ok(());
        };
        match keyword {
            b"v" => self.position(w, visitor),
            b"vt" => self.tex_coord(w),
            b"vn" => self.normal(w),
            b"f" | b"fo" => self.face(w, visitor),
            // Grouping, smoothing and materials: nothing of the geometry is lost.
            b"o" | b"g" | b"s" | b"mtllib" => Ok(()),
            b"usemtl" => {
                self.use_material(line);
                Ok(())
            }
            // Everything else is counted and named in the import warning, including the
            // geometry a triangle mesh cannot hold: lines (`l`), points (`p`) and the
            // parameter-space vertices (`vp`) of free-form curves and surfaces.
            other => {
                note_ignored(&mut self.report, &String::from_utf8_lossy(other), 1);
                Ok(())
            }
        }
    }

    /// `usemtl NAME` (the rest of the line: names may hold spaces).
    fn use_material(&mut self, line: &[u8]) {
        let name = usemtl_name(line);
        if let Some(&i) = self.material_index.get(&name) {
            self.current_material = i;
            return;
        }
        match self.library.materials.get(&name).cloned() {
            Some(material) => {
                let i = self.materials.len() as u32;
                let texture_size = self.library.texture_size(&name);
                self.materials.push(UsedMaterial {
                    name: name.clone(),
                    material,
                    texture_size,
                    texture: None,
                });
                self.material_index.insert(name.clone(), i);
                self.used_materials.push(name);
                self.current_material = i;
            }
            None => {
                *self.report.unknown_materials.entry(name).or_default() += 1;
                self.current_material = NONE;
            }
        }
    }

    /// Parse at least `min` and at most `N` floats; returns the array and how many were read.
    ///
    /// More than `N` numbers is an error naming the line, not something to drop
    /// silently: the extra numbers are most often two statements run together (a lost
    /// newline) or a dialect this reader does not know, and guessing would shift or
    /// discolour the mesh without a word. `expected` says what the statement may hold.
    fn floats<'a, const N: usize>(
        &self,
        what: &str,
        min: usize,
        expected: &str,
        w: impl Iterator<Item = &'a [u8]>,
    ) -> Result<([f32; N], usize), MeshError> {
        let mut out = [0f32; N];
        let mut n = 0;
        for word in w {
            let x = parse_f32(word).ok_or_else(|| {
                self.malformed(format!(
                    "{what}: '{}' is not a number (expected {expected})",
                    String::from_utf8_lossy(word)
                ))
            })?;
            if let Some(slot) = out.get_mut(n) {
                *slot = x;
            }
            n += 1;
        }
        if n < min {
            return Err(self.malformed(format!(
                "{what} needs at least {min} numbers, found {n} (expected {expected})"
            )));
        }
        if n > N {
            return Err(self.malformed(format!("{what} has {n} numbers (expected {expected})")));
        }
        Ok((out, n))
    }

    fn position<'a>(
        &mut self,
        w: impl Iterator<Item = &'a [u8]>,
        visitor: &mut dyn MeshVisitor,
    ) -> Result<(), MeshError> {
        // The forms in use: `x y z`, `x y z w` (w, a rational weight, is dropped: it
        // only matters to free-form geometry) and the vertex colour extension
        // `x y z r g b [a]`. Five numbers is none of them (see `floats` for why that
        // and more than seven are errors rather than warnings).
        let (vals, n) = self.floats::<7>("v", 3, V_FORMS, w)?;
        if n == 5 {
            return Err(self.malformed(format!("v has 5 numbers (expected {V_FORMS})")));
        }
        let position = [vals[0], vals[1], vals[2]];
        if !position.iter().all(|c| c.is_finite()) {
            return Err(MeshError::NonFinite {
                path: self.path.to_path_buf(),
                vertex: self.v_count,
            });
        }
        let color = if n >= 6 && self.vertex_colors {
            let alpha = if n >= 7 { vals[6] } else { 1.0 };
            [vals[3], vals[4], vals[5], alpha].map(|c| (c * 255.0).round() as u8)
        } else {
            [255; 4]
        };
        self.v_count += 1;
        match &mut self.combined {
            Some(c) => {
                c.positions.push(position);
                if self.vertex_colors {
                    c.colors.push(color);
                }
                Ok(())
            }
            None => {
                let v = Vertex {
                    position,
                    color,
                    ..Vertex::default()
                };
                self.deliver(&v, visitor).map(drop)
            }
        }
    }

    fn tex_coord<'a>(&mut self, w: impl Iterator<Item = &'a [u8]>) -> Result<(), MeshError> {
        let (vals, _) = self.floats::<3>("vt", 1, "u [v [w]]", w)?;
        if !(vals[0].is_finite() && vals[1].is_finite()) {
            return Err(MeshError::NonFiniteUv {
                path: self.path.to_path_buf(),
                index: self.vt_count,
            });
        }
        self.vt_count += 1;
        if let Some(c) = &mut self.combined {
            c.uvs.push([vals[0], vals[1]]);
        }
        Ok(())
    }

    fn normal<'a>(&mut self, w: impl Iterator<Item = &'a [u8]>) -> Result<(), MeshError> {
        let (vals, _) = self.floats::<3>("vn", 3, "x y z", w)?;
        self.vn_count += 1;
        if let Some(c) = &mut self.combined {
            c.normals.push(vals);
        }
        Ok(())
    }

    /// Hand a vertex to the visitor; returns its output index.
    fn deliver(&mut self, v: &Vertex, visitor: &mut dyn MeshVisitor) -> Result<u32, MeshError> {
        let index = u32::try_from(self.delivered).map_err(|_| MeshError::TooManyVertices {
            path: self.path.to_path_buf(),
        })?;
        visitor.vertex(v)?;
        self.delivered += 1;
        self.report.vertices += 1;
        Ok(index)
    }

    fn face<'a>(
        &mut self,
        w: impl Iterator<Item = &'a [u8]>,
        visitor: &mut dyn MeshVisitor,
    ) -> Result<(), MeshError> {
        let mut corners = std::mem::take(&mut self.corners);
        corners.clear();
        let result = self.face_corners(w, &mut corners, visitor);
        let result = result.and_then(|()| self.emitter.emit(&corners, visitor, &mut self.report));
        self.corners = corners;
        result
    }

    fn face_corners<'a>(
        &mut self,
        w: impl Iterator<Item = &'a [u8]>,
        corners: &mut Vec<u32>,
        visitor: &mut dyn MeshVisitor,
    ) -> Result<(), MeshError> {
        let mut parsed = std::mem::take(&mut self.parsed);
        parsed.clear();
        let result = self.face_vertices(w, &mut parsed, corners, visitor);
        self.parsed = parsed;
        result
    }

    fn face_vertices<'a>(
        &mut self,
        w: impl Iterator<Item = &'a [u8]>,
        parsed: &mut Vec<(u32, u32, u32)>,
        corners: &mut Vec<u32>,
        visitor: &mut dyn MeshVisitor,
    ) -> Result<(), MeshError> {
        for corner in w {
            parsed.push(self.parse_corner(corner)?);
        }
        let material = self.materials.get(self.current_material as usize);
        let map_kd = material.is_some_and(|m| m.material.map_kd.is_some());
        let all_vt = parsed.iter().all(|&(_, vt, _)| vt != NONE);
        if map_kd && !all_vt && parsed.len() >= 3 {
            self.report.untextured_faces += 1;
        }
        let readable = self.textures && material.is_some_and(|m| m.texture_size.is_some());
        // A face of a textured material with `vt` on some corners only is untextured:
        // its corners drop their `vt`, so they cannot be one vertex with the textured
        // corners of other faces.
        let (textured, drop_vt) = (readable && all_vt, readable && !all_vt);
        for &(v, vt, vn) in parsed.iter() {
            let index = match self.combined.is_some() {
                true => {
                    let vt = if drop_vt { NONE } else { vt };
                    self.combined_vertex(v, vt, vn, textured, visitor)?
                }
                false => v,
            };
            corners.push(index);
        }
        Ok(())
    }

    /// The texture index of material `material`, its `TextureSource` made the first time.
    fn texture_of(&mut self, material: u32) -> u32 {
        let Some(m) = self.materials.get_mut(material as usize) else {
            return NO_TEXTURE;
        };
        if let Some(t) = m.texture {
            return t;
        }
        let (Some(size), Ok(t)) = (m.texture_size, u32::try_from(self.report.textures.len()))
        else {
            return NO_TEXTURE;
        };
        let Some(source) = m.material.texture_source(&m.name, size) else {
            return NO_TEXTURE;
        };
        self.report.textures.push(source);
        m.texture = Some(t);
        t
    }

    /// Resolve `v[/vt][/vn]` into 0-based indices (`NONE` when absent).
    fn parse_corner(&self, corner: &[u8]) -> Result<(u32, u32, u32), MeshError> {
        let mut parts = corner.split(|&b| b == b'/');
        let bad = || {
            self.malformed(format!(
                "bad face corner '{}'",
                String::from_utf8_lossy(corner)
            ))
        };
        let v = parts.next().filter(|p| !p.is_empty()).ok_or_else(bad)?;
        let vt = parts.next().filter(|p| !p.is_empty());
        let vn = parts.next().filter(|p| !p.is_empty());
        if parts.next().is_some() {
            return Err(bad());
        }
        let v = self.resolve(v, self.v_count, "vertex")?;
        let vt = vt
            .map(|p| self.resolve(p, self.vt_count, "texture coordinate"))
            .transpose()?;
        let vn = vn
            .map(|p| self.resolve(p, self.vn_count, "normal"))
            .transpose()?;
        Ok((v, vt.unwrap_or(NONE), vn.unwrap_or(NONE)))
    }

    /// 1-based or negative (relative) OBJ index → 0-based, checked against `count`.
    fn resolve(&self, word: &[u8], count: u64, what: &str) -> Result<u32, MeshError> {
        let text = String::from_utf8_lossy(word);
        let Ok(raw) = text.parse::<i64>() else {
            // A run of digits too long for 64 bits is an integer, just out of range.
            let digits = text.strip_prefix(['-', '+']).unwrap_or(&text);
            let problem = match !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
                true => format!("is out of range ({count} defined so far)"),
                false => "is not an integer".to_string(),
            };
            return Err(self.malformed(format!("{what} index '{text}' {problem}")));
        };
        let resolved = match raw {
            1.. => Some(raw - 1),
            ..=-1 => i64::try_from(count).ok().map(|c| c + raw),
            0 => None,
        };
        match resolved {
            Some(i) if i >= 0 && (i as u64) < count => Ok(i as u32),
            _ if what == "vertex" => Err(MeshError::IndexOutOfRange {
                path: self.path.to_path_buf(),
                line_or_offset: format!("line {}", self.line_no),
                index: raw,
                vertex_count: count,
            }),
            _ => Err(self.malformed(format!(
                "{what} index {raw} out of range ({count} defined so far)"
            ))),
        }
    }

    /// The output index of the (v, vt, vn) combination, delivering it the first time;
    /// `textured`: it samples the current material's texture.
    fn combined_vertex(
        &mut self,
        v: u32,
        vt: u32,
        vn: u32,
        textured: bool,
        visitor: &mut dyn MeshVisitor,
    ) -> Result<u32, MeshError> {
        let material = if self.key_materials {
            self.current_material
        } else {
            NONE
        };
        let Some(c) = &self.combined else {
            return Ok(v);
        };
        if let Some(&i) = c.map.get(&[v, vt, vn, material]) {
            return Ok(i);
        }
        // A vertex of a textured material whose image reads is textured when its face has
        // `vt` on every corner (the others dropped theirs): keyed by the material, it
        // is never one vertex with an untextured one.
        let texture = match textured {
            true => self.texture_of(material),
            false => NO_TEXTURE,
        };
        let Some(c) = &self.combined else {
            return Ok(v);
        };
        let used = self.materials.get(material as usize);
        // `resolve` checked every index against the table lengths.
        let get = |table: &[[f32; 3]], i: u32| table.get(i as usize).copied().unwrap_or_default();
        let vertex = Vertex {
            position: get(&c.positions, v),
            normal: if vn == NONE {
                [0.0; 3]
            } else {
                get(&c.normals, vn)
            },
            color: {
                let own = c.colors.get(v as usize).copied().unwrap_or([255; 4]);
                match used {
                    Some(m) => m.material.tint(own),
                    None => own,
                }
            },
            uv: {
                let uv = c.uvs.get(vt as usize).copied().unwrap_or_default();
                match used.and_then(|m| m.material.map_kd.as_ref()) {
                    Some(map) if vt != NONE => map.transform(uv),
                    _ => uv,
                }
            },
            texture,
        };
        let index = self.deliver(&vertex, visitor)?;
        if let Some(c) = &mut self.combined {
            c.map.insert([v, vt, vn, material], index);
        }
        Ok(index)
    }
}

fn parse_f32(word: &[u8]) -> Option<f32> {
    std::str::from_utf8(word).ok()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prescan_detects_modes() {
        let s = prescan(Path::new("x"), &b"v 1 2 3\nf 1 2 3\n"[..]).unwrap();
        assert!(!s.uses_vt && !s.uses_vn && !s.colors);
        let s = prescan(Path::new("x"), &b"v 1 2 3 1 0 0\nf 1//1 2//1 3//1\n"[..]).unwrap();
        assert!(!s.uses_vt && s.uses_vn && s.colors);
        let s = prescan(Path::new("x"), &b"v 1 2 3 # 4 5 6\nf 1/2 2/2 3/2\n"[..]).unwrap();
        assert!(s.uses_vt && !s.uses_vn && !s.colors);
    }
}
