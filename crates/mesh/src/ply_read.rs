//! PLY importer (ascii, binary little- and big-endian), streamed.
//!
//! PLY is the format Tessera's large inputs usually come in, so this reader is the one
//! that must be fast and frugal: it walks the file once through a 1 MiB window, hands each
//! vertex and face to the visitor as soon as it is decoded, and never holds more than one
//! record. The header is compiled into a per-property plan (which slot each value lands
//! in, at which byte offset) so the hot loop is a tight, monomorphized decode with no
//! dynamic dispatch per value. Elements other than `vertex` and `face`, and properties
//! Tessera does not use, are skipped in all three encodings.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::common::{finish_report, note_ignored, PolygonEmitter};
use crate::source::{ReadErr, Source};
use crate::{Attributes, ImportReport, MeshError, MeshHeader, MeshVisitor, Vertex};

/// Longest header line accepted.
const MAX_HEADER_LINE: usize = 64 * 1024;

// ---------------------------------------------------------------------------------------
// Header model
// ---------------------------------------------------------------------------------------

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// Record size when every property is a scalar (binary encodings only).
    fn fixed_stride(&self) -> Option<usize> {
        self.props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(s) => Some(s.size()),
                PropKind::List { .. } => None,
            })
            .sum()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
}

// ---------------------------------------------------------------------------------------
// Entry point
// ---------------------------------------------------------------------------------------

/// Read the PLY file at `path` into `visitor`.
pub(crate) fn read_ply(
    path: &Path,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let file = File::open(path).map_err(|e| MeshError::io(path, e))?;
    read_ply_from(path, file, visitor)
}

/// Read PLY data from `reader`; `path` is only used in messages.
pub(crate) fn read_ply_from<R: Read>(
    path: &Path,
    reader: R,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let mut cx = Ctx {
        path,
        src: Source::new(reader),
        ascii: false,
    };
    let header = parse_header(&mut cx)?;
    cx.ascii = header.format == Format::Ascii;
    let (vertex_el, face_el, strips) = find_mesh_elements(&cx, &header)?;
    let vplan = VertexPlan::new(&cx, &header.elements[vertex_el])?;
    let fplan = FacePlan::new(&cx, &header.elements[face_el])?;
    visitor.header(&MeshHeader {
        attributes: vplan.attributes,
        vertex_count: Some(header.elements[vertex_el].count),
        // A strip holds any number of triangles.
        face_count: (!strips).then_some(header.elements[face_el].count),
    })?;
    let mut report = ImportReport::default();
    let plans = Plans {
        vertex_el,
        face_el,
        strips,
        vplan,
        fplan,
    };
    match header.format {
        Format::Ascii => read_body::<Ascii, R>(&mut cx, &header, &plans, visitor, &mut report)?,
        Format::BinaryLe => read_body::<Le, R>(&mut cx, &header, &plans, visitor, &mut report)?,
        Format::BinaryBe => read_body::<Be, R>(&mut cx, &header, &plans, visitor, &mut report)?,
    }
    let tail = cx
        .src
        .drain()
        .map_err(|e| cx.err(e, || "the end of the file".into()))?;
    if cx.ascii {
        report.trailing_bytes_ignored = tail.non_space;
        report.unterminated_last_line = tail.non_space == 0 && !tail.ends_in_newline;
    } else {
        report.trailing_bytes_ignored = tail.bytes;
    }
    finish_report(path, report)
}

/// The reader state shared by all stages: where we are, for error messages.
struct Ctx<'p, R> {
    path: &'p Path,
    src: Source<R>,
    ascii: bool,
}

impl<R: Read> Ctx<'_, R> {
    fn location(&self) -> String {
        if self.ascii {
            format!("line {}", self.src.line)
        } else {
            format!("byte {}", self.src.offset())
        }
    }

    fn malformed(&self, detail: impl Into<String>) -> MeshError {
        MeshError::malformed(self.path, self.location(), detail)
    }

    /// Turn a low-level read error into a [`MeshError`], `what` naming what was being read.
    fn err(&self, e: ReadErr, what: impl FnOnce() -> String) -> MeshError {
        match e {
            ReadErr::Eof => MeshError::truncated(self.path, format!("expected {}", what())),
            ReadErr::Io(e) => MeshError::io(self.path, e),
            ReadErr::Parse(msg) => self.malformed(format!("{}: {msg}", what())),
            ReadErr::BadIndex(i) => self.malformed(format!("{}: bad index {i}", what())),
            ReadErr::BadListCount { count, at, why } => {
                let at = match self.ascii {
                    true => format!("line {at}"),
                    false => format!("byte {at}"),
                };
                MeshError::malformed(
                    self.path,
                    at,
                    format!("{}: list count {count} {why}", what()),
                )
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Header parsing
// ---------------------------------------------------------------------------------------

fn parse_header<R: Read>(cx: &mut Ctx<'_, R>) -> Result<Header, MeshError> {
    let mut line = Vec::new();
    let next_line = |cx: &mut Ctx<'_, R>, line: &mut Vec<u8>| -> Result<bool, MeshError> {
        cx.src
            .line_into(line, MAX_HEADER_LINE)
            .map_err(|e| cx.err(e, || "a header line".into()))
    };
    let magic_ok = next_line(cx, &mut line)? && line.trim_ascii() == b"ply";
    if !magic_ok {
        return Err(MeshError::malformed(
            cx.path,
            "line 1",
            "not a PLY file (no 'ply' magic line)",
        ));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if !next_line(cx, &mut line)? {
            return Err(MeshError::truncated(
                cx.path,
                "header ends before 'end_header'",
            ));
        }
        // The line counter already moved past this line.
        let at = format!("line {}", cx.src.line.saturating_sub(1));
        let bad = |detail: String| MeshError::malformed(cx.path, at.clone(), detail);
        let text = String::from_utf8_lossy(&line);
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["end_header"] => break,
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _version] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => Format::BinaryBe,
                    other => return Err(bad(format!("unknown PLY format '{other}'"))),
                });
            }
            ["format", ..] => return Err(bad(format!("bad format line '{text}'"))),
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| bad(format!("bad element count '{count}'")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", rest @ ..] => {
                let prop = parse_property(rest).map_err(bad)?;
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element".into()))?;
                el.props.push(prop);
            }
            _ => return Err(bad(format!("unexpected header line '{text}'"))),
        }
    }
    let format =
        format.ok_or_else(|| MeshError::malformed(cx.path, "header", "no 'format' line"))?;
    Ok(Header { format, elements })
}

fn parse_property(words: &[&str]) -> Result<Property, String> {
    let ty =
        |name: &str| Scalar::parse(name).ok_or_else(|| format!("unknown property type '{name}'"));
    match *words {
        ["list", count, item, name] => {
            let count = ty(count)?;
            if count.is_float() {
                return Err(format!("list '{name}' has a non-integer count type"));
            }
            Ok(Property {
                name: name.to_string(),
                kind: PropKind::List {
                    count,
                    item: ty(item)?,
                },
            })
        }
        [t, name] => Ok(Property {
            name: name.to_string(),
            kind: PropKind::Scalar(ty(t)?),
        }),
        _ => Err(format!("bad property line 'property {}'", words.join(" "))),
    }
}

/// Indices of the `vertex` and `face` elements (or, without faces, `tristrips`: the
/// triangle strips some scanners' tools write, e.g. the Stanford Igea scan), checking
/// their presence and order; `true` when the faces are strips.
fn find_mesh_elements<R: Read>(
    cx: &Ctx<'_, R>,
    header: &Header,
) -> Result<(usize, usize, bool), MeshError> {
    let find = |name: &str| -> Result<Option<usize>, MeshError> {
        let mut found = header
            .elements
            .iter()
            .enumerate()
            .filter(|(_, e)| e.name == name);
        let first = found.next().map(|(i, _)| i);
        if found.next().is_some() {
            return Err(MeshError::malformed(
                cx.path,
                "header",
                format!("two '{name}' elements"),
            ));
        }
        Ok(first)
    };
    let vertex = find("vertex")?
        .ok_or_else(|| MeshError::malformed(cx.path, "header", "no 'vertex' element"))?;
    let (face, strips) = match (find("face")?, find("tristrips")?) {
        (Some(f), _) => (f, false),
        (None, Some(t)) => (t, true),
        (None, None) => {
            return Err(MeshError::malformed(
                cx.path,
                "header",
                "no 'face' or 'tristrips' element (point clouds are not meshes)",
            ))
        }
    };
    if face < vertex && header.elements[face].count > 0 {
        return Err(MeshError::malformed(
            cx.path,
            "header",
            "the 'face' element comes before the 'vertex' element; Tessera needs vertices first",
        ));
    }
    if header.elements[vertex].count > u64::from(u32::MAX) {
        return Err(MeshError::TooManyVertices {
            path: cx.path.to_path_buf(),
        });
    }
    Ok((vertex, face, strips))
}

// ---------------------------------------------------------------------------------------
// Plans: what to do with each property
// ---------------------------------------------------------------------------------------

const X: usize = 0;
const NX: usize = 3;
const R: usize = 6;
const A: usize = 9;
const U: usize = 10;
/// Where values nobody wants are written.
const TRASH: usize = 12;
const SLOTS: usize = 13;
/// Slot values before a vertex is read: colour channels default to 255.
const DEFAULTS: [f64; SLOTS] = [
    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 255.0, 255.0, 255.0, 255.0, 0.0, 0.0, 0.0,
];

fn slot_for(name: &str) -> Option<usize> {
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" | "normal_x" => 3,
        "ny" | "normal_y" => 4,
        "nz" | "normal_z" => 5,
        "red" | "diffuse_red" => 6,
        "green" | "diffuse_green" => 7,
        "blue" | "diffuse_blue" => 8,
        "alpha" | "diffuse_alpha" => 9,
        "u" | "s" | "texture_u" | "texture_s" => 10,
        "v" | "t" | "texture_v" | "texture_t" => 11,
        _ => return None,
    })
}

#[derive(Clone, Copy, Debug)]
struct VertexProp {
    kind: PropKind,
    slot: usize,
    /// Multiplier applied to the value (255 for float colours).
    scale: f64,
    /// Byte offset inside a fixed-size binary record.
    offset: usize,
}

#[derive(Debug)]
struct VertexPlan {
    props: Vec<VertexProp>,
    /// Record size when all properties are scalars.
    stride: Option<usize>,
    attributes: Attributes,
}

impl VertexPlan {
    fn new<R: Read>(cx: &Ctx<'_, R>, el: &Element) -> Result<VertexPlan, MeshError> {
        let mut taken = [false; SLOTS];
        let mut props = Vec::with_capacity(el.props.len());
        let mut offset = 0;
        for p in &el.props {
            let slot = match (p.kind, slot_for(&p.name)) {
                (PropKind::Scalar(_), Some(s)) if !taken[s] => s,
                _ => TRASH,
            };
            taken[slot] = true;
            let scale = match p.kind {
                PropKind::Scalar(s) if s.is_float() && (R..=A).contains(&slot) => 255.0,
                _ => 1.0,
            };
            props.push(VertexProp {
                kind: p.kind,
                slot,
                scale,
                offset,
            });
            offset += match p.kind {
                PropKind::Scalar(s) => s.size(),
                PropKind::List { .. } => 0,
            };
        }
        for (axis, slot) in ["x", "y", "z"].iter().zip(X..) {
            if !taken[slot] {
                return Err(MeshError::malformed(
                    cx.path,
                    "header",
                    format!("the vertex element has no scalar property '{axis}'"),
                ));
            }
        }
        let attributes = Attributes {
            normals: taken[NX..NX + 3].iter().all(|&t| t),
            colors: taken[R..R + 3].iter().all(|&t| t),
            uvs: taken[U..U + 2].iter().all(|&t| t),
            textures: false,
        };
        // An incomplete group (say nx, ny without nz) is ignored entirely.
        let keep = |slot: usize| match slot {
            NX..=5 => attributes.normals,
            R..=A => attributes.colors,
            U..=11 => attributes.uvs,
            _ => true,
        };
        for p in &mut props {
            if !keep(p.slot) {
                p.slot = TRASH;
            }
        }
        Ok(VertexPlan {
            props,
            stride: el.fixed_stride(),
            attributes,
        })
    }
}

#[derive(Debug)]
struct FacePlan {
    props: Vec<PropKind>,
    /// Which property holds the vertex indices.
    indices: usize,
}

impl FacePlan {
    fn new<R: Read>(cx: &Ctx<'_, R>, el: &Element) -> Result<FacePlan, MeshError> {
        let pos = el
            .props
            .iter()
            .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
            .ok_or_else(|| {
                MeshError::malformed(
                    cx.path,
                    "header",
                    "the face element has no 'vertex_indices' (or 'vertex_index') property",
                )
            })?;
        match el.props[pos].kind {
            PropKind::List { item, .. } if !item.is_float() => {}
            _ => {
                return Err(MeshError::malformed(
                    cx.path,
                    "header",
                    "the face vertex indices must be a list of integers",
                ))
            }
        }
        Ok(FacePlan {
            props: el.props.iter().map(|p| p.kind).collect(),
            indices: pos,
        })
    }

    /// `Some(count type)` for the common binary layout: only an index list of 4-byte ints
    /// with a 1- or 2-byte count (so one list never needs more than 256 KiB of window).
    fn simple_binary(&self) -> Option<(Scalar, Scalar)> {
        match self.props.as_slice() {
            [PropKind::List {
                count: count @ (Scalar::U8 | Scalar::I8 | Scalar::U16 | Scalar::I16),
                item: item @ (Scalar::I32 | Scalar::U32),
            }] => Some((*count, *item)),
            _ => None,
        }
    }
}

struct Plans {
    vertex_el: usize,
    face_el: usize,
    /// The face element is `tristrips`.
    strips: bool,
    vplan: VertexPlan,
    fplan: FacePlan,
}

// ---------------------------------------------------------------------------------------
// Decoding, monomorphized per encoding
// ---------------------------------------------------------------------------------------

/// How values are encoded: decoding functions are generic over this so the hot loops
/// compile to straight code per encoding.
trait Decoder {
    const BINARY: bool;
    /// Read one value of type `ty`.
    fn value<R: Read>(src: &mut Source<R>, ty: Scalar) -> Result<f64, ReadErr>;
    /// Decode a value at `off` in a fixed-size binary record (binary encodings only).
    fn at(rec: &[u8], off: usize, ty: Scalar) -> f64;
}

/// Copy `N` bytes at `off`; zeros if out of bounds (cannot happen with a valid plan).
#[inline(always)]
fn bytes_at<const N: usize>(rec: &[u8], off: usize) -> [u8; N] {
    let mut a = [0u8; N];
    if let Some(s) = rec.get(off..off + N) {
        a.copy_from_slice(s);
    }
    a
}

macro_rules! binary_decoder {
    ($name:ident, $from:ident) => {
        struct $name;
        impl Decoder for $name {
            const BINARY: bool = true;
            #[inline(always)]
            fn value<R: Read>(src: &mut Source<R>, ty: Scalar) -> Result<f64, ReadErr> {
                let rec = src.take(ty.size())?;
                Ok(Self::at(rec, 0, ty))
            }
            #[inline(always)]
            fn at(rec: &[u8], off: usize, ty: Scalar) -> f64 {
                match ty {
                    Scalar::I8 => f64::from(i8::$from(bytes_at(rec, off))),
                    Scalar::U8 => f64::from(u8::$from(bytes_at(rec, off))),
                    Scalar::I16 => f64::from(i16::$from(bytes_at(rec, off))),
                    Scalar::U16 => f64::from(u16::$from(bytes_at(rec, off))),
                    Scalar::I32 => f64::from(i32::$from(bytes_at(rec, off))),
                    Scalar::U32 => f64::from(u32::$from(bytes_at(rec, off))),
                    Scalar::F32 => f64::from(f32::$from(bytes_at(rec, off))),
                    Scalar::F64 => f64::$from(bytes_at(rec, off)),
                }
            }
        }
    };
}

binary_decoder!(Le, from_le_bytes);
binary_decoder!(Be, from_be_bytes);

struct Ascii;

impl Decoder for Ascii {
    const BINARY: bool = false;
    fn value<R: Read>(src: &mut Source<R>, _ty: Scalar) -> Result<f64, ReadErr> {
        let tok = src.token()?.ok_or(ReadErr::Eof)?;
        std::str::from_utf8(tok)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| {
                ReadErr::Parse(format!(
                    "'{}' is not a number",
                    String::from_utf8_lossy(tok)
                ))
            })
    }
    fn at(_rec: &[u8], _off: usize, _ty: Scalar) -> f64 {
        0.0
    }
}

/// A list length: a non-negative integer.
#[inline(always)]
fn list_len<D: Decoder, R: Read>(src: &mut Source<R>, ty: Scalar) -> Result<u64, ReadErr> {
    let n = D::value(src, ty)?;
    if !(n >= 0.0 && n.fract() == 0.0) {
        return Err(ReadErr::Parse(format!("invalid list length {n}")));
    }
    Ok(n as u64)
}

/// A list length and where it is, for [`ReadErr::BadListCount`]: its byte offset in a
/// binary file, its line in a text one.
#[inline(always)]
fn list_head<D: Decoder, R: Read>(src: &mut Source<R>, ty: Scalar) -> Result<(u64, u64), ReadErr> {
    let start = src.offset();
    let n = list_len::<D, R>(src, ty)?;
    // A text token does not consume the newline after it: `line` is the count's own.
    Ok((n, if D::BINARY { start } else { src.line }))
}

/// The end of the file inside a list whose length nothing else bounds (a strip, a
/// property Tessera skips): say that the count may be the culprit. Truncation is the
/// other explanation, and from the bytes alone the two cannot be told apart; the
/// message names both, and the count, so the user can judge (4294967295 is not a length).
fn past_end(count: u64, at: u64) -> impl Fn(ReadErr) -> ReadErr {
    move |e| match e {
        ReadErr::Eof => ReadErr::BadListCount {
            count,
            at,
            why: "is too large: the file ends before the list does (a corrupt count, or a \
                  truncated file)"
                .into(),
        },
        other => other,
    }
}

/// A face list longer than the vertex count cannot be a polygon Tessera keeps (by the
/// pigeonhole principle some corner repeats, and the face would be skipped as
/// degenerate): it is a corrupt count, which would otherwise read the rest of the file
/// as indices and end in "file is truncated" or a bogus index far from the real problem.
#[cold]
fn too_many_corners(count: u64, at: u64, vertex_count: u64) -> ReadErr {
    ReadErr::BadListCount {
        count,
        at,
        why: format!(
            "is implausible: a face cannot have more corners than the mesh has vertices \
             ({vertex_count})"
        ),
    }
}

/// Read past one property value of any kind.
fn skip_prop<D: Decoder, R: Read>(src: &mut Source<R>, kind: PropKind) -> Result<(), ReadErr> {
    match kind {
        PropKind::Scalar(s) if D::BINARY => src.skip(s.size() as u64),
        PropKind::Scalar(s) => D::value(src, s).map(drop),
        PropKind::List { count, item } => {
            let (n, at) = list_head::<D, R>(src, count)?;
            if D::BINARY {
                return src
                    .skip(n.saturating_mul(item.size() as u64))
                    .map_err(past_end(n, at));
            }
            for _ in 0..n {
                D::value(src, item).map_err(past_end(n, at))?;
            }
            Ok(())
        }
    }
}

// ---------------------------------------------------------------------------------------
// Body
// ---------------------------------------------------------------------------------------

fn read_body<D: Decoder, R: Read>(
    cx: &mut Ctx<'_, R>,
    header: &Header,
    plans: &Plans,
    visitor: &mut dyn MeshVisitor,
    report: &mut ImportReport,
) -> Result<(), MeshError> {
    let vertex_count = header.elements[plans.vertex_el].count;
    for (i, el) in header.elements.iter().enumerate() {
        if i == plans.vertex_el {
            read_vertices::<D, R>(cx, el, &plans.vplan, visitor)?;
            report.vertices = el.count;
        } else if i == plans.face_el && plans.strips {
            read_strips::<D, R>(cx, el, &plans.fplan, vertex_count, visitor, report)?;
        } else if i == plans.face_el {
            read_faces::<D, R>(cx, el, &plans.fplan, vertex_count, visitor, report)?;
        } else {
            skip_element::<D, R>(cx, el)?;
            if el.count > 0 {
                note_ignored(report, &format!("element {}", el.name), el.count);
            }
        }
    }
    Ok(())
}

fn skip_element<D: Decoder, R: Read>(cx: &mut Ctx<'_, R>, el: &Element) -> Result<(), MeshError> {
    let what = |i: u64| move || format!("element '{}' number {i} of {}", el.name, el.count);
    if el.props.is_empty() {
        return Ok(()); // Nothing to read, however large the count.
    }
    if let (true, Some(stride)) = (D::BINARY, el.fixed_stride()) {
        let bytes = el.count.saturating_mul(stride as u64);
        return cx.src.skip(bytes).map_err(|e| cx.err(e, what(el.count)));
    }
    for i in 0..el.count {
        for p in &el.props {
            skip_prop::<D, R>(&mut cx.src, p.kind).map_err(|e| cx.err(e, what(i)))?;
        }
    }
    Ok(())
}

fn read_vertices<D: Decoder, R: Read>(
    cx: &mut Ctx<'_, R>,
    el: &Element,
    plan: &VertexPlan,
    visitor: &mut dyn MeshVisitor,
) -> Result<(), MeshError> {
    let fixed = plan.stride.filter(|_| D::BINARY);
    for i in 0..el.count {
        let mut vals = DEFAULTS;
        let read = match fixed {
            Some(stride) => read_vertex_fixed::<D, R>(&mut cx.src, plan, stride, &mut vals),
            None => read_vertex_generic::<D, R>(&mut cx.src, plan, &mut vals),
        };
        read.map_err(|e| cx.err(e, || format!("vertex {i} of {}", el.count)))?;
        let v = make_vertex(&vals);
        if !v.position.iter().all(|c| c.is_finite()) {
            return Err(MeshError::NonFinite {
                path: cx.path.to_path_buf(),
                vertex: i,
            });
        }
        if !v.uv.iter().all(|c| c.is_finite()) {
            return Err(MeshError::NonFiniteUv {
                path: cx.path.to_path_buf(),
                index: i,
            });
        }
        visitor.vertex(&v)?;
    }
    Ok(())
}

#[inline(always)]
fn read_vertex_fixed<D: Decoder, R: Read>(
    src: &mut Source<R>,
    plan: &VertexPlan,
    stride: usize,
    vals: &mut [f64; SLOTS],
) -> Result<(), ReadErr> {
    let rec = src.take(stride)?;
    for p in &plan.props {
        if let PropKind::Scalar(ty) = p.kind {
            vals[p.slot] = D::at(rec, p.offset, ty) * p.scale;
        }
    }
    Ok(())
}

fn read_vertex_generic<D: Decoder, R: Read>(
    src: &mut Source<R>,
    plan: &VertexPlan,
    vals: &mut [f64; SLOTS],
) -> Result<(), ReadErr> {
    for p in &plan.props {
        match p.kind {
            PropKind::Scalar(ty) => vals[p.slot] = D::value(src, ty)? * p.scale,
            list => skip_prop::<D, R>(src, list)?,
        }
    }
    Ok(())
}

#[inline(always)]
fn make_vertex(vals: &[f64; SLOTS]) -> Vertex {
    let f = |i: usize| vals[i] as f32;
    // Round half up; `as u8` saturates, negative values and NaN give 0. (Not
    // `f64::round`, a libm call on baseline x86-64, four times per vertex.)
    let c = |i: usize| {
        let v = vals[i];
        if v >= 0.0 {
            (v + 0.5) as u8
        } else {
            0
        }
    };
    Vertex {
        position: [f(0), f(1), f(2)],
        normal: [f(3), f(4), f(5)],
        color: [c(6), c(7), c(8), c(9)],
        uv: [f(10), f(11)],
        texture: crate::NO_TEXTURE,
    }
}

fn read_faces<D: Decoder, R: Read>(
    cx: &mut Ctx<'_, R>,
    el: &Element,
    plan: &FacePlan,
    vertex_count: u64,
    visitor: &mut dyn MeshVisitor,
    report: &mut ImportReport,
) -> Result<(), MeshError> {
    let mut corners: Vec<u32> = Vec::with_capacity(16);
    let mut emitter = PolygonEmitter::default();
    let simple = plan.simple_binary().filter(|_| D::BINARY);
    for i in 0..el.count {
        corners.clear();
        let read = match simple {
            Some(count_ty) => {
                read_face_simple::<D, R>(&mut cx.src, count_ty, vertex_count, &mut corners)
            }
            None => read_face_generic::<D, R>(&mut cx.src, plan, vertex_count, &mut corners),
        };
        match read {
            Ok(()) => {}
            Err(ReadErr::BadIndex(bad)) => return Err(index_error(cx, i, bad, vertex_count)),
            Err(e) => return Err(cx.err(e, || format!("face {i} of {}", el.count))),
        }
        emitter.emit(&corners, visitor, report)?;
    }
    Ok(())
}

/// Triangle strips: each entry a list of vertex indices where -1 restarts the strip;
/// triangle k of a strip is (v[k], v[k+1], v[k+2]), its winding flipped for odd k. The
/// zero-area triangles strips use to turn corners are dropped without a count (they are
/// how strips are made, not defects of the mesh).
fn read_strips<D: Decoder, R: Read>(
    cx: &mut Ctx<'_, R>,
    el: &Element,
    plan: &FacePlan,
    vertex_count: u64,
    visitor: &mut dyn MeshVisitor,
    report: &mut ImportReport,
) -> Result<(), MeshError> {
    for i in 0..el.count {
        let mut run: [u32; 3] = [0; 3];
        let mut len = 0usize;
        for (k, &kind) in plan.props.iter().enumerate() {
            let what = || format!("triangle strip {i} of {}", el.count);
            match kind {
                PropKind::List { count, item } if k == plan.indices => {
                    let (n, at) =
                        list_head::<D, R>(&mut cx.src, count).map_err(|e| cx.err(e, what))?;
                    for _ in 0..n {
                        let x = D::value(&mut cx.src, item)
                            .map_err(past_end(n, at))
                            .map_err(|e| cx.err(e, what))?;
                        if x == -1.0 {
                            len = 0;
                            continue;
                        }
                        let v = match checked_index(x, vertex_count) {
                            Ok(v) => v,
                            Err(ReadErr::BadIndex(bad)) => {
                                return Err(index_error(cx, i, bad, vertex_count))
                            }
                            Err(e) => return Err(cx.err(e, what)),
                        };
                        run = [run[1], run[2], v];
                        len += 1;
                        if len < 3 {
                            continue;
                        }
                        let [a, b, c] = run;
                        if a == b || b == c || a == c {
                            continue;
                        }
                        let t = if len % 2 == 1 { [a, b, c] } else { [b, a, c] };
                        visitor.triangle(t)?;
                        report.triangles += 1;
                    }
                }
                other => skip_prop::<D, R>(&mut cx.src, other).map_err(|e| cx.err(e, what))?,
            }
        }
    }
    Ok(())
}

fn index_error<R: Read>(cx: &Ctx<'_, R>, face: u64, index: i64, vertex_count: u64) -> MeshError {
    MeshError::IndexOutOfRange {
        path: cx.path.to_path_buf(),
        line_or_offset: format!("face {face} ({})", cx.location()),
        index,
        vertex_count,
    }
}

/// Check one index value against the vertex count.
#[inline(always)]
fn checked_index(x: f64, vertex_count: u64) -> Result<u32, ReadErr> {
    // Integral exactly when the truncated value converts back to it (`f64::fract` is a
    // libm call on baseline x86-64; this runs for every corner). `vertex_count` is at
    // most 2^32, so the cast is exact for every index in range.
    if x >= 0.0 && x < vertex_count as f64 && (x as u32) as f64 == x {
        Ok(x as u32)
    } else {
        Err(bad_index(x))
    }
}

/// Why `x` is no vertex index: out of range, or (text files only: binary index lists
/// are integers by their type) not an integer at all, which must not read as "index 0
/// out of range" (what `0.5 as i64` would say).
#[cold]
fn bad_index(x: f64) -> ReadErr {
    if x.is_finite() && x.fract() == 0.0 {
        ReadErr::BadIndex(x as i64)
    } else {
        ReadErr::Parse(format!("vertex index {x} is not an integer"))
    }
}

/// Binary faces made of one short list (count of 1 or 2 bytes) of 4-byte indices:
/// decode the whole list from one borrowed slice.
#[inline(always)]
fn read_face_simple<D: Decoder, R: Read>(
    src: &mut Source<R>,
    (count_ty, item): (Scalar, Scalar),
    vertex_count: u64,
    corners: &mut Vec<u32>,
) -> Result<(), ReadErr> {
    let n = list_len::<D, R>(src, count_ty)?;
    if n > vertex_count {
        // The count is just behind (this path is binary only); found on the cold path.
        let at = src.offset() - count_ty.size() as u64;
        return Err(too_many_corners(n, at, vertex_count));
    }
    let n = n as usize;
    let rec = src.take(4 * n)?;
    for k in 0..n {
        corners.push(checked_index(D::at(rec, 4 * k, item), vertex_count)?);
    }
    Ok(())
}

fn read_face_generic<D: Decoder, R: Read>(
    src: &mut Source<R>,
    plan: &FacePlan,
    vertex_count: u64,
    corners: &mut Vec<u32>,
) -> Result<(), ReadErr> {
    for (k, &kind) in plan.props.iter().enumerate() {
        match kind {
            PropKind::List { count, item } if k == plan.indices => {
                let (n, at) = list_head::<D, R>(src, count)?;
                if n > vertex_count {
                    return Err(too_many_corners(n, at, vertex_count));
                }
                for _ in 0..n {
                    corners.push(checked_index(D::value(src, item)?, vertex_count)?);
                }
            }
            other => skip_prop::<D, R>(src, other)?,
        }
    }
    Ok(())
}
