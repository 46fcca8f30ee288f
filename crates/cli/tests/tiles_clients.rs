//! Real 3D Tiles clients (issue 33) on `tessera export-tiles` output, in Debian's
//! headless Chromium (WebGL2 on SwiftShader, driven by `web/tests/tiles.mjs`):
//! 3DTilesRendererJS (npm `3d-tiles-renderer` on `three`) and CesiumJS (npm `cesium`)
//! load the Bunny's tileset from `tessera serve --tiles` on loopback
//! (`web/tests/tiles.html`, served with `--web web`), wait until idle, and their
//! screenshots are compared with `tessera render --complete` of the same camera at the
//! same screen-space error: the silhouettes' intersection over union, and crack pixels
//! (background pixels enclosed by the surface where the native render has surface at
//! least 2 pixels from its edge: `tessera_image::enclosed_background_mask`; the clients
//! clear to magenta, which no surface here is, so dark shading never reads as a hole). Prints the tiles and bytes each client
//! fetched and the triangles it drew.
//!
//! Skipped, loudly, when Chromium or the npm packages of web/ are missing
//! (`scripts/setup` installs both).

mod common;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;
use serde_json::{json, Value};
use tessera_image::{coverage, enclosed_background_mask, iou, Image};

const WIDTH: u32 = 480;
const HEIGHT: u32 = 360;
/// The screen-space error of both sides: `tessera render`'s default tolerance and the
/// clients' maximum screen-space error.
const SSE_PX: f64 = 1.0;

/// The views: (model, camera). Two of the Bunny (the three-quarter view of the browser
/// tests, and one close to its flank: a cut over more levels), one of the textured
/// scissors from above (PNG images in the tiles). No eye on the z axis: with the
/// tileset at the Earth's centre that is the polar axis, where CesiumJS 1.145 draws the
/// whole view 5 pixels to the side (measured with the scissors seen from [0, 0, 0.3]:
/// IoU 0.88; from a point 1 cm off the axis it matches 3DTilesRendererJS pixel for
/// pixel).
const VIEWS: [(&str, &str); 3] = [
    (
        "bunny",
        r#"{"position": [0.03, 0.14, 0.22], "target": [-0.0168, 0.11, -0.0015], "up": [0, 1, 0], "fov_y_deg": 45}"#,
    ),
    (
        "bunny",
        r#"{"position": [0.12, 0.12, 0.05], "target": [-0.0168, 0.1, -0.0015], "up": [0, 1, 0], "fov_y_deg": 45}"#,
    ),
    (
        "scissors",
        r#"{"position": [0.01, 0.005, 0.3], "target": [0.002355, 0.005853, 0.0], "up": [0, 1, 0], "fov_y_deg": 45}"#,
    ),
];

/// Silhouette intersection over union each client must reach against `tessera render
/// --complete`. Measured (Chromium, SwiftShader against lavapipe, 480x360, no
/// antialiasing on either side; both clients drew tessera render's own cut: 21,921 and
/// 34,559 triangles of the Bunny, 15,728 of the scissors): 0.9932, 0.9863 and 0.9733,
/// the same for both clients (their silhouettes are the same pixels: one rasteriser,
/// one cut), what is left being rasterisation at the edges; the same silhouettes moved
/// 6 pixels score 0.933, 0.942 and 0.842 (the control below).
const MIN_IOU: f64 = 0.95;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Why the test cannot run here, if it cannot.
fn missing() -> Option<String> {
    let chromium = std::env::var_os("TESSERA_CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    if !chromium.is_file() {
        return Some(format!("{} is missing", chromium.display()));
    }
    for p in ["playwright-core", "three", "3d-tiles-renderer", "cesium"] {
        if !repo().join("web/node_modules").join(p).is_dir() {
            return Some(format!("web/node_modules/{p} is missing"));
        }
    }
    None
}

/// `tessera serve --tiles TILES... --web web` on a free loopback port.
fn serve(tilesets: &[PathBuf]) -> (Running, SocketAddr) {
    let mut argv: Vec<std::ffi::OsString> = vec!["--web".into(), repo().join("web").into()];
    for t in tilesets {
        argv.push("--tiles".into());
        argv.push(t.into());
    }
    let argv: Vec<&std::ffi::OsStr> = argv.iter().map(|a| a.as_os_str()).collect();
    serve_tessera(&argv)
}

/// `tessera render --complete` of `camera` at [`SSE_PX`]: the frame and its triangles.
fn render(model: &Path, camera: &str, out: &Path) -> (Image, u64) {
    render_complete(
        model,
        camera,
        out,
        (WIDTH, HEIGHT),
        &["--tolerance", &SSE_PX.to_string()],
    )
}

/// `img` with every pixel within 3 of the corner's colour in each channel set to it
/// exactly (the clients' clear colour goes through their colour management).
fn snap_background(img: &Image) -> (Image, [u8; 3]) {
    let bg = img.pixel(0, 0);
    let mut out = img.clone();
    for p in out.rgba.chunks_exact_mut(4) {
        if (0..3).all(|c| p[c].abs_diff(bg[c]) <= 3) {
            p[..3].copy_from_slice(&bg[..3]);
        }
    }
    (out, [bg[0], bg[1], bg[2]])
}

/// Pixels at least `r` pixels (in x and y) inside a mask: covered, and every pixel
/// within `r` covered too. Where the rasterisers agree whatever their edge rules.
fn interior(mask: &[bool], w: usize, r: usize) -> Vec<bool> {
    let h = mask.len() / w;
    (0..mask.len())
        .map(|i| {
            let (x, y) = (i % w, i / w);
            x >= r
                && y >= r
                && x + r < w
                && y + r < h
                && (y - r..=y + r).all(|yy| (x - r..=x + r).all(|xx| mask[yy * w + xx]))
        })
        .collect()
}

/// Crack pixels: background the client's surface encloses where the native frame's
/// surface is at least 2 pixels from its own background (holes the model has, like the
/// scissors' finger loops, differ only at their edges).
fn crack_pixels(shot: &Image, bg: [u8; 3], native_inside: &[bool]) -> usize {
    let holes = enclosed_background_mask(shot, bg);
    (0..holes.len())
        .filter(|&i| holes[i] && native_inside[i])
        .count()
}

#[test]
fn three_d_tiles_clients_draw_what_tessera_render_draws() {
    if let Some(why) = missing() {
        eprintln!(
            "\n!!! SKIPPED three_d_tiles_clients_draw_what_tessera_render_draws: {why}. \
             Run scripts/setup (it installs chromium and the npm packages of web/: \
             3d-tiles-renderer, three, cesium, playwright-core). !!!\n"
        );
        return;
    }
    let work = tempfile::tempdir().unwrap();
    let inputs = [
        ("bunny", repo().join("../shared/data/bunny.obj")),
        (
            "scissors",
            repo().join("../shared/data/ycb-scissors/textured_simple_reoriented.obj"),
        ),
    ];
    let mut tilesets = Vec::new();
    for (name, input) in &inputs {
        assert!(input.is_file(), "{} is missing", input.display());
        let model = work.path().join(format!("{name}.tsr"));
        let (code, _, err) = run_tessera(args!["build", input, "-o", model, "--quiet"]);
        assert_eq!(code, 0, "{err}");
        let tiles = work.path().join(format!("{name}-tiles"));
        let (code, out, err) = run_tessera(args!["export-tiles", model, "-o", tiles, "--quiet"]);
        assert_eq!(code, 0, "{err}");
        eprintln!("{name}: {}", out.trim());
        tilesets.push(tiles);
    }
    let (_server, addr) = serve(&tilesets);

    let clients = ["three", "cesium"];
    let mut visits = Vec::new();
    let mut natives = Vec::new();
    for (k, (name, camera)) in VIEWS.iter().enumerate() {
        let model = work.path().join(format!("{name}.tsr"));
        natives.push(render(
            &model,
            camera,
            &work.path().join(format!("native{k}")),
        ));
        for client in clients {
            visits.push(json!({
                "name": format!("{client}{k}"),
                "url": format!(
                    "http://{addr}/tests/tiles.html?client={client}&tileset=/tiles/{name}-tiles/tileset.json&sse={SSE_PX}&w={WIDTH}&h={HEIGHT}&bg=255,0,255&camera={}",
                    encode(camera)
                ),
                "shot": work.path().join(format!("{client}{k}.png")),
                "viewport": [WIDTH, HEIGHT],
                "timeout_ms": 120000,
            }));
        }
    }
    let plan = work.path().join("plan.json");
    std::fs::write(&plan, json!({ "visits": visits }).to_string()).unwrap();
    let run = Command::new("node")
        .arg(repo().join("web/tests/tiles.mjs"))
        .arg(&plan)
        .current_dir(repo().join("web"))
        .output()
        .expect("node is missing (scripts/setup installs it)");
    assert!(
        run.status.success(),
        "the browser driver failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let results: Vec<Value> = serde_json::from_slice(&run.stdout).unwrap();
    let mut failures = Vec::new();
    for (k, (native, native_triangles)) in natives.iter().enumerate() {
        let (native, bg) = snap_background(native);
        let native_cover = coverage(&native);
        let native_holes = enclosed_background_mask(&native, bg);
        let native_inside = interior(&native_cover, WIDTH as usize, 2);
        for client in clients {
            let name = format!("{client}{k}");
            let r = results.iter().find(|r| r["name"] == name.as_str()).unwrap();
            assert_eq!(r["outcome"], "idle", "{name}: {r:#}");
            let shot = Image::load_png(&work.path().join(format!("{name}.png"))).unwrap();
            assert_eq!((shot.width, shot.height), (WIDTH, HEIGHT), "{name}");
            let (shot, sbg) = snap_background(&shot);
            let cover = coverage(&shot);
            let score = iou(&cover, &native_cover);
            let w = WIDTH as usize;
            let holes = enclosed_background_mask(&shot, sbg);
            let cracks = crack_pixels(&shot, sbg, &native_inside);
            let res = &r["result"];
            eprintln!(
                "{name}: idle in {} ms; fetched {} tiles, {} bytes ({} requests); drew {} triangles (tessera render: {native_triangles}); silhouette IoU {score:.4} ({} pixels, native {}); crack pixels {cracks} (enclosed background: {}, native {})",
                r["ms"],
                res["fetched"]["glb"],
                res["fetched"]["bytes"],
                res["fetched"]["requests"],
                res["triangles"],
                cover.iter().filter(|&&c| c).count(),
                native_cover.iter().filter(|&&c| c).count(),
                holes.iter().filter(|&&h| h).count(),
                native_holes.iter().filter(|&&h| h).count(),
            );
            // Negative control: the same silhouette 6 pixels to the right.
            let shifted: Vec<bool> = (0..cover.len())
                .map(|i| i % w >= 6 && cover[i - 6])
                .collect();
            let control = iou(&shifted, &native_cover);
            eprintln!("{name}: 6 px off: IoU {control:.4}");
            assert!(
                control < MIN_IOU,
                "the IoU threshold does not see a 6 px shift ({control:.4})"
            );
            // Negative control of the crack count: a 3x3 hole punched well inside
            // both surfaces (the first such pixel in reading order) is 9 pixels.
            let (inside, native_inside3) = (interior(&cover, w, 3), interior(&native_cover, w, 3));
            let at = (0..inside.len())
                .find(|&i| inside[i] && native_inside3[i])
                .expect("the frames share some surface");
            let mut punched = shot.clone();
            for dy in 0..3 {
                for dx in 0..3 {
                    let i = 4 * (at + dy * w + dx - w - 1);
                    punched.rgba[i..i + 3].copy_from_slice(&sbg);
                }
            }
            assert_eq!(
                crack_pixels(&punched, sbg, &native_inside),
                cracks + 9,
                "{name}: the crack count misses a punched hole"
            );
            if score < MIN_IOU {
                failures.push(format!("{name}: silhouette IoU {score:.4} < {MIN_IOU}"));
            }
            if cracks > 0 {
                failures.push(format!("{name}: {cracks} crack pixels"));
            }
        }
    }
    // TESSERA_KEEP_SHOTS=DIR keeps the frames for a look.
    if let Some(keep) = std::env::var_os("TESSERA_KEEP_SHOTS") {
        std::fs::create_dir_all(&keep).unwrap();
        for e in std::fs::read_dir(work.path()).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() && p.join("frame_00000.png").is_file() {
                let to = Path::new(&keep)
                    .join(format!("{}.png", p.file_name().unwrap().to_string_lossy()));
                std::fs::copy(p.join("frame_00000.png"), to).unwrap();
            } else if p.extension().is_some_and(|x| x == "png") {
                std::fs::copy(&p, Path::new(&keep).join(p.file_name().unwrap())).unwrap();
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
