//! The energy on the GPU (wgpu, headless): each candidate's arch is rasterised into a tile of a
//! class atlas (render pass, Vulkan rasterisation rules like the CPU twin), and a compute
//! histogram counts the six bins of every tile; one submission and one readback per batch.
//!
//! Everything is created once in [`GpuEnergy::new`]: pipelines, layouts, the meshes' vertex
//! and index buffers, the atlas and the mask texture; per-batch buffers grow when a batch needs
//! more and are reused otherwise. Masks are uploaded once per frame in `set_frame`.

mod adapter;
mod atlas;

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};
use nalgebra::Matrix4;

use wgpu::util::DeviceExt;

pub use crate::error::GpuError;
pub use adapter::{ADAPTER_ENV, GpuContext};

use super::lens::Lens;
use super::raster::{self, CLASS_BODY, CLASS_BOI, NEAR_MM, Rect};
use super::{Counts, Energy, EnergyEngine, Region, Scene, counts_with_outside, mask_totals};
use crate::capture::{Arch, ArchPoses, FrameMasks, Mesh};
use crate::error::Result;
use crate::geometry::{Camera, Pose};

/// How the counts are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Counting {
    /// The compute-shader histogram (the engine).
    Histogram,
    /// The paper's architecture, as a baseline: a colour image per camera (mask white, model
    /// red at alpha 0.5, BOI green), read back whole and counted on one CPU thread.
    Readback,
}

/// Side of an atlas page (pixels); masks up to this size are supported.
const PAGE: u32 = 4096;
/// A dispatch's z extent is at most 65535 workgroups.
const MAX_TILES_PER_PAGE: usize = 65535;
/// Pixels per workgroup side in shaders/histogram.wgsl.
const HISTOGRAM_BLOCK: u32 = 32;
/// Uniform entries with dynamic offsets are 256 bytes apart.
const PAGE_PARAMS_STRIDE: u64 = 256;

/// `Draw` in shaders/raster.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DrawRecord {
    camera_from_model: [[f32; 4]; 4],
    focal: [f32; 2],
    centre: [f32; 2],
    half_viewport: [f32; 2],
    near: f32,
    far: f32,
    class_id: u32,
    projected: u32,
    mask_offset: [i32; 2],
    layer: u32,
    arch_bit: u32,
    _pad: [u32; 2],
    /// The camera's lens (k1, k2, p1, p2), k3, its limit (r²) and whether it has one.
    lens: [f32; 4],
    lens_k3: f32,
    lens_limit_r2: f32,
    distorted: u32,
    _pad2: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct TileRecord {
    atlas_x: u32,
    atlas_y: u32,
    width: u32,
    height: u32,
    mask_x: u32,
    mask_y: u32,
    layer: u32,
    arch_bit: u32,
    other_bit: u32,
    slot: u32,
    _pad: [u32; 2],
}

/// An arch on the GPU: body triangles first, then BOI triangles, in one index buffer.
struct GpuMesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    body_indices: u32,
    boi_indices: u32,
    /// Corners of the model-space bounding box, for conservative footprints.
    corners: [[f32; 3]; 8],
    radius: f64,
}

impl GpuMesh {
    fn new(device: &wgpu::Device, mesh: &Mesh, label: &str) -> GpuMesh {
        let mut indices: Vec<u32> = Vec::with_capacity(mesh.triangles.len() * 3);
        for want in [false, true] {
            for (t, _) in mesh
                .triangles
                .iter()
                .zip(&mesh.boi)
                .filter(|(_, b)| **b == want)
            {
                indices.extend_from_slice(t);
            }
        }
        let boi = mesh.boi_face_count() as u32 * 3;
        let (lo, hi) = mesh.bounds();
        let corners = crate::energy::clusters::box_corners(lo, hi);
        let radius = corners
            .iter()
            .map(|c| (c[0] as f64).hypot(c[1] as f64).hypot(c[2] as f64))
            .fold(0.0, f64::max);
        GpuMesh {
            vertices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(&mesh.positions),
                usage: wgpu::BufferUsages::VERTEX,
            }),
            indices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(&indices),
                usage: wgpu::BufferUsages::INDEX,
            }),
            body_indices: indices.len() as u32 - boi,
            boi_indices: boi,
            corners,
            radius,
        }
    }
}

/// Per-batch buffers, grown on demand, and the bind groups over them.
struct Batch {
    draws: wgpu::Buffer,
    tiles: wgpu::Buffer,
    pages: wgpu::Buffer,
    counts: wgpu::Buffer,
    staging: wgpu::Buffer,
    draw_group: wgpu::BindGroup,
    count_group: wgpu::BindGroup,
    /// Capacities: draws, tiles, pages.
    capacity: (usize, usize, usize),
}

/// The readback baseline's colour target, pipelines and staging buffer.
struct ReadbackTarget {
    colour: wgpu::Texture,
    colour_view: wgpu::TextureView,
    clear: wgpu::RenderPipeline,
    prepass: wgpu::RenderPipeline,
    mask: wgpu::RenderPipeline,
    colour_pass: wgpu::RenderPipeline,
    staging: Mutex<Option<(wgpu::Buffer, u64)>>,
}

pub struct GpuEnergy {
    ctx: GpuContext,
    scene: Scene,
    region: Region,
    counting: Counting,
    meshes: [GpuMesh; 2],
    model_pipeline: wgpu::RenderPipeline,
    clear_pipeline: wgpu::RenderPipeline,
    count_pipeline: wgpu::ComputePipeline,
    readback: Option<ReadbackTarget>,
    draw_layout: wgpu::BindGroupLayout,
    count_layout: wgpu::BindGroupLayout,
    class_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    masks: wgpu::Texture,
    masks_view: wgpu::TextureView,
    /// Per camera: the frame's mask totals per scored arch (upper, lower; see
    /// `mask_totals`), or `None` without a mask.
    frame: Vec<Option<[[u64; 2]; 2]>>,
    batch: Mutex<Option<Batch>>,
}

const CLASS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Uint;
const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// What distinguishes one render pipeline from another.
struct PipelineSpec {
    label: &'static str,
    vertex: &'static str,
    fragment: &'static str,
    format: wgpu::TextureFormat,
    blend: Option<wgpu::BlendState>,
    write_mask: wgpu::ColorWrites,
    depth_compare: wgpu::CompareFunction,
    depth_write: bool,
}
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl GpuEnergy {
    /// Open the best adapter (see [`adapter`]) and build the engine for `scene`.
    pub fn new(scene: Scene, region: Region) -> Result<GpuEnergy, GpuError> {
        Self::with_context(adapter::open()?, scene, region, Counting::Histogram)
    }

    /// The paper's architecture on the same adapter (always full frame).
    pub fn readback_baseline(scene: Scene) -> Result<GpuEnergy, GpuError> {
        Self::with_context(
            adapter::open()?,
            scene,
            Region::FullFrame,
            Counting::Readback,
        )
    }

    pub fn with_context(
        ctx: GpuContext,
        scene: Scene,
        region: Region,
        counting: Counting,
    ) -> Result<GpuEnergy, GpuError> {
        // The baseline reads the whole target back, as the paper does.
        let region = if counting == Counting::Readback {
            Region::FullFrame
        } else {
            region
        };
        let scene = scene.compacted();
        let device = &ctx.device;
        let (mut mask_w, mut mask_h) = (1, 1);
        for cam in scene.cameras.iter().flatten() {
            if cam.width > PAGE || cam.height > PAGE {
                return Err(GpuError::MaskTooLarge {
                    camera: cam.name.clone(),
                    width: cam.width,
                    height: cam.height,
                    page: PAGE,
                });
            }
            mask_w = mask_w.max(cam.width);
            mask_h = mask_h.max(cam.height);
        }
        let raster_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raster.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/raster.wgsl").into()),
        });
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
        // Every render pipeline comes from this one description.
        let render_pipeline = |spec: PipelineSpec| {
            let attributes = wgpu::vertex_attr_array![0 => Float32x3];
            let buffers = [Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })];
            let is_model = spec.vertex == "vs_model";
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(spec.label),
                layout: Some(&render_layout),
                vertex: wgpu::VertexState {
                    module: &raster_module,
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
                    module: &raster_module,
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
        };
        use wgpu::CompareFunction::{Always, Equal, Less};
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
        let model_pipeline = render_pipeline(class_spec("model", "vs_model", Less));
        let clear_pipeline = render_pipeline(class_spec("clear tile", "vs_clear", Always));
        let readback = (counting == Counting::Readback).then(|| {
            let colour_spec = |label, vertex, fragment, depth_compare, depth_write| PipelineSpec {
                label,
                vertex,
                fragment,
                format: COLOUR_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
                depth_compare,
                depth_write,
            };
            let colour = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("colour page"),
                size: wgpu::Extent3d {
                    width: PAGE,
                    height: PAGE,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: COLOUR_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            ReadbackTarget {
                colour_view: colour.create_view(&Default::default()),
                colour,
                clear: render_pipeline(colour_spec(
                    "clear colour",
                    "vs_clear",
                    "fs_clear_colour",
                    Always,
                    true,
                )),
                prepass: render_pipeline(PipelineSpec {
                    write_mask: wgpu::ColorWrites::empty(),
                    ..colour_spec("depth pre-pass", "vs_model", "fs_clear_colour", Less, true)
                }),
                mask: render_pipeline(colour_spec("mask", "vs_clear", "fs_mask", Always, false)),
                colour_pass: render_pipeline(colour_spec(
                    "model colour",
                    "vs_model",
                    "fs_colour",
                    Equal,
                    false,
                )),
                staging: Mutex::new(None),
            }
        });
        let count_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
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
        let texture = |label, format, usage, (w, h, layers)| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: layers,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let attachment = wgpu::TextureUsages::RENDER_ATTACHMENT;
        let class = texture(
            "class atlas",
            CLASS_FORMAT,
            attachment | wgpu::TextureUsages::TEXTURE_BINDING,
            (PAGE, PAGE, 1),
        );
        let depth = texture("depth atlas", DEPTH_FORMAT, attachment, (PAGE, PAGE, 1));
        let layers = scene.cameras.len().max(1) as u32;
        let masks = texture(
            "masks",
            wgpu::TextureFormat::R8Uint,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            (mask_w, mask_h, layers),
        );
        let masks_view = masks.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let meshes = [
            GpuMesh::new(device, &scene.upper, "upper"),
            GpuMesh::new(device, &scene.lower, "lower"),
        ];
        Ok(GpuEnergy {
            counting,
            readback,
            frame: vec![None; scene.cameras.len()],
            class_view: class.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            masks,
            masks_view,
            meshes,
            model_pipeline,
            clear_pipeline,
            count_pipeline,
            draw_layout,
            count_layout,
            region,
            scene,
            batch: Mutex::new(None),
            ctx,
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// A camera's mask totals for the scored arch; the readback baseline, like the paper,
    /// sees only the arch's own mask, and counts the other arch's pixels as none.
    fn totals(&self, frame: &[[u64; 2]; 2], arch: Arch) -> [u64; 2] {
        let t = frame[(arch == Arch::Lower) as usize];
        match self.counting {
            Counting::Histogram => t,
            Counting::Readback => [t[0], 0],
        }
    }

    fn mesh(&self, arch: Arch) -> &GpuMesh {
        &self.meshes[(arch == Arch::Lower) as usize]
    }

    /// The batch buffers with room for the given counts (grown, never shrunk).
    fn batch_with_room<'a>(
        &self,
        slot: &'a mut Option<Batch>,
        draws: usize,
        tiles: usize,
        pages: usize,
    ) -> &'a Batch {
        let fits = slot.as_ref().is_some_and(|b| {
            b.capacity.0 >= draws && b.capacity.1 >= tiles && b.capacity.2 >= pages
        });
        if !fits {
            let old = slot.as_ref().map(|b| b.capacity).unwrap_or((0, 0, 0));
            let cap = (
                draws.max(old.0).next_power_of_two().max(64),
                tiles.max(old.1).next_power_of_two().max(32),
                pages.max(old.2).next_power_of_two().max(4),
            );
            *slot = Some(self.make_batch(cap));
        }
        slot.as_ref().expect("just made")
    }

    fn make_batch(&self, capacity: (usize, usize, usize)) -> Batch {
        let device = &self.ctx.device;
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let counts_size = (capacity.1 * 9 * 4) as u64;
        let draws = buffer(
            "draws",
            (capacity.0 * size_of::<DrawRecord>()) as u64,
            U::STORAGE | U::COPY_DST,
        );
        let tiles = buffer(
            "tiles",
            (capacity.1 * size_of::<TileRecord>()) as u64,
            U::STORAGE | U::COPY_DST,
        );
        let pages = buffer(
            "pages",
            capacity.2 as u64 * PAGE_PARAMS_STRIDE,
            U::UNIFORM | U::COPY_DST,
        );
        let counts = buffer(
            "counts",
            counts_size,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let staging = buffer("counts readback", counts_size, U::MAP_READ | U::COPY_DST);
        let draw_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("draws"),
            layout: &self.draw_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: draws.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&self.masks_view),
                },
            ],
        });
        let count_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("histogram"),
            layout: &self.count_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: tiles.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: counts.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&self.class_view),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&self.masks_view),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &pages,
                        offset: 0,
                        size: wgpu::BufferSize::new(16),
                    }),
                },
            ],
        });
        Batch {
            draws,
            tiles,
            pages,
            counts,
            staging,
            draw_group,
            count_group,
            capacity,
        }
    }
}

/// The viewport a camera's tiles are drawn with: the image's size rounded up to powers of two
/// (exact arithmetic in the shader's snapping; see shaders/raster.wgsl).
fn viewport_size(cam: &Camera) -> (u32, u32) {
    (
        cam.width.next_power_of_two(),
        cam.height.next_power_of_two(),
    )
}

fn pose_matrix(p: &Pose) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(p.rotation.matrix());
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&p.translation);
    m
}

fn to_f32_columns(m: &Matrix4<f64>) -> [[f32; 4]; 4] {
    std::array::from_fn(|c| std::array::from_fn(|r| m[(r, c)] as f32))
}

/// One tile of a batch: a candidate seen by a camera, over `rect` of that camera's mask.
struct Tile {
    candidate: usize,
    camera: usize,
    rect: Rect,
}

impl GpuEnergy {
    /// The image region a tile must cover for a candidate (see [`Region`]).
    fn tile_rect(&self, cam: &Camera, arch: Arch, poses: &ArchPoses) -> Rect {
        if self.region == Region::FullFrame {
            return Rect::full(cam.width, cam.height);
        }
        let corners_in_camera = |a: Arch| -> Vec<[f32; 3]> {
            let p = cam.camera_from_world.compose(poses.get(a));
            self.mesh(a)
                .corners
                .iter()
                .map(|c| {
                    let v = p.transform_point(&nalgebra::Vector3::new(
                        c[0] as f64,
                        c[1] as f64,
                        c[2] as f64,
                    ));
                    [v.x as f32, v.y as f32, v.z as f32]
                })
                .collect()
        };
        let lens = Lens::of(cam);
        let mut rect = raster::footprint(cam, lens.as_ref(), &corners_in_camera(arch));
        if self.scene.other_arch_class() != raster::CLASS_NONE {
            let other = corners_in_camera(arch.other());
            rect = rect.union(&raster::footprint(cam, lens.as_ref(), &other));
        }
        rect
    }

    fn run_batch(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>, GpuError> {
        let mut tiles = Vec::new();
        for (candidate, poses) in candidates.iter().enumerate() {
            for (camera, cam) in self.scene.cameras.iter().enumerate() {
                if let (Some(cam), Some(_)) = (cam, self.frame[camera]) {
                    let rect = self.tile_rect(cam, arch, poses);
                    if rect.area() > 0 {
                        tiles.push(Tile {
                            candidate,
                            camera,
                            rect,
                        });
                    }
                }
            }
        }
        let inside = if tiles.is_empty() {
            Vec::new()
        } else {
            self.render_and_count(arch, candidates, &tiles)?
        };
        let n_cams = self.scene.cameras.len();
        let mut energies: Vec<Energy> = (0..candidates.len())
            .map(|_| Energy {
                cameras: vec![Counts::default(); n_cams],
            })
            .collect();
        // Cameras with a mask but no tile (the arch is out of view) still count their mask.
        for e in &mut energies {
            for (k, totals) in self.frame.iter().enumerate() {
                if let (Some(t), Some(cam)) = (totals, &self.scene.cameras[k]) {
                    e.cameras[k] = counts_with_outside([0; 9], cam, self.totals(t, arch));
                }
            }
        }
        for (tile, bins) in tiles.iter().zip(inside) {
            let cam = self.scene.cameras[tile.camera]
                .as_ref()
                .expect("tiles only for cameras");
            let totals = self.frame[tile.camera].expect("tiles only for cameras with masks");
            energies[tile.candidate].cameras[tile.camera] =
                counts_with_outside(bins, cam, self.totals(&totals, arch));
        }
        Ok(energies)
    }

    /// Render every tile (page by page), count each, read the counts back.
    fn render_and_count(
        &self,
        arch: Arch,
        candidates: &[ArchPoses],
        tiles: &[Tile],
    ) -> Result<Vec<[u64; 9]>, GpuError> {
        let sizes: Vec<(u32, u32)> = tiles
            .iter()
            .map(|t| (t.rect.width, t.rect.height))
            .collect();
        let placement = atlas::pack(&sizes, PAGE, MAX_TILES_PER_PAGE);
        let draws = self.draw_records(arch, candidates, tiles, &placement);
        match self.counting {
            Counting::Histogram => self.count_histogram(arch, tiles, &placement, &draws),
            Counting::Readback => self.count_readback(tiles, &placement, &draws),
        }
    }

    /// Three draws per tile, in drawing order: the other arch, the scored arch's body, its BOI.
    fn draw_records(
        &self,
        arch: Arch,
        candidates: &[ArchPoses],
        tiles: &[Tile],
        placement: &[atlas::Placement],
    ) -> Vec<DrawRecord> {
        let scored = self.mesh(arch);
        let other = self.mesh(arch.other());
        let other_class = self.scene.other_arch_class();
        let mut draws = Vec::with_capacity(tiles.len() * 3);
        for (tile, place) in tiles.iter().zip(placement) {
            let cam = self.scene.cameras[tile.camera]
                .as_ref()
                .expect("tiles only for cameras");
            let poses = &candidates[tile.candidate];
            // One depth range for the whole tile (depth must compare across draws).
            let centre = cam.centre_world();
            let far = [(arch, scored), (arch.other(), other)]
                .iter()
                .map(|(a, m)| (poses.get(*a).translation - centre).norm() + m.radius)
                .fold(0.0, f64::max)
                * 1.5
                + 10.0;
            let (vw, vh) = viewport_size(cam);
            let lens = Lens::of(cam);
            let record = |a: Arch, mesh: &GpuMesh, class_id: u8| {
                let camera_from_model = cam.camera_from_world.compose(poses.get(a));
                let projected = mesh.corners.iter().all(|c| {
                    let v = nalgebra::Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                    camera_from_model.transform_point(&v).z >= NEAR_MM
                });
                DrawRecord {
                    camera_from_model: to_f32_columns(&pose_matrix(&camera_from_model)),
                    focal: [cam.fx as f32, cam.fy as f32],
                    centre: [(cam.cx + 0.5) as f32, (cam.cy + 0.5) as f32],
                    half_viewport: [vw as f32 / 2.0, vh as f32 / 2.0],
                    near: NEAR_MM as f32,
                    far: far as f32,
                    class_id: class_id as u32,
                    projected: projected as u32,
                    mask_offset: [
                        place.x as i32 - tile.rect.x0 as i32,
                        place.y as i32 - tile.rect.y0 as i32,
                    ],
                    layer: tile.camera as u32,
                    arch_bit: arch.mask_bit() as u32,
                    _pad: [0; 2],
                    lens: lens.map_or([0.0; 4], |l| [l.k1, l.k2, l.p1, l.p2]),
                    lens_k3: lens.map_or(0.0, |l| l.k3),
                    lens_limit_r2: lens.map_or(0.0, |l| l.limit_r2),
                    distorted: lens.is_some() as u32,
                    _pad2: 0,
                }
            };
            draws.push(record(arch.other(), other, other_class));
            draws.push(record(arch, scored, CLASS_BODY));
            draws.push(record(arch, scored, CLASS_BOI));
        }
        draws
    }

    /// Viewport and scissor of a tile: the whole image's viewport, shifted so that the tile's
    /// region of the image lands on its place in the atlas; the scissor keeps drawing inside.
    fn set_tile(&self, pass: &mut wgpu::RenderPass<'_>, tile: &Tile, place: &atlas::Placement) {
        let cam = self.scene.cameras[tile.camera]
            .as_ref()
            .expect("tiles only for cameras");
        let r = &tile.rect;
        let (vw, vh) = viewport_size(cam);
        let (vx, vy) = (place.x as f32 - r.x0 as f32, place.y as f32 - r.y0 as f32);
        pass.set_viewport(vx, vy, vw as f32, vh as f32, 0.0, 1.0);
        pass.set_scissor_rect(place.x, place.y, r.width, r.height);
    }

    /// The three model draws of a tile whose records start at `first`, with the pipeline set.
    fn draw_arches(&self, pass: &mut wgpu::RenderPass<'_>, arch: Arch, first: u32) {
        let (scored, other) = (self.mesh(arch), self.mesh(arch.other()));
        pass.set_vertex_buffer(0, other.vertices.slice(..));
        pass.set_index_buffer(other.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(
            0..other.body_indices + other.boi_indices,
            0,
            first..first + 1,
        );
        pass.set_vertex_buffer(0, scored.vertices.slice(..));
        pass.set_index_buffer(scored.indices.slice(..), wgpu::IndexFormat::Uint32);
        if scored.body_indices > 0 {
            pass.draw_indexed(0..scored.body_indices, 0, first + 1..first + 2);
        }
        if scored.boi_indices > 0 {
            let all = scored.body_indices + scored.boi_indices;
            pass.draw_indexed(scored.body_indices..all, 0, first + 2..first + 3);
        }
    }

    fn begin_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        colour: &wgpu::TextureView,
    ) -> wgpu::RenderPass<'e> {
        // Load, not clear: each tile is cleared by its own triangle (clearing costs its area).
        fn load<V>() -> wgpu::Operations<V> {
            wgpu::Operations {
                load: wgpu::LoadOp::Load,
                store: wgpu::StoreOp::Store,
            }
        }
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("tiles"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: colour,
                depth_slice: None,
                resolve_target: None,
                ops: load(),
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
                depth_ops: Some(load()),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    fn read_back(&self, buffer: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, GpuError> {
        let slice = buffer.slice(..size);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .to_vec();
        buffer.unmap();
        Ok(bytes)
    }

    fn count_histogram(
        &self,
        arch: Arch,
        tiles: &[Tile],
        placement: &[atlas::Placement],
        draws: &[DrawRecord],
    ) -> Result<Vec<[u64; 9]>, GpuError> {
        let n_pages = placement.last().map_or(0, |p| p.page + 1);
        let records: Vec<TileRecord> = tiles
            .iter()
            .zip(placement)
            .enumerate()
            .map(|(slot, (tile, place))| TileRecord {
                atlas_x: place.x,
                atlas_y: place.y,
                width: tile.rect.width,
                height: tile.rect.height,
                mask_x: tile.rect.x0,
                mask_y: tile.rect.y0,
                layer: tile.camera as u32,
                arch_bit: arch.mask_bit() as u32,
                other_bit: arch.other().mask_bit() as u32,
                slot: slot as u32,
                _pad: [0; 2],
            })
            .collect();
        // Page p's tiles are contiguous (packing is in order): its first tile index.
        let mut page_params = vec![0u8; n_pages * PAGE_PARAMS_STRIDE as usize];
        for (i, p) in placement.iter().enumerate().rev() {
            page_params[p.page * PAGE_PARAMS_STRIDE as usize..][..4]
                .copy_from_slice(&(i as u32).to_le_bytes());
        }
        let mut guard = self.batch.lock().unwrap_or_else(|e| e.into_inner());
        let batch = self.batch_with_room(&mut guard, draws.len(), tiles.len(), n_pages);
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        queue.write_buffer(&batch.draws, 0, bytemuck::cast_slice(draws));
        queue.write_buffer(&batch.tiles, 0, bytemuck::cast_slice(&records));
        queue.write_buffer(&batch.pages, 0, &page_params);
        let counts_size = (tiles.len() * 9 * 4) as u64;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("energy"),
        });
        encoder.clear_buffer(&batch.counts, 0, Some(counts_size));
        for page in 0..n_pages {
            let on_page: Vec<usize> = (0..tiles.len())
                .filter(|&i| placement[i].page == page)
                .collect();
            {
                let mut pass = self.begin_pass(&mut encoder, &self.class_view);
                pass.set_bind_group(0, &batch.draw_group, &[]);
                for &i in &on_page {
                    self.set_tile(&mut pass, &tiles[i], &placement[i]);
                    pass.set_pipeline(&self.clear_pipeline);
                    pass.draw(0..3, 0..1);
                    pass.set_pipeline(&self.model_pipeline);
                    self.draw_arches(&mut pass, arch, (i * 3) as u32);
                }
            }
            let max_w = on_page
                .iter()
                .map(|&i| tiles[i].rect.width)
                .max()
                .unwrap_or(0);
            let max_h = on_page
                .iter()
                .map(|&i| tiles[i].rect.height)
                .max()
                .unwrap_or(0);
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("histogram"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.count_pipeline);
            pass.set_bind_group(
                0,
                &batch.count_group,
                &[(page as u64 * PAGE_PARAMS_STRIDE) as u32],
            );
            pass.dispatch_workgroups(
                max_w.div_ceil(HISTOGRAM_BLOCK),
                max_h.div_ceil(HISTOGRAM_BLOCK),
                on_page.len() as u32,
            );
        }
        encoder.copy_buffer_to_buffer(&batch.counts, 0, &batch.staging, 0, counts_size);
        queue.submit([encoder.finish()]);
        let bytes = self.read_back(&batch.staging, counts_size)?;
        Ok(bytemuck::cast_slice::<u8, u32>(&bytes)
            .chunks_exact(9)
            .map(|c| std::array::from_fn(|k| c[k] as u64))
            .collect())
    }

    /// The paper's architecture: per page, draw each tile in colour, copy every tile to the
    /// CPU whole, classify its pixels' colours on one thread.
    fn count_readback(
        &self,
        tiles: &[Tile],
        placement: &[atlas::Placement],
        draws: &[DrawRecord],
    ) -> Result<Vec<[u64; 9]>, GpuError> {
        let target = self
            .readback
            .as_ref()
            .expect("a readback engine has its colour target");
        let n_pages = placement.last().map_or(0, |p| p.page + 1);
        let row_bytes = |w: u32| (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let mut guard = self.batch.lock().unwrap_or_else(|e| e.into_inner());
        let batch = self.batch_with_room(&mut guard, draws.len(), tiles.len(), n_pages);
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        queue.write_buffer(&batch.draws, 0, bytemuck::cast_slice(draws));
        let mut out = vec![[0u64; 9]; tiles.len()];
        for page in 0..n_pages {
            let on_page: Vec<usize> = (0..tiles.len())
                .filter(|&i| placement[i].page == page)
                .collect();
            let offsets: Vec<u64> = on_page
                .iter()
                .scan(0u64, |acc, &i| {
                    let at = *acc;
                    *acc += row_bytes(tiles[i].rect.width) as u64 * tiles[i].rect.height as u64;
                    Some(at)
                })
                .collect();
            let total: u64 = on_page
                .iter()
                .map(|&i| row_bytes(tiles[i].rect.width) as u64 * tiles[i].rect.height as u64)
                .sum();
            let mut staging_slot = target.staging.lock().unwrap_or_else(|e| e.into_inner());
            if staging_slot.as_ref().is_none_or(|(_, cap)| *cap < total) {
                let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("colour readback"),
                    size: total,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                *staging_slot = Some((buffer, total));
            }
            let staging = &staging_slot.as_ref().expect("just made").0;
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
            {
                let mut pass = self.begin_pass(&mut encoder, &target.colour_view);
                pass.set_bind_group(0, &batch.draw_group, &[]);
                for &i in &on_page {
                    let first = (i * 3) as u32;
                    self.set_tile(&mut pass, &tiles[i], &placement[i]);
                    pass.set_pipeline(&target.clear);
                    pass.draw(0..3, 0..1);
                    pass.set_pipeline(&target.prepass);
                    self.draw_arches(&mut pass, tiles_arch(draws, first), first);
                    pass.set_pipeline(&target.mask);
                    pass.draw(0..3, first + 1..first + 2);
                    pass.set_pipeline(&target.colour_pass);
                    self.draw_arches(&mut pass, tiles_arch(draws, first), first);
                }
            }
            for (&i, &offset) in on_page.iter().zip(&offsets) {
                let (r, p) = (&tiles[i].rect, &placement[i]);
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        texture: &target.colour,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x: p.x,
                            y: p.y,
                            z: 0,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer: staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset,
                            bytes_per_row: Some(row_bytes(r.width)),
                            rows_per_image: Some(r.height),
                        },
                    },
                    wgpu::Extent3d {
                        width: r.width,
                        height: r.height,
                        depth_or_array_layers: 1,
                    },
                );
            }
            queue.submit([encoder.finish()]);
            let bytes = self.read_back(staging, total)?;
            for (&i, &offset) in on_page.iter().zip(&offsets) {
                let r = &tiles[i].rect;
                let stride = row_bytes(r.width) as usize;
                let bins = &mut out[i];
                for y in 0..r.height as usize {
                    let row = &bytes[offset as usize + y * stride..][..r.width as usize * 4];
                    for px in row.chunks_exact(4) {
                        bins[colour_bin(px)] += 1;
                    }
                }
            }
        }
        Ok(out)
    }
}

/// The scored arch of a tile, from its body draw's label bit.
fn tiles_arch(draws: &[DrawRecord], first: u32) -> Arch {
    if draws[first as usize + 1].arch_bit == Arch::Upper.mask_bit() as u32 {
        Arch::Upper
    } else {
        Arch::Lower
    }
}

/// The paper's colour counting, into the first six of the nine bins (the baseline cannot tell
/// the other arch's pixels from background): white = mask uncovered, pink = mask under the
/// body, light green = mask under the BOI, dark red = body off the mask, dark green = BOI off
/// the mask (the paper's #Pixel_DGreen), black = neither. Alpha 0.5 puts the halves at 127/128.
fn colour_bin(rgba: &[u8]) -> usize {
    let (r, g, b) = (rgba[0], rgba[1], rgba[2]);
    match (r >= 192, g >= 192, b >= 192) {
        (true, true, true) => 3,
        (true, false, _) => 4,
        (false, true, _) => 5,
        _ if r >= 64 => 1,
        _ if g >= 64 => 2,
        _ => 0,
    }
}

impl EnergyEngine for GpuEnergy {
    fn name(&self) -> String {
        format!("gpu {}, {}", self.ctx.describe(), self.region.name())
    }

    fn set_frame(&mut self, masks: &FrameMasks) -> Result<()> {
        for (layer, m) in masks.masks.iter().enumerate() {
            self.frame[layer] = m
                .as_ref()
                .map(|m| [mask_totals(m, Arch::Upper), mask_totals(m, Arch::Lower)]);
            let Some(m) = m else { continue };
            self.ctx.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.masks,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: layer as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                &m.data,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(m.width),
                    rows_per_image: Some(m.height),
                },
                wgpu::Extent3d {
                    width: m.width,
                    height: m.height,
                    depth_or_array_layers: 1,
                },
            );
        }
        Ok(())
    }

    fn evaluate(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>> {
        Ok(self.run_batch(arch, candidates)?)
    }
}
