//! One run from chunks of a take tracked apart (`track --frames A..B --locate`, on a cluster):
//! each chunk overlaps the one before; where the overlap's frames agree the later chunk takes
//! over after it, and where they do not, the later chunk's frames are tracked again from the
//! earlier one's, as a single run would have tracked them. The joined frames are settled by
//! the window over frames as one run's are, and written with that run's fingerprint.

use std::ops::Range;
use std::path::{Path, PathBuf};

use super::output::{SettledFrames, as_tracked, check_records, journal_path};
use super::session::{Session, SessionOptions, fingerprint};
use super::settings::TrackSettings;
use super::state::FrameResult;
use super::window::Window;
use crate::anatomy::MeshMetric;
use crate::capture::Capture;
use crate::energy::{Backend, Region};
use crate::error::{Error, Result};
use crate::formats::{FrameRecordJson, Status, TRACKS_FORMAT, TracksJson};
use crate::io::{check_replaceable, write_json_atomic};
use crate::stats::Stats;

/// How far apart two chunks' poses of a frame may always be and still agree (mm, the mean
/// distance of the arch's vertices, for the jaw and for the upper arch).
pub const DEFAULT_TOLERANCE_MM: f64 = 0.05;

/// Two chunks agree within this many times their frames' combined noise. Each chunk's frames
/// scatter about the motion by their noise (what the window over frames takes out of them),
/// so two runs of the same frames differ by about the two noises combined, whichever started
/// where, and drift apart for a few frames at a time (the median over the checked frames does
/// not average that out); past three times that, one of them is on another track.
pub const NOISE_FACTOR: f64 = 3.0;

/// What a merge is asked to do.
#[derive(Debug, Clone)]
pub struct MergeOptions {
    pub output: PathBuf,
    /// Replace an output that exists.
    pub force: bool,
    /// The chunks' tracking settings (a chunk tracked with others is refused).
    pub settings: TrackSettings,
    /// The engine that tracks again where chunks disagree.
    pub backend: Backend,
    pub region: Region,
    pub tolerance_mm: f64,
}

/// Where one chunk meets the next.
#[derive(Debug, Clone)]
pub struct Seam {
    /// The later chunk's file.
    pub part: PathBuf,
    /// The frames both chunks tracked.
    pub overlap: Range<u32>,
    /// The overlap's frames compared: its second half, where the later chunk has had half
    /// the overlap to settle from its own start.
    pub checked: Range<u32>,
    /// The median difference over the checked frames (mm); `None` where no checked frame was
    /// `ok` in both.
    pub jaw_mm: Option<f64>,
    pub upper_mm: Option<f64>,
    /// Where they stop agreeing: the tolerance, or more where the chunks' noise says so (mm;
    /// jaw, upper arch).
    pub limit_mm: [f64; 2],
    /// Frames tracked again from the earlier chunk's (0 where the overlap agreed).
    pub retracked: usize,
}

impl Seam {
    pub fn agreed(&self) -> bool {
        self.retracked == 0
    }
}

/// What a merge did.
#[derive(Debug, Clone)]
pub struct MergeReport {
    pub frames: Range<u32>,
    pub seams: Vec<Seam>,
    /// tracks.json's records, as written.
    pub records: Vec<FrameRecordJson>,
    pub fingerprint: String,
}

/// A chunk's frames as tracked.
struct Part {
    path: PathBuf,
    records: Vec<FrameRecordJson>,
    /// How far its frames as tracked are from them as settled by the window (root mean square
    /// over its `ok` frames, mm; jaw, upper arch): their noise. 0 without a window.
    noise_mm: [f64; 2],
}

impl Part {
    fn frames(&self) -> Range<u32> {
        self.records[0].frame..self.records[self.records.len() - 1].frame + 1
    }
}

/// Join the chunks at `parts` (tracks.json files of `track --frames A..B`, in any order) into
/// one run at `options.output`. `on_frame` sees each frame tracked again.
pub fn merge(
    capture: &Capture,
    parts: &[PathBuf],
    options: &MergeOptions,
    on_frame: &mut dyn FnMut(&FrameResult),
) -> Result<MergeReport> {
    options.settings.validate()?;
    let output = &options.output;
    check_replaceable(output)?;
    check_replaceable(&journal_path(output))?;
    if (output.exists() || journal_path(output).exists()) && !options.force {
        return Err(Error::invalid(
            output,
            "output",
            "already exists; pass --force to replace it",
        ));
    }
    let metrics = [
        MeshMetric::new(capture.upper()),
        MeshMetric::new(capture.lower()),
    ];
    let whole = fingerprint(capture, &options.settings, false);
    let located = fingerprint(capture, &options.settings, true);
    let mut chunks = Vec::new();
    for path in parts {
        if same_file(path, output) {
            return Err(Error::invalid(
                path,
                "output",
                "is also a chunk to merge: write the merged run to another file",
            ));
        }
        chunks.push(read_part(capture, path, [&whole, &located], &metrics)?);
    }
    // A journal left beside the output (a run or merge into it, interrupted) would be taken
    // for the frames tracked again below: it goes with the output it belonged to.
    let journal = journal_path(output);
    if journal.exists() {
        std::fs::remove_file(&journal).map_err(|error| Error::Write {
            path: journal.clone(),
            error,
        })?;
    }
    chunks.sort_by_key(|p| (p.frames().start, p.frames().end));
    let Some((first, rest)) = chunks.split_first() else {
        return Err(Error::invalid(output, "chunks", "none given"));
    };
    let mut merged = first.records.clone();
    let mut noise = first.noise_mm;
    let mut seams = Vec::new();
    for part in rest {
        let last = merged[merged.len() - 1].frame;
        let (start, end) = (part.frames().start, part.frames().end);
        if start > last + 1 {
            return Err(Error::invalid(
                &part.path,
                "frames",
                format!(
                    "starts at frame {start}, but the chunks before it end at frame {last}: frames {}..{start} are in no chunk",
                    last + 1
                ),
            ));
        }
        if end <= last + 1 {
            return Err(Error::invalid(
                &part.path,
                "frames",
                format!(
                    "ends at frame {}, within the chunks before it (to frame {last}): it adds nothing",
                    end - 1
                ),
            ));
        }
        let overlap = start..last + 1;
        let checked = overlap.start + overlap.len() as u32 / 2..overlap.end;
        let (jaw_mm, upper_mm) = compare(&part.path, &merged, &part.records, &checked, &metrics)?;
        let limit_mm = [0, 1].map(|k| {
            options
                .tolerance_mm
                .max(NOISE_FACTOR * noise[k].hypot(part.noise_mm[k]))
        });
        let agreed = matches!((jaw_mm, upper_mm), (Some(j), Some(u))
            if j <= limit_mm[0] && u <= limit_mm[1]);
        noise = part.noise_mm;
        let retracked = if agreed {
            merged.extend(part.records.iter().filter(|r| r.frame > last).cloned());
            0
        } else {
            merged = retrack(capture, options, &whole, merged, end, on_frame)?;
            (end - last - 1) as usize
        };
        seams.push(Seam {
            part: part.path.clone(),
            overlap,
            checked,
            jaw_mm,
            upper_mm,
            limit_mm,
            retracked,
        });
    }
    let frames = merged[0].frame..merged[merged.len() - 1].frame + 1;
    let mut settled = SettledFrames::new(&Window::new(&options.settings.window, capture));
    for r in merged {
        let (r, estimate) = as_tracked(output, r)?;
        settled.push(r, estimate);
    }
    settled.settle(true);
    let records = settled.output();
    write_json_atomic(
        output,
        &TracksJson {
            format: TRACKS_FORMAT.to_string(),
            fingerprint: Some(whole.clone()),
            frames: records.clone(),
        },
    )?;
    Ok(MergeReport {
        frames,
        seams,
        records,
        fingerprint: whole,
    })
}

/// A chunk's finished tracks.json, its records as tracked.
fn read_part(
    capture: &Capture,
    path: &Path,
    fingerprints: [&String; 2],
    [upper, lower]: &[MeshMetric; 2],
) -> Result<Part> {
    let journal = journal_path(path);
    if journal.exists() {
        return Err(Error::invalid(
            path,
            "frames",
            format!(
                "the chunk is unfinished ({} is beside it): finish it with `track --resume` first",
                journal.display()
            ),
        ));
    }
    let tj: TracksJson = crate::io::read_json(path, "tracks file")?;
    match tj.fingerprint.as_deref() {
        Some(f) if fingerprints.iter().any(|w| *w == f) => {}
        _ => {
            return Err(Error::invalid(
                path,
                "fingerprint",
                "was tracked from another capture or with other settings than these: give merge the tracking options the chunks had",
            ));
        }
    }
    if tj.frames.is_empty() {
        return Err(Error::invalid(path, "frames", "empty: no frame tracked"));
    }
    check_records(path, &tj.frames, &capture.frames(), |i| {
        format!("frames[{i}]")
    })?;
    let mut squares = [0.0, 0.0];
    let mut count = 0;
    for r in tj.frames.iter().filter(|r| r.status() == Status::Ok) {
        let settled = r.poses(path)?;
        let tracked = as_tracked(path, r.clone())?.1.poses;
        squares[0] += lower.mean_distance(&settled.jaw(), &tracked.jaw()).powi(2);
        squares[1] += upper.mean_distance(&settled.upper, &tracked.upper).powi(2);
        count += 1;
    }
    let records = tj
        .frames
        .into_iter()
        .map(|r| Ok(as_tracked(path, r)?.0))
        .collect::<Result<_>>()?;
    Ok(Part {
        path: path.to_path_buf(),
        records,
        noise_mm: squares.map(|s| (s / count.max(1) as f64).sqrt()),
    })
}

/// The median differences of the jaw and of the upper arch between `a` and `b` over the
/// `checked` frames that are `ok` in both (`path`: the later chunk's, for errors). The median,
/// not the largest: one frame where either run is at its noisiest says nothing about which
/// track the later chunk is on.
fn compare(
    path: &Path,
    a: &[FrameRecordJson],
    b: &[FrameRecordJson],
    checked: &Range<u32>,
    [upper, lower]: &[MeshMetric; 2],
) -> Result<(Option<f64>, Option<f64>)> {
    let (mut jaw, mut up) = (Vec::new(), Vec::new());
    for frame in checked.clone() {
        let find = |rs: &[FrameRecordJson]| rs.iter().find(|r| r.frame == frame).cloned();
        let (Some(ra), Some(rb)) = (find(a), find(b)) else {
            continue;
        };
        if ra.status() != Status::Ok || rb.status() != Status::Ok {
            continue;
        }
        let (pa, pb) = (ra.poses(path)?, rb.poses(path)?);
        jaw.push(lower.mean_distance(&pa.jaw(), &pb.jaw()));
        up.push(upper.mean_distance(&pa.upper, &pb.upper));
    }
    let median = |v: &[f64]| (!v.is_empty()).then(|| Stats::of(v).median);
    Ok((median(&jaw), median(&up)))
}

/// The frames after `merged` up to `end` tracked again, continuing `merged` as a resumed run
/// continues its journal: the same state, so the same frames a single run tracks.
fn retrack(
    capture: &Capture,
    options: &MergeOptions,
    whole: &str,
    merged: Vec<FrameRecordJson>,
    end: u32,
    on_frame: &mut dyn FnMut(&FrameResult),
) -> Result<Vec<FrameRecordJson>> {
    let output = &options.output;
    let start = merged[0].frame;
    write_json_atomic(
        output,
        &TracksJson {
            format: TRACKS_FORMAT.to_string(),
            fingerprint: Some(whole.to_string()),
            frames: merged,
        },
    )?;
    let session = Session::open(
        capture,
        SessionOptions {
            frames: Some(start..end),
            backend: options.backend,
            region: options.region,
            resume: true,
            settings: options.settings.clone(),
            ..SessionOptions::new(output)
        },
    )?;
    let summary = session.run(on_frame)?;
    summary
        .records
        .into_iter()
        .map(|r| Ok(as_tracked(output, r)?.0))
        .collect()
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}
