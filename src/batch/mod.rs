//! A study split into jobs: each take cut into chunks of frames that overlap their
//! neighbours, one `jawtrack track` task per chunk (resumable, so a task preempted or killed
//! is run again without losing its frames), then one `jawtrack merge` per take. The plan is a
//! file (`plan.json` in the batch folder) of command lines, so every runner runs the same
//! commands: Slurm job arrays (`slurm`), a Ray cluster (`ray`), or processes on this machine
//! (`local`).

pub mod local;
pub mod ray;
pub mod slurm;

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::formats::TracksJson;
use crate::io::{read_json, write_json_atomic};
use crate::track::output::journal_path;

pub const PLAN_FORMAT: &str = "jawtrack-batch/1";
const PLAN_FILE: &str = "plan.json";

/// A batch: what runs, where, and with which options.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    pub format: String,
    /// The jawtrack binary the tasks run.
    pub jawtrack: PathBuf,
    /// Where the tasks run: relative paths among `track_args` are read from here.
    pub workdir: PathBuf,
    /// The tracking options of every chunk and merge, as `track` takes them.
    pub track_args: Vec<String>,
    pub takes: Vec<Take>,
}

/// One capture's chunks and the merged run they make.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Take {
    pub capture: PathBuf,
    /// The merged tracks.json.
    pub output: PathBuf,
    pub chunks: Vec<Chunk>,
}

/// The frames one task tracks, into its own tracks.json.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Chunk {
    pub frames: Range<u32>,
    /// The first frame's poses found from its masks (every chunk but a take's first, which
    /// starts as a single run would).
    pub locate: bool,
    pub part: PathBuf,
}

/// A capture to plan: its folder and frames.
pub struct TakeFrames {
    pub capture: PathBuf,
    pub frames: Range<u32>,
}

/// How far a chunk's task has come, from its files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    pub frames_done: usize,
    pub frames: usize,
    /// Its tracks.json is complete (no journal beside it).
    pub finished: bool,
}

impl Plan {
    /// Cut each take into chunks of `chunk_frames` frames, each but the first starting
    /// `overlap` frames early; outputs go to `dir/<capture's folder name>/`.
    pub fn new(
        takes: &[TakeFrames],
        chunk_frames: u32,
        overlap: u32,
        dir: &Path,
        jawtrack: PathBuf,
        workdir: PathBuf,
        track_args: Vec<String>,
    ) -> Result<Plan> {
        if chunk_frames == 0 {
            return Err(Error::invalid(dir, "chunk_frames", "must be at least 1"));
        }
        let mut names: Vec<String> = Vec::new();
        let mut planned = Vec::new();
        for take in takes {
            let base = take
                .capture
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .filter(|n| !n.is_empty() && n != "..")
                .unwrap_or_else(|| "capture".to_string());
            let mut name = base.clone();
            let mut k = 2;
            while names.contains(&name) {
                name = format!("{base}-{k}");
                k += 1;
            }
            names.push(name.clone());
            let folder = dir.join(&name);
            let mut chunks = Vec::new();
            let mut own = take.frames.start;
            while own < take.frames.end {
                let end = own.saturating_add(chunk_frames).min(take.frames.end);
                let index = chunks.len();
                chunks.push(Chunk {
                    frames: own.saturating_sub(overlap).max(take.frames.start)..end,
                    locate: index > 0,
                    part: folder.join("parts").join(format!("chunk-{index:04}.json")),
                });
                own = end;
            }
            planned.push(Take {
                capture: take.capture.clone(),
                output: folder.join("tracks.json"),
                chunks,
            });
        }
        Ok(Plan {
            format: PLAN_FORMAT.to_string(),
            jawtrack,
            workdir,
            track_args,
            takes: planned,
        })
    }

    pub fn save(&self, dir: &Path) -> Result<()> {
        write_json_atomic(&dir.join(PLAN_FILE), self)
    }

    pub fn load(dir: &Path) -> Result<Plan> {
        let path = dir.join(PLAN_FILE);
        let plan: Plan = read_json(&path, "batch plan")?;
        if plan.format != PLAN_FORMAT {
            return Err(Error::invalid(
                &path,
                "format",
                format!("{:?}, expected {PLAN_FORMAT:?}", plan.format),
            ));
        }
        Ok(plan)
    }

    /// Every chunk as a task, numbered as the job array numbers them: (take, chunk).
    pub fn tasks(&self) -> Vec<(usize, usize)> {
        self.takes
            .iter()
            .enumerate()
            .flat_map(|(t, take)| (0..take.chunks.len()).map(move |c| (t, c)))
            .collect()
    }

    /// Task `task`'s command line (arguments of jawtrack): its chunk tracked with `--resume`,
    /// so a task run again continues after its last frame.
    pub fn task_args(&self, task: usize) -> Vec<String> {
        let (t, c) = self.tasks()[task];
        let (take, chunk) = (&self.takes[t], &self.takes[t].chunks[c]);
        let mut args = vec![
            "track".to_string(),
            path_arg(&take.capture),
            "-o".to_string(),
            path_arg(&chunk.part),
            "--frames".to_string(),
            format!("{}..{}", chunk.frames.start, chunk.frames.end),
            "--resume".to_string(),
        ];
        if chunk.locate {
            args.push("--locate".to_string());
        }
        args.extend(self.track_args.iter().cloned());
        args
    }

    /// Take `take`'s merge command line.
    pub fn merge_args(&self, take: usize) -> Vec<String> {
        let take = &self.takes[take];
        let mut args = vec!["merge".to_string(), path_arg(&take.capture)];
        args.extend(take.chunks.iter().map(|c| path_arg(&c.part)));
        args.extend([
            "-o".to_string(),
            path_arg(&take.output),
            "--force".to_string(),
        ]);
        args.extend(self.track_args.iter().cloned());
        args
    }

    /// The tasks whose chunk is not finished.
    pub fn unfinished(&self) -> Vec<usize> {
        self.progress()
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.finished)
            .map(|(i, _)| i)
            .collect()
    }

    /// How far each task has come.
    pub fn progress(&self) -> Vec<Progress> {
        self.tasks()
            .into_iter()
            .map(|(t, c)| progress(&self.takes[t].chunks[c]))
            .collect()
    }
}

fn path_arg(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// A chunk's progress from its files: the journal while it runs (or was stopped), its
/// tracks.json once finished. A file that does not read counts as nothing done.
fn progress(chunk: &Chunk) -> Progress {
    let frames = chunk.frames.len();
    let journal = journal_path(&chunk.part);
    if journal.exists() {
        // One line of head, then a line per frame (a last line cut off is not a frame).
        let done = std::fs::read_to_string(&journal)
            .map(|t| t.matches('\n').count().saturating_sub(1))
            .unwrap_or(0);
        return Progress {
            frames_done: done.min(frames),
            frames,
            finished: false,
        };
    }
    match read_json::<TracksJson>(&chunk.part, "tracks file") {
        Ok(tj) => {
            let done = tj
                .frames
                .iter()
                .filter(|r| chunk.frames.contains(&r.frame))
                .count();
            Progress {
                frames_done: done,
                frames,
                finished: done == frames,
            }
        }
        Err(_) => Progress {
            frames_done: 0,
            frames,
            finished: false,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(frames: Range<u32>, chunk: u32, overlap: u32) -> Plan {
        Plan::new(
            &[TakeFrames {
                capture: "/data/cap".into(),
                frames,
            }],
            chunk,
            overlap,
            Path::new("/out"),
            "/bin/jawtrack".into(),
            "/work".into(),
            vec!["--search".into(), "gauss-newton".into()],
        )
        .unwrap()
    }

    #[test]
    fn chunks_cover_the_take_and_overlap_the_one_before() {
        let p = plan(10..35, 10, 3);
        let frames: Vec<_> = p.takes[0].chunks.iter().map(|c| c.frames.clone()).collect();
        assert_eq!(frames, [10..20, 17..30, 27..35]);
        let locate: Vec<_> = p.takes[0].chunks.iter().map(|c| c.locate).collect();
        assert_eq!(locate, [false, true, true]);
        assert_eq!(p.tasks(), [(0, 0), (0, 1), (0, 2)]);
    }

    #[test]
    fn a_task_resumes_its_chunk_with_the_batch_options() {
        let p = plan(0..30, 10, 4);
        assert_eq!(
            p.task_args(1).join(" "),
            "track /data/cap -o /out/cap/parts/chunk-0001.json --frames 6..20 --resume --locate --search gauss-newton"
        );
        assert_eq!(
            p.merge_args(0).join(" "),
            "merge /data/cap /out/cap/parts/chunk-0000.json /out/cap/parts/chunk-0001.json /out/cap/parts/chunk-0002.json -o /out/cap/tracks.json --force --search gauss-newton"
        );
    }

    #[test]
    fn takes_of_the_same_name_get_their_own_folders() {
        let takes = [
            TakeFrames {
                capture: "/a/cap".into(),
                frames: 0..5,
            },
            TakeFrames {
                capture: "/b/cap".into(),
                frames: 0..5,
            },
        ];
        let p = Plan::new(
            &takes,
            10,
            2,
            Path::new("/out"),
            "j".into(),
            "/".into(),
            vec![],
        )
        .unwrap();
        assert_eq!(p.takes[0].output, Path::new("/out/cap/tracks.json"));
        assert_eq!(p.takes[1].output, Path::new("/out/cap-2/tracks.json"));
    }

    #[test]
    fn progress_reads_the_journal_then_the_finished_file() {
        let t = tempfile::tempdir().unwrap();
        let chunk = Chunk {
            frames: 4..7,
            locate: true,
            part: t.path().join("part.json"),
        };
        assert_eq!(progress(&chunk).frames_done, 0);
        std::fs::write(
            journal_path(&chunk.part),
            "{\"fingerprint\":\"x\"}\n{}\n{}\n{\"fr",
        )
        .unwrap();
        let p = progress(&chunk);
        assert_eq!((p.frames_done, p.finished), (2, false));
        std::fs::remove_file(journal_path(&chunk.part)).unwrap();
        let rec = |f: u32| {
            format!(
                r#"{{"frame": {f}, "upper": {{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}}, "lower": {{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}}}}"#
            )
        };
        let body = format!("{{\"frames\": [{}, {}, {}]}}", rec(4), rec(5), rec(6));
        std::fs::write(&chunk.part, body).unwrap();
        let p = progress(&chunk);
        assert_eq!((p.frames_done, p.frames, p.finished), (3, 3, true));
    }
}
