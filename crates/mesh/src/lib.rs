//! Mesh input and output for Tessera, streamed with bounded memory (PLY, OBJ, STL and
//! glTF 2.0 in; binary PLY out).
//!
//! Importers do not build an in-memory mesh: they push vertices and triangles into a
//! [`MeshVisitor`], so the builder can spill them to disk as they arrive and a file of
//! 10^9 triangles never has to fit in RAM. Every importer reports bad input as a
//! [`MeshError`] naming the file and the problem; problems that can be skipped safely
//! (degenerate faces, for instance) are counted in the [`ImportReport`] instead.

mod assets;
mod common;
mod error;
#[doc(hidden)]
pub mod fuzzing;
mod gltf_import;
mod image_probe;
mod mtl;
mod obj;
mod ply_read;
mod ply_write;
mod progress;
mod source;
mod stl;
mod types;

pub use assets::{open_regular, AssetPolicy, ReadOptions};
pub use error::MeshError;
pub use ply_write::{PlyWriter, PlyWriterOptions};
pub use progress::{NoProgress, Progress};
pub use types::{
    Attributes, ImageSource, ImportReport, MeshHeader, MeshVisitor, TextureSource, Vertex, Wrap,
    NO_TEXTURE,
};

use std::path::Path;

/// The input formats Tessera reads, chosen from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFormat {
    Ply,
    Obj,
    Stl,
    /// glTF 2.0: `.gltf` (JSON) or `.glb` (binary container).
    Gltf,
}

impl InputFormat {
    /// Guess the format from the extension (case-insensitive; a `.gz` after it is looked
    /// through: `scan.ply.gz` is PLY). `None` when unknown.
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let mut ext = path.extension()?.to_str()?.to_ascii_lowercase();
        if ext == "gz" {
            ext = Path::new(path.file_stem()?)
                .extension()?
                .to_str()?
                .to_ascii_lowercase();
        }
        match ext.as_str() {
            "ply" => Some(InputFormat::Ply),
            "obj" => Some(InputFormat::Obj),
            "stl" => Some(InputFormat::Stl),
            "gltf" | "glb" => Some(InputFormat::Gltf),
            _ => None,
        }
    }

    /// The format the first bytes of a (decompressed) file show, where they are
    /// unambiguous: `ply` starts every PLY file, `glTF` every GLB. OBJ, STL and the
    /// JSON of a `.gltf` have no magic number.
    fn from_magic(head: &[u8]) -> Option<InputFormat> {
        if head.starts_with(b"ply") {
            Some(InputFormat::Ply)
        } else if head.starts_with(gltf_import::GLB_MAGIC) {
            Some(InputFormat::Gltf)
        } else {
            None
        }
    }
}

/// The gzip magic number.
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// The first `n` bytes of a stream (fewer if it is shorter).
fn head_of(r: impl std::io::Read, n: u64) -> std::io::Result<Vec<u8>> {
    let mut head = Vec::new();
    std::io::Read::read_to_end(&mut r.take(n), &mut head)?;
    Ok(head)
}

/// Read a mesh file, streaming its vertices and triangles into `visitor`.
///
/// Calls, in order: `visitor.header(..)` exactly once, then `vertex(..)` and `triangle(..)`
/// calls. A triangle only references vertices already delivered (indices are global,
/// 0-based, in delivery order). Polygons are triangulated (fan). Returns what was read and
/// what was skipped; fails with a [`MeshError`] naming the file on unreadable, truncated
/// or malformed input. An error returned by the visitor is passed through unchanged.
///
/// Gzip-compressed files (by content, whatever the name: `scan.ply.gz`) are read through
/// the inflater as they stream (PLY, OBJ, STL; not glTF); the format comes from the
/// extension (looked through `.gz`), else from the first bytes where they say it (PLY,
/// GLB).
///
/// glTF 2.0 (`.gltf` with external or `data:` buffers, `.glb`) is flattened: every
/// triangle primitive (lists, strips, fans) of every node of the default scene (else of
/// every scene; else every mesh once), placed by its node's world transform, a mirroring
/// transform flipping the winding; colour = `COLOR_0` x the material's base colour
/// factor, in sRGB; UVs through the base colour texture's `KHR_texture_transform`.
/// `KHR_mesh_quantization`, `EXT_meshopt_compression` and `KHR_draco_mesh_compression`
/// (decoded in pure Rust, a Draco primitive whole, once per mesh) are read; any other
/// required extension is refused by name. Buffers are memory-mapped, not read into
/// memory.
///
/// Textures (OBJ `map_Kd`, glTF `baseColorTexture` through `TEXCOORD_0`, PNG or JPEG):
/// each vertex that samples one carries its index in [`ImportReport::textures`]
/// ([`Vertex::texture`], else [`NO_TEXTURE`]), which describes the image (where its bytes
/// are, its size from its header, wrap modes, tint, v convention); the images themselves
/// are not read. Textures that cannot be used (missing or unreadable images, other
/// formats, other coordinate sets) leave their vertices untextured in the material's
/// colour and are reported ([`ImportReport::textures_not_used`], `missing_files`,
/// `unreadable_images`) with a warning.
///
/// Files the input names (glTF buffers and images, OBJ material libraries and their
/// textures) are read only when they are regular files under the input's folder (see
/// [`read_mesh_with`] to allow another folder).
pub fn read_mesh(path: &Path, visitor: &mut dyn MeshVisitor) -> Result<ImportReport, MeshError> {
    read_mesh_with(path, &ReadOptions::default(), visitor)
}

/// [`read_mesh`] with options: [`ReadOptions::assets`] says where the files the input
/// names may be read from (by default, only regular files under the input's folder,
/// symlinks resolved; a reference elsewhere is an error naming it).
pub fn read_mesh_with(
    path: &Path,
    options: &ReadOptions,
    visitor: &mut dyn MeshVisitor,
) -> Result<ImportReport, MeshError> {
    use flate2::read::MultiGzDecoder;
    let io = |e| MeshError::io(path, e);
    let open = || std::fs::File::open(path).map_err(io);
    let gzip = head_of(open()?, 2).map_err(io)? == GZIP_MAGIC;
    let open_gz = || open().map(MultiGzDecoder::new);
    let format = match InputFormat::from_path(path) {
        Some(f) => Some(f),
        None if gzip => InputFormat::from_magic(&head_of(open_gz()?, 4).map_err(io)?),
        None => InputFormat::from_magic(&head_of(open()?, 4).map_err(io)?),
    };
    let Some(format) = format else {
        return Err(MeshError::UnknownFormat {
            path: path.to_path_buf(),
        });
    };
    match (format, gzip) {
        (InputFormat::Ply, false) => ply_read::read_ply(path, visitor),
        (InputFormat::Obj, false) => obj::read_obj(path, options, visitor),
        (InputFormat::Stl, false) => stl::read_stl(path, visitor),
        (InputFormat::Gltf, false) => gltf_import::read_gltf(path, options, visitor),
        // glTF is read through a memory map (buffers are random access): inflating it
        // would mean a temporary copy of the whole file.
        (InputFormat::Gltf, true) => Err(MeshError::malformed(
            path,
            "gzip",
            "a gzip-compressed glTF is not read; decompress it first (gunzip)",
        )),
        (InputFormat::Ply, true) => ply_read::read_ply_from(path, open_gz()?, visitor),
        (InputFormat::Obj, true) => obj::read_obj_from(path, Some(options), open_gz, visitor),
        (InputFormat::Stl, true) => {
            // Binary STL is told from ASCII by its size: inflate once to count.
            let size = std::io::copy(&mut open_gz()?, &mut std::io::sink()).map_err(io)?;
            stl::read_stl_from(path, size, open_gz()?, open_gz, visitor)
        }
    }
}
