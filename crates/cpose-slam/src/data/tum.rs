//! TUM RGB-D: `rgb.txt` and `depth.txt` (`timestamp path` per line), `groundtruth.txt`
//! (`t tx ty tz qx qy qz qw`), depth PNGs at 5000 units per metre. Frames are associated as
//! NICE-SLAM does: for each colour image, the nearest depth image and the nearest ground-truth
//! pose, both within 0.08 s; then a frame is kept only if it comes more than 1/32 s after the last
//! kept one. Poses are re-expressed relative to the first kept frame (`P₀⁻¹ P`), as NICE-SLAM.
//! Lens distortion is not removed (NICE-SLAM undistorts fr1's colour only).

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::replica::stored_size;
use super::{FrameFiles, Intrinsics, RgbdError, RgbdSequence, data_lines, line_path, parse_floats};

/// The Freiburg 1 Kinect's colour camera (NICE-SLAM's `freiburg1_desk.yaml`).
pub const TUM_FR1_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 517.3,
    fy: 516.5,
    cx: 318.6,
    cy: 255.3,
};

/// The Freiburg 2 Kinect's colour camera.
const TUM_FR2_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 520.9,
    fy: 521.0,
    cx: 325.1,
    cy: 249.7,
};

/// The Freiburg 3 Kinect's colour camera.
const TUM_FR3_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 535.4,
    fy: 539.2,
    cx: 320.1,
    cy: 247.6,
};

/// TUM's depth PNG units per metre.
pub const TUM_DEPTH_SCALE: f64 = 5000.0;

/// Largest colour–depth and colour–pose time difference of an association, seconds.
const MAX_DT: f64 = 0.08;

/// Smallest time between kept frames, seconds.
const MIN_FRAME_GAP: f64 = 1.0 / 32.0;

/// Reads the TUM RGB-D sequence in `root`. `intrinsics` overrides the camera, which is otherwise
/// chosen by the folder's name (`freiburg2`/`fr2`, `freiburg3`/`fr3`, else Freiburg 1).
/// Without `groundtruth.txt` frames are associated by depth alone and have no ground truth.
pub fn read_tum_rgbd(
    root: &Path,
    intrinsics: Option<Intrinsics>,
    resolution: f64,
) -> Result<RgbdSequence, RgbdError> {
    if !root.join("rgb.txt").is_file() {
        return Err(RgbdError::layout(
            root,
            "expected a TUM RGB-D sequence: rgb.txt, depth.txt, groundtruth.txt, rgb/, depth/",
        ));
    }
    let rgb = stamped_paths(root, "rgb.txt")?;
    let depth = stamped_paths(root, "depth.txt")?;
    let gt_path = root.join("groundtruth.txt");
    let gt = if gt_path.is_file() {
        Some(read_groundtruth(&gt_path)?)
    } else {
        None
    };
    let depth_times: Vec<f64> = depth.iter().map(|d| d.0).collect();
    let gt_times: Vec<f64> = gt.iter().flatten().map(|g| g.0).collect();
    let mut frames: Vec<FrameFiles> = Vec::new();
    let mut truth: Vec<Option<Isometry3<f64>>> = Vec::new();
    for (t, color) in &rgb {
        let Some(j) = nearest(&depth_times, *t).filter(|&j| (depth_times[j] - t).abs() < MAX_DT)
        else {
            continue;
        };
        let pose = match &gt {
            Some(gt) => {
                match nearest(&gt_times, *t).filter(|&k| (gt_times[k] - t).abs() < MAX_DT) {
                    Some(k) => Some(gt[k].1),
                    None => continue,
                }
            }
            None => None,
        };
        if frames
            .last()
            .is_some_and(|last| t - last.time <= MIN_FRAME_GAP)
        {
            continue;
        }
        frames.push(FrameFiles {
            time: *t,
            color: color.clone(),
            depth: depth[j].1.clone(),
        });
        truth.push(pose);
    }
    if frames.is_empty() {
        return Err(RgbdError::layout(
            root,
            format!(
                "no colour image has a depth image (and a ground-truth pose) within {MAX_DT} s"
            ),
        ));
    }
    if let Some(first) = truth[0] {
        let inv = first.inverse();
        for p in truth.iter_mut().flatten() {
            *p = inv * *p;
        }
    }
    let name = root.to_string_lossy().to_ascii_lowercase();
    let intrinsics = intrinsics.unwrap_or(if name.contains("freiburg2") || name.contains("fr2") {
        TUM_FR2_INTRINSICS
    } else if name.contains("freiburg3") || name.contains("fr3") {
        TUM_FR3_INTRINSICS
    } else {
        TUM_FR1_INTRINSICS
    });
    let stored = stored_size(&frames[0].depth)?;
    RgbdSequence::new(
        root,
        &intrinsics,
        stored,
        frames,
        truth,
        TUM_DEPTH_SCALE,
        resolution,
    )
}

/// `(timestamp, root/path)` per line of `root/name`, sorted by time.
fn stamped_paths(root: &Path, name: &str) -> Result<Vec<(f64, std::path::PathBuf)>, RgbdError> {
    let path = root.join(name);
    let mut out = Vec::new();
    for (number, line) in data_lines(&path)? {
        let mut parts = line.split_whitespace();
        match (parts.next().map(str::parse::<f64>), parts.next()) {
            (Some(Ok(t)), Some(file)) if t.is_finite() => out.push((t, root.join(file))),
            _ => {
                return Err(RgbdError::format(
                    &line_path(&path, number),
                    "`timestamp path`",
                    format!("{line:?}"),
                ));
            }
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// `(t, world_from_camera)` per line of a TUM `groundtruth.txt`, sorted by time.
fn read_groundtruth(path: &Path) -> Result<Vec<(f64, Isometry3<f64>)>, RgbdError> {
    let mut out = Vec::new();
    for (number, line) in data_lines(path)? {
        let v = parse_floats(path, number, &line, 8)?;
        let q = Quaternion::new(v[7], v[4], v[5], v[6]);
        if q.norm() < 0.5 || v.iter().any(|x| !x.is_finite()) {
            return Err(RgbdError::format(
                &line_path(path, number),
                "a finite pose with a unit quaternion (qx qy qz qw)",
                format!("{line:?}"),
            ));
        }
        let pose = Isometry3::from_parts(
            Translation3::new(v[1], v[2], v[3]),
            UnitQuaternion::from_quaternion(q),
        );
        out.push((v[0], pose));
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// Index of the value of sorted `times` nearest to `t` (`None` if empty).
fn nearest(times: &[f64], t: f64) -> Option<usize> {
    let k = times.partition_point(|&x| x < t);
    [k.checked_sub(1), (k < times.len()).then_some(k)]
        .into_iter()
        .flatten()
        .min_by(|&a, &b| (times[a] - t).abs().total_cmp(&(times[b] - t).abs()))
}

#[cfg(test)]
mod tests {
    use super::super::{DepthImage, test_dir};
    use super::*;
    use cpose_nerf::image::Image;

    #[test]
    fn association_follows_nice_slam_and_poses_start_at_the_identity() {
        let root = test_dir("tum-fr2-assoc");
        std::fs::create_dir_all(root.join("rgb")).unwrap();
        std::fs::create_dir_all(root.join("depth")).unwrap();
        let mut rgb = String::from("# colour images\n");
        let mut depth = String::new();
        // Colour at 0, 0.02 (too close to 0: dropped), 0.1, 0.3 (no depth within 0.08: dropped).
        for (i, t) in [0.0, 0.02, 0.1, 0.3].iter().enumerate() {
            rgb.push_str(&format!("{t:.4} rgb/{i}.png\n"));
            Image::from_fn(8, 6, |_, _| [0.5; 3])
                .save_png(root.join(format!("rgb/{i}.png")))
                .unwrap();
        }
        for (i, t) in [0.01, 0.09, 0.5].iter().enumerate() {
            depth.push_str(&format!("{t:.4} depth/{i}.png\n"));
            DepthImage::new(8, 6, vec![1.0 + i as f32; 48])
                .unwrap()
                .save_png(&root.join(format!("depth/{i}.png")), TUM_DEPTH_SCALE)
                .unwrap();
        }
        std::fs::write(root.join("rgb.txt"), rgb).unwrap();
        std::fs::write(root.join("depth.txt"), depth).unwrap();
        let mut gt = String::new();
        for k in 0..40 {
            let t = k as f64 * 0.01;
            gt.push_str(&format!("{t:.4} {} 2 3 0 0 0.2588190 0.9659258\n", 1.0 + t));
        }
        std::fs::write(root.join("groundtruth.txt"), gt).unwrap();
        let seq = read_tum_rgbd(&root, None, 1.0).unwrap();
        assert_eq!(seq.times(), vec![0.0, 0.1]);
        assert!(
            (seq.camera.fx - 520.9 * 8.0 / 640.0).abs() < 1e-12,
            "fr2 by the folder name"
        );
        let first = seq.truth[0].unwrap();
        assert!(first.translation.vector.norm() < 1e-12 && first.rotation.angle() < 1e-9);
        // P₀⁻¹ P₁: the camera moved 0.1 along world x, which is rotated by −30° about z.
        let p1 = seq.truth[1].unwrap().translation.vector;
        assert!((p1.norm() - 0.1).abs() < 1e-9 && (p1.x - 0.1 * 0.866_025_4).abs() < 1e-6);
        assert!((seq.load(1).unwrap().depth.at(0, 0) - 2.0).abs() < 1e-3);
    }

    #[test]
    fn malformed_lines_are_named() {
        let root = test_dir("tum-bad");
        std::fs::write(
            root.join("rgb.txt"),
            "0.0 rgb/0.png\nnot-a-time rgb/1.png\n",
        )
        .unwrap();
        std::fs::write(root.join("depth.txt"), "").unwrap();
        let err = read_tum_rgbd(&root, None, 1.0).unwrap_err().to_string();
        assert!(
            err.contains("rgb.txt:2") && err.contains("timestamp path"),
            "{err}"
        );
        let err = read_tum_rgbd(&root.join("nope"), None, 1.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("expected a TUM RGB-D sequence"), "{err}");
    }
}
