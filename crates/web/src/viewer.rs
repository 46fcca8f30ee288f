//! The browser viewer: one model from a URL, drawn into a canvas with WebGL2 through
//! wgpu, by the same code as the desktop (see the crate docs). JavaScript owns the
//! frame loop (`requestAnimationFrame` calls [`Viewer::frame`]) and the DOM events
//! (forwarded to [`Viewer::pointer_down`] and friends, in canvas pixels; touch gestures
//! arrive as drags and [`Viewer::pinch`]). The wheel, double-click and pinch act about
//! the point drawn under the cursor: the depth of the last frame read back
//! (`crate::pick`) and unprojected, then the desktop's `Navigator` calls (`zoom`
//! toward it, `recentre` on it, `pinch` about it).

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;
use std::sync::Arc;

use glam::DVec3;
use rustc_hash::FxHashMap;
use serde_json::{json, Value};
use tessera_format::{Grid, ModelIndex, PatchData, ATTR_COLORS, ATTR_TEXTURE};
use tessera_nav::{Navigator, ScenePoints};
use tessera_render::{FrameParams, Gpu, GpuCache, GpuStore, Renderer, Shading};
use tessera_select::Camera;
use tessera_stream::{
    memory_split, Answer, Driver, FrameStats, IndexGrower, PatchSource, ResidentStore, SceneStores,
    Scheduler, SchedulerOptions, StoreError,
};
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::spawn_local;

use crate::http::{Http, HttpError};
use crate::pick::DepthPicker;
use crate::plan::{Attempt, Fetcher, SparseBytes, PREFIX_BYTES};

/// Most time one frame spends decoding fetched patches on the main thread,
/// milliseconds: when the page gives no decode workers ([`Viewer::set_decoder`]) or
/// they failed; the per-patch cost is in the statistics (`decode_ms_mean`).
const DECODE_BUDGET_MS: f64 = 6.0;
/// Jobs at each decode worker at most: enough that small patches (a fraction of a
/// millisecond each) keep it busy between two replies taken in.
const JOBS_PER_WORKER: usize = 32;
/// Decoded bytes of the jobs at the workers at most (their replies wait in memory until
/// a frame takes them; a large textured patch goes alone).
const JOB_BYTES: u64 = 48 << 20;
/// Index pages read at open (as `tessera_http::TOP_PAGES`).
const TOP_PAGES: u64 = 1;
/// Root vertices kept to frame the home view (as the desktop viewer).
const HOME_POINTS: usize = 20_000;

/// Milliseconds from the page's time origin (`performance.now()`).
pub fn now_ms() -> f64 {
    thread_local! {
        static PERF: Option<web_sys::Performance> = {
            let g = js_sys::global();
            match g.dyn_ref::<web_sys::Window>() {
                Some(w) => w.performance(),
                // A decode worker.
                None => g.dyn_ref::<web_sys::WorkerGlobalScope>().and_then(|w| w.performance()),
            }
        };
    }
    PERF.with(|p| p.as_ref().map_or_else(js_sys::Date::now, |p| p.now()))
}

fn err(msg: impl std::fmt::Display) -> JsError {
    JsError::new(&msg.to_string())
}

/// Reads with `f` over `sparse`, fetching what it lacks, until it is done.
async fn read_with<T>(
    http: &Http,
    sparse: &RefCell<SparseBytes>,
    f: impl Fn(&SparseBytes) -> Result<T, tessera_format::FormatError>,
) -> Result<T, String> {
    use tessera_format::ByteSource;
    for _ in 0..64 {
        let step = sparse.borrow().attempt(&f);
        match step {
            Attempt::Done(v) => return Ok(v),
            Attempt::Failed(e) => return Err(e.to_string()),
            // A truncated file (opened at the length its header names): not there.
            Attempt::Need(r) if r.end > http.len() => {
                return Err(tessera_format::FormatError::Truncated {
                    expected_bytes: sparse.borrow().len(),
                    actual_bytes: http.len(),
                }
                .to_string())
            }
            Attempt::Need(r) => {
                let body = http
                    .get(r.clone(), false)
                    .await
                    .map_err(|e| e.message().to_string())?;
                sparse.borrow_mut().insert(r.start, body);
            }
        }
    }
    Err("the index asked for more than 64 reads".into())
}

/// The patch source: range requests through [`Fetcher`] (coalesced, at most 3 in
/// flight, aborted when the view no longer wants them), decoded by the page's decode
/// workers ([`Viewer::set_decoder`]), or between frames on this thread without them.
pub(crate) struct Remote {
    pub http: Rc<Http>,
    pub fetcher: Rc<RefCell<Fetcher>>,
    /// An error that stops streaming (the model changed on the server).
    pub fatal: Rc<RefCell<Option<String>>>,
    pub closed: Rc<Cell<bool>>,
    /// The requests in flight, by the fetcher's id, to abort.
    aborts: Aborts,
    /// The roots, fetched and decoded while opening (answered by `read_now`).
    roots: Vec<Answer>,
    /// The page's decode workers, if any.
    pub decoder: Option<Rc<Decoders>>,
    /// Whether they failed (then decoding falls back to this thread, for good).
    pub workers_failed: Rc<Cell<bool>>,
    /// Make textures' mips in the workers (a textured model).
    mips: bool,
    /// The GPU samples BC7 (its largest texture; `None`: it does not): the workers hand
    /// BC7 textures over as blocks where they upload as blocks
    /// ([`crate::wire::Job::blocks`]), else decoded.
    pub blocks: Option<u32>,
}

/// The abort controllers of the requests in flight.
type Aborts = Rc<RefCell<FxHashMap<u64, web_sys::AbortController>>>;

/// The page's decode function (a job's bytes in, a promise of the reply's bytes:
/// `crate::wire`) and how many workers run it.
pub(crate) struct Decoders {
    decode: js_sys::Function,
    pub workers: usize,
}

/// What handing jobs to the workers needs, cloned into each callback.
#[derive(Clone)]
struct Dispatch {
    decoders: Rc<Decoders>,
    fetcher: Rc<RefCell<Fetcher>>,
    failed: Rc<Cell<bool>>,
    closed: Rc<Cell<bool>>,
    mips: bool,
    blocks: Option<u32>,
}

impl Remote {
    /// The source of an opened model (`roots`: [`Opened::roots`]); `mips`: make the
    /// textures' mip chains in the decode workers.
    pub fn new(http: Rc<Http>, index: &Arc<ModelIndex>, roots: Vec<Answer>, mips: bool) -> Remote {
        Remote {
            http,
            fetcher: Rc::new(RefCell::new(Fetcher::new(index.clone()))),
            fatal: Rc::new(RefCell::new(None)),
            closed: Rc::new(Cell::new(false)),
            aborts: Rc::default(),
            roots,
            decoder: None,
            workers_failed: Rc::new(Cell::new(false)),
            mips,
            blocks: None,
        }
    }

    /// Decodes fetched patches with `decode` from now on ([`Viewer::set_decoder`]).
    pub fn set_decoder(&mut self, decode: js_sys::Function, workers: u32) {
        self.decoder = (workers > 0).then(|| {
            Rc::new(Decoders {
                decode,
                workers: workers as usize,
            })
        });
    }

    /// Sends what the fetcher wants sent; each answer sends more.
    fn pump(&self) {
        pump(&Pipes {
            http: self.http.clone(),
            fetcher: self.fetcher.clone(),
            fatal: self.fatal.clone(),
            closed: self.closed.clone(),
            aborts: self.aborts.clone(),
            workers: self.dispatcher(),
        });
    }

    /// Aborts the requests the fetcher cancelled (the view no longer wants them).
    fn abort_cancelled(&self) {
        let ids = self.fetcher.borrow_mut().take_cancelled();
        let mut aborts = self.aborts.borrow_mut();
        for id in ids {
            if let Some(c) = aborts.remove(&id) {
                c.abort();
            }
        }
    }

    /// Stops streaming: requests in flight are aborted, their answers and the decode
    /// workers' land nowhere, no new ones start.
    pub fn close(&self) {
        self.closed.set(true);
        for (_, c) in self.aborts.borrow_mut().drain() {
            c.abort();
        }
    }

    fn dispatcher(&self) -> Option<Dispatch> {
        let decoders = self.decoder.clone()?;
        Some(Dispatch {
            decoders,
            fetcher: self.fetcher.clone(),
            failed: self.workers_failed.clone(),
            closed: self.closed.clone(),
            mips: self.mips,
            blocks: self.blocks,
        })
    }
}

/// Hands fetched patches to the decode workers, as many as they take
/// ([`JOBS_PER_WORKER`], [`JOB_BYTES`]); each reply is delivered to the fetcher when it
/// comes (taken by the next frame) and hands out more, as does each fetch completed, so
/// the workers never wait for a frame.
fn dispatch(d: &Dispatch) {
    if d.failed.get() || d.closed.get() {
        return;
    }
    let jobs = d.fetcher.borrow_mut().take_jobs(
        d.decoders.workers * JOBS_PER_WORKER,
        JOB_BYTES,
        d.mips,
        d.blocks,
    );
    for (node, job) in jobs {
        let promise = match d
            .decoders
            .decode
            .call1(&JsValue::NULL, &js_sys::Uint8Array::from(&job[..]))
        {
            Ok(p) => js_sys::Promise::resolve(&p),
            Err(e) => {
                workers_failed(&d.fetcher, &d.failed, node, job, format!("{e:?}"));
                continue;
            }
        };
        let d = d.clone();
        spawn_local(async move {
            let r = wasm_bindgen_futures::JsFuture::from(promise).await;
            if d.closed.get() {
                return;
            }
            let t0 = now_ms();
            let reply = match r {
                Ok(v) => v
                    .dyn_into::<js_sys::Uint8Array>()
                    .map_err(|_| "a reply that is not bytes".to_string())
                    .and_then(|a| crate::wire::read_reply(node, &JsBytes(a))),
                Err(e) => Err(e.as_string().unwrap_or_else(|| format!("{e:?}"))),
            };
            match reply {
                Ok((answer, ms)) => {
                    d.fetcher.borrow_mut().deliver(answer, ms, now_ms() - t0);
                    dispatch(&d);
                }
                Err(why) => workers_failed(&d.fetcher, &d.failed, node, job, why),
            }
        });
    }
}

/// What sending requests needs, cloned into each request's future.
#[derive(Clone)]
struct Pipes {
    http: Rc<Http>,
    fetcher: Rc<RefCell<Fetcher>>,
    fatal: Rc<RefCell<Option<String>>>,
    closed: Rc<Cell<bool>>,
    aborts: Aborts,
    workers: Option<Dispatch>,
}

fn pump(p: &Pipes) {
    let Pipes {
        http,
        fetcher,
        fatal,
        closed,
        aborts,
        ..
    } = p;
    if closed.get() || fatal.borrow().is_some() {
        return;
    }
    loop {
        let Some(req) = fetcher.borrow_mut().next_request() else {
            break;
        };
        // Past the end of a truncated file (opened at the length its header names):
        // those patches do not exist; they fail for good, their parents stay drawn.
        if req.range.end > http.len() {
            fetcher.borrow_mut().fail(
                req.id,
                &format!(
                    "the file ends at byte {}: the model is truncated",
                    http.len()
                ),
            );
            continue;
        }
        // Without an AbortController (none in this context) the request just runs on.
        let abort = web_sys::AbortController::new().ok();
        if let Some(c) = &abort {
            aborts.borrow_mut().insert(req.id, c.clone());
        }
        let p = p.clone();
        spawn_local(async move {
            let signal = abort.as_ref().map(|c| c.signal());
            let r = p
                .http
                .get_abortable(req.range.clone(), false, signal.as_ref())
                .await;
            p.aborts.borrow_mut().remove(&req.id);
            let Pipes {
                fetcher,
                fatal,
                closed,
                workers,
                ..
            } = &p;
            // Closed, or cancelled: the fetcher forgot the request (an answer would
            // be dropped anyway).
            if closed.get() || signal.is_some_and(|s| s.aborted()) {
                return;
            }
            let r = match r {
                Ok(body) => Ok(body),
                Err(HttpError::Fatal(m)) => {
                    *fatal.borrow_mut() = Some(m.clone());
                    Err(m)
                }
                Err(HttpError::Transient(m)) => Err(m),
            };
            fetcher.borrow_mut().complete(req.id, r);
            // The fetched patches go to the workers now, not at the next frame.
            if let Some(d) = workers {
                dispatch(d);
            }
            pump(&p);
        });
    }
}

/// A worker's reply where it arrived (a `Uint8Array`), read by `crate::wire` straight
/// into the decoded patch's arrays.
struct JsBytes(js_sys::Uint8Array);

impl crate::wire::ReplyBytes for JsBytes {
    fn len(&self) -> usize {
        self.0.length() as usize
    }
    fn copy_into(&self, at: usize, dst: &mut [u8]) {
        self.0
            .subarray(at as u32, (at + dst.len()) as u32)
            .copy_to(dst);
    }
}

/// A decode worker failed (it could not start, or crashed): node `node`'s job goes back
/// to the fetcher, decoded on this thread, as is everything after it.
fn workers_failed(
    fetcher: &RefCell<Fetcher>,
    failed: &Cell<bool>,
    node: u32,
    job: Vec<u8>,
    why: String,
) {
    if !failed.replace(true) {
        web_sys::console::warn_1(
            &format!("tessera: decode workers failed ({why}); decoding on the main thread").into(),
        );
    }
    fetcher.borrow_mut().requeue(node, job);
}

impl PatchSource for Remote {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        self.fetcher.borrow_mut().set_wanted(wanted);
        self.abort_cancelled();
        self.pump();
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        if let Some(d) = self.dispatcher().filter(|_| !self.workers_failed.get()) {
            dispatch(&d);
            // The workers' answers; fetched patches wait for a worker.
            self.fetcher.borrow_mut().drain_settled(out);
        } else {
            self.fetcher
                .borrow_mut()
                .drain(out, DECODE_BUDGET_MS, now_ms);
        }
        self.pump();
    }
    fn pending(&self) -> usize {
        // Fetched patches not decoded yet are not answered yet either.
        let fetch = self.fetcher.borrow();
        fetch.pending() + fetch.undecoded()
    }
    fn read_now(&mut self, nodes: &[u32]) -> Option<Vec<Answer>> {
        // Only the roots, once: they were fetched before the viewer was made.
        let roots = std::mem::take(&mut self.roots);
        (!roots.is_empty() && roots.len() == nodes.len()).then_some(roots)
    }
    fn set_index(&mut self, index: &Arc<ModelIndex>) {
        self.fetcher.borrow_mut().set_index(index.clone());
    }
}

/// Main-thread time of uploads into the GPU cache (textured patches: the mip chain
/// made on the CPU, in wasm, and the texture copies), for the frame statistics.
#[derive(Clone, Copy, Debug, Default)]
struct UploadTimes {
    uploads: u64,
    textured: u64,
    ms: f64,
    textured_ms: f64,
    max_ms: f64,
}

/// The GPU cache's store with its uploads timed ([`UploadTimes`]).
struct TimedStore<'a> {
    inner: GpuStore<'a>,
    times: &'a mut UploadTimes,
}

impl<'a> TimedStore<'a> {
    /// Model 0's store in `cache`, its uploads timed into `times`.
    fn of(
        cache: &'a mut GpuCache,
        gpu: &'a Gpu,
        quant_step: f64,
        times: &'a mut UploadTimes,
    ) -> TimedStore<'a> {
        TimedStore {
            inner: GpuStore {
                cache,
                device: &gpu.device,
                queue: &gpu.queue,
                quant_step,
                model: 0,
            },
            times,
        }
    }
}

impl ResidentStore for TimedStore<'_> {
    fn bytes_for(&self, patch: &PatchData) -> u64 {
        self.inner.bytes_for(patch)
    }
    fn estimate_bytes(&self, vertices: u32, triangles: u32) -> u64 {
        self.inner.estimate_bytes(vertices, triangles)
    }
    fn estimate_texture_bytes(&self, size: [u16; 2]) -> u64 {
        self.inner.estimate_texture_bytes(size)
    }
    fn has_room(&self, patches: &[&PatchData]) -> bool {
        self.inner.has_room(patches)
    }
    fn upload_in_group(
        &mut self,
        node: u32,
        patch: &PatchData,
        siblings: &[&PatchData],
    ) -> Result<u64, StoreError> {
        let t0 = now_ms();
        let r = self.inner.upload_in_group(node, patch, siblings);
        if r.is_ok() {
            let ms = now_ms() - t0;
            let t = &mut *self.times;
            t.uploads += 1;
            t.ms += ms;
            t.max_ms = t.max_ms.max(ms);
            if patch.texture.is_some() {
                t.textured += 1;
                t.textured_ms += ms;
            }
        }
        r
    }
    fn evict(&mut self, node: u32) {
        self.inner.evict(node);
    }
    fn resident_bytes(&self) -> u64 {
        self.inner.resident_bytes()
    }
    fn flush(&mut self) {
        self.inner.flush();
    }
}

/// The canvas's GPU cache (one model) as the driver's stores, uploads timed.
struct WebStores<'a> {
    cache: &'a mut GpuCache,
    gpu: &'a Gpu,
    quant_step: f64,
    times: &'a mut UploadTimes,
}

impl SceneStores for WebStores<'_> {
    type Store<'b>
        = TimedStore<'b>
    where
        Self: 'b;
    fn store(&mut self, _model: usize) -> TimedStore<'_> {
        TimedStore::of(self.cache, self.gpu, self.quant_step, self.times)
    }
    fn index_grown(&mut self, _model: usize, index: &ModelIndex) {
        // Levels and parents of the new nodes, for their vertex tags and texel detail.
        self.cache.set_nodes(0, index);
    }
}

/// What a depth pick (the point drawn under a pixel) is for.
#[derive(Clone, Copy, Debug)]
enum Purpose {
    /// Wheel steps, zoomed toward the point (toward the pivot over the background).
    Zoom(f64),
    /// Double-click: the pivot moves to the point.
    Recentre,
    /// The point a pinch zooms about (taken once, when the pinch starts).
    Pinch,
    /// Asked by the page (`point_at`); answered in the frame statistics.
    Query(u32),
}

#[derive(Clone, Copy, Debug)]
struct PickRequest {
    x: f64,
    y: f64,
    purpose: Purpose,
}

/// A pinch in progress: waiting for its point (the spread so far accumulated), or
/// zooming about it (None: the background, toward the pivot).
#[derive(Clone, Copy, Debug)]
enum Pinch {
    Waiting(f64),
    About(Option<DVec3>),
}

/// A view of one remote model in a canvas. See the module docs.
#[wasm_bindgen]
pub struct Viewer {
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: Renderer,
    cache: GpuCache,
    depth: wgpu::TextureView,
    /// The model streamed (what the three.js adapter's `Stream` shares).
    m: Streamed,
    nav: Navigator,
    quant_step: f64,
    has_colors: bool,
    /// The model has patch textures (`ATTR_TEXTURE`).
    textured: bool,
    uploads: UploadTimes,
    last_ms: Option<f64>,
    converged: bool,
    dirty: bool,
    drag: Option<i16>,
    pointer: (f64, f64),
    /// Depth picks: the reader, the requests waiting for it, the one in flight (with
    /// the camera and planes of the frame it reads), answers for the page.
    picker: DepthPicker,
    picks: VecDeque<PickRequest>,
    pick_in_flight: Option<(PickRequest, Camera, (f64, f64))>,
    answers: Vec<Value>,
    pinch: Option<Pinch>,
    /// The camera and near/far planes of the frame the depth texture holds.
    drawn: Option<(Camera, (f64, f64))>,
}

fn depth_view(device: &wgpu::Device, w: u32, h: u32) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("tessera web depth"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: tessera_render::DEPTH_FORMAT,
            // Sampled by the depth pick (crate::pick).
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

fn parse_camera(json: &str) -> Result<Camera, JsError> {
    Camera::from_json_str(json).map_err(|e| err(format!("camera: {e}")))
}

/// A grown index (or why growing failed), taken by the next frame.
type Grown = Rc<RefCell<Option<Result<ModelIndex, String>>>>;

/// The browser's `IndexGrower`: a task on the page's event loop reads more of the
/// paged index (pages doubled until another level shows: a page may end inside a
/// level, which stays hidden until it is whole, as `tessera-http` does) through the
/// ranges fetched so far; the next frame takes it. A failure is reported and retried
/// 2 s later.
pub(crate) struct WebGrower {
    index: Arc<ModelIndex>,
    http: Rc<Http>,
    sparse: Rc<RefCell<SparseBytes>>,
    closed: Rc<Cell<bool>>,
    grown: Grown,
    growing: Rc<Cell<bool>>,
    /// No growth before this time (after a failure), seconds.
    grow_after_s: f64,
}

impl IndexGrower for WebGrower {
    fn index(&self) -> &ModelIndex {
        &self.index
    }

    fn grow(&mut self, time_s: f64) {
        if self.growing.get() || time_s < self.grow_after_s {
            return;
        }
        self.growing.set(true);
        let (http, sparse, grown, growing, closed) = (
            self.http.clone(),
            self.sparse.clone(),
            self.grown.clone(),
            self.growing.clone(),
            self.closed.clone(),
        );
        let base = self.index.clone();
        spawn_local(async move {
            let shown = base.nodes().len();
            let mut cur = (*base).clone();
            let r = loop {
                let pages = (2 * cur.loaded_pages()).max(1);
                match read_with(&http, &sparse, |s| cur.grown(s, pages)).await {
                    Ok(next) if next.nodes().len() > shown || next.is_complete() => break Ok(next),
                    Ok(next) => cur = next,
                    Err(e) => break Err(e),
                }
            };
            if !closed.get() {
                *grown.borrow_mut() = Some(r);
            }
            growing.set(false);
        });
    }

    fn take(&mut self, time_s: f64) -> Option<Arc<ModelIndex>> {
        let grown = self.grown.borrow_mut().take();
        match grown {
            Some(Ok(ix)) if ix.nodes().len() > self.index.nodes().len() => {
                self.index = Arc::new(ix);
                Some(self.index.clone())
            }
            Some(Err(e)) => {
                web_sys::console::warn_1(
                    &format!("tessera: reading more of the index: {e}").into(),
                );
                self.grow_after_s = time_s + 2.0;
                None
            }
            _ => None,
        }
    }

    fn growing(&self) -> bool {
        self.growing.get()
    }
}

/// The browser's frame driver: one model, its [`Remote`], its index grown by a task,
/// its budgets a share of the page's.
pub(crate) type WebDriver = Driver<Remote, WebGrower, crate::budget::Registration>;

/// A model being streamed: what the canvas [`Viewer`] and the three.js adapter's
/// `Stream` share around their own stores: the shared frame driver
/// (`tessera_stream::Driver`, as the desktop's) over the model's scheduler, patch
/// source and index, and the figures of the frames.
pub(crate) struct Streamed {
    pub driver: WebDriver,
    opened_ms: f64,
    /// Milliseconds from `open` to the first frame drawn (the roots) and to the first
    /// converged frame.
    first_frame_ms: Option<f64>,
    converged_ms: Option<f64>,
    index_bytes: u64,
    frames: u64,
    /// Why part of the model cannot be shown (a truncated file), for the page.
    warning: Option<String>,
}

impl Drop for Streamed {
    fn drop(&mut self) {
        // Requests in flight are aborted; no new ones start.
        self.source().close();
    }
}

impl Streamed {
    /// The model opened (`rest`) with its `scheduler` over `source`; its budgets are
    /// the scheduler's at open, shared with the page's other models from the first
    /// frame on.
    pub fn new(
        index: Arc<ModelIndex>,
        scheduler: Scheduler,
        source: Remote,
        rest: OpenedRest,
        opened_ms: f64,
    ) -> Streamed {
        let grower = WebGrower {
            index,
            http: source.http.clone(),
            sparse: rest.sparse,
            closed: source.closed.clone(),
            grown: Rc::new(RefCell::new(None)),
            growing: Rc::new(Cell::new(false)),
            grow_after_s: 0.0,
        };
        let mut driver = Driver::new(crate::budget::Registration::new(scheduler.budgets()));
        driver.add(scheduler, source, grower);
        Streamed {
            driver,
            opened_ms,
            first_frame_ms: None,
            converged_ms: None,
            index_bytes: rest.index_bytes,
            frames: 0,
            warning: rest.warning,
        }
    }

    /// The model's scheduler.
    pub fn scheduler(&self) -> &Scheduler {
        &self.driver.model(0).scheduler
    }

    /// The model's scheduler, mutably.
    pub fn scheduler_mut(&mut self) -> &mut Scheduler {
        &mut self.driver.model_mut(0).scheduler
    }

    /// The model's patch source.
    pub fn source(&self) -> &Remote {
        &self.driver.model(0).source
    }

    /// The model's patch source, mutably.
    pub fn source_mut(&mut self) -> &mut Remote {
        &mut self.driver.model_mut(0).source
    }

    /// The index read so far.
    pub fn index(&self) -> &ModelIndex {
        self.driver.model(0).index()
    }

    /// The index read so far, shared.
    pub fn index_arc(&self) -> Arc<ModelIndex> {
        self.driver.model(0).grower.index.clone()
    }

    /// The last frame's statistics.
    pub fn stats(&self) -> &FrameStats {
        self.driver.model(0).stats()
    }

    /// Whether the model is hidden (a view scrolled away: [`Viewer::set_visible`]):
    /// its frames draw and ask for nothing and its demand is 0.
    pub fn hidden(&self) -> bool {
        !self.driver.model(0).is_visible()
    }

    /// Hides or shows the model from the next frame on.
    pub fn set_hidden(&mut self, hidden: bool) {
        self.driver.set_visible(0, !hidden);
    }

    /// Changes the model's own memory budget (split as every front end splits one
    /// memory figure, `tessera_stream::memory_split`; its share of the page's from the
    /// next frame on).
    pub fn set_memory(&mut self, bytes: u64) {
        self.driver.budgets().set_cap(memory_split(bytes));
    }

    /// Counts a frame shown (after the driver's frame and its draw).
    pub fn framed(&mut self) {
        self.frames += 1;
        if self.first_frame_ms.is_none() && self.stats().selected_nodes > 0 {
            self.first_frame_ms = Some(now_ms() - self.opened_ms);
        }
    }

    /// Whether streaming has settled (the driver's rule, as the desktop's) after a
    /// frame shown.
    pub fn settled(&self) -> bool {
        self.driver.settled() && self.first_frame_ms.is_some()
    }

    /// Records whether the view converged this frame (the first time: when).
    pub fn converged(&mut self, converged: bool) {
        if converged && self.converged_ms.is_none() {
            self.converged_ms = Some(now_ms() - self.opened_ms);
        }
    }

    /// The statistics both front ends report (see `web/tessera.js`); `idle`: the view
    /// converged.
    pub fn stats_json(&self, idle: bool) -> Value {
        let source = self.source();
        let fetch = source.fetcher.borrow();
        let f = fetch.stats();
        let main_decoded = f.decoded - f.worker_decoded;
        let s = self.stats();
        let index = self.index();
        json!({
            "idle": idle,
            "frame": self.frames,
            "nodes": s.selected_nodes,
            "triangles": s.triangles,
            "max_level": s.max_level,
            "pending": s.pending_loads,
            "in_flight": fetch.in_flight(),
            "undecoded": fetch.undecoded(),
            "bytes_received": source.http.bytes.get(),
            "index_bytes": self.index_bytes,
            "requests": source.http.requests.get(),
            "failed_requests": f.failed_requests,
            // Requests aborted because the view stopped wanting them, and the bytes
            // they asked for.
            "cancelled_requests": f.cancelled_requests,
            "cancelled_bytes": f.cancelled_bytes,
            // Models on the page sharing its memory budget (crate::budget).
            "page_models": self.driver.budgets().page_models(),
            // Groups the view needs that its budgets leave out this frame.
            "budget_limited": s.budget_limited,
            // The store bytes the view's whole cut needs (its demand on the budgets).
            "wanted_bytes": s.wanted_bytes,
            "failed_patches": s.failed_patches,
            "index_nodes": index.nodes().len(),
            "model_nodes": index.header().node_count,
            "ram_bytes": s.ram_resident_bytes,
            "selection_ms": s.selection_ms,
            // Patches decoded: all, and by the decode workers (their time is off the
            // main thread, mips included); the decode_ms_* figures are this thread's
            // (roots, and every patch without workers).
            "decoded": f.decoded,
            "worker_decoded": f.worker_decoded,
            "worker_decode_ms_mean": if f.worker_decoded > 0 { f.worker_ms / f.worker_decoded as f64 } else { 0.0 },
            "at_workers": fetch.at_workers(),
            // Main-thread time taking the workers' replies in (copies).
            "reply_ms_mean": if f.worker_decoded > 0 { f.reply_ms / f.worker_decoded as f64 } else { 0.0 },
            "reply_ms_max": f.reply_max_ms,
            "decode_workers": source.decoder.as_ref().map_or(0, |d| d.workers),
            "workers_failed": source.workers_failed.get(),
            "decode_ms_mean": if main_decoded > 0 { f.decode_ms / main_decoded as f64 } else { 0.0 },
            "decode_ms_max": f.decode_max_ms,
            "decode_ms_total": f.decode_ms,
            "first_frame_ms": self.first_frame_ms,
            "converged_ms": self.converged_ms,
            // A problem that does not stop the view (a truncated file), or null.
            "warning": self.warning,
        })
    }
}

/// A model opened over HTTP: what [`open_model`] read.
pub(crate) struct Opened {
    pub http: Rc<Http>,
    pub sparse: Rc<RefCell<SparseBytes>>,
    pub index: ModelIndex,
    /// The roots, fetched and decoded (answered by [`Remote`]'s `read_now`).
    pub roots: Vec<Answer>,
    /// The roots' vertices in model coordinates (or the bounding sphere's box), which
    /// frame the home view, and their box.
    pub scene: ScenePoints,
    /// Why part of the model cannot be shown (a truncated file), for the page.
    pub warning: Option<String>,
    /// Bytes fetched to read the header and the top of the index.
    pub index_bytes: u64,
}

/// What [`Streamed::new`] keeps of an [`Opened`].
pub(crate) struct OpenedRest {
    sparse: Rc<RefCell<SparseBytes>>,
    warning: Option<String>,
    index_bytes: u64,
}

impl Opened {
    /// The connection, the index, the roots, and the rest for [`Streamed::new`].
    pub fn split(self) -> (Rc<Http>, ModelIndex, Vec<Answer>, OpenedRest) {
        let rest = OpenedRest {
            sparse: self.sparse,
            warning: self.warning,
            index_bytes: self.index_bytes,
        };
        (self.http, self.index, self.roots, rest)
    }
}

/// Opens the model at `url` (what [`Viewer::open`] and [`crate::stream::Stream::open`]
/// share): its first `prefix_bytes`, the top of its index, its roots. A file shorter
/// than its header says is opened at the header's length (the warning says so).
pub(crate) async fn open_model(url: &str, prefix_bytes: u64) -> Result<Opened, JsError> {
    // The model: its first 64 KiB, the top of its index, its roots.
    let http = Rc::new(Http::new(url));
    let prefix = http
        .open(prefix_bytes)
        .await
        .map_err(|e| err(e.message()))?;
    // A file shorter than its header says (a partial upload or copy): opened at the
    // length the header names, so the index and the patches that exist are read and
    // shown; what lies past the end is reported, its nodes' parents drawn instead.
    let served = http.len();
    let (length, warning) = match ModelIndex::parse_header(&prefix, served) {
        Err(e @ tessera_format::FormatError::Truncated { expected_bytes, .. })
            if prefix.len() as u64 >= tessera_format::HEADER_BYTES && expected_bytes > served =>
        {
            (
                expected_bytes,
                Some(format!(
                    "{url}: {e}: the patches stored past byte {served} are missing \
                         (coarser levels are shown in their place)"
                )),
            )
        }
        _ => (served, None),
    };
    let sparse = Rc::new(RefCell::new(SparseBytes::new(length)));
    sparse.borrow_mut().insert(0, prefix);
    let cannot = |m: String| err(format!("cannot open {url}: {m}"));
    let index = read_with(&http, &sparse, |s| ModelIndex::read_top(s, TOP_PAGES))
        .await
        .map_err(cannot)?;
    let index_bytes = http.bytes.get();
    let root_count = (index.header().root_count as usize).min(index.nodes().len());
    let roots_range = match root_count {
        0 => return Err(cannot("the model has no roots".into())),
        n => {
            let a = index.patch_range(0).map_err(|e| cannot(e.to_string()))?;
            let b = index
                .patch_range(n - 1)
                .map_err(|e| cannot(e.to_string()))?;
            a.start..b.end
        }
    };
    let body = read_with(&http, &sparse, |s| {
        use tessera_format::ByteSource;
        s.read(roots_range.clone()).map(|b| b.into_owned())
    })
    .await
    .map_err(cannot)?;
    let grid = Grid::of_header(index.header());
    let mut points = Vec::new();
    let mut roots = Vec::new();
    for n in 0..root_count {
        let r = index.patch_range(n).map_err(|e| cannot(e.to_string()))?;
        let at = (r.start - roots_range.start) as usize..(r.end - roots_range.start) as usize;
        let p = index.decode_patch(n, &body[at]);
        if let Ok(p) = &p {
            points.extend(p.positions.iter().map(|&q| DVec3::from(grid.position(q))));
        }
        roots.push(Answer::from_result(n as u32, p));
    }
    let scene = ScenePoints::from_points(&points, HOME_POINTS, index.header().bounding_sphere);

    Ok(Opened {
        http,
        sparse,
        index,
        roots,
        scene,
        warning,
        index_bytes,
    })
}

/// The options `Viewer::open` and `Stream::open` share (their JSON `options`).
pub(crate) struct StreamOptions {
    /// `tolerancePx` (default 1).
    pub tolerance_px: f32,
    /// `memoryBytes` (default 512 MiB): half for the resident patches, a quarter for
    /// decoded patches waiting ([`new_scheduler`]).
    pub memory: u64,
    /// `prefixBytes` (default [`PREFIX_BYTES`]).
    pub prefix_bytes: u64,
    /// `maxTextureDim` (default none).
    pub max_texture_dim: Option<u32>,
    /// `morph` (default true): geomorphing (patches blend from their parent's shape;
    /// false draws each at its own, so refinements pop in).
    pub morph: bool,
}

impl StreamOptions {
    /// The shared options of `options` (JSON), and the whole object for the others.
    pub fn parse(options: &str) -> Result<(StreamOptions, Value), JsError> {
        let opts: Value =
            serde_json::from_str(options).map_err(|e| err(format!("options: {e}")))?;
        let o = StreamOptions {
            tolerance_px: opts["tolerancePx"].as_f64().unwrap_or(1.0) as f32,
            memory: opts["memoryBytes"].as_f64().unwrap_or(512.0 * 1048576.0) as u64,
            prefix_bytes: opts["prefixBytes"]
                .as_f64()
                .map_or(PREFIX_BYTES, |b| (b as u64).max(1)),
            max_texture_dim: opts["maxTextureDim"]
                .as_f64()
                .filter(|d| d.is_finite() && *d >= 1.0)
                .map(|d| d as u32),
            morph: opts["morph"].as_bool().unwrap_or(true),
        };
        Ok((o, opts))
    }
}

/// The scheduler of an opened model with the options `o`: `memory` bytes split as
/// every front end splits them (`tessera_stream::memory_split`).
pub(crate) fn new_scheduler(index: &ModelIndex, o: &StreamOptions) -> Scheduler {
    let mut options = SchedulerOptions {
        tolerance_px: o.tolerance_px,
        clock: now_ms,
        ..SchedulerOptions::default()
    }
    .with_memory(o.memory);
    options.morph.enabled &= o.morph;
    Scheduler::new(index, options)
}

/// The navigation of every front end over the roots' extent (`tessera_nav::home_navigator`):
/// the home view framed by them, up guessed from their box.
pub(crate) fn home_navigator(scene: &ScenePoints, quant_step: f64, w: u32, h: u32) -> Navigator {
    tessera_nav::home_navigator(scene, scene.guess_up(), quant_step, w, h)
}

#[wasm_bindgen]
impl Viewer {
    /// Opens the model at `url` in `canvas` (its current pixel size). `options` is a
    /// JSON object: `tolerancePx` (default 1), `memoryBytes` (default 512 MiB: half for
    /// the GPU cache, a quarter for decoded patches, as `tessera render --memory`),
    /// `camera` (a camera of docs/camera.md; default the home view framed by the roots),
    /// `prefixBytes` (bytes of the first request, default 64 KiB: the header and the
    /// top of the index of most models; what it lacks is fetched after),
    /// `maxTextureDim` (default: the adapter's; lower makes a device whose largest
    /// texture is that, as a smaller GPU's, at least the canvas's size),
    /// `cancelRequests` (default true: requests the view stopped wanting are aborted),
    /// `morph` (default true: geomorphing). Errors carry a message meant for the page.
    pub async fn open(
        canvas: web_sys::HtmlCanvasElement,
        url: String,
        options: String,
    ) -> Result<Viewer, JsError> {
        let opened_ms = now_ms();
        let (o, opts) = StreamOptions::parse(&options)?;
        let StreamOptions {
            memory,
            prefix_bytes,
            max_texture_dim,
            ..
        } = o;
        let camera = match &opts["camera"] {
            Value::Null => None,
            v => Some(Camera::from_json_value(v).map_err(|e| err(format!("camera: {e}")))?),
        };
        let (w, h) = (canvas.width().max(1), canvas.height().max(1));

        // The device: WebGL2 (see ARCHITECTURE.md for why not WebGPU).
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = wgpu::Backends::GL;
        let instance = wgpu::Instance::new(desc);
        let no_webgl = |e: &dyn std::fmt::Display| {
            err(format!(
                "this browser cannot draw with WebGL2 ({e}): enable WebGL or hardware \
                 acceleration, or use a browser that has it"
            ))
        };
        let surface = instance
            .create_surface(wgpu::SurfaceTarget::Canvas(canvas))
            .map_err(|e| no_webgl(&e))?;
        // `maxTextureDim`: never below the canvas's size.
        let gpu = Gpu::with_instance_limited_async(
            instance,
            Some(&surface),
            max_texture_dim.map(|d| d.max(w).max(h)),
        )
        .await
        .map_err(|e| no_webgl(&e))?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // The frame is shown as the patch shader writes it (no sRGB encoding), as the
        // native PNGs store it.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| err("the canvas offers no colour format"))?;
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: w,
            height: h,
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps
                .alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&gpu.device, &config);

        let opened = open_model(&url, prefix_bytes).await?;
        let grid = Grid::of_header(opened.index.header());
        let mut nav = home_navigator(&opened.scene, grid.step(), w, h);
        let (http, index, roots, opened_rest) = opened.split();
        if let Some(cam) = &camera {
            nav.set_camera(cam)
                .map_err(|e| err(format!("camera: {e}")))?;
            nav.resize(w, h);
        }

        let index = Arc::new(index);
        let mut renderer = Renderer::new(&gpu.device, format);
        renderer.set_base_vertex(gpu.base_vertex());
        let has_colors = index.header().attributes & ATTR_COLORS != 0;
        renderer.has_colors = has_colors;
        let mut cache = GpuCache::new(&gpu.device, memory_split(memory).0);
        // Levels for the vertex tags; parents and their errors for the texel detail a
        // textured patch morphs from (as the desktop).
        cache.set_nodes(0, &index);
        // Textured models (a texture per patch): uploaded with their textures (BC7 as
        // blocks where the device samples them, else RGBA8 with mips, from the first
        // level that fits the device's largest texture) and drawn through the textured
        // pipeline, as the desktop.
        let textured = index.header().attributes & ATTR_TEXTURE != 0;
        cache.set_textured(0, textured);
        cache.set_texture_codec(0, index.header().patch_texture_codec());
        let mut scheduler = new_scheduler(&index, &o);
        let mut source = Remote::new(http, &index, roots, textured);
        source.blocks = cache.bc7_block_limit();
        // `cancelRequests: false` lets requests the view stopped wanting finish (to
        // compare).
        if opts["cancelRequests"] == Value::Bool(false) {
            source.fetcher.borrow_mut().set_cancel(false);
        }
        let quant_step = grid.step();
        let mut uploads = UploadTimes::default();
        scheduler.load_roots(
            &mut source,
            &mut TimedStore::of(&mut cache, &gpu, quant_step, &mut uploads),
        );
        let depth = depth_view(&gpu.device, w, h);
        let picker = DepthPicker::new(&gpu.device);
        Ok(Viewer {
            gpu,
            surface,
            config,
            renderer,
            cache,
            depth,
            m: Streamed::new(index, scheduler, source, opened_rest, opened_ms),
            nav,
            quant_step,
            has_colors,
            textured,
            uploads,
            last_ms: None,
            converged: false,
            dirty: true,
            drag: None,
            pointer: (0.0, 0.0),
            picker,
            picks: VecDeque::new(),
            pick_in_flight: None,
            answers: Vec::new(),
            pinch: None,
            drawn: None,
        })
    }

    /// One frame at `time_ms` (`requestAnimationFrame`'s time): navigation, the
    /// scheduler (answers in, requests out, uploads), and a draw when anything changed.
    /// Returns the statistics as JSON (see `web/tessera.js`); a fatal streaming error
    /// comes back as an exception.
    pub fn frame(&mut self, time_ms: f64) -> Result<String, JsError> {
        if let Some(m) = self.m.source().fatal.borrow().as_ref() {
            return Err(err(m));
        }
        let dt = self.last_ms.map_or(0.0, |t| ((time_ms - t) / 1e3).max(0.0));
        self.last_ms = Some(time_ms);
        let time_s = time_ms / 1e3;
        // Depth picks answered since the last frame act now (zoom, recentre, pinch),
        // before the navigation moves; the next one reads the frame last drawn.
        self.poll_picks();
        let moving = self.nav.needs_update() || self.drag.is_some();
        self.nav.update(dt);
        let mut stores = WebStores {
            cache: &mut self.cache,
            gpu: &self.gpu,
            quant_step: self.quant_step,
            times: &mut self.uploads,
        };
        // A paged index read further: select over more of it.
        if self.m.driver.take_grown(time_s, &mut stores) {
            self.dirty = true;
        }
        // (An idle view follows its share of the page's budgets too; a hidden one runs
        // the driver's idle frame: no selection, draw or request, its memory given back.)
        let idle = self.converged
            && !moving
            && !self.dirty
            && !self.m.driver.budgets_moved(time_s, u64::MAX);
        let mut drew = false;
        if self.m.hidden() {
            self.m.driver.frame(&self.nav.camera(), time_s, &mut stores);
        } else if !idle {
            let camera = self.nav.camera();
            self.m.driver.frame(&camera, time_s, &mut stores);
            self.dirty = false;
            // A frame the canvas could not take (resized, lost) is drawn again next time.
            drew = self.draw(&camera);
            self.dirty |= !drew;
            self.m.framed();
        }
        let converged = self.m.settled()
            && !self.nav.needs_update()
            && self.drag.is_none()
            && self.picks.is_empty()
            && self.pick_in_flight.is_none();
        self.converged = converged;
        self.m.converged(converged);
        let s = self.m.stats();
        let u = self.uploads;
        // The drawn patch with the largest texture: its size in the file and as
        // uploaded (from the first mip that fits the device's largest texture).
        let largest_texture = self
            .m
            .scheduler()
            .draw()
            .iter()
            .filter_map(|&n| {
                let t = &self.cache.slot(n)?.texture.as_ref()?.texture;
                let stored = self.m.index().nodes().get(n as usize)?.texture_size;
                Some((n, stored, [t.width(), t.height()]))
            })
            .max_by_key(|&(n, stored, _)| (stored[0].max(stored[1]), std::cmp::Reverse(n)))
            .map(
                |(n, stored, uploaded)| json!({"node": n, "stored": stored, "uploaded": uploaded}),
            );
        let mut out = self.m.stats_json(converged);
        let own = json!({
            // Whether this call drew the canvas (a screenshot reads it right after).
            "drew": drew,
            // Not shown (scrolled away): nothing drawn or fetched, demand 0.
            "hidden": self.m.hidden(),
            // GPU bytes of the resident patches, their textures (mips included) in
            // them, and the textures' part.
            "gpu_bytes": s.gpu_resident_bytes,
            "gpu_budget_bytes": s.gpu_budget_bytes,
            "gpu_texture_bytes": self.cache.stats().texture_bytes,
            "textured": self.textured,
            // The device's largest 2D texture: larger patch textures are uploaded from
            // their first mip that fits.
            "max_texture_dim": self.gpu.device.limits().max_texture_dimension_2d,
            // BC7 textures go to the GPU as blocks (the device samples BC), else RGBA8.
            "texture_blocks": self.cache.samples_bc7(),
            "adapter_max_texture_dim": self.gpu.adapter.limits().max_texture_dimension_2d,
            // {"node", "stored": [w, h], "uploaded": [w, h]} or null (no texture drawn).
            "largest_texture": largest_texture,
            // Uploads into the GPU cache (main thread): textured patches make their
            // mip chain on the CPU there.
            "uploads": u.uploads,
            "upload_ms_total": u.ms,
            "upload_ms_max": u.max_ms,
            "textured_uploads": u.textured,
            "textured_upload_ms_mean": if u.textured > 0 { u.textured_ms / u.textured as f64 } else { 0.0 },
            "adapter": self.gpu.adapter_label,
            "pivot": self.nav.pivot().to_array(),
            // Answers to point_at: [{"id", "point": [x, y, z] or null}].
            "picks": std::mem::take(&mut self.answers),
        });
        if let (Value::Object(o), Value::Object(mine)) = (&mut out, own) {
            o.extend(mine);
        }
        Ok(out.to_string())
    }

    /// Draws and presents the frame; false when the canvas gave no texture.
    fn draw(&mut self, camera: &Camera) -> bool {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.gpu.device, &self.config);
                return false;
            }
            _ => return false,
        };
        let view = frame.texture.create_view(&Default::default());
        // Near and far fitted to the drawn nodes' tight spheres (the driver's, as the
        // desktop's).
        let planes = self.m.driver.fitted_planes(camera);
        self.drawn = Some((camera.clone(), planes));
        let params = FrameParams::with_planes(
            camera,
            self.m.index().header().cube_origin,
            planes,
            Shading::default(),
        );
        self.renderer
            .set_model_frame(&self.gpu.queue, 0, &params, self.has_colors);
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("tessera web frame"),
            });
        let cache = &self.cache;
        let ratios = self.m.scheduler().morph_ratios();
        let slots = self
            .m
            .scheduler()
            .draw()
            .iter()
            .enumerate()
            .filter_map(|(k, &n)| {
                let r = ratios.get(k).copied().unwrap_or(0.0);
                cache.slot(n).map(|s| (s, r))
            });
        let device = &self.gpu.device;
        self.renderer
            .encode_pass(device, &mut enc, &view, &self.depth, cache, slots, true);
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.queue.present(frame);
        true
    }

    /// Decodes fetched patches with `decode` from now on: called with a job's bytes
    /// (a `Uint8Array`, `crate::wire`), it returns a promise of the reply's bytes (the
    /// page's decode workers run [`crate::worker::decode_job`] on it). `workers` is how
    /// many run at once. Without a decoder, or once it fails, patches are decoded on
    /// this thread between frames.
    pub fn set_decoder(&mut self, decode: js_sys::Function, workers: u32) {
        self.m.source_mut().set_decoder(decode, workers);
    }

    /// The canvas was resized to `width` x `height` pixels.
    pub fn resize(&mut self, width: u32, height: u32) {
        let (w, h) = (width.max(1), height.max(1));
        if (w, h) == (self.config.width, self.config.height) {
            return;
        }
        self.config.width = w;
        self.config.height = h;
        self.surface.configure(&self.gpu.device, &self.config);
        self.depth = depth_view(&self.gpu.device, w, h);
        // The new depth texture holds no frame yet.
        self.drawn = None;
        self.nav.resize(w, h);
        self.dirty = true;
    }

    /// The current camera as JSON (docs/camera.md), sized as the canvas.
    pub fn camera(&self) -> String {
        self.nav.camera().to_json_string()
    }

    /// Moves to `json` (a camera of docs/camera.md); the image keeps the canvas's size.
    pub fn set_camera(&mut self, json: &str) -> Result<(), JsError> {
        let cam = parse_camera(json)?;
        self.nav
            .set_camera(&cam)
            .map_err(|e| err(format!("camera: {e}")))?;
        self.nav.resize(self.config.width, self.config.height);
        self.dirty = true;
        Ok(())
    }

    /// Draws the next frame even when nothing changed (a screenshot reads the canvas
    /// right after that frame: a WebGL canvas is cleared once it has been shown).
    pub fn redraw(&mut self) {
        self.dirty = true;
    }

    /// Back to the home view.
    pub fn reset(&mut self) {
        self.nav.reset();
        self.dirty = true;
    }

    /// Changes the screen-space tolerance (pixels).
    pub fn set_tolerance_px(&mut self, tolerance_px: f32) {
        self.m.scheduler_mut().set_tolerance_px(tolerance_px);
        self.dirty = true;
    }

    /// Whether the canvas is on screen (the page's IntersectionObserver). A hidden view
    /// draws, selects and fetches nothing, and its demand on the page's budgets is 0,
    /// so the views on screen get the memory it held as they need it (it keeps what
    /// they leave it); shown again, it selects and draws at its next frame.
    pub fn set_visible(&mut self, visible: bool) {
        if self.m.hidden() == visible {
            self.m.set_hidden(!visible);
            self.dirty = true;
        }
    }

    /// A mouse button went down at (`x`, `y`) canvas pixels: 0 left (orbit; with
    /// `pan`, pan), 1 middle and 2 right (pan).
    pub fn pointer_down(&mut self, button: i16, x: f64, y: f64, pan: bool) {
        self.nav.press();
        self.drag = Some(if pan && button == 0 { 2 } else { button });
        self.pointer = (x, y);
        self.dirty = true;
    }

    /// The pointer moved to (`x`, `y`) canvas pixels.
    pub fn pointer_move(&mut self, x: f64, y: f64) {
        let (dx, dy) = (x - self.pointer.0, y - self.pointer.1);
        self.pointer = (x, y);
        match self.drag {
            Some(0) => self.nav.drag_orbit(dx, dy),
            Some(_) => self.nav.drag_pan(dx, dy),
            None => return,
        }
        self.dirty = true;
    }

    /// The button went up (inertia may carry the motion on).
    pub fn pointer_up(&mut self) {
        if self.drag.take().is_some() {
            self.nav.release();
            self.dirty = true;
        }
    }

    /// Two fingers' spread grew by `scale` (> 1 zooms in) around their centre
    /// (`x`, `y`) canvas pixels: [`Navigator::pinch`], at once, about the point drawn
    /// under the centre where the pinch started (picked once; the spread waits for it;
    /// the background: toward the pivot). [`Viewer::pinch_end`] ends the pinch.
    pub fn pinch(&mut self, scale: f64, x: f64, y: f64) {
        if !(scale.is_finite() && scale > 0.0) {
            return;
        }
        match &mut self.pinch {
            None => {
                self.pinch = Some(Pinch::Waiting(scale));
                self.request_pick(x, y, Purpose::Pinch);
            }
            Some(Pinch::Waiting(s)) => *s *= scale,
            Some(Pinch::About(p)) => self.nav.pinch(scale, *p),
        }
        self.dirty = true;
    }

    /// The fingers of a pinch left (or became one): the next pinch picks its point anew.
    pub fn pinch_end(&mut self) {
        if let Some(Pinch::Waiting(s)) = self.pinch.take() {
            // Its point never came: what the fingers did still counts.
            self.nav.pinch(s, None);
        }
        self.dirty = true;
    }

    /// Wheel steps (positive zooms in) with the cursor at (`x`, `y`) canvas pixels:
    /// toward the point drawn there, as the desktop (the depth under the cursor; the
    /// background: toward the pivot). The zoom starts when the depth has been read (a
    /// frame or two); steps at the same pixel meanwhile add up.
    pub fn wheel(&mut self, steps: f64, x: f64, y: f64) {
        if !steps.is_finite() || steps == 0.0 {
            return;
        }
        if let Some(PickRequest {
            x: px,
            y: py,
            purpose: Purpose::Zoom(s),
        }) = self.picks.back_mut()
        {
            if (*px - x).abs() + (*py - y).abs() < 2.0 {
                *s += steps;
                return;
            }
        }
        self.request_pick(x, y, Purpose::Zoom(steps));
        self.dirty = true;
    }

    /// Double-click at (`x`, `y`) canvas pixels: the pivot moves to the point drawn
    /// there ([`Navigator::recentre`]: animated, the orientation kept); nothing over the
    /// background.
    pub fn recentre_at(&mut self, x: f64, y: f64) {
        self.request_pick(x, y, Purpose::Recentre);
        self.dirty = true;
    }

    /// The point of the model's full-resolution surface under (`x`, `y`) canvas pixels
    /// (the ray through that pixel's centre), whatever is drawn: the leaf patches under
    /// the ray fetched batch by batch as the best-first walk reaches them
    /// ([`crate::plan::PickReader`], `tessera_pick`, the desktop's pick). A promise of
    /// the hit's JSON (`point`, `normal`: model coordinates; `distance` from the eye;
    /// `node`, `triangle`; `exact`: false when the index read so far shows no deeper
    /// level there or a patch could not be read; `passes`, `patches`, `bytes` fetched;
    /// `ms`), or `null` when the ray misses the model.
    pub fn pick(&self, x: f64, y: f64) -> js_sys::Promise {
        let camera = self.nav.camera();
        let ray = tessera_pick::Ray::through_pixel(&camera, x.floor() + 0.5, y.floor() + 0.5);
        let reader = crate::plan::PickReader::new(self.m.index_arc());
        let http = self.m.source().http.clone();
        let closed = self.m.source().closed.clone();
        wasm_bindgen_futures::future_to_promise(async move {
            let t0 = now_ms();
            let fail = |m: String| JsValue::from(js_sys::Error::new(&format!("pick: {m}")));
            let mut fetched = 0usize;
            for pass in 1..=64u32 {
                if closed.get() {
                    return Err(fail("the view was disposed".into()));
                }
                let attempt = reader.attempt(&ray).map_err(|e| fail(e.to_string()))?;
                match attempt {
                    crate::plan::PickAttempt::Done(hit, stats) => {
                        let Some(h) = hit else {
                            return Ok(JsValue::NULL);
                        };
                        let v = json!({
                            "point": h.point,
                            "normal": h.normal,
                            "distance": h.distance,
                            "node": h.node,
                            "triangle": h.triangle,
                            "exact": h.exact,
                            "passes": pass,
                            "patches": fetched,
                            "bytes": reader.held_bytes(),
                            "skipped": stats.skipped.len(),
                            "ms": now_ms() - t0,
                        });
                        return js_sys::JSON::parse(&v.to_string());
                    }
                    crate::plan::PickAttempt::Need(ranges) => {
                        for (range, nodes) in ranges {
                            let body = http
                                .get(range.clone(), false)
                                .await
                                .map_err(|e| fail(e.message().to_string()))?;
                            fetched += nodes.len();
                            reader.insert(range.start, &body, &nodes);
                        }
                    }
                }
            }
            Err(fail(
                "the ray crosses more patches than a pick reads".into(),
            ))
        })
    }

    /// Asks for the point drawn under (`x`, `y`) canvas pixels (the depth of the last
    /// frame, unprojected: the drawn cut's surface, model coordinates). The answer comes
    /// in a later frame's statistics, `picks`: `{"id": id, "point": [x, y, z] or null}`.
    pub fn point_at(&mut self, id: u32, x: f64, y: f64) {
        self.request_pick(x, y, Purpose::Query(id));
        self.dirty = true;
    }

    fn request_pick(&mut self, x: f64, y: f64, purpose: Purpose) {
        self.picks.push_back(PickRequest { x, y, purpose });
        self.start_pick();
    }

    /// Starts the next waiting pick when none is in flight (over the frame last drawn;
    /// none drawn yet: it is answered with nothing).
    fn start_pick(&mut self) {
        while self.pick_in_flight.is_none() {
            let Some(req) = self.picks.pop_front() else {
                return;
            };
            let (w, h) = (self.config.width, self.config.height);
            let inside =
                req.x >= 0.0 && req.y >= 0.0 && req.x < f64::from(w) && req.y < f64::from(h);
            match self.drawn.clone() {
                Some((camera, planes)) if inside => {
                    let started = self.picker.start(
                        &self.gpu.device,
                        &self.gpu.queue,
                        &self.depth,
                        w,
                        h,
                        req.x as u32,
                        req.y as u32,
                    );
                    debug_assert!(started);
                    self.pick_in_flight = Some((req, camera, planes));
                }
                _ => self.picked(req, None),
            }
        }
    }

    /// Takes the answer of the pick in flight (if it came) and starts the next.
    fn poll_picks(&mut self) {
        if let Some(answer) = self.picker.poll(&self.gpu.device) {
            if let Some((req, camera, planes)) = self.pick_in_flight.take() {
                let point = answer
                    .and_then(|d| tessera_nav::point_at_depth(&camera, req.x, req.y, d, planes));
                self.picked(req, point);
            }
        }
        self.start_pick();
    }

    fn picked(&mut self, req: PickRequest, point: Option<DVec3>) {
        match req.purpose {
            Purpose::Zoom(steps) => self.nav.zoom(steps, point),
            Purpose::Recentre => {
                if let Some(p) = point {
                    self.nav.recentre(p);
                }
            }
            Purpose::Pinch => {
                if let Some(Pinch::Waiting(s)) = self.pinch {
                    self.nav.pinch(s, point);
                    self.pinch = Some(Pinch::About(point));
                }
            }
            Purpose::Query(id) => self.answers.push(json!({
                "id": id,
                "point": point.map(|p| p.to_array()),
            })),
        }
        self.dirty = true;
    }
}
