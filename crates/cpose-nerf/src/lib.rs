//! cpose-nerf: the neural-field base of cpose — cameras and rays, radiance fields, volume
//! rendering with analytic backward ([`render`]), training cameras as corrections of their
//! initial poses ([`poses`]) and the field's optimiser ([`field3d::FieldOptimizer`]), all shared
//! by the tasks of this crate and the crates above it; image metrics and a synthetic scene
//! renderer; tasks `planar` (2-D image alignment) and `nerf` (NeRF from noisy or unknown poses).
//!
//! Built on [`cpose_core`]; the event and SLAM crates build on this one.

pub use cpose_core;

pub mod camera;
pub mod data;
mod error;
pub mod field2d;
pub mod field3d;
mod field_common;
pub mod image;
pub mod mesh;
pub mod metrics;
pub mod nerf;
pub mod planar;
pub mod poses;
pub mod render;
pub mod scene;
pub mod warp2d;

pub use error::DataError;
