//! Tessera in the browser: the viewer that `web/tessera.js` drives, built for
//! `wasm32-unknown-unknown` by `scripts/build-web` (wasm-bindgen). It runs the same
//! Rust code as the desktop: the format reader and patch decoder (`tessera-format`
//! without its file features), the streaming core's `Scheduler`, the `Navigator` and
//! the wgpu `Renderer` / `GpuCache` of `tessera-render` (without its native feature)
//! with the native WGSL shader, on WebGL2.
//!
//! - [`plan`]: what to fetch (the index through a sparse byte source, patches in
//!   coalesced range requests, at most 3 in flight) and the decoding of fetched
//!   patches within a time budget per frame. Plain Rust, tested natively.
//! - `http` (wasm32): range requests with `fetch`, the ETag pinned with `If-Range`,
//!   errors worded for the page (404, no range support, CORS, model changed).
//! - `viewer` (wasm32): `Viewer`, the wasm-bindgen class: open (device, first 64 KiB,
//!   top of the index, roots), `frame` (navigation, scheduler, draw), input, camera.
//! - `stream` (wasm32): `Stream`, the wasm-bindgen class under the three.js adapter
//!   (`web/tessera-three.js`): the same open, fetching, decode workers and scheduler
//!   as the viewer, no device; resident patches kept as arrays for three.js meshes,
//!   what was added and evicted, and the draw list, each frame.
//! - `pick` (wasm32): the depth under a pixel of the last frame read back on WebGL2
//!   (a one-pixel pass packing the depth's bits into RGBA8), for zoom to the cursor,
//!   double-click recentre and pinch about the fingers.
//!
//! - `probe` (wasm32): `probeRun` and `ProbeBench`, the streaming core over a model
//!   file's bytes with no device or fetch, which `scripts/check-wasm` and
//!   `scripts/bench-web` run under Node.
//!
//! - [`budget`]: one memory budget for every model on the page (views and three.js
//!   models), split each frame by their demand as the desktop splits its scene's.
//!   Plain Rust, tested natively.
//! - [`wire`]: the messages to and from the decode workers (a job: a fetched patch and
//!   what decoding it needs from its node record; a reply: the decoded patch, its
//!   texture's mips included, flattened into one transferable buffer). Plain Rust,
//!   tested natively.
//! - `worker` (wasm32): `decode_job`, what each worker (`web/tessera_worker.js`, the
//!   same wasm module) runs.
//!
//! Fetching is asynchronous and never blocks a frame. Decoding (zstd, the attribute
//! streams, PNG/JPEG textures) and the textures' mip chains run in the page's decode
//! workers (`Viewer::set_decoder`; `web/tessera.js` starts them); the main thread only
//! copies the reply into the GPU cache. Without workers (`workers: 0`, or a browser
//! where they fail), patches are decoded on the main thread between frames, at most
//! 6 ms of it a frame, and the cache makes the mips at upload. Both paths are timed in
//! the frame statistics (`worker_decode_ms_mean`, `decode_ms_*`,
//! `textured_upload_ms_mean`, `upload_ms_max`).

// The frame statistics' `json!` object is larger than the macro's default depth.
#![recursion_limit = "256"]

pub mod budget;
pub mod plan;
pub mod scene;
pub mod wire;

#[cfg(target_arch = "wasm32")]
mod http;
#[cfg(target_arch = "wasm32")]
mod pick;
#[cfg(target_arch = "wasm32")]
mod probe;
#[cfg(target_arch = "wasm32")]
mod stream;
#[cfg(target_arch = "wasm32")]
mod viewer;
#[cfg(target_arch = "wasm32")]
mod worker;

#[cfg(target_arch = "wasm32")]
pub use stream::Stream;
#[cfg(target_arch = "wasm32")]
pub use viewer::Viewer;

/// Panics go to the browser console (with the message) instead of "unreachable".
#[cfg(target_arch = "wasm32")]
#[wasm_bindgen::prelude::wasm_bindgen(start)]
pub fn start() {
    std::panic::set_hook(Box::new(|info| {
        web_sys::console::error_1(&format!("tessera: {info}").into());
    }));
}
