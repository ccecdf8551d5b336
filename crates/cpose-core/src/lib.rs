//! cpose-core: continuous camera poses as differentiable functions of time.
//!
//! The [`PoseField`] trait and its implementations (PoseNet, per-frame poses, B-splines,
//! composition), SE(3) helpers and conventions, a small neural-network kit with exact time
//! derivatives, trajectory I/O and evaluation that agrees with evo, plots of trajectories, errors
//! and training curves ([`plot`]), and the task and pose-field registries the `cpose` command
//! line is built on.
//!
//! Not for: scenes, rendering or datasets of images (see `cpose-nerf` and the crates above it).
//!
//! Fit PoseNet to a few timed poses, then query it between them, in the world:
//!
//! ```
//! use cpose_core::fit::{self, FitData, FitSettings, ImuMode};
//! use cpose_core::{PoseNetConfig, TimeRange};
//! use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
//!
//! let times: Vec<f64> = (0..9).map(|i| 0.25 * i as f64).collect();
//! let poses: Vec<Isometry3<f64>> = times
//!     .iter()
//!     .map(|&t| {
//!         let turn = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.3 * t));
//!         Isometry3::from_parts(Translation3::new(t, 0.2 * t * t, 1.5), turn)
//!     })
//!     .collect();
//! let range = TimeRange::new(0.0, 2.0).expect("start < end");
//! // Bands for poses every 0.25 s (see `pose_field::posenet`).
//! let bands = cpose_core::pose_field::posenet::bands_for_spacing(range, 0.25, 1.0);
//! let mut field = PoseNetConfig { bands, ..PoseNetConfig::default() }.init::<f32>(range)?;
//! let data = FitData { times: &times, poses: &poses, imu: &[] };
//! let (frame, report) = fit::fit(&mut field, data, &FitSettings::default(), ImuMode::None, 0)?;
//! assert!(report.known_trans_err_m < 0.01, "{report:?}");
//! // Between two samples: the position to a centimetre, the velocity (truth: 1 m/s along x)
//! // to a fifth.
//! let midway = &fit::sample(&field, &frame, &[0.875])?[0];
//! assert!((midway.pose.translation.x - 0.875).abs() < 0.01, "{midway:?}");
//! assert!((midway.lin_vel_world.x - 1.0).abs() < 0.2, "{midway:?}");
//! # Ok::<(), anyhow::Error>(())
//! ```

mod real;
mod time;

pub mod checkpoint;
pub mod config;
pub mod eval;
pub mod fit;
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
