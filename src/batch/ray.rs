//! A batch for Ray: the plan's command lines (`commands.json`) and a small Python driver
//! (`ray_batch.py`) that runs each as a Ray task, retried when it fails (its chunk resumes),
//! then the merges. The driver only calls the jawtrack binary.

use std::path::Path;

use serde::Serialize;

use super::Plan;
use crate::error::Result;
use crate::io::{write_atomic, write_json_atomic};

pub const DRIVER: &str = "ray_batch.py";
const DRIVER_SOURCE: &str = include_str!("ray_batch.py");

/// What the driver runs.
#[derive(Serialize)]
struct Commands<'a> {
    jawtrack: &'a Path,
    workdir: &'a Path,
    /// Per chunk, the arguments of jawtrack (as the job array's tasks).
    tasks: Vec<Vec<String>>,
    /// Per take, the arguments of its merge.
    merges: Vec<Vec<String>>,
}

/// Write `commands.json` and `ray_batch.py` for `plan` into `dir`.
pub fn write_driver(plan: &Plan, dir: &Path) -> Result<()> {
    write_json_atomic(
        &dir.join("commands.json"),
        &Commands {
            jawtrack: &plan.jawtrack,
            workdir: &plan.workdir,
            tasks: (0..plan.tasks().len()).map(|t| plan.task_args(t)).collect(),
            merges: (0..plan.takes.len()).map(|t| plan.merge_args(t)).collect(),
        },
    )?;
    write_atomic(&dir.join(DRIVER), DRIVER_SOURCE.as_bytes())
}
