use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Parser;
use jawtrack::batch::slurm::{self, Resources};
use jawtrack::batch::{Plan, TakeFrames, local, ray};
use jawtrack::capture::MaskMode;

use super::track::TrackingArgs;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Plan a study as a Slurm job array (a task per chunk of frames, then a merge job per
    /// run) into DIR: plan.json, track.sbatch, merge.sbatch; with --submit, submit them.
    Slurm(SlurmArgs),
    /// Plan a study as `batch slurm` does, for Ray: commands.json and ray_batch.py, a driver
    /// that runs each chunk as a Ray task (`python3 DIR/ray_batch.py DIR [--address auto]`).
    Ray(PlanArgs),
    /// Submit the tasks of DIR not yet finished, and the merge job after them.
    Submit {
        /// The batch folder (`batch slurm`'s -o).
        dir: PathBuf,
    },
    /// Plan a study as `batch slurm` does and run it on this machine, TASKS chunks at a time.
    Local(LocalArgs),
    /// Run the unfinished tasks of a planned batch on this machine, then the merges.
    Run {
        /// The batch folder.
        dir: PathBuf,
        /// Chunks tracked at once.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1024))]
        tasks: u32,
    },
    /// What a batch has done: frames per chunk, the merged runs, the jobs submitted.
    Status {
        /// The batch folder.
        dir: PathBuf,
    },
}

/// A study cut into chunks.
#[derive(clap::Args)]
pub struct PlanArgs {
    /// The captures (takes) to track.
    #[arg(required = true)]
    pub captures: Vec<PathBuf>,
    /// The batch folder to write (must not hold a batch already): plan.json, logs/, and per
    /// capture its chunks (parts/) and the merged tracks.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frames per chunk: a task's work.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub chunk_frames: u32,
    /// Frames each chunk also tracks before its own, to check that it agrees with the chunk
    /// before it (`merge`); half of them are compared.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub overlap: u32,
    /// Tracking options for every chunk and merge, as `track` takes them (e.g. `--search
    /// gauss-newton --settings s.json`), after `--`.
    #[arg(last = true, allow_hyphen_values = true)]
    pub track_options: Vec<String>,
}

#[derive(clap::Args)]
pub struct SlurmArgs {
    #[command(flatten)]
    pub plan: PlanArgs,
    /// The Slurm partition (default: the cluster's).
    #[arg(long)]
    pub partition: Option<String>,
    /// Each task's wall-clock limit, as Slurm writes it (`HH:MM:SS`, `D-HH`, minutes).
    #[arg(long)]
    pub time: Option<String>,
    /// Cores per task (its energy's threads).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub cpus: u32,
    /// GPUs per task (`--gres=gpu:G`); 0 tracks on the CPU reference.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=64))]
    pub gpus: u32,
    /// Submit the jobs with sbatch once written.
    #[arg(long)]
    pub submit: bool,
}

#[derive(clap::Args)]
pub struct LocalArgs {
    #[command(flatten)]
    pub plan: PlanArgs,
    /// Chunks tracked at once.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub tasks: u32,
}

/// The tracking options a batch passes on, parsed as `track` parses them.
#[derive(Parser)]
#[command(name = "jawtrack track")]
struct TrackOptions {
    #[command(flatten)]
    how: TrackingArgs,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Slurm(a) => {
            let (plan, dir) = make_plan(&a.plan)?;
            let resources = Resources {
                partition: a.partition,
                time: a.time,
                cpus: a.cpus,
                gpus: a.gpus,
            };
            slurm::write_scripts(&plan, &dir, &resources)?;
            plan.save(&dir)?;
            println!(
                "{} tasks over {} runs -> {}",
                plan.tasks().len(),
                plan.takes.len(),
                dir.display()
            );
            if a.submit {
                submit(&plan, &dir)?;
            } else {
                println!("submit with: jawtrack batch submit {}", dir.display());
            }
            Ok(())
        }
        Command::Ray(a) => {
            let (plan, dir) = make_plan(&a)?;
            ray::write_driver(&plan, &dir)?;
            plan.save(&dir)?;
            println!(
                "{} tasks over {} runs -> {}\nrun with: python3 {} {} [--address auto] [--cpus C] [--gpus G] (Python with `pip install ray`)",
                plan.tasks().len(),
                plan.takes.len(),
                dir.display(),
                dir.join(ray::DRIVER).display(),
                dir.display()
            );
            Ok(())
        }
        Command::Submit { dir } => {
            let plan = Plan::load(&dir)?;
            submit(&plan, &dir)
        }
        Command::Local(a) => {
            let (plan, dir) = make_plan(&a.plan)?;
            plan.save(&dir)?;
            run_here(&plan, &dir, a.tasks)
        }
        Command::Run { dir, tasks } => {
            let plan = Plan::load(&dir)?;
            run_here(&plan, &dir, tasks)
        }
        Command::Status { dir } => status(&dir),
    }
}

/// The plan `a` asks for, its folder made; the captures opened and the options checked first,
/// so that no task fails on them.
fn make_plan(a: &PlanArgs) -> anyhow::Result<(Plan, PathBuf)> {
    let dir = std::path::absolute(&a.output)
        .with_context(|| format!("{}: not a usable path", a.output.display()))?;
    if dir.join("plan.json").exists() {
        bail!(
            "{} holds a batch already: `jawtrack batch status` shows it, `batch submit` or `batch \
             run` goes on with it; plan a new one into another folder",
            dir.display()
        );
    }
    let options = TrackOptions::try_parse_from(
        std::iter::once("jawtrack track".to_string()).chain(a.track_options.iter().cloned()),
    )
    .map_err(|e| anyhow::anyhow!("the tracking options after `--`: {e}"))?;
    options.how.settings()?;
    let mut takes = Vec::new();
    for path in &a.captures {
        let capture = options.how.open(path)?;
        let frames = capture.frames();
        if matches!(capture.mask_mode(), MaskMode::Combined)
            && frames.len() > a.chunk_frames as usize
        {
            bail!(
                "{}: combined masks (one label for both arches): a chunk after the first cannot \
                 find its first poses from them; track this capture in one chunk (--chunk-frames \
                 {} or more)",
                path.display(),
                frames.len()
            );
        }
        takes.push(TakeFrames {
            capture: std::path::absolute(path)
                .with_context(|| format!("{}: not a usable path", path.display()))?,
            frames,
        });
    }
    let workdir = std::env::current_dir().context("the current folder")?;
    let jawtrack = std::env::current_exe().context("finding this jawtrack binary")?;
    let plan = Plan::new(
        &takes,
        a.chunk_frames,
        a.overlap,
        &dir,
        jawtrack,
        workdir,
        a.track_options.clone(),
    )?;
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok((plan, dir))
}

fn submit(plan: &Plan, dir: &Path) -> anyhow::Result<()> {
    let s = slurm::submit(plan, dir)?;
    match &s.array_job {
        Some(id) => println!(
            "submitted job array {id} ({} of {} tasks not yet finished) and merge job {} after it",
            s.tasks.len(),
            plan.tasks().len(),
            s.merge_job
        ),
        None => println!(
            "every chunk is finished: submitted merge job {}",
            s.merge_job
        ),
    }
    println!(
        "follow it with: jawtrack batch status {} (logs in {})",
        dir.display(),
        dir.join("logs").display()
    );
    Ok(())
}

fn run_here(plan: &Plan, dir: &Path, tasks: u32) -> anyhow::Result<()> {
    let jawtrack = std::env::current_exe().context("finding this jawtrack binary")?;
    let on_event = |e: local::Event| match e {
        local::Event::Started { task } => eprintln!("task {task} started"),
        local::Event::Finished { task, ok, seconds } => eprintln!(
            "task {task} {} after {seconds:.1} s",
            if ok { "finished" } else { "FAILED" }
        ),
        local::Event::Merged { take, ok, seconds } => eprintln!(
            "{}: merge {} after {seconds:.1} s",
            plan.takes[take].output.display(),
            if ok { "done" } else { "FAILED" }
        ),
    };
    let report = local::run(plan, dir, &jawtrack, tasks as usize, &on_event)?;
    let frames: usize = plan
        .takes
        .iter()
        .map(|t| t.chunks.iter().map(|c| c.frames.len()).sum::<usize>())
        .sum();
    println!(
        "{} tasks ({} to run, {} at a time) in {:.1} s, merged in {:.1} s",
        plan.tasks().len(),
        report.tasks.len(),
        tasks,
        report.track_seconds,
        report.merge_seconds
    );
    println!(
        "{frames} frames tracked, overlaps included: {:.3} s a frame of wall-clock time",
        (report.track_seconds + report.merge_seconds) / frames.max(1) as f64
    );
    for take in &plan.takes {
        println!("  {}", take.output.display());
    }
    Ok(())
}

fn status(dir: &Path) -> anyhow::Result<()> {
    let plan = Plan::load(dir)?;
    let progress = plan.progress();
    let mut task = 0;
    let mut unfinished = Vec::new();
    for take in &plan.takes {
        let mine = &progress[task..task + take.chunks.len()];
        let done = mine.iter().filter(|p| p.finished).count();
        let merged = take.output.exists() && done == mine.len();
        println!(
            "{}: {done} of {} chunks finished, {} of {} frames{}",
            take.capture.display(),
            mine.len(),
            mine.iter().map(|p| p.frames_done).sum::<usize>(),
            mine.iter().map(|p| p.frames).sum::<usize>(),
            if merged {
                format!(", merged -> {}", take.output.display())
            } else {
                String::new()
            }
        );
        for (k, (p, chunk)) in mine.iter().zip(&take.chunks).enumerate() {
            if !p.finished {
                println!(
                    "  task {} (frames {}..{}): {} of {} frames",
                    task + k,
                    chunk.frames.start,
                    chunk.frames.end,
                    p.frames_done,
                    p.frames
                );
                unfinished.push(task + k);
            }
        }
        task += take.chunks.len();
    }
    for s in slurm::submissions(dir)? {
        println!(
            "submitted: job array {} ({} tasks), merge job {}",
            s.array_job.as_deref().unwrap_or("-"),
            s.tasks.len(),
            s.merge_job
        );
    }
    if unfinished.is_empty() {
        println!("every chunk is finished");
    } else {
        println!(
            "{} tasks unfinished: `jawtrack batch submit {}` (Slurm) or `jawtrack batch run {}` runs them",
            unfinished.len(),
            dir.display(),
            dir.display()
        );
    }
    Ok(())
}
