use std::path::PathBuf;

use jawtrack::track::merge::{DEFAULT_TOLERANCE_MM, MergeOptions, merge};
use jawtrack::track::score_records;

use super::track::TrackingArgs;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder.
    pub capture: PathBuf,
    /// The chunks' tracks.json files (`track --frames A..B`, each overlapping the one before
    /// by a few frames), in any order.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Where to write the merged tracks.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace the output when it exists.
    #[arg(long)]
    pub force: bool,
    /// Overlapping frames agree when both chunks put the jaw, and the upper arch, within this
    /// of each other (mm, mean vertex distance), or within three times their frames' noise where
    /// that is more; where they do not, the later chunk is tracked again from the earlier one.
    #[arg(long, default_value_t = DEFAULT_TOLERANCE_MM, value_parser = super::args::non_negative_mm)]
    pub tolerance_mm: f64,
    /// The options the chunks were tracked with (their fingerprints must match).
    #[command(flatten)]
    pub how: TrackingArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = a.how.open(&a.capture)?;
    let options = MergeOptions {
        output: a.output.clone(),
        force: a.force,
        settings: a.how.settings()?,
        backend: a.how.backend(),
        region: a.how.region(),
        tolerance_mm: a.tolerance_mm,
    };
    let report =
        super::run::with_spinner("merging (tracking again where chunks disagree)", || {
            merge(&capture, &a.parts, &options, &mut |_| {})
        })?;
    let mm = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    for s in &report.seams {
        println!(
            "{}: overlap {}..{}, checked {}..{}: jaw {} mm (limit {:.3}), upper {} mm (limit {:.3}) -> {}",
            s.part.display(),
            s.overlap.start,
            s.overlap.end,
            s.checked.start,
            s.checked.end,
            mm(s.jaw_mm),
            s.limit_mm[0],
            mm(s.upper_mm),
            s.limit_mm[1],
            if s.agreed() {
                "agree".to_string()
            } else {
                format!(
                    "FLAGGED: its {} frames after the overlap tracked again",
                    s.retracked
                )
            }
        );
    }
    println!(
        "merged {} chunks, frames {}..{} ({} records) -> {}",
        a.parts.len(),
        report.frames.start,
        report.frames.end,
        report.records.len(),
        a.output.display()
    );
    if let Some(score) = score_records(&capture, &a.output, &report.records)? {
        println!();
        super::report::score(&score);
    }
    Ok(())
}
