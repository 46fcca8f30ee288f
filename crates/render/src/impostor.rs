//! The GPU side of texture impostors (the policy is `tessera_stream::impostor`): one
//! texture per impostor slot (RGBA8, the size of the image rectangle it was sampled
//! over) with depth buffers to sample into, and the pipeline that draws the textured quads
//! (`impostor.wgsl`) into the frame's pass, depth-tested against the geometry.

use glam::DVec3;
use tessera_select::Camera;
use wgpu::util::DeviceExt;

use crate::renderer::{FrameParams, Shading, DEPTH_FORMAT};

/// The WGSL source of the impostor shader (validated by the naga test).
pub const IMPOSTOR_SHADER: &str = include_str!("impostor.wgsl");

/// The format impostor textures are sampled into and read from.
pub const IMPOSTOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

struct Target {
    size: [u32; 2],
    view: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
    _texture: wgpu::Texture,
}

/// One quad to draw: its texture slot, centre and half-extent vectors (world), and
/// the dither thresholds it keeps.
#[derive(Clone, Copy, Debug)]
pub struct Quad {
    pub slot: usize,
    pub center: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub keep: [f32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct QuadVertex {
    position: [f32; 3],
    uv: [f32; 2],
    keep: [f32; 2],
}

/// Impostor textures and the quad pipeline. See the module docs.
pub struct ImpostorRenderer {
    pipeline: wgpu::RenderPipeline,
    texture_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    uniform: wgpu::Buffer,
    uniform_group: wgpu::BindGroup,
    targets: Vec<Option<Target>>,
    depths: Vec<([u32; 2], wgpu::TextureView, wgpu::Texture)>,
}

impl ImpostorRenderer {
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> ImpostorRenderer {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tessera impostor shader"),
            source: wgpu::ShaderSource::Wgsl(IMPOSTOR_SHADER.into()),
        });
        let uniform_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tessera impostor uniforms layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(64),
                },
                count: None,
            }],
        });
        // A texture and its filtering sampler, as a patch texture's.
        let texture_layout = crate::texture::texture_bind_group_layout(device);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tessera impostor pipeline layout"),
            bind_group_layouts: &[Some(&uniform_layout), Some(&texture_layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2, 2 => Float32x2];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("tessera impostor pipeline"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_quad"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<QuadVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_quad"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: color_format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tessera impostor uniforms"),
            size: 64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let uniform_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tessera impostor uniforms"),
            layout: &uniform_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("tessera impostor sampler"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            ..Default::default()
        });
        ImpostorRenderer {
            pipeline,
            texture_layout,
            sampler,
            uniform,
            uniform_group,
            targets: Vec::new(),
            depths: Vec::new(),
        }
    }

    /// The colour and depth views to sample slot `slot` into, `size` texels (its
    /// texture made or remade to that size; a depth buffer is kept per size).
    pub fn target(
        &mut self,
        device: &wgpu::Device,
        slot: usize,
        size: [u32; 2],
    ) -> (&wgpu::TextureView, &wgpu::TextureView) {
        if self.targets.len() <= slot {
            self.targets.resize_with(slot + 1, || None);
        }
        if self.targets[slot].as_ref().is_none_or(|t| t.size != size) {
            let texture = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("tessera impostor"),
                size: wgpu::Extent3d {
                    width: size[0],
                    height: size[1],
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: IMPOSTOR_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            let bind_group = crate::texture::texture_bind_group(
                device,
                &self.texture_layout,
                &view,
                &self.sampler,
                "tessera impostor texture",
            );
            self.targets[slot] = Some(Target {
                size,
                view,
                bind_group,
                _texture: texture,
            });
        }
        if !self.depths.iter().any(|(s, _, _)| *s == size) {
            // Sides come in steps of 16 texels (`ImpostorSample::new`): a few sizes.
            let (texture, view) = crate::renderer::create_depth_texture(device, size[0], size[1]);
            self.depths.push((size, view, texture));
        }
        let color = &self.targets[slot].as_ref().expect("made above").view;
        let depth = &self
            .depths
            .iter()
            .find(|(s, _, _)| *s == size)
            .expect("made above")
            .1;
        (color, depth)
    }

    /// The views of slot `slot`'s texture and a depth buffer of its size, made by
    /// [`ImpostorRenderer::target`].
    pub fn views(&self, slot: usize, size: [u32; 2]) -> (&wgpu::TextureView, &wgpu::TextureView) {
        let color = &self.targets[slot].as_ref().expect("made by target").view;
        let depth = &self
            .depths
            .iter()
            .find(|(s, _, _)| *s == size)
            .expect("made by target")
            .1;
        (color, depth)
    }

    /// Frees slot `slot`'s texture.
    pub fn release(&mut self, slot: usize) {
        if let Some(t) = self.targets.get_mut(slot) {
            *t = None;
        }
    }

    /// Bytes of the impostor textures held.
    pub fn texture_bytes(&self) -> u64 {
        self.targets
            .iter()
            .flatten()
            .map(|t| u64::from(t.size[0]) * u64::from(t.size[1]) * 4)
            .sum()
    }

    /// Encodes one pass drawing `quads` over what `color`/`depth` hold (depth-tested
    /// against it), seen by `camera` with near and far planes `planes` (world units).
    #[allow(clippy::too_many_arguments)]
    pub fn encode_quads(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        camera: &Camera,
        planes: (f64, f64),
        quads: &[Quad],
    ) {
        let quads: Vec<&Quad> = quads
            .iter()
            .filter(|q| self.targets.get(q.slot).is_some_and(Option::is_some))
            .collect();
        if quads.is_empty() {
            return;
        }
        // Eye-relative world coordinates: the same matrices as a model whose local
        // frame starts at the eye.
        let eye = DVec3::from(camera.position);
        let p = FrameParams::with_planes(camera, camera.position, planes, Shading::default());
        queue.write_buffer(
            &self.uniform,
            0,
            bytemuck::bytes_of(&p.view_proj.to_cols_array()),
        );
        let mut vertices = Vec::with_capacity(quads.len() * 6);
        for q in &quads {
            let corner = |sx: f64, sy: f64, u: f32, v: f32| QuadVertex {
                position: (q.center + q.right * sx + q.up * sy - eye)
                    .as_vec3()
                    .to_array(),
                uv: [u, v],
                keep: q.keep,
            };
            let (tl, tr, bl, br) = (
                corner(-1.0, 1.0, 0.0, 0.0),
                corner(1.0, 1.0, 1.0, 0.0),
                corner(-1.0, -1.0, 0.0, 1.0),
                corner(1.0, -1.0, 1.0, 1.0),
            );
            vertices.extend_from_slice(&[tl, bl, br, tl, br, tr]);
        }
        let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("tessera impostor quads"),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("tessera impostor pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.uniform_group, &[]);
        pass.set_vertex_buffer(0, buffer.slice(..));
        for (k, q) in quads.iter().enumerate() {
            let t = self.targets[q.slot].as_ref().expect("filtered above");
            pass.set_bind_group(1, &t.bind_group, &[]);
            let k = k as u32 * 6;
            pass.draw(k..k + 6, 0..1);
        }
    }
}
