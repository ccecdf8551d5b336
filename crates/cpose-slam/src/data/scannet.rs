//! ScanNet as NICE-SLAM reads it: `color/N.jpg`, `depth/N.png` (16-bit, millimetres) and
//! `pose/N.txt` (a 4×4 `world_from_camera`, OpenCV axes; lost frames hold `inf`), sorted by `N`,
//! in the scene folder or its `frames/` subfolder. Colour (1296×968) is resized to the depth's
//! 640×480. Intrinsics from `intrinsic/intrinsic_depth.txt` when present, else NICE-SLAM's.

use std::path::Path;

use super::replica::stored_size;
use super::{
    FrameFiles, Intrinsics, RgbdError, RgbdSequence, data_lines, numbered_files, paired_by_number,
    parse_floats,
};
use cpose_core::geometry::isometry_from_rows;

/// The depth camera of NICE-SLAM's ScanNet config (640×480).
pub const SCANNET_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 577.590698,
    fy: 578.729797,
    cx: 318.905426,
    cy: 242.683609,
};

/// ScanNet's depth PNG units per metre.
pub const SCANNET_DEPTH_SCALE: f64 = 1000.0;

/// ScanNet's frame rate, Hz (frame `i` gets time `i / 30`).
const SCANNET_FRAME_RATE: f64 = 30.0;

/// Reads the ScanNet scene in `root` (or `root/frames`) at `resolution` (NICE-SLAM crops it by
/// 10: [`RgbdSequence::cropped`]). Frames whose pose is missing from `pose/` are an error;
/// poses with `inf`/`nan` entries are kept as `None` (dropped from the ATE, as NICE-SLAM does).
pub fn read_scannet(root: &Path, resolution: f64) -> Result<RgbdSequence, RgbdError> {
    let base = if root.join("frames").join("color").is_dir() {
        root.join("frames")
    } else {
        root.to_path_buf()
    };
    if !base.join("color").is_dir() {
        return Err(RgbdError::layout(
            root,
            "expected a ScanNet scene: color/0.jpg, depth/0.png, pose/0.txt, … \
             (in the scene folder or its frames/ subfolder)",
        ));
    }
    let files = paired_by_number(
        &base,
        [
            (
                "colour",
                numbered_files(&base.join("color"), "", &["jpg", "jpeg", "png"])?,
            ),
            ("depth", numbered_files(&base.join("depth"), "", &["png"])?),
            ("pose", numbered_files(&base.join("pose"), "", &["txt"])?),
        ],
    )?;
    if files.is_empty() {
        return Err(RgbdError::layout(
            &base,
            "no frames in color/, depth/ and pose/",
        ));
    }
    let stored = stored_size(&files[0].1[1])?;
    let intrinsics = match base.join("intrinsic/intrinsic_depth.txt") {
        path if path.is_file() => read_matrix_intrinsics(&path, stored)?,
        _ => SCANNET_INTRINSICS,
    };
    let mut truth = Vec::with_capacity(files.len());
    let mut frames = Vec::with_capacity(files.len());
    for (n, [color, depth, pose]) in files {
        truth.push(isometry_from_rows(&read_matrix(&pose)?).ok());
        frames.push(FrameFiles {
            time: n as f64 / SCANNET_FRAME_RATE,
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
        SCANNET_DEPTH_SCALE,
        resolution,
    )
}

/// The 16 numbers of a 4×4 matrix written as four lines of four (`inf` and `nan` parse).
fn read_matrix(path: &Path) -> Result<Vec<f64>, RgbdError> {
    let lines = data_lines(path)?;
    if lines.len() < 4 {
        return Err(RgbdError::format(
            path,
            "a 4×4 matrix on four lines",
            format!("{} lines", lines.len()),
        ));
    }
    let mut m = Vec::with_capacity(16);
    for (number, line) in &lines[..4] {
        m.extend(parse_floats(path, *number, line, 4)?);
    }
    Ok(m)
}

/// Intrinsics from a 4×4 `K` file, for images of `size`.
fn read_matrix_intrinsics(path: &Path, size: (usize, usize)) -> Result<Intrinsics, RgbdError> {
    let m = read_matrix(path)?;
    Intrinsics {
        width: size.0,
        height: size.1,
        fx: m[0],
        fy: m[5],
        cx: m[2],
        cy: m[6],
    }
    .checked(path)
}

#[cfg(test)]
mod tests {
    use super::super::{DepthImage, test_dir};
    use super::*;
    use cpose_nerf::image::Image;

    #[test]
    fn scannet_sorts_numerically_resizes_colour_crops_and_keeps_lost_poses_as_none() {
        let root = test_dir("scannet");
        let frames = root.join("frames");
        for sub in ["color", "depth", "pose", "intrinsic"] {
            std::fs::create_dir_all(frames.join(sub)).unwrap();
        }
        std::fs::write(
            frames.join("intrinsic/intrinsic_depth.txt"),
            "20 0 15.5 0\n0 20 11.5 0\n0 0 1 0\n0 0 0 1\n",
        )
        .unwrap();
        for i in [0usize, 2, 10] {
            Image::from_fn(64, 48, |_, _| [0.25, 0.5, 0.75])
                .save_png(frames.join(format!("color/{i}.jpg")))
                .unwrap();
            DepthImage::new(32, 24, vec![0.001 * (i + 1) as f32; 32 * 24])
                .unwrap()
                .save_png(&frames.join(format!("depth/{i}.png")), 1000.0)
                .unwrap();
            let pose = if i == 2 {
                "inf inf inf inf\ninf inf inf inf\ninf inf inf inf\n0 0 0 1\n".to_string()
            } else {
                format!("1 0 0 {i}\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
            };
            std::fs::write(frames.join(format!("pose/{i}.txt")), pose).unwrap();
        }
        let seq = read_scannet(&root, 1.0).unwrap().cropped(2).unwrap();
        assert_eq!(seq.len(), 3);
        assert!(seq.frames[2].depth.ends_with("10.png"), "numeric order");
        assert_eq!(seq.truth[2].unwrap().translation.x, 10.0);
        assert!(seq.truth[1].is_none(), "inf pose is lost");
        // Camera: depth size, minus the crop on each side.
        assert_eq!((seq.camera.width, seq.camera.height), (28, 20));
        assert_eq!((seq.camera.cx, seq.camera.cy), (14.0, 10.0));
        let f = seq.load(2).unwrap();
        assert_eq!((f.color.width(), f.color.height()), (28, 20));
        assert!((f.depth.at(0, 0) - 0.011).abs() < 1e-6, "file 10.png");
        assert!((f.color.pixel(3, 3)[1] - 0.5).abs() < 0.01);
    }

    #[test]
    fn a_frame_without_its_pose_file_is_named() {
        let root = test_dir("scannet-missing");
        for sub in ["color", "depth", "pose"] {
            std::fs::create_dir_all(root.join(sub)).unwrap();
        }
        Image::from_fn(4, 3, |_, _| [0.0; 3])
            .save_png(root.join("color/0.jpg"))
            .unwrap();
        DepthImage::new(4, 3, vec![1.0; 12])
            .unwrap()
            .save_png(&root.join("depth/0.png"), 1000.0)
            .unwrap();
        let err = read_scannet(&root, 1.0).unwrap_err().to_string();
        assert!(
            err.contains("frame 0 has a colour file") && err.contains("no pose file"),
            "{err}"
        );
        // A depth image missing in the middle never shifts the later frames onto it.
        for n in 1..3 {
            std::fs::copy(
                root.join("color/0.jpg"),
                root.join(format!("color/{n}.jpg")),
            )
            .unwrap();
            std::fs::write(
                root.join(format!("pose/{n}.txt")),
                "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",
            )
            .unwrap();
        }
        std::fs::write(
            root.join("pose/0.txt"),
            "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",
        )
        .unwrap();
        std::fs::copy(root.join("depth/0.png"), root.join("depth/2.png")).unwrap();
        let err = read_scannet(&root, 1.0).unwrap_err().to_string();
        assert!(
            err.contains("frame 1 has a colour file") && err.contains("no depth file"),
            "{err}"
        );
    }
}
