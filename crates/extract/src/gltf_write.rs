//! A cut written as glTF 2.0: `.glb` (one binary file) or `.gltf` (JSON with the buffer
//! embedded as a `data:` URI), for MeshLab, Blender and any glTF viewer.
//!
//! What the file holds ([`write_cut_gltf`]):
//!
//! - One scene, one node (no transform), one mesh. Positions are model coordinates
//!   (grid points through the model's [`Grid`], as the PLY writer writes them) as `f32`,
//!   with the `min`/`max` glTF requires; `NORMAL` when the model has normals; indices
//!   `u16` when the primitive has at most 65,535 vertices, else `u32`.
//! - **Untextured** model ([`GltfContent::Welded`]): one primitive, the welded cut of
//!   `tessera_select::merge_patches` (the same mesh the PLY gets), with
//!   `COLOR_0` (`FLOAT` RGBA, linear: Tessera's colour bytes are sRGB like a PLY's,
//!   glTF's vertex colours are linear, so each byte is decoded exactly; a glTF importer
//!   that re-encodes them gets the bytes back) when the model has colours, and the
//!   source texture coordinates as `TEXCOORD_0` when it has UVs without textures.
//! - **Textured** model ([`GltfContent::Textured`]): one primitive per patch with
//!   triangles, each with its own material whose `baseColorTexture` is that patch's
//!   texture (PNG, lossless re-encoding of the decoded texels; sampler clamp-to-edge,
//!   linear magnification, trilinear minification) and `TEXCOORD_0` = each vertex's
//!   coordinate in the patch texture (`charts[chart_id].map(uv)`: normalised, origin at
//!   the top-left, v down, as glTF wants). Patches are not welded to one another: their
//!   shared border vertices sample different textures. No `COLOR_0` (the patch
//!   textures already hold the untextured vertices' colours, in solid-colour charts).
//! - Materials are `metallicFactor` 0, `roughnessFactor` 1 (a scan is not metal; the
//!   glTF default metallic 1 renders it dark), opaque, single-sided.
//!
//! - Frames ([`GltfFrame`]): `tessera extract` writes model coordinates as they are;
//!   3D Tiles content (`tessera-tiles`, through [`encode_gltf`]) writes positions
//!   relative to the tile's centre, the node translated to it, and the axes turned to
//!   glTF's +Y up. Stored PNG and JPEG patch textures go in as they are when the patch
//!   was decoded without its texels.
//!
//! The whole file is assembled in memory (cuts are small: the model itself is never
//! held) and written through [`AtomicFile`]: nothing appears at the path unless the
//! whole file was written. The bytes depend only on the cut (no time stamps), so local
//! and remote extracts of one model are identical.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use ::gltf::json;
use base64::Engine as _;
use json::validation::{Checked::Valid, USize64};
use tessera_format::{AtomicFile, FormatError, Grid, PatchData, PatchTexture, TextureCodec};

use tessera_select::CutMesh;

/// Which glTF container to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GltfContainer {
    /// `.glb`: the JSON and one binary chunk (buffer and PNG images) in one file.
    Binary,
    /// `.gltf`: JSON text; the buffer (images included, through buffer views) is one
    /// base64 `data:` URI, so the file is self-contained (about a third larger than the
    /// `.glb`).
    Embedded,
}

impl GltfContainer {
    /// The container a path's extension asks for (`.glb` or `.gltf`, any case).
    pub fn of_path(path: &Path) -> Option<GltfContainer> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "glb" => Some(GltfContainer::Binary),
            "gltf" => Some(GltfContainer::Embedded),
            _ => None,
        }
    }
}

/// What to write.
pub enum GltfContent<'a> {
    /// An untextured model's welded cut: one primitive.
    Welded(&'a CutMesh),
    /// A textured model's cut: its decoded patches (node index, patch), one primitive
    /// and one material per patch with triangles. Each such patch must carry its
    /// texture's `rgba` (as [`tessera_format::decode_patch`] gives it), UVs and charts.
    Textured(&'a [(u32, &'a PatchData)]),
}

/// What was written.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GltfSummary {
    /// Bytes of the file.
    pub bytes: u64,
    /// Primitives (= materials for a textured cut).
    pub primitives: usize,
    /// Patch textures written (0 for an untextured cut).
    pub textures: usize,
    /// Bytes of the PNG images among `bytes`.
    pub texture_bytes: u64,
}

/// Writes a cut as glTF 2.0 at `path` (see the module documentation), atomically.
/// `name` names the scene and its node (e.g. the model and the cut). An empty cut gives
/// a valid file with an empty scene-less asset.
///
/// Errors: I/O (naming the file), a patch texture that does not encode, a textured
/// patch without its decoded texels or charts, a file over glTF's 4 GiB.
pub fn write_cut_gltf(
    grid: &Grid,
    content: GltfContent<'_>,
    path: &Path,
    container: GltfContainer,
    name: &str,
) -> Result<GltfSummary, FormatError> {
    let (bytes, summary) = encode_gltf(grid, content, &GltfFrame::MODEL, container, name)?;
    let mut f = AtomicFile::create(path, 1 << 20)?;
    f.write_all(&bytes)
        .map_err(|e| FormatError::io(f.tmp_path(), e))?;
    f.commit()?;
    Ok(summary)
}

/// Where the glTF's coordinates are: model coordinates minus `origin`, turned to glTF's
/// +Y up when `y_up`, and the scene's one node translated by `translation` (model
/// axes, written in the glTF's). Small coordinates keep `f32` precision on
/// georeferenced models: 3D Tiles content ([`GltfFrame::tile`]) has each tile's centre
/// as `origin` and that centre relative to the tileset's own origin as `translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfFrame {
    /// Model-space point subtracted from every position (in f64) before it is rounded
    /// to `f32`.
    pub origin: [f64; 3],
    /// Model axes are +Z up (3D Tiles' convention): write `(x, z, -y)` for the model's
    /// `(x, y, z)` (positions, normals, the translation), the inverse of the Y-up to
    /// Z-up rotation 3D Tiles clients apply to glTF content, so that the tileset sees
    /// model axes.
    pub y_up: bool,
    /// The node's translation, model axes (none when zero).
    pub translation: [f64; 3],
}

impl GltfFrame {
    /// Model coordinates as they are (`tessera extract`): no offset, no rotation.
    pub const MODEL: GltfFrame = GltfFrame {
        origin: [0.0; 3],
        y_up: false,
        translation: [0.0; 3],
    };

    /// 3D Tiles content of a tile centred at `centre` (model coordinates) in a tileset
    /// whose coordinates are model coordinates minus `tileset_origin`: positions
    /// relative to the centre, the node translated by `centre - tileset_origin`, axes
    /// turned to glTF's +Y up.
    pub fn tile(centre: [f64; 3], tileset_origin: [f64; 3]) -> GltfFrame {
        GltfFrame {
            origin: centre,
            y_up: true,
            translation: [0, 1, 2].map(|k| centre[k] - tileset_origin[k]),
        }
    }

    /// A model-space vector in the glTF's axes.
    pub fn axes(&self, v: [f64; 3]) -> [f64; 3] {
        if self.y_up {
            [v[0], v[2], -v[1]]
        } else {
            v
        }
    }
}

/// [`write_cut_gltf`]'s document as bytes, in `frame` (not written anywhere): what a
/// caller that writes many files (3D Tiles export) encodes in parallel. Errors name the
/// node; the file they go to is the caller's to name.
pub fn encode_gltf(
    grid: &Grid,
    content: GltfContent<'_>,
    frame: &GltfFrame,
    container: GltfContainer,
    name: &str,
) -> Result<(Vec<u8>, GltfSummary), FormatError> {
    let mut doc = Doc::new();
    let mut summary = GltfSummary::default();
    let mut primitives = Vec::new();
    match content {
        GltfContent::Welded(mesh) => {
            if mesh.triangle_count() > 0 {
                let colors: Vec<[f32; 4]> = mesh.colors.iter().map(|&c| linear_rgba(c)).collect();
                let material = doc.material(name.to_string(), None);
                primitives.push(doc.primitive(
                    grid,
                    frame,
                    &mesh.positions,
                    &mesh.normals,
                    &mesh.uvs,
                    &colors,
                    &mesh.indices,
                    material,
                ));
            }
        }
        GltfContent::Textured(patches) => {
            let sampler = doc.root.push(json::texture::Sampler {
                mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
                min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
                name: None,
                wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
                wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
                extensions: Default::default(),
                extras: Default::default(),
            });
            for &(node, p) in patches {
                if p.triangle_count() == 0 {
                    continue;
                }
                let bad = |what: &str| FormatError::InvalidInput {
                    detail: format!(
                        "node {node}: a textured patch {what} (decode it with decode_patch)"
                    ),
                };
                let t = p.texture.as_ref().ok_or_else(|| bad("has no texture"))?;
                let (image, mime) = texture_image(t).map_err(|e| e.with_node(node))?;
                let image = image.ok_or_else(|| bad("has no decoded texels"))?;
                if p.uvs.len() != p.positions.len() || p.chart_ids.len() != p.positions.len() {
                    return Err(bad("lacks UVs or chart ids"));
                }
                let uvs = p
                    .uvs
                    .iter()
                    .zip(&p.chart_ids)
                    .map(|(&uv, &c)| {
                        p.charts
                            .get(c as usize)
                            .map(|ch| ch.map(uv))
                            .ok_or_else(|| bad("has a chart id out of range"))
                    })
                    .collect::<Result<Vec<[f32; 2]>, FormatError>>()?;
                summary.texture_bytes += image.len() as u64;
                summary.textures += 1;
                let view = doc.view(&image, None);
                let image = doc.root.push(json::Image {
                    buffer_view: Some(view),
                    mime_type: Some(json::image::MimeType(mime.into())),
                    name: Some(format!("node {node}")),
                    uri: None,
                    extensions: Default::default(),
                    extras: Default::default(),
                });
                let texture = doc.root.push(json::Texture {
                    name: Some(format!("node {node}")),
                    sampler: Some(sampler),
                    source: image,
                    extensions: Default::default(),
                    extras: Default::default(),
                });
                let material = doc.material(format!("node {node}"), Some(texture));
                primitives.push(doc.primitive(
                    grid,
                    frame,
                    &p.positions,
                    &p.normals,
                    &uvs,
                    &[],
                    &p.indices,
                    material,
                ));
            }
        }
    }
    summary.primitives = primitives.len();
    if !primitives.is_empty() {
        let mesh = doc.root.push(json::Mesh {
            name: Some(name.to_string()),
            primitives,
            weights: None,
            extensions: Default::default(),
            extras: Default::default(),
        });
        let t = frame.axes(frame.translation);
        let node = doc.root.push(json::Node {
            mesh: Some(mesh),
            name: Some(name.to_string()),
            translation: (t != [0.0; 3]).then(|| t.map(|x| x as f32)),
            ..Default::default()
        });
        let scene = doc.root.push(json::Scene {
            name: Some(name.to_string()),
            nodes: vec![node],
            extensions: Default::default(),
            extras: Default::default(),
        });
        doc.root.scene = Some(scene);
    }
    let bytes = doc.finish(container)?;
    summary.bytes = bytes.len() as u64;
    Ok((bytes, summary))
}

/// A patch texture as a glTF image and its MIME type: a stored PNG or JPEG as it is
/// (when the patch was decoded without its texels, `decode_patch_with(.., false)`),
/// otherwise its decoded texels (decoded here from BC7 when they are not) re-encoded as
/// PNG, losslessly. `None` when it has neither.
fn texture_image(t: &PatchTexture) -> Result<(Option<Vec<u8>>, &'static str), FormatError> {
    match t.codec {
        Some(TextureCodec::Png) if !t.encoded.is_empty() => {
            return Ok((Some(t.encoded.clone()), "image/png"))
        }
        Some(TextureCodec::Jpeg) if !t.encoded.is_empty() => {
            return Ok((Some(t.encoded.clone()), "image/jpeg"))
        }
        _ => {}
    }
    // BC7 textures come as blocks or still encoded: their texels for the PNG.
    let decoded;
    let t = if t.rgba.is_empty() && (!t.blocks.is_empty() || !t.encoded.is_empty()) {
        let mut d = PatchTexture {
            rgba: Vec::new(),
            mips: Vec::new(),
            ..t.clone()
        };
        d.decode_rgba()?;
        decoded = d;
        &decoded
    } else {
        t
    };
    let texels = 4 * t.width as usize * t.height as usize;
    if t.rgba.len() != texels || texels == 0 {
        return Ok((None, "image/png"));
    }
    let png = PatchTexture::encode(t.width, t.height, &t.rgba, TextureCodec::Png, 100)?.encoded;
    Ok((Some(png), "image/png"))
}

/// An sRGB colour byte as glTF's linear value (alpha is linear coverage, kept).
pub fn linear_rgba(c: [u8; 4]) -> [f32; 4] {
    let lin = |b: u8| {
        let s = f64::from(b) / 255.0;
        (if s <= 0.040_45 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }) as f32
    };
    [lin(c[0]), lin(c[1]), lin(c[2]), f32::from(c[3]) / 255.0]
}

/// The document being assembled: the JSON and the one binary buffer.
struct Doc {
    root: json::Root,
    bin: Vec<u8>,
}

impl Doc {
    fn new() -> Doc {
        Doc {
            root: json::Root {
                asset: json::Asset {
                    generator: Some(format!("tessera extract {}", env!("CARGO_PKG_VERSION"))),
                    ..Default::default()
                },
                ..Default::default()
            },
            bin: Vec::new(),
        }
    }

    /// A buffer view of `bytes` (appended to the buffer at a 4-byte boundary).
    fn view(
        &mut self,
        bytes: &[u8],
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: Default::default(),
            extras: Default::default(),
        })
    }

    /// An accessor of `count` tightly packed elements in a new view of `bytes`.
    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        bytes: &[u8],
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        target: json::buffer::Target,
        bounds: Option<([f32; 3], [f32; 3])>,
    ) -> json::Index<json::Accessor> {
        let view = self.view(bytes, Some(target));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            type_: Valid(type_),
            min: bounds.map(|(lo, _)| json::Value::from(lo.to_vec())),
            max: bounds.map(|(_, hi)| json::Value::from(hi.to_vec())),
            name: None,
            normalized: false,
            sparse: None,
            extensions: Default::default(),
            extras: Default::default(),
        })
    }

    /// A non-metallic, fully rough material, textured by `texture` when given.
    fn material(
        &mut self,
        name: String,
        texture: Option<json::Index<json::Texture>>,
    ) -> json::Index<json::Material> {
        self.root.push(json::Material {
            name: Some(name),
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_texture: texture.map(|index| json::texture::Info {
                    index,
                    tex_coord: 0,
                    extensions: Default::default(),
                    extras: Default::default(),
                }),
                metallic_factor: json::material::StrengthFactor(0.0),
                roughness_factor: json::material::StrengthFactor(1.0),
                ..Default::default()
            },
            ..Default::default()
        })
    }

    /// A triangle primitive; attribute slices are empty or one per position.
    #[allow(clippy::too_many_arguments)]
    fn primitive(
        &mut self,
        grid: &Grid,
        frame: &GltfFrame,
        positions: &[[u32; 3]],
        normals: &[[f32; 3]],
        uvs: &[[f32; 2]],
        colors: &[[f32; 4]],
        indices: &[u32],
        material: json::Index<json::Material>,
    ) -> json::mesh::Primitive {
        use json::accessor::{ComponentType as C, Type as T};
        use json::buffer::Target::{ArrayBuffer, ElementArrayBuffer};
        use json::mesh::Semantic as S;
        let n = positions.len();
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        let mut bytes = Vec::with_capacity(12 * n);
        for &q in positions {
            let m = grid.position(q);
            let p = frame
                .axes([0, 1, 2].map(|k| m[k] - frame.origin[k]))
                .map(|x| x as f32);
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
                bytes.extend_from_slice(&p[k].to_le_bytes());
            }
        }
        let mut attributes = BTreeMap::new();
        let pos = self.accessor(&bytes, n, C::F32, T::Vec3, ArrayBuffer, Some((lo, hi)));
        attributes.insert(Valid(S::Positions), pos);
        if normals.len() == n && n > 0 {
            let turned: Vec<[f32; 3]>;
            let normals = if frame.y_up {
                turned = normals.iter().map(|&[x, y, z]| [x, z, -y]).collect();
                &turned[..]
            } else {
                normals
            };
            let bytes = f32_bytes(normals.iter().flatten());
            let a = self.accessor(&bytes, n, C::F32, T::Vec3, ArrayBuffer, None);
            attributes.insert(Valid(S::Normals), a);
        }
        if uvs.len() == n && n > 0 {
            let bytes = f32_bytes(uvs.iter().flatten());
            let a = self.accessor(&bytes, n, C::F32, T::Vec2, ArrayBuffer, None);
            attributes.insert(Valid(S::TexCoords(0)), a);
        }
        if colors.len() == n && n > 0 {
            let bytes = f32_bytes(colors.iter().flatten());
            let a = self.accessor(&bytes, n, C::F32, T::Vec4, ArrayBuffer, None);
            attributes.insert(Valid(S::Colors(0)), a);
        }
        // 16-bit indices where they fit (patches mostly do): half the index bytes.
        let (bytes, component): (Vec<u8>, _) = if n <= usize::from(u16::MAX) {
            let b = indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            (b, C::U16)
        } else {
            (
                indices.iter().flat_map(|i| i.to_le_bytes()).collect(),
                C::U32,
            )
        };
        let ind = self.accessor(
            &bytes,
            indices.len(),
            component,
            T::Scalar,
            ElementArrayBuffer,
            None,
        );
        json::mesh::Primitive {
            attributes,
            indices: Some(ind),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
            extensions: Default::default(),
            extras: Default::default(),
        }
    }

    /// The file's bytes.
    fn finish(mut self, container: GltfContainer) -> Result<Vec<u8>, FormatError> {
        let io = |detail: String| FormatError::InvalidInput { detail };
        // The buffer a whole number of words (16-bit indices can end it mid-word), so
        // the .glb's chunk and the .gltf's buffer are the same bytes.
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        if !self.bin.is_empty() {
            self.root.buffers.push(json::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: match container {
                    GltfContainer::Binary => None,
                    GltfContainer::Embedded => Some(format!(
                        "data:application/octet-stream;base64,{}",
                        base64::engine::general_purpose::STANDARD.encode(&self.bin)
                    )),
                },
                extensions: Default::default(),
                extras: Default::default(),
            });
        }
        let bytes: Vec<u8> = match container {
            GltfContainer::Binary => {
                let json = self.root.to_vec().map_err(|e| io(e.to_string()))?;
                let pad4 = |n: usize| n.div_ceil(4) * 4;
                let total = 12
                    + 8
                    + pad4(json.len())
                    + if self.bin.is_empty() {
                        0
                    } else {
                        8 + pad4(self.bin.len())
                    };
                let length = u32::try_from(total).map_err(|_| {
                    io(format!(
                        "{total} bytes: a .glb holds at most 4 GiB (write a smaller cut)"
                    ))
                })?;
                let glb = ::gltf::binary::Glb {
                    header: ::gltf::binary::Header {
                        magic: *b"glTF",
                        version: 2,
                        length,
                    },
                    json: Cow::Owned(json),
                    bin: (!self.bin.is_empty()).then(|| Cow::Borrowed(&self.bin[..])),
                };
                let mut out = Vec::with_capacity(total);
                glb.to_writer(&mut out).map_err(|e| io(e.to_string()))?;
                out
            }
            GltfContainer::Embedded => {
                let mut json = self.root.to_vec_pretty().map_err(|e| io(e.to_string()))?;
                json.push(b'\n');
                json
            }
        };
        Ok(bytes)
    }
}

fn f32_bytes<'a>(values: impl Iterator<Item = &'a f32>) -> Vec<u8> {
    values.flat_map(|x| x.to_le_bytes()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The glTF importer's encoding (tessera-mesh `srgb8`), in f32 as it computes it.
    fn srgb8(linear: f32) -> u8 {
        let x = linear.clamp(0.0, 1.0);
        let s = if x <= 0.003_130_8 {
            12.92 * x
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    }

    #[test]
    fn colour_bytes_survive_linear_and_back() {
        // Why: COLOR_0 is linear; a coloured cut that goes out as glTF and comes back in
        // through the importer must keep every sRGB byte, not drift by one.
        for b in 0..=255u8 {
            let l = linear_rgba([b, b, b, b]);
            assert_eq!(srgb8(l[0]), b, "byte {b}: linear {}", l[0]);
            assert_eq!((l[3] * 255.0 + 0.5) as u8, b);
        }
    }

    #[test]
    fn containers_follow_the_extension() {
        assert_eq!(
            GltfContainer::of_path(Path::new("a/b.GLB")),
            Some(GltfContainer::Binary)
        );
        assert_eq!(
            GltfContainer::of_path(Path::new("b.gltf")),
            Some(GltfContainer::Embedded)
        );
        assert_eq!(GltfContainer::of_path(Path::new("b.ply")), None);
        assert_eq!(GltfContainer::of_path(Path::new("glb")), None);
    }

    fn square() -> CutMesh {
        CutMesh {
            positions: vec![[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            colors: vec![[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [9; 4]],
            uvs: Vec::new(),
            indices: vec![0, 1, 2, 2, 3, 0],
        }
    }

    #[test]
    fn a_welded_cut_parses_and_validates_in_both_containers() {
        // Why: the file must be valid glTF 2.0 (the gltf crate's validation), positions in
        // model coordinates with exact bounds, and the two containers the same document.
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::new([1.0, 2.0, 3.0], [4.0, 4.0, 4.0], 2);
        let mesh = square();
        for (file, c) in [
            ("cut.glb", GltfContainer::Binary),
            ("cut.gltf", GltfContainer::Embedded),
        ] {
            let path = dir.path().join(file);
            let s = write_cut_gltf(&grid, GltfContent::Welded(&mesh), &path, c, "test").unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(s.bytes, bytes.len() as u64);
            assert_eq!((s.primitives, s.textures), (1, 0));
            let g = ::gltf::Gltf::from_slice(&bytes).unwrap_or_else(|e| panic!("{file}: {e}"));
            let prim = g.meshes().next().unwrap().primitives().next().unwrap();
            let b = prim.bounding_box();
            let lo = grid.position([0, 0, 0]).map(|x| x as f32);
            let hi = grid.position([4, 4, 0]).map(|x| x as f32);
            assert_eq!((b.min, b.max), (lo, hi));
            let names: Vec<String> = prim.attributes().map(|(s, _)| s.to_string()).collect();
            assert_eq!(names, ["POSITION", "NORMAL", "COLOR_0"]);
            assert_eq!(prim.indices().unwrap().count(), 6);
            // Four vertices: 16-bit indices.
            assert_eq!(
                prim.indices().unwrap().data_type(),
                ::gltf::accessor::DataType::U16
            );
            assert_eq!(g.blob.is_some(), c == GltfContainer::Binary);
        }
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["cut.glb", "cut.gltf"], "no temporary files left");
    }

    #[test]
    fn a_textured_cut_has_a_material_and_patch_coordinates_per_patch() {
        // Why: each patch is drawn with its own texture, so TEXCOORD_0 must be the patch
        // texture's coordinate (the chart map of the source UV), not the source UV, and
        // each primitive must name its own material and PNG image; patches without
        // triangles are left out.
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::new([0.0; 3], [1.0; 3], 4);
        let chart = tessera_format::TextureChart {
            image: 0,
            scale: [0.5, 0.25],
            offset: [0.125, 0.5],
        };
        let patch = |shade: u8| PatchData {
            positions: vec![[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            colors: vec![[7; 4]; 3],
            indices: vec![0, 1, 2],
            charts: vec![chart],
            chart_ids: vec![0; 3],
            texture: Some(PatchTexture {
                width: 2,
                height: 1,
                codec: None,
                encoded: Vec::new(),
                rgba: vec![shade, 0, 0, 255, 0, shade, 0, 255],
                ..Default::default()
            }),
            ..PatchData::default()
        };
        let (a, b, empty) = (patch(10), patch(200), PatchData::default());
        let patches = [(3, &a), (5, &empty), (8, &b)];
        let path = dir.path().join("t.glb");
        let s = write_cut_gltf(
            &grid,
            GltfContent::Textured(&patches),
            &path,
            GltfContainer::Binary,
            "t",
        )
        .unwrap();
        assert_eq!((s.primitives, s.textures), (2, 2));
        let bytes = std::fs::read(&path).unwrap();
        let g = ::gltf::Gltf::from_slice(&bytes).unwrap();
        let blob = g.blob.as_deref().unwrap();
        let mesh = g.meshes().next().unwrap();
        let mut images = Vec::new();
        for (k, prim) in mesh.primitives().enumerate() {
            let names: Vec<String> = prim.attributes().map(|(s, _)| s.to_string()).collect();
            assert_eq!(names, ["POSITION", "NORMAL", "TEXCOORD_0"]);
            let uv = prim.get(&::gltf::Semantic::TexCoords(0)).unwrap();
            let view = uv.view().unwrap();
            let raw = &blob[view.offset()..view.offset() + view.length()];
            let got: Vec<f32> = raw
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            assert_eq!(got, [0.125, 0.5, 0.625, 0.5, 0.125, 0.75]);
            let m = prim.material();
            assert_eq!(m.name(), Some(["node 3", "node 8"][k]));
            let info = m.pbr_metallic_roughness().base_color_texture().unwrap();
            let t = info.texture();
            assert_eq!(
                t.sampler().wrap_s(),
                ::gltf::texture::WrappingMode::ClampToEdge
            );
            match t.source().source() {
                ::gltf::image::Source::View { view, mime_type } => {
                    assert_eq!(mime_type, "image/png");
                    let png = &blob[view.offset()..view.offset() + view.length()];
                    assert!(png.starts_with(b"\x89PNG"));
                    images.push(t.source().index());
                }
                _ => panic!("image not in a buffer view"),
            }
        }
        assert_eq!(images, [0, 1]);
    }

    #[test]
    fn an_empty_cut_is_a_valid_empty_asset() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::new([0.0; 3], [1.0; 3], 4);
        let path = dir.path().join("e.glb");
        let empty = CutMesh::default();
        let s = write_cut_gltf(
            &grid,
            GltfContent::Welded(&empty),
            &path,
            GltfContainer::Binary,
            "e",
        )
        .unwrap();
        assert_eq!(s.primitives, 0);
        let g = ::gltf::Gltf::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(g.meshes().count(), 0);
    }

    #[test]
    fn a_missing_directory_fails_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::new([0.0; 3], [1.0; 3], 4);
        let path = dir.path().join("no/such/dir/e.glb");
        let mesh = square();
        let e = write_cut_gltf(
            &grid,
            GltfContent::Welded(&mesh),
            &path,
            GltfContainer::Binary,
            "e",
        )
        .unwrap_err();
        assert!(e.to_string().contains("No such file"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
