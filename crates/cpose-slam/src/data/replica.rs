//! Replica in NICE-SLAM's layout: `results/frame%06d.jpg`, `results/depth%06d.png` (16-bit,
//! 6553.5 units per metre) and `traj.txt` (one row-major 4×4 `world_from_camera` per line, OpenCV
//! axes). The intrinsics come from `cam_params.json` (`{"camera": {"w", "h", "fx", "fy", "cx",
//! "cy", "scale"}}`, in the scene folder or its parent, as NICE-SLAM's download has it), else
//! from the caller, else Replica's 1200×680 camera.

use std::path::Path;

use cpose_nerf::image::Image;
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::{
    DepthImage, FrameFiles, Intrinsics, RgbdError, RgbdSequence, data_lines, numbered_files,
    paired_by_number, parse_floats,
};
use cpose_core::geometry::isometry_from_rows;

/// Replica's camera in NICE-SLAM's configs: 1200×680, `f = 600`, principal point (599.5, 339.5).
pub const REPLICA_INTRINSICS: Intrinsics = Intrinsics {
    width: 1200,
    height: 680,
    fx: 600.0,
    fy: 600.0,
    cx: 599.5,
    cy: 339.5,
};

/// Replica's depth PNG units per metre.
pub const REPLICA_DEPTH_SCALE: f64 = 6553.5;

/// JPEG quality of written colour frames.
const JPEG_QUALITY: u8 = 95;

#[derive(Debug, Deserialize, Serialize)]
struct CamParams {
    camera: CamParamsCamera,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct CamParamsCamera {
    w: usize,
    h: usize,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    scale: f64,
}

/// Reads the Replica sequence in `root`. Frame `i` gets time `i / frame_rate` seconds.
/// `intrinsics` is used when no `cam_params.json` is found. Errors name the file: no
/// `results/` folder or no frames, colour and depth counts that differ, a `traj.txt` shorter
/// than the frame list or with a malformed line.
pub fn read_replica(
    root: &Path,
    intrinsics: Option<Intrinsics>,
    resolution: f64,
    frame_rate: f64,
) -> Result<RgbdSequence, RgbdError> {
    let results = root.join("results");
    if !results.is_dir() {
        return Err(RgbdError::layout(
            root,
            "expected a Replica scene in NICE-SLAM's layout: results/frame000000.jpg, \
             results/depth000000.png, …, traj.txt",
        ));
    }
    let files = paired_by_number(
        &results,
        [
            (
                "colour",
                numbered_files(&results, "frame", &["jpg", "jpeg", "png"])?,
            ),
            ("depth", numbered_files(&results, "depth", &["png"])?),
        ],
    )?;
    if files.is_empty() {
        return Err(RgbdError::layout(
            &results,
            "no frames (frame*.jpg, depth*.png)",
        ));
    }
    let stored = stored_size(&files[0].1[1])?;
    if !(frame_rate.is_finite() && frame_rate > 0.0) {
        return Err(RgbdError::layout(
            root,
            format!("frame rate {frame_rate} must be positive"),
        ));
    }
    let (intrinsics, depth_scale) = match cam_params(root)? {
        Some(found) => found,
        None => (
            intrinsics.unwrap_or(REPLICA_INTRINSICS),
            REPLICA_DEPTH_SCALE,
        ),
    };
    // Line k of traj.txt is the pose of frame k.
    let traj = root.join("traj.txt");
    let lines = data_lines(&traj)?;
    let last = files[files.len() - 1].0;
    if (lines.len() as u64) <= last {
        return Err(RgbdError::layout(
            &traj,
            format!(
                "{} poses for frames up to {last}: the trajectory must have one line per frame",
                lines.len(),
            ),
        ));
    }
    let mut truth = Vec::with_capacity(files.len());
    let mut frames = Vec::with_capacity(files.len());
    for (n, [color, depth]) in files {
        let (number, line) = &lines[n as usize];
        let m = parse_floats(&traj, *number, line, 16)?;
        truth.push(isometry_from_rows(&m).ok());
        frames.push(FrameFiles {
            time: n as f64 / frame_rate,
            color,
            depth,
        });
    }
    RgbdSequence::new(
        root,
        &intrinsics,
        stored,
        frames,
        truth,
        depth_scale,
        resolution,
    )
}

/// The size of the depth image at `path` (read from its header).
pub(super) fn stored_size(path: &Path) -> Result<(usize, usize), RgbdError> {
    let (w, h) = ::image::image_dimensions(path)
        .map_err(|e| RgbdError::format(path, "a readable depth PNG", e.to_string()))?;
    Ok((w as usize, h as usize))
}

/// `cam_params.json` in `root` or its parent: the intrinsics and depth scale.
fn cam_params(root: &Path) -> Result<Option<(Intrinsics, f64)>, RgbdError> {
    let candidates = [
        Some(root.join("cam_params.json")),
        root.parent().map(|p| p.join("cam_params.json")),
    ];
    for path in candidates.into_iter().flatten() {
        if !path.is_file() {
            continue;
        }
        let text = std::fs::read_to_string(&path).map_err(|e| RgbdError::io(&path, e))?;
        let params: CamParams = serde_json::from_str(&text).map_err(|e| {
            RgbdError::format(
                &path,
                r#"{"camera": {"w", "h", "fx", "fy", "cx", "cy", "scale"}}"#,
                e.to_string(),
            )
        })?;
        let c = params.camera;
        let intrinsics = Intrinsics {
            width: c.w,
            height: c.h,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
        }
        .checked(&path)?;
        if !(c.scale.is_finite() && c.scale > 0.0) {
            return Err(RgbdError::format(
                &path,
                "a positive depth scale (PNG units per metre)",
                format!("scale = {}", c.scale),
            ));
        }
        return Ok(Some((intrinsics, c.scale)));
    }
    Ok(None)
}

/// Writes a sequence in the layout [`read_replica`] reads, with `cam_params.json` describing
/// `intrinsics` at the frames' size and Replica's depth scale. Frames come from `frame(i)` for
/// `i < poses.len()` (rendered on demand, so a long sequence need not fit in memory); the
/// colour is written as JPEG (quality 95), the depth as 16-bit PNG.
pub fn write_replica(
    root: &Path,
    intrinsics: &Intrinsics,
    poses: &[Isometry3<f64>],
    mut frame: impl FnMut(usize) -> (Image, DepthImage),
) -> Result<(), RgbdError> {
    let results = root.join("results");
    std::fs::create_dir_all(&results).map_err(|e| RgbdError::io(&results, e))?;
    let params = CamParams {
        camera: CamParamsCamera {
            w: intrinsics.width,
            h: intrinsics.height,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            scale: REPLICA_DEPTH_SCALE,
        },
    };
    let json = serde_json::to_string_pretty(&params).expect("plain numbers serialise");
    let path = root.join("cam_params.json");
    cpose_core::fs::write_atomic(&path, json.as_bytes()).map_err(|e| RgbdError::io(&path, e))?;
    let mut traj = String::new();
    for (i, pose) in poses.iter().enumerate() {
        let (color, depth) = frame(i);
        save_jpeg(&color, &results.join(format!("frame{i:06}.jpg")))?;
        depth.save_png(
            &results.join(format!("depth{i:06}.png")),
            REPLICA_DEPTH_SCALE,
        )?;
        let m = pose.to_homogeneous();
        let row: Vec<String> = (0..4)
            .flat_map(|r| (0..4).map(move |c| (r, c)))
            .map(|(r, c)| format!("{:.18e}", m[(r, c)]))
            .collect();
        traj.push_str(&row.join(" "));
        traj.push('\n');
    }
    let path = root.join("traj.txt");
    cpose_core::fs::write_atomic(&path, traj.as_bytes()).map_err(|e| RgbdError::io(&path, e))
}

/// Saves `image` as an 8-bit JPEG, atomically.
pub(super) fn save_jpeg(image: &Image, path: &Path) -> Result<(), RgbdError> {
    let bytes: Vec<u8> = image
        .data()
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let mut jpeg = Vec::new();
    ::image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, JPEG_QUALITY)
        .encode(
            &bytes,
            image.width() as u32,
            image.height() as u32,
            ::image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| RgbdError::format(path, "an encodable colour image", e.to_string()))?;
    cpose_core::fs::write_atomic(path, &jpeg).map_err(|e| RgbdError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::super::test_dir;
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn small_sequence(root: &Path, frames: usize) -> Vec<Isometry3<f64>> {
        let intr = Intrinsics {
            width: 8,
            height: 6,
            fx: 4.0,
            fy: 4.0,
            cx: 3.5,
            cy: 2.5,
        };
        let poses: Vec<Isometry3<f64>> = (0..frames)
            .map(|i| {
                Isometry3::from_parts(
                    Translation3::new(i as f64 * 0.1, -0.2, 1.5),
                    UnitQuaternion::from_scaled_axis(Vector3::new(0.1, 0.2 * i as f64, -0.3)),
                )
            })
            .collect();
        write_replica(root, &intr, &poses, |i| {
            let color = Image::from_fn(8, 6, |x, y| [x as f32 / 8.0, y as f32 / 6.0, 0.5]);
            let depth = DepthImage::new(8, 6, vec![1.0 + i as f32; 48]).unwrap();
            (color, depth)
        })
        .unwrap();
        poses
    }

    #[test]
    fn written_sequences_read_back_with_poses_camera_and_depth() {
        let root = test_dir("replica-round-trip");
        let poses = small_sequence(&root, 3);
        let seq = read_replica(&root, None, 1.0, 30.0).unwrap();
        assert_eq!(seq.len(), 3);
        // cam_params.json wins over Replica's defaults; (3.5 + ½) is the continuous centre.
        assert_eq!((seq.camera.width, seq.camera.height), (8, 6));
        assert_eq!(
            (seq.camera.fx, seq.camera.cx, seq.camera.cy),
            (4.0, 4.0, 3.0)
        );
        for (gt, read) in poses.iter().zip(&seq.truth) {
            let read = read.unwrap();
            assert!((gt.translation.vector - read.translation.vector).norm() < 1e-12);
            assert!(gt.rotation.angle_to(&read.rotation) < 1e-9);
        }
        let frame = seq.load(2).unwrap();
        assert!((frame.time - 2.0 / 30.0).abs() < 1e-12);
        assert!((frame.depth.at(3, 3) - 3.0).abs() < 1e-4);
        let c = frame.color.pixel(4, 3);
        assert!(
            (c[0] - 0.5).abs() < 0.03 && (c[2] - 0.5).abs() < 0.03,
            "{c:?}"
        );
        // Half resolution: the camera and both images scale together.
        let half = read_replica(&root, None, 0.5, 30.0).unwrap();
        assert_eq!(
            (half.camera.width, half.camera.fx, half.camera.cx),
            (4, 2.0, 2.0)
        );
        let frame = half.load(0).unwrap();
        assert_eq!(
            (
                frame.color.width(),
                frame.depth.width(),
                frame.depth.height()
            ),
            (4, 4, 3)
        );
        // A crop cuts every side; a second crop replaces the first.
        let cropped = seq.cropped(2).unwrap().cropped(1).unwrap();
        assert_eq!(
            (cropped.camera.width, cropped.camera.height),
            (6, 4),
            "8×6 less one pixel per side"
        );
        assert_eq!((cropped.camera.cx, cropped.camera.cy), (3.0, 2.0));
        let frame = cropped.load(2).unwrap();
        assert_eq!((frame.color.width(), frame.depth.height()), (6, 4));
        let err = cropped.cropped(3).unwrap_err().to_string();
        assert!(
            err.contains("crop_edge 3 leaves no pixels of a 8×6 image"),
            "{err}"
        );
    }

    #[test]
    fn bad_layouts_name_the_file_and_what_was_expected() {
        let root = test_dir("replica-bad");
        let err = read_replica(&root, None, 1.0, 30.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("results/frame000000.jpg"), "{err}");
        small_sequence(&root, 3);
        // A trajectory shorter than the frame list.
        let traj = root.join("traj.txt");
        let text = std::fs::read_to_string(&traj).unwrap();
        let two: String = text.lines().take(2).map(|l| format!("{l}\n")).collect();
        std::fs::write(&traj, two).unwrap();
        let err = read_replica(&root, None, 1.0, 30.0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("traj.txt") && err.contains("2 poses for frames up to 2"),
            "{err}"
        );
        // A malformed line names its number.
        std::fs::write(&traj, text.replacen("e0", "x", 1)).unwrap();
        let err = read_replica(&root, None, 1.0, 30.0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("traj.txt:1") && err.contains("16 numbers"),
            "{err}"
        );
        std::fs::write(&traj, &text).unwrap();
        // A depth image of another size, and a missing colour frame.
        DepthImage::new(4, 4, vec![1.0; 16])
            .unwrap()
            .save_png(&root.join("results/depth000001.png"), 6553.5)
            .unwrap();
        let seq = read_replica(&root, None, 1.0, 30.0).unwrap();
        let err = seq.load(1).unwrap_err().to_string();
        assert!(
            err.contains("depth000001.png") && err.contains("8×6") && err.contains("4×4"),
            "{err}"
        );
        std::fs::remove_file(root.join("results/frame000002.jpg")).unwrap();
        let err = read_replica(&root, None, 1.0, 30.0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("frame 2 has a depth file")
                && err.contains("depth000002.png")
                && err.contains("no colour file"),
            "{err}"
        );
    }

    #[test]
    fn impossible_cameras_and_depth_scales_name_cam_params() {
        let root = test_dir("replica-bad-camera");
        small_sequence(&root, 2);
        let path = root.join("cam_params.json");
        let good = std::fs::read_to_string(&path).unwrap();
        let params: serde_json::Value = serde_json::from_str(&good).unwrap();
        for (key, value, expect) in [
            ("w", serde_json::json!(0), "0×6"),
            ("fx", serde_json::json!(-4.0), "fx = -4"),
            ("scale", serde_json::json!(0.0), "scale = 0"),
            ("scale", serde_json::json!(-1.0), "scale = -1"),
        ] {
            let mut bad = params.clone();
            bad["camera"][key] = value.clone();
            std::fs::write(&path, bad.to_string()).unwrap();
            let err = read_replica(&root, None, 1.0, 30.0)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("cam_params.json") && err.contains(expect),
                "{key} = {value}: {err}"
            );
        }
    }
}
