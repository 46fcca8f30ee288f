//! A view of one model: the streaming core's [`Scheduler`] driving the GPU cache and
//! the pager, one call per frame. Shared by `tessera render`, the tests and (next) the
//! window.
//!
//! The policy (what to draw, request, upload and evict) is all in `tessera-stream`; the
//! viewer is the wgpu mechanics around it: the device, the GPU cache as the scheduler's
//! resident store, the loader threads as its patch source, render passes and readback.
//! The three modes are `tessera_stream::Mode`'s: progressive (never waits), complete
//! (the whole cut, in several passes if it exceeds the cache) and full resolution.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::DVec3;
use tessera_format::{ModelIndex, PatchReader, ATTR_COLORS};
use tessera_page::{Pager, PagerOptions};
use tessera_select::Camera;
use tessera_stream::{CompleteError, Scheduler, SchedulerOptions};

pub use tessera_stream::{FrameStats, Mode};

use crate::cache::{GpuCache, GpuStore};
use crate::gpu::Gpu;
use crate::renderer::{clip_planes, instance_tag, FrameParams, Renderer, Shading};
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
    /// GPU cache budget (vertex + index buffers). Default 256 MiB.
    pub gpu_budget_bytes: u64,
    /// RAM budget of decoded patches. Default 128 MiB.
    pub ram_budget_bytes: u64,
    /// Loader threads of the pager. Default 1.
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
        }
    }
}

/// See the module docs.
pub struct Viewer {
    gpu: Gpu,
    renderer: Renderer,
    cache: GpuCache,
    model: Arc<dyn PatchReader>,
    scheduler: Scheduler,
    pager: Pager,
    opts: ViewerOptions,
    quant_step: f64,
    start: Instant,
    /// A thread reading more of a paged index is running.
    growing: Arc<AtomicBool>,
    /// The paged index as grown since `model.index()` was read (None: not grown).
    grown: Option<Arc<ModelIndex>>,
    /// Near and far planes of the last frame.
    planes: (f64, f64),
    /// The last frame's camera (its projection unprojects the depth under a pixel).
    last_camera: Option<Camera>,
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
        let mut renderer = Renderer::new(&gpu.device, wgpu::TextureFormat::Rgba8Unorm);
        renderer.background = opts.background;
        renderer.has_colors = model.index().header().attributes & ATTR_COLORS != 0;
        let cache = GpuCache::new(&gpu.device, opts.gpu_budget_bytes);
        let scheduler = Scheduler::new(
            model.index(),
            SchedulerOptions {
                tolerance_px: opts.tolerance_px,
                cull: opts.cull,
                mode: opts.mode,
                store_budget_bytes: opts.gpu_budget_bytes,
                ram_budget_bytes: opts.ram_budget_bytes,
                upload_budget_bytes: opts.upload_budget_bytes,
                prefetch: opts.prefetch,
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
        let quant_step = model.index().grid().step();
        let mut v = Viewer {
            gpu,
            renderer,
            cache,
            model,
            scheduler,
            pager,
            opts,
            quant_step,
            start: Instant::now(),
            growing: Arc::new(AtomicBool::new(false)),
            grown: None,
            planes: (0.0, 0.0),
            last_camera: None,
        };
        let mut store = GpuStore {
            cache: &mut v.cache,
            device: &v.gpu.device,
            queue: &v.gpu.queue,
            quant_step: v.quant_step,
        };
        v.scheduler.load_roots(&mut v.pager, &mut store);
        Ok(v)
    }

    /// The device (e.g. to report the adapter).
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The model.
    pub fn model(&self) -> &Arc<dyn PatchReader> {
        &self.model
    }

    /// The options.
    pub fn options(&self) -> &ViewerOptions {
        &self.opts
    }

    /// The streaming core driving this viewer.
    pub fn scheduler(&self) -> &Scheduler {
        &self.scheduler
    }

    /// Nodes drawn by the last frame.
    pub fn last_draw(&self) -> &[u32] {
        self.scheduler.draw()
    }

    /// Renders one frame of `camera` into the offscreen target (camera.width x
    /// camera.height); read it with [`Viewer::read_image`].
    pub fn render(&mut self, camera: &Camera) -> Result<FrameStats, RenderError> {
        self.render_with(camera, camera)
    }

    /// Renders one frame: the cut is selected (and loaded) for `select`, and drawn seen
    /// from `camera` (the same camera, except while the cut is frozen: fly around and
    /// look at what a view selected). Both must have the same size.
    pub fn render_with(
        &mut self,
        select: &Camera,
        camera: &Camera,
    ) -> Result<FrameStats, RenderError> {
        let t0 = Instant::now();
        self.renderer
            .ensure_offscreen(&self.gpu.device, camera.width, camera.height);
        let cube_origin = self.model.index().header().cube_origin;
        let (color, depth) = self
            .renderer
            .offscreen_views()
            .ok_or(RenderError::NoFrame)?;
        let mut store = GpuStore {
            cache: &mut self.cache,
            device: &self.gpu.device,
            queue: &self.gpu.queue,
            quant_step: self.quant_step,
        };
        // A paged index read further since the last frame: select over more of it.
        if let Some(ix) = self.model.latest_index() {
            if ix.nodes().len() > self.scheduler.node_count() {
                self.scheduler.set_index(&ix, &mut store);
                self.grown = Some(ix);
            }
        }
        let index = self.grown.as_deref().unwrap_or(self.model.index());
        let mut stats = match self.opts.mode {
            Mode::Progressive => {
                let time_s = self.start.elapsed().as_secs_f64();
                let stats = self
                    .scheduler
                    .frame(select, time_s, &mut self.pager, &mut store);
                if stats.index_wants > 0 && !self.growing.swap(true, Ordering::AcqRel) {
                    // Read more of the index off this thread; the frame never waits.
                    let (model, growing) = (self.model.clone(), self.growing.clone());
                    std::thread::spawn(move || {
                        model.grow_index();
                        growing.store(false, Ordering::Release);
                    });
                }
                let nodes = self.scheduler.draw();
                self.planes = fitted_planes(index, camera, nodes);
                let params =
                    FrameParams::with_planes(camera, cube_origin, self.planes, self.opts.shading);
                self.renderer.set_frame(&self.gpu.queue, &params);
                submit_pass(
                    &self.gpu,
                    &self.renderer,
                    (color, depth),
                    store.cache,
                    index,
                    nodes,
                    true,
                );
                stats
            }
            Mode::Complete | Mode::FullResolution => {
                // The passes of one frame share planes: fitted to the whole model
                // (the cut is not known before it is drawn), tightened by the last
                // frame's cut would risk clipping.
                let h = self.model.index().header();
                let b = h.bounding_sphere;
                self.planes = clip_planes(
                    DVec3::from(camera.position),
                    [(DVec3::new(b[0], b[1], b[2]), b[3].max(1e-9))],
                );
                let params =
                    FrameParams::with_planes(camera, cube_origin, self.planes, self.opts.shading);
                self.renderer.set_frame(&self.gpu.queue, &params);
                let (gpu, renderer) = (&self.gpu, &self.renderer);
                self.scheduler
                    .complete_frame(select, &mut self.pager, &mut store, |s, nodes, clear| {
                        submit_pass(gpu, renderer, (color, depth), s.cache, index, nodes, clear);
                        Ok::<(), RenderError>(())
                    })
                    .map_err(|e| match e {
                        CompleteError::StoreTooSmall => RenderError::CacheTooSmall,
                        CompleteError::NoBlockingReads => {
                            RenderError::Io("the patch source cannot read on demand".into())
                        }
                        CompleteError::Pass(e) => e,
                    })?
            }
        };
        self.gpu.wait_idle()?;
        self.last_camera = Some(camera.clone());
        stats.frame_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }

    /// The surface point drawn at pixel (`x`, `y`) of the last frame (pixels from the
    /// top left), model coordinates, from the depth buffer: a point on whatever level
    /// was drawn (for zooming toward the cursor; a full-resolution pick is
    /// `tessera-pick`'s). None over the background. Waits for the GPU.
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
        if d <= 0.0 {
            return Ok(None);
        }
        // Reversed Z of a perspective projection: depth = near / z_view (near at 1,
        // infinity at 0, exactly so when far >> near; with a finite far the correction
        // below inverts the same formula the projection uses).
        let (near, far) = self.planes;
        let z = near * far / (f64::from(d) * (far - near) + near);
        let b = cam.basis();
        let tan_y = (0.5 * cam.fov_y_rad()).tan();
        let ndc_x = (x + 0.5) / f64::from(cam.width) * 2.0 - 1.0;
        let ndc_y = 1.0 - (y + 0.5) / f64::from(cam.height) * 2.0;
        let dir = b.forward + b.right * (ndc_x * tan_y * cam.aspect()) + b.up * (ndc_y * tan_y);
        let p = DVec3::from(cam.position) + dir * z;
        Ok(Some(p.to_array()))
    }

    /// The offscreen colour target of the last frame (a window blits it).
    pub fn offscreen_color(&self) -> Option<&wgpu::TextureView> {
        self.renderer.offscreen_color()
    }

    /// The pager's counters (bytes read, loads, queue).
    pub fn pager_stats(&self) -> tessera_page::PagerStats {
        self.pager.stats()
    }

    /// Near and far planes of the last frame (model units).
    pub fn clip_planes(&self) -> (f64, f64) {
        self.planes
    }

    /// The index the scheduler selects over (grown from a paged one, if it was).
    pub fn index(&self) -> &ModelIndex {
        self.grown.as_deref().unwrap_or(self.model.index())
    }

    /// Changes the screen-space tolerance (pixels) from the next frame on.
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        self.scheduler.set_tolerance_px(tolerance_px);
        self.opts.tolerance_px = self.scheduler.options().tolerance_px;
    }

    /// Turns the prefetch set on or off from the next frame on.
    pub fn set_prefetch(&mut self, prefetch: bool) {
        self.scheduler.set_prefetch(prefetch);
        self.opts.prefetch = prefetch;
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

/// Near and far planes fitted to the tight spheres of the `nodes` drawn (a close-up
/// gets a near plane just in front of the surface it looks at).
fn fitted_planes(index: &ModelIndex, camera: &Camera, nodes: &[u32]) -> (f64, f64) {
    let origin = DVec3::from(index.header().cube_origin);
    let spheres = nodes.iter().filter_map(|&n| {
        let s = index.nodes().get(n as usize)?.tight_sphere;
        let c = origin + DVec3::new(f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
        // f32 spheres: widen by their rounding.
        Some((
            c,
            f64::from(s[3]) * (1.0 + 1e-6) + c.abs().max_element() * 1e-6,
        ))
    });
    clip_planes(DVec3::from(camera.position), spheres)
}

/// Encodes and submits one render pass drawing the resident `nodes` into the offscreen
/// target; `clear` starts the frame, otherwise the pass adds to what is there.
fn submit_pass(
    gpu: &Gpu,
    renderer: &Renderer,
    (color, depth): (&wgpu::TextureView, &wgpu::TextureView),
    cache: &GpuCache,
    index: &ModelIndex,
    nodes: &[u32],
    clear: bool,
) {
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera frame encoder"),
        });
    let slots = nodes.iter().filter_map(|&n| {
        let level = index.nodes().get(n as usize).map_or(0, |r| r.level);
        cache.slot(n).map(|s| (instance_tag(n, level), s))
    });
    renderer.encode_pass(&mut enc, color, depth, cache, slots, clear);
    gpu.queue.submit([enc.finish()]);
}
