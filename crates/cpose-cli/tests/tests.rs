//! Integration tests of the `cpose` command line (one test binary, as ripgrep does).

// An integration test is its own crate: name every application crate again so that their
// registrations are linked here too (see docs/methods.md §5.4).
use cpose_events as _;
use cpose_imu as _;
use cpose_nerf as _;
use cpose_slam as _;

// The bad-input corpus: every reader and task config fed broken input, one table per family.
mod bad_input;
// Runs the built `cpose` binary: listing, and every kind of bad input.
mod binary;
// `cpose eval ate`, bad trajectory files, and a smoke run of every committed config.
mod commands;
// Every text and binary reader fed two thousand seeded random mutations of a valid file.
mod fuzz;
// Runs `cpose_cli::main_with_args` in this process, with a task and a pose field registered
// by the test itself: full runs, run folders, errors raised inside tasks.
mod in_process;
// `cpose run --resume` after SIGKILL, for every task on the study skeleton.
mod resume;
// Temporary folders and config files.
mod util;
