//! Tracking: the pose search per arch and frame (`search`, the paper's), Gauss-Newton on the
//! silhouettes per arch (`align`) and over both arches at once (`joint`; a frame of it,
//! `joint_frame`), both arches found from the masks alone (`locate`: no init.json, or lost), the frame loop around them (`sequence`, its settings in `settings`) and
//! where it stands between frames (`state`), the jaw prior's starts (`prior`), what anatomy
//! adds to the objective (`penalties`: the arches' non-penetration, `contact`, and the jaw's
//! manifold, `manifold`), tracks.json as it is written (`output`), scoring against ground
//! truth (`score`) and overlays (`overlay`); the window over frames that settles each frame
//! with its neighbours (`window`); chunks of a take tracked apart joined into one run
//! (`merge`).

pub mod align;
pub mod contact;
pub mod edge_offsets;
pub mod floor;
pub mod joint;
pub mod joint_frame;
pub mod locate;
pub mod manifold;
pub mod mask_source;
pub mod merge;
pub mod output;
pub mod overlay;
pub mod penalties;
pub mod prior;
pub mod score;
pub mod search;
pub mod sequence;
pub mod session;
pub mod settings;
pub mod state;
pub mod window;

pub use mask_source::MaskSource;
pub use search::{ArchSearch, Found, GaussNewtonSettings, SearchSettings, Solver, search};
pub use sequence::{Status, prior_and_penalties, track_frames};
pub use session::{Session, SessionOptions, Summary, score_records};
pub use settings::{JawSpace, LabelledSettings, TrackSettings};
pub use state::{FrameResult, TrackState};
