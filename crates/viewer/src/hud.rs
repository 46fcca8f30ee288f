//! The HUD (egui): statistics of the streaming core, display controls, navigation and
//! light, picked point and measure. The HUD only edits [`Hud`] and returns
//! [`Action`]s; the app applies them (one place changes the viewer).

use std::collections::VecDeque;

use glam::DVec3;
use tessera_nav::{Mode as NavMode, UpAxis, UP_AXES};
use tessera_render::{ColorMode, FrameStats};

/// Frames of the frame-time plot.
pub const HISTORY: usize = 240;

/// The HUD's switches and what it remembers between frames.
pub struct Hud {
    pub visible: bool,
    pub tolerance_px: f32,
    pub color_mode: ColorMode,
    pub wireframe: bool,
    pub freeze: bool,
    pub prefetch: bool,
    /// Geomorphing between levels.
    pub morph: bool,
    pub unlit: bool,
    /// Directional light instead of the head light.
    pub directional: bool,
    /// Directional light: angle around the up axis and above the horizon, degrees.
    pub light_azimuth_deg: f64,
    pub light_elevation_deg: f64,
    pub measure_mode: bool,
    /// Wall time between frames, milliseconds (newest last).
    pub frame_ms: VecDeque<f32>,
}

impl Hud {
    pub fn new(tolerance_px: f32, prefetch: bool, morph: bool) -> Hud {
        Hud {
            visible: true,
            tolerance_px,
            color_mode: ColorMode::Natural,
            wireframe: false,
            freeze: false,
            prefetch,
            morph,
            unlit: false,
            directional: false,
            light_azimuth_deg: 35.0,
            light_elevation_deg: 15.0,
            measure_mode: false,
            frame_ms: VecDeque::with_capacity(HISTORY),
        }
    }

    pub fn push_frame_ms(&mut self, ms: f32) {
        if self.frame_ms.len() == HISTORY {
            self.frame_ms.pop_front();
        }
        self.frame_ms.push_back(ms);
    }

    /// The directional light's direction (toward the light), model coordinates.
    pub fn light_dir(&self, up: UpAxis) -> [f64; 3] {
        let u = up.vector();
        let (a, b) = u.any_orthonormal_pair();
        let (az, el) = (
            self.light_azimuth_deg.to_radians(),
            self.light_elevation_deg.to_radians(),
        );
        let d: DVec3 = (a * az.cos() + b * az.sin()) * el.cos() + u * el.sin();
        d.to_array()
    }
}

/// What the HUD asks the app to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    ResetView,
    Screenshot,
    CopyCamera,
    SetUp(UpAxis),
    SetMode(NavMode),
    ToggleAutoRotate,
    ClearMeasure,
    /// Show or hide model `i` of the scene.
    SetVisible(usize, bool),
    Quit,
}

/// One model of the scene, for the HUD's list.
pub struct ModelInfo {
    pub name: String,
    pub visible: bool,
    pub triangles: u64,
    pub gpu_bytes: u64,
    /// Its share of the GPU budget this frame (0 when it is not split).
    pub gpu_budget: u64,
}

/// Figures the HUD shows (read-only).
pub struct Info<'a> {
    pub models: &'a [ModelInfo],
    pub adapter: &'a str,
    pub stats: &'a FrameStats,
    pub gpu_budget: u64,
    pub ram_budget: u64,
    pub bytes_read_per_s: f64,
    pub up: UpAxis,
    pub mode: NavMode,
    pub auto_rotate: bool,
    pub can_wireframe: bool,
    /// Picked point (model coordinates), whether at full resolution, pick time.
    pub picked: Option<([f64; 3], bool, f64)>,
    pub measure: &'a [[f64; 3]],
    pub picks_pending: usize,
    pub message: Option<&'a str>,
    pub units_step: f64,
    /// Screen positions (points, not pixels) of the measured points, and of the picked
    /// point, where they are in front of the camera.
    pub measure_screen: Vec<egui::Pos2>,
    pub picked_screen: Option<egui::Pos2>,
    /// The impostors' figures (None: off).
    pub impostors: Option<tessera_render::ImpostorStats>,
}

fn mib(b: u64) -> f64 {
    b as f64 / (1024.0 * 1024.0)
}

/// Draws the HUD; returns the actions asked for.
pub fn draw(ctx: &egui::Context, hud: &mut Hud, info: &Info) -> Vec<Action> {
    let mut actions = Vec::new();
    if let Some(m) = info.message {
        egui::Area::new(egui::Id::unique("tessera-message"))
            .anchor(egui::Align2::CENTER_BOTTOM, [0.0, -16.0])
            .show(ctx, |ui| {
                egui::Frame::popup(ui.style()).show(ui, |ui| ui.label(m));
            });
    }
    // Markers over the model: the picked point, the measured points and their segment.
    let painter = ctx.layer_painter(egui::LayerId::new(
        egui::Order::Background,
        egui::Id::unique("tessera-markers"),
    ));
    let yellow = egui::Color32::from_rgb(255, 210, 60);
    if let [a, b] = info.measure_screen[..] {
        painter.line_segment([a, b], egui::Stroke::new(2.0, yellow));
    }
    for &p in &info.measure_screen {
        painter.circle(p, 4.0, yellow, egui::Stroke::new(1.0, egui::Color32::BLACK));
    }
    if let Some(p) = info.picked_screen {
        painter.circle_stroke(p, 6.0, egui::Stroke::new(1.5, egui::Color32::WHITE));
    }
    if !hud.visible {
        return actions;
    }
    egui::Window::new("Tessera")
        .default_pos([10.0, 10.0])
        .default_width(300.0)
        .resizable(false)
        .show(ctx, |ui| {
            let s = info.stats;
            if let [m] = info.models {
                ui.label(egui::RichText::new(&m.name).strong());
            } else {
                // Several models: one budget, split by what each view needs.
                for (i, m) in info.models.iter().enumerate() {
                    ui.horizontal(|ui| {
                        let mut on = m.visible;
                        if ui
                            .checkbox(&mut on, egui::RichText::new(&m.name).strong())
                            .changed()
                        {
                            actions.push(Action::SetVisible(i, on));
                        }
                        ui.label(
                            egui::RichText::new(format!(
                                "{} tris, {:.0}/{:.0} MiB",
                                m.triangles,
                                mib(m.gpu_bytes),
                                mib(m.gpu_budget)
                            ))
                            .small(),
                        );
                    });
                }
            }
            ui.label(egui::RichText::new(info.adapter).small());
            let last = hud.frame_ms.back().copied().unwrap_or(0.0);
            let fps = if last > 0.0 { 1000.0 / last } else { 0.0 };
            ui.label(format!(
                "{fps:5.1} fps   frame {last:5.1} ms   render {:5.1} ms",
                s.frame_ms
            ));
            frame_plot(ui, &hud.frame_ms);
            // One row a figure: (label, value).
            let mut rows = vec![
                ("triangles", format!("{}", s.triangles)),
                (
                    "patches",
                    format!("{} (level <= {})", s.selected_nodes, s.max_level),
                ),
                (
                    "GPU cache",
                    format!(
                        "{:.0} / {:.0} MiB",
                        mib(s.gpu_resident_bytes),
                        mib(info.gpu_budget)
                    ),
                ),
                (
                    "RAM cache",
                    format!(
                        "{:.0} / {:.0} MiB",
                        mib(s.ram_resident_bytes),
                        mib(info.ram_budget)
                    ),
                ),
                ("pending loads", format!("{}", s.pending_loads)),
                (
                    "morph ratio",
                    format!("mean {:.2}, max {:.2}", s.morph_mean, s.morph_max),
                ),
                (
                    "read",
                    format!("{:.1} MiB/s", info.bytes_read_per_s / 1048576.0),
                ),
            ];
            if let Some(im) = &info.impostors {
                rows.push((
                    "impostors",
                    format!(
                        "{} drawn, {} dissolving, {:.1} MiB, {} triangles saved",
                        im.impostors,
                        im.transitioning,
                        mib(im.texture_bytes),
                        im.triangles_saved
                    ),
                ));
            }
            if s.failed_patches > 0 {
                rows.push((
                    "failed patches",
                    format!("{} (parents drawn)", s.failed_patches),
                ));
            }
            egui::Grid::new("stats").num_columns(2).show(ui, |ui| {
                for (label, value) in rows {
                    ui.label(label);
                    ui.label(value);
                    ui.end_row();
                }
            });
            ui.separator();
            ui.add(
                egui::Slider::new(&mut hud.tolerance_px, 0.25..=16.0)
                    .logarithmic(true)
                    .text("tolerance px"),
            );
            ui.horizontal(|ui| {
                ui.label("colour");
                ui.selectable_value(&mut hud.color_mode, ColorMode::Natural, "model");
                ui.selectable_value(&mut hud.color_mode, ColorMode::ByNode, "node");
                ui.selectable_value(&mut hud.color_mode, ColorMode::ByLevel, "level");
            });
            ui.horizontal(|ui| {
                ui.add_enabled(
                    info.can_wireframe,
                    egui::Checkbox::new(&mut hud.wireframe, "wireframe (X)"),
                );
                ui.checkbox(&mut hud.freeze, "freeze cut (Space)");
            });
            ui.horizontal(|ui| {
                ui.checkbox(&mut hud.prefetch, "prefetch");
                ui.checkbox(&mut hud.morph, "morph (G)");
                ui.checkbox(&mut hud.unlit, "unlit (B)");
            });
            ui.horizontal(|ui| {
                ui.label("light");
                ui.selectable_value(&mut hud.directional, false, "head");
                ui.selectable_value(&mut hud.directional, true, "directional (L)");
            });
            if hud.directional {
                ui.add(
                    egui::Slider::new(&mut hud.light_azimuth_deg, -180.0..=180.0).text("azimuth"),
                );
                ui.add(
                    egui::Slider::new(&mut hud.light_elevation_deg, -89.0..=89.0).text("elevation"),
                );
                ui.label(egui::RichText::new("Ctrl + drag moves the light").small());
            }
            ui.separator();
            ui.horizontal(|ui| {
                ui.label("up");
                let mut up = info.up;
                egui::ComboBox::from_id_salt("up")
                    .selected_text(up.to_string())
                    .width(50.0)
                    .show_ui(ui, |ui| {
                        for a in UP_AXES {
                            ui.selectable_value(&mut up, a, a.to_string());
                        }
                    });
                if up != info.up {
                    actions.push(Action::SetUp(up));
                }
                ui.label("(U)");
                let mut mode = info.mode;
                ui.selectable_value(&mut mode, NavMode::Orbit, "orbit");
                ui.selectable_value(&mut mode, NavMode::Trackball, "trackball");
                ui.selectable_value(&mut mode, NavMode::Fly, "fly (F)");
                if mode != info.mode {
                    actions.push(Action::SetMode(mode));
                }
            });
            ui.horizontal(|ui| {
                if ui.button("reset view (R)").clicked() {
                    actions.push(Action::ResetView);
                }
                let spin = if info.auto_rotate {
                    "stop turntable (T)"
                } else {
                    "turntable (T)"
                };
                if ui.button(spin).clicked() {
                    actions.push(Action::ToggleAutoRotate);
                }
            });
            ui.horizontal(|ui| {
                if ui.button("screenshot (S)").clicked() {
                    actions.push(Action::Screenshot);
                }
                if ui.button("copy camera (C)").clicked() {
                    actions.push(Action::CopyCamera);
                }
                if ui.button("quit").clicked() {
                    actions.push(Action::Quit);
                }
            });
            ui.separator();
            ui.checkbox(&mut hud.measure_mode, "measure (M): click two points");
            if let Some((p, exact, ms)) = info.picked {
                ui.label(format!("picked {:.6}, {:.6}, {:.6}", p[0], p[1], p[2]));
                ui.label(
                    egui::RichText::new(format!(
                        "{} in {ms:.1} ms (grid step {:.3e})",
                        if exact {
                            "full resolution"
                        } else {
                            "finest level read so far"
                        },
                        info.units_step
                    ))
                    .small(),
                );
            }
            if info.picks_pending > 0 {
                ui.label("picking…");
            }
            if let [a, b] = info.measure {
                let (a, b) = (DVec3::from(*a), DVec3::from(*b));
                let u = info.up.vector();
                ui.label(format!("distance {:.6}", (b - a).length()));
                ui.label(format!(
                    "height difference {:.6} (along {})",
                    (b - a).dot(u),
                    info.up
                ));
                if ui.button("clear measure").clicked() {
                    actions.push(Action::ClearMeasure);
                }
            } else if hud.measure_mode && info.measure.len() == 1 {
                ui.label("click the second point");
            }
            ui.label(
                egui::RichText::new(
                    "drag orbit · shift/right drag pan · wheel zoom to cursor · \
                     double-click recentre · H hides this",
                )
                .small(),
            );
        });
    actions
}

/// A small plot of the frame times (the last [`HISTORY`] frames), scaled to the
/// largest, with the 16.7 ms line.
fn frame_plot(ui: &mut egui::Ui, ms: &VecDeque<f32>) {
    let (rect, _) = ui.allocate_exact_size(egui::vec2(280.0, 48.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, egui::Color32::from_black_alpha(90));
    let top = ms.iter().copied().fold(33.4f32, f32::max);
    let y = |v: f32| rect.bottom() - (v / top).min(1.0) * rect.height();
    painter.hline(
        rect.x_range(),
        y(16.7),
        egui::Stroke::new(1.0, egui::Color32::from_rgb(70, 110, 70)),
    );
    let n = ms.len().max(2);
    let pts: Vec<egui::Pos2> = ms
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            egui::pos2(
                rect.left() + rect.width() * i as f32 / (HISTORY - 1).max(n - 1) as f32,
                y(v),
            )
        })
        .collect();
    painter.add(egui::Shape::line(
        pts,
        egui::Stroke::new(1.0, egui::Color32::from_rgb(230, 200, 90)),
    ));
    painter.text(
        rect.left_top() + egui::vec2(4.0, 2.0),
        egui::Align2::LEFT_TOP,
        format!("max {top:.0} ms"),
        egui::FontId::monospace(10.0),
        egui::Color32::GRAY,
    );
}
