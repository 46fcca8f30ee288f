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
//! - `pick` (wasm32): the depth under a pixel of the last frame read back on WebGL2
//!   (a one-pixel pass packing the depth's bits into RGBA8), for zoom to the cursor,
//!   double-click recentre and pinch about the fingers.
//!
//! Decoding runs on the main thread between frames in this first step (at most
//! 6 ms of it per frame; the cost per patch is in the frame statistics); fetching is
//! asynchronous and never blocks a frame. A web worker for decoding is next.
//!
//! Textured models (format version 3, a texture per patch) decode their PNG/JPEG
//! textures in the same place (`tessera_format::decode_patch`, the `image` crate in
//! wasm) and the GPU cache makes each texture's mips on upload, on the main thread too:
//! both are timed in the frame statistics (`decode_ms_*`, `textured_upload_ms_mean`,
//! `upload_ms_max`). Measured on the YCB scissors in headless Chromium: about 25 ms a
//! patch to decode and as much to upload on average, 0.2-0.26 s and 0.36-0.49 s for its
//! largest texture (2435x3993), so one patch can hold a frame up for most of a second.

pub mod plan;

#[cfg(target_arch = "wasm32")]
mod http;
#[cfg(target_arch = "wasm32")]
mod pick;
#[cfg(target_arch = "wasm32")]
mod viewer;

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
