//! Device setup: one wgpu instance, adapter, device and queue, made once.

use crate::RenderError;

/// A wgpu device and queue with what was learnt about the adapter.
pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// "name (backend, device type)", for logs and stats files.
    pub adapter_label: String,
}

impl Gpu {
    /// A device without a window. The backend comes from `WGPU_BACKEND` when set (e.g.
    /// `gl` for llvmpipe), else wgpu's default order, which on a machine without a GPU
    /// finds lavapipe (Mesa's CPU Vulkan). `WGPU_ADAPTER_NAME` picks an adapter by name.
    #[cfg(feature = "native")]
    pub fn headless() -> Result<Gpu, RenderError> {
        // Without WGPU_BACKEND, try the primary backends first and GL only if they find
        // nothing: probing EGL on a machine without it logs a scary (harmless) error.
        if std::env::var_os("WGPU_BACKEND").is_some() {
            let instance = wgpu::Instance::new(
                wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
            );
            return Self::with_instance(instance, None);
        }
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = wgpu::Backends::PRIMARY;
        match Self::with_instance(wgpu::Instance::new(desc), None) {
            Ok(gpu) => Ok(gpu),
            Err(primary) => {
                let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
                desc.backends = wgpu::Backends::GL;
                Self::with_instance(wgpu::Instance::new(desc), None).map_err(|_| primary)
            }
        }
    }

    /// A device for `instance`, compatible with `surface` when given (blocking).
    #[cfg(feature = "native")]
    pub fn with_instance(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Gpu, RenderError> {
        pollster::block_on(Self::with_instance_async(instance, surface))
    }

    /// [`Gpu::with_instance`] without blocking: what a browser runs (its adapter and
    /// device arrive through promises). Limits: wgpu's downlevel defaults, or WebGL2's
    /// where the adapter has no compute shaders (WebGL2: no storage buffers either; the
    /// renderer needs neither), with the adapter's buffer size and texture resolution.
    pub async fn with_instance_async(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Gpu, RenderError> {
        Self::with_instance_limited_async(instance, surface, None).await
    }

    /// [`Gpu::with_instance_async`] with the device's largest 2D texture lowered to
    /// `max_texture_dim` where given (to see a textured model as on a device with a
    /// smaller limit: the GPU cache uploads a larger patch texture from its first mip
    /// that fits).
    pub async fn with_instance_limited_async(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
        max_texture_dim: Option<u32>,
    ) -> Result<Gpu, RenderError> {
        let adapter = wgpu::util::initialize_adapter_from_env_or_default(&instance, surface)
            .await
            .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let adapter_label = format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type);
        // Ask for the adapter's buffer size limits: the GPU cache wants two big buffers.
        let alimits = adapter.limits();
        let compute = adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS);
        let base = if compute {
            wgpu::Limits::downlevel_defaults()
        } else {
            wgpu::Limits::downlevel_webgl2_defaults()
        };
        let limits = wgpu::Limits {
            max_buffer_size: alimits.max_buffer_size,
            ..base
        }
        .using_resolution(alimits.clone());
        let limits = wgpu::Limits {
            max_texture_dimension_2d: max_texture_dim
                .map_or(limits.max_texture_dimension_2d, |d| {
                    d.min(limits.max_texture_dimension_2d)
                }),
            ..limits
        };
        // Lines for the wireframe overlay, and BC texture sampling (BC7 patch textures
        // go to the GPU as blocks), where the adapter has them. `TESSERA_TEXTURE_BLOCKS=0`
        // leaves BC out, so BC7 textures are decoded to RGBA8 as on a device without it
        // (to compare the two; lavapipe, desktop GPUs and Chromium's WebGL2 on desktops
        // have it, phones mostly do not).
        let mut wanted = wgpu::Features::POLYGON_MODE_LINE;
        if std::env::var("TESSERA_TEXTURE_BLOCKS").map_or(true, |v| v != "0") {
            wanted |= wgpu::Features::TEXTURE_COMPRESSION_BC;
        }
        let features = adapter.features() & wanted;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("tessera device"),
                required_features: features,
                required_limits: limits,
                ..Default::default()
            })
            .await
            .map_err(|e| RenderError::Device(e.to_string()))?;
        tracing::info!(adapter = %adapter_label, "gpu ready");
        Ok(Gpu {
            instance,
            adapter,
            device,
            queue,
            adapter_label,
        })
    }

    /// Whether draws may start at a vertex offset (WebGL2 cannot): pass it to
    /// [`crate::Renderer::set_base_vertex`].
    pub fn base_vertex(&self) -> bool {
        self.adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::BASE_VERTEX)
    }

    /// Blocks until the GPU has finished all submitted work.
    #[cfg(feature = "native")]
    pub fn wait_idle(&self) -> Result<(), RenderError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| RenderError::Device(e.to_string()))
    }
}
