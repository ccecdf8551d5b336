//! The crate's data error: reading, writing and checking dataset files and images.

use std::io;
use std::path::PathBuf;

/// Errors of the dataset readers ([`crate::data`]) and of images ([`crate::image::Image`]):
/// reading, decoding, checking, encoding and writing. Every variant about a file names it and
/// says what was expected.
///
/// The byte-level NumPy parser reports [`crate::data::npy::NpyError`], which the readers turn
/// into [`DataError::Format`] with the file named.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A file or folder could not be read.
    #[error("cannot read {}: {error}", .path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        error: io::Error,
    },
    /// A file's content is not what the format requires.
    #[error("{}: expected {expected}, got {found}", .path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What the reader expected.
        expected: String,
        /// What it found.
        found: String,
    },
    /// A data file could not be written, replaced or removed (a COLMAP model,
    /// [`crate::data::colmap::write_colmap_model`]).
    #[error("cannot write {}: {error}", .path.display())]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        error: io::Error,
    },
    /// An image file could not be read (missing, a folder, no permission …).
    #[error("cannot read image {} (expected a readable PNG or JPEG file): {error}", .path.display())]
    ImageRead {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: io::Error,
    },
    /// An image file's bytes are neither PNG nor JPEG.
    #[error("image {}: expected PNG or JPEG data, got {found}", .path.display())]
    ImageUnsupported {
        /// The file.
        path: PathBuf,
        /// What the data looks like (a format name, or "unrecognised data").
        found: String,
    },
    /// An image file starts like a PNG or JPEG but cannot be decoded.
    #[error("image {}: expected valid {format} data, got a decoding error: {error}", .path.display())]
    ImageDecode {
        /// The file.
        path: PathBuf,
        /// "PNG" or "JPEG".
        format: &'static str,
        /// The decoder's error.
        error: ::image::ImageError,
    },
    /// A JPEG file ends before its last scan's end-of-image marker: a truncated file, which
    /// the decoder would otherwise fill with grey.
    #[error("image {}: expected complete JPEG data, got a file that ends inside its image data \
             (no end-of-image marker after the last scan; truncated?)", .path.display())]
    ImageTruncated {
        /// The file.
        path: PathBuf,
    },
    /// An image's size differs from the first image's of a dataset.
    #[error("image {}: expected the size of the first image {}, {}×{}, got {}×{}",
        .path.display(), .first.display(), .expected.0, .expected.1, .found.0, .found.1)]
    ImageSize {
        /// The image file.
        path: PathBuf,
        /// The first image file, whose size all must have.
        first: PathBuf,
        /// The first image's `(width, height)`.
        expected: (usize, usize),
        /// This image's `(width, height)`.
        found: (usize, usize),
    },
    /// Width, height and data length do not describe an RGB image.
    #[error(
        "expected 1 ≤ width, height ≤ {max} and 3·width·height values, got {width}×{height} with {len} values",
        max = u32::MAX
    )]
    ImageShape {
        /// Requested width.
        width: usize,
        /// Requested height.
        height: usize,
        /// Length of the data given.
        len: usize,
    },
    /// Encoding a PNG in memory failed.
    #[error("cannot encode PNG for {}: {error}", .path.display())]
    ImageEncode {
        /// The file that was to be written.
        path: PathBuf,
        /// The encoder's error.
        error: ::image::ImageError,
    },
    /// Writing an encoded image file failed.
    #[error("cannot write image {}: {error}", .path.display())]
    ImageWrite {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: io::Error,
    },
}

impl DataError {
    /// [`DataError::Format`]: `path`'s content is not `expected`, it is `found`.
    pub fn format(
        path: &std::path::Path,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        DataError::Format {
            path: path.to_path_buf(),
            expected: expected.into(),
            found: found.into(),
        }
    }
}
