use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder (with capture.json).
    pub capture: PathBuf,
    /// Only read mask headers; do not decode every mask.
    #[arg(long)]
    pub quick: bool,
    #[command(flatten)]
    pub load: super::args::LoadArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (capture, pixels) =
        super::run::open_and_check(&a.capture, a.load.open_options(), !a.quick)?;
    let means: Option<Vec<[f64; 3]>> = pixels.map(|p| p.iter().map(|c| c.mean()).collect());
    super::report::capture(&capture, means.as_deref());
    Ok(())
}
