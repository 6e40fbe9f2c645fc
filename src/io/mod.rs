//! Files in and out, safely: a file a user gave is read only when it is a regular file of
//! bounded size (`read`), JSON with errors that name the file and the field (`json`), and
//! every output written atomically, never over a file the command reads (`write`); a hash
//! for the fingerprints written into them (`fnv`).

mod fnv;
pub mod json;
pub mod read;
mod write;

pub use fnv::Fnv;
pub use json::{check_finite, parse_json, read_json, read_json_noting_unknown};
pub use read::{open_input, quote, read_text};
pub use write::{
    Reads, check_outputs, check_replaceable, encode_png, resolved, write_atomic, write_json_atomic,
};
