//! The desktop viewer behind `tessera view`: a winit window showing a model through
//! the same per-frame code as `tessera render` (`tessera_render::Viewer`: the
//! streaming core's scheduler, the pager, the GPU cache), navigation from
//! `tessera-nav`, full-resolution picking from `tessera-pick`, and an egui HUD.
//!
//! A frame: input events move the [`tessera_nav::Navigator`]; `update(dt)` runs its
//! inertia and animations; the viewer renders the camera into its offscreen target
//! (never waiting for the disk: progressive mode); [`blit`] copies that onto the
//! window surface and egui draws the HUD over it. Screenshots are the offscreen
//! frame, so they equal a `tessera render` of the same camera.
//!
//! Scripted runs (`--script`) replay a camera path in real time instead of user input,
//! write a frame log and a screenshot, and exit: the CI test and `scripts/bench-view`
//! drive the window this way.

mod app;
mod blit;
mod hud;
mod pickers;

use std::path::PathBuf;
use std::sync::Arc;

use tessera_format::PatchReader;
use tessera_nav::UpAxis;
use tessera_select::{Camera, CameraPath, Placement};

/// What `tessera view` was asked to show, and how.
pub struct ViewArgs {
    /// The models (local files or remote ones), their names for the HUD and where each
    /// stands in the scene (a scene file's placements; identities for models given on
    /// the command line, which share their model coordinates): one scene, one GPU and
    /// one RAM budget shared.
    pub models: Vec<(Arc<dyn PatchReader>, String, Placement)>,
    /// Open at this camera (else the home view framing the model).
    pub camera: Option<Camera>,
    /// Up axis (else guessed from the model's extent).
    pub up: Option<UpAxis>,
    pub tolerance_px: f32,
    /// Total memory budget: half for the GPU patch cache, a quarter for decoded patches.
    pub memory_bytes: u64,
    /// Replay this camera path in real time, then exit.
    pub script: Option<CameraPath>,
    /// One JSON object per frame.
    pub frame_log: Option<PathBuf>,
    /// Save the last frame here on exit.
    pub screenshot: Option<PathBuf>,
    pub prefetch: bool,
    /// Geomorphing between levels (`--no-morph` turns it off; G and the HUD toggle it).
    pub morph: bool,
    /// Texture impostors for a scene's distant models (docs/impostors.md).
    pub impostors: bool,
    /// Window size (inner, physical pixels).
    pub width: u32,
    pub height: u32,
    /// Loader threads of the pager.
    pub loaders: usize,
}

/// Why the viewer could not run.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error(
        "no display: neither DISPLAY nor WAYLAND_DISPLAY is set. On a machine without a \
         screen use `tessera render MODEL --orbit 24` (PNG frames), or run the viewer under \
         a virtual display: `xvfb-run -a -s \"-screen 0 1280x720x24\" tessera view MODEL`"
    )]
    NoDisplay,
    #[error("cannot open a window: {0} (is an X11 or Wayland display running?)")]
    Window(String),
    #[error(
        "no usable GPU adapter for the window: {0}. Install Mesa's Vulkan driver \
         (apt-get install mesa-vulkan-drivers) or a GPU driver, or render headless with \
         `tessera render`"
    )]
    NoAdapter(String),
    #[error("{0}")]
    Render(#[from] tessera_render::RenderError),
    #[error("{0}")]
    Other(String),
}

/// Opens the window and runs until it is closed (or the script ends).
pub fn run(args: ViewArgs) -> Result<(), ViewError> {
    if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        return Err(ViewError::NoDisplay);
    }
    app::run(args)
}
