//! cpose-core: continuous camera poses as differentiable functions of time.
//!
//! The [`PoseField`] trait and its implementations (PoseNet, per-frame poses, B-splines,
//! composition), SE(3) helpers and conventions, a small neural-network kit with exact time
//! derivatives, trajectory I/O and evaluation that agrees with evo, and the task and pose-field
//! registries the `cpose` command line is built on.
//!
//! Not for: scenes, rendering or datasets of images (see `cpose-nerf` and the crates above it).

mod real;
mod time;

pub mod pose_field;
#[cfg(any(test, feature = "testing"))]
pub mod testing;

pub use pose_field::{
    DiscretePoses, DiscretePosesConfig, Order, ParamKind, PoseBatch, PoseField, PoseFieldError,
};
pub use real::Real;
pub use time::{TimeRange, Timestamp};
