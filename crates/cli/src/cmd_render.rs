//! `tessera render`: render a camera path (or an orbit) of a model to PNG frames with
//! per-frame statistics, headless (lavapipe on a machine without a GPU).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context};
use serde_json::json;
use std::io::Write;

use tessera_render::{FrameStats, Mode, Viewer, ViewerOptions};
use tessera_select::CameraPath;

#[derive(clap::Args)]
#[command(group(
    clap::ArgGroup::new("cameras").required(true).multiple(false).args(["path", "orbit"])
))]
pub struct Args {
    /// The model: a .tsr file or an http:// URL of one (e.g. from `tessera serve`), or
    /// a scene file of several placed models (.json, see docs/scene.md).
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
    /// Switch levels without geomorphing (by default a refined node's vertices move
    /// smoothly from its parent's shape to its own; see docs/morph.md).
    #[arg(long)]
    no_morph: bool,
    /// Textured models: morph the geometry only (by default a patch morphing in from its
    /// parent's shape also shows its parent's texel detail and sharpens as it morphs).
    #[arg(long)]
    no_texel_blend: bool,
    /// Draw frame i with the cut and morph ratios selected for the camera of frame
    /// i - N (its own camera otherwise): rendered beside a normal run, the difference is
    /// what the selection update alone changes, i.e. popping (0: off).
    #[arg(long, default_value_t = 0, value_name = "N")]
    selection_lag: u32,
    /// Benchmark hook: delay every patch read by this many milliseconds (a slow disk or
    /// network, progressive mode).
    #[arg(long, hide = true, default_value_t = 0)]
    read_delay_ms: u64,
    /// Draw every model as its geometry (by default a scene's models that project to
    /// less than --impostor-px of radius are drawn as texture impostors, progressive
    /// frames only; see docs/impostors.md).
    #[arg(long)]
    no_impostors: bool,
    /// Projected radius (pixels) below which a scene's model becomes an impostor.
    #[arg(long, default_value_t = 40.0, value_name = "PX")]
    impostor_px: f64,
    /// Frames a dissolve between geometry and impostor takes (1: a one-frame swap, the
    /// benchmarks' control).
    #[arg(long, default_value_t = 8, value_name = "N", hide = true)]
    impostor_transition_frames: u32,
    /// A frame time to hold, milliseconds: while frames are slower, more of a scene's
    /// models become impostors (the --impostor-px threshold grows), while they are
    /// much faster, fewer.
    #[arg(long, value_name = "MS")]
    frame_budget_ms: Option<f64>,
    /// The impostors' parallax error bound, pixels (a texture is sampled again past it).
    #[arg(long, default_value_t = 1.5, value_name = "PX")]
    impostor_error_px: f64,
    /// Seconds over which a group that arrives late blends in from its parent's shape
    /// (progressive mode; 0: it appears at once).
    #[arg(long, default_value_t = 0.25, value_name = "S")]
    arrival_blend: f64,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        bail!("--width and --height must be between 1 and 16384");
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance must be a positive number of pixels");
    }
    if !(a.arrival_blend.is_finite() && (0.0..=10.0).contains(&a.arrival_blend)) {
        bail!("--arrival-blend must be between 0 and 10 seconds");
    }
    if !(a.impostor_px.is_finite() && a.impostor_px >= 0.0) {
        bail!("--impostor-px must be a number of pixels, 0 or more");
    }
    if a.frame_budget_ms
        .is_some_and(|b| !(b.is_finite() && b > 0.0))
    {
        bail!("--frame-budget-ms must be a positive number of milliseconds");
    }
    if !(a.impostor_error_px.is_finite() && a.impostor_error_px > 0.0) {
        bail!("--impostor-error-px must be a positive number of pixels");
    }
    if a.orbit == Some(0) {
        bail!("--orbit needs at least one frame");
    }
    let progressive = !(a.full_resolution || a.complete);
    let opened = crate::open::open_scene(&a.model, progressive)?;
    // What the remote counters below report: the first model's.
    let model = opened.models[0].0.clone();
    let shots = match (&a.path, a.orbit) {
        (Some(p), _) => Shots::Path(CameraPath::from_file(p, a.width, a.height)?),
        (None, Some(n)) => {
            let scene = opened.points(20_000);
            let up = a.up.or(opened.up).unwrap_or_else(|| scene.guess_up());
            Shots::Orbit(
                tessera_nav::orbit_path(&scene, up, n, a.width, a.height)
                    .context("cannot frame the model for an orbit")?,
            )
        }
        (None, None) => bail!("give --path or --orbit"),
    };
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mode = mode_of(&a);
    let mut opts = viewer_options(&a, mode);
    if opened.models.len() > 1 && !a.no_impostors && mode == Mode::Progressive {
        opts.impostors = Some(tessera_render::ImpostorOptions {
            max_radius_px: a.impostor_px,
            transition_frames: a.impostor_transition_frames.max(1),
            max_error_px: a.impostor_error_px,
            frame_budget_ms: a.frame_budget_ms,
            ..Default::default()
        });
    }
    let t_open = Instant::now();
    let opened_names = opened.names;
    let mut viewer = Viewer::with_scene(tessera_render::Gpu::headless()?, opened.models, opts)?;
    let setup_ms = t_open.elapsed().as_secs_f64() * 1e3;
    // What a remote model transferred to show the roots (its index top and root patches).
    let at_first_frame = model.transfer();
    let adapter = viewer.gpu().adapter_label.clone();
    let n = shots.frames();
    // Per-frame statistics go straight to the stats file (and aggregates are kept as
    // sums and a histogram): a render of 10^9 frames holds no list of frames or cameras.
    let mut stats_file = match &a.stats {
        None => None,
        Some(p) => Some(StatsFile::create(
            p,
            json!({
                "model": a.model.display().to_string(),
                "scene_models": opened_names.len(),
                "adapter": adapter,
                "width": a.width,
                "height": a.height,
                "tolerance_px": a.tolerance,
                "memory_budget_bytes": a.memory,
            }),
        )?),
    };
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(u64::from(n)),
        indicatif::ProgressDrawTarget::stderr(),
    );
    bar.set_style(
        indicatif::ProgressStyle::with_template("rendering {pos}/{len} frames [{elapsed}<{eta}]")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    if n < 50 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let mut agg = Aggregate::default();
    let mut last = FrameStats::default();
    crate::progress::install_interrupt_handler();
    for i in 0..n {
        if crate::progress::interrupted() {
            bar.finish_and_clear();
            bail!("interrupted after {i} of {n} frames (the stats file is not written)");
        }
        let cam = shots.camera(i);
        let s = if a.selection_lag > 0 {
            let select = shots.camera(i.saturating_sub(a.selection_lag));
            viewer.render_with(&select, &cam)?
        } else {
            viewer.render(&cam)?
        };
        if let Some(dir) = &a.out {
            let img = viewer.read_image()?;
            img.save_png(&dir.join(format!("frame_{i:05}.png")))?;
        }
        if let Some(f) = stats_file.as_mut() {
            let rss = tessera_build::current_rss_bytes();
            let mut v = serde_json::to_value(&s)?;
            v["rss_bytes"] = json!(rss);
            if let Some(imp) = viewer.impostor_stats() {
                v["impostors"] = serde_json::to_value(imp)?;
            }
            if let Some((bytes, requests)) = model.transfer() {
                v["remote_bytes"] = json!(bytes);
                v["remote_requests"] = json!(requests);
                v["index_nodes"] = json!(viewer.scheduler().node_count());
            }
            f.frame(&v)?;
        }
        agg.add(&s);
        last = s;
        bar.inc(1);
    }
    bar.finish_and_clear();
    // The kernel's high-water mark also sees peaks inside a frame, which the per-frame
    // samples above miss.
    let peak_rss = tessera_build::peak_rss_bytes().unwrap_or_else(tessera_build::current_rss_bytes);
    let mut summary = json!({
        "frames": agg.frames,
        "mode": mode,
        "mean_frame_ms": agg.mean(agg.frame_ms),
        "median_frame_ms": agg.median_ms(),
        "max_frame_ms": agg.max_frame_ms,
        "mean_selection_ms": agg.mean(agg.selection_ms),
        "mean_triangles": agg.mean(agg.triangles),
        "mean_morph_ratio": agg.mean(agg.morph_mean),
        "max_morph_ratio": agg.morph_max,
        "bytes_uploaded": agg.bytes_uploaded,
        "failed_patches": last.failed_patches,
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
    if let Some(f) = stats_file {
        f.finish(&summary)?;
    }
    println!(
        "{} frames ({:?}) on {}: mean {:.1} ms/frame (median {:.1}), {:.0} triangles/frame, selection {:.3} ms, peak RSS {} MiB",
        agg.frames,
        mode,
        adapter,
        summary["mean_frame_ms"].as_f64().unwrap_or(0.0),
        agg.median_ms(),
        summary["mean_triangles"].as_f64().unwrap_or(0.0),
        summary["mean_selection_ms"].as_f64().unwrap_or(0.0),
        peak_rss >> 20,
    );
    if let Some(((b0, r0), (b, r))) = transfer {
        println!(
            "remote: {b0} bytes in {r0} requests before the first frame, {b} bytes in {r} requests in all"
        );
    }
    report_skipped(&viewer, mode)?;
    Ok(ExitCode::SUCCESS)
}

/// The frame mode the flags ask for.
fn mode_of(a: &Args) -> Mode {
    if a.full_resolution {
        Mode::FullResolution
    } else if a.complete {
        Mode::Complete
    } else {
        Mode::Progressive
    }
}

/// The viewer's options from the flags: one memory figure split as every front end
/// splits it (`memory_split`).
fn viewer_options(a: &Args, mode: Mode) -> ViewerOptions {
    let (gpu_budget_bytes, ram_budget_bytes) = tessera_render::memory_split(a.memory);
    ViewerOptions {
        tolerance_px: a.tolerance,
        cull: !a.no_cull,
        mode,
        gpu_budget_bytes,
        ram_budget_bytes,
        loader_threads: a.loaders.max(1),
        prefetch: !a.no_prefetch,
        morph: tessera_render::MorphOptions {
            enabled: !a.no_morph,
            arrival_blend_s: a.arrival_blend,
            ..Default::default()
        },
        texel_blend: !a.no_texel_blend,
        read_delay: (a.read_delay_ms > 0)
            .then(|| std::time::Duration::from_millis(a.read_delay_ms)),
        ..Default::default()
    }
}

/// `--stats FILE`, written as the frames go (one JSON document: the head's fields, then
/// "frames", then "summary"), atomically: nothing at the path until [`StatsFile::finish`].
struct StatsFile {
    f: tessera_format::AtomicFile,
    path: std::path::PathBuf,
    frames: u64,
}

impl StatsFile {
    fn err(&self, e: &dyn std::fmt::Display) -> anyhow::Error {
        anyhow::anyhow!("cannot write {}: {e}", self.path.display())
    }

    /// Starts the document at `path` with the fields of `head`.
    fn create(path: &std::path::Path, head: serde_json::Value) -> anyhow::Result<StatsFile> {
        let err =
            |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot write {}: {e}", path.display());
        let mut f =
            tessera_format::AtomicFile::create(path, 1 << 16).map_err(|e| err(&e.source))?;
        let head = serde_json::to_string_pretty(&head)?;
        let head = head.trim_end().trim_end_matches('}').trim_end();
        write!(f, "{head},\n  \"frames\": [").map_err(|e| err(&e))?;
        Ok(StatsFile {
            f,
            path: path.to_path_buf(),
            frames: 0,
        })
    }

    /// One frame's statistics.
    fn frame(&mut self, v: &serde_json::Value) -> anyhow::Result<()> {
        let sep = if self.frames == 0 {
            "\n    "
        } else {
            ",\n    "
        };
        self.frames += 1;
        write!(self.f, "{sep}{v}").map_err(|e| self.err(&e))
    }

    /// Ends the document with `summary` and puts it in place.
    fn finish(mut self, summary: &serde_json::Value) -> anyhow::Result<()> {
        let summary_text = serde_json::to_string_pretty(summary)?.replace('\n', "\n  ");
        write!(self.f, "\n  ],\n  \"summary\": {summary_text}\n}}\n").map_err(|e| self.err(&e))?;
        let path = self.path.clone();
        self.f
            .commit()
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display(), e = e.source))
    }
}

/// Says what became of patches that could not be read, truthfully for the mode and the
/// cause: corrupt ones (bad bytes: never retried) leave their parent drawn in a
/// level-of-detail frame (a failed root leaves its part of the model empty; at full
/// resolution, which draws leaves only, a hole); unavailable ones (the disk or the
/// server failed to deliver them) make complete and full-resolution frames incomplete,
/// which is an error: the frames written are not what was asked for.
fn report_skipped(viewer: &Viewer, mode: Mode) -> anyhow::Result<()> {
    let (mut corrupt, mut corrupt_roots, mut unavailable) = (0, 0, 0);
    for i in 0..viewer.model_count() {
        let s = viewer.scheduler_of(i);
        let index = viewer.index_of(i);
        for &n in s.failed() {
            if s.is_retrying(n) {
                unavailable += 1;
            } else {
                corrupt += 1;
                let root = index
                    .nodes()
                    .get(n as usize)
                    .is_some_and(|r| r.parent == tessera_format::NO_NODE);
                corrupt_roots += usize::from(root);
            }
        }
    }
    if corrupt > 0 {
        let (n, roots) = (corrupt, corrupt_roots);
        if mode == Mode::FullResolution {
            eprintln!(
                "warning: {n} corrupt patch(es) skipped; full resolution draws leaves only, so \
                 their parts of the model are missing from the frames"
            );
        } else if roots == n {
            eprintln!(
                "warning: {n} corrupt root patch(es) skipped; their parts of the model are missing"
            );
        } else if roots > 0 {
            eprintln!(
                "warning: {n} corrupt patch(es) skipped: for {} their parents were drawn instead; \
                 {roots} were roots, whose parts of the model are missing",
                n - roots
            );
        } else {
            eprintln!("warning: {n} corrupt patch(es) skipped; their parents were drawn instead");
        }
    }
    if unavailable > 0 {
        let what = format!(
            "{unavailable} patch(es) could not be read (unavailable: the disk or the server \
             did not deliver them; see the warnings above)"
        );
        if mode == Mode::Progressive {
            eprintln!("warning: {what}; their parents were drawn instead");
        } else {
            bail!("{what}, so the frames are incomplete");
        }
    }
    Ok(())
}

/// The cameras of a render: a path's frames or an orbit's, one at a time.
enum Shots {
    Path(CameraPath),
    Orbit(tessera_nav::OrbitCameras),
}

impl Shots {
    fn frames(&self) -> u32 {
        match self {
            Shots::Path(p) => p.frames.max(1),
            Shots::Orbit(o) => o.frames(),
        }
    }

    fn camera(&self, i: u32) -> tessera_select::Camera {
        match self {
            Shots::Path(p) => p.camera(i),
            Shots::Orbit(o) => o.camera(i),
        }
    }
}

/// Sums and a histogram of frame statistics (constant memory over any number of
/// frames).
#[derive(Default)]
struct Aggregate {
    frames: u64,
    frame_ms: f64,
    selection_ms: f64,
    triangles: f64,
    bytes_uploaded: u64,
    max_frame_ms: f64,
    /// Sum of the frames' mean morph ratios, and the largest ratio of any frame.
    morph_mean: f64,
    morph_max: f32,
    /// Frame times in bins 0.1% wide on a log scale from 1 us (see `bin`).
    bins: Vec<u32>,
}

impl Aggregate {
    const BIN_STEP: f64 = 1.001;

    fn bin(ms: f64) -> usize {
        ((ms.max(1e-3) / 1e-3).ln() / Self::BIN_STEP.ln()) as usize
    }

    fn add(&mut self, s: &FrameStats) {
        self.frames += 1;
        self.frame_ms += s.frame_ms;
        self.selection_ms += s.selection_ms;
        self.triangles += s.triangles as f64;
        self.bytes_uploaded += s.bytes_uploaded;
        self.max_frame_ms = self.max_frame_ms.max(s.frame_ms);
        self.morph_mean += f64::from(s.morph_mean);
        self.morph_max = self.morph_max.max(s.morph_max);
        let b = Self::bin(s.frame_ms).min(40_000);
        if self.bins.len() <= b {
            self.bins.resize(b + 1, 0);
        }
        self.bins[b] += 1;
    }

    fn mean(&self, sum: f64) -> f64 {
        sum / self.frames.max(1) as f64
    }

    /// The median frame time, to 0.1% (the middle of its bin).
    fn median_ms(&self) -> f64 {
        let half = self.frames.div_ceil(2);
        let mut seen = 0u64;
        for (b, &c) in self.bins.iter().enumerate() {
            seen += u64::from(c);
            if seen >= half && c > 0 {
                return 1e-3 * Self::BIN_STEP.powf(b as f64 + 0.5);
            }
        }
        0.0
    }
}
