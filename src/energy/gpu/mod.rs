//! The energy on the GPU (wgpu, headless): each candidate's arch is rasterised into a tile of a
//! class atlas (render pass, Vulkan rasterisation rules like the CPU twin), and a compute
//! histogram counts the six bins of every tile; one submission and one readback per batch.
//!
//! Everything is created once in [`GpuEnergy::new`]: pipelines, layouts, the meshes' vertex
//! and index buffers, the atlas and the mask texture; per-batch buffers grow when a batch needs
//! more and are reused otherwise. Masks are uploaded once per frame in `set_frame`.

mod adapter;
mod atlas;
mod batch;
mod draw;
mod edge_terms;
mod histogram;
mod mesh;
mod pipelines;
mod readback;

use std::sync::Mutex;

pub use crate::error::GpuError;
pub use adapter::{ADAPTER_ENV, GpuContext};

use atlas::{MAX_TILES_PER_PAGE, PAGE};
use batch::Batch;
use edge_terms::EdgeStage;
use mesh::GpuMesh;
use pipelines::{CLASS_FORMAT, DEPTH_FORMAT, Pipelines};
use readback::ReadbackTarget;

use super::edge_terms::{EdgeQuery, EdgeTerm};
use super::lens::Lens;
use super::pyramid;
use super::raster::{self, Rect};
use super::{
    BINS, Counts, Energy, EnergyEngine, MaskTotals, Region, Scene, counts_with_outside,
    frame_totals,
};
use crate::arch::{Arch, ArchPoses, PerArch};
use crate::capture::{FrameMasks, LabelMask};
use crate::error::Result;
use crate::geometry::Camera;

/// How the counts are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Counting {
    /// The compute-shader histogram (the engine).
    Histogram,
    /// The paper's architecture, as a baseline: a colour image per camera (mask white, model
    /// red at alpha 0.5, BOI green), read back whole and counted on one CPU thread.
    Readback,
}

pub struct GpuEnergy {
    ctx: GpuContext,
    scene: Scene,
    region: Region,
    meshes: [GpuMesh; 2],
    pipelines: Pipelines,
    /// The paper's colour target when this is the readback baseline; `None`: the histogram.
    readback: Option<ReadbackTarget>,
    class_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    masks: wgpu::Texture,
    masks_view: wgpu::TextureView,
    /// Per layer of `masks`: how much of each pixel each arch's teeth hold (r upper, g lower),
    /// the labels' own 0 or 1 where a mask has no soft evidence; the smooth energy reads it.
    evidence: wgpu::Texture,
    evidence_view: wgpu::TextureView,
    /// Per camera: the frame's mask totals per scored arch (upper, lower; see
    /// `mask_totals`), or `None` without a mask.
    frame: Vec<Option<PerArch<MaskTotals>>>,
    /// Per layer of `masks` (a camera at a level of the pyramid): the frame's mask size, or
    /// `None` without a mask.
    mask_sizes: Vec<Option<(u32, u32)>>,
    batch: Mutex<Option<Batch>>,
    /// The smooth energy's edge terms (shaders/edge_terms.wgsl).
    edges: EdgeStage,
}

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
        let pipelines = Pipelines::new(device);
        let readback =
            (counting == Counting::Readback).then(|| ReadbackTarget::new(device, &pipelines));
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
        // Each camera's mask at every level of the pyramid: level l of camera k in layer
        // l·n + k, so that the counts read the masks themselves in layers 0..n.
        let layers = (scene.cameras.len().max(1) * (pyramid::MAX_LEVEL + 1)) as u32;
        let masks = texture(
            "masks",
            wgpu::TextureFormat::R8Uint,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            (mask_w, mask_h, layers),
        );
        let array = wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        };
        let masks_view = masks.create_view(&array);
        let evidence = texture(
            "evidence",
            wgpu::TextureFormat::Rg8Unorm,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            (mask_w, mask_h, layers),
        );
        let evidence_view = evidence.create_view(&array);
        let meshes = [
            GpuMesh::new(device, &scene.upper, "upper"),
            GpuMesh::new(device, &scene.lower, "lower"),
        ];
        Ok(GpuEnergy {
            readback,
            frame: vec![None; scene.cameras.len()],
            mask_sizes: vec![None; scene.cameras.len() * (pyramid::MAX_LEVEL + 1)],
            edges: EdgeStage::new(device),
            class_view: class.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            masks,
            masks_view,
            evidence,
            evidence_view,
            meshes,
            pipelines,
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
    fn totals(&self, frame: &PerArch<MaskTotals>, arch: Arch) -> MaskTotals {
        let t = *frame.get(arch);
        match self.readback {
            None => t,
            Some(_) => MaskTotals { other: 0, ..t },
        }
    }

    fn mesh(&self, arch: Arch) -> &GpuMesh {
        &self.meshes[arch.index()]
    }
}

/// One tile of a batch: a candidate seen by a camera, over `rect` of that camera's mask.
struct Tile {
    candidate: usize,
    camera: usize,
    rect: Rect,
}

impl GpuEnergy {
    /// Upload a mask into its layer of the masks texture, and its evidence into the
    /// evidence texture's.
    fn write_mask(&self, layer: usize, m: &LabelMask) {
        let evidence: Vec<u8> = match &m.soft {
            Some(soft) => soft.iter().flatten().copied().collect(),
            None => m
                .data
                .iter()
                .flat_map(|&v| Arch::BOTH.map(|a| if v & a.mask_bit() != 0 { 255 } else { 0 }))
                .collect(),
        };
        self.write_layer(&self.masks, layer, m, &m.data, 1);
        self.write_layer(&self.evidence, layer, m, &evidence, 2);
    }

    /// `data` (`bytes` a pixel, `m`'s size) into `layer` of `texture`.
    fn write_layer(
        &self,
        texture: &wgpu::Texture,
        layer: usize,
        m: &LabelMask,
        data: &[u8],
        bytes: u32,
    ) {
        self.ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: layer as u32,
                },
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(bytes * m.width),
                rows_per_image: Some(m.height),
            },
            wgpu::Extent3d {
                width: m.width,
                height: m.height,
                depth_or_array_layers: 1,
            },
        );
    }

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
                    e.cameras[k] = counts_with_outside([0; BINS], cam, self.totals(t, arch));
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
    ) -> Result<Vec<[u64; BINS]>, GpuError> {
        let sizes: Vec<(u32, u32)> = tiles
            .iter()
            .map(|t| (t.rect.width, t.rect.height))
            .collect();
        let placement = atlas::pack(&sizes, PAGE, MAX_TILES_PER_PAGE);
        let draws = self.draw_records(arch, candidates, tiles, &placement);
        match &self.readback {
            None => self.count_histogram(arch, tiles, &placement, &draws),
            Some(target) => self.count_readback(target, tiles, &placement, &draws),
        }
    }
}

impl EnergyEngine for GpuEnergy {
    fn name(&self) -> String {
        format!("gpu {}, {}", self.ctx.describe(), self.region.name())
    }

    fn set_frame(&mut self, masks: &FrameMasks) -> Result<()> {
        let n = self.frame.len();
        for (k, m) in masks.masks.iter().enumerate() {
            self.frame[k] = m.as_ref().map(frame_totals);
            for level in 0..=pyramid::MAX_LEVEL {
                let layer = level * n + k;
                let Some(m) = m else {
                    self.mask_sizes[layer] = None;
                    continue;
                };
                let reduced;
                let m = if level == 0 {
                    m
                } else {
                    reduced = pyramid::mask(m, level);
                    &reduced
                };
                self.mask_sizes[layer] = Some((m.width, m.height));
                self.write_mask(layer, m);
            }
        }
        Ok(())
    }

    fn evaluate(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>> {
        Ok(self.run_batch(arch, candidates)?)
    }

    fn edge_terms(&self, q: &EdgeQuery) -> Result<Vec<Option<EdgeTerm>>> {
        Ok(self.run_edge_terms(q)?)
    }
}
