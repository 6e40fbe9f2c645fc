//! The smooth energy's edge terms on the GPU (shaders/edge_terms.wgsl, whose CPU twin is
//! src/energy/edge_terms.rs): the samples and their views in, one term per sample read back,
//! over the frame's mask texture; one submission per query. Its pipeline is made once, its
//! buffers grow when a query needs more and are reused otherwise.

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};

use super::GpuEnergy;
use crate::arch::{LOWER_BIT, UPPER_BIT};
use crate::capture::masks::MOUTH_BIT;
use crate::energy::edge_terms::{EdgeKind, EdgeQuery, EdgeTerm};
use crate::error::GpuError;

/// `Sample` in shaders/edge_terms.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SampleRecord {
    pixel: [f32; 2],
    normal: [f32; 2],
    jacobian: [f32; 12],
    length: f32,
    view: u32,
    arch: u32,
    kind: u32,
}

/// `Sample.kind` in shaders/edge_terms.wgsl.
fn kind_bits(kind: EdgeKind) -> u32 {
    match kind {
        EdgeKind::Region => 0,
        EdgeKind::Silhouette { boi } => 1 | (boi as u32) << 1,
    }
}

/// `View` in shaders/edge_terms.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewRecord {
    layer: u32,
    width: u32,
    height: u32,
    _pad: u32,
}

/// `Params` in shaders/edge_terms.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ParamsRecord {
    moved: [f32; 12],
    reach: f32,
    smoothing: f32,
    lambda: f32,
    cross: f32,
    mouth: f32,
    count: u32,
    upper_bit: u32,
    lower_bit: u32,
    mouth_bit: u32,
    _pad: [u32; 3],
}

/// Threads per workgroup in shaders/edge_terms.wgsl.
const WORKGROUP: u32 = 64;

/// The stage's pipeline, made once, and its buffers, grown on demand.
pub(super) struct EdgeStage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    buffers: Mutex<Option<EdgeBuffers>>,
}

struct EdgeBuffers {
    samples: wgpu::Buffer,
    views: wgpu::Buffer,
    terms: wgpu::Buffer,
    staging: wgpu::Buffer,
    group: wgpu::BindGroup,
    /// Room for this many samples and views.
    samples_room: usize,
    views_room: usize,
}

impl EdgeStage {
    pub(super) fn new(device: &wgpu::Device) -> EdgeStage {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("edge_terms.wgsl"),
            source: wgpu::ShaderSource::Wgsl(
                include_str!("../../../shaders/edge_terms.wgsl").into(),
            ),
        });
        let buffer = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("edge terms"),
            entries: &[
                buffer(0, storage(true)),
                buffer(1, storage(true)),
                buffer(2, wgpu::BufferBindingType::Uniform),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
                buffer(4, storage(false)),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("edge terms"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("edge terms"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("edge_terms"),
            compilation_options: Default::default(),
            cache: None,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("edge params"),
            size: std::mem::size_of::<ParamsRecord>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        EdgeStage {
            layout,
            pipeline,
            params,
            buffers: Mutex::new(None),
        }
    }
}

impl GpuEnergy {
    /// Buffers with room for `samples` samples and `views` views (grown by half again when
    /// they must grow, so that a run's slowly growing stages do not remake them each time).
    fn edge_buffers<'g>(
        &self,
        guard: &'g mut Option<EdgeBuffers>,
        samples: usize,
        views: usize,
    ) -> &'g EdgeBuffers {
        let fits = guard
            .as_ref()
            .is_some_and(|b| b.samples_room >= samples && b.views_room >= views);
        if !fits {
            let device = &self.ctx.device;
            let (samples, views) = (samples.max(1) * 3 / 2 + 1, views.max(1));
            let make = |label, size: usize, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size as u64,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let copy_dst = wgpu::BufferUsages::COPY_DST;
            let storage = wgpu::BufferUsages::STORAGE;
            let terms_size = samples * 16;
            let buffers_samples = make(
                "edge samples",
                samples * std::mem::size_of::<SampleRecord>(),
                storage | copy_dst,
            );
            let buffers_views = make(
                "edge views",
                views * std::mem::size_of::<ViewRecord>(),
                storage | copy_dst,
            );
            let terms = make(
                "edge terms",
                terms_size,
                storage | wgpu::BufferUsages::COPY_SRC,
            );
            let staging = make(
                "edge terms staging",
                terms_size,
                wgpu::BufferUsages::MAP_READ | copy_dst,
            );
            let stage = &self.edges;
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("edge terms"),
                layout: &stage.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: buffers_samples.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: buffers_views.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: stage.params.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&self.masks_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: terms.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::TextureView(&self.evidence_view),
                    },
                ],
            });
            *guard = Some(EdgeBuffers {
                samples: buffers_samples,
                views: buffers_views,
                terms,
                staging,
                group,
                samples_room: samples,
                views_room: views,
            });
        }
        guard.as_ref().expect("made above")
    }

    /// Each sample's term over the frame's masks (see [`crate::energy::edge_terms`]).
    pub(super) fn run_edge_terms(&self, q: &EdgeQuery) -> Result<Vec<Option<EdgeTerm>>, GpuError> {
        if q.samples.is_empty() {
            return Ok(Vec::new());
        }
        let samples: Vec<SampleRecord> = q
            .samples
            .iter()
            .map(|s| {
                let j = &s.point.jacobian;
                SampleRecord {
                    pixel: [s.point.pixel.x as f32, s.point.pixel.y as f32],
                    normal: [s.point.normal.x as f32, s.point.normal.y as f32],
                    jacobian: std::array::from_fn(|i| j[(i / 6, i % 6)] as f32),
                    length: s.point.length as f32,
                    view: s.view as u32,
                    arch: s.arch as u32,
                    kind: kind_bits(s.kind),
                }
            })
            .collect();
        // A view without a mask this frame is an empty one: no edge is found in it.
        let views: Vec<ViewRecord> = q
            .cameras
            .iter()
            .map(|&k| {
                let layer = q.params.level * self.frame.len() + k;
                let (width, height) = self
                    .mask_sizes
                    .get(layer)
                    .copied()
                    .flatten()
                    .unwrap_or((0, 0));
                ViewRecord {
                    layer: layer as u32,
                    width,
                    height,
                    _pad: 0,
                }
            })
            .collect();
        let (u, l) = (&q.moved[0], &q.moved[1]);
        let p = &q.params;
        let params = ParamsRecord {
            moved: std::array::from_fn(|i| if i < 6 { u[i] } else { l[i - 6] } as f32),
            reach: p.reach_px as f32,
            smoothing: p.smoothing_px as f32,
            lambda: p.weights.lambda as f32,
            cross: p.weights.cross as f32,
            mouth: p.weights.mouth as f32,
            count: samples.len() as u32,
            upper_bit: UPPER_BIT as u32,
            lower_bit: LOWER_BIT as u32,
            mouth_bit: MOUTH_BIT as u32,
            _pad: [0; 3],
        };
        let mut guard = self.edges.buffers.lock().unwrap_or_else(|e| e.into_inner());
        let b = self.edge_buffers(&mut guard, samples.len(), views.len());
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        queue.write_buffer(&b.samples, 0, bytemuck::cast_slice(&samples));
        queue.write_buffer(&b.views, 0, bytemuck::cast_slice(&views));
        queue.write_buffer(&self.edges.params, 0, bytemuck::bytes_of(&params));
        let size = (samples.len() * 16) as u64;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("edge terms"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("edge terms"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.edges.pipeline);
            pass.set_bind_group(0, &b.group, &[]);
            pass.dispatch_workgroups((samples.len() as u32).div_ceil(WORKGROUP), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&b.terms, 0, &b.staging, 0, size);
        queue.submit([encoder.finish()]);
        let bytes = self.ctx.read_back(&b.staging, size)?;
        let float = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        Ok(bytes
            .chunks_exact(16)
            .map(|c| [0, 4, 8, 12].map(|k| float(&c[k..])))
            .map(|t| {
                (t[3] != 0.0).then(|| EdgeTerm {
                    offset_px: t[0] as f64,
                    weight: t[1] as f64,
                    energy: t[2] as f64,
                })
            })
            .collect())
    }
}
