//! The jaw from the skin (Zoss et al. 2019, *Accurate Markerless Jaw Tracking for Facial
//! Performance Capture*): the jaw pose predicted from a tracked face surface alone.
//!
//! [`format`] reads face sequences; [`features`] turns skin and jaw into the paper's features;
//! [`regress`] learns the mapping; [`predictor`] turns a prediction into a jaw pose;
//! [`retarget`] solves the paper's transforms that carry a mapping to a new subject, and
//! [`carry`] blends every way of carrying every mapping a model holds; [`baseline`] is the
//! paper's comparison;
//! [`eval`] scores them all.

pub mod baseline;
pub mod carry;
pub mod eval;
pub mod features;
pub mod fill;
pub mod format;
pub mod model;
pub mod plot;
pub mod regress;
pub mod retarget;
pub mod subject;
