//! Choosing an energy backend: `auto`, `gpu`, `cpu` or `readback` (the paper's architecture,
//! for comparison).

use super::gpu::{GpuEnergy, GpuError};
use super::{CpuEnergy, EnergyEngine, Region, Scene};
use crate::error::Result;

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Backend {
    /// A hardware GPU adapter when there is one; the CPU reference otherwise, and also when the
    /// only adapter is a software rasteriser (slower than the CPU reference: see README).
    #[default]
    Auto,
    /// The GPU engine (any adapter, software ones included; `JAWTRACK_ADAPTER` picks one).
    Gpu,
    /// The CPU reference.
    Cpu,
    /// The paper's architecture on the GPU: colour image read back and counted on the CPU.
    Readback,
}

/// An opened engine and a line saying what was chosen and why.
pub struct OpenedEngine {
    pub engine: Box<dyn EnergyEngine>,
    pub choice: String,
}

pub fn open_engine(backend: Backend, scene: Scene, region: Region) -> Result<OpenedEngine> {
    let cpu = |scene, why: String| -> OpenedEngine {
        let engine = CpuEnergy::with_region(scene, region);
        OpenedEngine {
            choice: format!("{}{why}", engine.name()),
            engine: Box::new(engine),
        }
    };
    Ok(match backend {
        Backend::Cpu => cpu(scene, String::new()),
        Backend::Gpu => {
            let e = GpuEnergy::new(scene, region)?;
            OpenedEngine {
                choice: e.name(),
                engine: Box::new(e),
            }
        }
        Backend::Readback => {
            let e = GpuEnergy::readback_baseline(scene)?;
            OpenedEngine {
                choice: format!("readback baseline on {}", e.context().describe()),
                engine: Box::new(e),
            }
        }
        Backend::Auto => match GpuEnergy::new(scene.clone(), region) {
            Ok(e) if !e.context().is_software() => OpenedEngine {
                choice: format!("{} (auto)", e.name()),
                engine: Box::new(e),
            },
            Ok(e) => cpu(
                scene,
                format!(
                    " (auto: the only adapter, {}, is a software rasteriser, slower than the CPU reference; --backend gpu uses it anyway)",
                    e.context().describe()
                ),
            ),
            Err(e @ GpuError::NoAdapter { .. }) => cpu(scene, format!(" (auto: {e})")),
            Err(e) => return Err(e.into()),
        },
    })
}
