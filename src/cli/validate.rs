use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder (with capture.json).
    pub capture: PathBuf,
    /// Only read mask headers; do not decode every mask.
    #[arg(long)]
    pub quick: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = super::run::open_and_check(&a.capture, !a.quick)?;
    super::report::capture(&capture);
    Ok(())
}
