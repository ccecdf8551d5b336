//! Real multi-view datasets for the `nerf` task: LLFF forward-facing scenes ([`llff`]) and the
//! Blender / NeRF-synthetic format ([`blender`]), loaded into one small [`Dataset`] type; NumPy
//! `.npy` arrays ([`npy`]) for them and for the event readers above this crate; COLMAP sparse
//! models ([`colmap`]: cameras, image poses and 3-D points), read and written, and a whole COLMAP
//! capture, photos and model, as a dataset ([`colmap_scene`]); nerfstudio's `transforms.json`
//! ([`nerfstudio`]).
//!
//! # Conventions (see CONVENTIONS.md)
//!
//! * Poses are `world_from_camera` isometries (`world_from_camera * p_cam = p_world`).
//! * Camera axes are OpenCV's: x right, y down, z forward (the viewing direction is `+z`). Each
//!   reader converts its file's axes at the boundary and documents the conversion.
//! * Intrinsics are a pinhole `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` in continuous pixel
//!   coordinates (pixel `(x, y)` has its centre at `(x + 0.5, y + 0.5)`), so a principal point at
//!   the image centre is `(W/2, H/2)`.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::DataError;
use crate::camera::PinholeCamera;
use crate::image::Image;

pub mod blender;
pub mod capture;
pub mod colmap;
pub mod colmap_scene;
pub mod distortion;
pub mod llff;
pub mod nerfstudio;
pub mod npy;

/// Images with their poses and one shared camera. All vectors have one entry per image, in the
/// reader's order; all images have the size `camera.width × camera.height`.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The RGB images.
    pub images: Vec<Image>,
    /// `world_from_camera` per image, OpenCV camera axes.
    pub world_from_camera: Vec<Isometry3<f64>>,
    /// The shared pinhole camera.
    pub camera: PinholeCamera,
    /// `[near, far]` scene depth bounds per image when the format has them (LLFF), else `None`.
    pub bounds: Option<Vec<[f64; 2]>>,
    /// The image file names (without folder), e.g. `image000.png` or `r_0.png`.
    pub names: Vec<String>,
}

impl Dataset {
    /// The number of images.
    pub fn len(&self) -> usize {
        self.images.len()
    }

    /// Whether there are no images.
    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// Images `0, every, 2·every, …` with their poses, bounds and names ([`subsample`]).
    ///
    /// # Panics
    /// If `every` is 0.
    pub fn subsampled(&self, every: usize) -> Dataset {
        Dataset {
            images: subsample(&self.images, every),
            world_from_camera: subsample(&self.world_from_camera, every),
            camera: self.camera,
            bounds: self.bounds.as_ref().map(|b| subsample(b, every)),
            names: subsample(&self.names, every),
        }
    }
}

/// Every `every`-th item starting with the first: items `0, every, 2·every, …`. The paper's
/// "fern/2", "fern/4" (a faster camera, §4.1.2) are `subsample(frames, 2)`, `subsample(frames,
/// 4)`.
///
/// # Panics
/// If `every` is 0.
pub fn subsample<T: Clone>(items: &[T], every: usize) -> Vec<T> {
    assert!(every >= 1, "subsample: every must be ≥ 1");
    items.iter().step_by(every).cloned().collect()
}

/// Loads `paths` with `load`, checking that all images have the size of the first one.
/// Returns the images and their `(width, height)`; errors if `paths` is empty (naming `folder`).
fn load_same_size(
    paths: &[PathBuf],
    folder: &Path,
    load: impl Fn(&Path) -> Result<Image, DataError>,
) -> Result<(Vec<Image>, (usize, usize)), DataError> {
    let mut images = Vec::with_capacity(paths.len());
    let mut size = None;
    for path in paths {
        let image = load(path)?;
        let found = (image.width(), image.height());
        match size {
            None => size = Some(found),
            Some(expected) if expected != found => {
                return Err(DataError::ImageSize {
                    path: path.clone(),
                    first: paths[0].clone(),
                    expected,
                    found,
                });
            }
            Some(_) => {}
        }
        images.push(image);
    }
    let size = size.ok_or_else(|| DataError::Format {
        path: folder.to_path_buf(),
        expected: "at least one image".to_owned(),
        found: "none".to_owned(),
    })?;
    Ok((images, size))
}

/// The largest `|RᵀR − I|` entry and `|det R − 1|` accepted for a rotation read from a file
/// (file values are rounded; COLMAP/Blender store near-orthonormal matrices).
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// The isometry `[R | t]` from a near-orthonormal rotation read from `path`; errors when `R` is
/// not a rotation within [`ROTATION_TOLERANCE`] (or has non-finite entries). The quaternion of
/// `R` (Shepperd's method) is normalised, which absorbs the file's rounding.
pub fn isometry_from_rt(
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
    path: &Path,
    what: &str,
) -> Result<Isometry3<f64>, DataError> {
    let orth_err = (rotation.transpose() * rotation - Matrix3::identity()).amax();
    let det_err = (rotation.determinant() - 1.0).abs();
    let finite = rotation
        .iter()
        .chain(translation.iter())
        .all(|v| v.is_finite());
    if !(finite && orth_err < ROTATION_TOLERANCE && det_err < ROTATION_TOLERANCE) {
        return Err(DataError::Format {
            path: path.to_path_buf(),
            expected: format!(
                "{what}: a rotation (|RᵀR − I| and |det R − 1| below {ROTATION_TOLERANCE}) and a finite translation"
            ),
            // Rows inline: nalgebra's `Display` of a matrix spans several lines.
            found: format!(
                "|RᵀR − I| = {orth_err:.3e}, det R = {:.6}, R = {:?}, t = {:?}",
                rotation.determinant(),
                rotation
                    .row_iter()
                    .map(|r| [r[0], r[1], r[2]])
                    .collect::<Vec<_>>(),
                <[f64; 3]>::from(translation),
            ),
        });
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation));
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::new_normalize(q.into_inner()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsample_keeps_every_kth_from_the_first() {
        let items: Vec<usize> = (0..10).collect();
        assert_eq!(subsample(&items, 1), items);
        assert_eq!(subsample(&items, 2), [0, 2, 4, 6, 8]);
        assert_eq!(subsample(&items, 4), [0, 4, 8]);
        assert_eq!(subsample(&items, 20), [0]);
        assert!(subsample::<usize>(&[], 3).is_empty());
        let data = Dataset {
            images: (0..5)
                .map(|i| Image::from_fn(2, 1, |_, _| [i as f32; 3]))
                .collect(),
            world_from_camera: (0..5)
                .map(|i| Isometry3::translation(i as f64, 0.0, 0.0))
                .collect(),
            camera: PinholeCamera::centred(2, 1, 1.0),
            bounds: Some((0..5).map(|i| [i as f64, 10.0]).collect()),
            names: (0..5).map(|i| format!("{i}.png")).collect(),
        };
        let half = data.subsampled(2);
        assert_eq!(half.len(), 3);
        assert_eq!(half.names, ["0.png", "2.png", "4.png"]);
        assert_eq!(half.images[2].pixel(0, 0), [4.0; 3]);
        assert_eq!(half.world_from_camera[1].translation.vector.x, 2.0);
        assert_eq!(half.bounds.unwrap()[2], [4.0, 10.0]);
    }
}
