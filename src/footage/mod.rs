//! Footage in: calibration files from other tools, video frames, camera sync. Everything
//! here writes the capture format's files; nothing reads back from the layers above.

pub mod calib;
pub mod masks;
pub mod sync;
pub mod video;
