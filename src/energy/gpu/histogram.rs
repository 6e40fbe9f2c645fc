//! The engine's counting: per atlas page, the tiles' class pass, then the compute histogram
//! (shaders/histogram.wgsl, whose CPU twin is src/energy/histogram.rs) bins every tile's
//! pixels; one submission and one readback per batch.

use super::atlas;
use super::batch::{DrawRecord, PAGE_PARAMS_STRIDE, TileRecord};
use super::{GpuEnergy, Tile};
use crate::arch::Arch;
use crate::energy::BINS;
use crate::error::GpuError;

/// Pixels per workgroup side in shaders/histogram.wgsl.
const HISTOGRAM_BLOCK: u32 = 32;

impl GpuEnergy {
    pub(super) fn count_histogram(
        &self,
        arch: Arch,
        tiles: &[Tile],
        placement: &[atlas::Placement],
        draws: &[DrawRecord],
    ) -> Result<Vec<[u64; BINS]>, GpuError> {
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
        let counts_size = (tiles.len() * BINS * 4) as u64;
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
                    pass.set_pipeline(&self.pipelines.clear);
                    pass.draw(0..3, 0..1);
                    pass.set_pipeline(&self.pipelines.model);
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
            pass.set_pipeline(&self.pipelines.count);
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
        let bytes = self.ctx.read_back(&batch.staging, counts_size)?;
        Ok(bytemuck::cast_slice::<u8, u32>(&bytes)
            .chunks_exact(BINS)
            .map(|c| std::array::from_fn(|k| c[k] as u64))
            .collect())
    }
}
