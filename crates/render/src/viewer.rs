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

use tessera_format::{PatchReader, ATTR_COLORS};
use tessera_page::{Pager, PagerOptions};
use tessera_select::Camera;
use tessera_stream::{CompleteError, Scheduler, SchedulerOptions};

pub use tessera_stream::{FrameStats, Mode};

use crate::cache::{GpuCache, GpuStore};
use crate::gpu::Gpu;
use crate::renderer::{FrameParams, Renderer};
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
        let t0 = Instant::now();
        self.renderer
            .ensure_offscreen(&self.gpu.device, camera.width, camera.height);
        let h = self.model.index().header();
        let params = FrameParams::new(camera, h.cube_origin, h.bounding_sphere);
        self.renderer.set_frame(&self.gpu.queue, &params);
        let (color, depth) = self
            .renderer
            .offscreen_views()
            .ok_or(RenderError::NoFrame)?;
        let (gpu, renderer) = (&self.gpu, &self.renderer);
        let mut store = GpuStore {
            cache: &mut self.cache,
            device: &gpu.device,
            queue: &gpu.queue,
            quant_step: self.quant_step,
        };
        // A paged index read further since the last frame: select over more of it.
        if let Some(ix) = self.model.latest_index() {
            if ix.nodes().len() > self.scheduler.node_count() {
                self.scheduler.set_index(&ix, &mut store);
            }
        }
        let mut stats = match self.opts.mode {
            Mode::Progressive => {
                let time_s = self.start.elapsed().as_secs_f64();
                let stats = self
                    .scheduler
                    .frame(camera, time_s, &mut self.pager, &mut store);
                if stats.index_wants > 0 && !self.growing.swap(true, Ordering::AcqRel) {
                    // Read more of the index off this thread; the frame never waits.
                    let (model, growing) = (self.model.clone(), self.growing.clone());
                    std::thread::spawn(move || {
                        model.grow_index();
                        growing.store(false, Ordering::Release);
                    });
                }
                submit_pass(
                    gpu,
                    renderer,
                    (color, depth),
                    store.cache,
                    self.scheduler.draw(),
                    true,
                );
                stats
            }
            Mode::Complete | Mode::FullResolution => self
                .scheduler
                .complete_frame(camera, &mut self.pager, &mut store, |s, nodes, clear| {
                    submit_pass(gpu, renderer, (color, depth), s.cache, nodes, clear);
                    Ok::<(), RenderError>(())
                })
                .map_err(|e| match e {
                    CompleteError::StoreTooSmall => RenderError::CacheTooSmall,
                    CompleteError::NoBlockingReads => {
                        RenderError::Io("the patch source cannot read on demand".into())
                    }
                    CompleteError::Pass(e) => e,
                })?,
        };
        self.gpu.wait_idle()?;
        stats.frame_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }

    /// The last frame's pixels.
    pub fn read_image(&self) -> Result<Image, RenderError> {
        self.renderer
            .read_offscreen(&self.gpu.device, &self.gpu.queue)
    }
}

/// Encodes and submits one render pass drawing the resident `nodes` into the offscreen
/// target; `clear` starts the frame, otherwise the pass adds to what is there.
fn submit_pass(
    gpu: &Gpu,
    renderer: &Renderer,
    (color, depth): (&wgpu::TextureView, &wgpu::TextureView),
    cache: &GpuCache,
    nodes: &[u32],
    clear: bool,
) {
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera frame encoder"),
        });
    let slots = nodes.iter().filter_map(|&n| cache.slot(n));
    renderer.encode_pass(&mut enc, color, depth, cache, slots, clear);
    gpu.queue.submit([enc.finish()]);
}
