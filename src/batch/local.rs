//! A batch run on this machine: the plan's tasks as processes, a few at a time, then the
//! merges; what a workstation does without a cluster (or a Ray worker with one node).

use std::collections::VecDeque;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Instant;

use super::Plan;
use crate::error::{Error, Result};

/// What happened, as it happens.
#[derive(Debug, Clone)]
pub enum Event {
    Started { task: usize },
    Finished { task: usize, ok: bool, seconds: f64 },
    Merged { take: usize, ok: bool, seconds: f64 },
}

/// How a local run went.
#[derive(Debug, Clone)]
pub struct LocalReport {
    /// The tasks run (the others were finished already).
    pub tasks: Vec<usize>,
    pub track_seconds: f64,
    pub merge_seconds: f64,
}

/// Run the unfinished tasks of `plan` with `jawtrack`, `parallel` at a time, each with an
/// equal share of the cores for its energy's threads (unless RAYON_NUM_THREADS says), then
/// each take's merge. Output goes to `dir/logs/`. A failed task is an error naming its log,
/// after the others have run; the merges run only when every task succeeded.
pub fn run(
    plan: &Plan,
    dir: &Path,
    jawtrack: &Path,
    parallel: usize,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<LocalReport> {
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(|error| Error::Write {
        path: logs.clone(),
        error,
    })?;
    let tasks = plan.unfinished();
    let parallel = parallel.clamp(1, tasks.len().max(1));
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = std::env::var("RAYON_NUM_THREADS")
        .unwrap_or_else(|_| (cores / parallel).max(1).to_string());
    let queue = Mutex::new(tasks.iter().copied().collect::<VecDeque<_>>());
    let failures = Mutex::new(Vec::new());
    let started = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..parallel {
            s.spawn(|| {
                loop {
                    let Some(task) = queue.lock().expect("no panic holds it").pop_front() else {
                        break;
                    };
                    on_event(Event::Started { task });
                    let t0 = Instant::now();
                    let log = logs.join(format!("track-{task}.log"));
                    let result = run_logged(jawtrack, &plan.task_args(task), plan, &log, &threads);
                    on_event(Event::Finished {
                        task,
                        ok: result.is_ok(),
                        seconds: t0.elapsed().as_secs_f64(),
                    });
                    if let Err(e) = result {
                        failures.lock().expect("no panic holds it").push(e);
                    }
                }
            });
        }
    });
    let track_seconds = started.elapsed().as_secs_f64();
    if let Some(first) = failures
        .into_inner()
        .expect("no panic holds it")
        .into_iter()
        .next()
    {
        return Err(first);
    }
    let started = Instant::now();
    for take in 0..plan.takes.len() {
        let t0 = Instant::now();
        let log = logs.join(format!("merge-{take}.log"));
        let result = run_logged(
            jawtrack,
            &plan.merge_args(take),
            plan,
            &log,
            &cores.to_string(),
        );
        on_event(Event::Merged {
            take,
            ok: result.is_ok(),
            seconds: t0.elapsed().as_secs_f64(),
        });
        result?;
    }
    Ok(LocalReport {
        tasks,
        track_seconds,
        merge_seconds: started.elapsed().as_secs_f64(),
    })
}

/// Run `jawtrack args` in the plan's folder, its output appended to `log`.
fn run_logged(
    jawtrack: &Path,
    args: &[String],
    plan: &Plan,
    log: &Path,
    threads: &str,
) -> Result<()> {
    let werr = |error| Error::Write {
        path: log.to_path_buf(),
        error,
    };
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .map_err(werr)?;
    let failed = |problem: String| Error::Command {
        path: log.to_path_buf(),
        program: format!("jawtrack {}", args.first().map_or("", String::as_str)),
        problem,
    };
    let status = Command::new(jawtrack)
        .args(args)
        .current_dir(&plan.workdir)
        .env("RAYON_NUM_THREADS", threads)
        .stdin(Stdio::null())
        .stdout(file.try_clone().map_err(werr)?)
        .stderr(file)
        .status()
        .map_err(|e| failed(format!("cannot start {} ({e})", jawtrack.display())))?;
    if status.success() {
        Ok(())
    } else {
        Err(failed(format!("{status}; its output is in this log")))
    }
}
