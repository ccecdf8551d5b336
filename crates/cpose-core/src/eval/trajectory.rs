//! A timed sequence of poses, and the errors of building or reading one.

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

/// Everything that can go wrong when building, reading or writing a [`Trajectory`].
///
/// File errors name the 1-based line and, last, the file.
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// The file could not be opened or read (missing, a folder, not UTF-8, …).
    #[error("cannot read trajectory file {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file could not be written.
    #[error("cannot write trajectory file {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// No pose line at all (only comments or blank lines, or nothing).
    #[error("expected at least one pose line, got none: {}", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A value that does not parse as a number.
    #[error("line {line}: expected a number for `{column}`, got `{text}`: {}", path.display())]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Column name (`timestamp`, `tx`, …, `qw`).
        column: &'static str,
        /// The offending text.
        text: String,
    },
    /// A value that parses but is NaN or infinite.
    #[error("line {line}: expected a finite number for `{column}`, got `{text}`: {}", path.display())]
    NotFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Column name.
        column: &'static str,
        /// The offending text.
        text: String,
    },
    /// A quaternion whose norm is (numerically) zero, so it names no rotation.
    #[error("line {line}: expected a non-zero quaternion `qx qy qz qw`, got norm {norm:e}: {}", path.display())]
    ZeroQuaternion {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Its Euclidean norm.
        norm: f64,
    },
    /// A timestamp smaller than the one before it.
    #[error("line {line}: expected increasing timestamps, got {timestamp} after {previous}: {}", path.display())]
    UnsortedTimestamp {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The previous timestamp, seconds.
        previous: f64,
        /// This line's timestamp, seconds.
        timestamp: f64,
    },
    /// A line with the wrong number of values for its format.
    #[error("line {line}: expected {expected}, got {got}: {}", path.display())]
    Columns {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What the format needs.
        expected: &'static str,
        /// Number of values found.
        got: usize,
    },
    /// A KITTI matrix that is not a rotation.
    #[error("line {line}: expected a rotation matrix in `r11 … r33`, got one {defect:.2e} away from orthonormal: {}", path.display())]
    NotARotation {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// `max(‖RᵀR − I‖_F, |det R − 1|)`.
        defect: f64,
    },
    /// A file whose format cannot be told from its first data line.
    #[error(
        "cannot tell the trajectory format: expected 8 values (TUM), 12 (KITTI) or a csv of at least 8 (EuRoC) on the first data line, got {got}; name the format with --format: {}",
        path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Number of values on its first data line.
        got: usize,
    },
    /// A KITTI trajectory read without its times file.
    #[error("a KITTI trajectory has no timestamps: expected its times file (one time in seconds per line, as KITTI's times.txt; on the command line --gt-times, --est-times or --times) for: {}", path.display())]
    MissingTimes {
        /// The pose file.
        path: PathBuf,
    },
    /// A times file with another number of lines than its pose file has poses.
    #[error("expected one time per pose: {} has {poses} poses, {} {times} times", path.display(), times_path.display())]
    TimesCount {
        /// The pose file.
        path: PathBuf,
        /// Number of poses.
        poses: usize,
        /// The times file.
        times_path: PathBuf,
        /// Number of times.
        times: usize,
    },
    /// A file whose values break a [`Trajectory`] invariant (timestamps out of order …).
    #[error("{reason}: {}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The broken invariant.
        reason: String,
    },
    /// [`Trajectory::new`] got different numbers of timestamps and poses.
    #[error("expected as many poses as timestamps ({timestamps}), got {poses}")]
    LengthMismatch {
        /// Number of timestamps.
        timestamps: usize,
        /// Number of poses.
        poses: usize,
    },
    /// [`Trajectory::new`] got a NaN or infinite timestamp.
    #[error("pose {index}: expected a finite timestamp, got {timestamp}")]
    NonFiniteTimestamp {
        /// 0-based index.
        index: usize,
        /// The timestamp.
        timestamp: f64,
    },
    /// [`Trajectory::new`] got timestamps that do not strictly increase.
    #[error(
        "pose {index}: expected strictly increasing timestamps, got {timestamp} after {previous}"
    )]
    NotIncreasing {
        /// 0-based index.
        index: usize,
        /// The previous timestamp.
        previous: f64,
        /// This timestamp.
        timestamp: f64,
    },
    /// [`Trajectory::new`] got a pose with a NaN or infinite entry.
    #[error("pose {index}: expected finite translation and rotation, got {pose}")]
    NonFinitePose {
        /// 0-based index.
        index: usize,
        /// The pose, printed.
        pose: String,
    },
}

/// A trajectory: poses `world_from_body` (for a camera, `world_from_cam`) at timestamps in
/// seconds, as read from the file (e.g. Unix time in a TUM file).
///
/// Invariants, checked by [`Trajectory::new`]: as many poses as timestamps, timestamps finite and
/// strictly increasing, poses finite. It may be empty.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    timestamps_secs: Vec<f64>,
    world_from_body: Vec<Isometry3<f64>>,
}

impl Trajectory {
    /// A trajectory from timestamps (seconds) and poses `world_from_body`, checking the
    /// invariants listed on the type.
    pub fn new(
        timestamps_secs: Vec<f64>,
        world_from_body: Vec<Isometry3<f64>>,
    ) -> Result<Self, TrajectoryError> {
        if timestamps_secs.len() != world_from_body.len() {
            return Err(TrajectoryError::LengthMismatch {
                timestamps: timestamps_secs.len(),
                poses: world_from_body.len(),
            });
        }
        for (index, &timestamp) in timestamps_secs.iter().enumerate() {
            if !timestamp.is_finite() {
                return Err(TrajectoryError::NonFiniteTimestamp { index, timestamp });
            }
            if index > 0 && timestamp <= timestamps_secs[index - 1] {
                return Err(TrajectoryError::NotIncreasing {
                    index,
                    previous: timestamps_secs[index - 1],
                    timestamp,
                });
            }
        }
        for (index, pose) in world_from_body.iter().enumerate() {
            let finite = pose.translation.vector.iter().all(|v| v.is_finite())
                && pose.rotation.coords.iter().all(|v| v.is_finite());
            if !finite {
                return Err(TrajectoryError::NonFinitePose {
                    index,
                    pose: format!("{pose}"),
                });
            }
        }
        Ok(Self {
            timestamps_secs,
            world_from_body,
        })
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.timestamps_secs.len()
    }

    /// Whether there are no poses.
    pub fn is_empty(&self) -> bool {
        self.timestamps_secs.is_empty()
    }

    /// Timestamps in seconds, strictly increasing.
    pub fn timestamps_secs(&self) -> &[f64] {
        &self.timestamps_secs
    }

    /// Poses `world_from_body`, one per timestamp.
    pub fn poses(&self) -> &[Isometry3<f64>] {
        &self.world_from_body
    }

    /// Positions of the body in the world (the translation parts of the poses).
    pub fn positions(&self) -> Vec<nalgebra::Vector3<f64>> {
        self.world_from_body
            .iter()
            .map(|p| p.translation.vector)
            .collect()
    }

    /// Iterates over `(timestamp_secs, world_from_body)`.
    pub fn iter(&self) -> impl Iterator<Item = (f64, &Isometry3<f64>)> {
        self.timestamps_secs
            .iter()
            .copied()
            .zip(self.world_from_body.iter())
    }
}

/// The lines of a trajectory file that repeated the timestamp of the line before them: each one's
/// pose replaced that line's (the last pose of a timestamp is kept, the one evo's association
/// picks when the file is the longer trajectory). Real recordings have them (TUM RGB-D's fr2/desk
/// ground truth has one).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Duplicates {
    /// 1-based line numbers of the repeats.
    pub lines: Vec<usize>,
}

impl Duplicates {
    /// Whether no timestamp repeated.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }
}

/// Collects a file's poses line by line: timestamps may not decrease, and a repeated one
/// replaces the pose before it ([`Duplicates`]).
pub(crate) struct PoseLines<'a> {
    path: &'a Path,
    times: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
    duplicates: Duplicates,
}

impl<'a> PoseLines<'a> {
    pub(crate) fn new(path: &'a Path) -> Self {
        Self {
            path,
            times: Vec::new(),
            poses: Vec::new(),
            duplicates: Duplicates::default(),
        }
    }

    /// Adds the pose of 1-based `line` at `time` seconds.
    pub(crate) fn push(
        &mut self,
        line: usize,
        time: f64,
        pose: Isometry3<f64>,
    ) -> Result<(), TrajectoryError> {
        match self.times.last() {
            Some(&previous) if time < previous => {
                return Err(TrajectoryError::UnsortedTimestamp {
                    path: self.path.to_path_buf(),
                    line,
                    previous,
                    timestamp: time,
                });
            }
            Some(&previous) if time == previous => {
                self.poses.pop();
                self.times.pop();
                self.duplicates.lines.push(line);
            }
            _ => {}
        }
        self.times.push(time);
        self.poses.push(pose);
        Ok(())
    }

    /// The trajectory and the repeats; a file without poses is an error.
    pub(crate) fn finish(self) -> Result<(Trajectory, Duplicates), TrajectoryError> {
        if self.times.is_empty() {
            return Err(TrajectoryError::Empty {
                path: self.path.to_path_buf(),
            });
        }
        Ok((Trajectory::new(self.times, self.poses)?, self.duplicates))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_checks_lengths_order_and_finiteness() {
        let id = Isometry3::identity();
        assert!(matches!(
            Trajectory::new(vec![0.0, 1.0], vec![id]),
            Err(TrajectoryError::LengthMismatch {
                timestamps: 2,
                poses: 1
            })
        ));
        assert!(matches!(
            Trajectory::new(vec![1.0, 1.0], vec![id, id]),
            Err(TrajectoryError::NotIncreasing { index: 1, .. })
        ));
        assert!(matches!(
            Trajectory::new(vec![f64::NAN], vec![id]),
            Err(TrajectoryError::NonFiniteTimestamp { index: 0, .. })
        ));
        let bad = Isometry3::translation(f64::INFINITY, 0.0, 0.0);
        assert!(matches!(
            Trajectory::new(vec![0.0], vec![bad]),
            Err(TrajectoryError::NonFinitePose { index: 0, .. })
        ));
        let t = Trajectory::new(vec![0.0, 0.5], vec![id, id]).unwrap();
        assert_eq!(t.len(), 2);
        assert!(!t.is_empty());
        assert_eq!(t.iter().count(), 2);
    }
}
