//! cpose-core: continuous camera poses as differentiable functions of time.
//!
//! The [`PoseField`] trait and its implementations (PoseNet, per-frame poses, B-splines,
//! composition), SE(3) helpers and conventions, a small neural-network kit with exact time
//! derivatives, trajectory I/O and evaluation that agrees with evo, plots of trajectories, errors
//! and training curves ([`plot`]), and the task and pose-field registries the `cpose` command
//! line is built on.
//!
//! Not for: scenes, rendering or datasets of images (see `cpose-nerf` and the crates above it).

mod real;
mod time;

pub mod checkpoint;
pub mod config;
pub mod eval;
pub mod fs;
pub mod geometry;
pub mod nn;
pub mod plot;
pub mod pose_field;
pub mod progress;
pub mod provenance;
pub mod random;
pub mod registry;
pub mod run_dir;
pub mod study;
#[cfg(any(test, feature = "testing"))]
pub mod testing;

pub use config::{Config, ConfigError, RunConfig, Section};
pub use geometry::{
    EulerZyx, QuatJet, canonicalize_quat, gravity_world, hat, quat_from_wxyz, quat_from_xyzw,
    quat_to_wxyz, quat_to_xyzw, rotation_angle_between, se3_exp, se3_log, so3_exp, so3_log,
    so3_r3_exp, so3_r3_log, specific_force_body, vee,
};
pub use pose_field::{
    Composed, DiscretePoses, DiscretePosesConfig, LieSplinePoses, Order, ParamKind,
    PerDimSplinePoses, PoseBatch, PoseField, PoseFieldError, PoseNet, PoseNetConfig,
    SinusoidMotion, SplineConfig, SplineKind, SplinePoses, smooth_with_cubic_spline,
};
pub use real::Real;
pub use registry::{FieldContext, PoseFieldSpec, Task, TaskInput};
pub use time::{TimeRange, Timestamp};
