//! The depth under one pixel of the last frame, read back on WebGL2 (which cannot copy
//! a depth texture to a buffer): a one-pixel pass samples the frame's depth texture at
//! the pixel and writes the f32's four bytes into an RGBA8 target (`k / 255` is stored
//! exactly by a unorm8 target, so the bits come back unchanged), which is copied into a
//! small buffer and mapped asynchronously. One read is in flight at a time; its answer
//! comes to a later frame ([`DepthPicker::poll`]). The point is then the depth
//! unprojected with the camera and planes of the frame that was read
//! (`tessera_nav::point_at_depth`).

use std::cell::Cell;
use std::rc::Rc;

const SHADER: &str = include_str!("pick.wgsl");

/// Bytes of the readback buffer (one row, aligned as copies need).
const ROW_BYTES: u64 = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64;

/// See the module docs.
pub struct DepthPicker {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    uniform: wgpu::Buffer,
    target: wgpu::Texture,
    target_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    /// The read in flight: None until its buffer is mapped, then whether it mapped.
    in_flight: Option<Rc<Cell<Option<bool>>>>,
}

impl DepthPicker {
    pub fn new(device: &wgpu::Device) -> DepthPicker {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tessera depth pick shader"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tessera depth pick layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        // A depth texture read as unfilterable float (WebGPU allows it
                        // for depth32float; GLSL gets a plain sampler2D).
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::NonFiltering),
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(16),
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tessera depth pick pipeline layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("tessera depth pick pipeline"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::Rgba8Unorm,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        // Nearest, no mipmaps: a depth texture is complete in GL ES only so.
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("tessera depth pick sampler"),
            ..Default::default()
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tessera depth pick pixel"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let target = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("tessera depth pick target"),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let target_view = target.create_view(&Default::default());
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tessera depth pick readback"),
            size: ROW_BYTES,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        DepthPicker {
            pipeline,
            layout,
            sampler,
            uniform,
            target,
            target_view,
            readback,
            in_flight: None,
        }
    }

    /// Whether a read is in flight.
    pub fn busy(&self) -> bool {
        self.in_flight.is_some()
    }

    /// Starts reading the depth of pixel (`x`, `y`) of `depth` (a `width` x `height`
    /// depth texture made with `TEXTURE_BINDING`). False when a read is in flight.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        depth: &wgpu::TextureView,
        width: u32,
        height: u32,
        x: u32,
        y: u32,
    ) -> bool {
        if self.busy() {
            return false;
        }
        let at = [
            (x.min(width - 1) as f32 + 0.5) / width as f32,
            (y.min(height - 1) as f32 + 0.5) / height as f32,
            0.0f32,
            0.0,
        ];
        let bytes: Vec<u8> = at.iter().flat_map(|v| v.to_le_bytes()).collect();
        queue.write_buffer(&self.uniform, 0, &bytes);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tessera depth pick bind group"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(depth),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.uniform.as_entire_binding(),
                },
            ],
        });
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("tessera depth pick"),
        });
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("tessera depth pick pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.target_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.target,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(ROW_BYTES as u32),
                    rows_per_image: Some(1),
                },
            },
            wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
        );
        queue.submit([enc.finish()]);
        let done = Rc::new(Cell::new(None));
        let flag = done.clone();
        self.readback
            .slice(0..8)
            .map_async(wgpu::MapMode::Read, move |r| flag.set(Some(r.is_ok())));
        self.in_flight = Some(done);
        true
    }

    /// The answer of the read in flight once it has come: `Some(Some(depth))` (reversed
    /// Z: 0 is the background), `Some(None)` when the read failed; None while waiting
    /// (or with nothing in flight).
    pub fn poll(&mut self, device: &wgpu::Device) -> Option<Option<f32>> {
        let done = self.in_flight.as_ref()?;
        if done.get().is_none() {
            let _ = device.poll(wgpu::PollType::Poll);
        }
        let ok = done.get()?;
        self.in_flight = None;
        if !ok {
            return Some(None);
        }
        let d = self
            .readback
            .slice(0..8)
            .get_mapped_range()
            .ok()
            .map(|data| f32::from_le_bytes([data[0], data[1], data[2], data[3]]));
        self.readback.unmap();
        Some(d)
    }
}
