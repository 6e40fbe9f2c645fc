//! The empirical jaw rig (Zoss et al., *An Empirical Rig for Jaw Animation*, 2018): the jaw
//! frame, traditional rigs as baselines, Posselt's envelope, the RBF manifold map and the
//! unit-cube parameterisation.

pub mod adapt;
pub mod compare;
pub mod model;
pub mod rbf;
pub mod shield;
pub mod traditional;

pub use crate::anatomy::JawFrame;
pub use model::{EnvelopeError, EnvelopeRig};
pub use traditional::{Dofs, TraditionalRig};

/// A [`Pose`](crate::geometry::Pose) in files: `{"rotation": rows, "translation"}`.
pub(crate) mod pose_serde {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::formats::PoseJson;
    use crate::geometry::Pose;

    pub fn serialize<S: Serializer>(p: &Pose, s: S) -> Result<S::Ok, S::Error> {
        PoseJson::from(p).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Pose, D::Error> {
        let pj = PoseJson::deserialize(d)?;
        let limit = crate::formats::MAX_TRANSLATION_MM;
        if pj
            .translation
            .iter()
            .any(|t| !t.is_finite() || t.abs() > limit)
        {
            return Err(serde::de::Error::custom(format!(
                "translation: {:?} is not within {limit} mm",
                pj.translation
            )));
        }
        let rotation =
            Pose::rotation_from_rows(&pj.rotation, crate::formats::ROTATION_TOLERANCE)
                .ok_or_else(|| serde::de::Error::custom("rotation: not a rotation matrix"))?;
        Ok(Pose::new(rotation, nalgebra::Vector3::from(pj.translation)))
    }
}
