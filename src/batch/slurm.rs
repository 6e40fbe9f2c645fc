//! A batch as Slurm jobs: a job array with a task per chunk (`track.sbatch`) and a merge job
//! that waits for all of them (`merge.sbatch`). Tasks are requeued when preempted, and every
//! task resumes its chunk, so running one again never loses finished frames;
//! [`submit`] sends only the tasks not yet finished.

use std::path::Path;
use std::process::Command;

use serde::{Deserialize, Serialize};

use super::Plan;
use crate::error::{Error, Result};
use crate::io::{read_json, write_atomic, write_json_atomic};

pub const TRACK_SCRIPT: &str = "track.sbatch";
pub const MERGE_SCRIPT: &str = "merge.sbatch";
const JOBS_FILE: &str = "jobs.json";

/// What each job asks Slurm for.
#[derive(Debug, Clone, Default)]
pub struct Resources {
    pub partition: Option<String>,
    /// Wall-clock limit, in Slurm's forms (`MM`, `HH:MM:SS`, `D-HH`).
    pub time: Option<String>,
    pub cpus: u32,
    pub gpus: u32,
}

/// One submission: the array job (absent when every chunk was finished), the tasks it runs,
/// and the merge job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Submission {
    pub array_job: Option<String>,
    pub tasks: Vec<usize>,
    pub merge_job: String,
}

/// Write `track.sbatch` and `merge.sbatch` for `plan` into `dir` (and its `logs/`).
pub fn write_scripts(plan: &Plan, dir: &Path, resources: &Resources) -> Result<()> {
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(|error| Error::Write {
        path: logs.clone(),
        error,
    })?;
    let track = dir.join(TRACK_SCRIPT);
    let merge = dir.join(MERGE_SCRIPT);
    let tasks = plan.tasks().len();
    let mut text = header(
        plan,
        &track,
        "jawtrack-track",
        &logs.join("track-%a.log"),
        resources,
    )?;
    // The scripts' own lines, then the options: a directive after the first command is
    // ignored by sbatch.
    text.insert_str(
        text.find("#SBATCH").unwrap_or(0),
        &format!(
            "#SBATCH --array=0-{}\n#SBATCH --requeue\n",
            tasks.max(1) - 1
        ),
    );
    text.push_str(
        "case \"${SLURM_ARRAY_TASK_ID:?run this script as a job array (sbatch --array)}\" in\n",
    );
    for task in 0..tasks {
        text.push_str(&format!(
            "  {task}) exec \"$JAWTRACK\" {} ;;\n",
            quoted(&track, &plan.task_args(task))?
        ));
    }
    text.push_str(
        "  *) echo \"task $SLURM_ARRAY_TASK_ID: not in this batch's plan\" >&2; exit 2 ;;\nesac\n",
    );
    write_atomic(&track, text.as_bytes())?;

    let mut text = header(
        plan,
        &merge,
        "jawtrack-merge",
        &logs.join("merge.log"),
        resources,
    )?;
    text.push_str("failed=0\n");
    for take in 0..plan.takes.len() {
        text.push_str(&format!(
            "\"$JAWTRACK\" {} || failed=1\n",
            quoted(&merge, &plan.merge_args(take))?
        ));
    }
    text.push_str("exit \"$failed\"\n");
    write_atomic(&merge, text.as_bytes())
}

/// A script's first lines: the directives every job shares, the binary, the threads.
fn header(plan: &Plan, script: &Path, name: &str, log: &Path, r: &Resources) -> Result<String> {
    let mut text = format!(
        "#!/bin/bash\n# Written by `jawtrack batch slurm` from {}; `jawtrack batch submit` sends it.\n",
        script.with_file_name("plan.json").display()
    );
    let mut directive = |option: &str, value: &str| -> Result<()> {
        if value.contains(['"', '\n']) {
            return Err(Error::invalid(
                script,
                option,
                format!("{value:?}: a Slurm option cannot hold quotes or newlines"),
            ));
        }
        let value = if value.contains(char::is_whitespace) {
            format!("\"{value}\"")
        } else {
            value.to_string()
        };
        text.push_str(&format!("#SBATCH --{option}={value}\n"));
        Ok(())
    };
    directive("job-name", name)?;
    directive("output", &log.to_string_lossy())?;
    directive("open-mode", "append")?;
    directive("chdir", &plan.workdir.to_string_lossy())?;
    directive("cpus-per-task", &r.cpus.max(1).to_string())?;
    if let Some(p) = &r.partition {
        directive("partition", p)?;
    }
    if let Some(t) = &r.time {
        directive("time", t)?;
    }
    if r.gpus > 0 {
        directive("gres", &format!("gpu:{}", r.gpus))?;
    }
    text.push_str(&format!(
        "set -uo pipefail\nJAWTRACK=\"${{JAWTRACK:-{}}}\"\n\
         # The energy's threads: the cores Slurm gave the task.\n\
         export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n",
        quoted(script, &[plan.jawtrack.to_string_lossy().into_owned()])?
    ));
    Ok(text)
}

fn quoted(script: &Path, args: &[String]) -> Result<String> {
    shlex::try_join(args.iter().map(String::as_str)).map_err(|e| {
        Error::invalid(
            script,
            "command",
            format!("an argument cannot be written for the shell: {e}"),
        )
    })
}

/// Submit the tasks of `plan` not yet finished, and a merge job that runs once they all
/// succeed (cancelled by Slurm if one fails: `batch status` tells which, and submitting again
/// runs what is left). Each submission is added to `dir/jobs.json`.
pub fn submit(plan: &Plan, dir: &Path) -> Result<Submission> {
    let tasks = plan.unfinished();
    let track = dir.join(TRACK_SCRIPT);
    let merge = dir.join(MERGE_SCRIPT);
    for script in [&track, &merge] {
        if !script.exists() {
            return Err(Error::Missing {
                path: script.clone(),
                what: "Slurm script (written by `jawtrack batch slurm`)".to_string(),
            });
        }
    }
    let array_job = if tasks.is_empty() {
        None
    } else {
        Some(sbatch(
            &track,
            &[format!("--array={}", ranges(&tasks)), "--parsable".into()],
        )?)
    };
    let mut args = vec!["--parsable".to_string()];
    if let Some(id) = &array_job {
        args.push(format!("--dependency=afterok:{id}"));
        args.push("--kill-on-invalid-dep=yes".into());
    }
    let merge_job = sbatch(&merge, &args)?;
    let submission = Submission {
        array_job,
        tasks,
        merge_job,
    };
    let jobs = dir.join(JOBS_FILE);
    let mut all = submissions(dir)?;
    all.push(submission.clone());
    write_json_atomic(&jobs, &all)?;
    Ok(submission)
}

/// The submissions made so far from `dir`, oldest first.
pub fn submissions(dir: &Path) -> Result<Vec<Submission>> {
    let jobs = dir.join(JOBS_FILE);
    if jobs.exists() {
        read_json(&jobs, "job list")
    } else {
        Ok(Vec::new())
    }
}

/// `sbatch ARGS SCRIPT`, answering the job id.
fn sbatch(script: &Path, args: &[String]) -> Result<String> {
    let failed = |problem: String| Error::Command {
        path: script.to_path_buf(),
        program: "sbatch".to_string(),
        problem,
    };
    let out = Command::new("sbatch")
        .args(args)
        .arg(script)
        .output()
        .map_err(|e| failed(format!("cannot run it ({e}); is Slurm installed here?")))?;
    if !out.status.success() {
        return Err(failed(
            String::from_utf8_lossy(&out.stderr).trim().to_string(),
        ));
    }
    // --parsable: "id" or "id;cluster".
    let text = String::from_utf8_lossy(&out.stdout);
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(failed(format!("answered {:?}, not a job id", text.trim())));
    }
    Ok(id)
}

/// Task numbers as Slurm's array list: `0-3,5,7-8`.
fn ranges(tasks: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < tasks.len() {
        let mut j = i;
        while j + 1 < tasks.len() && tasks[j + 1] == tasks[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            tasks[i].to_string()
        } else {
            format!("{}-{}", tasks[i], tasks[j])
        });
        i = j + 1;
    }
    out.join(",")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::TakeFrames;

    #[test]
    fn array_lists_join_runs_of_tasks() {
        assert_eq!(ranges(&[0, 1, 2, 3, 5, 7, 8]), "0-3,5,7-8");
        assert_eq!(ranges(&[4]), "4");
    }

    #[test]
    fn the_array_script_runs_each_chunk_and_quotes_paths() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("my batch");
        let plan = Plan::new(
            &[TakeFrames {
                capture: "/data/take one".into(),
                frames: 0..20,
            }],
            10,
            3,
            &dir,
            "/opt/jawtrack".into(),
            "/work".into(),
            vec!["--settings".into(), "{\"window\": {\"frames\": 4}}".into()],
        )
        .unwrap();
        let resources = Resources {
            partition: Some("gpu".into()),
            cpus: 4,
            gpus: 1,
            ..Resources::default()
        };
        write_scripts(&plan, &dir, &resources).unwrap();
        let track = std::fs::read_to_string(dir.join(TRACK_SCRIPT)).unwrap();
        for line in [
            "#SBATCH --array=0-1\n",
            "#SBATCH --requeue\n",
            "#SBATCH --partition=gpu\n",
            "#SBATCH --cpus-per-task=4\n",
            "#SBATCH --gres=gpu:1\n",
            "  1) exec \"$JAWTRACK\" track '/data/take one' -o '",
            "--frames 7..20 --resume --locate --settings '{\"window\": {\"frames\": 4}}' ;;\n",
        ] {
            assert!(track.contains(line), "{line:?} not in\n{track}");
        }
        let output = format!("#SBATCH --output=\"{}", dir.join("logs").display());
        assert!(track.contains(&output), "{track}");
        let merge = std::fs::read_to_string(dir.join(MERGE_SCRIPT)).unwrap();
        assert!(
            merge.contains("\"$JAWTRACK\" merge '/data/take one' '"),
            "{merge}"
        );
        assert!(!merge.contains("--array"), "{merge}");
    }
}
