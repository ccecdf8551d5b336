//! The `cpose` binary.

// Name every application crate so that rustc links it and its registrations are visible.
use cpose_events as _;
use cpose_imu as _;
use cpose_nerf as _;
use cpose_slam as _;

fn main() {}
