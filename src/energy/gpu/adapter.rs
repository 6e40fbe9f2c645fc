//! Choosing a GPU adapter: `JAWTRACK_ADAPTER=substring` picks one by name; otherwise real GPUs
//! come before software ones. GL adapters are not used: on wgpu's GL backend (Mesa llvmpipe)
//! the hand-counted scene of tests/gpu_energy.rs draws the square off its place, so the engine
//! would disagree with the CPU reference without a word.

use super::GpuError;

/// The environment variable that picks an adapter by (case-insensitive) name substring.
pub const ADAPTER_ENV: &str = "JAWTRACK_ADAPTER";

pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// A software rasteriser (lavapipe/llvmpipe, WARP, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    /// Map `size` bytes of `buffer` and copy them out.
    pub fn read_back(&self, buffer: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, GpuError> {
        let slice = buffer.slice(..size);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
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
}

pub fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

fn rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let backend = match info.backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    };
    let kind = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    (kind, backend)
}

/// Open the best adapter (or the one `JAWTRACK_ADAPTER` names) and a device on it.
/// `WGPU_BACKEND` restricts the backends searched, as in wgpu.
pub fn open() -> Result<GpuContext, GpuError> {
    let wanted = std::env::var(ADAPTER_ENV).ok().filter(|s| !s.is_empty());
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let available: Vec<String> = adapters
        .iter()
        .map(|a| {
            let info = a.get_info();
            let unused = if info.backend == wgpu::Backend::Gl {
                " (GL: not used)"
            } else {
                ""
            };
            format!("{}{unused}", describe(&info))
        })
        .collect();
    adapters.retain(|a| a.get_info().backend != wgpu::Backend::Gl);
    if let Some(w) = &wanted {
        let w = w.to_lowercase();
        adapters.retain(|a| a.get_info().name.to_lowercase().contains(&w));
    }
    adapters.sort_by_key(|a| rank(&a.get_info()));
    let adapter = adapters
        .into_iter()
        .next()
        .ok_or_else(|| GpuError::NoAdapter {
            wanted: wanted.map(|w| format!("{ADAPTER_ENV}={w:?}")),
            available,
        })?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("jawtrack energy"),
        required_features: wgpu::Features::empty(),
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .map_err(|e| GpuError::Device(format!("{}: {e}", describe(&info))))?;
    Ok(GpuContext {
        device,
        queue,
        info,
    })
}
