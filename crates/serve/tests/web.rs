//! `ServeOptions::web_dir` (`tessera serve --web DIR`): the browser viewer's static files
//! at `/`, with their content types, nothing outside the directory, the models and the
//! catalogue unchanged; a directory without `index.html` is refused at start. Without
//! it, the viewer built into the binary (`EMBEDDED_WEB`).

mod common;

use std::path::PathBuf;
use std::time::Duration;

use common::TestServer;
use tessera_serve::{ServeError, ServeOptions};

fn model() -> Vec<u8> {
    common::built(1, 4_000)
}

/// Serves `inputs` with `web` on a free loopback port until the returned server drops.
fn start(inputs: Vec<PathBuf>, web: PathBuf) -> Result<(String, TestServer), ServeError> {
    start_with(inputs, Some(web), true)
}

/// Serves `inputs` with `web_dir` and `embedded_web` as given.
fn start_with(
    inputs: Vec<PathBuf>,
    web: Option<PathBuf>,
    embedded_web: bool,
) -> Result<(String, TestServer), ServeError> {
    let opts = ServeOptions {
        addr: "127.0.0.1:0".parse().unwrap(),
        web_dir: web,
        embedded_web,
        ..ServeOptions::default()
    };
    let s = TestServer::start(&inputs, opts)?;
    Ok((s.url(""), s))
}

/// GET with `Accept-Encoding: accept`: status, Content-Encoding, Vary and the body as
/// sent (not decoded).
fn get_encoded(url: &str, accept: &str) -> (u16, Option<String>, Option<String>, Vec<u8>) {
    let agent = ureq::Agent::new_with_config(
        ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(20)))
            .build(),
    );
    let mut r = agent
        .get(url)
        .header("accept-encoding", accept)
        .call()
        .unwrap();
    let h = |k: &str| {
        let v: Vec<&str> = r
            .headers()
            .get_all(k)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .collect();
        (!v.is_empty()).then(|| v.join(", "))
    };
    let (enc, vary) = (h("content-encoding"), h("vary"));
    let body = r.body_mut().read_to_vec().unwrap();
    (r.status().as_u16(), enc, vary, body)
}

fn gunzip(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(b), &mut out).unwrap();
    out
}

fn get(url: &str) -> (u16, Option<String>, Vec<u8>) {
    let agent = ureq::Agent::new_with_config(
        ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(20)))
            .build(),
    );
    let mut r = agent.get(url).call().unwrap();
    let ct = r
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    let body = r.body_mut().read_to_vec().unwrap();
    (r.status().as_u16(), ct, body)
}

#[test]
fn the_web_directory_is_served_at_the_root() {
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    let web = tmp.path().join("web");
    std::fs::create_dir_all(web.join("sub")).unwrap();
    std::fs::create_dir(&models).unwrap();
    std::fs::write(models.join("m.tsr"), model()).unwrap();
    std::fs::write(web.join("index.html"), "<!doctype html><title>t</title>").unwrap();
    std::fs::write(web.join("app_bg.wasm"), b"\0asm\x01\0\0\0").unwrap();
    std::fs::write(web.join("app.js"), "export {}").unwrap();
    std::fs::write(web.join("sub").join("x.json"), "{}").unwrap();
    std::fs::write(web.join(".secret"), "no").unwrap();
    std::fs::write(tmp.path().join("outside.txt"), "no").unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(tmp.path().join("outside.txt"), web.join("link.txt")).unwrap();

    let (base, _stop) = start(vec![models.clone()], web.clone()).expect("server");
    let (s, ct, body) = get(&format!("{base}/"));
    assert_eq!(s, 200);
    assert_eq!(ct.as_deref(), Some("text/html; charset=utf-8"));
    assert!(body.starts_with(b"<!doctype html>"));
    let (s, ct, body) = get(&format!("{base}/app_bg.wasm"));
    assert_eq!((s, ct.as_deref()), (200, Some("application/wasm")));
    assert_eq!(body, b"\0asm\x01\0\0\0");
    let (s, ct, _) = get(&format!("{base}/app.js"));
    assert_eq!(
        (s, ct.as_deref()),
        (200, Some("text/javascript; charset=utf-8"))
    );
    assert_eq!(get(&format!("{base}/sub/x.json")).0, 200);
    // Gzipped copies beside the files (as scripts/build-web writes them): sent to a
    // client that accepts gzip, when at least as new as the file.
    let js = "export const big = '".to_string() + &"tessera ".repeat(500) + "';\n";
    std::fs::write(web.join("app.js"), &js).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    std::io::Write::write_all(&mut gz, js.as_bytes()).unwrap();
    std::fs::write(web.join("app.js.gz"), gz.finish().unwrap()).unwrap();
    let (s, enc, vary, body) = get_encoded(&format!("{base}/app.js"), "gzip, deflate, br");
    assert_eq!((s, enc.as_deref()), (200, Some("gzip")));
    assert!(vary.is_some_and(|v| v.to_ascii_lowercase().contains("accept-encoding")));
    assert!(body.len() * 10 < js.len(), "{} of {}", body.len(), js.len());
    assert_eq!(gunzip(&body), js.as_bytes());
    for accept in ["identity", "gzip;q=0", "br"] {
        let (s, enc, _, body) = get_encoded(&format!("{base}/app.js"), accept);
        assert_eq!(
            (s, enc.as_deref(), body.as_slice()),
            (200, None, js.as_bytes()),
            "{accept}"
        );
    }
    // A copy older than its file is stale: the file goes out as it is.
    let f = std::fs::File::options()
        .write(true)
        .open(web.join("app.js.gz"))
        .unwrap();
    f.set_modified(std::time::SystemTime::now() - Duration::from_secs(3600))
        .unwrap();
    let (_, enc, _, body) = get_encoded(&format!("{base}/app.js"), "gzip");
    assert_eq!((enc, body.as_slice()), (None, js.as_bytes()));
    for bad in [
        "/missing.js",
        "/.secret",
        "/%2e%2e/outside.txt",
        "/sub/%2e%2e/%2e%2e/outside.txt",
        "/sub%2f..%2f..%2foutside.txt",
        "/link.txt",
        "/sub",
    ] {
        assert_eq!(get(&format!("{base}{bad}")).0, 404, "{bad}");
    }
    // The models and the catalogue are as without --web.
    let (s, _, cat) = get(&format!("{base}/api/models"));
    assert_eq!(s, 200);
    assert!(String::from_utf8_lossy(&cat).contains("/models/m.tsr"));
    let (s, _, m) = get(&format!("{base}/models/m.tsr"));
    assert_eq!(s, 200);
    assert_eq!(m, std::fs::read(models.join("m.tsr")).unwrap());

    // A directory that is not a built viewer is refused at start.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    match start(vec![models], empty) {
        Err(ServeError::Input { source, .. }) => {
            assert!(source.to_string().contains("index.html"), "{source}")
        }
        other => panic!("expected a refusal, got {:?}", other.map(|s| s.0)),
    }
}

/// Without `--web`, the viewer built into the binary: byte for byte the files of
/// `web/dist` it was built from (so a stale embed fails here), with their types;
/// `--no-web` (or a binary built before the viewer) answers `/` with a line of text.
#[test]
fn the_embedded_viewer_is_the_built_one() {
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    std::fs::create_dir(&models).unwrap();
    std::fs::write(models.join("m.tsr"), model()).unwrap();
    let dist = std::env::var_os("TESSERA_WEB_DIST")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../web/dist"));
    let built = dist.join("tessera_web_bg.wasm").is_file();
    assert_eq!(
        !tessera_serve::EMBEDDED_WEB.is_empty(),
        built,
        "the embedded viewer does not follow {}: build tessera-serve again",
        dist.display()
    );
    let (base, _stop) = start_with(vec![models.clone()], None, true).expect("server");
    let (s, ct, body) = get(&format!("{base}/"));
    assert_eq!(s, 200);
    if built {
        assert_eq!(ct.as_deref(), Some("text/html; charset=utf-8"));
        assert_eq!(body, std::fs::read(dist.join("index.html")).unwrap());
        for (name, ty) in [
            ("index.html", "text/html; charset=utf-8"),
            ("embed.html", "text/html; charset=utf-8"),
            ("tessera.js", "text/javascript; charset=utf-8"),
            ("tessera_worker.js", "text/javascript; charset=utf-8"),
            ("tessera_web.js", "text/javascript; charset=utf-8"),
            ("tessera_web_bg.wasm", "application/wasm"),
            // The three.js adapter, its page and three.js (a nested path).
            ("tessera-three.js", "text/javascript; charset=utf-8"),
            ("three.html", "text/html; charset=utf-8"),
            ("three/three.module.js", "text/javascript; charset=utf-8"),
            (
                "three/addons/controls/OrbitControls.js",
                "text/javascript; charset=utf-8",
            ),
        ] {
            let (s, ct, body) = get(&format!("{base}/{name}"));
            assert_eq!((s, ct.as_deref()), (200, Some(ty)), "{name}");
            assert!(
                body == std::fs::read(dist.join(name)).unwrap(),
                "/{name} is not {}: build tessera-serve again after scripts/build-web",
                dist.join(name).display()
            );
        }
        // Gzipped to a browser (it accepts gzip): the .wasm about a third of its size,
        // the same bytes once decoded.
        for name in [
            "tessera_web_bg.wasm",
            "tessera_web.js",
            "index.html",
            "three/three.module.js",
        ] {
            let file = std::fs::read(dist.join(name)).unwrap();
            let (s, enc, vary, body) =
                get_encoded(&format!("{base}/{name}"), "gzip, deflate, br, zstd");
            assert_eq!((s, enc.as_deref()), (200, Some("gzip")), "{name}");
            assert!(vary.is_some_and(|v| v.to_ascii_lowercase().contains("accept-encoding")));
            assert!(
                body.len() * 10 < file.len() * 9,
                "{name}: {} of {}",
                body.len(),
                file.len()
            );
            assert!(
                gunzip(&body) == file,
                "{name}: the gzipped copy is not the file"
            );
            if name.ends_with(".wasm") {
                eprintln!("{name}: {} bytes, {} sent gzipped", file.len(), body.len());
            }
        }
        // The page's own source is what was built (web/ against web/dist).
        let web = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../web");
        for name in ["index.html", "tessera.js", "tessera_worker.js"] {
            let (_, _, body) = get(&format!("{base}/{name}"));
            assert!(
                body == std::fs::read(web.join(name)).unwrap(),
                "/{name} differs from web/{name}: run scripts/build-web, then build again"
            );
        }
        for bad in [
            "/missing.js",
            "/.secret",
            "/%2e%2e/Cargo.toml",
            "/sub/index.html",
        ] {
            assert_eq!(get(&format!("{base}{bad}")).0, 404, "{bad}");
        }
    } else {
        assert!(String::from_utf8_lossy(&body).contains("no viewer page"));
    }
    let (s, _, m) = get(&format!("{base}/models/m.tsr"));
    assert_eq!(s, 200);
    assert_eq!(m, std::fs::read(models.join("m.tsr")).unwrap());

    let (base, _stop2) = start_with(vec![models], None, false).expect("server");
    let (s, ct, body) = get(&format!("{base}/"));
    assert_eq!((s, ct.as_deref()), (200, Some("text/plain; charset=utf-8")));
    assert!(String::from_utf8_lossy(&body).contains("/api/models"));
    assert_eq!(get(&format!("{base}/tessera.js")).0, 404);
}

#[test]
fn tileset_directories_are_served_under_tiles_with_their_content_types() {
    // Why (issue 33): 3D Tiles clients fetch `tileset.json` and the `.glb` tiles it
    // names from another origin, so each needs its content type and CORS; nothing
    // outside the directory may be reachable, and a tileset alone (no model) serves.
    let tmp = tempfile::tempdir().unwrap();
    let tiles = tmp.path().join("bunny-tiles");
    std::fs::create_dir_all(tiles.join("tiles")).unwrap();
    std::fs::write(tiles.join("tileset.json"), r#"{"asset":{"version":"1.1"}}"#).unwrap();
    std::fs::write(tiles.join("tiles").join("root.glb"), b"glTF\x02\0\0\0").unwrap();
    std::fs::write(tmp.path().join("outside.txt"), "no").unwrap();
    let opts = ServeOptions {
        addr: "127.0.0.1:0".parse().unwrap(),
        embedded_web: false,
        tiles: vec![tiles.clone()],
        ..ServeOptions::default()
    };
    let s = TestServer::start(&[], opts).expect("a tileset alone serves");
    let base = s.url("");
    let (st, ct, body) = get(&format!("{base}/tiles/bunny-tiles/tileset.json"));
    assert_eq!((st, ct.as_deref()), (200, Some("application/json")));
    assert!(body.starts_with(b"{\"asset\""));
    let (st, ct, body) = get(&format!("{base}/tiles/bunny-tiles/tiles/root.glb"));
    assert_eq!((st, ct.as_deref()), (200, Some("model/gltf-binary")));
    assert_eq!(body, b"glTF\x02\0\0\0");
    for bad in [
        "/tiles/bunny-tiles/../outside.txt",
        "/tiles/bunny-tiles/%2e%2e/outside.txt",
        "/tiles/other/tileset.json",
        "/tiles/bunny-tiles/",
    ] {
        assert_eq!(get(&format!("{base}{bad}")).0, 404, "{bad}");
    }
    let agent = ureq::Agent::new_with_config(
        ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build(),
    );
    let r = agent
        .get(&format!("{base}/tiles/bunny-tiles/tileset.json"))
        .header("origin", "http://elsewhere.example")
        .call()
        .unwrap();
    assert_eq!(
        r.headers()
            .get("access-control-allow-origin")
            .and_then(|v| v.to_str().ok()),
        Some("*")
    );
    // A directory without tileset.json is refused at start.
    let opts = ServeOptions {
        addr: "127.0.0.1:0".parse().unwrap(),
        tiles: vec![tmp.path().to_path_buf()],
        ..ServeOptions::default()
    };
    match TestServer::start(&[], opts) {
        Err(e) => assert!(e.to_string().contains("no tileset.json"), "{e}"),
        Ok(_) => panic!("a directory without tileset.json was served"),
    }
}
