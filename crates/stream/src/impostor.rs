//! Texture impostors for distant models (Aliaga, "Visualization of Complex Models Using
//! Dynamic Texture-based Simplification"): which models of a scene are drawn as a
//! texture on a plane instead of their geometry, when each texture is sampled again,
//! and the transitions between the two. The policy only: CPU, no GPU, built for wasm32
//! like the rest of the crate; a front end samples and draws what it decides
//! (`tessera_render`'s impostor cache natively).
//!
//! Regions are whole models (the paper's "subset of the scene"): a model whose bounding
//! sphere projects to less than `max_radius_px` becomes an impostor. Its texture is
//! taken from the current eye, looking at the sphere's centre with the sphere just
//! inside a square image whose side is the sphere's projected diameter (rounded up to a
//! power of two, clamped); the textured quad stands on the plane through the centre
//! facing that eye. Being a whole model, no geometry of another region crosses the
//! plane, so no border can crack (the paper's morphed borders are needed where one
//! surface is split between texture and geometry; the plane-depth approximation shows
//! only where models interpenetrate).
//!
//! Error bound (when a texture is sampled again): seen from an eye that has turned by
//! an angle `a` around the sphere's centre since the sample, points of the model at
//! different depths shift against each other by up to `radius * a`, i.e. about
//! `radius_px * a` pixels; the texture is re-sampled when that exceeds
//! `max_error_px`, or when the sphere's projected size has moved more than
//! `resample_scale` from the texture's resolution (too blurry, or wastefully sharp).
//!
//! Transitions are dissolves over `transition_frames` frames, never a one-frame swap:
//! each pixel of the region shows either the geometry or the texture, by a per-pixel
//! threshold (a dither) against the transition's progress, so the share of texture
//! pixels grows smoothly from 0 to 1 (and back); a re-sample dissolves from the old
//! texture to the new one the same way.

use glam::DVec3;
use tessera_select::Camera;

/// What the policy is asked to hold to.
#[derive(Clone, Debug, PartialEq)]
pub struct ImpostorOptions {
    pub enabled: bool,
    /// A model whose bounding sphere projects to a radius below this (pixels) is drawn
    /// as an impostor; back to geometry above `max_radius_px * hysteresis`.
    pub max_radius_px: f64,
    pub hysteresis: f64,
    /// Parallax error bound, pixels (see the module docs).
    pub max_error_px: f64,
    /// Re-sample when the projected diameter moves beyond this factor of the texture's.
    pub resample_scale: f64,
    /// Largest texture side, texels (a larger rectangle is sampled at less than a
    /// texel a pixel).
    pub max_size: u32,
    /// Texture memory of all impostors, bytes (RGBA8): models that do not fit stay
    /// geometry, the farthest first served.
    pub max_texture_bytes: u64,
    /// Textures sampled in one frame at most (each is a small render pass).
    pub max_samples_per_frame: usize,
    /// Frames a dissolve takes.
    pub transition_frames: u32,
    /// A frame time to hold (milliseconds): while frames take longer, more models
    /// become impostors (the radius threshold grows, up to `max_radius_limit_px`);
    /// while they take under 60% of it, fewer (down to `max_radius_px`).
    pub frame_budget_ms: Option<f64>,
    pub max_radius_limit_px: f64,
}

impl Default for ImpostorOptions {
    fn default() -> Self {
        ImpostorOptions {
            enabled: true,
            max_radius_px: 40.0,
            hysteresis: 1.25,
            max_error_px: 1.5,
            resample_scale: 1.5,
            max_size: 256,
            max_texture_bytes: 64 << 20,
            max_samples_per_frame: 48,
            transition_frames: 8,
            frame_budget_ms: None,
            max_radius_limit_px: 400.0,
        }
    }
}

/// How a texture was taken: with the frame's own camera, over the rectangle of the
/// image the model's sphere covers, so that at the sampling eye its texels are the
/// frame's pixels (the same rasterisation, not a resampled picture); `size` texels (the
/// rectangle's pixels, scaled down to fit `max_size` if it is larger; sides in steps of
/// 16).
#[derive(Clone, Debug, PartialEq)]
pub struct ImpostorSample {
    /// The frame camera it was taken with (world coordinates).
    pub camera: Camera,
    /// The image rectangle: left, top, width, height, whole pixels of `camera`'s image.
    pub rect: [f64; 4],
    pub size: [u32; 2],
    pub center: DVec3,
    pub radius: f64,
    /// The sphere's projected radius then, pixels.
    pub radius_px: f64,
    /// The cut it shows ([`ModelSphere::cut`] then).
    pub cut: u64,
}

impl ImpostorSample {
    /// The sample of the sphere (`center`, `radius`) seen by `camera`, at most
    /// `max_size` texels a side; None when the sphere is not wholly in front of the eye.
    pub fn new(
        camera: &Camera,
        center: DVec3,
        radius: f64,
        max_size: u32,
    ) -> Option<ImpostorSample> {
        let b = camera.basis();
        let eye = DVec3::from(camera.position);
        let z = (center - eye).dot(b.forward);
        if z <= radius * 1.001 {
            return None;
        }
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let scale = camera.projection_scale_px();
        let cx = w * 0.5 + (center - eye).dot(b.right) / z * scale;
        let cy = h * 0.5 - (center - eye).dot(b.up) / z * scale;
        // The projected sphere's extent, with room for its off-axis stretch and for
        // the filter at the silhouette.
        let r_px = Impostors::radius_px(camera, center, radius);
        let half = r_px * (1.0 + 0.5 * ((cx - w * 0.5).hypot(cy - h * 0.5) / scale).powi(2)) + 2.0;
        let (x0, y0) = ((cx - half).floor(), (cy - half).floor());
        // Sides in steps of 16 pixels (a front end keeps a depth buffer a size).
        let side = ((cx + half).ceil() - x0)
            .max((cy + half).ceil() - y0)
            .max(1.0);
        let side = (side / 16.0).ceil() * 16.0;
        let texels = side.min(f64::from(max_size.max(16) / 16 * 16)) as u32;
        Some(ImpostorSample {
            camera: camera.clone(),
            rect: [x0, y0, side, side],
            size: [texels, texels],
            center,
            radius,
            radius_px: r_px,
            cut: 0,
        })
    }

    /// The sampling eye.
    pub fn eye(&self) -> DVec3 {
        DVec3::from(self.camera.position)
    }

    /// Bytes of its texture (RGBA8).
    pub fn bytes(&self) -> u64 {
        u64::from(self.size[0]) * u64::from(self.size[1]) * 4
    }

    /// The distances along the view direction that hold the sphere (near, far).
    pub fn planes(&self) -> (f64, f64) {
        let b = self.camera.basis();
        let z = (self.center - self.eye()).dot(b.forward);
        let r = self.radius * 1.05;
        ((z - r).max(z * 1e-3), z + r)
    }

    /// The clip-space map taking the camera's whole image to the rectangle (applied
    /// after its projection, `crop * proj * view`), column-major.
    pub fn crop(&self) -> [[f32; 4]; 4] {
        let (w, h) = (f64::from(self.camera.width), f64::from(self.camera.height));
        let [x0, y0, rw, rh] = self.rect;
        let (ax, bx) = (w / rw, (w - 2.0 * x0) / rw - 1.0);
        let (ay, by) = (h / rh, 1.0 - h / rh + 2.0 * y0 / rh);
        [
            [ax as f32, 0.0, 0.0, 0.0],
            [0.0, ay as f32, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [bx as f32, by as f32, 0.0, 1.0],
        ]
    }

    /// The quad the texture is drawn on: the rectangle's slice of the camera's
    /// frustum on the plane through the sphere's centre facing the view direction
    /// (its centre, and the half-extent vectors along the image's right and up), so
    /// that from the sampling eye the texture maps exactly onto it.
    pub fn quad(&self) -> (DVec3, DVec3, DVec3) {
        let b = self.camera.basis();
        let eye = self.eye();
        let z = (self.center - eye).dot(b.forward);
        let (w, h) = (f64::from(self.camera.width), f64::from(self.camera.height));
        let scale = self.camera.projection_scale_px();
        let [x0, y0, rw, rh] = self.rect;
        let (mx, my) = (x0 + rw * 0.5 - w * 0.5, h * 0.5 - (y0 + rh * 0.5));
        let center = eye + b.forward * z + b.right * (mx / scale * z) + b.up * (my / scale * z);
        (
            center,
            b.right * (rw * 0.5 / scale * z),
            b.up * (rh * 0.5 / scale * z),
        )
    }
}

/// What one model shows this frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ImpostorDraw {
    /// Draw the geometry, keeping the pixels whose dither threshold is in `keep`
    /// (`[0, 1)` all of them).
    pub geometry: Option<[f32; 2]>,
    /// Draw texture `slot` (the front end's), keeping `keep`.
    pub textures: Vec<(usize, [f32; 2])>,
}

#[derive(Clone, Debug, PartialEq)]
enum State {
    Geometry,
    /// Dissolving from geometry to texture (`from_texture: None`) or from an old texture
    /// to a new one; `t` frames done of the transition.
    Dissolve {
        from: Option<usize>,
        to: usize,
        t: u32,
    },
    Impostor(usize),
    /// Dissolving from a texture back to geometry.
    Back {
        from: usize,
        t: u32,
    },
}

/// A texture the front end holds for the policy.
#[derive(Clone, Debug)]
struct Slot {
    sample: ImpostorSample,
    /// Sampled yet (the front end renders it, then calls [`Impostors::sampled`]).
    ready: bool,
    in_use: bool,
}

/// This frame's figures.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ImpostorStats {
    /// Models drawn as a texture only.
    pub impostors: u32,
    /// Models in a dissolve (either way, or between two textures).
    pub transitioning: u32,
    /// Textures to sample this frame.
    pub sampling: u32,
    /// Bytes of the textures held.
    pub texture_bytes: u64,
    /// Triangles of the cuts not drawn because a texture stands in (the front end's
    /// count).
    pub triangles_saved: u64,
    /// The projected radius below which models become impostors now, pixels.
    pub threshold_px: f64,
}

/// The impostor policy of a scene. See the module docs.
pub struct Impostors {
    pub options: ImpostorOptions,
    /// The radius threshold in force (`options.max_radius_px`, raised by the frame
    /// budget).
    threshold_px: f64,
    states: Vec<State>,
    slots: Vec<Slot>,
    /// Slots to sample (the front end's work list for this frame).
    to_sample: Vec<(usize, usize)>,
    stats: ImpostorStats,
}

/// A model's bounding sphere in world coordinates, as the policy sees it.
#[derive(Clone, Copy, Debug)]
pub struct ModelSphere {
    pub center: DVec3,
    pub radius: f64,
    /// Shown at all (a hidden model is neither).
    pub visible: bool,
    /// A signature of the cut the model draws now (the front end's: a hash of its
    /// nodes): a texture sampled from another cut (coarser nodes while it streamed in)
    /// is sampled again.
    pub cut: u64,
}

impl Impostors {
    pub fn new(options: ImpostorOptions, models: usize) -> Impostors {
        Impostors {
            threshold_px: options.max_radius_px,
            options,
            states: vec![State::Geometry; models],
            slots: Vec::new(),
            to_sample: Vec::new(),
            stats: ImpostorStats::default(),
        }
    }

    /// The last frame took `ms`: with a frame budget, the threshold follows (see
    /// [`ImpostorOptions::frame_budget_ms`]).
    pub fn frame_took(&mut self, ms: f64) {
        let Some(budget) = self.options.frame_budget_ms else {
            return;
        };
        let base = self.options.max_radius_px;
        let limit = self.options.max_radius_limit_px.max(base);
        if ms > budget {
            self.threshold_px = (self.threshold_px.max(1.0) * 1.15).min(limit);
        } else if ms < 0.6 * budget {
            self.threshold_px = (self.threshold_px / 1.1).max(base);
        }
    }

    /// The sphere's projected radius in pixels from `camera` (infinite when the eye is
    /// inside it).
    pub fn radius_px(camera: &Camera, center: DVec3, radius: f64) -> f64 {
        let d = (center - DVec3::from(camera.position)).length();
        if d <= radius {
            return f64::INFINITY;
        }
        radius / (d * d - radius * radius).sqrt() * camera.projection_scale_px()
    }

    fn held_bytes(&self) -> u64 {
        self.slots
            .iter()
            .filter(|s| s.in_use)
            .map(|s| s.sample.bytes())
            .sum()
    }

    fn new_slot(&mut self, sample: ImpostorSample) -> usize {
        let slot = Slot {
            sample,
            ready: false,
            in_use: true,
        };
        match self.slots.iter().position(|s| !s.in_use) {
            Some(i) => {
                self.slots[i] = slot;
                i
            }
            None => {
                self.slots.push(slot);
                self.slots.len() - 1
            }
        }
    }

    /// Whether texture `slot`, taken as `sample`, is still within the error bound from
    /// `camera` (see the module docs).
    pub fn within_bound(&self, sample: &ImpostorSample, camera: &Camera) -> bool {
        let eye = DVec3::from(camera.position);
        let (a, b) = (
            (sample.eye() - sample.center).normalize_or_zero(),
            (eye - sample.center).normalize_or_zero(),
        );
        let angle = a.dot(b).clamp(-1.0, 1.0).acos();
        let r_px = Self::radius_px(camera, sample.center, sample.radius);
        let scale = self.options.resample_scale;
        let size_ok = r_px <= sample.radius_px * scale && r_px * scale >= sample.radius_px;
        // The camera's image size changed: the texels no longer match its pixels.
        let same_image =
            camera.width == sample.camera.width && camera.height == sample.camera.height;
        r_px * angle <= self.options.max_error_px && size_ok && same_image
    }

    /// Decides this frame for `camera` over the models' `spheres` (world coordinates):
    /// which show geometry, which a texture, which dissolve; and which textures the
    /// front end must sample now ([`Impostors::to_sample`], before drawing).
    pub fn update(&mut self, camera: &Camera, spheres: &[ModelSphere]) {
        self.to_sample.clear();
        if self.states.len() != spheres.len() {
            self.states.resize(spheres.len(), State::Geometry);
        }
        let mut o = self.options.clone();
        o.max_radius_px = self.threshold_px;
        let frames = o.transition_frames.max(1);
        // Textures out of their bound first (they show wrong until re-sampled), then the
        // smallest models first: when the samples of a frame or the texture memory run
        // short, the models that cost the least texture for the triangles they save get
        // them.
        let mut order: Vec<(usize, f64, bool)> = spheres
            .iter()
            .enumerate()
            .map(|(i, &s)| {
                let stale = match self.states[i] {
                    State::Impostor(slot)
                    | State::Dissolve { to: slot, .. }
                    | State::Back { from: slot, .. } => {
                        let sample = &self.slots[slot].sample;
                        !self.within_bound(sample, camera) || sample.cut != s.cut
                    }
                    State::Geometry => false,
                };
                (i, Self::radius_px(camera, s.center, s.radius), stale)
            })
            .collect();
        order.sort_by(|a, b| b.2.cmp(&a.2).then(a.1.total_cmp(&b.1)));
        for (i, r_px, stale) in order {
            let s = spheres[i];
            let state = self.states[i].clone();
            let far = o.enabled && s.visible && r_px < o.max_radius_px;
            let near = !o.enabled || !s.visible || r_px > o.max_radius_px * o.hysteresis;
            let sample =
                ImpostorSample::new(camera, s.center, s.radius, o.max_size).map(|mut x| {
                    x.cut = s.cut;
                    x
                });
            // Not wholly in front of the eye: geometry.
            let far = far && sample.is_some();
            let near = near || sample.is_none();
            let sample = sample.unwrap_or_else(|| ImpostorSample {
                camera: camera.clone(),
                rect: [0.0, 0.0, 1.0, 1.0],
                size: [1, 1],
                center: s.center,
                radius: s.radius,
                radius_px: r_px,
                cut: s.cut,
            });
            let bytes = sample.bytes();
            let can_sample = |me: &Self| {
                me.to_sample.len() < o.max_samples_per_frame
                    && me.held_bytes() + bytes <= o.max_texture_bytes
            };
            self.states[i] = match state {
                State::Geometry if far && can_sample(self) => {
                    let slot = self.new_slot(sample.clone());
                    self.to_sample.push((i, slot));
                    State::Dissolve {
                        from: None,
                        to: slot,
                        t: 0,
                    }
                }
                State::Geometry => State::Geometry,
                State::Impostor(slot) if near => State::Back { from: slot, t: 0 },
                State::Impostor(slot) if stale && can_sample(self) => {
                    // The new texture dissolves in over the old: the two differ by the
                    // error bound, spread over the transition's frames.
                    let to = self.new_slot(sample.clone());
                    self.to_sample.push((i, to));
                    State::Dissolve {
                        from: Some(slot),
                        to,
                        t: 0,
                    }
                }
                // Out of its bound with no sample left this frame: the geometry comes
                // back (dissolving) rather than a texture showing wrong.
                State::Impostor(slot) if stale => State::Back { from: slot, t: 0 },
                State::Impostor(slot) => State::Impostor(slot),
                State::Dissolve { from, to, t } => {
                    // A texture out of its bound mid-dissolve is taken again (the eye
                    // moves fast): the dissolve goes on from an exact picture.
                    let to = self.refresh(i, to, stale, &sample, can_sample(self));
                    if near {
                        // Turned back before the end: back to geometry from the new one.
                        if let Some(f) = from {
                            self.slots[f].in_use = false;
                        }
                        State::Back {
                            from: to,
                            t: frames - t.min(frames),
                        }
                    } else if t + 1 >= frames {
                        if let Some(f) = from {
                            self.slots[f].in_use = false;
                        }
                        State::Impostor(to)
                    } else {
                        State::Dissolve { from, to, t: t + 1 }
                    }
                }
                State::Back { from, t } => {
                    let from = self.refresh(i, from, stale, &sample, can_sample(self));
                    if far {
                        State::Dissolve {
                            from: None,
                            to: from,
                            t: frames - t.min(frames),
                        }
                    } else if t + 1 >= frames {
                        self.slots[from].in_use = false;
                        State::Geometry
                    } else {
                        State::Back { from, t: t + 1 }
                    }
                }
            };
        }
        let mut st = ImpostorStats {
            threshold_px: self.threshold_px,
            sampling: self.to_sample.len() as u32,
            texture_bytes: self.held_bytes(),
            ..Default::default()
        };
        for s in &self.states {
            match s {
                State::Impostor(_) => st.impostors += 1,
                State::Dissolve { .. } | State::Back { .. } => st.transitioning += 1,
                State::Geometry => {}
            }
        }
        self.stats = st;
    }

    /// Texture `slot` of model `i`, or a new one sampled now in its place when it is
    /// `stale` and a sample is left.
    fn refresh(
        &mut self,
        i: usize,
        slot: usize,
        stale: bool,
        sample: &ImpostorSample,
        can_sample: bool,
    ) -> usize {
        if !(stale && can_sample) {
            return slot;
        }
        self.slots[slot].in_use = false;
        let to = self.new_slot(sample.clone());
        self.to_sample.push((i, to));
        to
    }

    /// The textures to sample this frame: (model, slot), each with [`Impostors::sample`].
    pub fn to_sample(&self) -> &[(usize, usize)] {
        &self.to_sample
    }

    /// How texture `slot` is (to be) taken.
    pub fn sample(&self, slot: usize) -> &ImpostorSample {
        &self.slots[slot].sample
    }

    /// Whether texture `slot` is held (a free one's GPU texture can go).
    pub fn in_use(&self, slot: usize) -> bool {
        self.slots.get(slot).is_some_and(|s| s.in_use)
    }

    /// Slots made so far (held or free).
    pub fn slot_count(&self) -> usize {
        self.slots.len()
    }

    /// Adds the front end's count of triangles a texture stood in for this frame.
    pub fn set_triangles_saved(&mut self, triangles: u64) {
        self.stats.triangles_saved = triangles;
    }

    /// The front end has rendered texture `slot`.
    pub fn sampled(&mut self, slot: usize) {
        self.slots[slot].ready = true;
    }

    /// What model `i` draws this frame (after [`Impostors::update`] and the samples).
    pub fn draw(&self, i: usize) -> ImpostorDraw {
        let frames = self.options.transition_frames.max(1) as f32;
        let all = [0.0, 1.0];
        let ready = |slot: usize| self.slots[slot].ready;
        match self.states.get(i) {
            None | Some(State::Geometry) => ImpostorDraw {
                geometry: Some(all),
                textures: vec![],
            },
            Some(State::Impostor(slot)) => ImpostorDraw {
                geometry: None,
                textures: vec![(*slot, all)],
            },
            Some(&State::Dissolve { from, to, t }) => {
                // Progress after this frame's step: the texture's share of the pixels.
                let f = ((t + 1) as f32 / frames).min(1.0);
                let (old_keep, new_keep) = ([f, 1.0], [0.0, f]);
                let mut textures = Vec::new();
                if ready(to) {
                    textures.push((to, new_keep));
                }
                match from {
                    Some(old) => {
                        textures.push((old, if ready(to) { old_keep } else { all }));
                        ImpostorDraw {
                            geometry: None,
                            textures,
                        }
                    }
                    None => ImpostorDraw {
                        geometry: Some(if ready(to) { old_keep } else { all }),
                        textures,
                    },
                }
            }
            Some(&State::Back { from, t }) => {
                let f = ((t + 1) as f32 / frames).min(1.0);
                ImpostorDraw {
                    geometry: Some([0.0, f]),
                    textures: vec![(from, [f, 1.0])],
                }
            }
        }
    }

    /// This frame's figures.
    pub fn stats(&self) -> ImpostorStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(x: f64, y: f64, z: f64) -> Camera {
        Camera {
            position: [x, y, z],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 50.0,
            width: 1280,
            height: 720,
        }
    }

    fn sphere() -> [ModelSphere; 1] {
        [ModelSphere {
            center: DVec3::ZERO,
            radius: 1.0,
            visible: true,
            cut: 7,
        }]
    }

    /// Runs frames from `c`, sampling what is asked; returns each frame's draw.
    fn run(p: &mut Impostors, c: &Camera, frames: usize) -> Vec<ImpostorDraw> {
        (0..frames)
            .map(|_| {
                p.update(c, &sphere());
                for &(_, slot) in p.to_sample().to_vec().iter() {
                    p.sampled(slot);
                }
                p.draw(0)
            })
            .collect()
    }

    #[test]
    fn a_far_model_dissolves_into_a_texture_and_back_never_in_one_frame() {
        let mut p = Impostors::new(ImpostorOptions::default(), 1);
        // Near: 1 unit at 3 units is far more than 40 px.
        let near = run(&mut p, &cam(3.0, 0.0, 0.0), 3);
        assert!(near
            .iter()
            .all(|d| d.geometry == Some([0.0, 1.0]) && d.textures.is_empty()));
        // Far: 1 unit at 100 units is ~7.7 px.
        let far = run(&mut p, &cam(100.0, 0.0, 0.0), 12);
        let frames = p.options.transition_frames as usize;
        // The texture's share of the pixels grows frame by frame to 1.
        let mut last = 0.0;
        for d in &far[..frames] {
            let share = d.textures.iter().map(|(_, k)| k[1] - k[0]).sum::<f32>();
            let geo = d.geometry.map_or(0.0, |k| k[1] - k[0]);
            assert!(
                (share + geo - 1.0).abs() < 1e-6,
                "{d:?}: every pixel one or the other"
            );
            assert!(
                share > last && share - last <= 1.0 / frames as f32 + 1e-6,
                "{d:?}"
            );
            last = share;
        }
        assert!(far[frames..]
            .iter()
            .all(|d| d.geometry.is_none() && d.textures.len() == 1));
        assert_eq!(p.stats().impostors, 1);
        // About 2 r + 4 texels a side (the rectangle the sphere covers), in 16s.
        let side = u64::from(p.sample(0).size[0]);
        assert_eq!(side, 32, "~7.7 px radius");
        assert_eq!(p.stats().texture_bytes, side * side * 4);
        // Near again: back to geometry over the same number of frames.
        let back = run(&mut p, &cam(3.0, 0.0, 0.0), frames + 2);
        assert!(back[0].geometry.is_some() && !back[0].textures.is_empty());
        assert_eq!(
            back[frames],
            ImpostorDraw {
                geometry: Some([0.0, 1.0]),
                textures: vec![]
            }
        );
        assert_eq!(p.stats().texture_bytes, 0, "the texture is given back");
    }

    #[test]
    fn turning_past_the_error_bound_resamples() {
        let mut p = Impostors::new(ImpostorOptions::default(), 1);
        run(&mut p, &cam(100.0, 0.0, 0.0), 10);
        let r_px = Impostors::radius_px(&cam(100.0, 0.0, 0.0), DVec3::ZERO, 1.0);
        // Within the bound (r_px * angle below 1.5 px): the same texture.
        let small = 0.5 / r_px;
        run(
            &mut p,
            &cam(100.0 * small.cos(), 100.0 * small.sin(), 0.0),
            2,
        );
        assert_eq!(p.stats().sampling, 0);
        assert_eq!(p.stats().impostors, 1);
        // Past it: a new texture, dissolved into from the old.
        let big = 3.0 / r_px;
        let c = cam(100.0 * big.cos(), 100.0 * big.sin(), 0.0);
        p.update(&c, &sphere());
        assert_eq!(p.stats().sampling, 1);
        let (_, slot) = p.to_sample()[0];
        p.sampled(slot);
        let d = p.draw(0);
        assert!(d.geometry.is_none() && d.textures.len() == 2, "{d:?}");
        assert!(p.within_bound(p.sample(slot), &c));
        // Once dissolved, the old texture is given back.
        let frames = p.options.transition_frames as usize;
        run(&mut p, &c, frames);
        assert_eq!(p.stats().texture_bytes, p.sample(slot).bytes());
    }

    #[test]
    fn a_texture_of_another_cut_is_sampled_again() {
        let mut p = Impostors::new(ImpostorOptions::default(), 1);
        let c = cam(100.0, 0.0, 0.0);
        run(&mut p, &c, 10);
        assert_eq!(p.stats().sampling, 0);
        // The model's cut refined (more of it streamed in): a new sample.
        let mut refined = sphere();
        refined[0].cut = 8;
        p.update(&c, &refined);
        assert_eq!(p.stats().sampling, 1);
        assert_eq!(p.sample(p.to_sample()[0].1).cut, 8);
    }

    #[test]
    fn a_frame_budget_raises_the_threshold_while_frames_are_slow() {
        let o = ImpostorOptions {
            frame_budget_ms: Some(33.0),
            ..Default::default()
        };
        let mut p = Impostors::new(o, 1);
        // 1 unit at 30 units: ~26 px, above no threshold yet (40 px): an impostor.
        // At 15 units (~52 px) geometry, until slow frames raise the threshold.
        let c = cam(15.0, 0.0, 0.0);
        run(&mut p, &c, 2);
        assert_eq!(p.stats().impostors + p.stats().transitioning, 0);
        for _ in 0..10 {
            p.frame_took(80.0);
        }
        run(&mut p, &c, 12);
        assert!(p.stats().threshold_px > 52.0, "{:?}", p.stats());
        assert_eq!(p.stats().impostors, 1);
        // Fast frames bring it back down to the configured one (and the model back).
        for _ in 0..40 {
            p.frame_took(5.0);
        }
        run(&mut p, &c, 12);
        assert_eq!(p.stats().threshold_px, 40.0);
        assert_eq!(p.stats().impostors, 0);
    }

    #[test]
    fn the_texture_budget_keeps_models_as_geometry() {
        let o = ImpostorOptions {
            max_texture_bytes: 32 * 32 * 4,
            ..Default::default()
        };
        let mut p = Impostors::new(o, 2);
        let spheres = [
            ModelSphere {
                center: DVec3::ZERO,
                radius: 1.0,
                visible: true,
                cut: 1,
            },
            ModelSphere {
                center: DVec3::new(0.0, 5.0, 0.0),
                radius: 1.0,
                visible: true,
                cut: 1,
            },
        ];
        p.update(&cam(100.0, 0.0, 0.0), &spheres);
        assert_eq!(p.stats().sampling, 1, "one texture fits");
        assert!(p.stats().texture_bytes <= 32 * 32 * 4);
        // Disabled: everything geometry.
        let mut off = Impostors::new(
            ImpostorOptions {
                enabled: false,
                ..Default::default()
            },
            2,
        );
        off.update(&cam(100.0, 0.0, 0.0), &spheres);
        let s = off.stats();
        assert_eq!(
            (s.impostors, s.transitioning, s.sampling, s.texture_bytes),
            (0, 0, 0, 0)
        );
    }
}
