//! The window: winit events in, frames out.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, KeyCode, NamedKey, PhysicalKey};
use winit::window::{Window, WindowId};

use tessera_format::PatchReader;
use tessera_nav::{FlyInput, Mode as NavMode, Navigator, UpAxis};
use tessera_pick::Ray;
use tessera_render::{FrameStats, Gpu, Light, Mode, Shading, Viewer, ViewerOptions};
use tessera_select::Placement;
use tessera_select::{Camera, CameraPath};

use crate::blit::Blit;
use crate::hud::{self, Action, Hud};
use crate::pickers::{Picked, Picker, Purpose};
use crate::{ViewArgs, ViewError};
use tessera_nav::{home_navigator, majority_up, ScenePoints};

/// Two presses closer than this (and a few pixels) are a double-click.
const DOUBLE_CLICK: Duration = Duration::from_millis(350);
/// Pixels a press may move and still be a click, not a drag.
const CLICK_SLOP_PX: f64 = 4.0;

pub fn run(args: ViewArgs) -> Result<(), ViewError> {
    let event_loop = EventLoop::new().map_err(|e| ViewError::Window(e.to_string()))?;
    let mut app = App {
        args: Some(args),
        running: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewError::Window(e.to_string()))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

struct App {
    args: Option<ViewArgs>,
    running: Option<Running>,
    error: Option<ViewError>,
}

/// Mouse buttons and keys held, and where the cursor is.
#[derive(Default)]
struct Input {
    cursor: PhysicalPosition<f64>,
    /// Button dragging and where it went down.
    drag: Option<(MouseButton, PhysicalPosition<f64>)>,
    dragged: bool,
    shift: bool,
    ctrl: bool,
    last_press: Option<(Instant, PhysicalPosition<f64>)>,
    fly: FlyInput,
}

struct Running {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    viewer: Viewer,
    blit: Blit,
    egui_ctx: egui::Context,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    nav: Navigator,
    hud: Hud,
    picker: Picker,
    input: Input,
    names: Vec<String>,
    up: UpAxis,
    gpu_budget: u64,
    ram_budget: u64,
    started: Instant,
    last_frame: Instant,
    frame: u64,
    frozen: Option<Camera>,
    stats: FrameStats,
    log: Option<BufWriter<File>>,
    script: Option<CameraPath>,
    screenshot: Option<PathBuf>,
    /// (time, bytes read) a second ago, for the read rate.
    read_mark: (Instant, u64),
    read_rate: f64,
    picked: Option<([f64; 3], bool, f64)>,
    measure: Vec<[f64; 3]>,
    message: Option<(String, Instant)>,
    /// The script ended: the next frame is the last.
    finishing: bool,
    /// Blit + HUD + present of the last frame, milliseconds.
    present_ms: f64,
    /// The loop slept since the last frame (nothing changed): the time since then is
    /// not a frame time.
    idle: bool,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() {
            return;
        }
        let Some(args) = self.args.take() else {
            return;
        };
        match Running::new(event_loop, args) {
            Ok(r) => {
                r.window.request_redraw();
                self.running = Some(r);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(r) = self.running.as_mut() else {
            return;
        };
        let response = r.egui_state.on_window_event(&r.window, &event);
        match &event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                return;
            }
            WindowEvent::Resized(size) => r.resize(*size),
            WindowEvent::RedrawRequested => {
                match r.frame() {
                    Ok(true) => {}
                    Ok(false) => event_loop.exit(),
                    Err(e) => {
                        self.error = Some(e);
                        event_loop.exit();
                    }
                }
                return;
            }
            _ => {}
        }
        if r.script.is_none() {
            if let WindowEvent::KeyboardInput { event: k, .. } = &event {
                tracing::debug!(key = ?k.physical_key, consumed = response.consumed, "key event");
            }
            r.input_event(&event, response.consumed, event_loop);
        }
        r.window.request_redraw();
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let Some(r) = self.running.as_mut() else {
            return;
        };
        // Draw continuously while anything changes (camera, loads, picks, a script);
        // sleep until the next event once the view has converged.
        if r.busy() {
            event_loop.set_control_flow(ControlFlow::Poll);
            r.window.request_redraw();
        } else {
            event_loop.set_control_flow(ControlFlow::Wait);
            r.idle = true;
        }
    }

    fn exiting(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(r) = self.running.as_mut() {
            if let Some(log) = r.log.as_mut() {
                let _ = log.flush();
            }
        }
    }
}

impl Running {
    fn new(event_loop: &ActiveEventLoop, args: ViewArgs) -> Result<Running, ViewError> {
        let attrs = Window::default_attributes()
            .with_title(format!(
                "{} - Tessera",
                args.models
                    .iter()
                    .map(|(_, n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
            .with_inner_size(PhysicalSize::new(args.width.max(64), args.height.max(64)));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| ViewError::Window(e.to_string()))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                Box::new(event_loop.owned_display_handle()),
            ));
        // A surface needs a driver of some backend for this display: without one (no
        // Vulkan ICD, no GL) the error is about the driver, not the display.
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| ViewError::NoAdapter(format!("cannot draw into the window ({e})")))?;
        let gpu = Gpu::with_instance(instance, Some(&surface)).map_err(|e| match e {
            tessera_render::RenderError::NoAdapter(m) => ViewError::NoAdapter(m),
            other => ViewError::Render(other),
        })?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // The frame is stored as written by the patch shader (no sRGB encoding), as in
        // the PNGs: pick a surface format that keeps the bytes.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| ViewError::Window("the surface offers no format".into()))?;
        let size = window.inner_size();
        let present_mode = if args.script.is_some() {
            wgpu::PresentMode::AutoNoVsync
        } else {
            wgpu::PresentMode::AutoVsync
        };
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&gpu.device, &config);
        let blit = Blit::new(&gpu.device, format);
        let egui_renderer = egui_wgpu::Renderer::new(&gpu.device, format, Default::default());
        let egui_ctx = egui::Context::default();
        let egui_state = egui_winit::State::new(
            egui_ctx.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(gpu.device.limits().max_texture_dimension_2d as usize),
        );

        let (gpu_budget, ram_budget) = tessera_render::memory_split(args.memory_bytes);
        if args.models.is_empty() {
            return Err(ViewError::Other("no model to show".into()));
        }
        let models: Vec<Arc<dyn PatchReader>> =
            args.models.iter().map(|(m, _, _)| m.clone()).collect();
        let placements: Vec<Placement> = args.models.iter().map(|(_, _, p)| *p).collect();
        let names: Vec<String> = args.models.iter().map(|(_, n, _)| n.clone()).collect();
        // Each distinct model's roots, decoded once: a sample thinned so the scene stays
        // near 20k points (framing), placed where each copy stands, and each box for the
        // up axis.
        let per_model = (20_000 / models.len()).max(64);
        let placed: Vec<(Arc<dyn PatchReader>, Placement)> = models
            .iter()
            .cloned()
            .zip(placements.iter().copied())
            .collect();
        let parts = tessera_nav::placed_scene_points(&placed, per_model);
        let scene = ScenePoints::union(&parts);
        // The up axis most models guess from their own extent (ties: the first model's):
        // models side by side make the union wide, not tall.
        let up = args.up.unwrap_or_else(|| majority_up(&parts));
        let viewer = Viewer::with_scene(
            gpu,
            models
                .iter()
                .cloned()
                .zip(placements.iter().copied())
                .collect(),
            ViewerOptions {
                tolerance_px: args.tolerance_px,
                mode: Mode::Progressive,
                gpu_budget_bytes: gpu_budget,
                ram_budget_bytes: ram_budget,
                loader_threads: args.loaders.max(1),
                prefetch: args.prefetch,
                morph: tessera_render::MorphOptions {
                    enabled: args.morph,
                    ..Default::default()
                },
                impostors: (args.impostors && models.len() > 1)
                    .then(tessera_render::ImpostorOptions::default),
                ..Default::default()
            },
        )?;
        let step = models
            .iter()
            .map(|m| m.index().grid().step())
            .fold(f64::INFINITY, f64::min);
        let mut nav = home_navigator(&scene, up, step, config.width, config.height);
        if let Some(cam) = &args.camera {
            nav.set_camera(cam)
                .map_err(|e| ViewError::Other(format!("--camera: {e}")))?;
            nav.resize(config.width, config.height);
        }
        let log = match &args.frame_log {
            None => None,
            Some(p) => Some(BufWriter::new(File::create(p).map_err(|e| {
                ViewError::Other(format!("{}: cannot write the frame log: {e}", p.display()))
            })?)),
        };
        let now = Instant::now();
        Ok(Running {
            window,
            surface,
            config,
            viewer,
            blit,
            egui_ctx,
            egui_state,
            egui_renderer,
            nav,
            hud: Hud::new(args.tolerance_px, args.prefetch, args.morph),
            picker: Picker::new(models.into_iter().zip(placements).collect()),
            input: Input::default(),
            names,
            up,
            gpu_budget,
            ram_budget,
            started: now,
            last_frame: now,
            frame: 0,
            frozen: None,
            stats: FrameStats::default(),
            log,
            script: args.script,
            screenshot: args.screenshot,
            read_mark: (now, 0),
            read_rate: 0.0,
            picked: None,
            measure: Vec::new(),
            message: None,
            finishing: false,
            present_ms: 0.0,
            idle: false,
        })
    }

    /// Whether the next frame may differ from the last.
    fn busy(&self) -> bool {
        self.script.is_some()
            || self.frame < 3
            || self.nav.needs_update()
            || self.input.fly.any_motion()
            // Streaming not at rest (the shared driver's rule, as the browser's).
            || !self.viewer.settled()
            || self.picker.pending() > 0
            || self.message.is_some()
    }

    fn resize(&mut self, size: PhysicalSize<u32>) {
        if size.width == 0 || size.height == 0 {
            return;
        }
        self.config.width = size.width;
        self.config.height = size.height;
        self.surface
            .configure(&self.viewer.gpu().device, &self.config);
        self.nav.resize(size.width, size.height);
    }

    fn say(&mut self, text: impl Into<String>) {
        let text = text.into();
        tracing::info!("{text}");
        self.message = Some((text, Instant::now()));
    }

    /// The camera of this frame, sized to the surface.
    fn camera(&self, now: Instant) -> (Camera, bool) {
        let (w, h) = (self.config.width, self.config.height);
        match &self.script {
            Some(path) => {
                let t = now.duration_since(self.started).as_secs_f64();
                let mut c = path.camera_at(t);
                c.width = w;
                c.height = h;
                (c, t >= path.playback_seconds())
            }
            None => (self.nav.camera(), false),
        }
    }

    /// One frame; false when the viewer should exit.
    fn frame(&mut self) -> Result<bool, ViewError> {
        let now = Instant::now();
        let dt = now.duration_since(self.last_frame).as_secs_f64().min(0.25);
        let slept = std::mem::take(&mut self.idle);
        let wall_ms = now.duration_since(self.last_frame).as_secs_f64() * 1e3;
        self.last_frame = now;
        for p in self.picker.poll() {
            self.picked_one(p);
        }
        if self.script.is_none() {
            self.nav.fly_keys(self.input.fly);
            self.nav.update(dt);
        }
        let (camera, script_done) = self.camera(now);
        self.apply_hud_state();
        let select = match (&self.frozen, self.hud.freeze) {
            (Some(f), true) => f.clone(),
            (_, true) => {
                self.frozen = Some(camera.clone());
                camera.clone()
            }
            _ => {
                self.frozen = None;
                camera.clone()
            }
        };
        let mut select = select;
        select.width = camera.width;
        select.height = camera.height;
        self.stats = self.viewer.render_with(&select, &camera)?;
        // After a sleep (or for the first frame) the frame's own time stands in for the
        // time since the last one.
        let wall_ms = if slept || self.frame == 0 {
            self.stats.frame_ms + self.present_ms
        } else {
            wall_ms
        };
        self.hud.push_frame_ms(wall_ms as f32);
        let read = self.viewer.pager_stats().bytes_read;
        let since = now.duration_since(self.read_mark.0).as_secs_f64();
        if since >= 0.5 {
            self.read_rate = (read - self.read_mark.1.min(read)) as f64 / since;
            self.read_mark = (now, read);
        }
        if self
            .message
            .as_ref()
            .is_some_and(|(_, t)| t.elapsed() > Duration::from_secs(4))
        {
            self.message = None;
        }
        let t_present = Instant::now();
        self.present()?;
        self.present_ms = t_present.elapsed().as_secs_f64() * 1e3;
        self.log_frame(now, wall_ms)?;
        self.frame += 1;
        if self.finishing {
            self.save_final_screenshot()?;
            return Ok(false);
        }
        if script_done {
            // One more frame at the path's last camera, then exit.
            self.finishing = true;
        }
        Ok(true)
    }

    fn apply_hud_state(&mut self) {
        if (self.hud.tolerance_px - self.viewer.options().tolerance_px).abs() > 1e-6 {
            self.viewer.set_tolerance_px(self.hud.tolerance_px);
        }
        if self.hud.prefetch != self.viewer.options().prefetch {
            self.viewer.set_prefetch(self.hud.prefetch);
        }
        if self.hud.morph != self.viewer.options().morph.enabled {
            self.viewer.set_morph(self.hud.morph);
        }
        let shading = Shading {
            light: if self.hud.directional {
                Light::Directional(self.hud.light_dir(self.up))
            } else {
                Light::Headlight
            },
            unlit: self.hud.unlit,
            color_mode: self.hud.color_mode,
            wireframe: self.hud.wireframe,
        };
        self.viewer.set_shading(shading);
    }

    /// Blits the frame onto the surface, draws the HUD, presents.
    fn present(&mut self) -> Result<(), ViewError> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface
                    .configure(&self.viewer.gpu().device, &self.config);
                return Ok(());
            }
            other => {
                tracing::debug!("no surface texture this frame: {other:?}");
                return Ok(());
            }
        };
        let target = frame.texture.create_view(&Default::default());
        let info_picked = self.picked;
        let raw = self.egui_state.take_egui_input(&self.window);
        let adapter = self.viewer.gpu().adapter_label.clone();
        let message = self.message.as_ref().map(|(m, _)| m.clone());
        let camera = self.nav.camera();
        let ppp = self.window.scale_factor() as f32;
        let to_screen = |p: &[f64; 3]| {
            project(&camera, *p).map(|(x, y)| egui::pos2(x as f32 / ppp, y as f32 / ppp))
        };
        let measure_screen = self.measure.iter().filter_map(to_screen).collect();
        let picked_screen = self.picked.as_ref().and_then(|(p, _, _)| to_screen(p));
        let models_info: Vec<hud::ModelInfo> = (0..self.viewer.model_count())
            .map(|i| {
                let s = self.viewer.model_stats(i);
                hud::ModelInfo {
                    name: self.names[i].clone(),
                    visible: self.viewer.is_visible(i),
                    triangles: s.triangles,
                    gpu_bytes: s.gpu_resident_bytes,
                    gpu_budget: s.gpu_budget_bytes,
                }
            })
            .collect();
        let info = hud::Info {
            impostors: self.viewer.impostor_stats(),
            models: &models_info,
            adapter: &adapter,
            stats: &self.stats,
            gpu_budget: self.gpu_budget,
            ram_budget: self.ram_budget,
            bytes_read_per_s: self.read_rate,
            up: self.up,
            mode: self.nav.mode(),
            auto_rotate: self.nav.auto_rotate().is_some(),
            can_wireframe: self.viewer.can_draw_wireframe(),
            picked: info_picked,
            measure: &self.measure,
            picks_pending: self.picker.pending(),
            message: message.as_deref(),
            units_step: (0..self.viewer.model_count())
                .map(|i| self.viewer.index_of(i).grid().step())
                .fold(f64::INFINITY, f64::min),
            measure_screen,
            picked_screen,
        };
        let hud_state = &mut self.hud;
        let mut actions = Vec::new();
        let mut out = self.egui_ctx.run_pass(raw, |ctx| {
            actions = hud::draw(ctx, hud_state, &info);
        });
        self.egui_state
            .handle_platform_output(&self.window, out.platform_output);
        let jobs = self.egui_ctx.tessellate(out.shapes, out.pixels_per_point);
        let gpu = self.viewer.gpu();
        for (id, deltas) in &out.textures_delta.set {
            for delta in deltas {
                self.egui_renderer
                    .update_texture(&gpu.device, &gpu.queue, *id, delta);
            }
        }
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point: out.pixels_per_point,
        };
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("tessera window encoder"),
            });
        if let Some(view) = self.viewer.offscreen_color() {
            self.blit.encode(&gpu.device, &mut enc, view, &target);
        }
        let extra =
            self.egui_renderer
                .update_buffers(&gpu.device, &gpu.queue, &mut enc, &jobs, &screen);
        {
            let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("tessera hud pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let mut pass = pass.forget_lifetime();
            self.egui_renderer.render(&mut pass, &jobs, &screen);
        }
        gpu.queue
            .submit(extra.into_iter().chain(std::iter::once(enc.finish())));
        self.window.pre_present_notify();
        gpu.queue.present(frame);
        for id in &out.textures_delta.free {
            self.egui_renderer.free_texture(id);
        }
        out.textures_delta.clear();
        for a in actions {
            self.action(a);
        }
        Ok(())
    }

    fn log_frame(&mut self, now: Instant, wall_ms: f64) -> Result<(), ViewError> {
        let Some(log) = self.log.as_mut() else {
            return Ok(());
        };
        let s = &self.stats;
        let line = serde_json::json!({
            "frame": self.frame,
            "t_s": now.duration_since(self.started).as_secs_f64(),
            "frame_ms": wall_ms,
            "render_ms": s.frame_ms,
            "present_ms": self.present_ms,
            "triangles": s.triangles,
            "nodes": s.selected_nodes,
            "max_level": s.max_level,
            "pending_loads": s.pending_loads,
            "uploaded_bytes": s.bytes_uploaded,
            "gpu_bytes": s.gpu_resident_bytes,
            "ram_bytes": s.ram_resident_bytes,
            "selection_ms": s.selection_ms,
            "failed_patches": s.failed_patches,
            "rss_bytes": current_rss_bytes(),
        });
        writeln!(log, "{line}").map_err(|e| ViewError::Other(format!("frame log: {e}")))
    }

    fn save_final_screenshot(&mut self) -> Result<(), ViewError> {
        if let Some(path) = self.screenshot.clone() {
            let img = self.viewer.read_image()?;
            img.save_png(&path)
                .map_err(|e| ViewError::Other(format!("{}: {}", path.display(), e.0)))?;
            eprintln!("screenshot: {}", path.display());
        }
        if let Some(log) = self.log.as_mut() {
            log.flush()
                .map_err(|e| ViewError::Other(format!("frame log: {e}")))?;
        }
        Ok(())
    }

    fn screenshot_now(&mut self) {
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        let path = PathBuf::from(format!("tessera-{stamp}.png"));
        match self
            .viewer
            .read_image()
            .map_err(|e| e.to_string())
            .and_then(|img| img.save_png(&path).map_err(|e| e.0))
        {
            Ok(()) => {
                let cam = path.with_extension("json");
                let _ = std::fs::write(&cam, self.nav.camera().to_json_string());
                self.say(format!(
                    "saved {} (camera in {})",
                    path.display(),
                    cam.display()
                ));
            }
            Err(e) => self.say(format!("screenshot failed: {e}")),
        }
    }

    fn action(&mut self, a: Action) {
        match a {
            Action::ResetView => self.nav.reset(),
            Action::Screenshot => self.screenshot_now(),
            Action::CopyCamera => {
                let json = self.nav.camera().to_json_string();
                self.egui_ctx.copy_text(json.clone());
                println!("{json}");
                self.say("camera copied (and printed): open it with --camera");
            }
            Action::SetUp(up) => {
                self.up = up;
                self.nav.set_up(up);
                self.say(format!("up axis {up}"));
            }
            Action::SetMode(m) => {
                self.nav.set_mode(m);
                self.say(match m {
                    NavMode::Fly => "fly: WASD move, Q/E down/up, drag to look, shift fast",
                    NavMode::Orbit => "orbit around the pivot, up axis kept",
                    NavMode::Trackball => "trackball: free rotation",
                });
            }
            Action::ToggleAutoRotate => {
                let next = match self.nav.auto_rotate() {
                    Some(_) => None,
                    None => Some(20.0),
                };
                self.nav.set_auto_rotate(next);
            }
            Action::ClearMeasure => self.measure.clear(),
            Action::SetVisible(i, v) => self.viewer.set_visible(i, v),
            Action::Quit => self.script = None,
        }
        if a == Action::Quit {
            // Close as the window manager would.
            self.finishing = true;
        }
    }

    fn picked_one(&mut self, p: Picked) {
        if let Some(e) = p.error {
            self.say(format!("pick failed: {e}"));
            return;
        }
        let Some(hit) = p.hit else {
            self.say("nothing under the cursor (empty space)");
            return;
        };
        self.picked = Some((hit.point, hit.exact, p.ms));
        match p.purpose {
            Purpose::Recentre => self.nav.recentre(DVec3::from(hit.point)),
            Purpose::Measure => {
                if self.measure.len() >= 2 {
                    self.measure.clear();
                }
                self.measure.push(hit.point);
            }
            Purpose::Inspect => {}
        }
    }

    fn ray_at(&self, at: PhysicalPosition<f64>) -> Ray {
        Ray::through_pixel(&self.nav.camera(), at.x, at.y)
    }

    /// The point drawn under the cursor (depth buffer; any level), for zooming.
    fn point_under(&self, at: PhysicalPosition<f64>) -> Option<DVec3> {
        match self.viewer.point_at(at.x, at.y) {
            Ok(p) => p.map(DVec3::from),
            Err(e) => {
                tracing::debug!("depth read failed: {e}");
                None
            }
        }
    }

    fn input_event(
        &mut self,
        event: &WindowEvent,
        egui_consumed: bool,
        event_loop: &ActiveEventLoop,
    ) {
        match event {
            WindowEvent::ModifiersChanged(m) => {
                self.input.shift = m.state().shift_key();
                self.input.ctrl = m.state().control_key();
            }
            WindowEvent::CursorMoved { position, .. } => {
                let (dx, dy) = (
                    position.x - self.input.cursor.x,
                    position.y - self.input.cursor.y,
                );
                self.input.cursor = *position;
                if let Some((button, down)) = self.input.drag {
                    if (position.x - down.x).abs() + (position.y - down.y).abs() > CLICK_SLOP_PX {
                        self.input.dragged = true;
                    }
                    self.drag(button, dx, dy);
                }
            }
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed if !egui_consumed => {
                    self.nav.press();
                    self.input.drag = Some((*button, self.input.cursor));
                    self.input.dragged = false;
                }
                ElementState::Released => {
                    if let Some((b, _)) = self.input.drag.take() {
                        self.nav.release();
                        if b == MouseButton::Left && !self.input.dragged {
                            self.click();
                        }
                    }
                }
                _ => {}
            },
            WindowEvent::MouseWheel { delta, .. } if !egui_consumed => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(*y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 60.0,
                };
                let toward = self.point_under(self.input.cursor);
                self.nav.zoom(steps, toward);
            }
            WindowEvent::KeyboardInput { event, .. }
                if !egui_consumed || !self.egui_ctx.egui_wants_keyboard_input() =>
            {
                self.key(event, event_loop);
            }
            _ => {}
        }
    }

    fn drag(&mut self, button: MouseButton, dx: f64, dy: f64) {
        let pan = button == MouseButton::Right
            || button == MouseButton::Middle
            || (button == MouseButton::Left && self.input.shift);
        if button == MouseButton::Left && self.input.ctrl {
            // Move the directional light: raking light by hand.
            self.hud.directional = true;
            self.hud.light_azimuth_deg =
                (self.hud.light_azimuth_deg - dx * 0.4 + 180.0).rem_euclid(360.0) - 180.0;
            self.hud.light_elevation_deg =
                (self.hud.light_elevation_deg - dy * 0.3).clamp(-89.0, 89.0);
        } else if self.nav.mode() == NavMode::Fly {
            self.nav.drag_look(dx, dy);
        } else if pan {
            self.nav.drag_pan(dx, dy);
        } else {
            self.nav.drag_orbit(dx, dy);
        }
    }

    fn click(&mut self) {
        let now = Instant::now();
        let at = self.input.cursor;
        let double = self.input.last_press.is_some_and(|(t, p)| {
            now.duration_since(t) < DOUBLE_CLICK
                && (p.x - at.x).abs() + (p.y - at.y).abs() < CLICK_SLOP_PX * 2.0
        });
        self.input.last_press = if double { None } else { Some((now, at)) };
        let ray = self.ray_at(at);
        let visible: Vec<bool> = (0..self.viewer.model_count())
            .map(|i| self.viewer.is_visible(i))
            .collect();
        if double {
            self.picker.pick(Purpose::Recentre, ray, visible);
        } else if self.hud.measure_mode {
            self.picker.pick(Purpose::Measure, ray, visible);
        } else {
            self.picker.pick(Purpose::Inspect, ray, visible);
        }
    }

    fn key(&mut self, event: &KeyEvent, event_loop: &ActiveEventLoop) {
        tracing::debug!(key = ?event.physical_key, state = ?event.state, "key");
        let pressed = event.state == ElementState::Pressed;
        let PhysicalKey::Code(code) = event.physical_key else {
            return;
        };
        // Held keys: fly mode.
        let fly = &mut self.input.fly;
        match code {
            KeyCode::KeyW => fly.forward = pressed,
            KeyCode::KeyS if self.nav.mode() == NavMode::Fly => fly.back = pressed,
            KeyCode::KeyA => fly.left = pressed,
            KeyCode::KeyD => fly.right = pressed,
            KeyCode::KeyQ => fly.down = pressed,
            KeyCode::KeyE => fly.up = pressed,
            KeyCode::ShiftLeft | KeyCode::ShiftRight => fly.fast = pressed,
            _ => {}
        }
        if !pressed {
            return;
        }
        let fly_mode = self.nav.mode() == NavMode::Fly;
        match code {
            KeyCode::KeyF => {
                let m = if fly_mode {
                    NavMode::Orbit
                } else {
                    NavMode::Fly
                };
                self.action(Action::SetMode(m));
            }
            KeyCode::KeyT => self.action(Action::ToggleAutoRotate),
            KeyCode::KeyR | KeyCode::Home => self.action(Action::ResetView),
            KeyCode::KeyU => self.action(Action::SetUp(self.up.next())),
            KeyCode::KeyS if !fly_mode => self.action(Action::Screenshot),
            KeyCode::KeyC => self.action(Action::CopyCamera),
            KeyCode::KeyH | KeyCode::F1 => self.hud.visible = !self.hud.visible,
            KeyCode::KeyM => {
                self.hud.measure_mode = !self.hud.measure_mode;
                self.measure.clear();
            }
            KeyCode::KeyX => self.hud.wireframe = !self.hud.wireframe,
            KeyCode::KeyL => self.hud.directional = !self.hud.directional,
            KeyCode::KeyB => self.hud.unlit = !self.hud.unlit,
            KeyCode::KeyG => self.hud.morph = !self.hud.morph,
            KeyCode::KeyN => {
                use tessera_render::ColorMode::*;
                self.hud.color_mode = match self.hud.color_mode {
                    Natural => ByNode,
                    ByNode => ByLevel,
                    ByLevel => Natural,
                };
            }
            KeyCode::Space => self.hud.freeze = !self.hud.freeze,
            // Arrows orbit; with shift they pan (a twentieth of the window a press).
            KeyCode::ArrowLeft | KeyCode::ArrowRight | KeyCode::ArrowUp | KeyCode::ArrowDown => {
                let (dx, dy) = match code {
                    KeyCode::ArrowLeft => (-1.0, 0.0),
                    KeyCode::ArrowRight => (1.0, 0.0),
                    KeyCode::ArrowUp => (0.0, 1.0),
                    _ => (0.0, -1.0),
                };
                if self.input.shift {
                    let step = f64::from(self.config.height) / 20.0;
                    self.nav.key_pan(dx * step, -dy * step);
                } else {
                    self.nav.key_orbit(dx * 10.0, dy * 10.0);
                }
            }
            KeyCode::Equal | KeyCode::NumpadAdd | KeyCode::PageUp => self.nav.zoom(1.0, None),
            KeyCode::Minus | KeyCode::NumpadSubtract | KeyCode::PageDown => {
                self.nav.zoom(-1.0, None)
            }
            KeyCode::Escape => {
                if self.hud.measure_mode || !self.measure.is_empty() {
                    self.hud.measure_mode = false;
                    self.measure.clear();
                } else if fly_mode {
                    self.action(Action::SetMode(NavMode::Orbit));
                }
            }
            _ => {
                if let Key::Named(NamedKey::Exit) = event.logical_key {
                    event_loop.exit();
                }
            }
        }
    }
}

/// Resident set size of this process (Linux: /proc/self/statm; 0 elsewhere), for the
/// frame log: on lavapipe the GPU cache lives in host memory, so this is the figure a
/// `--memory` budget bounds.
fn current_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4096)
}

/// Pixel coordinates (from the top left) of model point `p` seen by `camera`; None
/// behind the eye.
fn project(camera: &Camera, p: [f64; 3]) -> Option<(f64, f64)> {
    let b = camera.basis();
    let v = DVec3::from(p) - DVec3::from(camera.position);
    let z = v.dot(b.forward);
    if z <= 0.0 {
        return None;
    }
    let tan_y = (0.5 * camera.fov_y_rad()).tan();
    let x = v.dot(b.right) / (z * tan_y * camera.aspect());
    let y = v.dot(b.up) / (z * tan_y);
    Some((
        (x + 1.0) * 0.5 * f64::from(camera.width),
        (1.0 - y) * 0.5 * f64::from(camera.height),
    ))
}
