//! jawtrack: track the teeth in multi-camera video and learn how the jaw moves
//! (Yang et al., *Building Anatomically Realistic Jaw Kinematics Model from Data*, 2019).
//!
//! Data flows one way: [`capture`] → [`energy`] → track → rig; [`skin`] predicts the jaw from
//! the face surface (Zoss et al. 2019). [`geometry`] is shared;
//! [`synth`] writes synthetic captures with ground truth.

pub mod anatomy;
pub mod arch;
pub mod batch;
pub mod capture;
pub mod energy;
pub mod envelope;
pub mod error;
pub mod export;
pub mod footage;
pub mod formats;
pub mod geometry;
pub mod io;
pub mod mesh;
pub mod rig;
pub mod segment;
pub mod settings;
pub mod skin;
pub mod stats;
pub mod synth;
pub mod track;
pub mod view;

pub use error::{Error, Result};
