//! tracks.json, written as tracking goes: every finished frame is appended to a journal
//! (`<output>.journal`, one JSON line per frame, synced), and tracks.json is rewritten
//! atomically at most once a second and at the end. An interrupted run loses at most the frame
//! in progress; `--resume` reads the journal (or tracks.json) back and continues after the last
//! complete frame. Writes stay linear in the sequence length.
//!
//! The journal holds each frame as tracked (its poses and the masks' information about
//! them); tracks.json holds them settled by the window over frames ([`super::window`]), each
//! frame once the window's frames after it are in, the last ones at the end, with the tracked
//! poses beside them. A resumed run reads the frames as tracked back and settles them again.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::edge_offsets::EdgeOffsets;
use super::state::{Caution, FrameResult};
use super::window::{Estimate, Window, settled};
use crate::arch::ArchPoses;
use crate::energy::smooth::Matrix12;
use crate::error::{Error, Result};
use crate::formats::{
    ArchEnergyJson, FrameRecordJson, PerArchJson, PoseJson, Status, TRACKS_FORMAT, TrackedJson,
    TracksJson,
};
use crate::io::{check_replaceable, write_json_atomic};

const REWRITE_EVERY: Duration = Duration::from_secs(1);

pub struct TracksWriter {
    path: PathBuf,
    journal_path: PathBuf,
    journal: std::fs::File,
    frames: SettledFrames,
    fingerprint: String,
    last_rewrite: Instant,
}

/// Frames as tracked, and as the window over frames settles them: tracks.json's records are
/// a pure function of the records as tracked, so a run written in pieces (`merge`) comes out
/// as one written at once.
pub struct SettledFrames {
    /// Every frame as tracked, as the journal has it.
    records: Vec<FrameRecordJson>,
    /// The same, as a reader of the journal gets them back.
    estimates: Vec<Estimate>,
    /// The frames the window has settled.
    settled: Vec<ArchPoses>,
    window: Window,
}

impl SettledFrames {
    pub fn new(window: &Window) -> SettledFrames {
        SettledFrames {
            records: Vec::new(),
            estimates: Vec::new(),
            settled: Vec::new(),
            window: window.clone(),
        }
    }

    /// Add the next frame as tracked (a record as [`as_tracked`] gives it back).
    pub fn push(&mut self, record: FrameRecordJson, estimate: Estimate) {
        self.records.push(record);
        self.estimates.push(estimate);
        self.settle(false);
    }

    /// The frames as tracked.
    pub fn records(&self) -> &[FrameRecordJson] {
        &self.records
    }

    /// Settle every frame whose window is complete, or, at the `end`, every frame.
    pub fn settle(&mut self, end: bool) {
        let n = self.estimates.len();
        let complete = if end {
            n
        } else {
            n.saturating_sub(self.window.settings.frames)
        };
        while self.settled.len() < complete {
            let t = self.settled.len();
            // A frame without masks keeps the last pose, as settled.
            let poses = match (self.records[t].status(), self.settled.last()) {
                (Status::NoData, Some(last)) => *last,
                _ => settled(&self.estimates, t, &self.window),
            };
            self.settled.push(poses);
        }
    }

    /// The records as tracks.json has them: settled poses where the window has settled them,
    /// the tracked ones beside them.
    pub fn output(&self) -> Vec<FrameRecordJson> {
        let mut out = self.records.clone();
        for (rec, poses) in out.iter_mut().zip(&self.settled) {
            if rec.tracked.is_some() || rec.status() == Status::NoData {
                rec.upper = PoseJson::from(&poses.upper);
                rec.lower = PoseJson::from(&poses.lower);
                rec.jaw = Some(PoseJson::from(&poses.jaw()));
            }
        }
        out
    }
}

/// The journal's first line: what wrote it.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JournalHead {
    fingerprint: String,
}

/// The record of a tracked frame, as the spec writes it.
pub fn record(r: &FrameResult) -> FrameRecordJson {
    let arch_energy = energy_json;
    FrameRecordJson {
        frame: r.frame,
        upper: PoseJson::from(&r.poses.upper),
        lower: PoseJson::from(&r.poses.lower),
        jaw: Some(PoseJson::from(&r.poses.jaw())),
        energy: r.energies.as_ref().map(|[u, l]| PerArchJson {
            lower: arch_energy(l),
            upper: arch_energy(u),
        }),
        area_error: r.energies.as_ref().map(|[u, l]| PerArchJson {
            lower: Some(l.area_error()),
            upper: Some(u.area_error()),
        }),
        status: Some(r.written_status()),
        teeth_hidden: r.caution == Some(Caution::TeethHidden),
        recovered: r.caution == Some(Caution::Recovered),
        jaw_source: None,
        tracked: r.information.map(|info| TrackedJson {
            upper: PoseJson::from(&r.poses.upper),
            lower: PoseJson::from(&r.poses.lower),
            information: info.transpose().iter().copied().collect(),
        }),
        hand_set: false,
        edge_offsets: r.edge_offsets.as_ref().map(EdgeOffsets::to_json),
    }
}

/// An arch's energy terms as the record writes them.
pub fn energy_json(e: &crate::energy::Energy) -> ArchEnergyJson {
    ArchEnergyJson {
        boi_outside: e.boi_outside(),
        cross: Some(e.cross()),
        over_mouth: Some(e.over_mouth()),
        total: e.total(crate::energy::DEFAULT_LAMBDA),
        uncovered: e.uncovered(),
    }
}

/// A record as tracked (tracks.json's settled poses replaced by the tracked ones beside them)
/// and the estimate it holds; `path` is the file it was read from, for errors.
pub fn as_tracked(path: &Path, mut rec: FrameRecordJson) -> Result<(FrameRecordJson, Estimate)> {
    let mut information = None;
    if let Some(t) = &rec.tracked {
        let field = format!("frame {}.tracked.information", rec.frame);
        if t.information.len() != 144 || t.information.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(path, field, "not 144 finite numbers"));
        }
        information = Some(Matrix12::from_row_slice(&t.information));
        rec.upper = t.upper;
        rec.lower = t.lower;
        rec.jaw = None;
    }
    let poses = rec.poses(path)?;
    rec.jaw = Some(PoseJson::from(&poses.jaw()));
    Ok((rec, Estimate { poses, information }))
}

/// Where the journal of the run writing `path` is: beside it, `<name>.journal`. While it is
/// there the run is unfinished.
pub fn journal_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".journal");
    path.with_file_name(name)
}

impl TracksWriter {
    /// Start writing `path` for a run whose capture and settings have `fingerprint`. With
    /// `resume`, the frames already written (journal first, else tracks.json) are read back,
    /// checked (the same fingerprint; records as [`check_records`] wants them, within the
    /// capture's `frames`) and returned; without it an existing output is an error unless
    /// `force`.
    pub fn open(
        path: &Path,
        resume: bool,
        force: bool,
        frames: std::ops::Range<u32>,
        fingerprint: &str,
        window: &Window,
    ) -> Result<(TracksWriter, Vec<FrameRecordJson>)> {
        let journal_path = journal_path(path);
        // Before anything is read or written: neither may replace a device, pipe or link.
        check_replaceable(path)?;
        check_replaceable(&journal_path)?;
        let mut records = Vec::new();
        let exists = path.exists() || journal_path.exists();
        if resume {
            if journal_path.exists() {
                let (written_by, kept) = read_journal(&journal_path)?;
                check_fingerprint(&journal_path, "line 1", written_by.as_deref(), fingerprint)?;
                check_records(&journal_path, &kept, &frames, |i| format!("line {}", i + 2))?;
                records = kept;
            } else if path.exists() {
                let tj: TracksJson = crate::io::read_json(path, "tracks file")?;
                check_fingerprint(path, "fingerprint", tj.fingerprint.as_deref(), fingerprint)?;
                check_records(path, &tj.frames, &frames, |i| format!("frames[{i}]"))?;
                records = tj.frames;
            }
        } else if exists && !force {
            return Err(Error::invalid(
                path,
                "output",
                "already exists; pass --resume to continue it or --force to start over",
            ));
        }
        let from = if journal_path.exists() {
            &journal_path
        } else {
            path
        };
        let mut tracked = SettledFrames::new(window);
        for r in records {
            let (r, e) = as_tracked(from, r)?;
            tracked.push(r, e);
        }
        let werr = |error| Error::Write {
            path: journal_path.clone(),
            error,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(werr)?;
        }
        // The journal restarts with its head and exactly the frames kept.
        let mut journal = std::fs::File::create(&journal_path).map_err(werr)?;
        let head = JournalHead {
            fingerprint: fingerprint.to_string(),
        };
        writeln!(
            journal,
            "{}",
            serde_json::to_string(&head).expect("plain data")
        )
        .map_err(werr)?;
        for r in tracked.records() {
            writeln!(journal, "{}", serde_json::to_string(r).expect("plain data")).map_err(werr)?;
        }
        journal.sync_data().map_err(werr)?;
        let records = tracked.records().to_vec();
        let writer = TracksWriter {
            path: path.to_path_buf(),
            journal_path,
            journal,
            frames: tracked,
            fingerprint: fingerprint.to_string(),
            last_rewrite: Instant::now(),
        };
        Ok((writer, records))
    }

    pub fn push(&mut self, r: &FrameResult) -> Result<()> {
        let line = serde_json::to_string(&record(r)).expect("plain data");
        let werr = |error| Error::Write {
            path: self.journal_path.clone(),
            error,
        };
        writeln!(self.journal, "{line}").map_err(werr)?;
        self.journal.sync_data().map_err(werr)?;
        // The estimate as a resumed run reads it back from the journal: the same bits.
        let rec: FrameRecordJson = serde_json::from_str(&line).expect("just written");
        let (rec, estimate) = as_tracked(&self.journal_path, rec)?;
        self.frames.push(rec, estimate);
        if self.last_rewrite.elapsed() >= REWRITE_EVERY {
            self.rewrite()?;
        }
        Ok(())
    }

    fn rewrite(&mut self) -> Result<()> {
        self.last_rewrite = Instant::now();
        write_json_atomic(
            &self.path,
            &TracksJson {
                format: TRACKS_FORMAT.to_string(),
                fingerprint: Some(self.fingerprint.clone()),
                frames: self.frames.output(),
            },
        )
    }

    /// Settle the last frames, write tracks.json a last time and drop the journal.
    pub fn finish(mut self) -> Result<Vec<FrameRecordJson>> {
        self.frames.settle(true);
        self.rewrite()?;
        std::fs::remove_file(&self.journal_path).map_err(|error| Error::Write {
            path: self.journal_path.clone(),
            error,
        })?;
        Ok(self.frames.output())
    }
}

/// A written run's fingerprint must be this run's: a journal or tracks.json of another capture,
/// other settings or none at all is not continued.
fn check_fingerprint(path: &Path, field: &str, written: Option<&str>, now: &str) -> Result<()> {
    match written {
        Some(w) if w == now => Ok(()),
        Some(_) => Err(Error::invalid(
            path,
            field,
            "was written for another capture or other settings: --resume continues only the same run (--force starts over)",
        )),
        None => Err(Error::invalid(
            path,
            field,
            "no fingerprint of the run that wrote it: --resume continues only a run of this jawtrack (--force starts over)",
        )),
    }
}

/// The fingerprint in a journal's first line and the frame records after it. Only a last line
/// cut off by an interruption (no newline after it) may fail to parse, and is dropped; any
/// other line that does not parse is an error naming it.
fn read_journal(path: &Path) -> Result<(Option<String>, Vec<FrameRecordJson>)> {
    let text = crate::io::read::read_text(path, "journal")?;
    let mut lines: Vec<&str> = text.split_inclusive('\n').collect();
    let head = lines
        .first()
        .and_then(|l| serde_json::from_str::<JournalHead>(l.trim_end()).ok());
    if head.is_some() {
        lines.remove(0);
    }
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let line_no = i + 1 + usize::from(head.is_some());
        let torn = i + 1 == lines.len() && !line.ends_with('\n');
        match serde_json::from_str(line.trim_end()) {
            Ok(r) => out.push(r),
            Err(_) if torn => break,
            Err(e) => {
                return Err(Error::invalid(
                    path,
                    format!("line {line_no}"),
                    format!(
                        "not a frame record ({e}); only a last line cut off by an interruption may be"
                    ),
                ));
            }
        }
    }
    Ok((head.map(|h| h.fingerprint), out))
}

/// Records written before may be trusted only as a whole: frames within the capture's, in
/// increasing order without repeats, and poses that read back (finite, rotations). `at` names
/// a record for errors.
pub fn check_records(
    path: &Path,
    records: &[FrameRecordJson],
    frames: &std::ops::Range<u32>,
    at: impl Fn(usize) -> String,
) -> Result<()> {
    let mut previous: Option<u32> = None;
    for (i, r) in records.iter().enumerate() {
        if !frames.contains(&r.frame) {
            return Err(Error::invalid(
                path,
                at(i),
                format!(
                    "frame {} is outside the capture's frames {}..{}",
                    r.frame, frames.start, frames.end
                ),
            ));
        }
        if let Some(p) = previous.filter(|&p| r.frame <= p) {
            return Err(Error::invalid(
                path,
                at(i),
                format!(
                    "frame {} comes after frame {p}: frames must increase, each once",
                    r.frame
                ),
            ));
        }
        previous = Some(r.frame);
        r.poses(path).map_err(|e| match e {
            Error::Invalid { problem, field, .. } => {
                Error::invalid(path, format!("{}: {field}", at(i)), problem)
            }
            other => other,
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(frame: u32, x: &str) -> String {
        format!(
            r#"{{"frame": {frame}, "upper": {{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [{x},0,0]}}, "lower": {{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,-10,0]}}, "status": "ok"}}"#
        )
    }

    const HEAD: &str = "{\"fingerprint\": \"run\"}\n";

    /// Resume run `run` from a journal holding `text`, for a capture of frames 0..12.
    fn resume_run(text: &str, run: &str) -> Result<Vec<FrameRecordJson>> {
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("tracks.json");
        std::fs::write(t.path().join("tracks.json.journal"), text).unwrap();
        TracksWriter::open(&out, true, false, 0..12, run, &Window::default())
            .map(|(_, records)| records)
    }

    fn resume(text: &str) -> Result<Vec<FrameRecordJson>> {
        resume_run(&format!("{HEAD}{text}"), "run")
    }

    fn refused(text: &str, words: &[&str]) {
        let e = resume(text).unwrap_err().to_string();
        for w in words {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    }

    #[test]
    fn a_torn_last_line_is_dropped_and_the_rest_kept() {
        let text = format!(
            "{}\n{}\n{}",
            line(0, "0"),
            line(1, "0"),
            &line(2, "0")[..40]
        );
        let records = resume(&text).unwrap();
        assert_eq!(records.iter().map(|r| r.frame).collect::<Vec<_>>(), [0, 1]);
    }

    /// Found by hostile input (bf99878): each of these was accepted and tracks.json lied.
    #[test]
    fn a_journal_line_with_a_frame_outside_the_capture_is_refused() {
        refused(
            &format!("{}\n{}\n", line(0, "0"), line(999, "0")),
            &["tracks.json.journal", "`line 3`", "frame 999", "0..12"],
        );
    }

    #[test]
    fn a_duplicated_journal_line_is_refused() {
        refused(
            &format!("{}\n{}\n{}\n", line(0, "0"), line(1, "0"), line(1, "0")),
            &["`line 4`", "frame 1 comes after frame 1"],
        );
    }

    #[test]
    fn a_journal_pose_of_1e308_is_refused() {
        refused(
            &format!("{}\n{}\n", line(0, "0"), line(1, "1e308")),
            &["line 3: frame 1.upper.translation", "1 km"],
        );
    }

    #[test]
    fn garbage_in_the_middle_of_a_journal_is_refused_not_truncated() {
        refused(
            &format!("{}\nnot json\n{}\n", line(0, "0"), line(2, "0")),
            &["`line 3`", "not a frame record"],
        );
    }

    /// Found by hostile input (bf99878): a journal of another capture or other settings was
    /// continued.
    #[test]
    fn a_journal_of_another_run_or_of_none_is_refused() {
        let text = format!("{HEAD}{}\n", line(0, "0"));
        let e = resume_run(&text, "another").unwrap_err().to_string();
        assert!(
            e.contains("`line 1`") && e.contains("another capture or other settings"),
            "{e}"
        );
        let e = resume_run(&format!("{}\n", line(0, "0")), "run")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no fingerprint"), "{e}");
        assert_eq!(resume_run(&text, "run").unwrap().len(), 1);
    }
}
