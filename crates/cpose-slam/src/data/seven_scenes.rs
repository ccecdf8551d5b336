//! Microsoft 7-Scenes: per frame `frame-NNNNNN.color.png` (or `.color.jpg`),
//! `frame-NNNNNN.depth.png` (16-bit, millimetres, 65535 where the Kinect has no reading) and
//! `frame-NNNNNN.pose.txt` (a 4×4 `world_from_camera`, OpenCV axes, metres: the dataset's
//! KinectFusion reconstruction), in a sequence folder (`<scene>/seq-NN/`) or any flat folder of
//! such frames. Frames are paired by their number, never by position; a frame missing one of its
//! three files is an error naming it. The dataset has no timestamps: frame `N` is at `N / rate`
//! seconds (the Kinect's 30 Hz). Intrinsics from `camera-intrinsics.txt` (a 3×3 `K`) in the
//! folder or its parent when present, else the dataset's published 585 / 320 / 240. Colour and
//! depth are not registered to each other; as is usual with this dataset, one camera serves both.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::replica::stored_size;
use super::{FrameFiles, Intrinsics, RgbdError, RgbdSequence, data_lines, parse_floats};
use cpose_core::geometry::isometry_from_rows;

/// The camera 7-Scenes publishes for its 640×480 frames.
pub const SEVEN_SCENES_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 585.0,
    fy: 585.0,
    cx: 320.0,
    cy: 240.0,
};

/// 7-Scenes' depth PNG units per metre (millimetres).
pub const SEVEN_SCENES_DEPTH_SCALE: f64 = 1000.0;

/// The stored depth value of a pixel without a reading.
pub const SEVEN_SCENES_INVALID_DEPTH: u16 = 65535;

/// The three files of one frame, as found.
#[derive(Default)]
struct Found {
    color: Option<PathBuf>,
    depth: Option<PathBuf>,
    pose: Option<PathBuf>,
}

/// Reads the 7-Scenes frames in `root` at `resolution` (a factor in `(0, 1]`), frame `N` at
/// `N / frame_rate` seconds. Poses that are not finite or not rigid are kept as `None` (dropped
/// from the ATE and counted by it).
pub fn read_seven_scenes(
    root: &Path,
    resolution: f64,
    frame_rate: f64,
) -> Result<RgbdSequence, RgbdError> {
    if !(frame_rate.is_finite() && frame_rate > 0.0) {
        return Err(RgbdError::layout(
            root,
            format!("frame rate {frame_rate} Hz must be positive"),
        ));
    }
    let entries = std::fs::read_dir(root).map_err(|e| RgbdError::io(root, e))?;
    let mut frames: BTreeMap<u64, Found> = BTreeMap::new();
    let mut sequences = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| RgbdError::io(root, e))?.path();
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        if path.is_dir() && name.starts_with("seq-") {
            sequences.push(name.to_owned());
            continue;
        }
        let Some(rest) = name.strip_prefix("frame-") else {
            continue;
        };
        let Some((number, kind)) = rest.split_once('.') else {
            continue;
        };
        let Ok(number) = number.parse::<u64>() else {
            continue;
        };
        let found = frames.entry(number).or_default();
        let slot = match kind.to_ascii_lowercase().as_str() {
            "color.png" | "color.jpg" | "color.jpeg" => &mut found.color,
            "depth.png" => &mut found.depth,
            "pose.txt" => &mut found.pose,
            _ => continue,
        };
        if let Some(first) = slot.replace(path.clone()) {
            return Err(RgbdError::layout(
                root,
                format!(
                    "frame {number} has two files of one kind: {} and {}",
                    first.display(),
                    path.display()
                ),
            ));
        }
    }
    if frames.is_empty() {
        sequences.sort();
        let hint = if sequences.is_empty() {
            String::new()
        } else {
            format!(
                "; this looks like a scene folder: point at one of {}",
                sequences.join(", ")
            )
        };
        return Err(RgbdError::layout(
            root,
            format!(
                "expected 7-Scenes frames: frame-000000.color.png (or .jpg), \
                 frame-000000.depth.png, frame-000000.pose.txt, …{hint}"
            ),
        ));
    }
    let mut files = Vec::with_capacity(frames.len());
    let mut truth = Vec::with_capacity(frames.len());
    for (number, found) in frames {
        let missing = |what: &str| {
            RgbdError::layout(
                root,
                format!(
                    "frame {number} has no {what} file (frame-{number:06}.{what}…); every frame needs \
                     its colour, depth and pose"
                ),
            )
        };
        let color = found.color.ok_or_else(|| missing("color"))?;
        let depth = found.depth.ok_or_else(|| missing("depth"))?;
        let pose = found.pose.ok_or_else(|| missing("pose"))?;
        truth.push(isometry_from_rows(&read_pose(&pose)?).ok());
        files.push(FrameFiles {
            time: number as f64 / frame_rate,
            color,
            depth,
        });
    }
    let stored = stored_size(&files[0].depth)?;
    let intrinsics = [
        Some(root.join("camera-intrinsics.txt")),
        root.parent().map(|p| p.join("camera-intrinsics.txt")),
    ]
    .into_iter()
    .flatten()
    .find(|p| p.is_file())
    .map(|p| read_intrinsics(&p, stored))
    .transpose()?
    .unwrap_or(SEVEN_SCENES_INTRINSICS);
    let mut seq = RgbdSequence::new(
        root,
        &intrinsics,
        stored,
        files,
        truth,
        SEVEN_SCENES_DEPTH_SCALE,
        resolution,
    )?;
    seq.invalid_depth = Some(SEVEN_SCENES_INVALID_DEPTH);
    Ok(seq)
}

/// The 16 numbers of a pose file: a 4×4 matrix on four lines.
fn read_pose(path: &Path) -> Result<Vec<f64>, RgbdError> {
    let lines = data_lines(path)?;
    if lines.len() != 4 {
        return Err(RgbdError::format(
            path,
            "a 4×4 matrix on four lines",
            format!("{} lines", lines.len()),
        ));
    }
    let mut m = Vec::with_capacity(16);
    for (number, line) in &lines {
        m.extend(parse_floats(path, *number, line, 4)?);
    }
    Ok(m)
}

/// Intrinsics from a 3×3 `K` file, for frames of `size`. Errors name the file when `K` is not
/// a pinhole with positive focal lengths.
fn read_intrinsics(path: &Path, size: (usize, usize)) -> Result<Intrinsics, RgbdError> {
    let lines = data_lines(path)?;
    if lines.len() != 3 {
        return Err(RgbdError::format(
            path,
            "a 3×3 intrinsics matrix on three lines",
            format!("{} lines", lines.len()),
        ));
    }
    let mut k = Vec::with_capacity(9);
    for (number, line) in &lines {
        k.extend(parse_floats(path, *number, line, 3)?);
    }
    Intrinsics {
        width: size.0,
        height: size.1,
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
    }
    .checked(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::test_dir;

    /// The shared excerpt: 500 frames paired by number, at 30 Hz, the published camera, metric
    /// depth with the invalid pixels masked, and poses that move about 4 m in all.
    #[test]
    fn the_redkitchen_excerpt_reads_as_a_sequence() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let root = data_dir.join("7scenes/redkitchen_0000_0499");
        let seq = read_seven_scenes(&root, 0.5, 30.0).unwrap();
        assert_eq!(seq.len(), 500);
        assert!((seq.frames[499].time - 499.0 / 30.0).abs() < 1e-12);
        assert_eq!((seq.camera.width, seq.camera.height), (320, 240));
        assert!((seq.camera.fx - 292.5).abs() < 1e-9);
        assert!(seq.truth.iter().all(Option::is_some));
        let frame = seq.load(250).unwrap();
        let depth = frame.depth.data();
        let missing = depth.iter().filter(|d| **d == 0.0).count() as f64 / depth.len() as f64;
        assert!(missing > 0.01 && missing < 0.5, "{missing}");
        assert!(depth.iter().all(|d| *d < 10.0), "a 65535 read as depth");
        let path: f64 = seq
            .truth
            .windows(2)
            .map(|w| (w[1].unwrap().translation.vector - w[0].unwrap().translation.vector).norm())
            .sum();
        assert!(path > 1.0 && path < 20.0, "{path} m");
    }

    /// Writes frame `n` of a tiny 7-Scenes folder (4×3 pixels).
    fn write_frame(dir: &Path, n: u64, depth_mm: u16) {
        let color = cpose_nerf::image::Image::from_fn(4, 3, |x, _| [x as f32 / 4.0, 0.5, 0.5]);
        color
            .save_png(dir.join(format!("frame-{n:06}.color.png")))
            .unwrap();
        let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(4, 3, |x, _| {
            image::Luma([if x == 0 {
                SEVEN_SCENES_INVALID_DEPTH
            } else {
                depth_mm
            }])
        });
        depth
            .save(dir.join(format!("frame-{n:06}.depth.png")))
            .unwrap();
        let pose = format!("1 0 0 {}\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", n as f64 * 0.01);
        std::fs::write(dir.join(format!("frame-{n:06}.pose.txt")), pose).unwrap();
    }

    #[test]
    fn frames_pair_by_number_and_a_missing_file_is_named() {
        let dir = test_dir("7scenes");
        for n in [0, 1, 2, 10] {
            write_frame(&dir, n, 1500);
        }
        let seq = read_seven_scenes(&dir, 1.0, 30.0).unwrap();
        assert_eq!(seq.len(), 4);
        // Frame 10 keeps its number's time: a gap is not closed up.
        assert!((seq.frames[3].time - 10.0 / 30.0).abs() < 1e-12);
        assert!(seq.frames[3].depth.ends_with("frame-000010.depth.png"));
        let frame = seq.load(3).unwrap();
        assert_eq!(frame.depth.at(0, 1), 0.0, "65535 is no reading");
        assert!((frame.depth.at(1, 1) - 1.5).abs() < 1e-6);
        assert!((seq.truth[3].unwrap().translation.x - 0.1).abs() < 1e-12);

        // A middle frame without its depth: an error naming it, never a shifted pairing.
        std::fs::remove_file(dir.join("frame-000001.depth.png")).unwrap();
        let e = read_seven_scenes(&dir, 1.0, 30.0).unwrap_err().to_string();
        assert!(e.contains("frame 1 has no depth file"), "{e}");
    }

    #[test]
    fn bad_folders_and_files_are_errors_naming_them() {
        let dir = test_dir("7scenes-bad");
        std::fs::create_dir_all(dir.join("seq-01")).unwrap();
        let e = read_seven_scenes(&dir, 1.0, 30.0).unwrap_err().to_string();
        assert!(e.contains("point at one of seq-01"), "{e}");
        let seq = dir.join("seq-01");
        write_frame(&seq, 0, 1000);
        std::fs::write(seq.join("frame-000000.pose.txt"), "1 0 0\n").unwrap();
        let e = read_seven_scenes(&seq, 1.0, 30.0).unwrap_err().to_string();
        assert!(
            e.contains("frame-000000.pose.txt") && e.contains("4×4"),
            "{e}"
        );
        write_frame(&seq, 0, 1000);
        std::fs::write(
            dir.join("camera-intrinsics.txt"),
            "-585 0 320\n0 585 240\n0 0 1\n",
        )
        .unwrap();
        let e = read_seven_scenes(&seq, 1.0, 30.0).unwrap_err().to_string();
        assert!(
            e.contains("camera-intrinsics.txt") && e.contains("fx = -585"),
            "{e}"
        );
        let e = read_seven_scenes(&seq, 1.0, 0.0).unwrap_err().to_string();
        assert!(e.contains("frame rate"), "{e}");
    }
}
