//! glTF accessors: typed arrays over buffer views (strided, of any numeric component
//! type, optionally normalised, optionally patched by a sparse substitution), read in
//! chunks so a primitive of any size is decoded in bounded memory.
//!
//! Every range an accessor implies is checked once, when it is opened, with checked
//! arithmetic: after [`Accessor::open`] the reads cannot go out of bounds.

use ::gltf::json;
use json::accessor::ComponentType;
use json::validation::Checked;

use super::container::Views;
use crate::MeshError;

/// Zero bytes standing in for the elements of an accessor without a buffer view (the
/// specification says they are zeros): the largest element we read is 4 x 4 bytes.
const ZEROS: [u8; 16] = [0; 16];

/// The sparse substitution of an accessor: element `index` takes value `slot`.
struct Sparse<'a> {
    /// (element index, value slot), sorted by element index.
    entries: Vec<(u32, u32)>,
    /// Tightly packed values.
    values: &'a [u8],
}

/// An opened accessor whose every element is known to lie inside its buffer view.
pub(crate) struct Accessor<'a> {
    /// `accessor 3 (POSITION)`, for messages.
    pub name: String,
    pub count: usize,
    pub components: usize,
    kind: ComponentType,
    normalized: bool,
    elem_size: usize,
    /// Bytes from the first element, and the stride between elements.
    data: Option<(&'a [u8], usize)>,
    sparse: Option<Sparse<'a>>,
}

fn component_name(kind: ComponentType) -> &'static str {
    match kind {
        ComponentType::I8 => "BYTE",
        ComponentType::U8 => "UNSIGNED_BYTE",
        ComponentType::I16 => "SHORT",
        ComponentType::U16 => "UNSIGNED_SHORT",
        ComponentType::U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    }
}

impl<'a> Accessor<'a> {
    /// Open accessor `index`, read as `what` (`POSITION`, `indices`, ...), whose type must
    /// have one of `components` components (1 = SCALAR, ..., 4 = VEC4).
    pub(crate) fn open(
        views: &Views<'a>,
        index: usize,
        what: &str,
        components: &[usize],
    ) -> Result<Accessor<'a>, MeshError> {
        let path = views.path;
        let name = format!("accessor {index} ({what})");
        let bad = |why: String| MeshError::malformed(path, &name, why);
        let (a, kind, n) = typed(views, index, what, components, &name)?;
        let count = usize::try_from(a.count.0).map_err(|_| bad("count is too large".into()))?;
        let elem_size = kind.size() * n;
        let data = match a.buffer_view {
            None => None,
            Some(v) => {
                let (bytes, stride) = views.get(v.value())?;
                let stride = stride.unwrap_or(elem_size);
                if stride < elem_size {
                    return Err(bad(format!(
                        "byteStride {stride} is smaller than its element ({elem_size} bytes)"
                    )));
                }
                let offset = a.byte_offset.map_or(0, |o| o.0);
                let need = (count as u64)
                    .checked_sub(1)
                    .map(|last| {
                        last.checked_mul(stride as u64)
                            .and_then(|x| x.checked_add(elem_size as u64))
                            .and_then(|x| x.checked_add(offset))
                    })
                    .unwrap_or(Some(0));
                match need {
                    Some(need) if need <= bytes.len() as u64 => {}
                    _ => {
                        return Err(MeshError::truncated(
                            path,
                            format!(
                                "{name}: {count} elements of {elem_size} bytes (stride {stride}, offset {offset}) need {} bytes, bufferView {} has {}",
                                need.map_or_else(|| "more than 2^64".to_string(), |x| x.to_string()),
                                v.value(),
                                bytes.len()
                            ),
                        ))
                    }
                }
                let start = (offset as usize).min(bytes.len());
                Some((&bytes[start..], stride))
            }
        };
        let sparse = match &a.sparse {
            None => None,
            Some(s) => Some(open_sparse(views, &name, s, count, elem_size)?),
        };
        Ok(Accessor {
            name,
            count,
            components: n,
            kind,
            normalized: a.normalized,
            elem_size,
            data,
            sparse,
        })
    }

    /// Accessor `index`, read as `what` with one of `components` components, whose
    /// values were decoded from a `KHR_draco_mesh_compression` stream: `count` elements
    /// of `value_components` little-endian `f32`s in `values`, which must agree with the
    /// accessor's type.
    pub(crate) fn decoded(
        views: &Views<'a>,
        index: usize,
        what: &str,
        components: &[usize],
        (value_components, values): (usize, &'a [u8]),
        count: usize,
    ) -> Result<Accessor<'a>, MeshError> {
        let name = format!("accessor {index} ({what}, from KHR_draco_mesh_compression)");
        let (_, _, n) = typed(views, index, what, components, &name)?;
        if n != value_components {
            return Err(MeshError::malformed(
                views.path,
                &name,
                format!(
                    "has type {}, its Draco attribute has {value_components} components",
                    type_name(n)
                ),
            ));
        }
        Ok(Accessor::packed(name, values, count, n, ComponentType::F32))
    }

    /// Triangle corners decoded from a `KHR_draco_mesh_compression` stream: little-endian
    /// `u32`s in `values`, read as an index accessor named `name`.
    pub(crate) fn decoded_indices(name: String, values: &'a [u8]) -> Accessor<'a> {
        Accessor::packed(name, values, values.len() / 4, 1, ComponentType::U32)
    }

    /// Tightly packed elements of `components` x `kind` (4-byte kinds only).
    fn packed(
        name: String,
        values: &'a [u8],
        count: usize,
        components: usize,
        kind: ComponentType,
    ) -> Accessor<'a> {
        let elem_size = 4 * components;
        // The decoder wrote exactly `count` elements; fewer bytes would be our bug, and
        // are read as fewer elements rather than out of bounds.
        debug_assert!(values.len() >= count * elem_size);
        let count = count.min(values.len() / elem_size.max(1));
        Accessor {
            name,
            count,
            components,
            kind,
            normalized: false,
            elem_size,
            data: Some((values, elem_size)),
            sparse: None,
        }
    }

    /// Call `f(k, bytes)` for elements `start + k`, `k < n`, with each element's bytes
    /// (sparse substitutes after the base values, so theirs win). `start + n <= count`.
    fn for_range(&self, start: usize, n: usize, mut f: impl FnMut(usize, &[u8])) {
        let e = self.elem_size;
        match self.data {
            Some((bytes, stride)) => {
                for k in 0..n {
                    let at = (start + k) * stride;
                    f(k, &bytes[at..at + e]);
                }
            }
            None => (0..n).for_each(|k| f(k, &ZEROS[..e])),
        }
        if let Some(s) = &self.sparse {
            let from = s.entries.partition_point(|&(i, _)| (i as usize) < start);
            for &(i, slot) in &s.entries[from..] {
                let i = i as usize;
                if i >= start + n {
                    break;
                }
                let at = slot as usize * e;
                f(i - start, &s.values[at..at + e]);
            }
        }
    }

    /// Elements `start..start + n` as floats (normalised integers mapped to 0..1 or
    /// -1..1, other integers as they are), components past the accessor's set to `fill`.
    pub(crate) fn read_f32(&self, start: usize, n: usize, fill: f32, out: &mut Vec<[f32; 4]>) {
        out.clear();
        out.resize(n, [fill; 4]);
        let c = self.components;
        let norm = self.normalized;
        macro_rules! run {
            ($size:expr, $conv:expr) => {
                self.for_range(start, n, |k, b| {
                    let o = &mut out[k];
                    for j in 0..c {
                        let v: [u8; $size] = b[j * $size..(j + 1) * $size]
                            .try_into()
                            .unwrap_or([0; $size]);
                        o[j] = $conv(v);
                    }
                })
            };
        }
        match self.kind {
            ComponentType::F32 => run!(4, f32::from_le_bytes),
            ComponentType::U8 if norm => run!(1, |v: [u8; 1]| v[0] as f32 / 255.0),
            ComponentType::U8 => run!(1, |v: [u8; 1]| v[0] as f32),
            ComponentType::I8 if norm => {
                run!(1, |v: [u8; 1]| (v[0] as i8 as f32 / 127.0).max(-1.0))
            }
            ComponentType::I8 => run!(1, |v: [u8; 1]| v[0] as i8 as f32),
            ComponentType::U16 if norm => run!(2, |v| u16::from_le_bytes(v) as f32 / 65535.0),
            ComponentType::U16 => run!(2, |v| u16::from_le_bytes(v) as f32),
            ComponentType::I16 if norm => {
                run!(2, |v| (i16::from_le_bytes(v) as f32 / 32767.0).max(-1.0))
            }
            ComponentType::I16 => run!(2, |v| i16::from_le_bytes(v) as f32),
            ComponentType::U32 if norm => run!(4, |v| (u32::from_le_bytes(v) as f64
                / u32::MAX as f64) as f32),
            ComponentType::U32 => run!(4, |v| u32::from_le_bytes(v) as f32),
        }
    }

    /// Elements `start..start + n` of an index accessor (SCALAR, unsigned integers).
    pub(crate) fn read_indices(&self, start: usize, n: usize, out: &mut Vec<u32>) {
        out.clear();
        out.resize(n, 0);
        match self.kind {
            ComponentType::U8 | ComponentType::I8 => {
                self.for_range(start, n, |k, b| out[k] = u32::from(b[0]))
            }
            ComponentType::U16 | ComponentType::I16 => self.for_range(start, n, |k, b| {
                out[k] = u32::from(u16::from_le_bytes([b[0], b[1]]))
            }),
            ComponentType::U32 | ComponentType::F32 => self.for_range(start, n, |k, b| {
                out[k] = u32::from_le_bytes([b[0], b[1], b[2], b[3]])
            }),
        }
    }

    /// Check this is usable as an index accessor (unsigned integer components).
    pub(crate) fn check_index_type(&self, views: &Views<'_>) -> Result<(), MeshError> {
        match self.kind {
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32 => Ok(()),
            other => Err(MeshError::malformed(
                views.path,
                &self.name,
                format!(
                    "componentType {}; indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT",
                    component_name(other)
                ),
            )),
        }
    }

    /// The component type is floating point or normalised (for COLOR_0, which must be).
    pub(crate) fn is_float_or_normalized(&self) -> bool {
        self.kind == ComponentType::F32 || self.normalized
    }
}

/// Accessor `index` of the document, its component type and its number of components,
/// which must be one of `components` for it to be read as `what` (`name` in messages).
fn typed<'r>(
    views: &Views<'r>,
    index: usize,
    what: &str,
    components: &[usize],
    name: &str,
) -> Result<(&'r json::Accessor, ComponentType, usize), MeshError> {
    let bad = |why: String| MeshError::malformed(views.path, name, why);
    let a = views.root.accessors.get(index).ok_or_else(|| {
        bad(format!(
            "does not exist (the file has {} accessors)",
            views.root.accessors.len()
        ))
    })?;
    let Checked::Valid(kind) = a.component_type else {
        return Err(bad("unknown componentType".into()));
    };
    let n = match a.type_ {
        Checked::Valid(json::accessor::Type::Scalar) => 1,
        Checked::Valid(json::accessor::Type::Vec2) => 2,
        Checked::Valid(json::accessor::Type::Vec3) => 3,
        Checked::Valid(json::accessor::Type::Vec4) => 4,
        Checked::Valid(_) => 0,
        Checked::Invalid => return Err(bad("unknown type".into())),
    };
    if !components.contains(&n) {
        let want: Vec<String> = components.iter().map(|c| type_name(*c)).collect();
        return Err(bad(format!(
            "has type {}, {what} must be {}",
            if n == 0 {
                "MAT*".to_string()
            } else {
                type_name(n)
            },
            want.join(" or ")
        )));
    }
    Ok((a, kind.0, n))
}

fn type_name(n: usize) -> String {
    match n {
        1 => "SCALAR".into(),
        n => format!("VEC{n}"),
    }
}

fn open_sparse<'a>(
    views: &Views<'a>,
    name: &str,
    s: &json::accessor::sparse::Sparse,
    count: usize,
    elem_size: usize,
) -> Result<Sparse<'a>, MeshError> {
    let path = views.path;
    let bad = |why: String| MeshError::malformed(path, name, format!("sparse: {why}"));
    let n = usize::try_from(s.count.0).map_err(|_| bad("count is too large".into()))?;
    if n > count {
        return Err(bad(format!("{n} substitutes for {count} elements")));
    }
    let Checked::Valid(ikind) = s.indices.component_type else {
        return Err(bad("unknown indices componentType".into()));
    };
    let isize = ikind.0.size();
    if !matches!(
        ikind.0,
        ComponentType::U8 | ComponentType::U16 | ComponentType::U32
    ) {
        return Err(bad("indices must be unsigned integers".into()));
    }
    let part = |view: usize, offset: u64, size: usize, what: &str| -> Result<&'a [u8], MeshError> {
        let (bytes, _) = views.get(view)?;
        let end = (n as u64)
            .checked_mul(size as u64)
            .and_then(|x| x.checked_add(offset));
        match end {
            Some(end) if end <= bytes.len() as u64 => Ok(&bytes[offset as usize..end as usize]),
            _ => Err(MeshError::truncated(
                path,
                format!(
                    "{name}: sparse {what}: {n} x {size} bytes at offset {offset} do not fit in bufferView {view} ({} bytes)",
                    bytes.len()
                ),
            )),
        }
    };
    let ibytes = part(
        s.indices.buffer_view.value(),
        s.indices.byte_offset.0,
        isize,
        "indices",
    )?;
    let values = part(
        s.values.buffer_view.value(),
        s.values.byte_offset.0,
        elem_size,
        "values",
    )?;
    let mut entries = Vec::with_capacity(n);
    for (slot, b) in ibytes.chunks_exact(isize).enumerate() {
        let i = match isize {
            1 => u32::from(b[0]),
            2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        };
        if i as usize >= count {
            return Err(bad(format!(
                "index {i} at position {slot} is out of range (the accessor has {count} elements)"
            )));
        }
        entries.push((i, slot as u32));
    }
    // The specification wants increasing indices; a stable sort keeps the last of
    // repeated ones last, so it wins, as in a reader that applies them in order.
    entries.sort_by_key(|&(i, _)| i);
    Ok(Sparse { entries, values })
}
