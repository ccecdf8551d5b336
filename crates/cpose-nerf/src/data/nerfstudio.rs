//! nerfstudio's `transforms.json` (what `ns-process-data` writes for a user's photos or video),
//! read as a [`Dataset`] ([`load_nerfstudio`]) and written back with refined poses
//! ([`NerfstudioScene::write_refined`]).
//!
//! # Layout
//!
//! One JSON file (`<scene>/transforms.json`, or a path to the file itself) with the intrinsics at
//! the top level or per frame — `fl_x`, `fl_y`, `cx`, `cy` (pixels, continuous coordinates as
//! COLMAP's), `w`, `h`, the `camera_model` and its coefficients — and `frames`, each with a
//! `file_path` relative to the file's folder and a `transform_matrix`: a 4×4 row-major
//! camera-to-world matrix with **OpenGL camera axes** (x right, y up, z backwards), as Blender's.
//! Every other key is kept and written back unchanged.
//!
//! # Conversion
//!
//! * Pose: `world_from_camera = [R_gl · diag(1, −1, −1) | t]`
//!   ([`cpose_core::geometry::world_from_cam_cv_from_gl`]), the world frame the file's own.
//! * Camera: one for every frame (frames may repeat the top-level values; differing ones are an
//!   error); `camera_model` `PINHOLE`, `SIMPLE_PINHOLE` or `OPENCV` (the default, with `k1`, `k2`,
//!   `k3`, `p1`, `p2`, missing ones zero; the distortion is removed on load, [`super::distortion`]).
//!   `OPENCV_FISHEYE`, `EQUIRECTANGULAR` and others are refused, as is a non-zero `k4`.
//! * Order and time: frames are ordered by `file_path`, frame `i` of that order at `t = i`; a
//!   repeated `file_path` is an error.
//! * Downscaling by `N > 1`: `images_N/…` for a path under `images/` when it exists (what
//!   `ns-process-data` writes), else the image averaged down.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Vector3};
use serde_json::{Map, Value};

use super::capture::{NativeCamera, check_size, load_photos};
use super::distortion::Distortion;
use super::{Dataset, isometry_from_rt};
use crate::DataError;

/// The file, its parsed content and which frame each dataset image came from: what writing
/// refined poses back needs.
#[derive(Clone, Debug)]
pub struct NerfstudioScene {
    /// The `transforms.json` read.
    pub json_path: PathBuf,
    json: Map<String, Value>,
    /// Per dataset image, its index in the file's `frames`.
    frame_indices: Vec<usize>,
    /// Per dataset image, the absolute path of its full-resolution image.
    image_paths: Vec<PathBuf>,
    /// The largest shift, in pixels of the loaded images, by which undistortion moved a pixel.
    pub max_distortion_px: f64,
}

/// One frame's camera, as read.
#[derive(Clone, Debug, PartialEq)]
struct Intrinsics {
    model: String,
    camera: NativeCamera,
}

/// The camera of `frame` (its own keys, else the file's).
fn intrinsics(
    top: &Map<String, Value>,
    frame: &Map<String, Value>,
    path: &Path,
    what: &str,
) -> Result<Intrinsics, DataError> {
    let get = |key: &str| frame.get(key).or_else(|| top.get(key));
    let number = |key: &str, default: Option<f64>| -> Result<f64, DataError> {
        match get(key) {
            None => default.ok_or_else(|| {
                DataError::format(path, format!("{what}: the intrinsic {key}"), "none")
            }),
            Some(v) => v.as_f64().filter(|v| v.is_finite()).ok_or_else(|| {
                DataError::format(
                    path,
                    format!("{what}: a finite number {key}"),
                    v.to_string(),
                )
            }),
        }
    };
    let side = |key: &str| -> Result<usize, DataError> {
        let v = number(key, None)?;
        if (1.0..=65535.0).contains(&v) && v.fract() == 0.0 {
            Ok(v as usize)
        } else {
            Err(DataError::format(
                path,
                format!("{what}: {key} a whole number of pixels in 1..=65535"),
                v.to_string(),
            ))
        }
    };
    let model = match get("camera_model") {
        None => "OPENCV".to_owned(),
        Some(Value::String(s)) => s.clone(),
        Some(other) => {
            return Err(DataError::format(
                path,
                format!("{what}: a string camera_model"),
                other.to_string(),
            ));
        }
    };
    let zero = Some(0.0);
    let lens = match model.as_str() {
        "PINHOLE" | "SIMPLE_PINHOLE" => Distortion::default(),
        "OPENCV" => {
            if number("k4", zero)? != 0.0 {
                return Err(DataError::format(
                    path,
                    format!("{what}: k4 = 0 for OPENCV (k4 belongs to the fisheye model)"),
                    number("k4", zero)?.to_string(),
                ));
            }
            Distortion {
                radial: [
                    number("k1", zero)?,
                    number("k2", zero)?,
                    number("k3", zero)?,
                ],
                tangential: [number("p1", zero)?, number("p2", zero)?],
            }
        }
        other => {
            return Err(DataError::format(
                path,
                format!("{what}: camera_model PINHOLE, SIMPLE_PINHOLE or OPENCV"),
                other.to_owned(),
            ));
        }
    };
    let focal = [number("fl_x", None)?, number("fl_y", None)?];
    if focal.iter().any(|f| *f <= 0.0) {
        return Err(DataError::format(
            path,
            format!("{what}: positive focal lengths fl_x, fl_y"),
            format!("{focal:?}"),
        ));
    }
    Ok(Intrinsics {
        model,
        camera: NativeCamera {
            size: [side("w")?, side("h")?],
            focal,
            centre: [number("cx", None)?, number("cy", None)?],
            lens,
        },
    })
}

/// The 4×4 `transform_matrix` of a frame, its last row `0 0 0 1`.
fn matrix4(value: Option<&Value>) -> Option<[[f64; 4]; 4]> {
    let rows = value?.as_array()?;
    let mut m = [[0.0; 4]; 4];
    if rows.len() != 4 {
        return None;
    }
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|row| row.len() == 4)?;
        for (c, v) in row.iter().enumerate() {
            m[r][c] = v.as_f64().filter(|v| v.is_finite())?;
        }
    }
    (m[3] == [0.0, 0.0, 0.0, 1.0]).then_some(m)
}

/// Loads the nerfstudio scene at `path` (a folder holding `transforms.json`, or the file) at
/// downscale `factor` (see the module docs): the images, undistorted, with their poses (the
/// file's world frame), the pinhole camera and the file paths as names; and what
/// [`NerfstudioScene::write_refined`] needs.
pub fn load_nerfstudio(
    path: impl AsRef<Path>,
    factor: u32,
) -> Result<(Dataset, NerfstudioScene), DataError> {
    let path = path.as_ref();
    let json_path = if path.is_dir() {
        path.join("transforms.json")
    } else {
        path.to_path_buf()
    };
    let folder = json_path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let text = std::fs::read_to_string(&json_path).map_err(|error| DataError::Io {
        path: json_path.clone(),
        error,
    })?;
    let json: Map<String, Value> = serde_json::from_str(&text).map_err(|e| {
        DataError::format(&json_path, "a JSON object", format!("a parse error: {e}"))
    })?;
    if factor == 0 {
        return Err(DataError::format(
            &json_path,
            "a downscale factor of at least 1",
            "0",
        ));
    }
    let frames = json
        .get("frames")
        .and_then(Value::as_array)
        .filter(|f| !f.is_empty())
        .ok_or_else(|| DataError::format(&json_path, "a non-empty list `frames`", "none"))?;

    let mut entries = Vec::with_capacity(frames.len());
    let mut camera: Option<(Intrinsics, String)> = None;
    for (i, frame) in frames.iter().enumerate() {
        let frame = frame.as_object().ok_or_else(|| {
            DataError::format(
                &json_path,
                format!("frame {i}: an object"),
                frame.to_string(),
            )
        })?;
        let file_path = frame
            .get("file_path")
            .and_then(Value::as_str)
            .ok_or_else(|| {
                DataError::format(&json_path, format!("frame {i}: a string file_path"), "none")
            })?;
        let what = format!("frame {i} ({file_path})");
        let own = intrinsics(&json, frame, &json_path, &what)?;
        match &camera {
            None => camera = Some((own, what.clone())),
            Some((first, first_what)) if *first != own => {
                return Err(DataError::format(
                    &json_path,
                    format!("one camera for every frame, as {first_what}'s: {first:?}"),
                    format!("{what}: {own:?}"),
                ));
            }
            Some(_) => {}
        }
        let m = matrix4(frame.get("transform_matrix")).ok_or_else(|| {
            DataError::format(
                &json_path,
                format!("{what}: a 4×4 numeric transform_matrix with last row 0 0 0 1"),
                format!("{:?}", frame.get("transform_matrix")),
            )
        })?;
        let r_gl = Matrix3::from_fn(|r, c| m[r][c]);
        let centre = Vector3::new(m[0][3], m[1][3], m[2][3]);
        let pose_gl = isometry_from_rt(r_gl, centre, &json_path, &what)?;
        entries.push((
            file_path.to_owned(),
            i,
            cpose_core::geometry::world_from_cam_cv_from_gl(&pose_gl),
        ));
    }
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    if let Some(pair) = entries.windows(2).find(|p| p[0].0 == p[1].0) {
        return Err(DataError::format(
            &json_path,
            "each file_path once",
            format!("{} in frames {} and {}", pair[0].0, pair[0].1, pair[1].1),
        ));
    }
    let (camera, _) = camera.expect("frames is not empty");

    // The image to load for each frame, and whether it is still to be downscaled.
    let relative = |p: &str| p.strip_prefix("./").unwrap_or(p).to_owned();
    let full: Vec<PathBuf> = entries
        .iter()
        .map(|e| folder.join(relative(&e.0)))
        .collect();
    let downscaled: Vec<Option<PathBuf>> = entries
        .iter()
        .map(|e| {
            let rest = relative(&e.0);
            let rest = rest.strip_prefix("images/")?;
            let p = folder.join(format!("images_{factor}")).join(rest);
            (factor > 1 && p.is_file()).then_some(p)
        })
        .collect();
    let all_downscaled = downscaled.iter().all(Option::is_some);
    let paths: Vec<PathBuf> = if all_downscaled {
        downscaled.into_iter().flatten().collect()
    } else {
        full.clone()
    };
    let native = camera.camera;
    check_size(entries.len(), &native, factor, &json_path)?;
    let resize = if all_downscaled || factor == 1 {
        1.0
    } else {
        1.0 / f64::from(factor)
    };
    let (images, pinhole, max_distortion_px) = load_photos(&paths, &json_path, resize, &native)?;
    let dataset = Dataset {
        images,
        world_from_camera: entries.iter().map(|e| e.2).collect(),
        camera: pinhole,
        bounds: None,
        names: entries.iter().map(|e| relative(&e.0)).collect(),
    };
    let scene = NerfstudioScene {
        max_distortion_px,
        frame_indices: entries.iter().map(|e| e.1).collect(),
        image_paths: full
            .iter()
            .map(|p| std::path::absolute(p).unwrap_or_else(|_| p.clone()))
            .collect(),
        json,
        json_path,
    };
    Ok((dataset, scene))
}

impl NerfstudioScene {
    /// Writes a `transforms.json` to `path` that is the file read with only the dataset's
    /// images `indices`, their `transform_matrix` replaced by `world_from_camera` (one per index,
    /// the file's world frame), and their `file_path` made absolute so that it reads from
    /// anywhere (nerfstudio joins an absolute path as it is). Every other key is kept.
    pub fn write_refined(
        &self,
        path: &Path,
        indices: &[usize],
        world_from_camera: &[Isometry3<f64>],
    ) -> Result<(), DataError> {
        assert_eq!(indices.len(), world_from_camera.len(), "one pose per index");
        let frames = self.json.get("frames").and_then(Value::as_array);
        let frames: Vec<Value> = indices
            .iter()
            .zip(world_from_camera)
            .map(|(&i, pose)| {
                let mut frame = frames
                    .and_then(|f| f.get(self.frame_indices[i]))
                    .and_then(Value::as_object)
                    .cloned()
                    .unwrap_or_default();
                let gl = cpose_core::geometry::world_from_cam_gl_from_cv(pose).to_homogeneous();
                let rows: Vec<Value> = (0..4)
                    .map(|r| Value::from((0..4).map(|c| gl[(r, c)]).collect::<Vec<f64>>()))
                    .collect();
                frame.insert("transform_matrix".to_owned(), Value::from(rows));
                frame.insert(
                    "file_path".to_owned(),
                    Value::from(self.image_paths[i].to_string_lossy().into_owned()),
                );
                Value::Object(frame)
            })
            .collect();
        let mut json = self.json.clone();
        json.insert("frames".to_owned(), Value::from(frames));
        let text = serde_json::to_string_pretty(&json).expect("a JSON value serialises");
        cpose_core::fs::write_atomic(path, text.as_bytes()).map_err(|error| DataError::Write {
            path: path.to_path_buf(),
            error,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::testing::TempDir;
    use serde_json::json;

    /// A pose with OpenCV axes, its camera-to-world matrix with OpenGL axes as nerfstudio stores it.
    fn gl_rows(pose: &Isometry3<f64>) -> Value {
        let m = cpose_core::geometry::world_from_cam_gl_from_cv(pose).to_homogeneous();
        json!(
            (0..4)
                .map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        )
    }

    /// Three frames out of order, an OPENCV camera at the top level, one frame repeating it.
    fn scene(dir: &Path) -> Vec<Isometry3<f64>> {
        std::fs::create_dir_all(dir.join("images")).unwrap();
        let poses: Vec<Isometry3<f64>> = (0..3)
            .map(|i| {
                Isometry3::new(
                    Vector3::new(i as f64, 0.5, -1.0),
                    Vector3::new(0.1 * i as f64, 0.2, 0.0),
                )
            })
            .collect();
        for i in 0..3 {
            crate::image::procedural_texture(32, 24, i)
                .save_png(dir.join(format!("images/frame_{i:05}.png")))
                .unwrap();
        }
        let frame = |i: usize| json!({"file_path": format!("./images/frame_{i:05}.png"), "transform_matrix": gl_rows(&poses[i]), "colmap_im_id": i + 1});
        let mut first = frame(2);
        first["fl_x"] = json!(30.0);
        let text = json!({
            "camera_model": "OPENCV", "fl_x": 30.0, "fl_y": 31.0, "cx": 16.0, "cy": 12.0,
            "w": 32, "h": 24, "k1": -0.05, "k2": 0.0, "p1": 0.001, "p2": 0.0,
            "applied_transform": [[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0]],
            "frames": [first, frame(0), frame(1)],
        });
        std::fs::write(dir.join("transforms.json"), text.to_string()).unwrap();
        poses
    }

    #[test]
    fn frames_load_in_file_order_with_opencv_axes_and_write_back_refined() {
        let dir = TempDir::new("nerfstudio");
        let poses = scene(&dir);
        let (data, scene) = load_nerfstudio(&*dir, 1).unwrap();
        assert_eq!(
            data.names,
            [
                "images/frame_00000.png",
                "images/frame_00001.png",
                "images/frame_00002.png"
            ]
        );
        for (a, b) in data.world_from_camera.iter().zip(&poses) {
            assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
            assert!(a.rotation.angle_to(&b.rotation) < 1e-12);
        }
        assert_eq!(
            (data.camera.fx, data.camera.fy, data.camera.cx),
            (30.0, 31.0, 16.0)
        );
        assert!(scene.max_distortion_px > 0.1, "{}", scene.max_distortion_px);
        // Downscaled by 2 without images_2/: averaged down, the camera halved.
        let (half, _) = load_nerfstudio(dir.join("transforms.json"), 2).unwrap();
        assert_eq!((half.camera.width, half.camera.fx), (16, 15.0));

        let moved: Vec<Isometry3<f64>> = data.world_from_camera[..2]
            .iter()
            .map(|p| Isometry3::translation(0.0, 0.1, 0.0) * p)
            .collect();
        let out = dir.join("refined.json");
        scene.write_refined(&out, &[0, 1], &moved).unwrap();
        let (back, back_scene) = load_nerfstudio(&out, 1).unwrap();
        assert_eq!(back.len(), 2);
        for (a, b) in back.world_from_camera.iter().zip(&moved) {
            assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
        }
        assert_eq!(
            back_scene.json["applied_transform"],
            scene.json["applied_transform"]
        );
        let frames = back_scene.json["frames"].as_array().unwrap();
        assert_eq!(frames[0]["colmap_im_id"], 1);
        assert!(Path::new(frames[0]["file_path"].as_str().unwrap()).is_absolute());
    }

    #[test]
    fn bad_files_name_the_frame_and_what_was_expected() {
        let dir = TempDir::new("nerfstudio-bad");
        scene(&dir);
        let original = std::fs::read_to_string(dir.join("transforms.json")).unwrap();
        let cases: [(&str, &str, &[&str]); 5] = [
            // serde_json writes the keys sorted, without spaces.
            ("\"fl_y\":31.0", "\"fl_y\":32.0,\"fisheye\":1", &[]),
            (
                "\"camera_model\":\"OPENCV\"",
                "\"camera_model\":\"OPENCV_FISHEYE\"",
                &["PINHOLE, SIMPLE_PINHOLE or OPENCV", "OPENCV_FISHEYE"],
            ),
            (
                "frame_00001.png",
                "frame_00000.png",
                &["each file_path once", "frame_00000.png"],
            ),
            (
                "\"fl_x\":30.0,\"fl_y\"",
                "\"fl_x\":29.0,\"fl_y\"",
                &["one camera for every frame"],
            ),
            ("\"w\":32", "\"w\":0", &["w a whole number of pixels"]),
        ];
        for (from, to, expected) in cases {
            let text = original.replacen(from, to, 1);
            assert_ne!(text, original, "{from}");
            std::fs::write(dir.join("transforms.json"), &text).unwrap();
            let result = load_nerfstudio(&*dir, 1);
            if expected.is_empty() {
                result.unwrap();
                continue;
            }
            let e = result.unwrap_err().to_string();
            assert!(e.contains("transforms.json"), "{e}");
            for x in expected {
                assert!(e.contains(x), "{to}: {e}");
            }
        }
    }
}
