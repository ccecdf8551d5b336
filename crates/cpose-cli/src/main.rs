//! The `cpose` binary; everything but the linking lives in the `cpose_cli` library.

// Name every application crate so that rustc links it and its registrations are visible.
use cpose_events as _;
use cpose_imu as _;
use cpose_nerf as _;
use cpose_slam as _;

fn main() -> std::process::ExitCode {
    cpose_cli::main_with_args(std::env::args_os())
}
