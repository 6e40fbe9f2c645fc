//! `jawtrack rig`: learn the three-parameter jaw rig from jaw poses (`learn`), judge it
//! (`eval`, `compare`), and use it (`pose`, `encode`, `reconstruct`, `ik`, `animate`, `sample`).

mod learn;
mod motion;
mod pose;

use std::path::Path;
use std::time::Instant;

use jawtrack::formats::{JawPoses, read_jaw_poses};

use learn::{CompareArgs, EvalArgs, LearnArgs};
use motion::{AnimateArgs, SampleArgs};
use pose::{EncodeArgs, IkArgs, PoseArgs, ReconstructArgs};

#[derive(clap::Subcommand)]
pub enum Command {
    /// Learn a rig from jaw poses (a tracks.json, gt/poses.json or jawtrack-jaw/1 file).
    #[command(allow_negative_numbers = true)]
    Learn(LearnArgs),
    /// The paper's figures for a rig on a set of poses: reconstruction error of PCA, NLPCA and
    /// the rig (Fig. 12) and random rig poses against the captured ones (Fig. 13).
    Eval(EvalArgs),
    /// The jaw pose for parameters d1 (opening), d2 (lateral), d3 (protrusion), and whether
    /// they are valid (JSON on stdout).
    #[command(allow_negative_numbers = true)]
    Pose(PoseArgs),
    /// The parameters of every pose of a file.
    Encode(EncodeArgs),
    /// Each pose through the rig: encode, clamp into the valid ranges, decode (a jaw-pose file).
    Reconstruct(ReconstructArgs),
    /// Inverse kinematics: the valid parameters that bring a mesh point closest to a target.
    #[command(allow_negative_numbers = true)]
    Ik(IkArgs),
    /// Keyframe animation: key parameters at times, linearly interpolated, as jaw poses (and
    /// optionally posed meshes).
    #[command(allow_negative_numbers = true)]
    Animate(AnimateArgs),
    /// Random valid rig poses (the d1-dependent ranges, or the fixed ones).
    Sample(SampleArgs),
    /// Every rig on the same poses: traditional 1/3/5-DOF, PCA-3, the NLPCA rig, the envelope
    /// rig.
    Compare(CompareArgs),
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Learn(a) => learn::learn(a),
        Command::Eval(a) => learn::evaluate(a),
        Command::Pose(a) => pose::pose(a),
        Command::Encode(a) => pose::encode(a),
        Command::Reconstruct(a) => pose::reconstruct(a),
        Command::Ik(a) => pose::ik(a),
        Command::Animate(a) => motion::animate(a),
        Command::Sample(a) => motion::sample(a),
        Command::Compare(a) => learn::compare(a),
    }
}

/// Jaw poses and the seconds reading them took.
pub(super) fn load_poses(path: &Path) -> anyhow::Result<(JawPoses, f64)> {
    let started = Instant::now();
    let poses = read_jaw_poses(path)?;
    Ok((poses, started.elapsed().as_secs_f64()))
}
