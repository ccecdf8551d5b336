//! cpose-slam: RGB-D dense tracking and mapping with a neural map, PoseNet relative to a
//! reference frame (previous camera, world, random, intrinsic motion frame); Replica, ScanNet and
//! TUM-RGBD readers; task `slam`.

pub use cpose_nerf;

pub mod data;
pub mod map;
pub mod slam;
pub mod surface;
pub mod synth;
mod synth_task;
pub mod task;
pub mod track;
