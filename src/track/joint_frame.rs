//! A frame by the Gauss-Newton solver ([`super::joint`]): where it starts (the frame's starts,
//! and the jaw prior's poses near them for the lower arch), what anatomy adds as residuals
//! (the tracker's penalties as hinges), and which of result and start stands, by the energy.

use nalgebra::Vector6;

use super::align::FrameReads;
use super::edge_offsets::{EdgeOffsets, ViewOffsets};
use super::joint::{JawHinge, Terms, align_both, information_at, offsets_at};
use super::penalties::Penalties;
use super::prior::JawPrior;
use super::search::{GaussNewtonSettings, SearchSettings};
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks, MaskMode};
use crate::energy::contour::ContourEdges;
use crate::energy::edge_terms::{EdgeParams, EdgeQuery, EdgeSample};
use crate::energy::smooth::Matrix12;
use crate::energy::{Energy, EnergyEngine};
use crate::error::Result;
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// What stays the same over a run.
pub struct JointFrame<'a> {
    pub capture: &'a Capture,
    pub search: &'a SearchSettings,
    pub prior: &'a JawPrior,
    pub penalties: &'a Penalties,
    /// Each arch's contour edges (upper, lower).
    pub edges: &'a [ContourEdges; 2],
}

/// What [`JointFrame::solve`] found.
pub struct JointFound {
    pub poses: ArchPoses,
    /// Their energies (upper, lower).
    pub energies: [Energy; 2],
    pub evaluations: usize,
    /// Gauss-Newton steps taken.
    pub steps: usize,
    /// The masks' information about the solver's result ([`super::joint::JointAligned`]).
    pub information: Matrix12,
    /// Each camera's offset of its masks' edges after the frame, where they are estimated.
    pub offsets: Option<EdgeOffsets>,
}

impl JointFrame<'_> {
    /// Both arches with their contour edges.
    fn arches(&self) -> [(&Mesh, &ContourEdges); 2] {
        [
            (self.capture.upper(), &self.edges[0]),
            (self.capture.lower(), &self.edges[1]),
        ]
    }

    /// Whether the masks label each arch apart.
    fn apart(&self) -> bool {
        matches!(self.capture.mask_mode(), MaskMode::PerArch { .. })
    }

    fn with_views<T>(
        &self,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        f: impl FnOnce((&[&Camera], Terms)) -> T,
    ) -> T {
        with_views(self.capture, engine, masks, f)
    }

    /// The information the masks give about `poses`: for a frame another search found, so
    /// that the window over frames weighs it too.
    pub fn information(
        &self,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        poses: &ArchPoses,
    ) -> Result<Matrix12> {
        let (weights, gn) = (self.search.weights(), &self.search.gauss_newton);
        self.with_views(engine, masks, |views| {
            information_at(self.arches(), poses, views, self.apart(), &weights, gn)
        })
    }

    /// The offsets `offsets` (per camera) of the cameras with masks this frame, as
    /// [`align_both`] takes them: less the whole pixels the masks are corrected by
    /// ([`super::edge_offsets::corrected`]), whose samples are drawn wider by the rest; and
    /// those cameras' indices.
    fn view_offsets(&self, masks: &FrameMasks, offsets: &EdgeOffsets) -> (Vec<usize>, ViewOffsets) {
        let reads = FrameReads::new(self.capture, masks);
        let indices: Vec<usize> = (0..reads.len()).map(|k| reads.index(k)).collect();
        let (whole, applied) = (offsets.whole_px(), offsets.applied());
        let mut prior = offsets.of(&indices);
        for (p, &c) in prior.px.iter_mut().zip(&indices) {
            *p -= f64::from(whole[c]);
        }
        let applied = indices.iter().map(|&c| applied[c]).collect();
        (indices, ViewOffsets { prior, applied })
    }

    /// The offsets after a frame whose poses another search found at `poses`: measured
    /// there ([`offsets_at`]).
    pub fn measure_offsets(
        &self,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        poses: &ArchPoses,
        offsets: &EdgeOffsets,
    ) -> Result<EdgeOffsets> {
        let (weights, gn) = (self.search.weights(), &self.search.gauss_newton);
        let (indices, view) = self.view_offsets(masks, offsets);
        let measured = self.with_views(engine, masks, |views| {
            offsets_at(
                self.arches(),
                poses,
                (views, &view),
                self.apart(),
                &weights,
                gn,
            )
        })?;
        Ok(measured.map_or_else(|| offsets.clone(), |m| carried(offsets, &indices, &m)))
    }

    /// Each candidate scored on both arches: the objective of each plus the penalties, and
    /// the energies (upper, lower).
    fn score_both(
        &self,
        known: &mut Known,
        candidates: &[ArchPoses],
    ) -> Result<Vec<(f64, [Energy; 2])>> {
        let weights = self.search.weights();
        let upper = known.evaluate(Arch::Upper, candidates)?;
        let lower = known.evaluate(Arch::Lower, candidates)?;
        Ok(upper
            .into_iter()
            .zip(lower)
            .zip(candidates)
            .map(|((u, l), c)| {
                let total = u.objective(&weights) + l.objective(&weights) + self.penalties.of(c);
                (total, [u, l])
            })
            .collect())
    }

    /// Both arches' poses by Gauss-Newton ([`align_both`]) from the best of the frame's
    /// `starts`.
    pub fn solve(
        &self,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        starts: &[ArchPoses],
        offsets: Option<&EdgeOffsets>,
    ) -> Result<JointFound> {
        let weights = self.search.weights();
        let gn = &self.search.gauss_newton;
        let known = &mut Known {
            engine,
            energies: Vec::new(),
            evaluations: 0,
        };
        let scored = self.score_both(known, starts)?;
        let (k, _) = scored
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.0.total_cmp(&b.1.0))
            .expect("a start");
        let mut start = starts[k];
        if gn.jaw_prior_nearest > 0 {
            // The lower arch from the jaw prior's poses near the starts too, placed on the
            // upper arch just chosen.
            let jaws: Vec<Pose> = starts.iter().map(ArchPoses::jaw).collect();
            let mut options: Vec<ArchPoses> = starts
                .iter()
                .map(|s| start.with(Arch::Lower, s.lower))
                .collect();
            options.extend(
                self.prior
                    .nearest_to(&jaws, gn.jaw_prior_nearest)
                    .iter()
                    .map(|j| start.with(Arch::Lower, start.upper.compose(j))),
            );
            let energies = known.evaluate(Arch::Lower, &options)?;
            let (best, _) = options
                .iter()
                .zip(energies)
                .map(|(o, e)| (o, e.objective(&weights) + self.penalties.of(o)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("options");
            start = *best;
        }
        let view_offsets = offsets.map(|o| self.view_offsets(masks, o));
        let found = with_hinges(self.penalties, gn, |hinges| {
            self.with_views(engine, masks, |views| {
                align_both(
                    self.arches(),
                    start,
                    (views, view_offsets.as_ref().map(|v| &v.1)),
                    self.apart(),
                    hinges,
                    &weights,
                    gn,
                )
            })
        })?;
        let offsets = match (offsets, &view_offsets, &found.offsets) {
            (Some(before), Some((indices, _)), Some(found)) => {
                Some(carried(before, indices, found))
            }
            _ => offsets.cloned(),
        };
        let (found, steps, information) = (found.poses, found.steps, found.information);
        // The result, each arch's result with the other's start, and the start: where the
        // steps made an arch worse (too few samples to hold it, an edge that is another's),
        // its start stands.
        let candidates = [
            found,
            start.with(Arch::Upper, found.upper),
            start.with(Arch::Lower, found.lower),
            start,
        ];
        let (best, (_, energies)) = candidates
            .into_iter()
            .zip(self.score_both(known, &candidates)?)
            .min_by(|a, b| a.1.0.total_cmp(&b.1.0))
            .expect("candidates");
        Ok(JointFound {
            poses: best,
            energies,
            evaluations: known.evaluations,
            steps,
            information,
            offsets,
        })
    }
}

/// The take's offsets `before` after a frame measured `found` for the cameras `indices` (less
/// the whole pixels the masks were corrected by, added back here).
fn carried(before: &EdgeOffsets, indices: &[usize], found: &EdgeOffsets) -> EdgeOffsets {
    let whole = before.whole_px();
    let mut found = found.clone();
    for (p, &c) in found.px.iter_mut().zip(indices) {
        *p += f64::from(whole[c]);
    }
    before.after(indices, &found)
}

/// The energies a frame's solve has evaluated: a start, a prior's pose or the result may come
/// back among later candidates, and an energy is a function of the poses alone (the frame's
/// masks set).
struct Known<'e> {
    engine: &'e dyn EnergyEngine,
    energies: Vec<(Arch, ArchPoses, Energy)>,
    /// The engine's evaluations so far.
    evaluations: usize,
}

impl Known<'_> {
    /// `arch`'s energy at each candidate, evaluating only those not known yet.
    fn evaluate(&mut self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>> {
        let find = |known: &[(Arch, ArchPoses, Energy)], c: &ArchPoses| {
            known
                .iter()
                .find(|(a, p, _)| *a == arch && p == c)
                .map(|(.., e)| e.clone())
        };
        let mut new: Vec<ArchPoses> = Vec::new();
        for c in candidates {
            if find(&self.energies, c).is_none() && !new.contains(c) {
                new.push(*c);
            }
        }
        if !new.is_empty() {
            let energies = self.engine.evaluate(arch, &new)?;
            self.evaluations += new.len();
            self.energies
                .extend(new.into_iter().zip(energies).map(|(c, e)| (arch, c, e)));
        }
        Ok(candidates
            .iter()
            .map(|c| find(&self.energies, c).expect("evaluated"))
            .collect())
    }
}

/// `f` given the penalties' anatomy as Gauss-Newton's residuals in the jaw pose (their
/// stiffnesses `gn`'s; a stiffness of 0 leaves one out).
pub fn with_hinges<T>(
    penalties: &Penalties,
    gn: &GaussNewtonSettings,
    f: impl FnOnce(&[JawHinge]) -> T,
) -> T {
    let contact = penalties.contact.as_ref();
    let manifold = penalties.manifold.as_ref();
    let depth = |jaw: &Pose| contact.map_or(0.0, |c| c.depth(jaw));
    let off = |jaw: &Pose| manifold.map_or(0.0, |m| m.distance_mm(jaw));
    let mut hinges = Vec::new();
    if let Some(c) = contact.filter(|_| gn.contact_stiffness > 0.0) {
        hinges.push(JawHinge {
            distance_mm: &depth,
            tolerance_mm: c.tolerance_mm(),
            stiffness: gn.contact_stiffness,
        });
    }
    if let Some(m) = manifold.filter(|_| gn.manifold_stiffness > 0.0) {
        hinges.push(JawHinge {
            distance_mm: &off,
            tolerance_mm: m.tolerance_mm(),
            stiffness: gn.manifold_stiffness,
        });
    }
    f(&hinges)
}

/// `f` given the cameras that have masks this frame and `engine`'s edge terms over them (the
/// engine holds the frame's masks).
pub fn with_views<T>(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    f: impl FnOnce((&[&Camera], Terms)) -> T,
) -> T {
    let reads = FrameReads::new(capture, masks);
    let cameras: Vec<&Camera> = (0..reads.len()).map(|k| reads.camera(k)).collect();
    let indices: Vec<usize> = (0..reads.len()).map(|k| reads.index(k)).collect();
    let terms = |samples: &[EdgeSample], moved: &[Vector6<f64>; 2], params: &EdgeParams| {
        engine.edge_terms(&EdgeQuery {
            samples,
            cameras: &indices,
            moved: *moved,
            params: *params,
        })
    };
    f((&cameras, &terms))
}
