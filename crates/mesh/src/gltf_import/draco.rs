//! `KHR_draco_mesh_compression`: primitives whose geometry is a Draco stream, decoded
//! with `draco-core` (pure Rust, bit-compatible with Google's Draco decoder: sequential
//! and EdgeBreaker meshes, standard and valence traversals, bitstreams 1.x and 2.x).
//!
//! The extension names a buffer view holding the stream and maps glTF attribute
//! semantics (`POSITION`, `NORMAL`, `TEXCOORD_n`, `COLOR_0`) to the unique ids of Draco
//! attributes; the triangles are the Draco mesh's faces. The primitive's accessors still
//! describe the decoded data (their `type` is checked against the Draco attribute, their
//! `count` against the decoded point count, which the header promised), and an attribute
//! the extension does not map is read from its accessor as usual.
//!
//! A primitive that also carries an uncompressed fallback (every accessor the extension
//! stands for has a buffer view) is read from the fallback, which needs no decoding. A
//! Draco primitive is decoded whole (Draco cannot be decoded in parts) into per-point
//! `f32` arrays, once per mesh for all its instances, and freed before the next mesh.
//! A stream that does not decode is one error naming the primitive and its buffer view.

use ::gltf::json;
use draco_core::{DataType, DecodeLimits, DecoderBuffer, Mesh, MeshDecoder};

use super::container::Views;
use super::Draw;
use crate::MeshError;

/// The extension's name.
pub(super) const DRACO: &str = "KHR_draco_mesh_compression";

/// Decoded attribute bytes allowed per point the POSITION accessor declares (every
/// attribute of the stream counts, used or not: 16 attributes of 4 x 4 bytes), plus
/// [`SLACK_BYTES`]: a ceiling far above any real stream, below what a lying one claims.
const BYTES_PER_POINT: u64 = 256;
const SLACK_BYTES: u64 = 1 << 20;

/// The vertex attributes the importer reads, in [`DracoPrim::ids`] order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    Position = 0,
    Normal = 1,
    Uv = 2,
    Color = 3,
}

/// How a primitive's Draco stream is read.
#[derive(Clone, Debug)]
pub(super) struct DracoPrim {
    /// The buffer view holding the stream.
    pub view: usize,
    /// The Draco unique id of each [`Role`]'s attribute (`None`: read from its accessor).
    pub ids: [Option<u32>; 4],
}

impl DracoPrim {
    pub(super) fn id(&self, role: Role) -> Option<u32> {
        self.ids[role as usize]
    }
}

/// A decoded Draco primitive.
pub(super) struct Decoded {
    /// Decoded points (= the POSITION accessor's count, checked).
    pub points: usize,
    /// Per [`Role`]: components per point and the values, `f32` little-endian, point by
    /// point (normalised integers already mapped to 0..1 or -1..1).
    pub attrs: [Option<(usize, Vec<u8>)>; 4],
    /// The faces' corners, `u32` little-endian, three per face.
    pub indices: Vec<u8>,
}

/// The Draco extension of primitive `prim` (named `name` in messages), if the primitive
/// is to be read from it: `None` without the extension, or when every accessor it
/// stands for has a buffer view (an uncompressed fallback, read instead). `uv_set` is
/// the texture coordinate set the primitive's material reads.
pub(super) fn plan_of(
    path: &std::path::Path,
    root: &json::Root,
    prim: &json::mesh::Primitive,
    name: &str,
    uv_set: u32,
) -> Result<Option<DracoPrim>, MeshError> {
    use json::mesh::Semantic;
    let Some(ext) = prim.extensions.as_ref().and_then(|e| e.others.get(DRACO)) else {
        return Ok(None);
    };
    let bad = |why: String| MeshError::malformed(path, name, format!("{DRACO}: {why}"));
    let view = ext
        .get("bufferView")
        .ok_or_else(|| bad("'bufferView' is missing".into()))?
        .as_u64()
        .and_then(|v| usize::try_from(v).ok())
        .ok_or_else(|| bad("'bufferView' is not a non-negative integer".into()))?;
    let map = ext
        .get("attributes")
        .ok_or_else(|| bad("'attributes' is missing".into()))?
        .as_object()
        .ok_or_else(|| bad("'attributes' is not an object".into()))?;
    let id = |semantic: &str| -> Result<Option<u32>, MeshError> {
        match map.get(semantic) {
            None => Ok(None),
            Some(v) => v
                .as_u64()
                .and_then(|v| u32::try_from(v).ok())
                .map(Some)
                .ok_or_else(|| {
                    bad(format!(
                        "attribute id of {semantic} is not a 32-bit unsigned integer"
                    ))
                }),
        }
    };
    let ids = [
        id("POSITION")?,
        id("NORMAL")?,
        id(&format!("TEXCOORD_{uv_set}"))?,
        id("COLOR_0")?,
    ];
    // The accessors the stream stands for: the mapped attributes and the indices.
    let attr = |s: Semantic| prim.attributes.get(&json::validation::Checked::Valid(s));
    let semantics = [
        Semantic::Positions,
        Semantic::Normals,
        Semantic::TexCoords(uv_set),
        Semantic::Colors(0),
    ];
    let mut covered = semantics
        .into_iter()
        .zip(ids)
        .filter(|(_, id)| id.is_some())
        .filter_map(|(s, _)| attr(s).map(|a| a.value()))
        .chain(prim.indices.map(|i| i.value()));
    let fallback = covered.all(|a| {
        root.accessors
            .get(a)
            .is_some_and(|a| a.buffer_view.is_some())
    });
    if fallback {
        return Ok(None);
    }
    Ok(Some(DracoPrim { view, ids }))
}

/// Decode the Draco stream of draw `d` (whose extension is `dp`).
pub(super) fn decode(views: &Views<'_>, d: &Draw, dp: &DracoPrim) -> Result<Decoded, MeshError> {
    let path = views.path;
    let who = format!("{} ({DRACO}, bufferView {})", d.name, dp.view);
    let bad = |why: String| MeshError::malformed(path, &who, why);
    let (stream, _) = views.get(dp.view)?;
    let declared = views.root.accessors.get(d.position).ok_or_else(|| {
        bad(format!(
            "its POSITION accessor {} does not exist (the file has {} accessors)",
            d.position,
            views.root.accessors.len()
        ))
    })?;
    let points = declared.count.0;
    let limits = DecodeLimits::default().with_max_decoded_bytes(
        points
            .saturating_mul(BYTES_PER_POINT)
            .saturating_add(SLACK_BYTES),
    );
    let mut mesh = Mesh::new();
    // `draco-core` returns an error for every malformed stream it has been fuzzed with
    // (here too: tests/gltf.rs flips bytes of real files); a panic inside it would be
    // its bug, and is turned into this primitive's error rather than ending the import.
    let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut buffer = DecoderBuffer::new(stream).with_limits(limits);
        MeshDecoder::new().decode(&mut buffer, &mut mesh)
    }));
    match decoded {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let e = e.to_string().replace(['\n', '\r'], " ");
            return Err(bad(format!("the Draco stream does not decode ({e})")));
        }
        Err(_) => return Err(bad("the Draco decoder failed on this stream".into())),
    }
    if mesh.num_points() as u64 != points {
        return Err(bad(format!(
            "the Draco stream decodes {} points, its POSITION accessor {} says {points}",
            mesh.num_points(),
            d.position
        )));
    }
    let n = mesh.num_points();
    let mut attrs: [Option<(usize, Vec<u8>)>; 4] = Default::default();
    let uv = format!("TEXCOORD_{}", d.material.uv_set);
    let roles = [
        (Role::Position, "POSITION", Some(d.position)),
        (Role::Normal, "NORMAL", d.normal),
        (Role::Uv, uv.as_str(), d.uv),
        (Role::Color, "COLOR_0", d.color),
    ];
    for (role, semantic, accessor) in roles {
        let (Some(uid), Some(accessor)) = (dp.id(role), accessor) else {
            continue;
        };
        let att = mesh.attribute_by_unique_id(uid).ok_or_else(|| {
            bad(format!(
                "the Draco stream has no attribute with id {uid} (mapped to {semantic})"
            ))
        })?;
        let c = usize::from(att.num_components());
        if !(1..=4).contains(&c) {
            return Err(bad(format!(
                "the Draco attribute {uid} ({semantic}) has {c} components"
            )));
        }
        let mut values = att.read_f32s(n, c);
        // Integers are normalised where the Draco attribute or the accessor says so
        // (glTF readers follow the accessor), and always for colours (glTF's COLOR_0
        // is floating point or normalised).
        let normalized = att.normalized()
            || role == Role::Color
            || views
                .root
                .accessors
                .get(accessor)
                .is_some_and(|a| a.normalized);
        if let Some(max) = normalized.then(|| integer_max(att.data_type())).flatten() {
            let signed = matches!(
                att.data_type(),
                DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64
            );
            for v in &mut values {
                let x = (f64::from(*v) / max) as f32;
                *v = if signed { x.max(-1.0) } else { x };
            }
        }
        attrs[role as usize] = Some((c, values.iter().flat_map(|v| v.to_le_bytes()).collect()));
    }
    let mut indices = Vec::with_capacity(mesh.num_faces() * 12);
    for face in mesh.faces() {
        for p in face {
            indices.extend_from_slice(&p.0.to_le_bytes());
        }
    }
    Ok(Decoded {
        points: n,
        attrs,
        indices,
    })
}

/// The largest value of an integer Draco type, the divisor of its normalised values.
fn integer_max(t: DataType) -> Option<f64> {
    Some(match t {
        DataType::Int8 => f64::from(i8::MAX),
        DataType::Uint8 => f64::from(u8::MAX),
        DataType::Int16 => f64::from(i16::MAX),
        DataType::Uint16 => f64::from(u16::MAX),
        DataType::Int32 => f64::from(i32::MAX),
        DataType::Uint32 => f64::from(u32::MAX),
        DataType::Int64 => i64::MAX as f64,
        DataType::Uint64 => u64::MAX as f64,
        _ => return None,
    })
}
