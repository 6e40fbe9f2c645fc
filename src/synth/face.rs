//! Synthetic face sequences with ground truth (`jawtrack synth --face`), in the face-sequence
//! format: subjects who differ in size, joint, face shape and soft tissue, whose skin over the
//! chin and the jaw line follows the mandible only in part and slides over it (less the wider
//! the mouth opens, and not equally everywhere), with expressions that move the skin and not
//! the jaw (smile, lips pressed, pucker), and the noise of a face tracker. The jaw moves by the
//! joint model of [`crate::anatomy::JawModel`]: the five calibration poses first, then a
//! random mixture of opening, excursions and protrusion. Deterministic per seed.

use std::path::Path;

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::face_script::script;
use crate::anatomy::{JawControls, JawModel, procedural_arch, rest_bite};
use crate::error::{Error, Result};
use crate::geometry::{Pose, so3_exp};
use crate::io::write_json_atomic;
use crate::mesh::Mesh;
use crate::mesh::write_obj;
use crate::skin::format::{FACE_FORMAT, FaceFramesJson, FaceJson};

/// The skin grid: rows from under the chin to the nose, columns from ear to ear.
const ROWS: usize = 36;
const COLS: usize = 64;

#[derive(Debug, Clone)]
pub struct FaceSynthOptions {
    pub subjects: u32,
    pub frames: u32,
    pub seed: u64,
    /// The face tracker's noise: per vertex and coordinate (mm, standard deviation).
    pub noise_mm: f64,
    pub force: bool,
}

impl Default for FaceSynthOptions {
    fn default() -> Self {
        FaceSynthOptions {
            subjects: 4,
            frames: 600,
            seed: 0,
            noise_mm: 0.1,
            force: false,
        }
    }
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct FaceSynthReport {
    pub subjects: Vec<FaceSubjectReport>,
    pub seconds: f64,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct FaceSubjectReport {
    pub name: String,
    pub frames: u32,
    pub skin_vertices: usize,
    pub chin_tissue_mm: f64,
    pub sliding: f64,
    /// Largest incisal opening reached (mm) and the largest skin displacement (mm).
    pub max_opening_mm: f64,
    pub max_skin_mm: f64,
}

/// One subject: anatomy and soft tissue drawn from the seed.
struct FaceSubject {
    jaw: JawModel,
    mandible: Mesh,
    neutral: Mesh,
    /// Per skin vertex: how much it follows the mandible, and its outward normal.
    attach: Vec<f64>,
    normals: Vec<Vector3<f64>>,
    /// Per expression (smile, lips pressed, pucker): displacement per vertex at full strength.
    expressions: [Vec<Vector3<f64>>; 3],
    sliding: f64,
    stretch_mm: f64,
    gain: [f64; 3],
    chin_tissue_mm: f64,
    lower_incisor: Vector3<f64>,
}

/// Write `opts.subjects` subjects to `out/<name>/`.
pub fn generate_faces(
    out: &Path,
    opts: &FaceSynthOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<FaceSynthReport> {
    let started = std::time::Instant::now();
    if opts.subjects == 0 || opts.subjects > 64 {
        return Err(Error::invalid(out, "--subjects", "must be 1 to 64"));
    }
    if opts.frames < 200 || opts.frames > 100_000 {
        return Err(Error::invalid(
            out,
            "--frames",
            "must be 200 to 100000 (the calibration poses take the first 200)",
        ));
    }
    if !(opts.noise_mm.is_finite() && (0.0..=5.0).contains(&opts.noise_mm)) {
        return Err(Error::invalid(out, "--noise-mm", "must be 0 to 5 mm"));
    }
    super::check_out(out, opts.force)?;
    super::write_staged(out, |dir| {
        let mut subjects = Vec::new();
        for i in 0..opts.subjects {
            let name = format!("s{}", i + 1);
            let subject = FaceSubject::new(opts.seed, i);
            subjects.push(write_subject(
                &dir.join(&name),
                &name,
                &subject,
                opts,
                i,
                progress,
            )?);
        }
        Ok(FaceSynthReport {
            subjects,
            seconds: started.elapsed().as_secs_f64(),
        })
    })
}

impl FaceSubject {
    fn new(seed: u64, index: u32) -> FaceSubject {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (0x5eed_face ^ (index as u64) << 32));
        let size = rng.random_range(0.93..1.07);
        let scale = |m: Mesh| Mesh {
            positions: m
                .positions
                .iter()
                .map(|p| p.map(|c| c * size as f32))
                .collect(),
            ..m
        };
        let (upper, lower) = (scale(procedural_arch(true)), scale(procedural_arch(false)));
        let rest = rest_bite(&upper, &lower);
        let jaw = if index.is_multiple_of(2) {
            JawModel::for_arches(&upper, rest)
        } else {
            JawModel::variant_for_arches(&upper, rest)
        };
        let mandible = super::mandible::mandible_mesh(&lower, &jaw);
        let bone: Vec<Vector3<f64>> = mandible
            .points()
            .map(|p| rest.transform_point(&p))
            .collect();
        let chin_tissue_mm = rng.random_range(8.0..14.0);
        let width_extra = rng.random_range(-4.0..6.0);
        let cheek = rng.random_range(0.9..1.15);
        let neutral = skin_shell(&bone, &jaw, chin_tissue_mm, width_extra, cheek);
        let normals = vertex_normals(&neutral);
        let falloff = rng.random_range(9.0..15.0);
        let follow = rng.random_range(0.82..0.95);
        let attach = attachment(&neutral, &bone, chin_tissue_mm, falloff, follow);
        let amp = [
            rng.random_range(0.7..1.3),
            rng.random_range(0.7..1.3),
            rng.random_range(0.7..1.3),
        ];
        let expressions = expression_fields(&neutral, &normals, amp);
        let (llo, lhi) = lower.bounds();
        let lower_incisor = rest.transform_point(&Vector3::new(
            (llo[0] + lhi[0]) as f64 * 0.5,
            lhi[1] as f64,
            lhi[2] as f64,
        ));
        FaceSubject {
            jaw,
            mandible,
            neutral,
            attach,
            normals,
            expressions,
            sliding: rng.random_range(0.15..0.35),
            stretch_mm: rng.random_range(1.0..3.0),
            gain: [
                rng.random_range(0.9..1.0),
                rng.random_range(0.9..1.0),
                rng.random_range(0.9..1.0),
            ],
            chin_tissue_mm,
            lower_incisor,
        }
    }

    /// The skin in a frame: the jaw's motion carried to each vertex by its attachment, less
    /// the sliding, the stretch under the chin, the expressions, and the tracker's noise.
    fn skin(
        &self,
        c: &JawControls,
        expr: &[f64; 3],
        rng: &mut ChaCha8Rng,
        noise: f64,
    ) -> Vec<[f32; 3]> {
        let motion = self.jaw.mandible_motion(c);
        let (_, _, angle) = self.jaw.joint_state(c);
        let rho = (angle / self.jaw.max_opening_rad).clamp(0.0, 1.2);
        let jitter = Pose::new(
            so3_exp(&(Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * 0.03f64.to_radians())),
            Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * 0.05,
        );
        self.neutral
            .points()
            .enumerate()
            .map(|(i, s0)| {
                let w = self.attach[i];
                let slide = 1.0 - self.sliding * rho.powf(1.5) * (0.5 + (1.0 - w));
                let mut u = (motion.transform_point(&s0) - s0) * (w * slide);
                u -= self.normals[i] * (self.stretch_mm * rho * rho * 4.0 * w * (1.0 - w));
                for (field, a) in self.expressions.iter().zip(expr) {
                    u += field[i] * *a;
                }
                let n = Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * noise;
                let p = jitter.transform_point(&(s0 + u)) + n;
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect()
    }
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    // Box-Muller.
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    let v: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// The skin over the lower face at rest: per height an ellipse about a vertical axis at the
/// condyles, wide enough to clear the ramus and deep enough to clear the chin by the tissue;
/// under the chin it curls in.
fn skin_shell(
    bone: &[Vector3<f64>],
    jaw: &JawModel,
    tissue: f64,
    width_extra: f64,
    cheek: f64,
) -> Mesh {
    let max =
        |f: &dyn Fn(&Vector3<f64>) -> f64| bone.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    let zc = (jaw.condyle_left.z + jaw.condyle_right.z) * 0.5;
    let xc = (jaw.condyle_left.x + jaw.condyle_right.x) * 0.5;
    let a = max(&|p| (p.x - xc).abs()) + 12.0 + width_extra;
    let b = max(&|p| p.z) + tissue - zc;
    let y_low = -max(&|p| -p.y) - tissue;
    let y_top = 18.0;
    let mut mesh = Mesh {
        positions: Vec::with_capacity(ROWS * COLS),
        triangles: Vec::new(),
        boi: Vec::new(),
    };
    for r in 0..ROWS {
        let v = r as f64 / (ROWS - 1) as f64;
        let (y, radial) = if v < 0.2 {
            (y_low + 2.0 * v / 0.2, 0.72 + 0.28 * (v / 0.2).sqrt())
        } else {
            let f = (v - 0.2) / 0.8;
            (y_low + 2.0 + f * (y_top - y_low - 2.0), 1.0)
        };
        for k in 0..COLS {
            let th = (-105.0 + 210.0 * k as f64 / (COLS - 1) as f64).to_radians();
            // Cheeks fuller at mouth height; lips forward at the front.
            let fullness = 1.0 + (cheek - 1.0) * (-(y + 5.0).powi(2) / 400.0).exp();
            let lips = 4.0 * th.cos().max(0.0).powi(6) * (-(y + 4.0).powi(2) / 80.0).exp();
            let x = xc + a * radial * fullness * th.sin();
            let z = zc + (b * radial + lips) * th.cos();
            mesh.positions.push([x as f32, y as f32, z as f32]);
        }
    }
    for r in 0..ROWS - 1 {
        for k in 0..COLS - 1 {
            let at = |r: usize, k: usize| (r * COLS + k) as u32;
            // Wound so that normals point out of the face.
            mesh.triangles
                .push([at(r, k), at(r + 1, k), at(r + 1, k + 1)]);
            mesh.triangles
                .push([at(r, k), at(r + 1, k + 1), at(r, k + 1)]);
            mesh.boi.extend([false, false]);
        }
    }
    mesh
}

/// Vertex normals pointing away from the face's vertical axis, whichever way the grid winds.
fn vertex_normals(mesh: &Mesh) -> Vec<Vector3<f64>> {
    let centre = mesh.points().sum::<Vector3<f64>>() / mesh.positions.len() as f64;
    mesh.vertex_normals()
        .into_iter()
        .zip(mesh.points())
        .map(|(u, p)| {
            let out = Vector3::new(p.x - centre.x, 0.0, p.z - centre.z);
            if u.dot(&out) < 0.0 { -u } else { u }
        })
        .collect()
}

/// How much each skin vertex follows the mandible: most where the bone is near (the chin and
/// the jaw line), falling off with the depth of tissue, and nothing above the mouth.
fn attachment(
    skin: &Mesh,
    bone: &[Vector3<f64>],
    tissue: f64,
    falloff: f64,
    follow: f64,
) -> Vec<f64> {
    skin.points()
        .map(|s| {
            let d = bone
                .iter()
                .map(|b| (b - s).norm_squared())
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            let depth = (-(d - tissue).max(0.0) / falloff).exp();
            // Lower lip (y ≈ −12) half attached; above the mouth corner (y ≈ 0) not at all.
            let below_mouth = ((0.0 - s.y) / 12.0).clamp(0.0, 1.0);
            let smooth = below_mouth * below_mouth * (3.0 - 2.0 * below_mouth);
            follow * depth * smooth
        })
        .collect()
}

/// Displacement fields of three expressions that do not move the jaw: a smile (mouth corners
/// up, back and out), lips pressed (the mentalis lifts the chin's skin and the lower lip), a
/// pucker (lips forward, the chin's skin a little forward and up).
fn expression_fields(
    skin: &Mesh,
    normals: &[Vector3<f64>],
    amp: [f64; 3],
) -> [Vec<Vector3<f64>>; 3] {
    let pts: Vec<Vector3<f64>> = skin.points().collect();
    let front = pts.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
    let xs = pts.iter().map(|p| p.x).sum::<f64>() / pts.len() as f64;
    let bump = |p: &Vector3<f64>, cx: f64, cy: f64, dz: f64, r: f64| {
        let d2 = (p.x - cx).powi(2) + (p.y - cy).powi(2) + (p.z - (front - dz)).powi(2);
        (-d2 / (r * r)).exp()
    };
    let smile = pts
        .iter()
        .zip(normals)
        .map(|(p, n)| {
            let side = (p.x - xs).signum();
            let g = bump(p, xs + 24.0, -4.0, 14.0, 16.0) + bump(p, xs - 24.0, -4.0, 14.0, 16.0);
            (Vector3::new(side * 2.0, 3.0, -2.0) + n * 0.5) * (g * amp[0])
        })
        .collect();
    let pressed = pts
        .iter()
        .map(|p| {
            let chin = bump(p, xs, -32.0, 0.0, 14.0);
            let lip = bump(p, xs, -12.0, 0.0, 12.0);
            (Vector3::new(0.0, 1.5, 1.0) * chin + Vector3::new(0.0, 2.0, -0.5) * lip) * amp[1]
        })
        .collect();
    let pucker = pts
        .iter()
        .map(|p| {
            let lips = bump(p, xs, -4.0, 0.0, 15.0);
            let chin = bump(p, xs, -30.0, 0.0, 14.0);
            let inward = Vector3::new(-(p.x - xs) * 0.08, 0.0, 0.0);
            ((Vector3::new(0.0, 0.0, 4.0) + inward) * lips + Vector3::new(0.0, 0.5, 0.8) * chin)
                * amp[2]
        })
        .collect();
    [smile, pressed, pucker]
}

fn write_subject(
    dir: &Path,
    name: &str,
    s: &FaceSubject,
    opts: &FaceSynthOptions,
    index: u32,
    progress: &(dyn Fn() + Sync),
) -> Result<FaceSubjectReport> {
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir).map_err(|error| Error::Write {
        path: frames_dir.clone(),
        error,
    })?;
    write_obj(&s.neutral, &dir.join("neutral.obj"))?;
    write_obj(&s.mandible, &dir.join("mandible.obj"))?;
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed.wrapping_mul(31) ^ (index as u64 + 1) << 40);
    let (script, calibration) = script(opts.frames, &mut rng);
    let g = s.gain;
    let script: Vec<(JawControls, [f64; 3])> = script
        .into_iter()
        .map(|(c, e)| {
            let c = JawControls {
                open: c.open * g[0],
                lateral: c.lateral * g[1],
                protrusion: c.protrusion * g[2],
            };
            (c, e)
        })
        .collect();
    let results: Vec<(Pose, f64, f64)> = script
        .par_iter()
        .enumerate()
        .map(|(f, (c, e))| {
            let mut rng = ChaCha8Rng::seed_from_u64(
                opts.seed ^ ((index as u64) << 48) ^ (f as u64).wrapping_mul(0x9e37_79b9),
            );
            let skin = s.skin(c, e, &mut rng, opts.noise_mm);
            let path = frames_dir.join(format!("{f:06}.ply"));
            write_ply_vertices(&path, &skin)?;
            progress();
            let jaw = s.jaw.jaw_pose(c);
            let motion = s.jaw.mandible_motion(c);
            let opening = (motion.transform_point(&s.lower_incisor) - s.lower_incisor).norm();
            let skin_mm = skin
                .iter()
                .zip(&s.neutral.positions)
                .map(|(a, b)| {
                    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
                    ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64).sqrt()
                })
                .fold(0.0, f64::max);
            Ok((jaw, opening, skin_mm))
        })
        .collect::<Result<_>>()?;
    let frames: Vec<u32> = (0..results.len() as u32).collect();
    let poses: Vec<Pose> = results.iter().map(|(p, _, _)| *p).collect();
    crate::formats::write_jaw_poses(&dir.join("jaw.json"), &frames, &poses)?;
    let face = FaceJson {
        format: FACE_FORMAT.into(),
        frames: FaceFramesJson {
            first: 0,
            count: opts.frames,
        },
        neutral: "neutral.obj".into(),
        frames_dir: "frames".into(),
        mandible: "mandible.obj".into(),
        jaw: Some("jaw.json".into()),
        calibration: Some(calibration),
    };
    write_json_atomic(&dir.join("face.json"), &face)?;
    Ok(FaceSubjectReport {
        name: name.into(),
        frames: opts.frames,
        skin_vertices: s.neutral.positions.len(),
        chin_tissue_mm: s.chin_tissue_mm,
        sliding: s.sliding,
        max_opening_mm: results.iter().map(|r| r.1).fold(0.0, f64::max),
        max_skin_mm: results.iter().map(|r| r.2).fold(0.0, f64::max),
    })
}

/// A binary PLY of vertices alone: a frame's topology is the neutral's.
fn write_ply_vertices(path: &Path, v: &[[f32; 3]]) -> Result<()> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment jawtrack face frame: millimetres, skull frame\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        v.len()
    )
    .into_bytes();
    for p in v {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(path, out).map_err(|error| Error::Write {
        path: path.to_path_buf(),
        error,
    })
}
