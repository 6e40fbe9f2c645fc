//! The files jawtrack writes for other programs and reads back from them: a pose (`pose`),
//! tracks.json and gt/poses.json (`tracks`), jaw poses (`jaw`, `jawtrack-jaw/1`). The capture
//! folder's own documents (capture.json, cameras, init.json) are the capture's.

pub mod jaw;
pub mod pose;
pub mod tracks;

pub use jaw::{JAW_FORMAT, JawPoses, read_jaw_poses, write_jaw_poses};
pub use pose::{MAX_TRANSLATION_MM, PoseJson, ROTATION_TOLERANCE, read_pose_file};
pub use tracks::{
    ArchEnergyJson, EdgeOffsetsJson, FramePoses, FrameRecordJson, JawSource, MAX_JAW_MM,
    PerArchJson, Status, TRACKS_FORMAT, TrackedJson, TracksJson, read_poses, read_tracks,
};
