//! `jawtrack bench skin`: the jaw from the skin's speed and single-subject accuracy on a long
//! synthetic subject, written to a temporary folder: learning time on all its frames, then a
//! model learned on the first 60% scored on the rest, and the time a prediction takes.

use std::time::Instant;

use jawtrack::skin::format::FaceSequence;
use jawtrack::skin::model::{SkinSettings, learn_single};
use jawtrack::skin::subject::Subject;
use jawtrack::stats::Stats;
use jawtrack::synth::face::{FaceSynthOptions, generate_faces};

#[derive(clap::Args)]
pub struct SkinArgs {
    /// Frames of the synthetic subject.
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u32).range(200..=20_000))]
    frames: u32,
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
}

pub fn skin(a: SkinArgs) -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    let dir = tmp.path().join("faces");
    let opts = FaceSynthOptions {
        subjects: 1,
        frames: a.frames,
        seed: a.seed,
        ..FaceSynthOptions::default()
    };
    generate_faces(&dir, &opts, &|| {})?;
    let settings = SkinSettings::default();
    let clock = Instant::now();
    let seq = FaceSequence::open(&dir.join("s1"))?;
    let s = Subject::load(&seq, "s1", &|| {})?;
    let read_s = clock.elapsed().as_secs_f64();
    let all: Vec<usize> = (0..s.frames.len()).collect();
    let clock = Instant::now();
    learn_single(&s, None, &all, &settings)?;
    let learn_s = clock.elapsed().as_secs_f64() + read_s;
    let cut = (s.frames.len() as f64 * jawtrack::skin::eval::SINGLE_TRAIN_SHARE) as usize;
    let m = learn_single(&s, None, &all[..cut], &settings)?;
    let clock = Instant::now();
    let poses: Vec<_> = all[cut..]
        .iter()
        .map(|&i| m.predict(&s.skin_features(&m.skin_points, i)))
        .collect();
    let predict_ms = clock.elapsed().as_secs_f64() * 1e3 / poses.len().max(1) as f64;
    let errors: Vec<f64> = all[cut..]
        .iter()
        .zip(&poses)
        .map(|(&i, p)| {
            s.metric
                .mean_distance(p, &s.jaw[i].expect("synthetic subjects have every pose"))
        })
        .collect();
    let st = Stats::of(&errors);
    if a.json {
        println!(
            "{}",
            serde_json::json!({"frames": a.frames, "learn_s": learn_s, "read_s": read_s, "predict_ms": predict_ms,
                "train_frames": cut, "test_frames": errors.len(), "test_mm": st})
        );
        return Ok(());
    }
    println!(
        "one synthetic subject of {} frames (seed {}):",
        a.frames, a.seed
    );
    println!("  learning on every frame: {learn_s:.1} s (reading the frames {read_s:.1} s of it)");
    println!(
        "  learned on the first {cut}, tested on the last {}: mean {:.3}, median {:.3}, p95 {:.3} mm over the mandible's vertices",
        errors.len(),
        st.mean,
        st.median,
        st.p95
    );
    println!("  prediction (features, mapping, rigid fit): {predict_ms:.3} ms a frame");
    Ok(())
}
