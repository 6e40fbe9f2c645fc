//! The long steps several commands take, each with its progress bar on stderr.

use std::path::Path;

use anyhow::Context;
use jawtrack::capture::masks::MOUTH_BIT;
use jawtrack::capture::{Capture, LOWER_BIT, OpenOptions, UPPER_BIT};
use jawtrack::synth::{self, SynthOptions, SynthReport};
use jawtrack::track::{Session, SessionOptions, Summary};

/// Write a synthetic capture.
pub fn synthesise(out: &Path, opts: &SynthOptions) -> anyhow::Result<SynthReport> {
    let bar = super::progress_bar(opts.frames as u64, "synth");
    let report = synth::generate(out, opts, &|| bar.inc(1))
        .with_context(|| format!("writing a synthetic capture to {}", out.display()))?;
    bar.finish_and_clear();
    Ok(report)
}

/// Open a capture and (optionally) decode every mask of every frame.
pub fn open_and_check(
    dir: &Path,
    options: OpenOptions,
    decode_all: bool,
) -> anyhow::Result<(Capture, Option<Vec<LabelPixels>>)> {
    let capture = Capture::open_with(dir, options)
        .with_context(|| format!("invalid capture {}", dir.display()))?;
    super::report::notes(&capture);
    if !decode_all {
        return Ok((capture, None));
    }
    let mut pixels = vec![LabelPixels::default(); capture.cameras().len()];
    let bar = super::progress_bar(capture.frame_count() as u64, "decoding masks");
    for frame in capture.frames() {
        let masks = capture
            .load_masks(frame)
            .with_context(|| format!("invalid capture {}", dir.display()))?;
        for (p, mask) in pixels.iter_mut().zip(&masks.masks) {
            let Some(mask) = mask else { continue };
            p.masks += 1;
            for (k, bit) in [UPPER_BIT, LOWER_BIT, MOUTH_BIT].into_iter().enumerate() {
                p.pixels[k] += mask.count(bit);
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok((capture, Some(pixels)))
}

/// One camera's labelled pixels over the masks decoded: upper, lower (both alike with
/// combined masks) and the visible mouth interior.
#[derive(Debug, Clone, Default)]
pub struct LabelPixels {
    pub masks: u64,
    pub pixels: [u64; 3],
}

impl LabelPixels {
    /// Mean pixels per mask of each label.
    pub fn mean(&self) -> [f64; 3] {
        self.pixels.map(|p| p as f64 / self.masks.max(1) as f64)
    }
}

/// Track a capture as `options` say, printing the engine chosen.
pub fn track(capture: &Capture, options: SessionOptions) -> anyhow::Result<Summary> {
    let lambda = options.settings.search.lambda;
    let session = Session::open(capture, options)?;
    eprintln!("energy backend: {}", session.backend());
    let bar = super::progress_bar(session.todo().len() as u64, "tracking");
    let summary = session.run(&mut |r| {
        let e = r
            .energies
            .as_ref()
            .map_or(0.0, |[u, l]| u.total(lambda) + l.total(lambda));
        bar.set_message(format!(
            "tracking (E = {e:.0}, {})",
            r.written_status().as_str()
        ));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Run `step` with a spinner and the elapsed time on stderr: for long steps that cannot say how
/// far they are.
pub fn with_spinner<T>(what: &str, step: impl FnOnce() -> T) -> T {
    with_progress(what, |_| step())
}

/// Run `step` with a spinner, the elapsed time and what `step` last told its progress callback
/// (learning a rig: the stage, the evaluations so far and the error).
pub fn with_progress<T>(what: &str, step: impl FnOnce(&jawtrack::rig::Progress) -> T) -> T {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .expect("a valid template"),
    );
    bar.set_message(what.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let out = step(&|m: &str| bar.set_message(format!("{what}: {m}")));
    bar.finish_and_clear();
    out
}
