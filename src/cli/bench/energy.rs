//! `jawtrack bench energy`: evaluations per second of every energy backend, and how fast each
//! engine computes the smooth energy's edge terms (a Gauss-Newton step's); one synthetic
//! capture per mesh case, three cameras, half-resolution masks.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use jawtrack::arch::{Arch, ArchPoses};
use jawtrack::capture::{Capture, FrameMasks, MaskMode, OpenOptions};
use jawtrack::energy::contour::ContourEdges;
use jawtrack::energy::edge_terms::{EdgeParams, EdgeQuery};
use jawtrack::energy::gpu::GpuEnergy;
use jawtrack::energy::smooth;
use jawtrack::energy::{CpuEnergy, EnergyEngine, Region, Scene, Weights};
use jawtrack::geometry::Camera;
use jawtrack::synth::{Preset, SynthOptions, generate};
use jawtrack::track::GaussNewtonSettings;
use nalgebra::Vector6;

#[derive(clap::Args)]
pub struct EnergyArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Seconds to spend on each measurement (at least two runs each).
    #[arg(long, default_value_t = 1.0)]
    seconds: f64,
    /// Folder with the real scans (upper.obj, lower.obj); skipped when absent.
    #[arg(long, default_value = "../shared/data/scan-tag0")]
    scans: PathBuf,
    /// Triangles per arch of the simplified scan.
    #[arg(long, default_value_t = 10_000)]
    simplified: usize,
    /// Candidates per batch.
    #[arg(long, default_value_t = 64)]
    batch: usize,
    /// Which backends to time.
    #[arg(long, value_delimiter = ',', default_value = "cpu,gpu,readback", value_parser = ["cpu", "gpu", "readback"])]
    backends: Vec<String>,
}

#[derive(serde::Serialize)]
struct Row {
    mesh: String,
    triangles: usize,
    backend: String,
    region: String,
    batch: usize,
    ms_per_evaluation: f64,
    evaluations_per_second: f64,
}

/// The smooth energy's edge terms of both arches at one pose, as a Gauss-Newton step asks
/// for them.
#[derive(serde::Serialize)]
struct EdgeRow {
    mesh: String,
    backend: String,
    samples: usize,
    ms_per_query: f64,
    samples_per_second: f64,
}

#[derive(serde::Serialize)]
struct Report {
    machine: String,
    adapter: Option<String>,
    rows: Vec<Row>,
    edge_terms: Vec<EdgeRow>,
}

/// Candidates around the truth: small moves of the lower arch, as a search makes them.
fn candidates(truth: &ArchPoses, n: usize) -> Vec<ArchPoses> {
    (0..n)
        .map(|k| {
            let mut d = [0.0; 6];
            d[k % 6] = (k as f64 / n as f64 - 0.5) * if k % 6 < 3 { 0.02 } else { 1.0 };
            truth.with(Arch::Lower, truth.lower.with_euler_offset(&d))
        })
        .collect()
}

/// Mean time per evaluation of `batch` candidates, over at least two runs and `seconds`.
fn time(engine: &dyn EnergyEngine, batch: &[ArchPoses], seconds: f64) -> anyhow::Result<f64> {
    engine.evaluate(Arch::Lower, batch)?; // warm-up
    let budget = Duration::from_secs_f64(seconds);
    let started = Instant::now();
    let mut runs = 0;
    while runs < 2 || started.elapsed() < budget {
        engine.evaluate(Arch::Lower, batch)?;
        runs += 1;
    }
    Ok(started.elapsed().as_secs_f64() / (runs * batch.len()) as f64)
}

/// A mesh case: its name, scan folder, how the arches are simplified at load, lens.
type Case<'a> = (
    String,
    Option<&'a Path>,
    OpenOptions,
    Option<jawtrack::geometry::Distortion>,
);

/// A backend to time: its label, the region it evaluates and the engine.
type Engine = (String, Region, Box<dyn EnergyEngine>);

pub fn energy(a: EnergyArgs) -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    let cases = mesh_cases(&a);
    let mut report = Report {
        machine: format!("{} CPU threads", rayon::current_num_threads()),
        adapter: None,
        rows: Vec::new(),
        edge_terms: Vec::new(),
    };
    for case in cases {
        measure_case(&a, tmp.path(), case, &mut report)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

/// The procedural arch (with and without a lens), then the real scans in full, at the default
/// simplification and simplified to `a.simplified` triangles when they are present.
fn mesh_cases(a: &EnergyArgs) -> Vec<Case<'_>> {
    let full = OpenOptions {
        simplify_mm: Some(0.0),
        ..OpenOptions::default()
    };
    let lens = Some(jawtrack::synth::BARREL_LENS);
    let mut cases: Vec<Case> = vec![
        ("procedural".into(), None, full, None),
        ("procedural, barrel lens".into(), None, full, lens),
    ];
    if a.scans.join("upper.obj").exists() {
        let scans = Some(a.scans.as_path());
        cases.push(("scan-tag0".into(), scans, full, None));
        cases.push((
            "scan-tag0, default simplification".to_string(),
            scans,
            OpenOptions::default(),
            None,
        ));
        cases.push((
            "scan-tag0 simplified".to_string(),
            scans,
            OpenOptions {
                max_triangles: Some(a.simplified),
                ..full
            },
            None,
        ));
    } else {
        eprintln!("no scans at {}: procedural arch only", a.scans.display());
    }
    cases
}

/// Times every backend asked for on one mesh case and adds its rows to `report`.
fn measure_case(
    a: &EnergyArgs,
    tmp: &Path,
    case: Case<'_>,
    report: &mut Report,
) -> anyhow::Result<()> {
    let (name, meshes, open, distortion) = case;
    let capture = open_capture(tmp, meshes, open, distortion)?;
    let masks = capture.load_masks(3)?;
    let truth = capture
        .gt_poses(3)
        .context("benchmark capture without ground truth")?;
    let batch = candidates(&truth, a.batch);
    let scene = Scene::from_capture(&capture);
    let triangles = capture.lower().triangles.len();
    let mut engines = backends_to_time(&scene, &a.backends, &mut report.adapter)?;
    check_agreement(&mut engines, &masks, &batch)?;
    for (label, region, engine) in &engines {
        for n in [1, a.batch] {
            let s = time(engine.as_ref(), &batch[..n], a.seconds)?;
            eprintln!(
                "{name}: {label} {} batch {n}: {:.3} ms",
                region.name(),
                s * 1e3
            );
            report.rows.push(Row {
                mesh: name.clone(),
                triangles,
                backend: label.clone(),
                region: region.name().to_string(),
                batch: n,
                ms_per_evaluation: s * 1e3,
                evaluations_per_second: 1.0 / s,
            });
        }
    }
    time_edge_terms(a, &capture, &name, &engines, &truth, report)
}

/// Times each engine's edge terms (once per backend) at the samples of both arches drawn
/// near the truth, with Gauss-Newton's default spacing and its finest reach.
fn time_edge_terms(
    a: &EnergyArgs,
    capture: &Capture,
    name: &str,
    engines: &[Engine],
    truth: &ArchPoses,
    report: &mut Report,
) -> anyhow::Result<()> {
    let gn = GaussNewtonSettings::default();
    let edges = [
        ContourEdges::of(capture.upper()),
        ContourEdges::of(capture.lower()),
    ];
    let (indices, cameras): (Vec<usize>, Vec<Camera>) = capture
        .cameras()
        .iter()
        .enumerate()
        .filter_map(|(k, c)| Some((k, c.mask_camera()?)))
        .unzip();
    let views: Vec<&Camera> = cameras.iter().collect();
    let poses = candidates(truth, 2)[0];
    let arches = [(capture.upper(), &edges[0]), (capture.lower(), &edges[1])];
    let apart = matches!(capture.mask_mode(), MaskMode::PerArch { .. });
    let samples = smooth::samples(arches, &poses, &views, apart, gn.spacing_px);
    let q = EdgeQuery {
        samples: &samples,
        cameras: &indices,
        moved: [Vector6::zeros(); 2],
        params: EdgeParams {
            reach_px: gn.reaches_px.last().copied().unwrap_or(1.0),
            smoothing_px: gn.smoothing_px,
            weights: Weights {
                lambda: 0.4,
                cross: 1.0,
                mouth: 1.0,
            },
            level: 0,
        },
    };
    let mut timed: Vec<&str> = Vec::new();
    for (label, _, engine) in engines {
        if label == "readback" || timed.contains(&label.as_str()) {
            continue;
        }
        timed.push(label);
        engine.edge_terms(&q)?; // warm-up
        let budget = Duration::from_secs_f64(a.seconds);
        let started = Instant::now();
        let mut runs = 0;
        while runs < 2 || started.elapsed() < budget {
            engine.edge_terms(&q)?;
            runs += 1;
        }
        let s = started.elapsed().as_secs_f64() / runs as f64;
        eprintln!(
            "{name}: {label} edge terms, {} samples: {:.3} ms",
            samples.len(),
            s * 1e3
        );
        report.edge_terms.push(EdgeRow {
            mesh: name.to_string(),
            backend: label.clone(),
            samples: samples.len(),
            ms_per_query: s * 1e3,
            samples_per_second: samples.len() as f64 / s,
        });
    }
    Ok(())
}

/// Opens the synthetic capture of a mesh case, synthesising it in `tmp` the first time its
/// kind of mesh is asked for.
fn open_capture(
    tmp: &Path,
    meshes: Option<&Path>,
    open: OpenOptions,
    distortion: Option<jawtrack::geometry::Distortion>,
) -> anyhow::Result<Capture> {
    let dir = tmp.join(match (meshes.is_some(), distortion.is_some()) {
        (true, _) => "scan",
        (false, false) => "procedural",
        (false, true) => "procedural-lens",
    });
    if !dir.exists() {
        let opts = SynthOptions {
            frames: 6,
            preset: Preset::Realistic,
            meshes: meshes.map(Path::to_path_buf),
            distortion,
            ..SynthOptions::default()
        };
        generate(&dir, &opts, &|| {}).context("synthesising the benchmark capture")?;
    }
    Ok(Capture::open_with(&dir, open)?)
}

/// The engines of the backends in `backends`, one per region each supports; a GPU engine
/// records its adapter in `adapter`.
fn backends_to_time(
    scene: &Scene,
    backends: &[String],
    adapter: &mut Option<String>,
) -> anyhow::Result<Vec<Engine>> {
    let mut engines: Vec<Engine> = Vec::new();
    let want = |b: &str| backends.iter().any(|x| x == b);
    for region in [Region::Relevant, Region::Footprint, Region::FullFrame] {
        if want("cpu") {
            engines.push((
                "cpu".into(),
                region,
                Box::new(CpuEnergy::with_region(scene.clone(), region)),
            ));
        }
        // The GPU engine draws the footprint for `Energy`.
        if want("gpu") && region != Region::Relevant {
            match GpuEnergy::new(scene.clone(), region) {
                Ok(g) => {
                    *adapter = Some(g.context().describe());
                    engines.push(("gpu".into(), region, Box::new(g)));
                }
                Err(e) => eprintln!("gpu: {e}"),
            }
        }
    }
    if want("readback") {
        match GpuEnergy::readback_baseline(scene.clone()) {
            Ok(g) => engines.push(("readback".into(), Region::FullFrame, Box::new(g))),
            Err(e) => eprintln!("readback: {e}"),
        }
    }
    anyhow::ensure!(!engines.is_empty(), "no backend to time");
    Ok(engines)
}

/// Sets every engine to `masks` and checks each agrees with the first on one candidate before
/// it is timed (within a few pixels: see tests/gpu_energy.rs).
fn check_agreement(
    engines: &mut [Engine],
    masks: &FrameMasks,
    batch: &[ArchPoses],
) -> anyhow::Result<()> {
    let reference = engines[0].2.as_mut();
    reference.set_frame(masks)?;
    let expected = reference.evaluate(Arch::Lower, &batch[..1])?[0].total(0.4);
    for (label, region, engine) in engines.iter_mut() {
        engine.set_frame(masks)?;
        let got = engine.evaluate(Arch::Lower, &batch[..1])?[0].total(0.4);
        anyhow::ensure!(
            (got - expected).abs() <= 5.0,
            "{label} {} energy {got} differs from the CPU reference's {expected}",
            region.name()
        );
    }
    Ok(())
}

/// Prints the report as a table, one row per mesh, backend, region and batch size.
fn print_table(report: &Report) {
    println!(
        "energy of one arch, three cameras, 960x540 masks; {}; adapter: {}",
        report.machine,
        report.adapter.as_deref().unwrap_or("none")
    );
    println!(
        "{:<22} {:>9} {:<9} {:<14} {:>5} {:>11} {:>10}",
        "mesh", "triangles", "backend", "region", "batch", "ms/eval", "evals/s"
    );
    for r in &report.rows {
        println!(
            "{:<22} {:>9} {:<9} {:<14} {:>5} {:>11.3} {:>10.1}",
            r.mesh,
            r.triangles,
            r.backend,
            r.region,
            r.batch,
            r.ms_per_evaluation,
            r.evaluations_per_second
        );
    }
    println!("\nthe smooth energy's edge terms of both arches (a Gauss-Newton step's)");
    println!(
        "{:<34} {:<9} {:>8} {:>10} {:>12}",
        "mesh", "backend", "samples", "ms/query", "samples/s"
    );
    for r in &report.edge_terms {
        println!(
            "{:<34} {:<9} {:>8} {:>10.3} {:>12.0}",
            r.mesh, r.backend, r.samples, r.ms_per_query, r.samples_per_second
        );
    }
}
