//! The browser module's self-checks, for Node (`scripts/check-wasm`, `scripts/bench-web`):
//! the streaming core over a whole model file handed over as bytes
//! (`tessera_stream::bench`: patches decoded from the bytes, a store that only counts),
//! so the format reader, the patch decoder's C parts (zstd, meshoptimizer) and the
//! scheduler run in this very `.wasm` on a real model with no device, no fetch and no
//! clock. Native builds run the same code (`tessera-stream`'s `bench` tests and its
//! `bench-frames` example).

use tessera_stream::bench::{self, Bench, BenchOptions};
use wasm_bindgen::prelude::*;

/// Runs `frames` progressive frames of a slow orbit over the model file `model` from a
/// cold start ([`bench::run`]); returns `[nodes, triangles]` drawn by the last one.
/// Throws if the model does not parse.
#[wasm_bindgen(js_name = probeRun)]
pub fn probe_run(model: &[u8], frames: u32) -> Result<Vec<f64>, JsError> {
    let s = bench::run(model, frames).map_err(|e| JsError::new(&e))?;
    Ok(vec![s.selected_nodes as f64, s.triangles as f64])
}

/// [`Bench`] over a model file: the host times [`ProbeBench::frame`] with its own clock
/// (`performance.now()`), as `bench-frames` times the same call natively.
#[wasm_bindgen]
pub struct ProbeBench {
    bench: Bench<Vec<u8>>,
    triangles: u64,
}

#[wasm_bindgen]
impl ProbeBench {
    /// Parses `model` (copied into the module); an orbit of `frames` cameras of `w` x `h`
    /// pixels at `radii` bounding radii. Throws if the model does not parse.
    #[wasm_bindgen(constructor)]
    pub fn new(model: Vec<u8>, frames: u32, w: u32, h: u32, radii: f64) -> Result<Self, JsError> {
        let opts = BenchOptions {
            frames,
            width: w,
            height: h,
            distance: radii,
        };
        let bench = Bench::open(model, &opts).map_err(|e| JsError::new(&e))?;
        Ok(ProbeBench {
            bench,
            triangles: 0,
        })
    }

    /// Nodes of the model.
    pub fn nodes(&self) -> u32 {
        self.bench.nodes() as u32
    }

    /// [`Bench::warm`]: the passes run, or `undefined` if they did not settle.
    pub fn warm(&mut self) -> Option<u32> {
        self.bench.warm()
    }

    /// [`Bench::frame`] at camera `k`: the nodes drawn (the triangles in
    /// [`ProbeBench::triangles`], read outside the timed call).
    pub fn frame(&mut self, k: u32) -> u32 {
        let s = self.bench.frame(k);
        self.triangles = s.triangles;
        s.selected_nodes as u32
    }

    /// Triangles drawn by the last [`ProbeBench::frame`].
    #[wasm_bindgen(getter)]
    pub fn triangles(&self) -> f64 {
        self.triangles as f64
    }
}
