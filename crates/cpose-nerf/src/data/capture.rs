//! What the readers of users' own captures ([`super::colmap_scene`], [`super::nerfstudio`])
//! share: the size check before any photo is read, and loading the photos with the camera scaled
//! to them and its lens distortion removed.

use std::path::{Path, PathBuf};

use super::distortion::Distortion;
use super::load_same_size;
use crate::DataError;
use crate::camera::PinholeCamera;
use crate::image::Image;

/// The most pixels of all loaded photos together (a hundred million, 1.2 GB of colour); a larger
/// capture is refused before any photo is read, naming the downscale factor that fits.
pub const MAX_PIXELS: usize = 100_000_000;

/// A capture's camera as calibrated, at its photos' native size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct NativeCamera {
    /// `[width, height]` in pixels.
    pub(super) size: [usize; 2],
    pub(super) focal: [f64; 2],
    pub(super) centre: [f64; 2],
    pub(super) lens: Distortion,
}

/// Errors (naming `path`) unless `count` photos of `camera` fit in [`MAX_PIXELS`] at downscale
/// `factor`.
pub(super) fn check_size(
    count: usize,
    camera: &NativeCamera,
    factor: u32,
    path: &Path,
) -> Result<(), DataError> {
    let [w, h] = camera.size;
    let native = count as f64 * (w * h) as f64;
    let pixels = native / f64::from(factor).powi(2);
    if pixels <= MAX_PIXELS as f64 {
        return Ok(());
    }
    let fits = (native / MAX_PIXELS as f64).sqrt().ceil();
    Err(DataError::format(
        path,
        format!(
            "at most {MAX_PIXELS} pixels over all images (a downscale factor of {fits} or more \
             for {count} photos of {w}×{h})"
        ),
        format!("{pixels:.3e} pixels at factor {factor}"),
    ))
}

/// The photos at `paths` (averaged down by `1/resize` unless `resize` is 1), with `camera`
/// scaled to their size and its distortion removed: the images, the pinhole camera and the
/// largest shift undistortion made, in pixels. Errors name the file: an unreadable photo,
/// photos of different sizes, or a size that is not the camera's scaled by a common factor
/// (to a pixel of rounding).
pub(super) fn load_photos(
    paths: &[PathBuf],
    folder: &Path,
    resize: f64,
    camera: &NativeCamera,
) -> Result<(Vec<Image>, PinholeCamera, f64), DataError> {
    let (mut images, (width, height)) = load_same_size(paths, folder, |p| {
        let image = Image::load(p)?;
        Ok(if resize == 1.0 {
            image
        } else {
            image.resized(resize)
        })
    })?;
    let [w0, h0] = camera.size.map(|s| s as f64);
    if (width as f64 * h0 - height as f64 * w0).abs() > w0.max(h0) {
        return Err(DataError::format(
            &paths[0],
            format!("an image of the camera's aspect ratio, {w0}×{h0} scaled by a common factor"),
            format!("{width}×{height}"),
        ));
    }
    let (sx, sy) = (width as f64 / w0, height as f64 / h0);
    let pinhole = PinholeCamera {
        width,
        height,
        fx: camera.focal[0] * sx,
        fy: camera.focal[1] * sy,
        cx: camera.centre[0] * sx,
        cy: camera.centre[1] * sy,
    };
    if !camera.lens.is_none() {
        for image in &mut images {
            *image = camera.lens.undistort(image, &pinhole);
        }
    }
    Ok((images, pinhole, camera.lens.max_shift_px(&pinhole)))
}
