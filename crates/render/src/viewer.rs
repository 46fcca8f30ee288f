//! A view of one model, or of a scene of several: the streaming core's [`Scheduler`]
//! (one per model) driving the GPU cache and the pager, one call per frame. Shared by
//! `tessera render`, the tests and the window.
//!
//! A scene: every model keeps its own scheduler, pager and local frame; they share the
//! device, one GPU cache (one budget, one free space), one RAM budget, one render pass
//! and one depth buffer. Before each progressive frame the budgets are split by the
//! models' demand (`tessera_stream::BudgetSplit`: the rule and its smoothing are
//! explained there), so the model on screen gets the memory and one off screen or
//! hidden keeps its pinned roots (and, while nobody else needs the room, its cache).
//!
//! The policy (what to draw, request, upload and evict) is all in `tessera-stream`; the
//! viewer is the wgpu mechanics around it: the device, the GPU cache as the scheduler's
//! resident store, the loader threads as its patch source, render passes and readback.
//! The three modes are `tessera_stream::Mode`'s: progressive (never waits), complete
//! (the whole cut, in several passes if it exceeds the cache) and full resolution.

use std::sync::Arc;
use std::time::{Duration, Instant};

use tessera_format::{ModelIndex, PatchReader, ATTR_COLORS, ATTR_TEXTURE};
use tessera_page::{Pager, PagerOptions, ThreadGrower};
use tessera_select::{Camera, Placement};
use tessera_stream::{
    CompleteError, Driver, ImpostorOptions, ImpostorStats, Impostors, ModelSphere, MorphOptions,
    SceneBudgets, SceneStores, Scheduler, SchedulerOptions,
};

pub use tessera_stream::{FrameStats, Mode};

use crate::cache::{GpuCache, GpuStore};
use crate::gpu::Gpu;
use crate::impostor::{ImpostorRenderer, Quad};
use crate::renderer::{FrameParams, Light, Renderer, Shading};
use crate::RenderError;
use tessera_image::Image;

/// Options of a [`Viewer`].
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// Screen-space error tolerance, pixels.
    pub tolerance_px: f32,
    /// Frustum and normal-cone culling.
    pub cull: bool,
    pub mode: Mode,
    /// GPU cache budget (vertex + index buffers), shared by every model of a scene.
    /// Default 256 MiB.
    pub gpu_budget_bytes: u64,
    /// RAM budget of decoded patches, shared by every model of a scene. Default 128 MiB.
    pub ram_budget_bytes: u64,
    /// Loader threads of the pager (of each model's). Default 1.
    pub loader_threads: usize,
    /// Test hook: every patch read is delayed by this much (progressive mode).
    pub read_delay: Option<Duration>,
    /// Most bytes uploaded to the GPU per progressive frame. Default 32 MiB.
    pub upload_budget_bytes: u64,
    /// Ask for the prefetch set (grown spheres, predicted camera). Default on.
    pub prefetch: bool,
    /// Clear colour, linear RGBA.
    pub background: [f64; 4],
    /// Light, colour mode, wireframe.
    pub shading: Shading,
    /// Geomorphing: on/off, window, arrival blend (see `tessera_stream::MorphOptions`).
    pub morph: MorphOptions,
    /// Textured models: a patch morphing in from its parent also shows its parent's
    /// texel detail, sharpening as it morphs ([`Renderer::texel_blend`]; true).
    pub texel_blend: bool,
    /// Texture impostors for distant models (progressive frames; `tessera_stream::
    /// impostor`). None: off (the default).
    pub impostors: Option<ImpostorOptions>,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        let s = SchedulerOptions::default();
        ViewerOptions {
            tolerance_px: s.tolerance_px,
            cull: s.cull,
            mode: s.mode,
            gpu_budget_bytes: s.store_budget_bytes,
            ram_budget_bytes: s.ram_budget_bytes,
            loader_threads: 1,
            read_delay: None,
            upload_budget_bytes: s.upload_budget_bytes,
            prefetch: s.prefetch,
            background: [0.06, 0.07, 0.09, 1.0],
            shading: Shading::default(),
            morph: s.morph.clone(),
            texel_blend: true,
            impostors: None,
        }
    }
}

/// What the viewer keeps of each model beside the driver's part: the reader, its grid
/// step and whether it has colours. Every model has its own local frame (model
/// coordinates minus its header's cube origin), grid and cube; all share model
/// coordinates.
struct SceneModel {
    model: Arc<dyn PatchReader>,
    quant_step: f64,
    has_colors: bool,
}

/// The native driver: the pager's loader threads as each model's patch source, a
/// thread growing a paged index, the scene's own budgets.
type NativeDriver = Driver<Pager, ThreadGrower, SceneBudgets>;

/// The models' views of the one GPU cache, as the driver's stores.
struct CacheStores<'a> {
    cache: &'a mut GpuCache,
    gpu: &'a Gpu,
    models: &'a [SceneModel],
}

impl SceneStores for CacheStores<'_> {
    type Store<'b>
        = GpuStore<'b>
    where
        Self: 'b;
    fn store(&mut self, model: usize) -> GpuStore<'_> {
        GpuStore {
            cache: self.cache,
            device: &self.gpu.device,
            queue: &self.gpu.queue,
            quant_step: self.models[model].quant_step,
            model: model as u32,
        }
    }
    fn index_grown(&mut self, model: usize, index: &ModelIndex) {
        self.cache.set_nodes(model as u32, index);
    }
    fn usable_bytes(&self) -> u64 {
        self.cache.usable_bytes()
    }
}

/// See the module docs. Several models (`Viewer::with_models`) share the device, one
/// GPU cache (slots keyed by model and node) with one budget, one RAM budget, one
/// render pass and one depth buffer; each keeps its own scheduler and pager, and the
/// budgets are split between them every frame by demand (the shared
/// `tessera_stream::Driver`, as the browser's views).
pub struct Viewer {
    gpu: Gpu,
    renderer: Renderer,
    cache: GpuCache,
    models: Vec<SceneModel>,
    driver: NativeDriver,
    opts: ViewerOptions,
    start: Instant,
    /// Near and far planes of the last frame.
    planes: (f64, f64),
    /// The last frame's camera (its projection unprojects the depth under a pixel).
    last_camera: Option<Camera>,
    /// The impostor policy and textures, when on.
    impostors: Option<(Impostors, ImpostorRenderer)>,
}

impl Viewer {
    /// Opens a viewer on `model` (a local `Model` or any other [`PatchReader`]) with its
    /// own headless device.
    pub fn new(model: Arc<dyn PatchReader>, opts: ViewerOptions) -> Result<Viewer, RenderError> {
        let gpu = Gpu::headless()?;
        Self::with_gpu(gpu, model, opts)
    }

    /// Opens a viewer on `model` with an existing device; the roots are read and
    /// uploaded now (the first frame shows the whole model at its coarsest level).
    pub fn with_gpu(
        gpu: Gpu,
        model: Arc<dyn PatchReader>,
        opts: ViewerOptions,
    ) -> Result<Viewer, RenderError> {
        Self::with_models(gpu, vec![model], opts)
    }

    /// Opens a viewer on a scene of `models` (at least one), drawn together in their
    /// model coordinates; `opts.gpu_budget_bytes` and `opts.ram_budget_bytes` are the
    /// totals they share. Every model's roots are read and uploaded now (pinned: they
    /// must fit the GPU budget together).
    pub fn with_models(
        gpu: Gpu,
        models: Vec<Arc<dyn PatchReader>>,
        opts: ViewerOptions,
    ) -> Result<Viewer, RenderError> {
        let placed = models
            .into_iter()
            .map(|m| (m, Placement::IDENTITY))
            .collect();
        Self::with_scene(gpu, placed, opts)
    }

    /// Opens a viewer on a scene of placed models (at least one): each drawn where its
    /// [`Placement`] puts it (the same reader may stand several times: its index and
    /// file are shared, its patches cached once per placement). Otherwise as
    /// [`Viewer::with_models`].
    pub fn with_scene(
        gpu: Gpu,
        models: Vec<(Arc<dyn PatchReader>, Placement)>,
        opts: ViewerOptions,
    ) -> Result<Viewer, RenderError> {
        if models.is_empty() {
            return Err(RenderError::Io("a scene needs at least one model".into()));
        }
        let mut renderer = Renderer::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
        renderer.background = opts.background;
        renderer.set_base_vertex(gpu.base_vertex());
        renderer.has_colors = models[0].0.index().header().attributes & ATTR_COLORS != 0;
        renderer.texel_blend = opts.texel_blend;
        // One entry a model (and, with impostors, one a sample of a frame).
        renderer.ensure_models(&gpu.device, models.len() as u32 + 1);
        let mut cache = GpuCache::new(&gpu.device, opts.gpu_budget_bytes);
        let mut driver = Driver::new(SceneBudgets::new(
            opts.gpu_budget_bytes,
            opts.ram_budget_bytes,
        ));
        let mut scene = Vec::with_capacity(models.len());
        for (i, (model, placement)) in models.into_iter().enumerate() {
            let index = model.index();
            let scheduler = Scheduler::new(
                index,
                SchedulerOptions {
                    tolerance_px: opts.tolerance_px,
                    cull: opts.cull,
                    mode: opts.mode,
                    store_budget_bytes: opts.gpu_budget_bytes,
                    ram_budget_bytes: opts.ram_budget_bytes,
                    upload_budget_bytes: opts.upload_budget_bytes,
                    prefetch: opts.prefetch,
                    morph: opts.morph.clone(),
                    ..SchedulerOptions::default()
                },
            );
            let pager = Pager::new(
                model.clone(),
                PagerOptions {
                    threads: opts.loader_threads,
                    read_delay: opts.read_delay,
                },
            );
            cache.set_nodes(i as u32, index);
            cache.set_textured(i as u32, index.header().attributes & ATTR_TEXTURE != 0);
            cache.set_texture_codec(i as u32, index.header().patch_texture_codec());
            let k = driver.add(scheduler, pager, ThreadGrower::new(model.clone()));
            driver.set_placement(k, placement);
            scene.push(SceneModel {
                quant_step: index.grid().step(),
                has_colors: index.header().attributes & ATTR_COLORS != 0,
                model,
            });
        }
        // Roots first, each model with the whole budget (they are pinned); then the
        // first split (no demand yet: an even share of what the roots leave).
        {
            let mut stores = CacheStores {
                cache: &mut cache,
                gpu: &gpu,
                models: &scene,
            };
            driver.load_roots(&mut stores);
            let usable = stores.usable_bytes();
            driver.rebalance(0.0, usable);
        }
        let impostors = opts.impostors.clone().map(|o| {
            (
                Impostors::new(o, scene.len()),
                ImpostorRenderer::new(&gpu.device, renderer.color_format()),
            )
        });
        Ok(Viewer {
            gpu,
            renderer,
            cache,
            models: scene,
            driver,
            opts,
            start: Instant::now(),
            planes: (0.0, 0.0),
            last_camera: None,
            impostors,
        })
    }

    /// The models' views of the shared cache, for the driver.
    fn stores(&mut self) -> (&mut NativeDriver, CacheStores<'_>) {
        (
            &mut self.driver,
            CacheStores {
                cache: &mut self.cache,
                gpu: &self.gpu,
                models: &self.models,
            },
        )
    }

    /// The device (e.g. to report the adapter).
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The model (the first, in a scene of several).
    pub fn model(&self) -> &Arc<dyn PatchReader> {
        &self.models[0].model
    }

    /// Number of models in the scene.
    pub fn model_count(&self) -> usize {
        self.models.len()
    }

    /// Model `i` of the scene.
    pub fn model_of(&self, i: usize) -> &Arc<dyn PatchReader> {
        &self.models[i].model
    }

    /// Shows or hides model `i` from the next frame on. A hidden model draws nothing
    /// and asks for nothing; its demand is 0, so the other models get its memory (all
    /// but its pinned roots) as they need it.
    pub fn set_visible(&mut self, i: usize, visible: bool) {
        self.driver.set_visible(i, visible);
    }

    /// Whether model `i` is shown.
    pub fn is_visible(&self, i: usize) -> bool {
        self.driver.model(i).is_visible()
    }

    /// The options.
    pub fn options(&self) -> &ViewerOptions {
        &self.opts
    }

    /// The streaming core driving the (first) model.
    pub fn scheduler(&self) -> &Scheduler {
        &self.driver.model(0).scheduler
    }

    /// The streaming core driving model `i`.
    pub fn scheduler_of(&self, i: usize) -> &Scheduler {
        &self.driver.model(i).scheduler
    }

    /// Nodes of the (first) model drawn by the last frame.
    pub fn last_draw(&self) -> &[u32] {
        self.driver.model(0).scheduler.draw()
    }

    /// Nodes of model `i` drawn by the last frame.
    pub fn last_draw_of(&self, i: usize) -> &[u32] {
        self.driver.model(i).scheduler.draw()
    }

    /// Model `i`'s part of the last frame's statistics (its GPU bytes, budget, demand,
    /// cut); [`Viewer::render_with`] returns their combination.
    pub fn model_stats(&self, i: usize) -> &FrameStats {
        self.driver.model(i).stats()
    }

    /// Whether streaming has come to rest after the last frame (every shown model:
    /// nothing pending, growing or blending, nothing missing that could still arrive;
    /// `tessera_stream::DrivenModel::settled`, the browser's rule too).
    pub fn settled(&self) -> bool {
        self.driver.settled()
    }

    /// Renders one frame of `camera` into the offscreen target (camera.width x
    /// camera.height); read it with [`Viewer::read_image`].
    pub fn render(&mut self, camera: &Camera) -> Result<FrameStats, RenderError> {
        self.render_with(camera, camera)
    }

    /// Renders one frame: the cut is selected (and loaded) for `select`, and drawn seen
    /// from `camera` (the same camera, except while the cut is frozen: fly around and
    /// look at what a view selected). Both must have the same size. In a scene of
    /// several models the statistics are combined ([`FrameStats::combined`]: counts and
    /// bytes summed, deepest level); [`Viewer::model_stats`] has each model's.
    ///
    /// Complete and full-resolution frames of several models run model by model into
    /// the same target (cleared once, one depth buffer): each model in turn gets the
    /// whole GPU budget, the others released down to their pinned roots first.
    pub fn render_with(
        &mut self,
        select: &Camera,
        camera: &Camera,
    ) -> Result<FrameStats, RenderError> {
        let t0 = Instant::now();
        self.renderer
            .ensure_offscreen(&self.gpu.device, camera.width, camera.height);
        self.renderer
            .ensure_models(&self.gpu.device, self.models.len() as u32 + 1);
        let time_s = self.start.elapsed().as_secs_f64();
        let mut stats = match self.opts.mode {
            Mode::Progressive => {
                let (driver, mut stores) = self.stores();
                let stats = driver.frame(select, time_s, &mut stores);
                self.planes = self.driver.fitted_planes(camera);
                let quads = self.update_impostors(select);
                self.set_uniforms(camera);
                let draws: Vec<Draws> = self
                    .driver
                    .draws()
                    .filter(|&(i, _, _)| self.geometry_keep(i).is_some())
                    .map(|(i, nodes, ratios)| (i as u32, nodes, ratios))
                    .collect();
                self.submit_cleared(&draws);
                self.submit_quads(camera, &quads);
                stats
            }
            Mode::Complete | Mode::FullResolution => {
                let (driver, mut stores) = self.stores();
                driver.take_grown(time_s, &mut stores);
                self.complete_frames(select, camera)?
            }
        };
        self.gpu.wait_idle()?;
        self.last_camera = Some(camera.clone());
        stats.frame_ms = t0.elapsed().as_secs_f64() * 1e3;
        if let Some((policy, _)) = &mut self.impostors {
            policy.frame_took(stats.frame_ms);
        }
        Ok(stats)
    }

    /// One pass drawing `draws` into the cleared offscreen target.
    fn submit_cleared(&self, draws: &[Draws]) {
        if let Some(views) = self.renderer.offscreen_views() {
            submit_pass(&self.gpu, &self.renderer, views, &self.cache, draws, true);
        }
    }

    /// Every model's uniforms for `camera` with the frame's planes, each in its own
    /// coordinates ([`tessera_stream::DrivenModel::view`]).
    fn set_uniforms(&self, camera: &Camera) {
        for (i, m) in self.models.iter().enumerate() {
            let origin = m.model.index().header().cube_origin;
            let driven = self.driver.model(i);
            let (camera, planes) = driven.view(camera, self.planes);
            let mut shading = self.opts.shading;
            if let Light::Directional(d) = shading.light {
                // A light fixed in the scene, seen from the model's coordinates.
                let d = driven.placement().direction_to_model(d.into());
                shading.light = Light::Directional(d.to_array());
            }
            let params = FrameParams::with_planes(&camera, origin, planes, shading)
                .with_keep(self.geometry_keep(i).unwrap_or([0.0, 1.0]));
            self.renderer
                .set_model_frame(&self.gpu.queue, i as u32, &params, m.has_colors);
        }
    }

    fn complete_frames(
        &mut self,
        select: &Camera,
        camera: &Camera,
    ) -> Result<FrameStats, RenderError> {
        // The passes of one frame share planes: fitted to the whole models shown (the
        // cut is not known before it is drawn), tightened by the last frame's cut would
        // risk clipping.
        self.planes = self.driver.bounding_planes(camera);
        self.set_uniforms(camera);
        let n = self.models.len();
        let (total_gpu, total_ram) = (self.opts.gpu_budget_bytes, self.opts.ram_budget_bytes);
        let mut cleared = false;
        let mut passes = 0;
        for i in 0..n {
            if !self.driver.model(i).is_visible() {
                self.driver.model_mut(i).set_stats(FrameStats::default());
                continue;
            }
            if n > 1 {
                // This model gets the whole cache but the others' pinned roots.
                let mut others = 0;
                for j in (0..n).filter(|&j| j != i) {
                    let (driver, mut stores) = self.stores();
                    let m = driver.model_mut(j);
                    m.scheduler.release(&mut stores.store(j));
                    others += m.scheduler.resident_bytes();
                }
                self.driver
                    .model_mut(i)
                    .scheduler
                    .set_budgets(total_gpu.saturating_sub(others), total_ram);
            }
            let first = !cleared;
            let Some((color, depth)) = self.renderer.offscreen_views() else {
                return Err(RenderError::NoFrame);
            };
            let (gpu, renderer) = (&self.gpu, &self.renderer);
            let m = self.driver.model_mut(i);
            let select = m.placement().camera_to_model(select);
            let mut store = GpuStore {
                cache: &mut self.cache,
                device: &gpu.device,
                queue: &gpu.queue,
                quant_step: self.models[i].quant_step,
                model: i as u32,
            };
            let stats = m
                .scheduler
                .complete_frame(
                    &select,
                    &mut m.source,
                    &mut store,
                    |s, nodes, ratios, clear| {
                        let draws = [(i as u32, nodes, ratios)];
                        submit_pass(
                            gpu,
                            renderer,
                            (color, depth),
                            s.cache,
                            &draws,
                            clear && first,
                        );
                        Ok::<(), RenderError>(())
                    },
                )
                .map_err(|e| match e {
                    CompleteError::StoreTooSmall => RenderError::CacheTooSmall,
                    CompleteError::NoBlockingReads => {
                        RenderError::Io("the patch source cannot read on demand".into())
                    }
                    CompleteError::Pass(e) => e,
                })?;
            cleared = true;
            passes += stats.passes;
            m.set_stats(stats);
        }
        if !cleared {
            // Nothing shown: a cleared frame.
            self.submit_cleared(&[]);
        }
        let mut stats = self.driver.stats();
        stats.passes = passes;
        Ok(stats)
    }

    /// The dither thresholds of model `i`'s geometry this frame: all of them without
    /// impostors; None when a texture stands in for it alone.
    fn geometry_keep(&self, i: usize) -> Option<[f32; 2]> {
        match &self.impostors {
            Some((policy, _)) if self.opts.mode == Mode::Progressive => policy.draw(i).geometry,
            _ => Some([0.0, 1.0]),
        }
    }

    /// The impostor policy's frame for `select`: the decisions, the textures sampled
    /// (each a pass of the model's drawn cut from the sampling eye, submitted now), and
    /// the quads to draw.
    fn update_impostors(&mut self, select: &Camera) -> Vec<Quad> {
        let Some((mut policy, mut gpu_side)) = self.impostors.take() else {
            return Vec::new();
        };
        let spheres: Vec<ModelSphere> = self
            .driver
            .models()
            .iter()
            .map(|m| {
                let b = m.index().header().bounding_sphere;
                let (center, radius) = m
                    .placement()
                    .sphere_to_world(glam::DVec3::new(b[0], b[1], b[2]), b[3]);
                // The cut drawn now (FNV-1a over its nodes): a texture of another one
                // is sampled again.
                let cut = m
                    .scheduler
                    .draw()
                    .iter()
                    .fold(0xcbf2_9ce4_8422_2325u64, |h, &n| {
                        (h ^ u64::from(n)).wrapping_mul(0x0100_0000_01b3)
                    });
                ModelSphere {
                    center,
                    radius,
                    visible: m.is_visible(),
                    cut,
                }
            })
            .collect();
        policy.update(select, &spheres);
        for slot in 0..policy.slot_count() {
            if !policy.in_use(slot) {
                gpu_side.release(slot);
            }
        }
        // Every sample of the frame in one submission: each its own uniform entry past
        // the models'.
        let samples = policy.to_sample().to_vec();
        self.renderer.ensure_models(
            &self.gpu.device,
            (self.models.len() + samples.len().max(1)) as u32,
        );
        for (k, &(i, slot)) in samples.iter().enumerate() {
            let sample = policy.sample(slot);
            let driven = self.driver.model(i);
            // The frame's own camera over the sphere's rectangle of the image: at the
            // sampling eye the texels are the frame's pixels.
            let (camera, planes) = driven.view(&sample.camera, sample.planes());
            let origin = self.models[i].model.index().header().cube_origin;
            let mut params = FrameParams::with_planes(&camera, origin, planes, self.opts.shading);
            params.view_proj = glam::Mat4::from_cols_array_2d(&sample.crop()) * params.view_proj;
            let entry = (self.models.len() + k) as u32;
            self.renderer.set_model_frame(
                &self.gpu.queue,
                entry,
                &params,
                self.models[i].has_colors,
            );
            gpu_side.target(&self.gpu.device, slot, sample.size);
        }
        if !samples.is_empty() {
            let mut enc = self
                .gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("tessera impostor samples"),
                });
            let background = self.renderer.background;
            self.renderer.background = [0.0; 4];
            for (k, &(i, slot)) in samples.iter().enumerate() {
                let driven = self.driver.model(i);
                let entry = (self.models.len() + k) as u32;
                let (color, depth) = gpu_side.views(slot, policy.sample(slot).size);
                let cache = &self.cache;
                let nodes = driven.scheduler.draw();
                let ratios = driven.scheduler.morph_ratios();
                let slots = nodes.iter().enumerate().filter_map(|(j, &n)| {
                    let ratio = ratios.get(j).copied().unwrap_or(0.0);
                    cache.slot_of(i as u32, n).map(|s| (entry, s, ratio))
                });
                self.renderer.encode_models_pass(
                    &self.gpu.device,
                    &mut enc,
                    color,
                    depth,
                    cache,
                    slots,
                    true,
                );
            }
            self.renderer.background = background;
            self.gpu.queue.submit([enc.finish()]);
            for &(_, slot) in &samples {
                policy.sampled(slot);
            }
        }
        let mut quads = Vec::new();
        let mut saved = 0;
        for i in 0..self.models.len() {
            let d = policy.draw(i);
            if d.geometry.is_none() {
                saved += self.driver.model(i).stats().triangles;
            }
            for (slot, keep) in d.textures {
                let (center, right, up) = policy.sample(slot).quad();
                quads.push(Quad {
                    slot,
                    center,
                    right,
                    up,
                    keep,
                });
            }
        }
        policy.set_triangles_saved(saved);
        self.impostors = Some((policy, gpu_side));
        quads
    }

    /// Draws `quads` over the frame just drawn.
    fn submit_quads(&self, camera: &Camera, quads: &[Quad]) {
        let (Some((_, gpu_side)), Some((color, depth))) =
            (&self.impostors, self.renderer.offscreen_views())
        else {
            return;
        };
        if quads.is_empty() {
            return;
        }
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("tessera impostors"),
            });
        gpu_side.encode_quads(
            &self.gpu.device,
            &self.gpu.queue,
            &mut enc,
            color,
            depth,
            camera,
            self.planes,
            quads,
        );
        self.gpu.queue.submit([enc.finish()]);
    }

    /// The impostors' figures of the last frame (None: impostors off).
    pub fn impostor_stats(&self) -> Option<ImpostorStats> {
        self.impostors.as_ref().map(|(p, _)| p.stats())
    }

    /// The surface point drawn at pixel (`x`, `y`) of the last frame (pixels from the
    /// top left), model coordinates, from the depth buffer: a point on whatever level
    /// was drawn, of whichever model is in front (for zooming toward the cursor; a
    /// full-resolution pick is `tessera-pick`'s). None over the background. Waits for
    /// the GPU.
    pub fn point_at(&self, x: f64, y: f64) -> Result<Option<[f64; 3]>, RenderError> {
        let Some(cam) = &self.last_camera else {
            return Ok(None);
        };
        if !(x >= 0.0 && y >= 0.0) {
            return Ok(None);
        }
        let Some(d) =
            self.renderer
                .read_depth(&self.gpu.device, &self.gpu.queue, x as u32, y as u32)?
        else {
            return Ok(None);
        };
        // Reversed Z, unprojected at the pixel's centre (the pixel read).
        Ok(cam
            .point_at_depth(x, y, d, self.planes)
            .map(|p| p.to_array()))
    }

    /// The offscreen colour target of the last frame (a window blits it).
    pub fn offscreen_color(&self) -> Option<&wgpu::TextureView> {
        self.renderer.offscreen_color()
    }

    /// The pagers' counters (bytes read, loads, queue), summed over the models.
    pub fn pager_stats(&self) -> tessera_page::PagerStats {
        let mut out = tessera_page::PagerStats::default();
        for m in self.driver.models() {
            let s = m.source.stats();
            out.queued += s.queued;
            out.in_flight += s.in_flight;
            out.loads += s.loads;
            out.failures += s.failures;
            out.bytes_read += s.bytes_read;
        }
        out
    }

    /// Model `i`'s pager counters.
    pub fn pager_stats_of(&self, i: usize) -> tessera_page::PagerStats {
        self.driver.model(i).source.stats()
    }

    /// Near and far planes of the last frame (model units; shared by every model).
    pub fn clip_planes(&self) -> (f64, f64) {
        self.planes
    }

    /// The index the (first) model's scheduler selects over (grown from a paged one,
    /// if it was).
    pub fn index(&self) -> &ModelIndex {
        self.driver.model(0).index()
    }

    /// The index model `i`'s scheduler selects over.
    pub fn index_of(&self, i: usize) -> &ModelIndex {
        self.driver.model(i).index()
    }

    /// Changes the screen-space tolerance (pixels) of every model from the next frame on.
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        self.driver.set_tolerance_px(tolerance_px);
        self.opts.tolerance_px = self.driver.model(0).scheduler.options().tolerance_px;
    }

    /// Turns the prefetch set on or off from the next frame on.
    pub fn set_prefetch(&mut self, prefetch: bool) {
        self.driver.set_prefetch(prefetch);
        self.opts.prefetch = prefetch;
    }

    /// Turns geomorphing on or off from the next frame on.
    pub fn set_morph(&mut self, enabled: bool) {
        self.driver.set_morph(enabled);
        self.opts.morph.enabled = enabled;
    }

    /// Changes the display options from the next frame on.
    pub fn set_shading(&mut self, shading: Shading) {
        self.opts.shading = shading;
    }

    /// Whether the device draws the wireframe overlay.
    pub fn can_draw_wireframe(&self) -> bool {
        self.renderer.can_draw_wireframe()
    }

    /// The last frame's pixels.
    pub fn read_image(&self) -> Result<Image, RenderError> {
        self.renderer
            .read_offscreen(&self.gpu.device, &self.gpu.queue)
    }
}

/// One model's part of a pass: its number, the nodes drawn and their morph ratios.
type Draws<'a> = (u32, &'a [u32], &'a [f32]);

/// Encodes and submits one render pass drawing the resident nodes of each (model,
/// nodes, ratios) into the offscreen target; `clear` starts the frame, otherwise the
/// pass adds to what is there.
fn submit_pass(
    gpu: &Gpu,
    renderer: &Renderer,
    (color, depth): (&wgpu::TextureView, &wgpu::TextureView),
    cache: &GpuCache,
    draws: &[Draws],
    clear: bool,
) {
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera frame encoder"),
        });
    let slots = draws.iter().flat_map(|&(model, nodes, ratios)| {
        nodes.iter().enumerate().filter_map(move |(k, &n)| {
            let r = ratios.get(k).copied().unwrap_or(0.0);
            cache.slot_of(model, n).map(|s| (model, s, r))
        })
    });
    renderer.encode_models_pass(&gpu.device, &mut enc, color, depth, cache, slots, clear);
    gpu.queue.submit([enc.finish()]);
}
