//! The pose search for one arch in one frame (Yang et al., Section 4): a finite-difference
//! gradient of E, a golden-section search along it, rotation first with translation fixed and
//! then translation with rotation fixed, repeated until a round gains too little; then denser
//! local sampling around the pose (batched) to escape poor minima, and descent again from
//! there. This is the solver only; the frame loop is in `sequence`.
//!
//! A candidate is the start pose moved by δ = (θx, θy, θz, tx, ty, tz): rotations R = Rz·Ry·Rx
//! about the arch's centre, in world axes, then translations in world axes (mm).

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};

use super::penalties::Penalties;
use crate::arch::{Arch, ArchPoses};
use crate::energy::{Energy, EnergyEngine, Weights};
use crate::error::Result;
use crate::geometry::Pose;
use crate::settings::Rules;

/// The search's settings; the defaults suit three cameras at ~20 cm with half-resolution masks
/// (a pixel is ~0.4 mm there).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SearchSettings {
    /// Central-difference step for the gradient: rotation (rad) and translation (mm).
    pub fd_step_rad: f64,
    pub fd_step_mm: f64,
    /// Longest step of a line search along the normalised gradient.
    pub line_max_rad: f64,
    pub line_max_mm: f64,
    /// A line search stops when its bracket is shorter than this share of the longest step.
    pub line_tolerance: f64,
    /// At most this many descent rounds (rotation, then translation); a round that lowers E
    /// by less than `min_gain` ends the descent.
    pub max_rounds: usize,
    pub min_gain: f64,
    /// Local sampling: rounds, samples per round (one batch) and the half-widths of the box
    /// sampled around the pose in the first round (halved each round).
    pub sample_rounds: usize,
    pub samples: usize,
    pub sample_rad: f64,
    pub sample_mm: f64,
    /// Coarse to fine: the whole search (descent, sampling, descent) runs once per scale,
    /// with every step, line length and sampling box multiplied by it.
    pub scales: Vec<f64>,
    /// Weight of the boundary term, E = uncovered + λ·boi_outside.
    pub lambda: f64,
    /// Weight of the cross-label term added to E with per-arch masks: pixels labelled as the
    /// other arch where this arch's model is visible in front of it. Without it an arch can
    /// move in front of the other to cover its own mask's noisy edge at no cost. 0 gives the
    /// paper's E exactly; combined masks have no such pixels.
    pub cross_weight: f64,
    /// Weight μ of the over-mouth term added to E when the masks label the visible mouth
    /// interior (`masks.mouth`): pixels of it where a model is drawn. The paper's E never
    /// charges a tooth drawn where the camera sees none, so a pose can slide or tilt into
    /// the region the lips hide for free. 0 gives the paper's E; masks without the label
    /// have no such pixels.
    pub mouth_weight: f64,
    /// How the arches' poses are found: `paper`, the derivative-free search of the paper's
    /// energy per arch (finite differences, golden section, local sampling); `gauss-newton`,
    /// Gauss-Newton steps that bring both arches' teeth outlines onto their masks' edges at
    /// once, the contact and the jaw's manifold as residuals ([`super::joint`]), falling back
    /// to `paper` on a frame where it ends lost; `contour`, the same steps per arch
    /// ([`super::align`]); or `auto` (the default), `gauss-newton` where the energy is
    /// two-sided (the masks label the mouth interior and its term is on) or the masks are
    /// combined, `paper` on per-arch teeth masks alone (see [`Solver::for_masks`]).
    // `paper` is left out of the fingerprint's JSON, as it was when it was the default, so that
    // runs of that time resume with `--search paper`; a run of the default is a new run.
    #[serde(skip_serializing_if = "Solver::is_paper")]
    pub solver: Solver,
    /// The `gauss-newton` solver's settings.
    #[serde(skip_serializing_if = "GaussNewtonSettings::is_default")]
    pub gauss_newton: GaussNewtonSettings,
}

/// See [`super::joint`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaussNewtonSettings {
    /// How far (pixels) each silhouette sample looks for its mask's edge, one entry per
    /// stage, coarse to fine; each stage draws the arches once per camera.
    pub reaches_px: Vec<f64>,
    /// The first this many stages draw the arches and read the masks at half their
    /// resolution (the next level of the masks' pyramid, `energy::pyramid`): fewer samples,
    /// shorter searches and a quarter of the drawing, where the reach is long and a pixel's
    /// precision is not needed yet.
    pub coarse_stages: usize,
    /// Gauss-Newton steps per stage (fewer when a step moves nothing).
    pub steps: usize,
    /// Silhouette sample spacing (pixels of the stage's level).
    pub spacing_px: f64,
    /// The smoothing width ε (pixels): offsets below it are weighed as squares, above it as
    /// the pixel counts they stand for.
    pub smoothing_px: f64,
    /// What a millimetre² of either arch's displacement from the frame's start costs, in the
    /// silhouette residuals' unit (pixels of contour times pixels of offset): holds the
    /// directions the masks barely see (a nod about the incisal edges) where the last frame
    /// left them.
    pub motion_prior: f64,
    /// What a millimetre² of contact depth, and of the jaw's distance from its manifold,
    /// beyond their tolerances costs (same unit); 0 leaves a term out. The manifold is the
    /// average joint's, and a subject's jaw poses lie up to a millimetre or two off it
    /// (another joint, another rest bite): its stiffness is low enough to yield to what the
    /// masks see and holds only the directions they do not (docs/tracking.md, "Another
    /// subject's joint"). Contact is physics, and stays stiff.
    pub contact_stiffness: f64,
    pub manifold_stiffness: f64,
    /// The lower arch also starts from the best of this many poses of the jaw prior's fine
    /// grid nearest to the frame's starts (one evaluation each; see
    /// `TrackSettings::jaw_prior_fine_grid`): a jaw that went astray by a step or two comes
    /// back. Farther, the frame is lost and the paper's search, with the whole prior, takes
    /// it over.
    pub jaw_prior_nearest: usize,
    /// A frame whose worse arch's area error exceeds this many times the recent frames'
    /// typical one (or the tracker's bound of a low-confidence frame) goes to the paper's
    /// search.
    pub fallback_ratio: f64,
    /// A frame where either arch is drawn over more than this share of its mask's pixels'
    /// worth of what the masks say is not it (the other arch's label, the mouth interior) goes
    /// to the paper's search too: an arch the steps left over the open mouth fits its own
    /// label's area as well as the truth does. At the true pose the share is the masks' noise
    /// (0.01-0.05 on realistic masks).
    pub fallback_misdrawn: f64,
    /// Where the paper's search was asked because Gauss-Newton's answer fitted worse than the
    /// recent frames, in a take whose jaw's manifold was let go (the paper's search looks
    /// among the average joint's poses too), its answer (settled by Gauss-Newton) overrules
    /// Gauss-Newton's own only where its worse arch's area error is at least this share lower:
    /// a mouth opening wide shows more of the masks' errors from frame to frame, and the
    /// paper's search then lands a fit no better and a pose further off.
    pub fallback_gain: f64,
    /// Estimate each camera's offset of its masks' edges beside the poses
    /// (`super::edge_offsets`): a segmentation that draws the teeth wider in one camera and
    /// narrower in another, for the whole take.
    pub edge_offsets: bool,
}

impl Default for GaussNewtonSettings {
    fn default() -> Self {
        GaussNewtonSettings {
            reaches_px: vec![8.0, 4.0, 3.0],
            coarse_stages: 1,
            steps: 2,
            spacing_px: 2.0,
            smoothing_px: 0.5,
            motion_prior: 30.0,
            contact_stiffness: 1000.0,
            manifold_stiffness: 10.0,
            jaw_prior_nearest: 20,
            fallback_ratio: 1.5,
            fallback_misdrawn: 0.1,
            fallback_gain: 0.1,
            edge_offsets: true,
        }
    }
}

impl GaussNewtonSettings {
    fn is_default(&self) -> bool {
        *self == GaussNewtonSettings::default()
    }

    fn validate(&self, rules: &Rules) -> Result<()> {
        rules.length("reaches_px", self.reaches_px.len(), 1, 16)?;
        for (k, &reach) in self.reaches_px.iter().enumerate() {
            rules.number(&format!("reaches_px[{k}]"), reach, 0.5, 64.0)?;
        }
        rules.count(
            "coarse_stages",
            self.coarse_stages as u64,
            0,
            self.reaches_px.len() as u64,
        )?;
        rules.count("steps", self.steps as u64, 1, 100)?;
        rules.number("spacing_px", self.spacing_px, 0.25, 64.0)?;
        rules.above("smoothing_px", self.smoothing_px, 0.0, 64.0)?;
        rules.number("motion_prior", self.motion_prior, 0.0, 1e9)?;
        rules.number("contact_stiffness", self.contact_stiffness, 0.0, 1e9)?;
        rules.number("manifold_stiffness", self.manifold_stiffness, 0.0, 1e9)?;
        rules.number("fallback_ratio", self.fallback_ratio, 0.0, 1e9)?;
        rules.number("fallback_misdrawn", self.fallback_misdrawn, 0.0, 1e9)?;
        rules.number("fallback_gain", self.fallback_gain, 0.0, 1.0)?;
        rules.count(
            "jaw_prior_nearest",
            self.jaw_prior_nearest as u64,
            0,
            10_000,
        )?;
        Ok(())
    }
}

/// See [`SearchSettings::solver`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    #[default]
    Auto,
    Paper,
    GaussNewton,
    Contour,
}

impl Solver {
    fn is_paper(&self) -> bool {
        *self == Solver::Paper
    }

    /// As `--search` and the settings spell it.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Auto => "auto",
            Solver::Paper => "paper",
            Solver::GaussNewton => "gauss-newton",
            Solver::Contour => "contour",
        }
    }

    /// The solver `auto` stands for: Gauss-Newton where the energy is two-sided (the masks
    /// label the mouth interior and the over-mouth term weighs it) or the masks are combined,
    /// the paper's search on per-arch teeth masks alone. With the label Gauss-Newton is as
    /// accurate as the paper's search at a twelfth of its time. On one combined label the
    /// paper's search, one arch after the other, loses an arch to the other's pixels, which
    /// steps over both at once do not. On per-arch teeth masks alone an arch slides into the
    /// region the lips hide at no cost, and the paper's search, which samples the whole jaw
    /// prior in every frame, finds its way back on hard footage where the steps, holding to
    /// the last frame, do not (docs/tracking.md, "Which search").
    pub fn for_masks(self, two_sided: bool, combined: bool) -> Solver {
        match self {
            Solver::Auto if two_sided || combined => Solver::GaussNewton,
            Solver::Auto => Solver::Paper,
            other => other,
        }
    }
}

impl Default for SearchSettings {
    fn default() -> Self {
        SearchSettings {
            fd_step_rad: 0.2f64.to_radians(),
            fd_step_mm: 0.2,
            line_max_rad: 3f64.to_radians(),
            line_max_mm: 3.0,
            line_tolerance: 0.01,
            max_rounds: 12,
            min_gain: 0.5,
            sample_rounds: 2,
            samples: 32,
            sample_rad: 0.6f64.to_radians(),
            sample_mm: 0.6,
            scales: vec![1.0, 0.25],
            lambda: crate::energy::DEFAULT_LAMBDA,
            cross_weight: 1.0,
            mouth_weight: 1.0,
            solver: Solver::Auto,
            gauss_newton: GaussNewtonSettings::default(),
        }
    }
}

impl SearchSettings {
    /// Every field in its range (see [`crate::settings`]).
    pub fn validate(&self, rules: &Rules) -> Result<()> {
        // Steps and widths must be positive: a zero step never ends a line search and a zero
        // sampling box is an empty range.
        rules.above("fd_step_rad", self.fd_step_rad, 0.0, 0.2)?;
        rules.above("fd_step_mm", self.fd_step_mm, 0.0, 10.0)?;
        rules.above("line_max_rad", self.line_max_rad, 0.0, 1.0)?;
        rules.above("line_max_mm", self.line_max_mm, 0.0, 50.0)?;
        rules.number("line_tolerance", self.line_tolerance, 1e-6, 0.5)?;
        rules.count("max_rounds", self.max_rounds as u64, 0, 1000)?;
        rules.number("min_gain", self.min_gain, 0.0, 1e9)?;
        rules.count("sample_rounds", self.sample_rounds as u64, 0, 100)?;
        rules.count("samples", self.samples as u64, 1, 4096)?;
        rules.above("sample_rad", self.sample_rad, 0.0, 1.0)?;
        rules.above("sample_mm", self.sample_mm, 0.0, 50.0)?;
        rules.length("scales", self.scales.len(), 1, 16)?;
        for (k, &scale) in self.scales.iter().enumerate() {
            rules.above(&format!("scales[{k}]"), scale, 0.0, 100.0)?;
        }
        rules.number("lambda", self.lambda, 0.0, 1000.0)?;
        rules.number("cross_weight", self.cross_weight, 0.0, 1000.0)?;
        rules.number("mouth_weight", self.mouth_weight, 0.0, 1000.0)?;
        self.gauss_newton.validate(&rules.within("gauss_newton"))?;
        Ok(())
    }

    /// The weights of the objective the search minimises.
    pub fn weights(&self) -> Weights {
        Weights {
            lambda: self.lambda,
            cross: self.cross_weight,
            mouth: self.mouth_weight,
        }
    }
}

/// What a search found.
#[derive(Debug, Clone)]
pub struct Found {
    pub pose: Pose,
    pub energy: Energy,
    /// What the search minimised, at `pose`: the paper's E plus the cross-label and
    /// over-mouth terms and the penalties (contact, the jaw's manifold); [`Energy::total`] is the paper's E alone.
    pub objective: f64,
    pub evaluations: usize,
}

/// The objective of one search: E of `arch` at `start` moved by δ, the other arch fixed.
struct Objective<'a> {
    engine: &'a dyn EnergyEngine,
    arch: Arch,
    context: ArchPoses,
    start: Pose,
    /// The arch's centre in world: rotations turn about it.
    centre: Vector3<f64>,
    weights: Weights,
    penalties: &'a Penalties,
    evaluations: usize,
}

impl Objective<'_> {
    fn pose(&self, d: &[f64; 6]) -> Pose {
        let r = Pose::from_euler_tuple(&[d[0], d[1], d[2], 0.0, 0.0, 0.0]).rotation;
        let about_centre = Pose::new(r, self.centre - r * self.centre);
        Pose::from_translation(Vector3::new(d[3], d[4], d[5]))
            .compose(&about_centre)
            .compose(&self.start)
    }

    fn candidates(&self, ds: &[[f64; 6]]) -> Vec<ArchPoses> {
        ds.iter()
            .map(|d| self.context.with(self.arch, self.pose(d)))
            .collect()
    }

    /// The objective and the energy of each candidate.
    fn evaluate(&mut self, ds: &[[f64; 6]]) -> Result<Vec<(f64, Energy)>> {
        let candidates = self.candidates(ds);
        self.evaluations += ds.len();
        let energies = self.engine.evaluate(self.arch, &candidates)?;
        Ok(energies
            .into_iter()
            .zip(&candidates)
            .map(|(e, c)| (e.objective(&self.weights) + self.penalties.of(c), e))
            .collect())
    }

    fn totals(&mut self, ds: &[[f64; 6]]) -> Result<Vec<f64>> {
        Ok(self.evaluate(ds)?.into_iter().map(|(t, _)| t).collect())
    }
}

impl SearchSettings {
    /// The settings with every length (steps, line lengths, sampling box) times `k`.
    fn scaled(&self, k: f64) -> SearchSettings {
        SearchSettings {
            fd_step_rad: self.fd_step_rad * k,
            fd_step_mm: self.fd_step_mm * k,
            line_max_rad: self.line_max_rad * k,
            line_max_mm: self.line_max_mm * k,
            sample_rad: self.sample_rad * k,
            sample_mm: self.sample_mm * k,
            ..self.clone()
        }
    }
}

/// About an arch's radius: turns a rotation (rad) into a displacement (mm).
pub const RADIUS_MM: f64 = 30.0;

const GOLDEN: f64 = 0.618_033_988_749_894_9;

/// One arch's search: which arch, from where, and what else its objective holds.
#[derive(Debug, Clone, Copy)]
pub struct ArchSearch<'a> {
    pub arch: Arch,
    /// Both arches' poses: the search starts from `arch`'s and holds the other at its own.
    pub from: ArchPoses,
    /// The arch's centre in its model frame: rotations turn about it.
    pub centre: &'a Vector3<f64>,
    /// Added to the objective ([`Penalties::NONE`] for the energy alone).
    pub penalties: &'a Penalties,
    pub settings: &'a SearchSettings,
    /// Makes the sampling repeatable.
    pub seed: u64,
}

/// Search the pose of `q.arch` from `q.from`.
pub fn search(engine: &dyn EnergyEngine, q: &ArchSearch) -> Result<Found> {
    let (arch, s) = (q.arch, q.settings);
    let start = *q.from.get(arch);
    let mut obj = Objective {
        engine,
        arch,
        context: q.from,
        start,
        centre: start.transform_point(q.centre),
        weights: s.weights(),
        penalties: q.penalties,
        evaluations: 0,
    };
    let seed = q.seed;
    let mut best = [0.0; 6];
    let mut best_e = obj.totals(&[best])?[0];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for &scale in &s.scales {
        let s = &s.scaled(scale);
        descend(&mut obj, s, &mut best, &mut best_e)?;
        for round in 0..s.sample_rounds {
            // Denser local sampling around the pose, in one batch; descent again from a
            // better sample.
            let shrink = 0.5f64.powi(round as i32);
            let half = [
                s.sample_rad,
                s.sample_rad,
                s.sample_rad,
                s.sample_mm,
                s.sample_mm,
                s.sample_mm,
            ]
            .map(|h| h * shrink);
            let samples: Vec<[f64; 6]> = (0..s.samples)
                .map(|_| std::array::from_fn(|k| best[k] + rng.random_range(-half[k]..=half[k])))
                .collect();
            let totals = obj.totals(&samples)?;
            let (i, &e) = totals
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .expect("samples");
            if e < best_e {
                best = samples[i];
                best_e = e;
                descend(&mut obj, s, &mut best, &mut best_e)?;
            }
        }
    }
    let (objective, energy) = obj.evaluate(&[best])?.remove(0);
    Ok(Found {
        pose: obj.pose(&best),
        objective,
        energy,
        evaluations: obj.evaluations,
    })
}

/// Descent rounds: for the rotation block, then the translation block, a central-difference
/// gradient and a golden-section search along it.
fn descend(
    obj: &mut Objective,
    s: &SearchSettings,
    best: &mut [f64; 6],
    best_e: &mut f64,
) -> Result<()> {
    for _ in 0..s.max_rounds {
        let round_start = *best_e;
        for (block, h, max_step) in [
            (0..3, s.fd_step_rad, s.line_max_rad),
            (3..6, s.fd_step_mm, s.line_max_mm),
        ] {
            // Central differences on the block's three coordinates, one batch.
            let probes: Vec<[f64; 6]> = block
                .clone()
                .flat_map(|k| {
                    [1.0, -1.0].map(|sign| {
                        let mut d = *best;
                        d[k] += sign * h;
                        d
                    })
                })
                .collect();
            let e = obj.totals(&probes)?;
            let g: Vec<f64> = (0..3)
                .map(|i| (e[2 * i] - e[2 * i + 1]) / (2.0 * h))
                .collect();
            let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm == 0.0 {
                // A flat gradient: take the best probe if it is better.
                let (i, &ei) = e
                    .iter()
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(b.1))
                    .expect("probes");
                if ei < *best_e {
                    *best = probes[i];
                    *best_e = ei;
                }
                continue;
            }
            let mut dir = [0.0; 6];
            for (i, k) in block.clone().enumerate() {
                dir[k] = -g[i] / norm;
            }
            let (t, e_t) = line_search(
                obj,
                best,
                &dir,
                *best_e,
                max_step,
                s.line_tolerance * max_step,
            )?;
            if e_t < *best_e {
                for k in 0..6 {
                    best[k] += t * dir[k];
                }
                *best_e = e_t;
            }
        }
        if round_start - *best_e < s.min_gain {
            break;
        }
    }
    Ok(())
}

/// Minimise φ(t) = E(δ + t·dir) over t in [0, max_step]: bracket with one batch at
/// t = max_step·2^-k, then golden-section search inside the bracket.
fn line_search(
    obj: &mut Objective,
    at: &[f64; 6],
    dir: &[f64; 6],
    e0: f64,
    max_step: f64,
    tol: f64,
) -> Result<(f64, f64)> {
    let point = |t: f64| -> [f64; 6] { std::array::from_fn(|k| at[k] + t * dir[k]) };
    let ts: Vec<f64> = (0..5).rev().map(|k| max_step * 0.5f64.powi(k)).collect(); // 1/16 .. 1
    let es = obj.totals(&ts.iter().map(|&t| point(t)).collect::<Vec<_>>())?;
    let mut all_t = vec![0.0];
    all_t.extend(&ts);
    let mut all_e = vec![e0];
    all_e.extend(&es);
    // The best point and its neighbours bracket the minimum (at t = 0: the bracket [0, t1]).
    let k = (0..all_e.len())
        .min_by(|&a, &b| all_e[a].total_cmp(&all_e[b]))
        .expect("points");
    let (mut a, mut b) = (
        all_t[k.saturating_sub(1)],
        all_t[(k + 1).min(all_t.len() - 1)],
    );
    let (mut best_t, mut best_e) = (all_t[k], all_e[k]);
    let mut c = b - GOLDEN * (b - a);
    let mut d = a + GOLDEN * (b - a);
    let mut fc = obj.totals(&[point(c)])?[0];
    let mut fd = obj.totals(&[point(d)])?[0];
    while b - a > tol {
        if fc <= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - GOLDEN * (b - a);
            fc = obj.totals(&[point(c)])?[0];
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + GOLDEN * (b - a);
            fd = obj.totals(&[point(d)])?[0];
        }
        for (t, e) in [(c, fc), (d, fd)] {
            if e < best_e {
                best_t = t;
                best_e = e;
            }
        }
    }
    Ok((best_t, best_e))
}

#[cfg(test)]
mod tests {
    use super::Solver;

    #[test]
    fn auto_is_gauss_newton_on_a_two_sided_energy_or_combined_masks_and_a_choice_stays() {
        let auto = Solver::Auto;
        assert_eq!(auto.for_masks(true, false), Solver::GaussNewton);
        assert_eq!(auto.for_masks(false, true), Solver::GaussNewton);
        assert_eq!(auto.for_masks(false, false), Solver::Paper);
        for chosen in [Solver::Paper, Solver::GaussNewton, Solver::Contour] {
            assert_eq!(chosen.for_masks(true, true), chosen);
            assert_eq!(chosen.for_masks(false, false), chosen);
        }
    }
}
