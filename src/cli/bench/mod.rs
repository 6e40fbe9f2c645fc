//! `jawtrack bench`: the figures for performance engineers and the README's tables: the
//! energy's evaluations per second (`energy`), tracking against the energy's floor (`track`),
//! the rigs' figures (`rig`).

mod energy;
mod rig;
mod track;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Time the energy: CPU reference, GPU histogram and the readback baseline, single and
    /// batched, footprint and full frame, on a procedural arch and the real scans.
    Energy(energy::EnergyArgs),
    /// Track synthetic captures and compare with the energy's floor (the minimum of E found
    /// by a long, fine search from the truth), per preset: accuracy, speed, ratio to floor.
    Track(track::TrackArgs),
    /// Learn a rig from synthetic TMJ motion and report the paper's figures, learning time and
    /// IK speed.
    Rig(rig::RigArgs),
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Energy(a) => energy::energy(a),
        Command::Track(a) => track::track(a),
        Command::Rig(a) => rig::rig(a),
    }
}
