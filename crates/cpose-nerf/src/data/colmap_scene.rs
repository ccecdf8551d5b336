//! A user's own capture as a COLMAP reconstruction: the photos and the sparse model COLMAP
//! wrote for them, loaded as a [`Dataset`] ([`load_colmap_scene`]), and poses refined from it
//! written back as a COLMAP model ([`ColmapScene::write_refined`]) that COLMAP and the tools
//! built on it read.
//!
//! # Layout
//!
//! COLMAP's own: `<scene>/sparse/0/` (or `<scene>/sparse/`) holds the model (`cameras`,
//! `images`, `points3D`, binary or text: [`super::colmap`]); `<scene>/images/` the photos by the
//! names the model gives them. At a downscale factor `N > 1`, `<scene>/images_N/` is read when it
//! exists (LLFF's layout) and `images/` is averaged down by `N` otherwise.
//!
//! # Pairing and order
//!
//! Images are paired with poses **by name**: the model's name, or the same stem with another image
//! extension (LLFF's `images_N/` holds PNGs of COLMAP's JPEGs). A registered image without a file
//! is an error naming it; image files the model does not register are skipped and counted
//! ([`ColmapScene::unregistered`]). The registered images are ordered by name, and image `i` of
//! that order is taken at time `t = i` (a video's frames, numbered, are in time order).
//!
//! # Camera
//!
//! One camera for every image (the [`Dataset`] shares one); several ids with equal parameters are
//! accepted. Its intrinsics are scaled to the loaded images' size. The radial models'
//! distortion (`SIMPLE_RADIAL`, `RADIAL`) is removed on load ([`super::distortion`];
//! [`ColmapScene::max_distortion_px`] says by how much).
//!
//! # Depth bounds
//!
//! Per image, from the depths of the 3-D points its track observes (the point's track lists the
//! image): `near`, `far` are the 0.1 % and 99.9 % quantiles (linear interpolation between order
//! statistics), as LLFF's `poses_bounds.npy` holds them. A model without `points3D`, or an
//! image that observes no point in front of it, is an error.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3};

use super::Dataset;
use super::capture::{NativeCamera, check_size, load_photos};
use super::colmap::{
    CameraModel, ColmapCamera, ColmapFormat, ColmapModel, IMAGES, find_part, read_colmap_model,
    write_colmap_model,
};
use super::distortion::Distortion;
use super::llff::list_images;
use crate::DataError;

/// The quantiles of the observed point depths taken as an image's `near` and `far`, in percent.
pub const BOUND_PERCENTILES: [f64; 2] = [0.1, 99.9];

/// What of a COLMAP capture writing refined poses back needs, beside the [`Dataset`]
/// [`load_colmap_scene`] loads from it.
#[derive(Clone, Debug)]
pub struct ColmapScene {
    /// The model as read.
    pub model: ColmapModel,
    /// The folder it was read from.
    pub model_dir: PathBuf,
    /// The format of its `images` file (the refined model is written in it).
    pub format: ColmapFormat,
    /// The camera every image uses.
    pub camera: ColmapCamera,
    /// The COLMAP image id of each dataset image.
    pub image_ids: Vec<u32>,
    /// Image files of the image folder that the model does not register (skipped).
    pub unregistered: Vec<String>,
    /// The largest shift, in pixels of the loaded images, by which undistortion moved a pixel
    /// (0 for the pinhole models).
    pub max_distortion_px: f64,
}

/// The model folder of `scene_dir`: `sparse/0`, else `sparse`, whichever holds a `cameras` file.
fn find_model_dir(scene_dir: &Path) -> Result<PathBuf, DataError> {
    let candidates = [scene_dir.join("sparse").join("0"), scene_dir.join("sparse")];
    candidates
        .iter()
        .find(|d| d.join("cameras.bin").is_file() || d.join("cameras.txt").is_file())
        .cloned()
        .ok_or_else(|| {
            DataError::format(
                scene_dir,
                "a COLMAP reconstruction: sparse/0/ or sparse/ holding cameras, images and \
                 points3D (.bin or .txt), and the photos in images/",
                "no cameras.bin or cameras.txt in either folder",
            )
        })
}

/// Loads the COLMAP capture in `scene_dir` at downscale `factor` (see the module docs): the
/// images (undistorted, downscaled), their COLMAP poses (world frame and units of the
/// reconstruction), the pinhole camera, the depth bounds from the points and the image names,
/// ordered by name; and the model for [`ColmapScene::write_refined`].
///
/// Errors name the file or folder: no model, a model without `images` or `points3D`, images of
/// several different cameras, a registered image without its file, images of a size other than
/// the camera's (scaled by the factor), fewer than one point observed in front of an image.
pub fn load_colmap_scene(
    scene_dir: impl AsRef<Path>,
    factor: u32,
) -> Result<(Dataset, ColmapScene), DataError> {
    let scene_dir = scene_dir.as_ref();
    if factor == 0 {
        return Err(DataError::format(
            scene_dir,
            "a downscale factor of at least 1",
            "0",
        ));
    }
    let model_dir = find_model_dir(scene_dir)?;
    let model = read_colmap_model(&model_dir)?;
    // The reader read `images` from this file (when there is one).
    let (images_file, format) = find_part(&model_dir, IMAGES)
        .unwrap_or_else(|| (model_dir.join("images.txt"), ColmapFormat::Text));
    let Some(registered) = &model.images else {
        return Err(DataError::format(
            &model_dir,
            "an images.bin or images.txt with the registered images' poses",
            "neither file",
        ));
    };
    let Some(points) = &model.points else {
        return Err(DataError::format(
            &model_dir,
            "a points3D.bin or points3D.txt (the scene's depth bounds come from its points)",
            "neither file",
        ));
    };
    if registered.is_empty() {
        return Err(DataError::format(
            &images_file,
            "at least one registered image",
            "none",
        ));
    }
    let camera = shared_camera(&model, &model_dir)?;
    let p = &camera.params;
    let (f, centre, k) = match camera.model {
        CameraModel::SimplePinhole => ([p[0], p[0]], [p[1], p[2]], [0.0; 3]),
        CameraModel::Pinhole => ([p[0], p[1]], [p[2], p[3]], [0.0; 3]),
        CameraModel::SimpleRadial => ([p[0], p[0]], [p[1], p[2]], [p[3], 0.0, 0.0]),
        CameraModel::Radial => ([p[0], p[0]], [p[1], p[2]], [p[3], p[4], 0.0]),
    };
    let native = NativeCamera {
        size: [camera.width, camera.height],
        focal: f,
        centre,
        lens: Distortion {
            radial: k,
            tangential: [0.0; 2],
        },
    };
    check_size(registered.len(), &native, factor, scene_dir)?;

    let mut order: Vec<usize> = (0..registered.len()).collect();
    order.sort_by(|&a, &b| registered[a].name.cmp(&registered[b].name));
    if let Some(pair) = order
        .windows(2)
        .find(|w| registered[w[0]].name == registered[w[1]].name)
    {
        return Err(DataError::format(
            &images_file,
            "each image name once (photos are paired with poses by name)",
            format!(
                "{} for images {} and {}",
                registered[pair[0]].name, registered[pair[0]].id, registered[pair[1]].id
            ),
        ));
    }

    // The image folder, and the scale from it to the camera's size.
    let downscaled = scene_dir.join(format!("images_{factor}"));
    let (folder, resize) = if factor > 1 && downscaled.is_dir() {
        (downscaled, 1.0)
    } else {
        (scene_dir.join("images"), 1.0 / f64::from(factor))
    };
    if !folder.is_dir() {
        return Err(DataError::format(
            &folder,
            format!(
                "the folder of the {} photos the model registers",
                registered.len()
            ),
            "no such folder",
        ));
    }
    let files = list_images(&folder)?;
    let paths = order
        .iter()
        .map(|&i| find_image(&files, &registered[i].name, &folder))
        .collect::<Result<Vec<_>, _>>()?;
    let used: HashSet<&PathBuf> = paths.iter().collect();
    let unregistered = files
        .iter()
        .filter(|p| !used.contains(p))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();

    let (images, pinhole, max_distortion_px) = load_photos(&paths, &folder, resize, &native)?;

    let world_from_camera: Vec<Isometry3<f64>> = order
        .iter()
        .map(|&i| registered[i].world_from_camera)
        .collect();
    let image_ids: Vec<u32> = order.iter().map(|&i| registered[i].id).collect();
    let bounds = depth_bounds(&image_ids, &world_from_camera, points, &model_dir, |i| {
        registered[order[i]].name.clone()
    })?;
    let names = order.iter().map(|&i| registered[i].name.clone()).collect();
    let dataset = Dataset {
        images,
        world_from_camera,
        camera: pinhole,
        bounds: Some(bounds),
        names,
    };
    let scene = ColmapScene {
        model,
        model_dir,
        format,
        camera,
        image_ids,
        unregistered,
        max_distortion_px,
    };
    Ok((dataset, scene))
}

/// The camera every registered image uses; several cameras are accepted when their model, size
/// and parameters are equal.
fn shared_camera(model: &ColmapModel, model_dir: &Path) -> Result<ColmapCamera, DataError> {
    let images = model.images.as_deref().unwrap_or_default();
    let mut used: Vec<u32> = images.iter().map(|i| i.camera_id).collect();
    used.sort_unstable();
    used.dedup();
    // The reader checked that every image's camera exists.
    let cameras: Vec<&ColmapCamera> = used.iter().filter_map(|&id| model.camera(id)).collect();
    let first = cameras[0];
    let same = |c: &&ColmapCamera| {
        c.model == first.model
            && (c.width, c.height) == (first.width, first.height)
            && c.params == first.params
    };
    if let Some(other) = cameras.iter().find(|c| !same(c)) {
        return Err(DataError::format(
            model_dir,
            "one camera shared by every image (a single camera, as from COLMAP's \
             --ImageReader.single_camera 1)",
            format!(
                "{} cameras in use, e.g. camera {} ({} {}×{} {:?}) and camera {} ({} {}×{} {:?})",
                cameras.len(),
                first.id,
                first.model.name(),
                first.width,
                first.height,
                first.params,
                other.id,
                other.model.name(),
                other.width,
                other.height,
                other.params
            ),
        ));
    }
    Ok(first.clone())
}

/// The file of `files` for the model's image `name`: the same relative path, or the same stem
/// with another image extension.
fn find_image(files: &[PathBuf], name: &str, folder: &Path) -> Result<PathBuf, DataError> {
    let exact = folder.join(name);
    if exact.is_file() {
        return Ok(exact);
    }
    let stem = Path::new(name).file_stem();
    let parent = exact.parent();
    files
        .iter()
        .find(|f| f.file_stem() == stem && f.parent() == parent)
        .cloned()
        .ok_or_else(|| {
            DataError::format(
                &exact,
                "the photo of a registered image (that name, or its stem with .png, .jpg or .jpeg)",
                "no such file",
            )
        })
}

/// The `q`-th percentile of sorted `values`, linear between order statistics.
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let position = q / 100.0 * (sorted.len() - 1) as f64;
    let (below, frac) = (position.floor() as usize, position.fract());
    let above = (below + 1).min(sorted.len() - 1);
    sorted[below] + frac * (sorted[above] - sorted[below])
}

/// Per image, `[near, far]` from the depths of the points whose track observes it.
fn depth_bounds(
    image_ids: &[u32],
    world_from_camera: &[Isometry3<f64>],
    points: &[super::colmap::ColmapPoint],
    model_dir: &Path,
    name: impl Fn(usize) -> String,
) -> Result<Vec<[f64; 2]>, DataError> {
    let index: HashMap<u32, usize> = image_ids
        .iter()
        .enumerate()
        .map(|(i, &id)| (id, i))
        .collect();
    let mut depths = vec![Vec::new(); image_ids.len()];
    for point in points {
        let p = Point3::from(point.xyz);
        for &(image_id, _) in &point.track {
            if let Some(&i) = index.get(&image_id) {
                let z = world_from_camera[i].inverse_transform_point(&p).z;
                if z > 0.0 {
                    depths[i].push(z);
                }
            }
        }
    }
    depths
        .iter_mut()
        .enumerate()
        .map(|(i, d)| {
            if d.is_empty() {
                return Err(DataError::format(
                    model_dir,
                    format!(
                        "3-D points observed in front of image {} ({}), for its depth bounds",
                        image_ids[i],
                        name(i)
                    ),
                    "none in points3D's tracks",
                ));
            }
            d.sort_by(f64::total_cmp);
            let [near, far] = BOUND_PERCENTILES.map(|q| percentile(d, q));
            // One point (or all at one depth) gives near = far; widen to a shell around it.
            Ok(if far > near {
                [near, far]
            } else {
                [0.5 * near, 2.0 * near]
            })
        })
        .collect()
}

impl ColmapScene {
    /// Writes the model with the poses of the dataset's images `indices` replaced by
    /// `world_from_camera` (one per index, COLMAP's world frame) into `dir`, in the format the
    /// model was read in; an existing model there is replaced only with `replace`
    /// ([`write_colmap_model`]).
    ///
    /// Only those images are written. Points keep their positions; track elements of images
    /// not written are dropped, and then points seen by fewer than two images (COLMAP's least
    /// for a triangulated point), with the keypoints that referenced them.
    pub fn write_refined(
        &self,
        dir: &Path,
        indices: &[usize],
        world_from_camera: &[Isometry3<f64>],
        replace: bool,
    ) -> Result<(), DataError> {
        assert_eq!(indices.len(), world_from_camera.len(), "one pose per index");
        let refined: HashMap<u32, Isometry3<f64>> = indices
            .iter()
            .zip(world_from_camera)
            .map(|(&i, pose)| (self.image_ids[i], *pose))
            .collect();
        let mut points: Vec<_> = self.model.points.clone().unwrap_or_default();
        for point in &mut points {
            point.track.retain(|(image, _)| refined.contains_key(image));
        }
        points.retain(|p| p.track.len() >= 2);
        let kept: HashSet<u64> = points.iter().map(|p| p.id).collect();
        let images = self
            .model
            .images
            .iter()
            .flatten()
            .filter_map(|image| {
                let pose = refined.get(&image.id)?;
                let mut image = image.clone();
                image.world_from_camera = *pose;
                for (_, point) in &mut image.points2d {
                    if point.is_some_and(|id| !kept.contains(&id)) {
                        *point = None;
                    }
                }
                Some(image)
            })
            .collect();
        let model = ColmapModel {
            cameras: self.model.cameras.clone(),
            images: Some(images),
            points: Some(points),
        };
        std::fs::create_dir_all(dir).map_err(|error| DataError::Write {
            path: dir.to_path_buf(),
            error,
        })?;
        write_colmap_model(dir, &model, self.format, replace)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_between_order_statistics() {
        let v: Vec<f64> = (0..=10).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.0), 0.0);
        assert_eq!(percentile(&v, 100.0), 10.0);
        assert!((percentile(&v, 25.0) - 2.5).abs() < 1e-12);
        assert!((percentile(&v, 0.1) - 0.01).abs() < 1e-12);
        assert_eq!(percentile(&[3.0], 99.9), 3.0);
    }

    /// A COLMAP scene folder made of fern's real `cameras.bin` and `points3D.bin`, an `images.bin`
    /// written from the LLFF poses (fern ships none; its image ids are taken in name order) and
    /// its `images_8/` photos.
    fn fern_scene() -> Option<(cpose_core::testing::TempDir, Dataset)> {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return None;
        };
        let fern = data_dir.join("llff/fern");
        let scene = cpose_core::testing::TempDir::new("colmap-scene-fern");
        let real = read_colmap_model(&fern.join("sparse/0")).expect("fern's model");
        let llff = crate::data::llff::load_llff(&fern, 8).expect("fern");
        let camera_id = real.cameras[0].id;
        let images = llff
            .world_from_camera
            .iter()
            .zip(&llff.names)
            .enumerate()
            .map(|(i, (pose, name))| super::super::colmap::ColmapImage {
                id: i as u32 + 1,
                camera_id,
                // COLMAP's names are the original JPEGs; images_8 holds PNGs of them.
                name: name.replace(".png", ".JPG"),
                world_from_camera: *pose,
                points2d: vec![],
            })
            .collect();
        let model = ColmapModel {
            images: Some(images),
            ..real
        };
        let sparse = scene.join("sparse/0");
        std::fs::create_dir_all(&sparse).expect("sparse/0");
        write_colmap_model(&sparse, &model, ColmapFormat::Binary, false).expect("model");
        let images_8 = scene.join("images_8");
        std::fs::create_dir_all(&images_8).expect("images_8");
        for name in &llff.names {
            std::fs::copy(fern.join("images_8").join(name), images_8.join(name)).expect("copy");
        }
        Some((scene, llff))
    }

    /// fern as a COLMAP capture reads as the LLFF reader reads it: the same poses and focal
    /// length, and depth bounds from the points like `poses_bounds.npy`'s.
    #[test]
    fn fern_as_a_colmap_capture_matches_its_llff_release() {
        let Some((scene, llff)) = fern_scene() else {
            return;
        };
        let (data, loaded) = load_colmap_scene(&scene, 8).unwrap();
        assert_eq!(data.len(), 20);
        assert_eq!(data.names[0], "image000.JPG");
        assert_eq!(loaded.format, ColmapFormat::Binary);
        assert!(loaded.unregistered.is_empty());
        for (a, b) in data.world_from_camera.iter().zip(&llff.world_from_camera) {
            assert!((a.translation.vector - b.translation.vector).norm() < 1e-9);
            assert!(a.rotation.angle_to(&b.rotation) < 1e-9);
        }
        assert_eq!((data.camera.width, data.camera.height), (504, 378));
        assert!((data.camera.fx - llff.camera.fx).abs() < 1e-3 * llff.camera.fx);
        // fern's SIMPLE_RADIAL coefficient moves the corners by 3.7 px at 1/8 size (LLFF leaves it).
        println!(
            "fern: undistortion moves pixels by up to {:.3} px",
            loaded.max_distortion_px
        );
        assert!(loaded.max_distortion_px > 1.0 && loaded.max_distortion_px < 5.0);
        let (ours, theirs) = (data.bounds.as_ref().unwrap(), llff.bounds.as_ref().unwrap());
        for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
            println!(
                "image {i}: near {:.3} / {:.3}, far {:.3} / {:.3}",
                a[0], b[0], a[1], b[1]
            );
            assert!((a[0] / b[0] - 1.0).abs() < 0.005 && (a[1] / b[1] - 1.0).abs() < 0.005);
        }
    }

    /// Poses written back replace those of the images given, keep the rest of the model, and
    /// read back; a registered image without its photo, or an existing model, is refused.
    #[test]
    fn refined_poses_are_written_back_as_a_model_colmap_reads() {
        let Some((scene, _)) = fern_scene() else {
            return;
        };
        let (data, loaded) = load_colmap_scene(&scene, 8).unwrap();
        let moved: Vec<Isometry3<f64>> = data.world_from_camera[..18]
            .iter()
            .map(|p| Isometry3::translation(0.01, 0.0, 0.0) * p)
            .collect();
        let indices: Vec<usize> = (0..18).collect();
        let out = scene.join("refined");
        loaded.write_refined(&out, &indices, &moved, false).unwrap();
        let back = read_colmap_model(&out).unwrap();
        let images = back.images.as_ref().unwrap();
        assert_eq!(images.len(), 18);
        for (image, pose) in images.iter().zip(&moved) {
            assert_eq!(image.name, data.names[image.id as usize - 1]);
            assert!(
                (image.world_from_camera.translation.vector - pose.translation.vector).norm()
                    < 1e-12
            );
        }
        assert_eq!(back.cameras, loaded.model.cameras);
        let points = back.points.as_ref().unwrap();
        assert!(
            points
                .iter()
                .all(|p| p.track.len() >= 2 && p.track.iter().all(|t| t.0 <= 18))
        );
        assert!(points.len() > 5000, "{}", points.len());
        let again = loaded
            .write_refined(&out, &indices, &moved, false)
            .unwrap_err()
            .to_string();
        assert!(again.contains("an existing file"), "{again}");

        std::fs::remove_file(scene.join("images_8/image003.png")).unwrap();
        let e = load_colmap_scene(&scene, 8).unwrap_err().to_string();
        assert!(
            e.contains("image003.JPG") && e.contains("no such file"),
            "{e}"
        );
        let e = load_colmap_scene(scene.join("images_8"), 8)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sparse/0/ or sparse/"), "{e}");
    }
}
