//! Issue 29 (import side): hostile references and sizes. Every file the input names is
//! read only when it is a regular file under the input's folder (or the asset root
//! given), a FIFO or a device is refused before it can block or stream forever, an
//! over-large material library is refused before it is read, readers stop when their
//! visitor is cancelled even where they deliver nothing, and glTF `extras` of any JSON
//! type are accepted. Each test failed on the code before the fix (noted per test).

mod common;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::Collect;
use tessera_mesh::{
    read_mesh, read_mesh_with, AssetPolicy, MeshError, MeshHeader, MeshVisitor, ReadOptions, Vertex,
};

/// Three positions of a triangle, as a glTF buffer.
fn triangle_bin() -> Vec<u8> {
    [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect()
}

/// A glTF whose one triangle reads its positions from buffer `uri`, with `extra` spliced
/// into the document's top level (`"images": ...` and so on).
fn gltf_with_buffer(uri: &str, extra: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"uri":"{uri}","byteLength":36}}],
"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"nodes":[{{"mesh":0}}],"scenes":[{{"nodes":[0]}}],"scene":0{extra}}}"#
    )
}

/// `top/model/` (the input's folder) and `top/secret.bin` beside it, outside.
struct Layout {
    top: tempfile::TempDir,
}

impl Layout {
    fn new() -> Layout {
        let top = tempfile::tempdir().unwrap();
        std::fs::create_dir(top.path().join("model")).unwrap();
        std::fs::write(top.path().join("secret.bin"), triangle_bin()).unwrap();
        std::fs::write(top.path().join("model/inside.bin"), triangle_bin()).unwrap();
        Layout { top }
    }
    fn model(&self) -> PathBuf {
        self.top.path().join("model")
    }
    fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.model().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }
}

fn read(path: &Path, policy: AssetPolicy) -> Result<tessera_mesh::ImportReport, MeshError> {
    let mut c = Collect::default();
    read_mesh_with(path, &ReadOptions { assets: policy }, &mut c)
}

fn refusal(r: Result<tessera_mesh::ImportReport, MeshError>) -> String {
    match r {
        Err(e @ MeshError::Refused { .. }) => {
            let m = e.to_string();
            assert!(!m.contains('\n'), "{m}");
            m
        }
        Err(e) => panic!("expected a refusal, got another error: {e}"),
        Ok(r) => panic!("expected a refusal, the import succeeded: {r:?}"),
    }
}

#[cfg(unix)]
fn mkfifo(p: &Path) {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(p.as_os_str().as_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

/// Run `f` on a thread and fail (instead of hanging) when it takes over `secs`.
fn within<T: Send + 'static>(secs: u64, what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(secs))
        .unwrap_or_else(|_| panic!("{what}: no answer in {secs} s (it hangs)"))
}

#[test]
fn issue_29_gltf_buffer_uris_outside_the_input_folder_are_refused() {
    // Before: each of these read the outside file into the model, exit 0, no warning.
    let l = Layout::new();
    let secret = l.top.path().join("secret.bin");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&secret, l.model().join("link.bin")).unwrap();
    let mut uris = vec![
        "../secret.bin".to_string(),
        "..%2fsecret.bin".to_string(),
        secret.display().to_string(),
        "../../../../../../../../etc/passwd".to_string(),
    ];
    if cfg!(unix) {
        uris.push("link.bin".to_string());
    }
    for uri in &uris {
        let p = l.write("m.gltf", &gltf_with_buffer(uri, ""));
        let m = refusal(read(&p, AssetPolicy::default()));
        assert!(m.contains(&format!("glTF buffer 0 URI '{uri}'")), "{m}");
        assert!(m.contains("outside the input's folder"), "{m}");
        assert!(m.contains("--asset-root DIR"), "{m}");
    }
    // Inside the folder: read as always; and the outside file with the root widened.
    let p = l.write("m.gltf", &gltf_with_buffer("inside.bin", ""));
    read(&p, AssetPolicy::default()).unwrap();
    let p = l.write("m.gltf", &gltf_with_buffer("../secret.bin", ""));
    read(&p, AssetPolicy::under(l.top.path())).unwrap();
    // A root elsewhere still refuses, and names both roots.
    let elsewhere = tempfile::tempdir().unwrap();
    let m = refusal(read(&p, AssetPolicy::under(elsewhere.path())));
    assert!(m.contains("and the asset root"), "{m}");
}

#[test]
fn issue_29_gltf_image_uris_outside_the_input_folder_are_refused() {
    // Before: an image outside the folder became a texture (baked into the patches).
    let l = Layout::new();
    let mut png = std::io::Cursor::new(Vec::new());
    image::RgbImage::new(4, 4)
        .write_to(&mut png, image::ImageFormat::Png)
        .unwrap();
    std::fs::write(l.top.path().join("outside.png"), png.get_ref()).unwrap();
    // A textured triangle: UVs from a second view of inside.bin (its first 24 bytes).
    let doc = format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"uri":"inside.bin","byteLength":36}}],
"bufferViews":[{{"buffer":0,"byteLength":36}},{{"buffer":0,"byteLength":24}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"bufferView":1,"componentType":5126,"count":3,"type":"VEC2"}}],
"images":[{{"uri":"{}"}}],"textures":[{{"source":0}}],
"materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"material":0}}]}}],
"nodes":[{{"mesh":0}}],"scenes":[{{"nodes":[0]}}],"scene":0}}"#,
        "../outside.png"
    );
    let p = l.write("t.gltf", &doc);
    let m = refusal(read(&p, AssetPolicy::default()));
    assert!(m.contains("glTF image 0 URI '../outside.png'"), "{m}");
    let r = read(&p, AssetPolicy::under(l.top.path())).unwrap();
    assert_eq!(r.textures.len(), 1);
}

#[test]
fn issue_29_a_file_url_is_refused_with_a_true_message() {
    // Before: "only files beside the glTF and data: URIs are read", which was not so.
    let l = Layout::new();
    let p = l.write("u.gltf", &gltf_with_buffer("file:///etc/passwd", ""));
    let m = read(&p, AssetPolicy::default()).unwrap_err().to_string();
    assert!(m.contains("is a URL, which is never fetched"), "{m}");
    assert!(!m.contains("beside the glTF"), "{m}");
}

#[test]
fn issue_29_mtllib_dev_zero_is_refused_at_once() {
    // Before: `std::fs::read("/dev/zero")`: 2 GB in 2 s, then all of memory.
    let l = Layout::new();
    for dev in ["/dev/zero", "/dev/urandom"] {
        let p = l.write(
            "z.obj",
            &format!("mtllib {dev}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        );
        let started = Instant::now();
        let m = refusal(within(10, dev, move || read(&p, AssetPolicy::default())));
        assert!(m.contains("outside the input's folder"), "{m}");
        // Even with everything allowed, a device is not a regular file.
        let p = l.model().join("z.obj");
        let m = refusal(within(10, dev, move || read(&p, AssetPolicy::under("/"))));
        assert!(m.contains("character device"), "{m}");
        assert!(started.elapsed() < Duration::from_secs(2));
    }
}

#[cfg(unix)]
#[test]
fn issue_29_fifos_named_by_the_input_are_refused_without_blocking() {
    // Before: `File::open` of a FIFO blocked forever (mtllib, map_Kd, glTF buffer and
    // image alike).
    let l = Layout::new();
    mkfifo(&l.model().join("fifo"));
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\n";
    let cases = [
        ("mtllib.obj", format!("mtllib fifo\n{obj}")),
        ("mapkd.obj", format!("mtllib m.mtl\n{obj}")),
        ("buffer.gltf", gltf_with_buffer("fifo", "")),
    ];
    l.write("m.mtl", "newmtl m\nmap_Kd fifo\n");
    for (name, text) in cases {
        let p = l.write(name, &text);
        let m = refusal(within(10, name, move || read(&p, AssetPolicy::default())));
        assert!(m.contains("FIFO"), "{name}: {m}");
    }
}

#[test]
fn issue_29_a_material_library_over_64_mib_is_refused_before_it_is_read() {
    let l = Layout::new();
    let big = std::fs::File::create(l.model().join("big.mtl")).unwrap();
    // Sparse: costs no disk.
    big.set_len((64 << 20) + 1).unwrap();
    let p = l.write(
        "b.obj",
        "mtllib big.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let m = refusal(read(&p, AssetPolicy::default()));
    assert!(m.contains("more than the 64 MiB"), "{m}");
}

/// A visitor that asks to stop from the start and counts what it was given.
#[derive(Default)]
struct Stop {
    vertices: u64,
    triangles: u64,
}

impl MeshVisitor for Stop {
    fn header(&mut self, _: &MeshHeader) -> Result<(), MeshError> {
        Ok(())
    }
    fn vertex(&mut self, _: &Vertex) -> Result<(), MeshError> {
        self.vertices += 1;
        Ok(())
    }
    fn triangle(&mut self, _: [u32; 3]) -> Result<(), MeshError> {
        self.triangles += 1;
        Ok(())
    }
    fn cancelled(&self) -> bool {
        true
    }
}

#[test]
fn issue_29_readers_stop_when_cancelled_even_where_they_deliver_nothing() {
    // Before: only the builder's triangle sink polled Ctrl-C. A POSITION accessor of
    // 3 x 10^9 zeros (no buffer view) spooled for minutes; an index accessor of zeros
    // (every triangle degenerate) looped without a single visitor call.
    let dir = tempfile::tempdir().unwrap();
    let zeros = r#"{"asset":{"version":"2.0"},
"accessors":[{"componentType":5126,"count":3000000000,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}]}"#;
    let degenerate = format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"uri":"data:;base64,{}","byteLength":36}}],
"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"componentType":5125,"count":3000000000,"type":"SCALAR"}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}]}}"#,
        b64(&triangle_bin())
    );
    let obj: String = "v 0 0 0\nv 1 0 0\nv 0 1 0\n".to_string() + &"f 1 1 2\n".repeat(70_000);
    for (name, text) in [
        ("zeros.gltf", zeros.to_string()),
        ("degenerate.gltf", degenerate),
        ("degenerate.obj", obj),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        let (e, stop) = within(10, name, move || {
            let mut v = Stop::default();
            (read_mesh(&p, &mut v).unwrap_err(), v)
        });
        assert!(matches!(e, MeshError::Interrupted), "{name}: {e}");
        assert!(
            stop.vertices <= 1 << 16,
            "{name}: {} vertices",
            stop.vertices
        );
        assert_eq!(stop.triangles, 0, "{name}");
    }
}

fn b64(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

#[test]
fn issue_29_extras_of_any_json_type_are_accepted() {
    // Before: `"extras": 5` (or a string, array, null) was "JSON that is not a glTF 2.0
    // document", though the specification allows any JSON value.
    let l = Layout::new();
    for extras in ["5", "\"note\"", "[1, 2]", "null", "true", "{\"a\": 1}"] {
        let doc = gltf_with_buffer("inside.bin", &format!(",\"extras\":{extras}")).replace(
            r#""nodes":[{"mesh":0}]"#,
            &format!(r#""nodes":[{{"mesh":0,"extras":{extras}}}]"#),
        );
        let p = l.write("e.gltf", &doc);
        read(&p, AssetPolicy::default()).unwrap_or_else(|e| panic!("extras {extras}: {e}"));
    }
}
