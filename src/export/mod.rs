//! Motion out: jaw poses in anatomical units ([`motion`]), as glTF for animation packages
//! ([`gltf`]) and CSV for analysis ([`csv`]).

pub mod csv;
pub mod gltf;
pub mod motion;
