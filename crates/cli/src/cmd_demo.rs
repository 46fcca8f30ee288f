//! `tessera demo`: the bundled Nefertiti scan (public domain, 100k triangles), built
//! into a cache directory once, then shown in the viewer; on a machine without a
//! display, an orbit rendered to PNG files instead.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::Context;
use tessera_build::{build, BuildOptions};
use tessera_format::{FormatError, Model, PatchReader, FORMAT_VERSION};
use tessera_render::{Mode, Viewer, ViewerOptions};

/// The scan, gzip-compressed, inside the binary: the demo works from any directory.
const NEFERTITI_OBJ_GZ: &[u8] = include_bytes!("../../../data/nefertiti.obj.gz");

#[derive(clap::Args)]
pub struct Args {
    /// Where the built model is kept (default: $XDG_CACHE_HOME/tessera or
    /// ~/.cache/tessera).
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Build the model again even if the cache has it.
    #[arg(long)]
    rebuild: bool,
    /// Render the orbit to PNG files even when a display is available.
    #[arg(long)]
    headless: bool,
    /// Frames of the headless orbit.
    #[arg(long, default_value_t = 24)]
    frames: u32,
}

fn cache_dir(a: &Args) -> anyhow::Result<PathBuf> {
    if let Some(d) = &a.cache {
        return Ok(d.clone());
    }
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME").filter(|x| !x.is_empty()) {
        return Ok(PathBuf::from(x).join("tessera"));
    }
    match std::env::var_os("HOME").filter(|x| !x.is_empty()) {
        Some(h) => Ok(PathBuf::from(h).join(".cache").join("tessera")),
        None => {
            anyhow::bail!("no cache directory: set HOME or XDG_CACHE_HOME, or give --cache DIR")
        }
    }
}

/// The cached model, built first when missing, unreadable or of another format version.
fn ensure_model(dir: &Path, rebuild: bool) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    // The format version in the name: a Tessera that reads another version builds its own.
    let model = dir.join(format!("nefertiti-v{FORMAT_VERSION}.tsr"));
    if !rebuild {
        match Model::open(&model) {
            Ok(_) => return Ok(model),
            Err(FormatError::Io { cause, .. }) if cause.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => eprintln!("{}: {e}; building it again", model.display()),
        }
    }
    let obj = dir.join("nefertiti.obj.part");
    let mut text = Vec::new();
    flate2::read::GzDecoder::new(NEFERTITI_OBJ_GZ)
        .read_to_end(&mut text)
        .context("the bundled scan is damaged (rebuild tessera)")?;
    std::fs::write(&obj, &text).with_context(|| format!("cannot write {}", obj.display()))?;
    eprintln!(
        "building the demo model (Nefertiti, 99,938 triangles) into {}",
        model.display()
    );
    let bars = crate::progress::Bars::new(false);
    crate::progress::install_interrupt_handler();
    let opts = BuildOptions {
        tmp_dir: Some(dir.to_owned()),
        ..BuildOptions::default()
    };
    // The input is OBJ text; the builder picks the reader from the extension.
    let input = dir.join("nefertiti.obj");
    std::fs::rename(&obj, &input).with_context(|| format!("cannot write {}", input.display()))?;
    let r = build(&input, &model, &opts, &bars);
    let _ = std::fs::remove_file(&input);
    let r = r.with_context(|| format!("building {}", model.display()))?;
    eprintln!(
        "built in {:.1} s: {} nodes, {} levels, {} bytes",
        r.seconds, r.nodes, r.levels, r.output_bytes
    );
    Ok(model)
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let dir = cache_dir(&a)?;
    let path = ensure_model(&dir, a.rebuild)?;
    let model: Arc<dyn PatchReader> =
        Arc::new(Model::open(&path).with_context(|| format!("cannot open {}", path.display()))?);
    let has_display =
        std::env::var_os("DISPLAY").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some();
    if has_display && !a.headless {
        eprintln!("opening the viewer (drag to orbit, wheel to zoom, H hides the HUD)");
        tessera_viewer::run(tessera_viewer::ViewArgs {
            models: vec![(
                model,
                "Nefertiti (demo)".into(),
                tessera_select::Placement::IDENTITY,
            )],
            camera: None,
            up: None,
            tolerance_px: 1.0,
            memory_bytes: 1 << 30,
            script: None,
            frame_log: None,
            screenshot: None,
            prefetch: true,
            morph: true,
            impostors: true,
            width: 1280,
            height: 720,
            loaders: 2,
        })?;
        return Ok(ExitCode::SUCCESS);
    }
    // No display: the same views, to PNG.
    let frames_dir = dir.join("demo-frames");
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("cannot create {}", frames_dir.display()))?;
    let scene = tessera_nav::scene_points(model.as_ref(), 20_000);
    let up = scene.guess_up();
    let orbit = tessera_nav::orbit_path(&scene, up, a.frames.max(1), 1280, 720)?;
    let mut viewer = Viewer::new(
        model,
        ViewerOptions {
            mode: Mode::Complete,
            ..Default::default()
        },
    )?;
    let mut triangles = 0;
    for i in 0..orbit.frames() {
        let s = viewer.render(&orbit.camera(i))?;
        triangles = triangles.max(s.triangles);
        viewer
            .read_image()?
            .save_png(&frames_dir.join(format!("frame_{i:05}.png")))?;
    }
    let shown = std::fs::canonicalize(&frames_dir).unwrap_or(frames_dir);
    println!(
        "no display (DISPLAY and WAYLAND_DISPLAY unset): rendered {} frames of an orbit around {} \
         (up to {} triangles a frame) on {} to {}",
        a.frames.max(1),
        up,
        triangles,
        viewer.gpu().adapter_label,
        shown.display()
    );
    Ok(ExitCode::SUCCESS)
}
