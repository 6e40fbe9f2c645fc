//! Motion out: jaw poses as glTF for animation packages ([`gltf`]) and, in anatomical units
//! ([`crate::anatomy::motion`]), as CSV for analysis ([`csv`]).

pub mod csv;
pub mod gltf;
