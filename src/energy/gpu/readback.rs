//! The paper's architecture, as a baseline: per page, each tile drawn in colour (mask white,
//! model red at alpha 0.5, BOI green; shaders/readback.wgsl), copied to the CPU whole and its
//! pixels' colours classified on one thread.

use std::sync::Mutex;

use super::GpuEnergy;
use super::Tile;
use super::atlas;
use super::atlas::PAGE;
use super::batch::DrawRecord;
use super::pipelines::{COLOUR_FORMAT, PipelineSpec, Pipelines, raster_module};
use crate::arch::Arch;
use crate::energy::{BINS, MASK_MOUTH, MASK_NONE, MASK_OWN};
use crate::error::GpuError;

/// The readback baseline's colour target, pipelines and staging buffer.
pub struct ReadbackTarget {
    colour: wgpu::Texture,
    colour_view: wgpu::TextureView,
    clear: wgpu::RenderPipeline,
    prepass: wgpu::RenderPipeline,
    mask: wgpu::RenderPipeline,
    colour_pass: wgpu::RenderPipeline,
    staging: Mutex<Option<(wgpu::Buffer, u64)>>,
}

impl ReadbackTarget {
    pub fn new(device: &wgpu::Device, pipelines: &Pipelines) -> ReadbackTarget {
        use wgpu::CompareFunction::{Always, Equal, Less};
        let module = raster_module(device, Some(include_str!("../../../shaders/readback.wgsl")));
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
            clear: pipelines.render(
                device,
                &module,
                colour_spec("clear colour", "vs_clear", "fs_clear_colour", Always, true),
            ),
            prepass: pipelines.render(
                device,
                &module,
                PipelineSpec {
                    write_mask: wgpu::ColorWrites::empty(),
                    ..colour_spec("depth pre-pass", "vs_model", "fs_clear_colour", Less, true)
                },
            ),
            mask: pipelines.render(
                device,
                &module,
                colour_spec("mask", "vs_clear", "fs_mask", Always, false),
            ),
            colour_pass: pipelines.render(
                device,
                &module,
                colour_spec("model colour", "vs_model", "fs_colour", Equal, false),
            ),
            staging: Mutex::new(None),
        }
    }
}

impl GpuEnergy {
    /// The paper's architecture: per page, draw each tile in colour, copy every tile to the
    /// CPU whole, classify its pixels' colours on one thread.
    pub(super) fn count_readback(
        &self,
        target: &ReadbackTarget,
        tiles: &[Tile],
        placement: &[atlas::Placement],
        draws: &[DrawRecord],
    ) -> Result<Vec<[u64; BINS]>, GpuError> {
        let n_pages = placement.last().map_or(0, |p| p.page + 1);
        let row_bytes = |w: u32| (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let mut guard = self.batch.lock().unwrap_or_else(|e| e.into_inner());
        let batch = self.batch_with_room(&mut guard, draws.len(), tiles.len(), n_pages);
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        queue.write_buffer(&batch.draws, 0, bytemuck::cast_slice(draws));
        let mut out = vec![[0u64; BINS]; tiles.len()];
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
            let bytes = self.ctx.read_back(staging, total)?;
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

/// The paper's colour counting (the baseline cannot tell the other arch's pixels from
/// background): white = mask uncovered, pink = mask under the body, light green = mask under
/// the BOI, dark red = body off the mask, dark green = BOI off the mask (the paper's
/// #Pixel_DGreen), black = neither; and blue for the mouth interior, uncovered, under the
/// body (purple) or under the BOI (teal). Alpha 0.5 puts the halves at 127/128.
fn colour_bin(rgba: &[u8]) -> usize {
    let (r, g, b) = (rgba[0] >= 64, rgba[1] >= 64, rgba[2] >= 64);
    let (full_r, full_g, full_b) = (rgba[0] >= 192, rgba[1] >= 192, rgba[2] >= 192);
    let (state, class) = if full_r && full_g {
        (MASK_OWN, 0)
    } else if full_r {
        (MASK_OWN, 1)
    } else if full_g {
        (MASK_OWN, 2)
    } else if full_b {
        (MASK_MOUTH, 0)
    } else {
        let state = if b { MASK_MOUTH } else { MASK_NONE };
        (
            state,
            if r {
                1
            } else if g {
                2
            } else {
                0
            },
        )
    };
    state * 3 + class
}
