//! A batch's records and buffers: three draws per tile (`DrawRecord`, `Draw` in
//! shaders/raster.wgsl) and a tile record for the histogram, in buffers that grow when a batch
//! needs more and are reused otherwise.

use bytemuck::{Pod, Zeroable};
use nalgebra::Matrix4;

use super::atlas;
use super::draw::viewport_size;
use super::mesh::GpuMesh;
use super::{GpuEnergy, Tile};
use crate::arch::{Arch, ArchPoses};
use crate::energy::BINS;
use crate::energy::lens::Lens;
use crate::energy::raster::{CLASS_BODY, CLASS_BOI, NEAR_MM};
use crate::geometry::Pose;

/// Uniform entries with dynamic offsets are 256 bytes apart.
pub const PAGE_PARAMS_STRIDE: u64 = 256;

/// `Draw` in shaders/raster.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct DrawRecord {
    pub camera_from_model: [[f32; 4]; 4],
    pub focal: [f32; 2],
    pub centre: [f32; 2],
    pub half_viewport: [f32; 2],
    pub near: f32,
    pub far: f32,
    pub class_id: u32,
    pub projected: u32,
    pub mask_offset: [i32; 2],
    pub layer: u32,
    pub arch_bit: u32,
    pub _pad: [u32; 2],
    /// The camera's lens ([`Lens::k`] in three fours), its limit (r²) and its model (0: none).
    pub lens: [[f32; 4]; 3],
    pub lens_limit_r2: f32,
    pub lens_model: u32,
    pub _pad2: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct TileRecord {
    pub atlas_x: u32,
    pub atlas_y: u32,
    pub width: u32,
    pub height: u32,
    pub mask_x: u32,
    pub mask_y: u32,
    pub layer: u32,
    pub arch_bit: u32,
    pub other_bit: u32,
    pub slot: u32,
    pub _pad: [u32; 2],
}

/// Per-batch buffers, grown on demand, and the bind groups over them.
pub struct Batch {
    pub draws: wgpu::Buffer,
    pub tiles: wgpu::Buffer,
    pub pages: wgpu::Buffer,
    pub counts: wgpu::Buffer,
    pub staging: wgpu::Buffer,
    pub draw_group: wgpu::BindGroup,
    pub count_group: wgpu::BindGroup,
    /// Capacities: draws, tiles, pages.
    pub capacity: (usize, usize, usize),
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

impl GpuEnergy {
    /// The batch buffers with room for the given counts (grown, never shrunk).
    pub(super) fn batch_with_room<'a>(
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
        let counts_size = (capacity.1 * BINS * 4) as u64;
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
            layout: &self.pipelines.draw_layout,
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
            layout: &self.pipelines.count_layout,
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

    /// Three draws per tile, in drawing order: the other arch, the scored arch's body, its BOI.
    pub(super) fn draw_records(
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
                    lens: lens.map_or([[0.0; 4]; 3], |l| {
                        [0, 4, 8].map(|i| [l.k[i], l.k[i + 1], l.k[i + 2], l.k[i + 3]])
                    }),
                    lens_limit_r2: lens.map_or(0.0, |l| l.limit_r2),
                    lens_model: lens.map_or(0, |l| l.model),
                    _pad2: [0; 2],
                }
            };
            draws.push(record(arch.other(), other, other_class));
            draws.push(record(arch, scored, CLASS_BODY));
            draws.push(record(arch, scored, CLASS_BOI));
        }
        draws
    }
}
