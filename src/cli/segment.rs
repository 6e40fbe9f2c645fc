use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::Context;
use jawtrack::capture::{Capture, OpenOptions};
use jawtrack::segment::{SegmentSettings, Segmenter, prepare, score::score_masks};
use jawtrack::track::{Session, SessionOptions, Summary, score_records};

use super::args::read_settings;
use super::track::TrackingArgs;

#[derive(clap::Args)]
pub struct Args {
    /// As for `track`; the capture holds images/<camera>/ (from `jawtrack import video`),
    /// init.json and capture.json's `masks` block (the values the masks are written with),
    /// and the masks go to its masks folder. Masks already there are never replaced without
    /// --force. The search is Gauss-Newton unless --search or --settings says otherwise.
    #[command(flatten)]
    pub run: super::track::RunArgs,
    /// Segmentation settings as JSON (the fields of `SegmentSettings`, docs/footage.md): a
    /// file, or the JSON itself when it starts with `{`.
    #[arg(long)]
    pub segment_settings: Option<PathBuf>,
    /// Also write each picture's posteriors into this folder (<camera>/<frame>.png): red
    /// teeth, green mouth interior, blue lips and skin, each as bright as it is probable
    /// before the graph cuts: why a mask came out as it did.
    #[arg(long)]
    pub debug: Option<PathBuf>,
}

pub fn run(mut args: Args) -> anyhow::Result<()> {
    gauss_newton_unless_asked(&mut args.run.how);
    let a = &args.run;
    let segment_settings = segment_settings(args.segment_settings.as_deref())?;
    let options = OpenOptions {
        masks_to_come: true,
        ..a.how.load.open_options()
    };
    let capture = Capture::open_with(&a.capture, options)
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    super::report::notes(&capture);
    let existing = capture
        .cameras()
        .iter()
        .map(|c| c.frames_present.len())
        .sum::<usize>();
    if existing > 0 && !a.force && !a.resume {
        anyhow::bail!(
            "{} already holds {existing} masks (perhaps corrected by hand): track from them \
             with `jawtrack track`, or pass --force to make them again",
            capture.mask_dir().display()
        );
    }
    if capture.mouth().is_none() {
        eprintln!(
            "note: capture.json's masks block has no `mouth` value, so the masks carry the \
             teeth alone (add e.g. \"mouth\": 40 to keep the mouth interior)"
        );
    }
    let (capture, sizes) = prepared(capture, options)?;
    let track_options = a.session_options(&capture)?;
    let run = segment_and_track(
        &capture,
        &sizes,
        track_options,
        segment_settings,
        args.debug.clone(),
    )?;
    let (summary, segmenter, todo) = (run.summary, run.segmenter, run.todo);
    super::report::track_summary(&a.output, &summary);
    if summary.tracked_now > 0 {
        println!(
            "segmentation {:.2} s per frame of that (all cameras)",
            segmenter.seconds / summary.tracked_now as f64
        );
    }
    println!("masks written to {}:", capture.mask_dir().display());
    for (cam, c) in capture.cameras().iter().zip(&segmenter.counts) {
        println!(
            "  {:<8} {} segmented, {} dark (lights off), {} with the arches out of view, {} without a picture",
            cam.calibrated.name, c.segmented, c.dark, c.out_of_view, c.no_picture
        );
    }
    if let Some(s) = score_masks(&capture, todo)? {
        let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        println!(
            "against gt/masks ({} pictures): IoU teeth {:.3} (worst picture {:.3}), upper {}, lower {}, mouth interior {}",
            s.pictures,
            s.teeth_iou,
            s.worst_teeth_iou,
            opt(s.upper_iou),
            opt(s.lower_iou),
            opt(s.mouth_iou)
        );
    }
    if let Some(report) = score_records(&capture, &a.output, &summary.records)? {
        println!();
        super::report::score(&report);
    }
    Ok(())
}

/// `capture` (opened with `options`) ready to segment: its init.json there, its
/// pictures' sizes known (`segment::prepare`) and, where `options` gave no bound, its arches
/// simplified for them, as `track` simplifies them when it reads the masks made here.
pub(crate) fn prepared(
    mut capture: Capture,
    options: OpenOptions,
) -> anyhow::Result<(Capture, Vec<(u32, u32)>)> {
    if capture.init().is_none() {
        anyhow::bail!(
            "{}: not found: segment starts its colour models from the arches drawn at the first \
             frame's poses (init.json's poses or bootstrap points); tracking without init.json \
             needs masks",
            capture.dir().join("init.json").display()
        );
    }
    let mut sizes = prepare(&mut capture)?;
    if options.simplify_mm.is_none() && options.max_triangles.is_none() {
        let bound = jawtrack::capture::resolution::simplify_mm(capture.cameras());
        if Some(bound) != capture.simplified_mm() {
            let options = OpenOptions {
                simplify_mm: Some(bound),
                ..options
            };
            let dir = capture.dir().to_path_buf();
            capture = Capture::open_with(&dir, options)
                .with_context(|| format!("invalid capture {}", dir.display()))?;
            sizes = prepare(&mut capture)?;
        }
    }
    Ok((capture, sizes))
}

/// A run of `segment`: the tracking summary, and the segmenter with its counts and time.
pub(crate) struct SegmentRun<'c> {
    pub summary: Summary,
    pub segmenter: Segmenter<'c>,
    /// The frames the run was asked for.
    pub todo: Range<u32>,
}

/// Segments and tracks the frames `options` names, writing the masks into the capture's
/// masks folder and the tracks where `options` says.
pub(crate) fn segment_and_track<'c>(
    capture: &'c Capture,
    sizes: &[(u32, u32)],
    options: SessionOptions,
    settings: SegmentSettings,
    debug: Option<PathBuf>,
) -> anyhow::Result<SegmentRun<'c>> {
    let session = Session::open(capture, options)?;
    eprintln!("energy backend: {}", session.backend());
    let todo = session.todo();
    let mut segmenter = Segmenter::new(capture, sizes, settings);
    if let Some(dir) = debug {
        segmenter = segmenter.with_debug(dir);
    }
    let bar = super::progress_bar(session.todo().len() as u64, "segmenting and tracking");
    let summary = session.run_with(Some(&mut segmenter), &mut |r| {
        bar.set_message(format!(
            "segmenting and tracking ({})",
            r.written_status().as_str()
        ));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    Ok(SegmentRun {
        summary,
        segmenter,
        todo,
    })
}

/// Masks made here sit on the frame's colours, not on a person's brush: Gauss-Newton follows
/// them to a tenth of a millimetre at a quarter of the paper's search's time
/// (docs/footage.md), so it is segment's search unless a search or settings are asked for.
pub(crate) fn gauss_newton_unless_asked(how: &mut TrackingArgs) {
    if how.search.is_none() && how.settings.is_none() {
        how.search = Some(super::args::SearchArg::GaussNewton);
    }
}

/// The segmentation settings `arg` gives (a file, or JSON itself), checked; else the defaults.
pub(crate) fn segment_settings(arg: Option<&Path>) -> anyhow::Result<SegmentSettings> {
    let Some(arg) = arg else {
        return Ok(SegmentSettings::default());
    };
    let (s, source): (SegmentSettings, _) =
        read_settings(arg, "segmentation settings", "--segment-settings")?;
    s.validate(source)?;
    Ok(s)
}
