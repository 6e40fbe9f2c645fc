//! CPU reference energy and synthesis benchmarks (criterion), one group per stage.
//! Run: `cargo bench --bench energy`. Needs ../shared/data/scan-tag0 for the real-scan cases
//! (skipped with a message when absent).

use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use jawtrack::capture::{Arch, ArchPoses, Capture, OpenOptions};
use jawtrack::energy::{CpuEnergy, EnergyEngine, Scene};
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
    Capture::open_with(dir, OpenOptions { max_triangles }).expect("open the benchmark capture")
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
    let mut group = c.benchmark_group("cpu_energy_3_cameras");
    for (name, meshes, max_tris) in cases {
        let dir = tmp.path().join(if meshes.is_some() {
            "scan"
        } else {
            "procedural"
        });
        let cap = capture(meshes, &dir, max_tris);
        let mut engine = CpuEnergy::new(Scene::from_capture(&cap));
        engine.set_frame(&cap.load_masks(4).unwrap()).unwrap();
        let truth: ArchPoses = cap.gt_poses(4).unwrap();
        group.bench_function(BenchmarkId::new("single", name), |b| {
            b.iter(|| engine.evaluate(Arch::Lower, &[truth]).unwrap())
        });
        let batch: Vec<ArchPoses> = (0..64)
            .map(|k| {
                let d = [0.0, 0.0, 0.0, 0.01 * k as f64, 0.0, 0.0];
                truth.with(Arch::Lower, truth.lower.with_euler_offset(&d))
            })
            .collect();
        group.throughput(criterion::Throughput::Elements(64));
        group.bench_function(BenchmarkId::new("batch64", name), |b| {
            b.iter(|| engine.evaluate(Arch::Lower, &batch).unwrap())
        });
        group.throughput(criterion::Throughput::Elements(1));
    }
    group.finish();
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
