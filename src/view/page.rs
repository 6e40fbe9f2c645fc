//! The page's files, in the binary: nothing is fetched from anywhere but the server.

pub const INDEX: &str = include_str!("page/index.html");
pub const SCRIPT: &str = include_str!("page/view.js");
