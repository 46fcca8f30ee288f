//! Tessera's renderer: a wgpu GPU patch cache with a range allocator (the streaming
//! core's resident store, [`GpuStore`]), a simple lit patch pipeline, offscreen targets
//! with readback, and a [`Viewer`] that runs one frame per call.
//!
//! Data flow per progressive frame: `tessera_stream::Scheduler::frame` selects over what
//! the GPU holds, asks the `tessera_page::Pager` for missing groups (visible first, then
//! the prefetch set) and uploads finished groups into the [`GpuCache`] → one render pass.
//!
//! A scene of several models (`Viewer::with_models`) keeps one scheduler and pager per
//! model over one shared cache, one GPU budget and one RAM budget, split every frame
//! by each view's demand (`tessera_stream::BudgetSplit`), and draws every model in its
//! own local frame into one pass and one depth buffer.
//!
//! Textured models (`ATTR_TEXTURE`, a texture per patch): the cache uploads each
//! patch's texture with its mips beside its vertices (texture coordinates in the
//! vertex's colour slots) and counts it in the patch's bytes; the renderer draws those
//! patches through a second pipeline that samples it, lit and coloured as the rest.
//!
//! Feature `native` (default): the [`Viewer`] (over `tessera-page`'s loader threads)
//! and the blocking device setup. Without it the crate builds for wasm32: the
//! browser client (`tessera-web`) draws with the same [`Renderer`], shader and
//! [`GpuCache`] / [`GpuStore`], on a device from [`Gpu::with_instance_async`].

mod cache;
mod gpu;
mod impostor;
mod renderer;
mod texture;
#[cfg(feature = "native")]
mod viewer;

pub use cache::{
    gpu_vertices, gpu_vertices_as, uv_unorm16, GpuCache, GpuCacheStats, GpuStore, GpuVertex, Slot,
};
pub use gpu::Gpu;
pub use impostor::{ImpostorRenderer, Quad, IMPOSTOR_FORMAT, IMPOSTOR_SHADER};
pub use renderer::{
    ColorMode, DrawInstance, FrameParams, Light, Renderer, Shading, DEPTH_FORMAT, PATCH_SHADER,
};
/// The CPU side of drawing a patch (morph targets, texel sizes), in `tessera-format` so
/// renderers without this crate share it.
pub use tessera_format::{
    morph_targets, patch_is_textured, patch_texel_size, texel_lod, MorphTarget,
};
pub use tessera_image::{diff_stats, enclosed_background_pixels, psnr, Image, ImageError};
pub use tessera_select::clip_planes_along;
pub use tessera_stream::{
    memory_split, FrameStats, ImpostorOptions, ImpostorStats, Mode, MorphOptions,
};
pub use texture::{
    bc7_uploads_as_blocks, downsample, mip_chain, mip_level_count, texture_bind_group_layout,
    texture_gpu_bytes, texture_gpu_bytes_as, SlotTexture, BC7_TEXTURE_FORMAT, PATCH_TEXTURE_FORMAT,
};
#[cfg(feature = "native")]
pub use viewer::{Viewer, ViewerOptions};

/// Errors of the renderer.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("no usable GPU adapter (install Mesa's lavapipe: mesa-vulkan-drivers): {0}")]
    NoAdapter(String),
    #[error("GPU device error: {0}")]
    Device(String),
    #[error("nothing has been rendered yet")]
    NoFrame,
    #[error("the GPU cache is too small for a single patch; raise --gpu-budget")]
    CacheTooSmall,
    #[error("{0}")]
    Io(String),
}

impl From<ImageError> for RenderError {
    fn from(e: ImageError) -> RenderError {
        RenderError::Io(e.0)
    }
}
