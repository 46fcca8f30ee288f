//! `tessera render`: render a camera path (or an orbit) of a model to PNG frames with
//! per-frame statistics, headless (lavapipe on a machine without a GPU).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use serde_json::json;
use tessera_render::{FrameStats, Mode, Viewer, ViewerOptions};
use tessera_select::CameraPath;

#[derive(clap::Args)]
#[command(group(
    clap::ArgGroup::new("cameras").required(true).multiple(false).args(["path", "orbit"])
))]
pub struct Args {
    /// The model: a .tsr file or an http:// URL of one (e.g. from `tessera serve`).
    model: PathBuf,
    /// Camera path (JSON keyframes, see docs/camera.md).
    #[arg(long, value_name = "PATH.json")]
    path: Option<PathBuf>,
    /// Render N frames orbiting the model instead of a path file (around the up axis,
    /// framed by the model's extent).
    #[arg(long, value_name = "N")]
    orbit: Option<u32>,
    /// Up axis of the orbit: +x, -x, +y, -y, +z or -z (default: the axis the model is
    /// tallest along, as `tessera info` states).
    #[arg(long, value_name = "AXIS")]
    up: Option<tessera_nav::UpAxis>,
    /// Directory for the PNG frames (created if missing).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Image width, pixels.
    #[arg(long, default_value_t = 1280)]
    width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 720)]
    height: u32,
    /// Screen-space error tolerance, pixels.
    #[arg(long, default_value_t = 1.0)]
    tolerance: f32,
    /// Write per-frame statistics (JSON) here.
    #[arg(long, value_name = "STATS.json")]
    stats: Option<PathBuf>,
    /// Draw every leaf, no level of detail and no culling (the brute-force reference).
    #[arg(long, conflicts_with = "complete")]
    full_resolution: bool,
    /// Every frame waits until its whole cut is loaded (offline rendering); by default
    /// frames never wait and show coarser nodes while patches stream in.
    #[arg(long)]
    complete: bool,
    /// Total memory budget: half for the GPU patch cache, a quarter for decoded patches
    /// in RAM.
    #[arg(long, default_value = "512M", value_parser = crate::parse_bytes)]
    memory: u64,
    /// Loader threads (progressive mode).
    #[arg(long, default_value_t = 1)]
    loaders: usize,
    /// Keep patches outside the frustum or facing away.
    #[arg(long)]
    no_cull: bool,
    /// Do not prefetch beyond the current view.
    #[arg(long)]
    no_prefetch: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        bail!("--width and --height must be between 1 and 16384");
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance must be a positive number of pixels");
    }
    if a.orbit == Some(0) {
        bail!("--orbit needs at least one frame");
    }
    let progressive = !(a.full_resolution || a.complete);
    let model = crate::open::open_model_paged(&a.model, progressive)
        .with_context(|| format!("cannot open {}", a.model.display()))?;
    let path = match (&a.path, a.orbit) {
        (Some(p), _) => CameraPath::from_file(p, a.width, a.height)?,
        (None, Some(n)) => {
            let scene = tessera_viewer::scene_points(model.as_ref(), 20_000);
            let up = a.up.unwrap_or_else(|| {
                tessera_nav::guess_up(scene.min.to_array(), scene.max.to_array())
            });
            tessera_viewer::orbit_path(&scene, up, n, a.width, a.height)
                .context("cannot frame the model for an orbit")?
        }
        (None, None) => bail!("give --path or --orbit"),
    };
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mode = if a.full_resolution {
        Mode::FullResolution
    } else if a.complete {
        Mode::Complete
    } else {
        Mode::Progressive
    };
    let opts = ViewerOptions {
        tolerance_px: a.tolerance,
        cull: !a.no_cull,
        mode,
        gpu_budget_bytes: a.memory / 2,
        ram_budget_bytes: a.memory / 4,
        loader_threads: a.loaders.max(1),
        prefetch: !a.no_prefetch,
        ..Default::default()
    };
    let t_open = Instant::now();
    let mut viewer = Viewer::new(model.clone(), opts)?;
    let setup_ms = t_open.elapsed().as_secs_f64() * 1e3;
    // What a remote model transferred to show the roots (its index top and root patches).
    let at_first_frame = model.transfer();
    let adapter = viewer.gpu().adapter_label.clone();
    let cameras = path.cameras();
    let mut frames: Vec<serde_json::Value> = Vec::with_capacity(cameras.len());
    let mut all: Vec<FrameStats> = Vec::with_capacity(cameras.len());
    for (i, cam) in cameras.iter().enumerate() {
        let s = viewer.render(cam)?;
        if let Some(dir) = &a.out {
            let img = viewer.read_image()?;
            img.save_png(&dir.join(format!("frame_{i:05}.png")))?;
        }
        let rss = tessera_build::current_rss_bytes();
        let mut v = serde_json::to_value(&s)?;
        v["rss_bytes"] = json!(rss);
        if let Some((bytes, requests)) = model.transfer() {
            v["remote_bytes"] = json!(bytes);
            v["remote_requests"] = json!(requests);
            v["index_nodes"] = json!(viewer.scheduler().node_count());
        }
        frames.push(v);
        all.push(s);
    }
    // The kernel's high-water mark also sees peaks inside a frame, which the per-frame
    // samples above miss.
    let peak_rss = tessera_build::peak_rss_bytes().unwrap_or_else(tessera_build::current_rss_bytes);
    let n = all.len().max(1) as f64;
    let mean = |f: &dyn Fn(&FrameStats) -> f64| all.iter().map(f).sum::<f64>() / n;
    let mut sorted: Vec<f64> = all.iter().map(|s| s.frame_ms).collect();
    sorted.sort_by(f64::total_cmp);
    let median_ms = match sorted.len() {
        0 => 0.0,
        n if n % 2 == 1 => sorted[n / 2],
        n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    };
    let mut summary = json!({
        "frames": all.len(),
        "mode": mode,
        "mean_frame_ms": mean(&|s| s.frame_ms),
        "median_frame_ms": median_ms,
        "max_frame_ms": sorted.last().copied().unwrap_or(0.0),
        "mean_selection_ms": mean(&|s| s.selection_ms),
        "mean_triangles": mean(&|s| s.triangles as f64),
        "bytes_uploaded": all.iter().map(|s| s.bytes_uploaded).sum::<u64>(),
        "failed_patches": all.last().map_or(0, |s| s.failed_patches),
        "peak_rss_bytes": peak_rss,
        "setup_ms": setup_ms,
    });
    let transfer = at_first_frame.zip(model.transfer());
    if let Some(((b0, r0), (b, r))) = transfer {
        summary["remote"] = json!({
            "first_frame_bytes": b0,
            "first_frame_requests": r0,
            "bytes": b,
            "requests": r,
        });
    }
    if let Some(p) = &a.stats {
        let doc = json!({
            "model": a.model.display().to_string(),
            "adapter": adapter,
            "width": a.width,
            "height": a.height,
            "tolerance_px": a.tolerance,
            "memory_budget_bytes": a.memory,
            "summary": summary,
            "frames": frames,
        });
        write_atomic(p, serde_json::to_string_pretty(&doc)?.as_bytes())?;
    }
    println!(
        "{} frames ({:?}) on {}: mean {:.1} ms/frame (median {:.1}), {:.0} triangles/frame, selection {:.3} ms, peak RSS {} MiB",
        all.len(),
        mode,
        adapter,
        summary["mean_frame_ms"].as_f64().unwrap_or(0.0),
        median_ms,
        summary["mean_triangles"].as_f64().unwrap_or(0.0),
        summary["mean_selection_ms"].as_f64().unwrap_or(0.0),
        peak_rss >> 20,
    );
    if let Some(((b0, r0), (b, r))) = transfer {
        println!(
            "remote: {b0} bytes in {r0} requests before the first frame, {b} bytes in {r} requests in all"
        );
    }
    let failed = all.last().map_or(0, |s| s.failed_patches);
    if failed > 0 {
        eprintln!("warning: {failed} corrupt patch(es) skipped; their parents were drawn");
    }
    Ok(ExitCode::SUCCESS)
}

fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write;
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot write {}: {e}", path.display());
    let mut file = tessera_format::AtomicFile::create(path, 1 << 16).map_err(|e| err(&e.source))?;
    file.write_all(bytes).map_err(|e| err(&e))?;
    file.commit().map_err(|e| err(&e.source))
}
