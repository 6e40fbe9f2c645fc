//! Drawing a tile: its viewport and scissor in the atlas, the three model draws, the render
//! pass over the atlas (loaded, not cleared: each tile clears itself).

use super::atlas;
use super::{GpuEnergy, Tile};
use crate::arch::Arch;
use crate::geometry::Camera;

/// The viewport a camera's tiles are drawn with: the image's size rounded up to powers of two
/// (exact arithmetic in the shader's snapping; see shaders/raster.wgsl).
pub fn viewport_size(cam: &Camera) -> (u32, u32) {
    (
        cam.width.next_power_of_two(),
        cam.height.next_power_of_two(),
    )
}

impl GpuEnergy {
    /// Viewport and scissor of a tile: the whole image's viewport, shifted so that the tile's
    /// region of the image lands on its place in the atlas; the scissor keeps drawing inside.
    pub(super) fn set_tile(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        tile: &Tile,
        place: &atlas::Placement,
    ) {
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
    pub(super) fn draw_arches(&self, pass: &mut wgpu::RenderPass<'_>, arch: Arch, first: u32) {
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

    pub(super) fn begin_pass<'e>(
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
}
