//! The rig for animators in the browser (`jawtrack view`): a local page that draws the arches
//! and mandible with WebGL2, three sliders in degrees and mm whose lateral and protrusion
//! ranges follow the opening, IK by dragging a vertex (Eq. 10), keyframes exported as glTF,
//! and, with a tracked capture, a timeline of the motion with each camera's overlay, where a
//! frame's arches are moved by hand and the frames after it tracked again ([`Workbench`]); with
//! a capture, its first pose picked by clicks and written as init.json (`first_pose`). The rig
//! is optional with a capture.
//!
//! The server ([`serve`]) answers the page's questions through [`Viewer`]; the drawing, the
//! orbit camera, picking and the keys live in the page (`page/view.js`).

mod first_pose;
mod page;
mod pictures;
mod scene;
mod server;
mod workbench;

pub use scene::{
    AnimationQuery, IkQuery, IkReply, Meshes, Part, PoseQuery, PoseReply, Refused, SceneReply,
    Viewer,
};
pub use server::{Limits, serve, serve_with};
pub use workbench::{Retracking, Workbench, backup_path};
