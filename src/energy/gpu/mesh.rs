//! The arches on the GPU.

use wgpu::util::DeviceExt;

use crate::mesh::Mesh;

/// An arch on the GPU: body triangles first, then BOI triangles, in one index buffer.
pub struct GpuMesh {
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub body_indices: u32,
    pub boi_indices: u32,
    /// Corners of the model-space bounding box, for conservative footprints.
    pub corners: [[f32; 3]; 8],
    pub radius: f64,
}

impl GpuMesh {
    pub fn new(device: &wgpu::Device, mesh: &Mesh, label: &str) -> GpuMesh {
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
