//! Real third-party glTF files (issue 11, "Real third-party files"): the YCB scissors
//! (`../shared/data/ycb-scissors/`, never copied into the repository) converted at test
//! time by the writers people use, from npm (`web/node_modules/.bin`, installed by
//! `.ci/run`): `obj2gltf` (`.gltf` with embedded buffers, `.gltf` with a separate `.bin`,
//! `.glb`), `gltfpack` (quantised: `KHR_mesh_quantization` + `KHR_texture_transform`; and
//! `-cc`: `EXT_meshopt_compression`), `gltf-pipeline -d` (`KHR_draco_mesh_compression`,
//! `.gltf` and `.glb`; EdgeBreaker valence, positions quantised to 11 bits). Each file must
//! `tessera build`, `verify`, and keep the OBJ build's triangle count (exactly: Draco
//! keeps the connectivity) and the OBJ's extent (within the writer's quantisation) and
//! use the scan's texture image. Then bytes of the real Draco stream are flipped: every
//! damaged stream is read or refused with one error naming the Draco primitive, never a
//! panic.
//!
//! Without the data or the tools the test says why on stderr and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

use tessera_mesh::{MeshError, MeshHeader, MeshVisitor, Vertex};

/// How far a writer may move positions.
#[derive(Clone, Copy)]
enum Quantised {
    No,
    /// gltfpack: 14 bits of the largest extent by default.
    Gltfpack,
    /// gltf-pipeline's Draco: 11 bits of the largest extent by default.
    Draco,
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `web/node_modules/.bin/NAME`, if installed.
fn tool(name: &str) -> Option<PathBuf> {
    let p = repo().join("web/node_modules/.bin").join(name);
    p.exists().then_some(p)
}

/// Run a converter; panics with its output when it fails.
fn convert(tool: &Path, args: &[&std::ffi::OsStr]) {
    let out = Command::new(tool)
        .args(args)
        .output()
        .expect("run converter");
    assert!(
        out.status.success(),
        "{} {:?} failed:\n{}{}",
        tool.display(),
        args,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `tessera ARGS`: (success, stdout, stderr).
fn tessera(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .env_remove("TESSERA_LOG")
        .args(args)
        .output()
        .expect("run tessera");
    let (o, e) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    assert!(!e.contains("panicked"), "tessera {args:?} panicked:\n{e}");
    (out.status.success(), o, e)
}

/// Builds `input` into `model`; the build report (JSON) and stderr.
fn build(input: &Path, model: &Path) -> (serde_json::Value, String) {
    let (ok, out, err) = tessera(&[
        "build".as_ref(),
        "--json".as_ref(),
        "--threads".as_ref(),
        "2".as_ref(),
        input.as_os_str(),
        "-o".as_ref(),
        model.as_os_str(),
    ]);
    assert!(ok, "building {}:\n{err}", input.display());
    let report = serde_json::from_str(&out).unwrap_or_else(|e| panic!("build --json: {e}\n{out}"));
    (report, err)
}

/// The bounding box of what the importer delivers.
#[derive(Default)]
struct Extent {
    min: [f32; 3],
    max: [f32; 3],
    vertices: u64,
    triangles: u64,
}

impl MeshVisitor for Extent {
    fn header(&mut self, _: &MeshHeader) -> Result<(), MeshError> {
        self.min = [f32::INFINITY; 3];
        self.max = [f32::NEG_INFINITY; 3];
        Ok(())
    }
    fn vertex(&mut self, v: &Vertex) -> Result<(), MeshError> {
        for a in 0..3 {
            self.min[a] = self.min[a].min(v.position[a]);
            self.max[a] = self.max[a].max(v.position[a]);
        }
        self.vertices += 1;
        Ok(())
    }
    fn triangle(&mut self, _: [u32; 3]) -> Result<(), MeshError> {
        self.triangles += 1;
        Ok(())
    }
}

/// What the importer delivers from `path`, and the best time of three imports.
fn extent(path: &Path) -> (Extent, f64) {
    let mut best = f64::INFINITY;
    let mut e = Extent::default();
    for _ in 0..3 {
        e = Extent::default();
        let t = std::time::Instant::now();
        tessera_mesh::read_mesh(path, &mut e).unwrap_or_else(|err| panic!("{err}"));
        best = best.min(t.elapsed().as_secs_f64());
    }
    (e, best)
}

/// The byte ranges of the Draco streams of the `.glb` `glb` (views of its binary chunk).
fn draco_streams(glb: &[u8]) -> Vec<std::ops::Range<usize>> {
    let u32_at = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[..4], b"glTF");
    let json_len = u32_at(12);
    let root: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len + 8;
    let mut out = Vec::new();
    for m in root["meshes"].as_array().unwrap() {
        for p in m["primitives"].as_array().unwrap() {
            let ext = &p["extensions"]["KHR_draco_mesh_compression"];
            if let Some(v) = ext["bufferView"].as_u64() {
                let view = &root["bufferViews"][v as usize];
                assert_eq!(
                    view["buffer"].as_u64(),
                    Some(0),
                    "the stream is in the binary chunk"
                );
                let at = bin_at + view["byteOffset"].as_u64().unwrap_or(0) as usize;
                out.push(at..at + view["byteLength"].as_u64().unwrap() as usize);
            }
        }
    }
    out
}

/// Flip bits and overwrite bytes of the Draco streams of `glb`, `n` times (a fixed
/// sequence), through the glTF fuzz target (which checks the visitor contract and that
/// errors are one line): no panic, and every error names the Draco primitive. Returns
/// (read, refused).
fn flip_draco_bytes(glb: &[u8], n: usize) -> (usize, usize) {
    let streams = draco_streams(glb);
    assert!(!streams.is_empty(), "no Draco stream in the .glb");
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let (mut read, mut refused) = (0, 0);
    let mut g = glb.to_vec();
    for _ in 0..n {
        let s = streams[next() as usize % streams.len()].clone();
        let mut changed = Vec::new();
        for _ in 0..1 + next() % 8 {
            let r = next();
            // Half of the changes in the first 64 bytes: headers and counts.
            let span = if r & 1 == 0 { s.len().min(64) } else { s.len() };
            let i = s.start + (r >> 8) as usize % span;
            changed.push((i, g[i]));
            if r & 2 == 0 {
                g[i] ^= 1 << ((r >> 4) & 7);
            } else {
                g[i] = (r >> 32) as u8;
            }
        }
        match tessera_mesh::fuzzing::fuzz_gltf(&g) {
            Ok(_) => read += 1,
            Err(e) => {
                let e = e.to_string();
                assert!(
                    e.contains("mesh 0 primitive 0") && e.contains("KHR_draco_mesh_compression"),
                    "a damaged stream's error does not name its primitive: {e}"
                );
                refused += 1;
            }
        }
        for (i, b) in changed.into_iter().rev() {
            g[i] = b;
        }
    }
    (read, refused)
}

#[test]
fn third_party_gltf_files_build_like_the_obj() {
    let obj = repo().join("../shared/data/ycb-scissors/textured_simple_reoriented.obj");
    if !obj.exists() {
        eprintln!(
            "note: {} is absent (../shared/data); skipping",
            obj.display()
        );
        return;
    }
    let (Some(obj2gltf), Some(gltfpack), Some(pipeline)) =
        (tool("obj2gltf"), tool("gltfpack"), tool("gltf-pipeline"))
    else {
        eprintln!(
            "note: obj2gltf, gltfpack or gltf-pipeline is not in web/node_modules/.bin \
             (run `cd web && npm install`; .ci/run does); skipping the third-party glTF test"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    std::fs::create_dir(d("separate")).unwrap();
    let (embedded, separate, glb) = (
        d("scissors.gltf"),
        d("separate/scissors.gltf"),
        d("scissors.glb"),
    );
    let (quantized, meshopt, draco, draco_glb) = (
        d("scissors-q.glb"),
        d("scissors-cc.glb"),
        d("scissors-draco.gltf"),
        d("scissors-draco.glb"),
    );
    let i = "-i".as_ref();
    let o = "-o".as_ref();
    convert(&obj2gltf, &[i, obj.as_os_str(), o, embedded.as_os_str()]);
    convert(
        &obj2gltf,
        &[
            i,
            obj.as_os_str(),
            o,
            separate.as_os_str(),
            "--separate".as_ref(),
        ],
    );
    convert(
        &obj2gltf,
        &[i, obj.as_os_str(), o, glb.as_os_str(), "-b".as_ref()],
    );
    convert(&gltfpack, &[i, glb.as_os_str(), o, quantized.as_os_str()]);
    convert(
        &gltfpack,
        &[i, glb.as_os_str(), o, meshopt.as_os_str(), "-cc".as_ref()],
    );
    convert(
        &pipeline,
        &[i, embedded.as_os_str(), o, draco.as_os_str(), "-d".as_ref()],
    );
    convert(
        &pipeline,
        &[
            i,
            embedded.as_os_str(),
            o,
            draco_glb.as_os_str(),
            "-d".as_ref(),
        ],
    );
    assert!(
        std::fs::read_dir(d("separate")).unwrap().count() >= 2,
        "obj2gltf --separate wrote its .bin beside the .gltf"
    );

    let (obj_report, _) = build(&obj, &d("obj.tsr"));
    let triangles = obj_report["input_triangles"].as_u64().unwrap();
    let (obj_extent, _) = extent(&obj);
    let size = (0..3)
        .map(|a| obj_extent.max[a] - obj_extent.min[a])
        .fold(0.0f32, f32::max);
    for (input, quantised) in [
        (&embedded, Quantised::No),
        (&separate, Quantised::No),
        (&glb, Quantised::No),
        (&quantized, Quantised::Gltfpack),
        (&meshopt, Quantised::Gltfpack),
        (&draco, Quantised::Draco),
        (&draco_glb, Quantised::Draco),
    ] {
        let name = input
            .strip_prefix(dir.path())
            .unwrap()
            .display()
            .to_string();
        let model = d(&format!("{}.tsr", name.replace('/', "-")));
        let (report, stderr) = build(input, &model);
        assert_eq!(
            report["input_triangles"].as_u64(),
            Some(triangles),
            "{name}: triangles differ from the OBJ build"
        );
        // The texture is used: one source image (the scan's 4096x4096 PNG), cut into
        // patch textures, none unreadable.
        assert_eq!(
            report["textures"]["source_images"].as_u64(),
            Some(1),
            "{name}: the texture was not used:\n{stderr}"
        );
        assert_eq!(
            report["textures"]["source_texels"].as_u64(),
            obj_report["textures"]["source_texels"].as_u64(),
            "{name}: not the OBJ's image"
        );
        let (ok, _, err) = tessera(&["verify".as_ref(), model.as_os_str()]);
        assert!(ok, "{name}: verify failed:\n{err}");
        // Quantised positions are within a step (or two) of the grid of 2^bits - 1
        // steps over the largest extent.
        let tol = match quantised {
            Quantised::No => size * 1e-6,
            Quantised::Gltfpack => size / 8192.0,
            Quantised::Draco => size / 2048.0,
        };
        let (e, seconds) = extent(input);
        for a in 0..3 {
            assert!(
                (e.min[a] - obj_extent.min[a]).abs() <= tol
                    && (e.max[a] - obj_extent.max[a]).abs() <= tol,
                "{name}: extent {:?}..{:?}, the OBJ's {:?}..{:?} (tolerance {tol})",
                e.min,
                e.max,
                obj_extent.min,
                obj_extent.max
            );
        }
        eprintln!(
            "{name}: {} triangles, {} vertices, imported in {:.2} ms ({:.1} M triangles/s)",
            e.triangles,
            e.vertices,
            seconds * 1e3,
            e.triangles as f64 / seconds / 1e6
        );
    }

    // The real Draco stream, damaged: read or refused by name, never a panic.
    let glb_bytes = std::fs::read(&draco_glb).unwrap();
    let n = 300;
    let (read, refused) = flip_draco_bytes(&glb_bytes, n);
    eprintln!("scissors-draco.glb: {n} damaged streams: {read} read, {refused} refused");
    assert!(refused > 0, "no damaged stream was refused");
}
