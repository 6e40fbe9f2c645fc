//! clap commands, one file each (`args`: what they share; `report`: what they print;
//! `run`: their long steps with progress): the only place that prints or uses anyhow or clap.

mod args;
mod batch;
mod bench;
mod demo;
mod energy;
mod envelope;
mod export;
mod import;
mod merge;
mod mesh;
mod report;
mod rig;
mod run;
mod score;
mod segment;
mod skin;
mod sync;
mod synth;
mod track;
mod validate;
mod view;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Track the teeth in multi-camera video and learn how the jaw moves.
#[derive(Parser)]
#[command(name = "jawtrack", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Synthesise a realistic capture, check it and show its energy (no arguments needed).
    Demo(demo::Args),
    /// Write a synthetic capture with ground truth.
    Synth(synth::Args),
    /// Bring footage into a capture: cameras from calibration tools, frames from videos.
    #[command(subcommand)]
    Import(import::Command),
    /// Per-camera frame offsets from a light switched off and on, into frames.offsets.
    Sync(sync::Args),
    /// Check a capture and print a summary, or what is wrong.
    Validate(validate::Args),
    /// Make the masks from the colour frames while tracking (writes masks/ and tracks.json).
    Segment(segment::Args),
    /// Track both arches through a capture and write tracks.json.
    Track(track::Args),
    /// Join chunks of a take tracked apart (`track --frames A..B`) into one tracks.json.
    Merge(merge::Args),
    /// A study on a cluster: takes cut into chunks, as a Slurm job array or processes here.
    #[command(subcommand)]
    Batch(batch::Command),
    /// Score a tracks.json against the capture's ground truth.
    Score(score::Args),
    /// Print the energy terms of a frame per camera and arch.
    Energy(energy::Args),
    /// Tracked motion out: glTF (Blender, Maya) and CSV (degrees and mm at the incisal point).
    Export(export::Args),
    /// Learn the three-parameter jaw rig from jaw poses, and use it.
    #[command(subcommand)]
    Rig(rig::Command),
    /// The rig for animators in the browser: sliders, drag IK, keyframes, the tracked timeline.
    View(view::Args),
    /// The empirical jaw rig on Posselt's envelope (Zoss et al. 2018).
    #[command(subcommand)]
    Envelope(envelope::Command),
    /// The jaw from the skin (Zoss et al. 2019): learn, retarget, predict, evaluate.
    #[command(subcommand)]
    Skin(skin::Command),
    /// Mesh tools.
    #[command(subcommand)]
    Mesh(mesh::Command),
    /// Benchmarks for performance engineers.
    #[command(subcommand)]
    Bench(bench::Command),
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Synth(a) => synth::run(a),
        Command::Import(c) => import::run(c),
        Command::Sync(a) => sync::run(a),
        Command::Validate(a) => validate::run(a),
        Command::Segment(a) => segment::run(a),
        Command::Track(a) => track::run(a),
        Command::Merge(a) => merge::run(a),
        Command::Batch(c) => batch::run(c),
        Command::Score(a) => score::run(a),
        Command::Energy(a) => energy::run(a),
        Command::Export(a) => export::run(a),
        Command::Rig(c) => rig::run(c),
        Command::View(a) => view::run(a),
        Command::Envelope(c) => envelope::run(c),
        Command::Skin(c) => skin::run(c),
        Command::Mesh(c) => mesh::run(c),
        Command::Bench(c) => bench::run(c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub(crate) fn progress_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {per_sec} eta {eta}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
