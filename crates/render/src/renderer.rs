//! The draw side: pipeline and uniforms (set up once), offscreen targets (remade only
//! when the size changes), and a per-frame pass that draws a list of cached patches.
//! [`Renderer::encode_pass`] takes any colour view of [`Renderer::color_format`], so a
//! window surface's texture is drawn the same way as the offscreen target.
//!
//! Several models in one frame: each has its own local frame, so its own uniforms
//! (view-projection relative to its cube origin, whether it has colours). They live in
//! one uniform buffer, one entry per model at a 256-byte aligned stride, selected per
//! draw with a dynamic offset (core WebGPU and WebGL2, no extra feature), and every
//! model is drawn in the same pass against one depth buffer.

use glam::{DVec3, Mat4};
use tessera_select::{clip_planes_along, Camera};
use wgpu::util::DeviceExt;

use crate::cache::{GpuCache, GpuVertex, Slot, VERTEX_BYTES};
use crate::RenderError;
use tessera_image::Image;

/// The WGSL source of the patch shader (validated by a test with naga, no GPU needed).
pub const PATCH_SHADER: &str = include_str!("patch.wgsl");

/// Depth format of every target.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    light_dir: [f32; 4],
    sky_up_has_color: [f32; 4],
    clay: [f32; 4],
    /// x: colour mode (0 natural, 1 by node, 2 by level); y: 1 = unlit; z: wireframe
    /// pass (lines drawn dark); w unused.
    mode: [f32; 4],
}

/// Per-draw instance data: the drawn node's morph ratio, tag, and texel detail.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DrawInstance {
    /// 0: the node's own shape, 1: its parent's.
    pub ratio: f32,
    /// [`crate::cache::vertex_tag`] of the node.
    pub tag: u32,
    /// [`crate::cache::Slot::texel_lod`]: the textured pipeline samples no finer than
    /// mip level `ratio * texel_lod`.
    pub texel_lod: f32,
}

/// Where the light comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// A head light from just above and left of the eye (moves with the camera).
    Headlight,
    /// A directional light fixed in the model: unit direction TOWARD the light, model
    /// coordinates (raking light: drag it low over a surface to read its relief).
    Directional([f64; 3]),
}

/// How patches are coloured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ColorMode {
    /// The model's colours (per-vertex colour, else clay).
    #[default]
    Natural,
    /// A colour per node (patch boundaries show).
    ByNode,
    /// A colour per level of the hierarchy (coarse blue to fine red).
    ByLevel,
}

/// Display options of a frame (the HUD's switches).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    pub light: Light,
    /// Colour without lighting (scans with baked colour).
    pub unlit: bool,
    pub color_mode: ColorMode,
    /// Triangle edges drawn over the surface (when the device can draw lines).
    pub wireframe: bool,
}

impl Default for Shading {
    fn default() -> Self {
        Shading {
            light: Light::Headlight,
            unlit: false,
            color_mode: ColorMode::Natural,
            wireframe: false,
        }
    }
}

/// Per-frame constants derived from the camera.
#[derive(Clone, Copy, Debug)]
pub struct FrameParams {
    pub view_proj: Mat4,
    /// Unit direction toward the light, local frame.
    pub light_dir: [f32; 3],
    /// Camera up, local frame.
    pub sky_up: [f32; 3],
    /// Near and far planes used (model units).
    pub near: f64,
    pub far: f64,
    pub shading: Shading,
    /// The dither thresholds this model keeps (`[0, 1)`: every pixel; a model
    /// dissolving into its impostor keeps a part, see `tessera_stream::impostor`).
    pub keep: [f32; 2],
}

impl FrameParams {
    /// Matrices for `camera` in the local frame of a model with `cube_origin`, with near
    /// and far planes fitted around `bounds` (the model's bounding sphere, model
    /// coordinates).
    pub fn new(camera: &Camera, cube_origin: [f64; 3], bounds: [f64; 4]) -> FrameParams {
        let c = DVec3::new(bounds[0], bounds[1], bounds[2]);
        let planes = clip_planes_along(
            DVec3::from(camera.position),
            camera.basis().forward,
            [(c, bounds[3].max(1e-9))],
        );
        Self::with_planes(camera, cube_origin, planes, Shading::default())
    }

    /// Matrices for `camera` with the given near and far planes (see [`clip_planes_along`]):
    /// a reversed-Z projection (near maps to depth 1, far to 0).
    pub fn with_planes(
        camera: &Camera,
        cube_origin: [f64; 3],
        (near, far): (f64, f64),
        shading: Shading,
    ) -> FrameParams {
        let view = camera.view_matrix_local(cube_origin);
        // Reversed Z: the same perspective with near and far swapped.
        let proj = camera.projection_matrix(far as f32, near as f32);
        let b = camera.basis();
        let to_light = match shading.light {
            // Head light from above-left of the eye, so silhouettes still shade.
            Light::Headlight => (-b.forward + b.up * 0.45 - b.right * 0.3).normalize(),
            Light::Directional(d) => {
                let d = DVec3::from(d);
                if d.length_squared() > 0.0 && d.is_finite() {
                    d.normalize()
                } else {
                    -b.forward
                }
            }
        };
        FrameParams {
            view_proj: proj * view,
            light_dir: to_light.as_vec3().to_array(),
            sky_up: b.up.as_vec3().to_array(),
            near,
            far,
            shading,
            keep: [0.0, 1.0],
        }
    }

    /// These parameters keeping only the pixels whose dither threshold is in `keep`.
    pub fn with_keep(mut self, keep: [f32; 2]) -> FrameParams {
        self.keep = keep;
        self
    }
}

/// The patch vertex ([`GpuVertex`]) as the untextured pipeline reads it.
const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 6] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x3,
    2 => Snorm16x2,
    3 => Snorm16x2,
    4 => Unorm8x4,
    5 => Unorm8x4
];
/// The same vertex as the textured pipeline reads it: the colour slots hold texture
/// coordinates ([`crate::cache::uv_unorm16`]).
const TEXTURED_VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 6] = wgpu::vertex_attr_array![
    0 => Float32x3,
    1 => Float32x3,
    2 => Snorm16x2,
    3 => Snorm16x2,
    4 => Unorm16x2,
    5 => Unorm16x2
];
/// Per draw (one instance): the node's morph ratio, tag and texel detail.
const INSTANCE_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![6 => Float32, 7 => Uint32, 8 => Float32];

/// One patch pipeline of the shader: entry points, vertex attributes, polygon mode and
/// depth bias (the fill, wireframe and textured pipelines differ only there).
struct PipelineSpec<'a> {
    layout: &'a wgpu::PipelineLayout,
    attributes: &'a [wgpu::VertexAttribute],
    vs: &'a str,
    fs: &'a str,
    polygon_mode: wgpu::PolygonMode,
    bias: wgpu::DepthBiasState,
}

fn patch_pipeline(
    device: &wgpu::Device,
    shader: &wgpu::ShaderModule,
    color_format: wgpu::TextureFormat,
    spec: &PipelineSpec<'_>,
) -> wgpu::RenderPipeline {
    let vertex_layout = wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<GpuVertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: spec.attributes,
    };
    let instance_layout = wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<DrawInstance>() as u64,
        step_mode: wgpu::VertexStepMode::Instance,
        attributes: &INSTANCE_ATTRIBUTES,
    };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("tessera patch pipeline"),
        layout: Some(spec.layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some(spec.vs),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout), Some(instance_layout)],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: Some(wgpu::Face::Back),
            polygon_mode: spec.polygon_mode,
            ..Default::default()
        },
        // Reversed Z: nearer is larger (see `clip_planes_along`).
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(spec.polygon_mode == wgpu::PolygonMode::Fill),
            depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
            stencil: Default::default(),
            bias: spec.bias,
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some(spec.fs),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: color_format,
                blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Pipeline, uniforms and offscreen targets.
pub struct Renderer {
    pipeline: wgpu::RenderPipeline,
    /// The pipeline of textured models' patches (their slots have a texture), made at
    /// the first frame that draws one: models without textures never pay for it.
    textured_pipeline: std::cell::OnceCell<wgpu::RenderPipeline>,
    /// The plain and textured pipelines of models dissolving into or out of their
    /// impostors (`fs_*_dissolve`: they discard), made when first needed.
    dissolve_pipeline: std::cell::OnceCell<wgpu::RenderPipeline>,
    textured_dissolve_pipeline: std::cell::OnceCell<wgpu::RenderPipeline>,
    /// Per uniform entry: whether its model keeps only part of its pixels.
    dissolving: std::cell::RefCell<Vec<bool>>,
    plain_layout: wgpu::PipelineLayout,
    shader: wgpu::ShaderModule,
    /// Line pipeline of the wireframe overlay (None: the device cannot draw lines).
    wire_pipeline: Option<wgpu::RenderPipeline>,
    /// Whether the frame set last draws the wireframe overlay.
    wireframe: std::cell::Cell<bool>,
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    bind_group_layout: wgpu::BindGroupLayout,
    /// Entries the uniform buffer holds (one per model).
    entries: u32,
    /// Bytes between entries (the device's uniform offset alignment, at least the size).
    stride: u64,
    color_format: wgpu::TextureFormat,
    targets: Option<Targets>,
    /// Clear colour (linear RGBA).
    pub background: [f64; 4],
    /// Whether vertex colours are used (else a clay colour).
    pub has_colors: bool,
    /// Whether a textured patch morphing in from its parent also shows its parent's
    /// texel detail ([`crate::cache::Slot::texel_lod`]; true).
    pub texel_blend: bool,
    /// Whether draws may start at a vertex offset (see [`Renderer::set_base_vertex`]).
    base_vertex: bool,
}

struct Targets {
    width: u32,
    height: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    depth_readback: wgpu::Buffer,
    padded_row: u32,
}

impl Renderer {
    /// Builds the pipeline for colour targets of `color_format`.
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> Renderer {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tessera patch shader"),
            source: wgpu::ShaderSource::Wgsl(PATCH_SHADER.into()),
        });
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tessera frame uniforms layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(
                        std::mem::size_of::<FrameUniform>() as u64
                    ),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tessera patch pipeline layout"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let make = |polygon_mode: wgpu::PolygonMode, fs: &str, bias: wgpu::DepthBiasState| {
            let spec = PipelineSpec {
                layout: &layout,
                attributes: &VERTEX_ATTRIBUTES,
                vs: "vs_main",
                fs,
                polygon_mode,
                bias,
            };
            patch_pipeline(device, &shader, color_format, &spec)
        };
        let pipeline = make(wgpu::PolygonMode::Fill, "fs_main", Default::default());
        // Edges over the surface: lines need the device feature (lavapipe and desktop
        // GPUs have it; WebGL does not), pulled toward the eye by a slope-scaled bias
        // so they win the depth test against their own triangles.
        let wire_pipeline = device
            .features()
            .contains(wgpu::Features::POLYGON_MODE_LINE)
            .then(|| {
                make(
                    wgpu::PolygonMode::Line,
                    "fs_wire",
                    wgpu::DepthBiasState {
                        constant: 4,
                        slope_scale: 1.5,
                        clamp: 0.0,
                    },
                )
            });
        let align = u64::from(device.limits().min_uniform_buffer_offset_alignment).max(1);
        let stride = (std::mem::size_of::<FrameUniform>() as u64).next_multiple_of(align);
        let (uniform, bind_group) = Self::make_uniforms(device, &bgl, stride, 1);
        Renderer {
            pipeline,
            textured_pipeline: std::cell::OnceCell::new(),
            dissolve_pipeline: std::cell::OnceCell::new(),
            textured_dissolve_pipeline: std::cell::OnceCell::new(),
            dissolving: std::cell::RefCell::new(Vec::new()),
            plain_layout: layout,
            shader,
            wire_pipeline,
            wireframe: std::cell::Cell::new(false),
            uniform,
            bind_group,
            bind_group_layout: bgl,
            entries: 1,
            stride,
            color_format,
            targets: None,
            background: [0.06, 0.07, 0.09, 1.0],
            has_colors: false,
            texel_blend: true,
            base_vertex: true,
        }
    }

    /// Whether the device draws from a vertex offset (`base_vertex`; wgpu's
    /// `DownlevelFlags::BASE_VERTEX`, see [`crate::Gpu::base_vertex`]). Without it (WebGL2,
    /// GL ES 3.0) each patch's draw binds the vertex buffer at the patch's first vertex
    /// instead: the same pixels, one vertex-buffer binding per draw. Default: true.
    pub fn set_base_vertex(&mut self, supported: bool) {
        self.base_vertex = supported;
    }

    fn make_uniforms(
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        stride: u64,
        entries: u32,
    ) -> (wgpu::Buffer, wgpu::BindGroup) {
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tessera frame uniforms"),
            size: stride * u64::from(entries.max(1)),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tessera frame uniforms bind group"),
            layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &uniform,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<FrameUniform>() as u64),
                }),
            }],
        });
        (uniform, bind_group)
    }

    /// Makes room for `models` uniform entries (one per model drawn in a frame).
    pub fn ensure_models(&mut self, device: &wgpu::Device, models: u32) {
        if models > self.entries {
            let (u, b) = Self::make_uniforms(device, &self.bind_group_layout, self.stride, models);
            self.uniform = u;
            self.bind_group = b;
            self.entries = models;
        }
    }

    /// Colour format of the targets this renderer draws into.
    pub fn color_format(&self) -> wgpu::TextureFormat {
        self.color_format
    }

    /// Makes sure the offscreen targets are `width` x `height`.
    pub fn ensure_offscreen(&mut self, device: &wgpu::Device, width: u32, height: u32) {
        if let Some(t) = &self.targets {
            if t.width == width && t.height == height {
                return;
            }
        }
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let color = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("tessera offscreen colour"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.color_format,
            // Sampled by a window's blit to its surface; copied by readback.
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let color_view = color.create_view(&wgpu::TextureViewDescriptor {
            label: Some("tessera offscreen colour view"),
            ..Default::default()
        });
        let (depth, depth_view) = create_depth_texture(device, width, height);
        let padded_row = (width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tessera offscreen readback"),
            size: u64::from(padded_row) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        self.targets = Some(Targets {
            width,
            height,
            color,
            color_view,
            depth,
            depth_view,
            readback,
            // Depth can only be copied whole (WebGPU forbids partial copies of depth
            // formats): one f32 per pixel, rows padded like the colour readback.
            depth_readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("tessera depth readback"),
                size: u64::from(padded_row) * u64::from(height),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            padded_row,
        });
    }

    /// Whether the wireframe overlay can be drawn on this device.
    pub fn can_draw_wireframe(&self) -> bool {
        self.wire_pipeline.is_some()
    }

    /// Writes the frame uniforms (call before encoding the frame's passes).
    pub fn set_frame(&self, queue: &wgpu::Queue, p: &FrameParams) {
        self.set_model_frame(queue, 0, p, self.has_colors);
    }

    /// Writes the uniforms of entry `model` (see [`Renderer::ensure_models`]): `p` in
    /// that model's local frame, `has_colors` its vertex colours. The shading and the
    /// wireframe switch are the frame's (the last call's).
    pub fn set_model_frame(
        &self,
        queue: &wgpu::Queue,
        model: u32,
        p: &FrameParams,
        has_colors: bool,
    ) {
        assert!(model < self.entries, "uniform entry {model} not made");
        self.wireframe.set(p.shading.wireframe);
        let color_mode = match p.shading.color_mode {
            ColorMode::Natural => 0.0,
            ColorMode::ByNode => 1.0,
            ColorMode::ByLevel => 2.0,
        };
        let u = FrameUniform {
            view_proj: p.view_proj.to_cols_array_2d(),
            light_dir: [p.light_dir[0], p.light_dir[1], p.light_dir[2], 0.0],
            sky_up_has_color: [
                p.sky_up[0],
                p.sky_up[1],
                p.sky_up[2],
                if has_colors { 1.0 } else { 0.0 },
            ],
            clay: [0.78, 0.74, 0.68, 1.0],
            mode: [
                color_mode,
                if p.shading.unlit { 1.0 } else { 0.0 },
                p.keep[0],
                p.keep[1],
            ],
        };
        {
            let mut d = self.dissolving.borrow_mut();
            if d.len() <= model as usize {
                d.resize(model as usize + 1, false);
            }
            d[model as usize] = p.keep != [0.0, 1.0];
        }
        queue.write_buffer(
            &self.uniform,
            u64::from(model) * self.stride,
            bytemuck::bytes_of(&u),
        );
    }

    /// Encodes one pass drawing `slots` (each with its morph ratio) from `cache` into
    /// `color`/`depth`; clears both first when `clear`, else keeps them (a frame drawn
    /// in several passes).
    #[allow(clippy::too_many_arguments)]
    pub fn encode_pass<'a>(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        cache: &GpuCache,
        slots: impl Iterator<Item = (&'a Slot, f32)>,
        clear: bool,
    ) {
        let slots = slots.map(|(s, r)| (0, s, r));
        self.encode_models_pass(device, encoder, color, depth, cache, slots, clear);
    }

    /// [`Renderer::encode_pass`] for several models: each slot comes with its model's
    /// uniform entry (written by [`Renderer::set_model_frame`]); slots of one model
    /// should come together (the entry is rebound when it changes).
    ///
    /// The ratios, tags and texel details go to the GPU as one small instance buffer per
    /// pass (12 bytes a draw), the draw's instance picking its entry: no per-vertex work, and the
    /// patches' vertex data never changes after upload.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_models_pass<'a>(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        cache: &GpuCache,
        slots: impl Iterator<Item = (u32, &'a Slot, f32)>,
        clear: bool,
    ) {
        let mut draws: Vec<(u32, &Slot)> = Vec::new();
        let mut instances: Vec<DrawInstance> = Vec::new();
        for (model, s, ratio) in slots {
            if s.indices.is_empty() || model >= self.entries {
                continue;
            }
            draws.push((model, s));
            instances.push(DrawInstance {
                ratio: if ratio.is_finite() {
                    ratio.clamp(0.0, 1.0)
                } else {
                    0.0
                },
                tag: s.tag,
                texel_lod: if self.texel_blend { s.texel_lod } else { 0.0 },
            });
        }
        if instances.is_empty() {
            // A valid (never read) binding for a pass that draws nothing.
            instances.push(DrawInstance::default());
        }
        // Textured patches draw through the textured pipeline, made with the cache's
        // texture layout the first time one is drawn.
        let textured = draws
            .iter()
            .any(|(_, s)| s.texture.is_some())
            .then(|| cache.texture_layout())
            .flatten()
            .map(|tex_layout| {
                self.textured_pipeline
                    .get_or_init(|| self.make_textured_pipeline(device, tex_layout, "fs_textured"))
            });
        // Models dissolving into or out of their impostors: the discarding variants.
        let dissolving = self.dissolving.borrow();
        let dissolves = |m: u32| dissolving.get(m as usize).copied().unwrap_or(false);
        let dissolve = draws
            .iter()
            .any(|&(m, s)| s.texture.is_none() && dissolves(m))
            .then(|| {
                self.dissolve_pipeline.get_or_init(|| {
                    let spec = PipelineSpec {
                        layout: &self.plain_layout,
                        attributes: &VERTEX_ATTRIBUTES,
                        vs: "vs_main",
                        fs: "fs_main_dissolve",
                        polygon_mode: wgpu::PolygonMode::Fill,
                        bias: Default::default(),
                    };
                    patch_pipeline(device, &self.shader, self.color_format, &spec)
                })
            });
        let textured_dissolve = draws
            .iter()
            .any(|&(m, s)| s.texture.is_some() && dissolves(m))
            .then(|| cache.texture_layout())
            .flatten()
            .map(|tex_layout| {
                self.textured_dissolve_pipeline.get_or_init(|| {
                    self.make_textured_pipeline(device, tex_layout, "fs_textured_dissolve")
                })
            });
        let instance_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("tessera draw instances"),
            contents: bytemuck::cast_slice(&instances),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let [r, g, b, a] = self.background;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("tessera patches pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: if clear {
                        wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a })
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: if clear {
                        wgpu::LoadOp::Clear(0.0)
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_vertex_buffer(0, cache.vertex_buffer().slice(..));
        pass.set_vertex_buffer(1, instance_buffer.slice(..));
        pass.set_index_buffer(cache.index_buffer().slice(..), wgpu::IndexFormat::Uint32);
        const INSTANCE_BYTES: u64 = std::mem::size_of::<DrawInstance>() as u64;
        // `fill`: the surface, through the plain or the textured pipeline as each patch
        // needs (slots of one model come together, so that switches once a model);
        // else the wireframe overlay (the pipeline set by the caller, for every patch).
        let draw = |pass: &mut wgpu::RenderPass<'_>, fill: bool| {
            let mut bound = None;
            let mut current = None;
            for (k, &(model, s)) in draws.iter().enumerate() {
                if fill {
                    let tex = s.texture.as_ref().zip(textured);
                    let key = (tex.is_some(), dissolves(model));
                    if current != Some(key) {
                        let pipeline = match key {
                            (false, false) => &self.pipeline,
                            (true, false) => tex.map_or(&self.pipeline, |(_, p)| p),
                            (false, true) => dissolve.unwrap_or(&self.pipeline),
                            (true, true) => textured_dissolve
                                .or(tex.map(|(_, p)| p))
                                .unwrap_or(&self.pipeline),
                        };
                        pass.set_pipeline(pipeline);
                        current = Some(key);
                        bound = None;
                    }
                    if let Some((t, _)) = tex {
                        pass.set_bind_group(1, &t.bind_group, &[]);
                    }
                }
                if bound != Some(model) {
                    let offset = u64::from(model) * self.stride;
                    pass.set_bind_group(0, &self.bind_group, &[offset as u32]);
                    bound = Some(model);
                }
                let k = k as u32;
                if self.base_vertex {
                    pass.draw_indexed(s.indices.clone(), s.vertices.start as i32, k..k + 1);
                } else {
                    // No base vertex (WebGL2), and no first instance either: bind both
                    // buffers at the draw's entries.
                    let bytes = u64::from(s.vertices.start) * VERTEX_BYTES
                        ..u64::from(s.vertices.end) * VERTEX_BYTES;
                    pass.set_vertex_buffer(0, cache.vertex_buffer().slice(bytes));
                    let i = u64::from(k) * INSTANCE_BYTES;
                    pass.set_vertex_buffer(1, instance_buffer.slice(i..i + INSTANCE_BYTES));
                    pass.draw_indexed(s.indices.clone(), 0, 0..1);
                }
            }
        };
        draw(&mut pass, true);
        if let (true, Some(wire)) = (self.wireframe.get(), &self.wire_pipeline) {
            pass.set_pipeline(wire);
            draw(&mut pass, false);
        }
    }

    /// The textured pipeline: group 0 the frame uniforms, group 1 a patch texture of
    /// `tex_layout` (the cache's), vertices with texture coordinates.
    fn make_textured_pipeline(
        &self,
        device: &wgpu::Device,
        tex_layout: &wgpu::BindGroupLayout,
        fs: &str,
    ) -> wgpu::RenderPipeline {
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tessera textured patch pipeline layout"),
            bind_group_layouts: &[Some(&self.bind_group_layout), Some(tex_layout)],
            immediate_size: 0,
        });
        let spec = PipelineSpec {
            layout: &layout,
            attributes: &TEXTURED_VERTEX_ATTRIBUTES,
            vs: "vs_textured",
            fs,
            polygon_mode: wgpu::PolygonMode::Fill,
            bias: Default::default(),
        };
        patch_pipeline(device, &self.shader, self.color_format, &spec)
    }

    /// The offscreen colour and depth views (after [`Renderer::ensure_offscreen`]).
    pub fn offscreen_views(&self) -> Option<(&wgpu::TextureView, &wgpu::TextureView)> {
        self.targets
            .as_ref()
            .map(|t| (&t.color_view, &t.depth_view))
    }

    /// The offscreen colour texture (a window samples it onto its surface).
    pub fn offscreen_color(&self) -> Option<&wgpu::TextureView> {
        self.targets.as_ref().map(|t| &t.color_view)
    }

    /// The stored depth of pixel (`x`, `y`) of the last frame (reversed Z: 0 is the
    /// background, 1 the near plane); None outside the target. Waits for the GPU.
    pub fn read_depth(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        x: u32,
        y: u32,
    ) -> Result<Option<f32>, RenderError> {
        let t = self.targets.as_ref().ok_or(RenderError::NoFrame)?;
        if x >= t.width || y >= t.height {
            return Ok(None);
        }
        // Map only the 8 bytes (the mapping alignment) around the pixel.
        let at = u64::from(y) * u64::from(t.padded_row) + u64::from(x) * 4;
        let start = at & !7;
        let slice = copy_and_map(
            device,
            queue,
            t,
            &t.depth,
            wgpu::TextureAspect::DepthOnly,
            &t.depth_readback,
            start..start + 8,
        )?;
        let d = {
            let data = slice
                .get_mapped_range()
                .map_err(|e| RenderError::Device(format!("{e:?}")))?;
            let o = (at - start) as usize;
            f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]])
        };
        t.depth_readback.unmap();
        Ok(Some(d))
    }

    /// Copies the offscreen colour target to the CPU (waits for the GPU).
    pub fn read_offscreen(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Image, RenderError> {
        let t = self.targets.as_ref().ok_or(RenderError::NoFrame)?;
        let slice = copy_and_map(
            device,
            queue,
            t,
            &t.color,
            wgpu::TextureAspect::All,
            &t.readback,
            0..t.readback.size(),
        )?;
        let mut rgba = Vec::with_capacity((t.width * t.height * 4) as usize);
        {
            let data = slice
                .get_mapped_range()
                .map_err(|e| RenderError::Device(format!("{e:?}")))?;
            for row in data.chunks(t.padded_row as usize).take(t.height as usize) {
                rgba.extend_from_slice(&row[..(t.width * 4) as usize]);
            }
        }
        t.readback.unmap();
        Ok(Image {
            width: t.width,
            height: t.height,
            rgba,
        })
    }
}

/// Copies the whole of `texture` (a target of `t`: depth formats cannot be copied in
/// part) into `buffer` with `t`'s padded rows, waits for the GPU, and returns `range` of
/// the buffer mapped for reading (unmap the buffer when done).
fn copy_and_map<'b>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    t: &Targets,
    texture: &wgpu::Texture,
    aspect: wgpu::TextureAspect,
    buffer: &'b wgpu::Buffer,
    range: std::ops::Range<u64>,
) -> Result<wgpu::BufferSlice<'b>, RenderError> {
    let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("tessera readback encoder"),
    });
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect,
        },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(t.padded_row),
                rows_per_image: Some(t.height),
            },
        },
        wgpu::Extent3d {
            width: t.width,
            height: t.height,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([enc.finish()]);
    let slice = buffer.slice(range);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| RenderError::Device(e.to_string()))?;
    Ok(slice)
}

/// A depth target for `width` x `height`.
pub(crate) fn create_depth_texture(
    device: &wgpu::Device,
    width: u32,
    height: u32,
) -> (wgpu::Texture, wgpu::TextureView) {
    let depth = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("tessera depth"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        // Copied from for the depth under the cursor (zoom to point).
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = depth.create_view(&wgpu::TextureViewDescriptor {
        label: Some("tessera depth view"),
        ..Default::default()
    });
    (depth, view)
}
