//! What the search adds to the energy besides the cross-label term: what the two arches'
//! anatomy forbids. The arches cannot pass through each other ([`Contact`]), and the jaw
//! moves on a low-dimensional manifold ([`JawManifold`]).

use super::contact::{Contact, ContactSettings};
use super::manifold::JawManifold;
use super::prior::{JawPrior, centre};
use super::settings::TrackSettings;
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, MaskMode};

#[derive(Debug, Clone)]
pub struct Penalties {
    pub contact: Option<Contact>,
    pub manifold: Option<JawManifold>,
}

impl Penalties {
    /// No penalty: the energy alone (the bench's floor).
    pub const NONE: Penalties = Penalties {
        contact: None,
        manifold: None,
    };

    /// The objective units (pixels) these poses cost.
    pub fn of(&self, poses: &ArchPoses) -> f64 {
        if self.contact.is_none() && self.manifold.is_none() {
            return 0.0;
        }
        let jaw = poses.jaw();
        self.contact.as_ref().map_or(0.0, |c| c.penalty(&jaw))
            + self.manifold.as_ref().map_or(0.0, |m| m.penalty(&jaw))
    }
}

/// The jaw prior and the penalties of a run over `capture` (its `settings` made for it,
/// `TrackSettings::for_capture`), fitted around `start`, the poses tracking starts from.
pub fn prior_and_penalties(
    capture: &Capture,
    settings: &TrackSettings,
    start: &ArchPoses,
) -> (JawPrior, Penalties) {
    // The prior serves both mask modes: with combined masks a lower-arch start could win by
    // covering the upper arch's pixels, which the contact penalty forbids (docs/tracking.md).
    // Which side of each arch the other is on comes from the poses tracking starts from.
    let prior = match &settings.jaw_space {
        Some(space) => JawPrior::of_poses(
            &space.poses,
            settings.jaw_prior_grid.iter().product(),
            settings.jaw_prior_nearest,
            centre(capture, Arch::Lower),
        ),
        None => JawPrior::new(
            capture.upper(),
            capture.lower(),
            &start.jaw(),
            settings.jaw_prior_grid,
            settings.jaw_prior_fine_grid,
            settings.jaw_prior_nearest,
            centre(capture, Arch::Lower),
        ),
    };
    let contact = (settings.contact_weight > 0.0).then(|| {
        Contact::new(
            capture.upper(),
            capture.lower(),
            &start.jaw(),
            ContactSettings {
                weight: settings.contact_weight,
                tolerance_mm: settings.contact_tolerance_mm,
            },
        )
    });
    let per_arch = matches!(capture.mask_mode(), MaskMode::PerArch { .. });
    let manifold =
        (per_arch && settings.jaw_manifold_weight > 0.0 && prior.fine.len() >= 4).then(|| {
            let new = match settings.jaw_space {
                Some(_) => JawManifold::sampled,
                None => JawManifold::new,
            };
            new(
                &prior.fine,
                capture.lower(),
                settings.jaw_manifold_weight,
                settings.jaw_manifold_tolerance_mm,
            )
        });
    (prior, Penalties { contact, manifold })
}
