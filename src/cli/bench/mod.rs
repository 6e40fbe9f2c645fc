//! `jawtrack bench`: the figures for performance engineers and the README's tables: the
//! energy's evaluations per second (`energy`), tracking against the energy's floor (`track`),
//! masks made from colour pictures and tracked (`segment`), the rigs' figures (`rig`), the jaw
//! from the skin (`skin`).

mod energy;
mod rig;
mod segment;
mod skin;
mod track;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Time the energy: CPU reference, GPU histogram and the readback baseline, single and
    /// batched, footprint and full frame, on a procedural arch and the real scans.
    Energy(energy::EnergyArgs),
    /// Track synthetic captures and compare with the energy's floor (the minimum of E found
    /// by a long, fine search from the truth and from the tracked poses), per preset:
    /// accuracy, speed, ratio to floor.
    Track(track::TrackArgs),
    /// Segment and track colour pictures (ours, filmed by `synth --images`, and other
    /// programs' captures): the masks' IoU, the poses' errors, time per frame.
    Segment(segment::SegmentArgs),
    /// Learn a rig from synthetic TMJ motion and report the paper's figures, learning time and
    /// IK speed.
    Rig(rig::RigArgs),
    /// The jaw from the skin on a long synthetic subject: learning time, prediction time,
    /// single-subject accuracy on later frames.
    Skin(skin::SkinArgs),
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Energy(a) => energy::energy(a),
        Command::Track(a) => track::track(a),
        Command::Segment(a) => segment::segment(a),
        Command::Rig(a) => rig::rig(a),
        Command::Skin(a) => skin::skin(a),
    }
}
