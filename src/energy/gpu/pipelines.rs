//! The engine's bind group layouts and pipelines, each render pipeline built from one
//! description ([`PipelineSpec`]) so that variants differ only where they say.

pub const CLASS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Uint;
pub const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// What distinguishes one render pipeline from another.
pub struct PipelineSpec {
    pub label: &'static str,
    pub vertex: &'static str,
    pub fragment: &'static str,
    pub format: wgpu::TextureFormat,
    pub blend: Option<wgpu::BlendState>,
    pub write_mask: wgpu::ColorWrites,
    pub depth_compare: wgpu::CompareFunction,
    pub depth_write: bool,
}

/// The layouts and the histogram engine's pipelines: the class pass (clear a tile, draw the
/// models) and the compute histogram.
pub struct Pipelines {
    pub draw_layout: wgpu::BindGroupLayout,
    pub count_layout: wgpu::BindGroupLayout,
    render_layout: wgpu::PipelineLayout,
    pub model: wgpu::RenderPipeline,
    pub clear: wgpu::RenderPipeline,
    pub count: wgpu::ComputePipeline,
}

/// shaders/raster.wgsl, or it with `appended` after it (the readback baseline's stages).
pub fn raster_module(device: &wgpu::Device, appended: Option<&str>) -> wgpu::ShaderModule {
    let raster = include_str!("../../../shaders/raster.wgsl");
    let source = match appended {
        Some(more) => format!("{raster}\n{more}"),
        None => raster.to_string(),
    };
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("raster.wgsl"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}

impl Pipelines {
    pub fn new(device: &wgpu::Device) -> Pipelines {
        let raster_module = raster_module(device, None);
        let histogram_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("histogram.wgsl"),
            source: wgpu::ShaderSource::Wgsl(
                include_str!("../../../shaders/histogram.wgsl").into(),
            ),
        });
        let storage = |binding, read_only, visibility| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let uint_texture = |binding, view_dimension| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Uint,
                view_dimension,
                multisampled: false,
            },
            count: None,
        };
        let draw_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("draws"),
            entries: &[
                storage(0, true, wgpu::ShaderStages::VERTEX_FRAGMENT),
                wgpu::BindGroupLayoutEntry {
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ..uint_texture(1, wgpu::TextureViewDimension::D2Array)
                },
            ],
        });
        let count_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("histogram"),
            entries: &[
                storage(0, true, wgpu::ShaderStages::COMPUTE),
                storage(1, false, wgpu::ShaderStages::COMPUTE),
                uint_texture(2, wgpu::TextureViewDimension::D2),
                uint_texture(3, wgpu::TextureViewDimension::D2Array),
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: wgpu::BufferSize::new(16),
                    },
                    count: None,
                },
            ],
        });
        let render_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raster"),
            bind_group_layouts: &[Some(&draw_layout)],
            immediate_size: 0,
        });
        let count = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("histogram"),
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("histogram"),
                    bind_group_layouts: &[Some(&count_layout)],
                    immediate_size: 0,
                }),
            ),
            module: &histogram_module,
            entry_point: Some("count"),
            compilation_options: Default::default(),
            cache: None,
        });
        let pipeline = |spec| render_pipeline(device, &render_layout, &raster_module, spec);
        use wgpu::CompareFunction::{Always, Less};
        let class_spec = |label, vertex, depth_compare| PipelineSpec {
            label,
            vertex,
            fragment: "fs_class",
            format: CLASS_FORMAT,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
            depth_compare,
            depth_write: true,
        };
        // First drawn wins ties, as in the CPU rasteriser (strictly nearer replaces).
        let model = pipeline(class_spec("model", "vs_model", Less));
        let clear = pipeline(class_spec("clear tile", "vs_clear", Always));
        Pipelines {
            draw_layout,
            count_layout,
            render_layout,
            model,
            clear,
            count,
        }
    }

    /// A render pipeline of `module` over the draw layout.
    pub fn render(
        &self,
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        spec: PipelineSpec,
    ) -> wgpu::RenderPipeline {
        render_pipeline(device, &self.render_layout, module, spec)
    }
}

fn render_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    spec: PipelineSpec,
) -> wgpu::RenderPipeline {
    let attributes = wgpu::vertex_attr_array![0 => Float32x3];
    let buffers = [Some(wgpu::VertexBufferLayout {
        array_stride: 12,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &attributes,
    })];
    let is_model = spec.vertex == "vs_model";
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(spec.label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(spec.vertex),
            compilation_options: Default::default(),
            buffers: if is_model { &buffers } else { &[] },
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(spec.depth_write),
            depth_compare: Some(spec.depth_compare),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(spec.fragment),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: spec.format,
                blend: spec.blend,
                write_mask: spec.write_mask,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}
