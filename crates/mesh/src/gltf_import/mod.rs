//! glTF 2.0 importer: `.gltf` (JSON with external `.bin` files or `data:` URIs) and
//! `.glb` (one binary file), streamed into a [`MeshVisitor`] like the PLY, OBJ and STL
//! readers.
//!
//! glTF describes a scene: nodes with transforms that place meshes, each mesh a list of
//! primitives that carry their own vertex arrays (accessors into buffers) and material.
//! Tessera builds one mesh, so the importer flattens the scene:
//!
//! 1. **Plan.** The JSON is parsed (the `gltf` crate's schema types) and checked: the
//!    extensions it requires must be ones we read, the shown scene's nodes are walked
//!    into mesh instances with their world transforms ([`scene`]), and every primitive
//!    of every instance becomes a *draw* (triangle modes) or is counted as ignored
//!    (points, lines). The attributes of the header follow from the draws: normals when
//!    every draw has them (else the builder computes them all), UVs and colours when any
//!    draw has them.
//! 2. **Buffers.** Only the buffers the draws read are opened: the GLB's binary chunk
//!    and external files memory-mapped, `data:` URIs decoded ([`container`]); an external
//!    file is read only where the asset policy allows it ([`crate::AssetPolicy`]: regular
//!    files under the input's folder by default), an image's as a buffer's.
//! 3. **Stream.** Instances are taken mesh by mesh (a mesh's `EXT_meshopt_compression`
//!    views and `KHR_draco_mesh_compression` primitives ([`draco`]) are decoded once for
//!    all its instances); each draw delivers its vertices in chunks of [`CHUNK`]
//!    (position through the world transform, normal through its inverse transpose and
//!    renormalised, UV through the base colour texture's `KHR_texture_transform`,
//!    colour: `COLOR_0` x the material's base colour factor), then its triangles
//!    (lists, strips and fans; a Draco primitive's decoded faces; winding flipped under
//!    a mirroring transform), indices checked against the primitive's vertex count.
//!
//! Memory is bounded by the chunk, the decoded meshopt views and Draco primitives of one
//! mesh, and sparse accessors' substitutes, whatever the size of the buffers.
//!
//! Colours: glTF's `COLOR_0` and `baseColorFactor` are linear; Tessera's colours are
//! displayed as they are (like the sRGB bytes of a PLY), so they are encoded to sRGB.
//!
//! Textures: a primitive whose material has a base colour texture read through
//! `TEXCOORD_0`, in PNG or JPEG, samples it: its vertices carry the index of the
//! texture's [`crate::TextureSource`] (where the image's bytes are, its size from its
//! header, the sampler's wrap modes, the base colour factor as tint), their UVs as the
//! file gives them (through `KHR_texture_transform`) and their colour stays the base
//! colour factor x `COLOR_0`, the fallback ([`texture`]). Textures that are not used
//! (another coordinate set, another image format, a missing or unreadable image) are
//! named in the report and a warning; their vertices are untextured, so a model never
//! turns black or silently wrong.
//!
//! `KHR_draco_mesh_compression` primitives are decoded with `draco-core` (see [`draco`]
//! for what is read and how), through the same transforms, materials, textures and
//! checks as uncompressed ones; a stream that does not decode is an error naming the
//! primitive.

mod accessor;
mod container;
mod draco;
mod material;
mod primitive;
mod scene;
mod texture;

use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::path::Path;

use ::gltf::json;
use json::validation::Checked;

use crate::assets::{folder_of, Assets};
use crate::common::{finish_report, note_ignored, PolygonEmitter};
use crate::ReadOptions;
use crate::{Attributes, ImportReport, MeshError, MeshHeader, MeshVisitor, NO_TEXTURE};
pub(crate) use container::External;
use container::{BufferData, Resolver, Views};
use draco::DracoPrim;
use material::MaterialUse;
use scene::Mat4;

pub(crate) use container::{clip, GLB_MAGIC};

/// Vertices (and triangles) decoded per step: big enough that per-chunk costs vanish,
/// small enough (a few MB of scratch) to keep memory flat.
const CHUNK: usize = 1 << 16;

/// Extensions a file may require (the first [`SUPPORTED_NAMED`] are named in the error
/// for others). The image formats are harmless: textures only in them are not used
/// (their materials are drawn in their base colour, with a warning).
const SUPPORTED_REQUIRED: &[&str] = &[
    "KHR_mesh_quantization",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "KHR_draco_mesh_compression",
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
];

const SUPPORTED_NAMED: usize = 5;

/// Read the `.gltf` or `.glb` file at `path`; external buffers and images are looked up
/// beside it, under `options`' policy.
pub(crate) fn read_gltf(
    path: &Path,
    options: &ReadOptions,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let map = container::map_file(path).map_err(|e| MeshError::io(path, e))?;
    let bytes: &[u8] = map.as_deref().unwrap_or(&[]);
    let assets = Assets::for_input(&options.assets, path)?;
    let external = External {
        dir: folder_of(path),
        assets: &assets,
    };
    read_gltf_from(path, bytes, Some(external), visitor)
}

/// Read a glTF held in `bytes` (a whole `.gltf` or `.glb`); external buffer and image
/// files are resolved by `external`, or refused when it is `None`. `path` names the file
/// in messages.
pub(crate) fn read_gltf_from(
    path: &Path,
    bytes: &[u8],
    external: Option<External<'_>>,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    let parts = container::split(path, bytes)?;
    let root = parse_json(path, &bytes[parts.json.clone()])?;
    check_required(path, &root)?;
    let mut report = ImportReport::default();
    let mut instances = scene::instances(path, &root)?;
    // Mesh by mesh, so each mesh's compressed views are decoded once for its instances.
    instances.sort_by_key(|i| i.mesh);
    let mut draws = plan(path, &root, &instances, &mut report)?;
    let mut textures = texture::Textures::new(path, &root, bytes, parts.bin.clone(), external);
    for d in &mut draws {
        d.texture = textures.of_draw(d, &mut report)?;
    }
    textures.warn(&report);

    // Open the buffers the draws read.
    let resolver = Resolver {
        path,
        external,
        bin: parts.bin.clone(),
    };
    let mut need: Vec<Option<u64>> = vec![None; root.buffers.len()];
    for view in draws.iter().flat_map(|d| d.views(&root)) {
        let (b, end) = container::source_buffer(path, &root, view)?;
        let slot = need.get_mut(b).ok_or_else(|| {
            MeshError::malformed(
                path,
                format!("bufferView {view}"),
                format!(
                    "reads buffer {b}, which does not exist (the file has {} buffers)",
                    root.buffers.len()
                ),
            )
        })?;
        *slot = Some(slot.unwrap_or(0).max(end));
    }
    let buffers = need
        .iter()
        .enumerate()
        .map(|(b, n)| n.map(|n| resolver.load(&root, b, n)).transpose())
        .collect::<Result<Vec<Option<BufferData>>, MeshError>>()?;

    let mut vertex_total: u64 = 0;
    let mut face_estimate: u64 = 0;
    for d in &draws {
        let a = root.accessors.get(d.position).map_or(0, |a| a.count.0);
        vertex_total = vertex_total.saturating_add(a);
        face_estimate = face_estimate.saturating_add(d.face_estimate(&root));
    }
    if vertex_total > u64::from(u32::MAX) {
        return Err(MeshError::TooManyVertices {
            path: path.to_path_buf(),
        });
    }
    let attributes = Attributes {
        normals: !draws.is_empty() && draws.iter().all(|d| d.normal.is_some()),
        uvs: draws.iter().any(|d| d.uv.is_some()),
        colors: draws
            .iter()
            .any(|d| d.color.is_some() || d.material.factor != [1.0; 4]),
        textures: draws.iter().any(|d| {
            d.texture != NO_TEXTURE
                && root
                    .accessors
                    .get(d.position)
                    .is_some_and(|a| a.count.0 > 0)
        }),
    };
    visitor.header(&MeshHeader {
        attributes,
        vertex_count: Some(vertex_total),
        face_count: Some(face_estimate),
    })?;

    let mut decoded = HashMap::new();
    let mut draco_decoded = HashMap::new();
    let mut decoded_for: Option<usize> = None;
    let mut emitter = PolygonEmitter::default();
    let mut base: u64 = 0;
    for d in &draws {
        if decoded_for != Some(d.mesh) {
            // The previous mesh's views are freed before this one's are decoded.
            decoded.clear();
            draco_decoded.clear();
            let mine = draws.iter().filter(|x| x.mesh == d.mesh);
            decoded = decode_meshopt_views(path, &root, bytes, &buffers, mine)?;
            decoded_for = Some(d.mesh);
        }
        let views = Views {
            path,
            root: &root,
            main: bytes,
            buffers: &buffers,
            decoded: &decoded,
        };
        // A Draco primitive is decoded once for all the mesh's instances.
        if let Some(dp) = &d.draco {
            if let Entry::Vacant(e) = draco_decoded.entry(d.primitive) {
                e.insert(draco::decode(&views, d, dp)?);
            }
        }
        let mut sink = primitive::DrawSink {
            emitter: &mut emitter,
            visitor: &mut *visitor,
            report: &mut report,
        };
        let n = primitive::emit_draw(
            &views,
            d,
            d.draco.as_ref().and(draco_decoded.get(&d.primitive)),
            attributes,
            base,
            &mut sink,
        )?;
        base += n;
    }
    finish_report(path, report)
}

/// Decode every `EXT_meshopt_compression` view that `draws` read, by view index.
fn decode_meshopt_views<'a>(
    path: &Path,
    root: &json::Root,
    main: &[u8],
    buffers: &[Option<BufferData>],
    draws: impl Iterator<Item = &'a Draw>,
) -> Result<HashMap<usize, Vec<u8>>, MeshError> {
    let none = HashMap::new();
    let views = Views {
        path,
        root,
        main,
        buffers,
        decoded: &none,
    };
    let mut out = HashMap::new();
    for view in draws.flat_map(|d| d.views(root)) {
        if out.contains_key(&view) {
            continue;
        }
        if let Some(m) = container::meshopt_of(path, root, view)? {
            out.insert(view, views.decode_meshopt(view, &m)?);
        }
    }
    Ok(out)
}

/// Parse the JSON, naming where it is wrong; a glTF 1.0 file is told apart.
fn parse_json(path: &Path, json_bytes: &[u8]) -> Result<json::Root, MeshError> {
    // GLB pads its JSON chunk with spaces; some writers pad with zeros.
    let trimmed = match json_bytes.iter().rposition(|&b| b != 0) {
        Some(end) => &json_bytes[..=end],
        None => &[][..],
    };
    match json::Root::from_slice(trimmed) {
        Ok(root) => {
            let v = &root.asset.version;
            if !v.starts_with("2.") {
                return Err(MeshError::malformed(
                    path,
                    "asset.version",
                    format!("glTF version '{v}'; only glTF 2.x is supported"),
                ));
            }
            Ok(root)
        }
        Err(e) => {
            // glTF 1.0 has a different schema: say so rather than report its first
            // mismatch.
            let version = serde_json::from_slice::<serde_json::Value>(trimmed)
                .ok()
                .and_then(|v| {
                    v.pointer("/asset/version")
                        .and_then(|s| s.as_str().map(str::to_string))
                });
            if let Some(v) = version.filter(|v| !v.starts_with("2.")) {
                return Err(MeshError::malformed(
                    path,
                    "asset.version",
                    format!("glTF version '{v}'; only glTF 2.x is supported"),
                ));
            }
            let what = if e.is_syntax() || e.is_eof() {
                "not valid JSON"
            } else {
                "JSON that is not a glTF 2.0 document"
            };
            Err(MeshError::malformed(
                path,
                format!("JSON line {} column {}", e.line(), e.column()),
                format!("{what}: {e}"),
            ))
        }
    }
}

fn check_required(path: &Path, root: &json::Root) -> Result<(), MeshError> {
    let mut unsupported = Vec::new();
    for ext in &root.extensions_required {
        if !SUPPORTED_REQUIRED.contains(&ext.as_str()) {
            unsupported.push(ext.as_str());
        }
    }
    if !unsupported.is_empty() {
        return Err(MeshError::malformed(
            path,
            "extensionsRequired",
            format!(
                "the file requires the glTF extension{} {}, which Tessera does not support (it reads {})",
                if unsupported.len() > 1 { "s" } else { "" },
                unsupported.join(", "),
                SUPPORTED_REQUIRED[..SUPPORTED_NAMED].join(", ")
            ),
        ));
    }
    Ok(())
}
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Triangles,
    Strip,
    Fan,
}

/// One primitive of one instance, to be delivered.
struct Draw {
    mesh: usize,
    /// Its index in the mesh.
    primitive: usize,
    /// `mesh 0 primitive 1`, for messages.
    name: String,
    mode: Mode,
    world: Mat4,
    position: usize,
    normal: Option<usize>,
    uv: Option<usize>,
    color: Option<usize>,
    indices: Option<usize>,
    material: MaterialUse,
    /// The texture its vertices sample ([`NO_TEXTURE`]: none); only with `uv`.
    texture: u32,
    /// Read from its `KHR_draco_mesh_compression` stream (attributes the stream has,
    /// and the triangles), not from the accessors.
    draco: Option<DracoPrim>,
}

impl Draw {
    /// The accessors whose data it reads (not those the Draco stream stands for).
    fn accessors(&self) -> impl Iterator<Item = usize> + '_ {
        use draco::Role;
        let from_draco = |r: Option<Role>| match (&self.draco, r) {
            (None, _) => false,
            (Some(dp), Some(r)) => dp.id(r).is_some(),
            // The indices.
            (Some(_), None) => true,
        };
        [
            (Some(self.position), Some(Role::Position)),
            (self.normal, Some(Role::Normal)),
            (self.uv, Some(Role::Uv)),
            (self.color, Some(Role::Color)),
            (self.indices, None),
        ]
        .into_iter()
        .filter(move |&(_, r)| !from_draco(r))
        .filter_map(|(a, _)| a)
    }

    /// The buffer views it reads: its accessors' (base data and sparse parts) and its
    /// Draco stream's.
    fn views(&self, root: &json::Root) -> Vec<usize> {
        let mut v: Vec<usize> = self.draco.iter().map(|dp| dp.view).collect();
        for a in self.accessors().filter_map(|a| root.accessors.get(a)) {
            v.extend(a.buffer_view.map(|b| b.value()));
            if let Some(s) = &a.sparse {
                v.push(s.indices.buffer_view.value());
                v.push(s.values.buffer_view.value());
            }
        }
        v
    }

    fn face_estimate(&self, root: &json::Root) -> u64 {
        let n = match self.indices {
            Some(i) => root.accessors.get(i).map_or(0, |a| a.count.0),
            None => root.accessors.get(self.position).map_or(0, |a| a.count.0),
        };
        if self.draco.is_some() {
            // Draco decodes faces, three indices each.
            return n / 3;
        }
        match self.mode {
            Mode::Triangles => n / 3,
            Mode::Strip | Mode::Fan => n.saturating_sub(2),
        }
    }
}

/// Turn the instances' primitives into draws, counting what is skipped.
fn plan(
    path: &Path,
    root: &json::Root,
    instances: &[scene::Instance],
    report: &mut ImportReport,
) -> Result<Vec<Draw>, MeshError> {
    use json::mesh::{Mode as M, Semantic};
    let mut draws = Vec::new();
    for inst in instances {
        let mesh = root.meshes.get(inst.mesh).ok_or_else(|| {
            MeshError::malformed(
                path,
                match inst.node {
                    Some(n) => format!("node {n}"),
                    None => "meshes".to_string(),
                },
                format!(
                    "mesh {} does not exist (the file has {} meshes)",
                    inst.mesh,
                    root.meshes.len()
                ),
            )
        })?;
        if let Some(n) = inst.node.and_then(|n| root.nodes.get(n)) {
            if n.skin.is_some() {
                note_ignored(report, "skin (drawn in its bind pose)", 1);
            }
        }
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let name = format!("mesh {} primitive {p}", inst.mesh);
            let mode = match prim.mode {
                Checked::Valid(M::Triangles) => Mode::Triangles,
                Checked::Valid(M::TriangleStrip) => Mode::Strip,
                Checked::Valid(M::TriangleFan) => Mode::Fan,
                Checked::Valid(other) => {
                    let n = match other {
                        M::Points => "POINTS",
                        M::Lines => "LINES",
                        M::LineLoop => "LINE_LOOP",
                        _ => "LINE_STRIP",
                    };
                    note_ignored(report, &format!("primitive mode {n}"), 1);
                    continue;
                }
                Checked::Invalid => {
                    note_ignored(report, "primitive mode (unknown)", 1);
                    continue;
                }
            };
            let attr = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
            let Some(position) = attr(Semantic::Positions) else {
                note_ignored(report, "primitive without POSITION", 1);
                continue;
            };
            if prim.targets.as_ref().is_some_and(|t| !t.is_empty()) {
                note_ignored(report, "morph targets (base shape used)", 1);
            }
            let material = MaterialUse::of(path, root, prim.material.map(|m| m.value()))?;
            let draco = draco::plan_of(path, root, prim, &name, material.uv_set)?;
            draws.push(Draw {
                mesh: inst.mesh,
                primitive: p,
                name,
                mode,
                world: inst.world,
                position,
                normal: attr(Semantic::Normals),
                uv: attr(Semantic::TexCoords(material.uv_set)),
                color: attr(Semantic::Colors(0)),
                indices: prim.indices.map(|i| i.value()),
                material,
                texture: NO_TEXTURE,
                draco,
            });
        }
    }
    Ok(draws)
}
