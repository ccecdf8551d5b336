//! The crate's error type.

use std::path::PathBuf;

use cpose_core::PoseFieldError;
use cpose_nerf::DataError;

/// Errors of the event readers, writers and simulator, and of event streams built or queried in
/// memory ([`crate::EventStream`]); file errors name the file and, where it helps, the line,
/// array or entry.
///
/// The byte-level ZIP reader reports [`crate::zip::ZipError`] (and `cpose-nerf`'s NumPy parser
/// its `NpyError`), which the `.npz` readers turn into [`EventsError::Format`] with the file and
/// the entry named.
#[derive(Debug, thiserror::Error)]
pub enum EventsError {
    /// A file or folder could not be read.
    #[error("cannot read {}: {error}", .path.display())]
    Read {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A file or folder could not be written.
    #[error("cannot write {}: {error}", .path.display())]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A file's content is not what its format requires.
    #[error("{}: {}expected {expected}, got {found}",
        .path.display(), .place.as_ref().map(|p| format!("{p}: ")).unwrap_or_default())]
    Format {
        /// The file.
        path: PathBuf,
        /// Where in the file: `line 12`, `array 't'`, `entry "x.npy"`; `None` for the whole file.
        place: Option<String>,
        /// What the reader expected.
        expected: String,
        /// What it found.
        found: String,
    },
    /// A pose, intrinsics or image file of a dataset, or an image written (`cpose-nerf`'s error
    /// names the file).
    #[error(transparent)]
    Data(#[from] DataError),
    /// Event columns of different lengths.
    #[error("event columns: expected equal lengths, got t {t}, x {x}, y {y}, p {p}")]
    ColumnLengths {
        /// Length of `t`.
        t: usize,
        /// Length of `x`.
        x: usize,
        /// Length of `y`.
        y: usize,
        /// Length of `p`.
        p: usize,
    },
    /// An event outside the sensor.
    #[error("event {index}: expected a pixel inside the {width}×{height} sensor, got ({x}, {y})")]
    OutsideSensor {
        /// Index of the event.
        index: usize,
        /// Its column.
        x: u16,
        /// Its row.
        y: u16,
        /// Sensor width.
        width: u16,
        /// Sensor height.
        height: u16,
    },
    /// A polarity other than ±1.
    #[error("event {index}: expected polarity +1 or −1, got {p}")]
    Polarity {
        /// Index of the event.
        index: usize,
        /// The polarity found.
        p: i8,
    },
    /// An event earlier than its predecessor.
    #[error(
        "event {index}: expected times in non-decreasing order, got {t_ns} ns after {prev_ns} ns"
    )]
    Unsorted {
        /// Index of the event.
        index: usize,
        /// Its time, ns.
        t_ns: i64,
        /// The previous event's time, ns.
        prev_ns: i64,
    },
    /// A time window whose end is before its start.
    #[error("time window: expected start ≤ end, got [{start_ns} ns, {end_ns} ns)")]
    ReversedWindow {
        /// Start, ns.
        start_ns: i64,
        /// End, ns.
        end_ns: i64,
    },
    /// A sensor without pixels.
    #[error("sensor: expected width and height ≥ 1, got {width}×{height}")]
    EmptySensor {
        /// Width.
        width: u16,
        /// Height.
        height: u16,
    },
    /// A pose field could not be evaluated.
    #[error(transparent)]
    PoseField(#[from] PoseFieldError),
    /// A configuration value is out of its range; `key` names it.
    #[error("{key}: expected {expected}, got {found}")]
    Invalid {
        /// The parameter, e.g. `simulator.threshold`.
        key: &'static str,
        /// What it must satisfy.
        expected: &'static str,
        /// The value found.
        found: String,
    },
}

impl EventsError {
    /// A [`EventsError::Format`] error.
    pub(crate) fn format(
        path: impl Into<PathBuf>,
        place: Option<String>,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        Self::Format {
            path: path.into(),
            place,
            expected: expected.into(),
            found: found.into(),
        }
    }
}
