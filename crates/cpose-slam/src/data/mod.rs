//! RGB-D sequences: colour and metric depth per frame, with timestamps and ground-truth poses
//! where the dataset has them. Readers for Replica (NICE-SLAM's layout), ScanNet and TUM-RGBD
//! list the files and parse the poses up front; frames are decoded one at a time
//! ([`RgbdSequence::load`]), so a sequence of thousands of frames costs no memory until used.
//!
//! # Conventions
//!
//! * Poses are `world_from_camera` with OpenCV camera axes (x right, y down, z forward), as all
//!   three datasets store them (NICE-SLAM flips to OpenGL internally; cpose does not).
//! * Depth is metric camera `z` (not the distance along the ray); `0` marks a missing reading.
//! * A sequence loads at a resolution factor `s` (`0 < s ≤ 1`): colour is resized with a tent
//!   filter, depth by taking the nearest stored pixel (averaging depth across an object's edge
//!   would invent surfaces between the two), and the camera is scaled to the new size. Then
//!   [`RgbdSequence::cropped`] cuts pixels from every side (NICE-SLAM crops ScanNet and TUM).

mod convert;
mod depth;
mod replica;
mod scannet;
mod seven_scenes;
mod tum;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use cpose_nerf::DataError;
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::image::Image;
use nalgebra::Isometry3;

pub use convert::{Layout, write_sequence};
pub use depth::DepthImage;
pub use replica::{REPLICA_DEPTH_SCALE, REPLICA_INTRINSICS, read_replica, write_replica};
pub use scannet::{SCANNET_DEPTH_SCALE, SCANNET_INTRINSICS, read_scannet};
pub use seven_scenes::{
    SEVEN_SCENES_DEPTH_SCALE, SEVEN_SCENES_INTRINSICS, SEVEN_SCENES_INVALID_DEPTH,
    read_seven_scenes,
};
pub use tum::{TUM_DEPTH_SCALE, TUM_FR1_INTRINSICS, read_tum_rgbd};

/// Errors from reading or writing RGB-D sequences. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum RgbdError {
    /// A file or folder could not be read or written.
    #[error("cannot access {}: {error}", .path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A colour image could not be loaded, saved or built (`cpose-nerf`'s error names the
    /// file).
    #[error(transparent)]
    Image(#[from] DataError),
    /// A file's content is not what the format requires.
    #[error("{}: expected {expected}, got {found}", .path.display())]
    Format {
        /// The file (with `:line` where it applies).
        path: PathBuf,
        /// What the reader expected.
        expected: String,
        /// What it found.
        found: String,
    },
    /// A folder holds no frames, or the frame lists disagree.
    #[error("{}: {message}", .path.display())]
    Layout {
        /// The sequence folder.
        path: PathBuf,
        /// What is wrong, and what the layout should be.
        message: String,
    },
}

impl RgbdError {
    fn io(path: &Path, error: std::io::Error) -> Self {
        RgbdError::Io {
            path: path.to_path_buf(),
            error,
        }
    }

    fn format(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Self {
        RgbdError::Format {
            path: path.to_path_buf(),
            expected: expected.into(),
            found: found.into(),
        }
    }

    fn layout(path: &Path, message: impl Into<String>) -> Self {
        RgbdError::Layout {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// Pinhole intrinsics as the datasets publish them: for a nominal `width × height` image, with
/// the principal point in integer pixel coordinates (pixel `0`'s centre at `0`, NICE-SLAM's and
/// OpenCV's convention). Images stored at another size with the same aspect ratio scale them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Nominal image width, pixels.
    pub width: usize,
    /// Nominal image height, pixels.
    pub height: usize,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, integer pixel coordinates.
    pub cx: f64,
    /// Principal point y, integer pixel coordinates.
    pub cy: f64,
}

impl Intrinsics {
    /// `self` if it is a pinhole camera: a size of at least 1×1, positive finite focal lengths
    /// and a finite principal point; else an error naming `path`, where the values came from.
    pub fn checked(self, path: &Path) -> Result<Self, RgbdError> {
        let Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
        } = self;
        let focal = |f: f64| f.is_finite() && f > 0.0;
        if width > 0 && height > 0 && focal(fx) && focal(fy) && cx.is_finite() && cy.is_finite() {
            Ok(self)
        } else {
            Err(RgbdError::format(
                path,
                "a camera of at least 1×1 pixels with positive focal lengths and a finite \
                 principal point",
                format!("{width}×{height}, fx = {fx}, fy = {fy}, cx = {cx}, cy = {cy}"),
            ))
        }
    }

    /// The camera of images of `width × height` pixels: the intrinsics scaled by
    /// `width / self.width` and `height / self.height` about the image's corner, in cpose's
    /// continuous pixel coordinates (`c = (c_int + ½)·s`). Errors (naming `path`) unless the
    /// aspect ratios agree to 1%.
    pub fn camera_for(
        &self,
        width: usize,
        height: usize,
        path: &Path,
    ) -> Result<PinholeCamera, RgbdError> {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        if width == 0 || height == 0 || (sx / sy - 1.0).abs() > 0.01 {
            return Err(RgbdError::format(
                path,
                format!(
                    "an image of the intrinsics' aspect ratio ({}×{} or a multiple)",
                    self.width, self.height
                ),
                format!("{width}×{height}"),
            ));
        }
        Ok(PinholeCamera {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx,
            cy: (self.cy + 0.5) * sy,
        })
    }
}

/// The files of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameFiles {
    /// Timestamp, seconds (the dataset's clock; Replica and ScanNet have none, so frame index
    /// over the nominal frame rate).
    pub time: f64,
    /// Colour image (PNG or JPEG).
    pub color: PathBuf,
    /// Depth image (16-bit PNG, `depth_scale` units per metre).
    pub depth: PathBuf,
}

/// One loaded frame.
#[derive(Clone, Debug)]
pub struct RgbdFrame {
    /// Index in the sequence.
    pub index: usize,
    /// Timestamp, seconds.
    pub time: f64,
    /// Colour, linear in `[0, 1]` as stored (no gamma handling).
    pub color: Image,
    /// Metric depth, `0` where missing.
    pub depth: DepthImage,
}

/// An RGB-D sequence on disk: its frames' files, ground truth and camera.
#[derive(Clone, Debug)]
pub struct RgbdSequence {
    /// The sequence folder.
    pub root: PathBuf,
    /// The camera of the frames as [`RgbdSequence::load`] returns them (scaled and cropped).
    pub camera: PinholeCamera,
    /// Per frame, its files.
    pub frames: Vec<FrameFiles>,
    /// Per frame, the ground-truth `world_from_camera`; `None` where the dataset has none or a
    /// non-finite one (ScanNet marks lost frames with `inf`).
    pub truth: Vec<Option<Isometry3<f64>>>,
    /// Depth PNG units per metre (Replica 6553.5, ScanNet 1000, TUM 5000, 7-Scenes 1000).
    pub depth_scale: f64,
    /// A stored depth value that marks a missing reading besides 0 (7-Scenes: 65535).
    pub invalid_depth: Option<u16>,
    /// The stored size of the depth images, which `camera` was derived from (colour of another
    /// size with the same aspect ratio, as ScanNet's, is resized to it first).
    stored: (usize, usize),
    /// Resolution factor applied on load.
    resolution: f64,
    /// Pixels cut from every side after resizing.
    crop_edge: usize,
}

impl RgbdSequence {
    /// Assembles a sequence whose stored depth images are `stored` pixels, loaded at
    /// `resolution` (uncropped: see [`RgbdSequence::cropped`]). Errors on an empty frame list or
    /// a factor outside `(0, 1]`.
    fn new(
        root: &Path,
        intrinsics: &Intrinsics,
        stored: (usize, usize),
        frames: Vec<FrameFiles>,
        truth: Vec<Option<Isometry3<f64>>>,
        depth_scale: f64,
        resolution: f64,
    ) -> Result<Self, RgbdError> {
        if frames.is_empty() {
            return Err(RgbdError::layout(root, "no frames found"));
        }
        if !(depth_scale.is_finite() && depth_scale > 0.0) {
            return Err(RgbdError::layout(
                root,
                format!("depth scale {depth_scale} must be a positive number of units per metre"),
            ));
        }
        if !(resolution > 0.0 && resolution <= 1.0) {
            return Err(RgbdError::layout(
                root,
                format!("resolution factor {resolution} must lie in (0, 1]"),
            ));
        }
        debug_assert_eq!(frames.len(), truth.len());
        let first = &frames[0].depth;
        let full = intrinsics.camera_for(stored.0, stored.1, first)?;
        // The camera of the image `resized` returns: the exact size ratio on each axis.
        let (sw, sh) = resized_size(stored, resolution);
        let (kx, ky) = (sw as f64 / stored.0 as f64, sh as f64 / stored.1 as f64);
        let camera = PinholeCamera {
            width: sw,
            height: sh,
            fx: full.fx * kx,
            fy: full.fy * ky,
            cx: full.cx * kx,
            cy: full.cy * ky,
        };
        Ok(Self {
            root: root.to_path_buf(),
            camera,
            frames,
            truth,
            depth_scale,
            invalid_depth: None,
            stored,
            resolution,
            crop_edge: 0,
        })
    }

    /// The sequence with `crop_edge` pixels cut from every side of the (resized) images, in place
    /// of the current crop (NICE-SLAM crops ScanNet by 10, TUM by 8); the camera's size and
    /// principal point follow. Errors on a crop that leaves no pixels.
    pub fn cropped(mut self, crop_edge: usize) -> Result<Self, RgbdError> {
        let (w, h) = (
            self.camera.width + 2 * self.crop_edge,
            self.camera.height + 2 * self.crop_edge,
        );
        if 2 * crop_edge >= w.min(h) {
            return Err(RgbdError::layout(
                &self.root,
                format!("crop_edge {crop_edge} leaves no pixels of a {w}×{h} image"),
            ));
        }
        let shift = self.crop_edge as f64 - crop_edge as f64;
        self.camera.width = w - 2 * crop_edge;
        self.camera.height = h - 2 * crop_edge;
        self.camera.cx += shift;
        self.camera.cy += shift;
        self.crop_edge = crop_edge;
        Ok(self)
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there are no frames (never true for a sequence a reader returned).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Every `stride`-th frame (from the first), as a camera `stride` times faster would see
    /// the scene; `stride ≤ 1` keeps all.
    pub fn every(mut self, stride: usize) -> Self {
        if stride > 1 {
            let keep = |i: &usize| i.is_multiple_of(stride);
            self.frames = self
                .frames
                .into_iter()
                .enumerate()
                .filter(|(i, _)| keep(i))
                .map(|(_, f)| f)
                .collect();
            self.truth = self
                .truth
                .into_iter()
                .enumerate()
                .filter(|(i, _)| keep(i))
                .map(|(_, t)| t)
                .collect();
        }
        self
    }

    /// Frame timestamps, seconds.
    pub fn times(&self) -> Vec<f64> {
        self.frames.iter().map(|f| f.time).collect()
    }

    /// Loads frame `index`: decodes both images, checks their stored sizes, resizes and crops.
    /// Errors name the file: missing, corrupt, or of another size than the first frame.
    ///
    /// # Panics
    /// If `index` is out of range.
    pub fn load(&self, index: usize) -> Result<RgbdFrame, RgbdError> {
        let files = &self.frames[index];
        let color = Image::load(&files.color)?;
        let depth =
            DepthImage::load_png_masked(&files.depth, self.depth_scale, self.invalid_depth)?;
        // ScanNet stores colour larger than depth: colour is resized to the depth's size.
        let color = if (color.width(), color.height()) == self.stored {
            color
        } else if same_aspect(&color, self.stored) {
            resize_exact(&color, self.stored.0, self.stored.1)
        } else {
            return Err(size_error(&files.color, self.stored, &color));
        };
        if (depth.width(), depth.height()) != self.stored {
            return Err(RgbdError::format(
                &files.depth,
                format!("a depth image of {}×{}", self.stored.0, self.stored.1),
                format!("{}×{}", depth.width(), depth.height()),
            ));
        }
        let (color, depth) = if self.resolution < 1.0 {
            let (w, h) = resized_size(self.stored, self.resolution);
            (resize_exact(&color, w, h), depth.resized_nearest(w, h))
        } else {
            (color, depth)
        };
        let e = self.crop_edge;
        Ok(RgbdFrame {
            index,
            time: files.time,
            color: crop(&color, e),
            depth: depth.cropped(e),
        })
    }
}

/// `(max(1, round(W·s)), max(1, round(H·s)))`, as [`Image::resized`].
fn resized_size(stored: (usize, usize), s: f64) -> (usize, usize) {
    let r = |n: usize| ((n as f64 * s).round() as usize).max(1);
    (r(stored.0), r(stored.1))
}

fn same_aspect(image: &Image, size: (usize, usize)) -> bool {
    let a = image.width() as f64 / image.height() as f64;
    let b = size.0 as f64 / size.1 as f64;
    (a / b - 1.0).abs() < 0.02
}

fn size_error(path: &Path, expected: (usize, usize), image: &Image) -> RgbdError {
    RgbdError::format(
        path,
        format!("a colour image of {}×{}", expected.0, expected.1),
        format!("{}×{}", image.width(), image.height()),
    )
}

/// `image` resized to exactly `w × h` (the tent filter of [`Image::resized`]).
fn resize_exact(image: &Image, w: usize, h: usize) -> Image {
    let out = image.resized(w as f64 / image.width() as f64);
    if (out.width(), out.height()) == (w, h) {
        out
    } else {
        // Rounding of the other axis differs by a pixel: resample to the exact size.
        Image::from_fn(w, h, |x, y| {
            let sx = ((x as f64 + 0.5) * out.width() as f64 / w as f64) as usize;
            let sy = ((y as f64 + 0.5) * out.height() as f64 / h as f64) as usize;
            out.pixel(sx.min(out.width() - 1), sy.min(out.height() - 1))
        })
    }
}

/// `image` without `e` pixels on every side.
fn crop(image: &Image, e: usize) -> Image {
    if e == 0 {
        return image.clone();
    }
    Image::from_fn(image.width() - 2 * e, image.height() - 2 * e, |x, y| {
        image.pixel(x + e, y + e)
    })
}

/// The lines of a text file with their 1-based numbers, skipping blanks and `#` comments.
fn data_lines(path: &Path) -> Result<Vec<(usize, String)>, RgbdError> {
    let text = std::fs::read_to_string(path).map_err(|e| RgbdError::io(path, e))?;
    Ok(text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim().to_string()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .collect())
}

/// Parses `n` whitespace-separated floats from `line` (line `number` of `path`).
fn parse_floats(path: &Path, number: usize, line: &str, n: usize) -> Result<Vec<f64>, RgbdError> {
    let values: Result<Vec<f64>, _> = line.split_whitespace().map(str::parse::<f64>).collect();
    match values {
        Ok(v) if v.len() == n => Ok(v),
        _ => Err(RgbdError::format(
            &line_path(path, number),
            format!("{n} numbers"),
            format!("{line:?}"),
        )),
    }
}

/// `path:number`, to name a line in an error.
fn line_path(path: &Path, number: usize) -> PathBuf {
    PathBuf::from(format!("{}:{number}", path.display()))
}

/// The files `<prefix><number>.<ext>` in `folder` (one of `extensions`, any case), by number.
fn numbered_files(
    folder: &Path,
    prefix: &str,
    extensions: &[&str],
) -> Result<BTreeMap<u64, PathBuf>, RgbdError> {
    let entries = std::fs::read_dir(folder).map_err(|e| RgbdError::io(folder, e))?;
    let mut found = BTreeMap::new();
    for entry in entries {
        let path = entry.map_err(|e| RgbdError::io(folder, e))?.path();
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let Some(rest) = name.strip_prefix(prefix) else {
            continue;
        };
        let Some((stem, ext)) = rest.rsplit_once('.') else {
            continue;
        };
        if !extensions.contains(&ext.to_ascii_lowercase().as_str()) {
            continue;
        }
        if let Ok(n) = stem.parse::<u64>() {
            found.insert(n, path);
        }
    }
    Ok(found)
}

/// Files of several kinds (e.g. `("colour", …)`, `("depth", …)`) paired by frame number, never by
/// position: every kind must hold a file for every number another kind holds. Returns the
/// numbers in order with one file per kind; the first gap is an error naming the frame, the file
/// it has and the kind it lacks.
fn paired_by_number<const N: usize>(
    folder: &Path,
    kinds: [(&str, BTreeMap<u64, PathBuf>); N],
) -> Result<Vec<(u64, [PathBuf; N])>, RgbdError> {
    let numbers: BTreeSet<u64> = kinds.iter().flat_map(|(_, m)| m.keys().copied()).collect();
    let mut frames = Vec::with_capacity(numbers.len());
    for n in numbers {
        let found: [Option<&PathBuf>; N] = std::array::from_fn(|k| kinds[k].1.get(&n));
        if let Some(missing) = found.iter().position(Option::is_none) {
            let (has, file) = kinds
                .iter()
                .zip(&found)
                .find_map(|((kind, _), f)| f.map(|f| (kind, f)))
                .map_or(("", String::new()), |(k, f)| (*k, f.display().to_string()));
            return Err(RgbdError::layout(
                folder,
                format!(
                    "frame {n} has a {has} file ({file}) but no {} file; frames are paired by \
                     their number, so every frame needs one of each",
                    kinds[missing].0
                ),
            ));
        }
        frames.push((n, found.map(|f| f.cloned().unwrap_or_default())));
    }
    Ok(frames)
}

/// A fresh empty folder for one test, removed when it ends.
#[cfg(test)]
pub(crate) fn test_dir(name: &str) -> cpose_core::testing::TempDir {
    cpose_core::testing::TempDir::new(&format!("slam-{name}"))
}
