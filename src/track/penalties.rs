//! What the search adds to the energy besides the cross-label term: what the two arches'
//! anatomy forbids. The arches cannot pass through each other ([`Contact`]), and the jaw
//! moves on a low-dimensional manifold ([`JawManifold`]).

use super::contact::Contact;
use super::manifold::JawManifold;
use crate::arch::ArchPoses;

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
