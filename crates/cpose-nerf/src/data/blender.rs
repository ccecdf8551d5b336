//! Blender / NeRF-synthetic scenes (`transforms_{split}.json` + RGBA PNGs), as released by the
//! NeRF authors and used by BARF (`data/blender.py`).
//!
//! # Layout
//!
//! `<scene>/transforms_{split}.json` holds `camera_angle_x` (horizontal field of view, radians)
//! and `frames`, each with `file_path` (relative to the scene, without extension; the image is
//! `file_path + ".png"`) and `transform_matrix`, a 4×4 row-major camera-to-world matrix with
//! OpenGL camera axes (x right, y up, z backwards).
//!
//! # Conversion
//!
//! * Pose: `world_from_camera = [R_gl · diag(1, −1, −1) | t]` (negate the y and z columns;
//!   [`cpose_core::geometry::world_from_cam_cv_from_gl`]), the same centre `t`.
//! * Focal: `fx = fy = 0.5·W / tan(0.5·camera_angle_x)`, principal point `(W/2, H/2)`.
//! * Colour: the RGBA images are composited over [`BlenderOptions::background`]
//!   (`α·rgb + (1 − α)·bg`; BARF uses white).
//!
//! The format carries no depth bounds (`bounds` is `None`); BARF renders Blender scenes with
//! near = 2, far = 6.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

use super::{Dataset, isometry_from_rt, load_same_size};
use crate::DataError;
use crate::camera::PinholeCamera;
use crate::image::Image;

/// Options of [`load_blender`].
#[derive(Clone, Debug, PartialEq)]
pub struct BlenderOptions {
    /// The split: reads `transforms_{split}.json` (`"train"`, `"val"` or `"test"`).
    pub split: String,
    /// The colour the RGBA images are composited over (default white `[1, 1, 1]`).
    pub background: [f32; 3],
    /// Keep at most this many frames (the first ones, in file order, after skipping).
    pub max_frames: Option<usize>,
    /// Skip frames whose image file does not exist instead of failing. Off by default; turn it
    /// on for excerpts such as `lego_subset`, which ships only 10 of the 100 training images
    /// with the full `transforms_train.json`.
    pub only_existing_images: bool,
}

impl Default for BlenderOptions {
    /// Split `"train"`, white background, all frames, missing images are errors.
    fn default() -> Self {
        BlenderOptions {
            split: "train".to_owned(),
            background: [1.0; 3],
            max_frames: None,
            only_existing_images: false,
        }
    }
}

/// Loads the NeRF-synthetic scene in `scene_dir` (see the module docs for the conversions).
/// Frames keep the JSON order; `names` are the image file names (e.g. `r_0.png`).
///
/// Errors name the file: a missing or malformed JSON (no `camera_angle_x` in `(0, π)`, no
/// `frames` list, a frame without a string `file_path` or a 4×4 numeric `transform_matrix`
/// whose last row is `0 0 0 1` and whose rotation is orthonormal), a missing image (unless
/// [`BlenderOptions::only_existing_images`]), no frames left, or images of different sizes.
pub fn load_blender(
    scene_dir: impl AsRef<Path>,
    options: &BlenderOptions,
) -> Result<Dataset, DataError> {
    let scene_dir = scene_dir.as_ref();
    let json_path = scene_dir.join(format!("transforms_{}.json", options.split));
    let text = std::fs::read_to_string(&json_path).map_err(|error| DataError::Io {
        path: json_path.clone(),
        error,
    })?;
    let bad = |expected: &str, found: String| DataError::Format {
        path: json_path.clone(),
        expected: expected.to_owned(),
        found,
    };
    let json: Value = serde_json::from_str(&text)
        .map_err(|e| bad("valid JSON", format!("a parse error: {e}")))?;
    let angle = json.get("camera_angle_x").and_then(Value::as_f64);
    let angle = match angle {
        Some(a) if a > 0.0 && a < std::f64::consts::PI => a,
        _ => {
            return Err(bad(
                "a number camera_angle_x in (0, π)",
                format!("{:?}", json.get("camera_angle_x")),
            ));
        }
    };
    let frames = json
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| bad("a list `frames`", "none".to_owned()))?;

    let mut paths = Vec::new();
    let mut names = Vec::new();
    let mut world_from_camera = Vec::new();
    for (i, frame) in frames.iter().enumerate() {
        if options.max_frames.is_some_and(|m| paths.len() >= m) {
            break;
        }
        let file_path = frame
            .get("file_path")
            .and_then(Value::as_str)
            .ok_or_else(|| bad(&format!("frame {i}: a string file_path"), frame.to_string()))?;
        let path: PathBuf = scene_dir.join(format!("{file_path}.png"));
        if options.only_existing_images && !path.is_file() {
            continue;
        }
        let m = matrix4(frame.get("transform_matrix")).ok_or_else(|| {
            bad(
                &format!("frame {i}: a 4×4 numeric transform_matrix with last row 0 0 0 1"),
                format!("{:?}", frame.get("transform_matrix")),
            )
        })?;
        let r_gl = Matrix3::from_fn(|r, c| m[r][c]);
        let centre = Vector3::new(m[0][3], m[1][3], m[2][3]);
        let what = format!("frame {i} ({file_path})");
        let pose_gl = isometry_from_rt(r_gl, centre, &json_path, &what)?;
        world_from_camera.push(cpose_core::geometry::world_from_cam_cv_from_gl(&pose_gl));
        names.push(
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
        paths.push(path);
    }
    let bg = options.background;
    let (images, (width, height)) =
        load_same_size(&paths, &json_path, |p| Image::load_rgba_over(p, bg))?;
    let focal = 0.5 * width as f64 / (0.5 * angle).tan();
    Ok(Dataset {
        images,
        world_from_camera,
        camera: PinholeCamera::centred(width, height, focal),
        bounds: None,
        names,
    })
}

/// The frame numbers of a Blender split that is one recording in time: the number each image
/// file's stem ends in (`r_17.png` → 17), which must rise strictly in file order. Errors name
/// `json_path` and the frame whose name has no number, repeats one or comes out of order.
pub fn sequence_numbers(names: &[String], json_path: &Path) -> Result<Vec<u64>, DataError> {
    let bad = |expected: &str, found: String| DataError::Format {
        path: json_path.to_owned(),
        expected: expected.to_owned(),
        found,
    };
    let mut numbers: Vec<u64> = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let stem = name
            .rsplit_once('.')
            .map_or(name.as_str(), |(stem, _)| stem);
        let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let number = stem[stem.len() - digits..].parse::<u64>().map_err(|_| {
            bad(
                "frames of a time sequence: image names ending in their frame number (r_<k>.png)",
                format!("frame {i}: {name}"),
            )
        })?;
        if let Some(&previous) = numbers.last()
            && number <= previous
        {
            let what = if number == previous {
                "repeats"
            } else {
                "comes after"
            };
            return Err(bad(
                "frames of a time sequence, in rising order of their numbers",
                format!("frame {i}: {name} {what} frame {}: {}", i - 1, names[i - 1]),
            ));
        }
        numbers.push(number);
    }
    Ok(numbers)
}

/// A 4×4 matrix of finite numbers (rows) whose last row is `0 0 0 1`.
fn matrix4(value: Option<&Value>) -> Option<[[f64; 4]; 4]> {
    let rows = value?.as_array()?;
    if rows.len() != 4 {
        return None;
    }
    let mut m = [[0.0; 4]; 4];
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array()?;
        if row.len() != 4 {
            return None;
        }
        for (c, v) in row.iter().enumerate() {
            m[r][c] = v.as_f64().filter(|v| v.is_finite())?;
        }
    }
    (m[3] == [0.0, 0.0, 0.0, 1.0]).then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lego_subset_loads_ten_frames_looking_at_the_origin() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let scene = data_dir.join("nerf_synthetic/lego_subset");
        // Without the option, the first missing image (r_1.png) is an error naming it.
        let err = load_blender(&scene, &BlenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("r_1.png"), "{err}");
        let options = BlenderOptions {
            only_existing_images: true,
            ..BlenderOptions::default()
        };
        let data = load_blender(&scene, &options).unwrap();
        assert_eq!(data.len(), 10);
        assert_eq!(data.names[0], "r_0.png");
        assert_eq!(data.names[9], "r_90.png");
        assert_eq!((data.camera.width, data.camera.height), (800, 800));
        assert!(
            (data.camera.fx - 1111.111).abs() < 0.01,
            "{:?}",
            data.camera
        );
        assert_eq!((data.camera.cx, data.camera.cy), (400.0, 400.0));
        assert!(data.bounds.is_none());
        // White background: the top-left corner is empty space.
        assert_eq!(data.images[0].pixel(0, 0), [1.0; 3]);
        for pose in &data.world_from_camera {
            let centre = pose.translation.vector;
            assert!((centre.norm() - 4.031).abs() < 0.01, "{}", centre.norm());
            let r = pose.rotation.to_rotation_matrix();
            let forward = r.matrix().column(2).into_owned();
            assert!(forward.dot(&-centre) > 0.9 * centre.norm());
            // y (down) points downwards in the world (z up in Blender scenes).
            assert!(r.matrix()[(2, 1)] < 0.0);
        }
        let few = BlenderOptions {
            max_frames: Some(3),
            ..options
        };
        assert_eq!(load_blender(&scene, &few).unwrap().len(), 3);
    }

    #[test]
    fn sequences_are_numbered_by_their_file_names_and_must_rise() {
        let json = Path::new("lego/transforms_test.json");
        let names = |list: &[&str]| list.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
        assert_eq!(
            sequence_numbers(&names(&["r_0.png", "r_2.png", "r_10.png"]), json).unwrap(),
            [0, 2, 10]
        );
        for (list, found) in [
            (
                &["r_0.png", "r_2.png", "r_1.png"][..],
                "r_1.png comes after frame 1: r_2.png",
            ),
            (&["r_0.png", "r_1.png", "r_1.png"][..], "r_1.png repeats"),
            (&["r_0.png", "cover.png"][..], "frame 1: cover.png"),
        ] {
            let e = sequence_numbers(&names(list), json)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("transforms_test.json") && e.contains(found),
                "{e}"
            );
        }
    }

    /// The whole Lego scene's test split: 200 views of one revolution, 3.6° apart.
    #[test]
    fn the_lego_test_split_is_one_orbit_in_file_order() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let scene = data_dir.join("nerf_synthetic/lego");
        let options = BlenderOptions {
            split: "test".to_owned(),
            max_frames: Some(11),
            ..BlenderOptions::default()
        };
        let data = load_blender(&scene, &options).unwrap();
        let numbers = sequence_numbers(&data.names, &scene.join("transforms_test.json")).unwrap();
        assert_eq!(numbers, (0..11).collect::<Vec<u64>>());
        assert_eq!((data.camera.width, data.camera.height), (400, 400));
        let azimuth = |k: usize| {
            let c = data.world_from_camera[k].translation.vector;
            c.y.atan2(c.x).to_degrees()
        };
        for k in 1..11 {
            let step = (azimuth(k) - azimuth(k - 1) + 540.0).rem_euclid(360.0) - 180.0;
            assert!((step.abs() - 3.6).abs() < 0.05, "view {k}: {step}°");
        }
    }

    #[test]
    fn malformed_json_errors_name_the_file() {
        let dir = cpose_core::testing::TempDir::new("blender");
        let json = dir.join("transforms_train.json");
        std::fs::write(&json, r#"{"frames": []}"#).unwrap();
        let err = load_blender(&dir, &BlenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("transforms_train.json") && err.contains("camera_angle_x"),
            "{err}"
        );
        std::fs::write(
            &json,
            r#"{"camera_angle_x": 0.7, "frames": [{"file_path": "./a", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}]}"#,
        )
        .unwrap();
        let err = load_blender(&dir, &BlenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("4×4"), "{err}");
        std::fs::write(&json, r#"{"camera_angle_x": 0.7, "frames": []}"#).unwrap();
        let err = load_blender(&dir, &BlenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least one image"), "{err}");
    }
}
