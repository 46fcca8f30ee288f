//! The decode worker's entry point: `web/tessera_worker.js` loads this same wasm module
//! in a web worker and calls [`decode_job`] for each job the viewer hands out
//! (`Viewer::set_decoder`), so patch decoding (zstd, the attribute streams, PNG/JPEG
//! textures) and the textures' mip chains run off the main thread.

use wasm_bindgen::prelude::*;

/// Runs one decode job (`crate::wire::Job`'s bytes) and returns the reply's bytes: the
/// decoded patch with its texture's mip chain (`tessera_render::mip_chain`, the chain
/// the GPU cache would otherwise make at upload), or the decode error.
#[wasm_bindgen]
pub fn decode_job(job: &[u8]) -> Vec<u8> {
    crate::wire::run_job(job, tessera_render::mip_chain, crate::viewer::now_ms)
}
