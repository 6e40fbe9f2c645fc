//! `jawtrack skin`: the jaw from the skin (Zoss et al. 2019) on face sequences.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use jawtrack::io::write_json_atomic;
use jawtrack::skin::carry::retarget_to;
use jawtrack::skin::eval::{Evaluation, evaluate};
use jawtrack::skin::format::{FaceSequence, subject_dirs};
use jawtrack::skin::model::{SkinModel, SkinSettings, learn_multi, learn_single, skin_points};
use jawtrack::skin::subject::Subject;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Learn a model from face sequences with jaw poses: one (a single-subject mapping) or
    /// several (the multi-subject mapping, the first as primary).
    Learn {
        /// Face sequence folders (each with face.json).
        #[arg(required = true)]
        faces: Vec<PathBuf>,
        /// The model file to write.
        #[arg(short, long)]
        out: PathBuf,
        /// Learn from the first N frames of a single subject only.
        #[arg(long, value_parser = clap::value_parser!(u32).range(8..))]
        first: Option<u32>,
        #[command(flatten)]
        settings: SettingsArg,
    },
    /// Carry a model to a new subject from its five calibration poses (face.json
    /// `calibration`, their poses in jaw.json), or from the teeth tracker's confident frames
    /// (`--tracks`: up to 24, spread over the motion; the better calibration).
    Retarget {
        model: PathBuf,
        face: PathBuf,
        /// tracks.json of the same capture (teeth tracker): its `ok` frames calibrate.
        #[arg(long)]
        tracks: Option<PathBuf>,
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        settings: SettingsArg,
    },
    /// Predict the jaw in every frame of a face sequence; writes a jawtrack-jaw/1 file.
    Predict {
        model: PathBuf,
        face: PathBuf,
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Fill the jaw of a tracks.json where the teeth tracker was not confident, from the skin:
    /// its confident frames retarget the model, which predicts the rest (`jaw_source` says
    /// which is which). The face sequence's frame numbers are the capture's.
    Fill {
        model: PathBuf,
        face: PathBuf,
        /// tracks.json of the same capture (teeth tracker).
        #[arg(long)]
        tracks: PathBuf,
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        settings: SettingsArg,
    },
    /// Leave-one-subject-out evaluation of a set of subjects (DIR/<name>/face.json), against
    /// the Procrustes baseline; a Table-1-style comparison.
    Eval {
        dir: PathBuf,
        /// Print the figures as JSON.
        #[arg(long)]
        json: bool,
        /// Write a plot of the error over frames (SVG), one panel per subject.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Also measure the multi-subject mapping carried with 10 and 24 calibration poses
        /// (the five, then frames spread over the sequence, as the teeth tracker gives them);
        /// several times the work.
        #[arg(long)]
        curve: bool,
        #[command(flatten)]
        settings: SettingsArg,
    },
}

#[derive(clap::Args)]
pub struct SettingsArg {
    /// A JSON file of settings (features, regress, retarget; see README).
    #[arg(long)]
    settings: Option<PathBuf>,
}

impl SettingsArg {
    fn read(&self) -> anyhow::Result<SkinSettings> {
        Ok(match &self.settings {
            None => SkinSettings::default(),
            Some(p) => jawtrack::io::read_json(p, "skin settings")?,
        })
    }
}

fn load(dir: &Path) -> anyhow::Result<Subject> {
    let seq = FaceSequence::open(dir)
        .with_context(|| format!("invalid face sequence {}", dir.display()))?;
    for f in &seq.unknown_fields {
        eprintln!(
            "note: {}: field `{f}` is not in the format and was ignored",
            dir.join("face.json").display()
        );
    }
    let name = dir
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("face")
        .to_string();
    let bar = super::progress_bar(seq.count as u64, &format!("reading {name}"));
    let s = Subject::load(&seq, &name, &|| bar.inc(1))
        .with_context(|| format!("invalid face sequence {}", dir.display()))?;
    bar.finish_and_clear();
    if let Some(note) = s.rest_note() {
        eprintln!("note: {note}");
    }
    Ok(s)
}

/// A model and a face sequence it can read (the same topology).
fn model_and_face(model: &Path, face: &Path) -> anyhow::Result<(SkinModel, Subject)> {
    let m = SkinModel::read(model)?;
    let s = load(face)?;
    m.check_topology(&s, &face.join("face.json"))?;
    Ok((m, s))
}

/// `out` may replace neither a file the command reads nor anything in a face folder (its
/// jaw.json is the ground truth).
fn guard(out: &Path, files: &[&Path], faces: &[&Path]) -> anyhow::Result<()> {
    jawtrack::io::check_replaceable(out)?;
    let reads = jawtrack::io::Reads {
        files: files.to_vec(),
        folders: faces.to_vec(),
    };
    jawtrack::io::check_outputs(&reads, &[out])?;
    Ok(())
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Learn {
            faces,
            out,
            first,
            settings,
        } => learn(&faces, &out, first, &settings),
        Command::Retarget {
            model,
            face,
            tracks,
            out,
            settings,
        } => retarget(&model, &face, tracks.as_deref(), &out, &settings),
        Command::Predict { model, face, out } => predict(&model, &face, &out),
        Command::Fill {
            model,
            face,
            tracks,
            out,
            settings,
        } => fill(&model, &face, &tracks, &out, &settings),
        Command::Eval {
            dir,
            json,
            plot,
            curve,
            settings,
        } => eval(&dir, json, plot.as_deref(), curve, &settings),
    }
}

/// `skin learn`: learn a single- or multi-subject model from the face sequences and write it.
fn learn(
    faces: &[PathBuf],
    out: &Path,
    first: Option<u32>,
    settings: &SettingsArg,
) -> anyhow::Result<()> {
    let settings = settings.read()?;
    let folders: Vec<&Path> = faces.iter().map(PathBuf::as_path).collect();
    guard(out, &[], &folders)?;
    let subjects = faces
        .iter()
        .map(|d| load(d))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let clock = Instant::now();
    let model = if subjects.len() == 1 {
        let s = &subjects[0];
        let n = first.map_or(s.frames.len(), |f| (f as usize).min(s.frames.len()));
        let rows: Vec<usize> = (0..n).collect();
        learn_single(s, None, &rows, &settings)?
    } else {
        // The pooled mapping, and every subject's own beside it for retargeting to weigh.
        let refs: Vec<&Subject> = subjects.iter().collect();
        let points = skin_points(&subjects[0], &settings)?;
        let own = subjects
            .iter()
            .map(|s| {
                let rows: Vec<usize> = (0..s.frames.len()).collect();
                learn_single(s, Some(points.clone()), &rows, &settings)
            })
            .collect::<jawtrack::error::Result<Vec<_>>>()?;
        let (pooled, _) = learn_multi(&refs, Some(points), Some(&own[0]), &settings)?;
        pooled.with_sources(
            subjects
                .iter()
                .zip(&own)
                .map(|(s, m)| (s.name.clone(), m))
                .collect(),
        )
    };
    write_json_atomic(out, &model)?;
    let r = &model.regressor;
    println!(
        "learned from {} ({} frames used, {} skin points, {} components, {} support vectors) in {:.1} s",
        model.trained_on.join(", "),
        r.samples,
        model.skin_points.len(),
        r.components,
        r.support.len(),
        clock.elapsed().as_secs_f64()
    );
    println!(
        "chosen on held-out frames: kernel width {} x median, C {}: bone points {:.3} mm there",
        r.width_multiple, r.penalty, r.held_out_mm
    );
    println!("wrote {}", out.display());
    Ok(())
}

/// `skin retarget`: carry the model to a new subject from its calibration poses, or from the
/// confident frames of a tracks.json, and write it.
fn retarget(
    model: &Path,
    face: &Path,
    tracks: Option<&Path>,
    out: &Path,
    settings: &SettingsArg,
) -> anyhow::Result<()> {
    let settings = settings.read()?;
    let reads: Vec<&Path> = [Some(model), tracks].into_iter().flatten().collect();
    guard(out, &reads, &[face])?;
    let (m, target) = model_and_face(model, face)?;
    let (r, report) = match tracks {
        Some(t) => {
            let tracked = jawtrack::formats::read_tracks(t)?;
            let (r, fr) = jawtrack::skin::fill::retarget_from_tracks(
                &m,
                &target,
                &tracked,
                t,
                &settings.retarget,
            )?;
            println!(
                "calibrated on {} of the {} confident frames of {} ({:?})",
                fr.calibration_frames.len(),
                fr.teeth_frames,
                t.display(),
                fr.calibration_frames
            );
            if !fr.left_out.is_empty() {
                println!(
                    "left out of the calibration, their teeth pose far from what the skin says: frames {:?}",
                    fr.left_out
                );
            }
            (r, fr.retarget)
        }
        None => retarget_to(&m, &target, &settings.retarget)?,
    };
    write_json_atomic(out, &r)?;
    println!(
        "retargeted to {}: the best-scored way ({}) takes Σ|Φ − B|² {:.3} → {:.3} mm² in {} steps",
        target.name, report.carried, report.cost_before, report.cost_after, report.iterations
    );
    print_choice(&report);
    println!("wrote {}", out.display());
    Ok(())
}

/// Say how the mapping was carried: every way's (and mapping's) score on the calibration
/// poses left out, and its weight in the blend.
fn print_choice(report: &jawtrack::skin::retarget::RetargetReport) {
    let scored: Vec<_> = report
        .candidates
        .iter()
        .filter(|c| c.mm.is_finite())
        .collect();
    if scored.len() < 2 {
        let score = scored
            .first()
            .map(|c| {
                format!(
                    ", bone points on the calibration poses left out {:.3} mm",
                    c.mm
                )
            })
            .unwrap_or_default();
        println!("carried: {}{score}", report.carried);
        return;
    }
    println!("carried by a blend: bone points on the calibration poses left out (mm), weight");
    for c in scored {
        let weight = report
            .blend
            .iter()
            .find(|b| b.0 == c.carry)
            .map_or(0.0, |b| b.1);
        println!(
            "  {:<44} {:.3} ± {:.3}  {weight:.2}",
            c.carry, c.mm, c.standard_error_mm
        );
    }
}

/// `skin predict`: predict the jaw in every frame, write the poses and report their error.
fn predict(model: &Path, face: &Path, out: &Path) -> anyhow::Result<()> {
    guard(out, &[model], &[face])?;
    let (m, s) = model_and_face(model, face)?;
    let clock = Instant::now();
    let poses = m.predict_sequence(&s);
    let per_frame = clock.elapsed().as_secs_f64() * 1e3 / poses.len().max(1) as f64;
    jawtrack::formats::write_jaw_poses(out, &s.frames, &poses)?;
    println!(
        "predicted {} frames, {per_frame:.3} ms a frame (reading excluded)",
        poses.len()
    );
    let errors = s.errors_against_jaw(&poses);
    if !errors.is_empty() {
        let st = jawtrack::stats::Stats::of(&errors);
        println!(
            "against the jaw poses in the sequence ({} frames): mean {:.3}, median {:.3}, p95 {:.3} mm",
            errors.len(),
            st.mean,
            st.median,
            st.p95
        );
    }
    println!("wrote {}", out.display());
    Ok(())
}

/// `skin fill`: fill the unconfident frames of a tracks.json from the skin and write it.
fn fill(
    model: &Path,
    face: &Path,
    tracks: &Path,
    out: &Path,
    settings: &SettingsArg,
) -> anyhow::Result<()> {
    let settings = settings.read()?;
    guard(out, &[model, tracks], &[face])?;
    let (m, s) = model_and_face(model, face)?;
    let t = jawtrack::formats::read_tracks(tracks)?;
    let (filled, r) = jawtrack::skin::fill::fill(&m, &s, &t, tracks, &settings.retarget)?;
    write_json_atomic(out, &filled)?;
    println!(
        "{} frames from the teeth, {} from the skin; retargeted on {} confident frames ({:?}): Σ|Φ − B|² {:.3} → {:.3} mm²",
        r.teeth_frames,
        r.skin_frames,
        r.calibration_frames.len(),
        r.calibration_frames,
        r.retarget.cost_before,
        r.retarget.cost_after
    );
    print_choice(&r.retarget);
    if !r.left_out.is_empty() {
        println!(
            "left out of the calibration, their teeth pose far from what the skin says: frames {:?}",
            r.left_out
        );
    }
    println!("wrote {}", out.display());
    Ok(())
}

/// `skin eval`: leave-one-subject-out evaluation of the subjects in `dir`, as JSON or a table.
fn eval(
    dir: &Path,
    json: bool,
    plot: Option<&Path>,
    curve: bool,
    settings: &SettingsArg,
) -> anyhow::Result<()> {
    let settings = settings.read()?;
    if let Some(p) = plot {
        jawtrack::io::check_replaceable(p)?;
    }
    let dirs = subject_dirs(dir)?;
    let subjects = dirs
        .iter()
        .map(|(_, d)| load(d))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let e = evaluate(dir, &subjects, &settings, curve, &|m| eprintln!("{m}"))?;
    if let Some(p) = plot {
        jawtrack::skin::plot::error_over_frames(p, &e)?;
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&summary(&e))?);
    } else {
        print_table(&e);
    }
    Ok(())
}

/// The figures without the per-frame series.
fn summary(e: &Evaluation) -> serde_json::Value {
    let mut v = serde_json::to_value(e).expect("plain data");
    if let Some(list) = v.get_mut("subjects").and_then(|s| s.as_array_mut()) {
        for s in list {
            if let Some(o) = s.as_object_mut() {
                o.remove("series");
            }
        }
    }
    v
}

fn print_table(e: &Evaluation) {
    println!("mean error over the mandible's vertices (mm); bone points in brackets");
    println!(
        "{:<8} {:>16} {:>26} {:>18} {:>13} {:>16}  won",
        "subject", "single", "best source, retargeted", "multi-subject", "uncalibrated", "baseline"
    );
    for s in &e.subjects {
        println!(
            "{:<8} {:>7.3} ({:>6.3}) {:>8.3} ({:>6.3}) {:<9} {:>8.3} ({:>6.3}) {:>13.3} {:>7.3} ({:>6.3})  {}",
            s.name,
            s.single_mm,
            s.single_bone_mm,
            s.retargeted_mm,
            s.retargeted_bone_mm,
            s.retargeted_from,
            s.multi_subject_mm,
            s.multi_subject_bone_mm,
            s.uncalibrated_mm,
            s.baseline_mm,
            s.baseline_bone_mm,
            s.won
        );
    }
    println!(
        "single: learned on the first {:.0}% of each subject's frames, tested on the rest; the others: leave-one-subject-out, every frame",
        jawtrack::skin::eval::SINGLE_TRAIN_SHARE * 100.0
    );
    println!(
        "best source: the other subject whose retargeted mapping errs least on this one's frames (known only with its truth); won: the lowest of the four that see only the five calibration poses"
    );
    for s in &e.subjects {
        let weights: Vec<String> = s
            .multi_subject_weights
            .iter()
            .map(|(n, w)| format!("{n} {w:.2}"))
            .collect();
        let curve: Vec<String> = s
            .calibration_curve
            .iter()
            .map(|(n, mm)| format!("{n}: {mm:.3}"))
            .collect();
        println!(
            "{}: best source's best rung {}; pooled mapping {:.3} mm (best rung {}); multi-subject weights {}; with more calibration poses {}",
            s.name,
            s.retargeted_carried,
            s.pooled_mm,
            s.pooled_carried,
            weights.join(", "),
            curve.join(", ")
        );
    }
    println!(
        "learning {:.1} s a subject ({} frames); prediction {:.3} ms a frame; {:.0} s in all",
        e.learn_s, e.learn_frames, e.predict_ms, e.seconds
    );
}
