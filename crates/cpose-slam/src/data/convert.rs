//! Writes a sequence in another dataset's layout: Replica (NICE-SLAM's `results/` and
//! `traj.txt`), ScanNet (`color/`, `depth/`, `pose/`, `intrinsic/`) or TUM RGB-D (`rgb.txt`,
//! `depth.txt`, `groundtruth.txt` with the frames' own timestamps). So a real recording in one
//! format exercises every reader on real pixels, and a user's capture can be brought to the layout
//! another tool reads. The example `rgbd_convert` runs it from the command line.
//!
//! Frames are written as the sequence loads them (at its resolution and crop, with its camera): colour as JPEG
//! (Replica, ScanNet) or PNG (TUM), depth as 16-bit PNG in the layout's own units per metre, a
//! missing reading as 0. Every frame needs a ground-truth pose. The destination must be an empty
//! or new folder: nothing of a user's is ever overwritten.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Isometry3;

use super::replica::save_jpeg;
use super::{
    DepthImage, Intrinsics, RgbdError, RgbdSequence, SCANNET_DEPTH_SCALE, TUM_DEPTH_SCALE,
    write_replica,
};
use cpose_nerf::image::Image;

/// A dataset layout [`write_sequence`] writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// NICE-SLAM's Replica: `results/frame%06d.jpg`, `results/depth%06d.png`, `traj.txt`,
    /// `cam_params.json`.
    Replica,
    /// ScanNet: `color/N.jpg`, `depth/N.png`, `pose/N.txt`, `intrinsic/intrinsic_depth.txt`.
    Scannet,
    /// TUM RGB-D: `rgb/`, `depth/`, `rgb.txt`, `depth.txt`, `groundtruth.txt`.
    Tum,
}

impl Layout {
    /// The layout of a name: `replica`, `scannet` or `tum`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "replica" => Some(Self::Replica),
            "scannet" => Some(Self::Scannet),
            "tum" => Some(Self::Tum),
            _ => None,
        }
    }
}

/// Writes the first `count` frames of `seq` (all when `None`) into the new or empty folder `dst`
/// in `layout`, with `seq`'s camera. Errors name the folder or file: `dst` not empty, a frame
/// without a ground-truth pose, a file that cannot be read or written.
pub fn write_sequence(
    seq: &RgbdSequence,
    layout: Layout,
    dst: &Path,
    count: Option<usize>,
) -> Result<(), RgbdError> {
    if dst.exists() {
        let mut entries = std::fs::read_dir(dst).map_err(|e| RgbdError::io(dst, e))?;
        if entries.next().is_some() {
            return Err(RgbdError::layout(
                dst,
                "the destination is not empty; name a new or empty folder (nothing is overwritten)",
            ));
        }
    }
    // The datasets' convention: the principal point in integer pixel coordinates.
    let c = &seq.camera;
    let intrinsics = &Intrinsics {
        width: c.width,
        height: c.height,
        fx: c.fx,
        fy: c.fy,
        cx: c.cx - 0.5,
        cy: c.cy - 0.5,
    };
    let n = count.unwrap_or(seq.len()).min(seq.len());
    let mut poses = Vec::with_capacity(n);
    for (i, pose) in seq.truth[..n].iter().enumerate() {
        poses.push(pose.ok_or_else(|| {
            RgbdError::layout(
                &seq.frames[i].color,
                format!("frame {i} has no ground-truth pose to write"),
            )
        })?);
    }
    let mkdir = |path: &Path| std::fs::create_dir_all(path).map_err(|e| RgbdError::io(path, e));
    mkdir(dst)?;
    match layout {
        Layout::Replica => {
            let mut failed = None;
            write_replica(dst, intrinsics, &poses, |i| match seq.load(i) {
                Ok(frame) => (frame.color, frame.depth),
                Err(e) => {
                    failed.get_or_insert(e);
                    (Image::from_fn(1, 1, |_, _| [0.0; 3]), empty_depth())
                }
            })?;
            if let Some(e) = failed {
                return Err(e);
            }
        }
        Layout::Scannet => {
            for sub in ["color", "depth", "pose", "intrinsic"] {
                mkdir(&dst.join(sub))?;
            }
            let k = format!(
                "{} 0 {} 0\n0 {} {} 0\n0 0 1 0\n0 0 0 1\n",
                intrinsics.fx, intrinsics.cx, intrinsics.fy, intrinsics.cy
            );
            write_text(&dst.join("intrinsic/intrinsic_depth.txt"), &k)?;
            for (i, pose) in poses.iter().enumerate() {
                let frame = seq.load(i)?;
                save_jpeg(&frame.color, &dst.join(format!("color/{i}.jpg")))?;
                frame
                    .depth
                    .save_png(&dst.join(format!("depth/{i}.png")), SCANNET_DEPTH_SCALE)?;
                write_text(&dst.join(format!("pose/{i}.txt")), &matrix_lines(pose))?;
            }
        }
        Layout::Tum => {
            mkdir(&dst.join("rgb"))?;
            mkdir(&dst.join("depth"))?;
            let (mut rgb, mut depth, mut truth) = (
                String::from("# color images\n# timestamp filename\n"),
                String::from("# depth maps\n# timestamp filename\n"),
                String::from("# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n"),
            );
            for (i, pose) in poses.iter().enumerate() {
                let frame = seq.load(i)?;
                let t = seq.frames[i].time;
                let name = format!("{t:.6}.png");
                frame.color.save_png(dst.join("rgb").join(&name))?;
                frame
                    .depth
                    .save_png(&dst.join("depth").join(&name), TUM_DEPTH_SCALE)?;
                let (p, q) = (pose.translation.vector, pose.rotation.coords);
                let _ = writeln!(rgb, "{t:.6} rgb/{name}");
                let _ = writeln!(depth, "{t:.6} depth/{name}");
                let _ = writeln!(
                    truth,
                    "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
                    p.x, p.y, p.z, q.x, q.y, q.z, q.w
                );
            }
            write_text(&dst.join("rgb.txt"), &rgb)?;
            write_text(&dst.join("depth.txt"), &depth)?;
            write_text(&dst.join("groundtruth.txt"), &truth)?;
        }
    }
    Ok(())
}

/// A 1×1 depth image without a reading.
fn empty_depth() -> DepthImage {
    DepthImage::new(1, 1, vec![0.0]).expect("one value for one pixel")
}

/// A 4×4 row-major matrix on four lines.
fn matrix_lines(pose: &Isometry3<f64>) -> String {
    let m = pose.to_homogeneous();
    let mut out = String::new();
    for r in 0..4 {
        let row: Vec<String> = (0..4).map(|c| format!("{:.12e}", m[(r, c)])).collect();
        out.push_str(&row.join(" "));
        out.push('\n');
    }
    out
}

fn write_text(path: &Path, text: &str) -> Result<(), RgbdError> {
    cpose_core::fs::write_atomic(path, text.as_bytes()).map_err(|e| RgbdError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{
        SEVEN_SCENES_INTRINSICS, read_replica, read_scannet, read_seven_scenes, read_tum_rgbd,
        test_dir,
    };

    /// Ten real Kinect frames of 7-Scenes written in every layout and read back by that
    /// layout's reader: the same poses (TUM's relative to its first, as NICE-SLAM reads it), the
    /// same camera and the same depth to the layout's precision, invalid pixels still missing.
    #[test]
    fn real_kinect_frames_round_trip_through_every_layout() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let source =
            read_seven_scenes(&data_dir.join("7scenes/redkitchen_0000_0499"), 1.0, 30.0).unwrap();
        let n = 10;
        let dir = test_dir("convert");
        let original = source.load(7).unwrap();
        for layout in [Layout::Replica, Layout::Scannet, Layout::Tum] {
            let dst = dir.join(format!("{layout:?}"));
            write_sequence(&source, layout, &dst, Some(n)).unwrap();
            let (read, precision) = match layout {
                // Replica's 6553.5 units per metre round the millimetres; the others hold them.
                Layout::Replica => (read_replica(&dst, None, 1.0, 30.0).unwrap(), 1e-4),
                Layout::Scannet => (read_scannet(&dst, 1.0).unwrap(), 2e-6),
                Layout::Tum => (
                    read_tum_rgbd(&dst, Some(SEVEN_SCENES_INTRINSICS), 1.0).unwrap(),
                    2e-6,
                ),
            };
            assert_eq!(read.len(), n, "{layout:?}");
            assert_eq!(read.camera, source.camera, "{layout:?}");
            let first = source.truth[0].unwrap();
            for i in 0..n {
                let expected = match layout {
                    Layout::Tum => first.inverse() * source.truth[i].unwrap(),
                    _ => source.truth[i].unwrap(),
                };
                let got = read.truth[i].unwrap();
                assert!(
                    (got.translation.vector - expected.translation.vector).norm() < 1e-6
                        && got.rotation.angle_to(&expected.rotation) < 1e-6,
                    "{layout:?} frame {i}"
                );
            }
            let frame = read.load(7).unwrap();
            for (a, b) in frame.depth.data().iter().zip(original.depth.data()) {
                let same = if *b == 0.0 {
                    *a == 0.0
                } else {
                    (a - b).abs() <= precision
                };
                assert!(same, "{layout:?}: {a} vs {b}");
            }
            let diff = cpose_nerf::image::psnr(frame.color.data(), original.color.data());
            assert!(diff > 30.0, "{layout:?}: colour PSNR {diff}");
        }
        let e = write_sequence(&source, Layout::Tum, &dir.join("Tum"), Some(n))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not empty"), "{e}");
    }
}
