//! The streaming core over a whole model held in memory, for checks and timing that
//! must run the same code natively and in WebAssembly (`scripts/check-wasm`,
//! `scripts/bench-web`): a [`SliceSource`] that decodes patches from the file's bytes, a
//! [`CountingStore`] in place of a GPU, and no clock (the host times the calls: natively
//! `examples/bench-frames.rs` with `Instant`, in WebAssembly the browser module's
//! `probe_bench_*` functions, `crates/web/src/probe.rs`, under Node with
//! `performance.now()`).
//!
//! - [`run`]: progressive frames of a slow orbit from a cold start; what the last one
//!   drew. `scripts/check-wasm` asserts that the WebAssembly build refines past the roots.
//! - [`Bench`]: a scheduler warmed up over a fixed orbit until a whole pass over it loads
//!   nothing (every patch the orbit's cuts and prefetch sets want resident), then one
//!   [`Bench::frame`] per call: `Scheduler::frame` in progressive mode with nothing left
//!   to load, i.e. selection + prefetch + the morph ratios of the drawn nodes + the
//!   bookkeeping of a frame, the CPU work a viewer's frame does before it draws.

use std::sync::Arc;

use tessera_format::ModelIndex;
use tessera_select::{Camera, Orbit};

use crate::{
    Answer, CountingStore, FrameStats, MorphOptions, PatchSource, Scheduler, SchedulerOptions,
};

/// A [`PatchSource`] over a whole model file in memory (`B`: `&[u8]`, `Vec<u8>`, ...):
/// answers every request at the next poll, decoding from the bytes.
pub struct SliceSource<B> {
    index: Arc<ModelIndex>,
    bytes: B,
    wanted: Vec<u32>,
}

impl<B: AsRef<[u8]>> SliceSource<B> {
    /// A source over `bytes`, the file `index` was read from.
    pub fn new(index: Arc<ModelIndex>, bytes: B) -> Self {
        SliceSource {
            index,
            bytes,
            wanted: Vec::new(),
        }
    }
}

impl<B: AsRef<[u8]>> PatchSource for SliceSource<B> {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        self.wanted = wanted.iter().map(|&(n, _)| n).collect();
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        for n in self.wanted.drain(..) {
            out.push(Answer::from_result(
                n,
                self.index.read_patch(self.bytes.as_ref(), n as usize),
            ));
        }
    }
    fn pending(&self) -> usize {
        self.wanted.len()
    }
}

/// Runs `frames` (at least 1) progressive frames of a slow orbit (3 degrees a frame, 15
/// degrees up, at 2.5 bounding radii) over the model file in `bytes`, from a cold start
/// with the default options; returns the last frame's statistics, or the error if the
/// model does not parse.
pub fn run(bytes: &[u8], frames: u32) -> Result<FrameStats, String> {
    let index = Arc::new(ModelIndex::read(bytes).map_err(|e| e.to_string())?);
    let mut sched = Scheduler::new(&index, SchedulerOptions::default());
    let mut src = SliceSource::new(index.clone(), bytes);
    let mut store = CountingStore::default();
    let b = index.header().bounding_sphere;
    let mut last = FrameStats::default();
    for f in 0..frames.max(1) {
        let cam = Camera::orbit(&Orbit {
            center: [b[0], b[1], b[2]],
            radius: b[3] * 2.5,
            azimuth_deg: f as f64 * 3.0,
            elevation_deg: 15.0,
            ..Orbit::default()
        })
        .map_err(|e| e.to_string())?;
        last = sched.frame(&cam, f as f64 / 60.0, &mut src, &mut store);
    }
    Ok(last)
}

/// The fixed orbit of the timing: `frames` cameras around the bounding sphere, evenly
/// spaced in azimuth, 20 degrees up, at `distance` radii from its centre, fov 45 deg.
#[derive(Clone, Copy, Debug)]
pub struct BenchOptions {
    /// Cameras of the orbit (default 24).
    pub frames: u32,
    /// Viewport width in pixels (default 1280).
    pub width: u32,
    /// Viewport height in pixels (default 720).
    pub height: u32,
    /// Distance of the cameras from the centre, in bounding radii (default 2).
    pub distance: f64,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            frames: 24,
            width: 1280,
            height: 720,
            distance: 2.0,
        }
    }
}

/// Warm-up passes over the orbit at most.
pub const MAX_WARM_PASSES: u32 = 10;
/// Frames a camera is held at most during a warm-up pass.
pub const MAX_HOLD_FRAMES: u32 = 600;

/// A scheduler over a model in memory, for timing frames (see the module docs).
pub struct Bench<B> {
    index: Arc<ModelIndex>,
    sched: Scheduler,
    src: SliceSource<B>,
    store: CountingStore,
    cameras: Vec<Camera>,
    /// Frames run so far (the scheduler's clock: 1/60 s a frame).
    t: u64,
}

impl<B: AsRef<[u8]>> Bench<B> {
    /// Parses the model; the scheduler as a viewer's (progressive, prefetch and
    /// geomorphing ratios on, 1 px), with a store budget (1 GiB) that holds the whole
    /// orbit and no arrival blend (with everything resident, each camera's frame draws
    /// its whole cut: a blend would hold refinement back for 0.25 s after every jump of
    /// the orbit, so the orbit would never settle).
    pub fn open(bytes: B, opts: &BenchOptions) -> Result<Self, String> {
        let index = Arc::new(ModelIndex::read(bytes.as_ref()).map_err(|e| e.to_string())?);
        let sched = Scheduler::new(
            &index,
            SchedulerOptions {
                store_budget_bytes: 1 << 30,
                morph: MorphOptions {
                    arrival_blend_s: 0.0,
                    ..MorphOptions::default()
                },
                ..SchedulerOptions::default()
            },
        );
        let b = index.header().bounding_sphere;
        let n = opts.frames.max(1);
        let cameras = (0..n)
            .map(|k| {
                Camera::orbit(&Orbit {
                    center: [b[0], b[1], b[2]],
                    radius: b[3] * opts.distance,
                    azimuth_deg: 360.0 * f64::from(k) / f64::from(n),
                    elevation_deg: 20.0,
                    fov_y_deg: 45.0,
                    width: opts.width,
                    height: opts.height,
                    ..Orbit::default()
                })
                .map_err(|e| e.to_string())
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Bench {
            src: SliceSource::new(index.clone(), bytes),
            index,
            sched,
            store: CountingStore::default(),
            cameras,
            t: 0,
        })
    }

    /// Nodes of the model.
    pub fn nodes(&self) -> usize {
        self.index.nodes().len()
    }

    /// Cameras of the orbit.
    pub fn frames(&self) -> u32 {
        self.cameras.len() as u32
    }

    /// Warms up: each camera held until its frame has converged (nothing uploaded,
    /// pending, missing or blending; at most [`MAX_HOLD_FRAMES`] frames), then passes
    /// over the orbit until one converges at every camera; returns the passes, or `None`
    /// if [`MAX_WARM_PASSES`] did not settle.
    pub fn warm(&mut self) -> Option<u32> {
        let settled = |s: &FrameStats| {
            s.patches_uploaded == 0
                && s.pending_loads == 0
                && s.cache_misses == 0
                && s.morph_blending == 0
        };
        for pass in 1..=MAX_WARM_PASSES {
            let mut clean = true;
            for k in 0..self.frames() {
                let mut held = 0;
                loop {
                    let s = self.frame(k);
                    if settled(&s) {
                        break;
                    }
                    clean = false;
                    held += 1;
                    if held >= MAX_HOLD_FRAMES {
                        break;
                    }
                }
            }
            if clean {
                return Some(pass);
            }
        }
        None
    }

    /// One scheduler frame at orbit camera `k` (modulo the orbit's length).
    pub fn frame(&mut self, k: u32) -> FrameStats {
        let cam = &self.cameras[(k % self.frames()) as usize];
        self.t += 1;
        self.sched
            .frame(cam, self.t as f64 / 60.0, &mut self.src, &mut self.store)
    }
}
