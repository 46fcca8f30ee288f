//! `tessera view`: the desktop viewer (a window; `tessera-viewer`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use tessera_select::{Camera, CameraPath};
use tessera_viewer::{ViewArgs, ViewError};

#[derive(clap::Args)]
pub struct Args {
    /// The models: .tsr files or http:// URLs of them, shown together in their own
    /// model coordinates (scans of one site line up), sharing one memory budget; or
    /// scene files (.json, docs/scene.md) of placed models.
    #[arg(required = true)]
    models: Vec<PathBuf>,
    /// Open at this camera (JSON, docs/camera.md; `C` in the viewer copies one).
    #[arg(long, value_name = "CAM.json")]
    camera: Option<PathBuf>,
    /// Up axis: +x, -x, +y, -y, +z or -z (default: the axis the model is tallest along,
    /// as `tessera info` states; `U` in the viewer cycles it).
    #[arg(long, value_name = "AXIS")]
    up: Option<tessera_nav::UpAxis>,
    /// Screen-space error tolerance, pixels.
    #[arg(long, default_value_t = 1.0)]
    tolerance: f32,
    /// Total memory budget: half for the GPU patch cache, a quarter for decoded patches
    /// in RAM.
    #[arg(long, default_value = "1G", value_parser = crate::parse_bytes)]
    memory: u64,
    /// Replay a camera path in real time (docs/camera.md; keyframes may carry `time_s`),
    /// then exit 0.
    #[arg(long, value_name = "PATH.json")]
    script: Option<PathBuf>,
    /// Write one JSON object per frame here.
    #[arg(long, value_name = "FILE.jsonl")]
    frame_log: Option<PathBuf>,
    /// Save the last frame here (PNG) on exit.
    #[arg(long, value_name = "FILE.png")]
    screenshot: Option<PathBuf>,
    /// Do not prefetch beyond the current view.
    #[arg(long)]
    no_prefetch: bool,
    /// Switch levels without geomorphing (G toggles it in the window).
    #[arg(long)]
    no_morph: bool,
    /// Draw every model of a scene as its geometry (by default distant ones are drawn
    /// as texture impostors, docs/impostors.md).
    #[arg(long)]
    no_impostors: bool,
    /// Window width, pixels.
    #[arg(long, default_value_t = 1280)]
    width: u32,
    /// Window height, pixels.
    #[arg(long, default_value_t = 720)]
    height: u32,
    /// Loader threads.
    #[arg(long, default_value_t = 2)]
    loaders: usize,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        bail!("--width and --height must be between 1 and 16384");
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance must be a positive number of pixels");
    }
    let camera = match &a.camera {
        None => None,
        Some(p) => Some(Camera::from_json_file(p)?),
    };
    let script = match &a.script {
        None => None,
        Some(p) => Some(CameraPath::from_file(p, a.width, a.height)?),
    };
    let mut models = Vec::with_capacity(a.models.len());
    let mut scene_up = None;
    for path in &a.models {
        let opened = crate::open::open_scene(path, true)?;
        scene_up = scene_up.or(opened.up);
        if opened.models.len() == 1 && !tessera_scene::is_scene_path(path) {
            let name = path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            );
            models.push((opened.models[0].0.clone(), name, opened.models[0].1));
            continue;
        }
        for ((model, placement), name) in opened.models.into_iter().zip(opened.names) {
            models.push((model, name, placement));
        }
    }
    let args = ViewArgs {
        models,
        camera,
        up: a.up.or(scene_up),
        tolerance_px: a.tolerance,
        memory_bytes: a.memory,
        script,
        frame_log: a.frame_log,
        screenshot: a.screenshot,
        prefetch: !a.no_prefetch,
        morph: !a.no_morph,
        impostors: !a.no_impostors,
        width: a.width,
        height: a.height,
        loaders: a.loaders,
    };
    match tessera_viewer::run(args) {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(e @ ViewError::NoDisplay) => {
            eprintln!("error: {e}");
            Ok(ExitCode::from(2))
        }
        Err(e) => Err(e.into()),
    }
}
