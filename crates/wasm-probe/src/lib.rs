//! A WebAssembly probe of the format reader and the streaming core (built by
//! `scripts/check-wasm`, run by `scripts/wasm/probe.mjs` under Node): the module gets a
//! whole model file's bytes, parses its index, decodes patches through a byte-slice
//! source, and runs progressive frames of the scheduler over a store that only counts
//! bytes: the code a browser client runs, until the browser client (its own issue)
//! replaces this crate. Natively it builds as an ordinary library; its test runs the
//! same frames on a generated model.

use std::sync::Arc;

use tessera_format::{ModelIndex, PatchData};
use tessera_select::{Camera, Orbit};
use tessera_stream::{Answer, CountingStore, PatchSource, Scheduler, SchedulerOptions};

/// Answers every request at the next poll, decoding from the bytes in memory.
struct SliceSource<'a> {
    index: &'a ModelIndex,
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
        index: &index,
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
    }
}
