//! cpose-imu: IMU samples, the EuRoC reader, IMU losses through a pose field's time derivatives,
//! the IMU's motion over a frame interval as a tie on `cpose-slam`'s relative tracker
//! ([`increment`]); tasks `trajectory` (fit a pose field to poses and IMU) and `slam_imu`.

use std::path::{Path, PathBuf};

pub mod bias;
pub mod euroc;
pub mod increment;
pub mod losses;
pub mod sim;
mod slam_imu;
pub mod tracker;
mod trajectory;

pub use cpose_core::fit::{ImuMode, ImuSample};
pub use cpose_slam;

/// Errors reading IMU and trajectory data.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The file could not be read.
    #[error("cannot read {}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file's content is not what was expected.
    #[error("line {line} of {}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was expected and what was found.
        message: String,
    },
}

impl DataError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    fn parse(path: &Path, line: usize, message: String) -> Self {
        Self::Parse {
            path: path.to_path_buf(),
            line,
            message,
        }
    }
}
