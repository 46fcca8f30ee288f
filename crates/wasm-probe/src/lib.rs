//! A WebAssembly probe of the format reader and the streaming core (built by
//! `scripts/check-wasm`, run by `scripts/wasm/probe.mjs` under Node): the module gets a
//! whole model file's bytes, parses its index, decodes patches through a byte-slice
//! source, and runs progressive frames of the scheduler over a store that only counts
//! bytes: the code a browser client runs, until the browser client (its own issue)
//! replaces this crate. Natively it builds as an ordinary library; its test runs the
//! same frames on a generated model.
//!
//! Timing (`probe_bench_*`, [`Bench`], for `scripts/bench-web`): a scheduler over a
//! model held in memory, warmed up over a fixed orbit of cameras until a whole pass over
//! it loads nothing (every patch the orbit's cuts and prefetch sets want resident in a
//! [`CountingStore`]), then one call per frame, which the host times: natively
//! `src/bin/bench-frames.rs` with `Instant`, in WebAssembly `bench.mjs` under Node with
//! `performance.now()` (the module imports nothing, so it has no clock of its own). Both
//! call the same [`Bench::frame`]: `Scheduler::frame` in progressive mode with nothing
//! left to load, i.e. selection + prefetch + the morph ratios of the drawn nodes + the
//! bookkeeping of a frame, the CPU work a viewer's frame does before it draws.

use std::sync::Arc;

use tessera_format::ModelIndex;
use tessera_select::{Camera, Orbit};
use tessera_stream::{
    Answer, CountingStore, FrameStats, MorphOptions, PatchSource, Scheduler, SchedulerOptions,
};

/// Answers every request at the next poll, decoding from the bytes in memory.
struct SliceSource<'a> {
    index: Arc<ModelIndex>,
    bytes: &'a [u8],
    wanted: Vec<u32>,
}

impl PatchSource for SliceSource<'_> {
    fn request(&mut self, wanted: &[(u32, f32)]) {
        self.wanted = wanted.iter().map(|&(n, _)| n).collect();
    }
    fn poll(&mut self, out: &mut Vec<Answer>) {
        for n in self.wanted.drain(..) {
            out.push(Answer::from_result(
                n,
                self.index.read_patch(self.bytes, n as usize),
            ));
        }
    }
    fn pending(&self) -> usize {
        self.wanted.len()
    }
}

/// Allocates `len` bytes for the host to fill with a model file.
#[no_mangle]
pub extern "C" fn probe_alloc(len: usize) -> *mut u8 {
    let mut v = vec![0u8; len];
    let p = v.as_mut_ptr();
    std::mem::forget(v);
    p
}

/// Runs `frames` progressive frames of an orbit over the model in `ptr..ptr+len`;
/// returns `nodes * 2^32 + triangles` drawn by the last one, or -1 if the model does
/// not parse.
///
/// # Safety
/// `ptr..ptr+len` must be a buffer from [`probe_alloc`] of that length.
#[no_mangle]
pub unsafe extern "C" fn probe_run(ptr: *const u8, len: usize, frames: u32) -> i64 {
    // SAFETY: the caller passes a live buffer of `len` bytes.
    let bytes: &[u8] = unsafe { std::slice::from_raw_parts(ptr, len) };
    run(bytes, frames).unwrap_or(-1)
}

fn run(bytes: &[u8], frames: u32) -> Option<i64> {
    let index = Arc::new(ModelIndex::read(bytes).ok()?);
    let mut sched = Scheduler::new(&index, SchedulerOptions::default());
    let mut src = SliceSource {
        index: index.clone(),
        bytes,
        wanted: Vec::new(),
    };
    let mut store = CountingStore::default();
    let b = index.header().bounding_sphere;
    let mut last = 0;
    for f in 0..frames.max(1) {
        let cam = Camera::orbit(&Orbit {
            center: [b[0], b[1], b[2]],
            radius: b[3] * 2.5,
            azimuth_deg: f as f64 * 3.0,
            elevation_deg: 15.0,
            ..Orbit::default()
        })
        .ok()?;
        let st = sched.frame(&cam, f as f64 / 60.0, &mut src, &mut store);
        last = ((st.selected_nodes as i64) << 32) | (st.triangles as i64 & 0xffff_ffff);
    }
    Some(last)
}

/// The fixed orbit of the timing: `frames` cameras around the bounding sphere, evenly
/// spaced in azimuth, 20 degrees up, at `distance` radii from its centre, fov 45 deg.
#[derive(Clone, Copy, Debug)]
pub struct BenchOptions {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
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

/// A scheduler over a model in memory, for timing frames (see the crate docs).
pub struct Bench {
    index: Arc<ModelIndex>,
    sched: Scheduler,
    src: SliceSource<'static>,
    store: CountingStore,
    cameras: Vec<Camera>,
    /// Frames run so far (the scheduler's clock: 1/60 s a frame).
    t: u64,
}

impl Bench {
    /// Parses the model; the scheduler as a viewer's (progressive, prefetch and
    /// geomorphing ratios on, 1 px), with a store budget (1 GiB) that holds the whole
    /// orbit and no arrival blend (with everything resident, each camera's frame draws
    /// its whole cut: a blend would hold refinement back for 0.25 s after every jump of
    /// the orbit, so the orbit would never settle).
    pub fn open(bytes: &'static [u8], opts: &BenchOptions) -> Result<Bench, String> {
        let index = Arc::new(ModelIndex::read(bytes).map_err(|e| e.to_string())?);
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
            src: SliceSource {
                index: index.clone(),
                bytes,
                wanted: Vec::new(),
            },
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

thread_local! {
    static BENCH: std::cell::RefCell<Option<Bench>> = const { std::cell::RefCell::new(None) };
}

/// Opens the timing scheduler ([`Bench::open`]) over the model in `ptr..ptr+len` (kept
/// for good: the host must not reuse the buffer), an orbit of `frames` cameras of
/// `width` x `height` at `distance_x100` / 100 radii; returns the model's nodes, or -1.
///
/// # Safety
/// `ptr..ptr+len` must be a buffer from [`probe_alloc`] of that length, never freed.
#[no_mangle]
pub unsafe extern "C" fn probe_bench_open(
    ptr: *const u8,
    len: usize,
    frames: u32,
    width: u32,
    height: u32,
    distance_x100: u32,
) -> i64 {
    // SAFETY: the caller passes a live buffer of `len` bytes that it never frees.
    let bytes: &'static [u8] = unsafe { std::slice::from_raw_parts(ptr, len) };
    let opts = BenchOptions {
        frames,
        width,
        height,
        distance: f64::from(distance_x100) / 100.0,
    };
    match Bench::open(bytes, &opts) {
        Ok(b) => {
            let n = b.nodes() as i64;
            BENCH.with(|c| *c.borrow_mut() = Some(b));
            n
        }
        Err(_) => -1,
    }
}

/// [`Bench::warm`]: the passes run, 0 if they did not settle, -1 before open.
#[no_mangle]
pub extern "C" fn probe_bench_warm() -> i64 {
    BENCH.with(|c| match c.borrow_mut().as_mut() {
        Some(b) => b.warm().map_or(0, i64::from),
        None => -1,
    })
}

/// [`Bench::frame`] at camera `k`: `nodes * 2^32 + triangles` drawn, -1 before open.
#[no_mangle]
pub extern "C" fn probe_bench_frame(k: u32) -> i64 {
    BENCH.with(|c| match c.borrow_mut().as_mut() {
        Some(b) => {
            let s = b.frame(k);
            ((s.selected_nodes as i64) << 32) | (s.triangles as i64 & 0xffff_ffff)
        }
        None => -1,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn refines_past_the_roots_on_a_real_model() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("s.ply");
        let tsr = dir.path().join("s.tsr");
        let opts = tessera_gen::SphereOptions {
            triangles: 20_000,
            ..Default::default()
        };
        tessera_gen::write_sphere(&ply, &opts, &tessera_gen::NoProgress).unwrap();
        let build = tessera_build::BuildOptions {
            leaf_triangles: 400,
            node_triangles: 200,
            ..Default::default()
        };
        tessera_build::build(&ply, &tsr, &build, &tessera_build::NoProgress).unwrap();
        let bytes = std::fs::read(&tsr).unwrap();
        let r = super::run(&bytes, 30).expect("parses");
        assert!(r >> 32 > 6, "drew {} nodes", r >> 32);
        assert_eq!(
            super::run(&bytes[..bytes.len() - 1], 30),
            None,
            "truncated model"
        );
        // The timing scheduler: warms up, then frames with nothing left to load.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        let opts = super::BenchOptions {
            frames: 8,
            ..Default::default()
        };
        let mut b = super::Bench::open(bytes, &opts).expect("parses");
        assert!(b.warm().is_some(), "the orbit did not settle");
        for k in 0..8 {
            let s = b.frame(k);
            assert!(s.selected_nodes > 6, "drew {} nodes", s.selected_nodes);
            assert_eq!((s.patches_uploaded, s.pending_loads), (0, 0));
        }
    }
}
