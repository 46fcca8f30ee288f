//! Entry points of the fuzz targets (`fuzz/fuzz_targets/{ply,obj,stl,gltf,mtl}.rs`) and of their
//! replay as ordinary tests (`tests/corpus.rs`): one function per target, so the two
//! cannot drift apart.
//!
//! Compiled always rather than behind a feature: the module is a few dozen lines with no
//! dependency of its own, and a feature that only the tests and the fuzz crate turn on
//! would be one more configuration to build (and to forget) in CI. It is hidden from the
//! docs and is not an API.
//!
//! Each function feeds the bytes through the importer the builder uses
//! ([`crate::read_mesh`] opens a file and calls the same `read_*_from` function with it;
//! here the streams are the byte slice itself) into a [`CheckingVisitor`], which keeps
//! nothing but counts, checks the [`MeshVisitor`] contract and stops a reader that
//! delivers more than [`DELIVERY_CAP`] vertices or triangles (a few KB of fuzz input
//! cannot hold that many; a reader that delivers them is looping). Errors are the
//! expected outcome for most inputs and are returned; a broken contract panics, which
//! the fuzzer reports as a crash.

use std::path::Path;

use crate::{ImportReport, MeshError, MeshHeader, MeshVisitor, Vertex, NO_TEXTURE};

/// Vertices or triangles a [`CheckingVisitor`] accepts before it stops the reader.
pub const DELIVERY_CAP: u64 = 1 << 24;

/// The name fuzz inputs carry in error messages.
pub const FUZZ_PATH: &str = "fuzz-input";

/// A visitor that counts and checks what a reader delivers.
#[derive(Debug, Default)]
pub struct CheckingVisitor {
    /// Headers received (the contract: exactly one, before any data).
    pub headers: u64,
    /// Vertices delivered.
    pub vertices: u64,
    /// Triangles delivered.
    pub triangles: u64,
    /// The header's claims, for the checks at the end.
    pub header: MeshHeader,
    /// Vertices delivered with a texture, and the largest texture index among them.
    pub textured: u64,
    pub max_texture: Option<u32>,
}

impl MeshVisitor for CheckingVisitor {
    fn header(&mut self, header: &MeshHeader) -> Result<(), MeshError> {
        assert_eq!(self.headers, 0, "header delivered twice");
        assert!(
            self.vertices == 0 && self.triangles == 0,
            "header after data"
        );
        self.headers += 1;
        self.header = header.clone();
        Ok(())
    }

    fn vertex(&mut self, vertex: &Vertex) -> Result<(), MeshError> {
        assert_eq!(self.headers, 1, "vertex before the header");
        assert!(
            vertex.position.iter().all(|c| c.is_finite()),
            "non-finite position {:?} delivered",
            vertex.position
        );
        if self.vertices >= DELIVERY_CAP {
            return Err(MeshError::Visitor(format!(
                "fuzz visitor: more than {DELIVERY_CAP} vertices"
            )));
        }
        if vertex.texture != NO_TEXTURE {
            self.textured += 1;
            self.max_texture = self.max_texture.max(Some(vertex.texture));
        }
        self.vertices += 1;
        Ok(())
    }

    fn triangle(&mut self, t: [u32; 3]) -> Result<(), MeshError> {
        assert_eq!(self.headers, 1, "triangle before the header");
        assert!(
            t.iter().all(|&i| u64::from(i) < self.vertices),
            "triangle {t:?} references a vertex not delivered yet ({} so far)",
            self.vertices
        );
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "degenerate triangle {t:?} delivered"
        );
        if self.triangles >= DELIVERY_CAP {
            return Err(MeshError::Visitor(format!(
                "fuzz visitor: more than {DELIVERY_CAP} triangles"
            )));
        }
        self.triangles += 1;
        Ok(())
    }
}

/// The checks common to every format once a reader has returned.
fn check(
    result: Result<ImportReport, MeshError>,
    v: &CheckingVisitor,
) -> Result<ImportReport, MeshError> {
    match &result {
        Ok(report) => {
            assert_eq!(v.headers, 1, "success without a header");
            assert_eq!(report.vertices, v.vertices, "report and deliveries differ");
            assert_eq!(
                report.triangles, v.triangles,
                "report and deliveries differ"
            );
            assert!(report.triangles > 0, "success without triangles");
            if let Some(n) = v.header.vertex_count {
                assert_eq!(n, v.vertices, "header vertex count not delivered");
            }
            let a = v.header.attributes;
            assert_eq!(
                a.textures,
                v.textured > 0,
                "the header's textures flag and the vertices disagree"
            );
            assert!(!a.textures || a.uvs, "textures without uvs");
            if let Some(t) = v.max_texture {
                assert!(
                    (t as usize) < report.textures.len(),
                    "vertex texture {t} of {} textures",
                    report.textures.len()
                );
            }
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.trim().is_empty(), "empty error message");
            assert!(!msg.contains('\n'), "error message of several lines: {msg}");
        }
    }
    result
}

/// The PLY target: the bytes as a `.ply` file.
pub fn fuzz_ply(data: &[u8]) -> Result<ImportReport, MeshError> {
    let mut v = CheckingVisitor::default();
    let r = crate::ply_read::read_ply_from(Path::new(FUZZ_PATH), data, &mut v);
    check(r, &v)
}

/// The OBJ target: the bytes as a `.obj` file.
pub fn fuzz_obj(data: &[u8]) -> Result<ImportReport, MeshError> {
    let mut v = CheckingVisitor::default();
    let r = crate::obj::read_obj_from(Path::new(FUZZ_PATH), None, || Ok(data), &mut v);
    check(r, &v)
}

/// The STL target: the bytes as a `.stl` file.
pub fn fuzz_stl(data: &[u8]) -> Result<ImportReport, MeshError> {
    let mut v = CheckingVisitor::default();
    let r = crate::stl::read_stl_from(
        Path::new(FUZZ_PATH),
        data.len() as u64,
        data,
        || Ok(data),
        &mut v,
    );
    check(r, &v)
}

/// The glTF target: the bytes as a `.gltf` or `.glb` file (GLB when they start with
/// `glTF`), with no external files (a buffer naming one is an error).
pub fn fuzz_gltf(data: &[u8]) -> Result<ImportReport, MeshError> {
    let mut v = CheckingVisitor::default();
    let r = crate::gltf_import::read_gltf_from(Path::new(FUZZ_PATH), data, None, &mut v);
    check(r, &v)
}

/// The MTL target (issue 29): the bytes as a material library, parsed as the OBJ
/// reader parses one, with no file opened (its `map_Kd` images are not resolved); every
/// material is then used as the reader uses it (tint, texture source, UV transform).
/// Returns an empty report: a library delivers no geometry.
pub fn fuzz_mtl(data: &[u8]) -> Result<ImportReport, MeshError> {
    let mut lib = crate::mtl::Library::default();
    let text = String::from_utf8_lossy(data);
    lib.parse(Path::new(FUZZ_PATH), &text, None)
        .map_err(|detail| MeshError::Refused {
            path: FUZZ_PATH.into(),
            detail,
        })?;
    for (name, m) in &lib.materials {
        assert!(m.kd.iter().all(|c| c.is_finite()), "{name}: Kd {:?}", m.kd);
        let _ = m.tint([200, 100, 50, 255]);
        if let Some(map) = &m.map_kd {
            assert!(!map.name.trim().is_empty(), "{name}: map_Kd without a name");
            let _ = map.transform([0.5, 0.5]);
            let t = m.texture_source(name, [1, 1]);
            assert!(t.is_some(), "{name}: a map_Kd without a texture source");
        }
    }
    Ok(ImportReport::default())
}
