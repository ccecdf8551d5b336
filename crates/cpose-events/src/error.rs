//! The crate's error type.

use std::path::PathBuf;

use cpose_core::PoseFieldError;
use cpose_nerf::data::DataError;
use cpose_nerf::image::ImageError;

use crate::stream::StreamError;

/// Errors of the event readers, writers and simulator; file errors name the file and, where it
/// helps, the line, array or entry.
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
    /// A pose, intrinsics or image file of a dataset (the error names the file).
    #[error(transparent)]
    Data(#[from] DataError),
    /// An image could not be read or written (the error names the file).
    #[error(transparent)]
    Image(#[from] ImageError),
    /// An in-memory stream operation failed.
    #[error(transparent)]
    Stream(#[from] StreamError),
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
