//! tracks.json, written as tracking goes: every finished frame is appended to a journal
//! (`<output>.journal`, one JSON line per frame, synced), and tracks.json is rewritten
//! atomically at most once a second and at the end. An interrupted run loses at most the frame
//! in progress; `--resume` reads the journal (or tracks.json) back and continues after the last
//! complete frame. Writes stay linear in the sequence length.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::json;

use super::sequence::{FrameResult, Status};
use crate::capture::json::{FrameRecordJson, PoseJson, TRACKS_FORMAT, TracksJson};
use crate::capture::{ArchPoses, check_replaceable, write_json_atomic};
use crate::error::{Error, Result};

const REWRITE_EVERY: Duration = Duration::from_secs(1);

pub struct TracksWriter {
    path: PathBuf,
    journal_path: PathBuf,
    journal: std::fs::File,
    records: Vec<FrameRecordJson>,
    last_rewrite: Instant,
}

/// The record of a tracked frame, as the spec writes it.
pub fn record(r: &FrameResult) -> FrameRecordJson {
    let arch_energy = |e: &crate::energy::Energy, lambda: f64| json!({"total": e.total(lambda), "uncovered": e.uncovered(), "boi_outside": e.boi_outside(), "cross": e.cross()});
    let lambda = crate::energy::DEFAULT_LAMBDA;
    FrameRecordJson {
        frame: r.frame,
        upper: PoseJson::from(&r.poses.upper),
        lower: PoseJson::from(&r.poses.lower),
        jaw: Some(PoseJson::from(&r.poses.jaw())),
        energy: r.energies.as_ref().map(
            |[u, l]| json!({"upper": arch_energy(u, lambda), "lower": arch_energy(l, lambda)}),
        ),
        area_error: r
            .energies
            .as_ref()
            .map(|[u, l]| json!({"upper": u.area_error(), "lower": l.area_error()})),
        status: Some(r.status),
    }
}

impl TracksWriter {
    fn journal_path(path: &Path) -> PathBuf {
        let mut name = path
            .file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default();
        name.push(".journal");
        path.with_file_name(name)
    }

    /// Start writing `path`. With `resume`, the frames already written (journal first, else
    /// tracks.json) are read back and returned; without it an existing output is an error
    /// unless `force`.
    pub fn open(
        path: &Path,
        resume: bool,
        force: bool,
    ) -> Result<(TracksWriter, Vec<FrameRecordJson>)> {
        let journal_path = Self::journal_path(path);
        // Before anything is read or written: neither may replace a device, pipe or link.
        check_replaceable(path)?;
        check_replaceable(&journal_path)?;
        let mut records = Vec::new();
        let exists = path.exists() || journal_path.exists();
        if resume {
            if journal_path.exists() {
                records = read_journal(&journal_path)?;
            } else if path.exists() {
                let tj: TracksJson = crate::capture::json::read_json(path, "tracks file")?;
                records = tj.frames;
            }
        } else if exists && !force {
            return Err(Error::invalid(
                path,
                "output",
                "already exists; pass --resume to continue it or --force to start over",
            ));
        }
        let werr = |error| Error::Write {
            path: journal_path.clone(),
            error,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(werr)?;
        }
        // The journal restarts with exactly the frames kept.
        let mut journal = std::fs::File::create(&journal_path).map_err(werr)?;
        for r in &records {
            writeln!(journal, "{}", serde_json::to_string(r).expect("plain data")).map_err(werr)?;
        }
        journal.sync_data().map_err(werr)?;
        Ok((
            TracksWriter {
                path: path.to_path_buf(),
                journal_path,
                journal,
                records: records.clone(),
                last_rewrite: Instant::now(),
            },
            records,
        ))
    }

    pub fn push(&mut self, r: &FrameResult) -> Result<()> {
        let rec = record(r);
        let werr = |error| Error::Write {
            path: self.journal_path.clone(),
            error,
        };
        writeln!(
            self.journal,
            "{}",
            serde_json::to_string(&rec).expect("plain data")
        )
        .map_err(werr)?;
        self.journal.sync_data().map_err(werr)?;
        self.records.push(rec);
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
                frames: self.records.clone(),
            },
        )
    }

    /// Write tracks.json a last time and drop the journal.
    pub fn finish(mut self) -> Result<Vec<FrameRecordJson>> {
        self.rewrite()?;
        std::fs::remove_file(&self.journal_path).map_err(|error| Error::Write {
            path: self.journal_path.clone(),
            error,
        })?;
        Ok(self.records)
    }
}

/// The complete lines of a journal (a last line cut off by an interruption is dropped).
fn read_journal(path: &Path) -> Result<Vec<FrameRecordJson>> {
    let (file, _) = crate::capture::read::open_input(path, "journal")?;
    let mut out = Vec::new();
    for line in std::io::BufReader::new(file).lines() {
        let line = line.map_err(|e| Error::read(path, "journal", e))?;
        match serde_json::from_str(&line) {
            Ok(r) => out.push(r),
            Err(_) => break,
        }
    }
    Ok(out)
}

/// Poses and status of a written record.
pub fn record_poses(path: &Path, r: &FrameRecordJson) -> Result<(ArchPoses, Status)> {
    let status = r.status();
    Ok((
        ArchPoses {
            upper: r.upper.to_pose(path, &format!("frame {}.upper", r.frame))?,
            lower: r.lower.to_pose(path, &format!("frame {}.lower", r.frame))?,
        },
        status,
    ))
}
