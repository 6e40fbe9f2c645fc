//! Energy and synthesis benchmarks (criterion), one group per stage: the CPU reference, the
//! GPU histogram engine and the readback baseline (GPU groups are skipped, with a message, when
//! there is no adapter). Run: `cargo bench --bench energy`. Needs ../shared/data/scan-tag0 for
//! the real-scan cases (skipped with a message when absent). `jawtrack bench energy` prints the
//! same comparison as a table.

use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use jawtrack::arch::{Arch, ArchPoses};
use jawtrack::capture::{Capture, OpenOptions};
use jawtrack::energy::gpu::GpuEnergy;
use jawtrack::energy::{CpuEnergy, EnergyEngine, Region, Scene};
use jawtrack::synth::{Preset, SynthOptions, generate};

fn capture(meshes: Option<&Path>, dir: &Path, max_triangles: Option<usize>) -> Capture {
    if !dir.exists() {
        let opts = SynthOptions {
            frames: 8,
            preset: Preset::Realistic,
            meshes: meshes.map(Path::to_path_buf),
            ..SynthOptions::default()
        };
        generate(dir, &opts, &|| {}).expect("synthesise the benchmark capture");
    }
    // The meshes as given (or cut to `max_triangles`): what each case names.
    let open = OpenOptions {
        max_triangles,
        simplify_mm: Some(0.0),
        ..OpenOptions::default()
    };
    Capture::open_with(dir, open).expect("open the benchmark capture")
}

fn bench_energy(c: &mut Criterion) {
    let tmp = tempfile::tempdir().unwrap();
    let scans = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scan-tag0");
    let mut cases: Vec<(&str, Option<&Path>, Option<usize>)> =
        vec![("procedural-8.6k", None, None)];
    if scans.join("upper.obj").exists() {
        cases.push(("scan-85k", Some(scans.as_path()), None));
        cases.push(("scan-simplified-10k", Some(scans.as_path()), Some(10_000)));
    } else {
        eprintln!(
            "no real scans at {}: benchmarking the procedural arch only",
            scans.display()
        );
    }
    for (name, meshes, max_tris) in cases {
        let dir = tmp.path().join(if meshes.is_some() {
            "scan"
        } else {
            "procedural"
        });
        let cap = capture(meshes, &dir, max_tris);
        let scene = Scene::from_capture(&cap);
        let masks = cap.load_masks(4).unwrap();
        let truth: ArchPoses = cap.gt_poses(4).unwrap();
        let batch: Vec<ArchPoses> = (0..64)
            .map(|k| {
                let d = [0.0, 0.0, 0.0, 0.01 * k as f64, 0.0, 0.0];
                truth.with(Arch::Lower, truth.lower.with_euler_offset(&d))
            })
            .collect();
        let mut engines: Vec<(String, Box<dyn EnergyEngine>)> = Vec::new();
        engines.push((
            "cpu-Energy".into(),
            Box::new(CpuEnergy::with_region(scene.clone(), Region::Relevant)),
        ));
        for region in [Region::Footprint, Region::FullFrame] {
            engines.push((
                format!("cpu-{region:?}"),
                Box::new(CpuEnergy::with_region(scene.clone(), region)),
            ));
            match GpuEnergy::new(scene.clone(), region) {
                Ok(g) => engines.push((format!("gpu-{region:?}"), Box::new(g))),
                Err(e) => eprintln!("no GPU group: {e}"),
            }
        }
        if let Ok(g) = GpuEnergy::readback_baseline(scene.clone()) {
            engines.push(("readback".into(), Box::new(g)));
        }
        let mut group = c.benchmark_group(format!("energy_3_cameras/{name}"));
        group.sample_size(10);
        for (label, engine) in &mut engines {
            engine.set_frame(&masks).unwrap();
            let engine = &*engine;
            group.throughput(criterion::Throughput::Elements(1));
            group.bench_function(BenchmarkId::new(label.as_str(), "single"), |b| {
                b.iter(|| engine.evaluate(Arch::Lower, &[truth]).unwrap())
            });
            group.throughput(criterion::Throughput::Elements(64));
            group.bench_function(BenchmarkId::new(label.as_str(), "batch64"), |b| {
                b.iter(|| engine.evaluate(Arch::Lower, &batch).unwrap())
            });
        }
        group.finish();
    }
}

fn bench_synth(c: &mut Criterion) {
    let mut group = c.benchmark_group("synth");
    group.sample_size(10);
    group.bench_function("realistic_8_frames", |b| {
        b.iter_batched(
            || tempfile::tempdir().unwrap(),
            |t| {
                let opts = SynthOptions {
                    frames: 8,
                    ..SynthOptions::default()
                };
                generate(&t.path().join("c"), &opts, &|| {}).unwrap()
            },
            criterion::BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(benches, bench_energy, bench_synth);
criterion_main!(benches);
