//! Trajectory files in the three formats evo reads: TUM ([`super::tum`]), EuRoC csv and KITTI,
//! chosen by name or detected ([`TrajectoryFormat::detect`]). `CONVENTIONS.md` states the
//! conventions; the tests below pin them.
//!
//! - **EuRoC csv** (`state_groundtruth_estimate0/data.csv` and pose files): comma-separated,
//!   `#` lines are comments, at least 8 columns `timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z`
//!   (the real part **first**, unlike TUM); further columns (velocity, biases) are ignored, as
//!   evo's `read_euroc_csv_trajectory` does. Timestamps are integer nanoseconds, read as
//!   `ns / 1e9` seconds and written rounded to the nanosecond.
//! - **KITTI**: 12 space-separated values per line, the first three rows of `world_from_cam`
//!   row by row (`r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz`). The file has no timestamps:
//!   they come from a separate times file (one number of seconds per line, KITTI odometry's
//!   `times.txt`), which reading requires and writing may leave out. The rotation is projected
//!   onto the nearest rotation (the files keep 6–9 digits); a matrix further than
//!   [`MAX_ROTATION_DEFECT`](crate::geometry::MAX_ROTATION_DEFECT) from a rotation is an error.
//!
//! Poses are `world_from_body` in every format.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::trajectory::{Duplicates, PoseLines, Trajectory, TrajectoryError};
use super::tum::{MIN_QUATERNION_NORM, parse_tum_lines, to_tum_string};
use crate::fs::write_atomic;
use crate::geometry::isometry_from_rows;

/// The header line written at the top of an EuRoC csv pose file.
pub const EUROC_HEADER: &str = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []";

/// A trajectory file format (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TrajectoryFormat {
    /// `timestamp tx ty tz qx qy qz qw`, seconds.
    Tum,
    /// `timestamp [ns], px, py, pz, qw, qx, qy, qz[, …]`.
    Euroc,
    /// `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz`, times in a separate file.
    Kitti,
}

impl TrajectoryFormat {
    /// All formats, in order.
    pub const ALL: [TrajectoryFormat; 3] = [Self::Tum, Self::Euroc, Self::Kitti];

    /// The name used in `--format` and messages: `tum`, `euroc`, `kitti`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Tum => "tum",
            Self::Euroc => "euroc",
            Self::Kitti => "kitti",
        }
    }

    /// The format of the file at `path` with contents `text`: a `.csv` name, or a comma-separated
    /// first data line of at least 8 values that starts with an integer of 13 digits or more
    /// (nanoseconds), is EuRoC; 12 values KITTI; 8 values TUM. Errors (naming the file) when none
    /// fits.
    pub fn detect(path: &Path, text: &str) -> Result<Self, TrajectoryError> {
        let csv = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        let first = text
            .strip_prefix('\u{feff}')
            .unwrap_or(text)
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && !l.starts_with('#'));
        let Some(first) = first else {
            // An empty file: let the reader of the likeliest format report it.
            return Ok(if csv { Self::Euroc } else { Self::Tum });
        };
        let comma: Vec<&str> = first.split(',').map(str::trim).collect();
        // Nanoseconds since the Unix epoch have 19 digits; seconds (TUM) have 10 before a point.
        let nanosecond_stamp = comma[0].len() >= 13 && comma[0].bytes().all(|b| b.is_ascii_digit());
        if csv || (comma.len() >= 8 && nanosecond_stamp) {
            return Ok(Self::Euroc);
        }
        match first.split_whitespace().count() {
            12 => Ok(Self::Kitti),
            8 => Ok(Self::Tum),
            _ if comma.len() == 8 => Ok(Self::Tum),
            got => Err(TrajectoryError::UnknownFormat {
                path: path.to_path_buf(),
                got: got.max(comma.len()),
            }),
        }
    }
}

impl fmt::Display for TrajectoryFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for TrajectoryFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|f| f.as_str().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                format!("unknown trajectory format `{s}` (expected tum, euroc or kitti)")
            })
    }
}

fn read_text(path: &Path) -> Result<String, TrajectoryError> {
    std::fs::read_to_string(path).map_err(|source| TrajectoryError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a trajectory file in `format` (detected when `None`), with the lines whose timestamp
/// repeated the line before ([`Duplicates`]: the later pose is kept). KITTI files need
/// `kitti_times`, their times file; it is ignored for the other formats.
pub fn read_trajectory(
    path: impl AsRef<Path>,
    format: Option<TrajectoryFormat>,
    kitti_times: Option<&Path>,
) -> Result<(Trajectory, Duplicates), TrajectoryError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    let format = match format {
        Some(f) => f,
        None => TrajectoryFormat::detect(path, &text)?,
    };
    match format {
        TrajectoryFormat::Tum => parse_tum_lines(&text, path),
        TrajectoryFormat::Euroc => parse_euroc(&text, path),
        TrajectoryFormat::Kitti => {
            let times_path = kitti_times.ok_or_else(|| TrajectoryError::MissingTimes {
                path: path.to_path_buf(),
            })?;
            let times = parse_times(&read_text(times_path)?, times_path)?;
            let poses = parse_kitti(&text, path)?;
            if times.len() != poses.len() {
                return Err(TrajectoryError::TimesCount {
                    path: path.to_path_buf(),
                    poses: poses.len(),
                    times_path: times_path.to_path_buf(),
                    times: times.len(),
                });
            }
            let mut lines = PoseLines::new(path);
            for ((line, _), (time, pose)) in data_lines(&text).zip(times.into_iter().zip(poses)) {
                lines.push(line, time, pose)?;
            }
            lines.finish()
        }
    }
}

/// Writes `trajectory` in `format`, atomically. For KITTI the timestamps go to `kitti_times`
/// when given (KITTI poses have none); it is ignored for the other formats.
pub fn write_trajectory(
    path: impl AsRef<Path>,
    trajectory: &Trajectory,
    format: TrajectoryFormat,
    kitti_times: Option<&Path>,
) -> Result<(), TrajectoryError> {
    let write = |path: &Path, text: String| {
        write_atomic(path, text).map_err(|source| TrajectoryError::Write {
            path: path.to_path_buf(),
            source,
        })
    };
    let path = path.as_ref();
    match format {
        TrajectoryFormat::Tum => write(path, to_tum_string(trajectory)),
        TrajectoryFormat::Euroc => write(path, to_euroc_string(trajectory)),
        TrajectoryFormat::Kitti => {
            if let Some(times) = kitti_times {
                let mut text = String::new();
                for t in trajectory.timestamps_secs() {
                    text.push_str(&format!("{t:e}\n"));
                }
                write(times, text)?;
            }
            write(path, to_kitti_string(trajectory))
        }
    }
}

/// The values of one data line, parsed as finite numbers named by `columns`.
fn numbers(
    fields: Vec<&str>,
    path: &Path,
    line: usize,
    columns: &[&'static str],
) -> Result<Vec<f64>, TrajectoryError> {
    fields
        .iter()
        .zip(columns)
        .map(|(text, &column)| {
            let value: f64 = text.parse().map_err(|_| TrajectoryError::NotANumber {
                path: path.to_path_buf(),
                line,
                column,
                text: (*text).to_owned(),
            })?;
            if value.is_finite() {
                Ok(value)
            } else {
                Err(TrajectoryError::NotFinite {
                    path: path.to_path_buf(),
                    line,
                    column,
                    text: (*text).to_owned(),
                })
            }
        })
        .collect()
}

/// The data lines of `text` as `(1-based line number, trimmed line)`: no blank or `#` lines.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.strip_prefix('\u{feff}')
        .unwrap_or(text)
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

const EUROC_COLUMNS: [&str; 8] = ["timestamp", "p_x", "p_y", "p_z", "q_w", "q_x", "q_y", "q_z"];

/// Parses an EuRoC csv trajectory (module docs); `path` names the origin in errors. A repeated
/// timestamp keeps the later pose ([`Duplicates`]).
pub fn parse_euroc(text: &str, path: &Path) -> Result<(Trajectory, Duplicates), TrajectoryError> {
    let expected = "at least 8 comma-separated columns `timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z` (EuRoC csv)";
    let mut poses = PoseLines::new(path);
    for (line, l) in data_lines(text) {
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() < EUROC_COLUMNS.len() {
            return Err(TrajectoryError::Columns {
                path: path.to_path_buf(),
                line,
                expected,
                got: fields.len(),
            });
        }
        let v = numbers(fields, path, line, &EUROC_COLUMNS)?;
        let q = Quaternion::new(v[4], v[5], v[6], v[7]);
        let norm = q.norm();
        if norm < MIN_QUATERNION_NORM {
            return Err(TrajectoryError::ZeroQuaternion {
                path: path.to_path_buf(),
                line,
                norm,
            });
        }
        let pose = Isometry3::from_parts(
            Translation3::new(v[1], v[2], v[3]),
            UnitQuaternion::from_quaternion(q),
        );
        poses.push(line, v[0] / 1e9, pose)?;
    }
    poses.finish()
}

const KITTI_COLUMNS: [&str; 12] = [
    "r11", "r12", "r13", "tx", "r21", "r22", "r23", "ty", "r31", "r32", "r33", "tz",
];

/// Parses the poses of a KITTI file (module docs), without timestamps.
pub fn parse_kitti(text: &str, path: &Path) -> Result<Vec<Isometry3<f64>>, TrajectoryError> {
    let expected =
        "12 space-separated values `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` (KITTI)";
    let mut poses = Vec::new();
    for (line, l) in data_lines(text) {
        let fields: Vec<&str> = l.split_whitespace().collect();
        if fields.len() != KITTI_COLUMNS.len() {
            return Err(TrajectoryError::Columns {
                path: path.to_path_buf(),
                line,
                expected,
                got: fields.len(),
            });
        }
        let v = numbers(fields, path, line, &KITTI_COLUMNS)?;
        let pose = isometry_from_rows(&v).map_err(|defect| TrajectoryError::NotARotation {
            path: path.to_path_buf(),
            line,
            defect,
        })?;
        poses.push(pose);
    }
    if poses.is_empty() {
        return Err(TrajectoryError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(poses)
}

/// Parses a times file: one number of seconds per line (`#` and blank lines skipped).
pub fn parse_times(text: &str, path: &Path) -> Result<Vec<f64>, TrajectoryError> {
    data_lines(text)
        .map(|(line, l)| {
            let fields: Vec<&str> = l.split_whitespace().collect();
            if fields.len() != 1 {
                return Err(TrajectoryError::Columns {
                    path: path.to_path_buf(),
                    line,
                    expected: "one timestamp in seconds per line",
                    got: fields.len(),
                });
            }
            Ok(numbers(fields, path, line, &["timestamp"])?[0])
        })
        .collect()
}

/// The text of an EuRoC csv pose file: [`EUROC_HEADER`], then one line per pose with the
/// timestamp in integer nanoseconds and the quaternion real part first.
pub fn to_euroc_string(trajectory: &Trajectory) -> String {
    use std::fmt::Write as _;
    let mut out = format!("{EUROC_HEADER}\n");
    for (t, pose) in trajectory.iter() {
        let p = &pose.translation.vector;
        let q = pose.rotation.quaternion();
        let ns = (t * 1e9).round() as i64;
        let _ = writeln!(
            out,
            "{ns},{},{},{},{},{},{},{}",
            p.x, p.y, p.z, q.w, q.i, q.j, q.k
        );
    }
    out
}

/// The text of a KITTI pose file: the first three rows of each pose's matrix, row by row.
pub fn to_kitti_string(trajectory: &Trajectory) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    for pose in trajectory.poses() {
        let m = pose.to_homogeneous();
        let row = |r: usize| format!("{} {} {} {}", m[(r, 0)], m[(r, 1)], m[(r, 2)], m[(r, 3)]);
        let _ = writeln!(out, "{} {} {}", row(0), row(1), row(2));
    }
    out
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use nalgebra::Vector3;

    use super::*;

    fn temp_path(name: &str) -> PathBuf {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!("cpose-formats-{}-{n}-{name}", std::process::id()))
    }

    fn sample() -> Trajectory {
        Trajectory::new(
            vec![1403715524.92214, 1403715525.0, 1403715525.25],
            vec![
                Isometry3::new(Vector3::new(0.5, 2.0, 0.97), Vector3::new(0.3, -0.2, 0.1)),
                Isometry3::new(Vector3::new(-1.0, 0.25, 3.0), Vector3::new(-1.0, 2.0, 0.5)),
                Isometry3::new(Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 3.0)),
            ],
        )
        .unwrap()
    }

    fn assert_same(a: &Trajectory, b: &Trajectory, time_tol: f64) {
        assert_eq!(a.len(), b.len());
        for ((ta, pa), (tb, pb)) in a.iter().zip(b.iter()) {
            assert!((ta - tb).abs() <= time_tol, "{ta} {tb}");
            assert!((pa.translation.vector - pb.translation.vector).norm() < 1e-12);
            assert!(pa.rotation.angle_to(&pb.rotation) < 1e-7);
        }
    }

    #[test]
    fn euroc_reads_the_real_ground_truth_layout_with_w_first_and_nanoseconds() {
        // Two rows of EuRoC V1_02's state_groundtruth_estimate0/data.csv (17 columns).
        let text = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\r\n\
            1403715524922140000,0.515292,1.996597,0.971028,0.161869,0.790012,-0.205215,0.554587,-0.006748,-0.01478,-0.00455,-0.002153,0.020744,0.075806,-0.013337,0.103464,0.093086\r\n\
            1403715524947140000,0.51512,1.996234,0.970893,0.162049,0.789908,-0.20555,0.554559,-0.003653,-0.009745,-0.005977,-0.002153,0.020744,0.075806,-0.013337,0.103464,0.093086\r\n";
        let path = Path::new("data.csv");
        assert_eq!(
            TrajectoryFormat::detect(Path::new("gt.txt"), text).unwrap(),
            TrajectoryFormat::Euroc
        );
        let (t, duplicates) = parse_euroc(text, path).unwrap();
        assert!(duplicates.is_empty());
        assert_eq!(t.timestamps_secs()[0], 1403715524922140000.0 / 1e9);
        assert_eq!(
            t.poses()[0].translation.vector,
            Vector3::new(0.515292, 1.996597, 0.971028)
        );
        // Real part first on disk: q = (w 0.161869, x 0.790012, y −0.205215, z 0.554587).
        let q = Quaternion::new(0.161869, 0.790012, -0.205215, 0.554587).normalize();
        assert!((t.poses()[0].rotation.quaternion().coords - q.coords).norm() < 1e-15);
    }

    #[test]
    fn kitti_is_row_major_world_from_cam_with_times_from_their_own_file() {
        // A quarter turn about z and a shift: r = [[0 −1 0] [1 0 0] [0 0 1]], t = (1, 2, 3).
        let poses = "0 -1 0 1 1 0 0 2 0 0 1 3\n1 0 0 0 0 1 0 0 0 0 1 0\n";
        let times = "0.0e0\n1.5e-1\n";
        let (pose_path, times_path) = (temp_path("poses.txt"), temp_path("times.txt"));
        std::fs::write(&pose_path, poses).unwrap();
        std::fs::write(&times_path, times).unwrap();
        assert_eq!(
            TrajectoryFormat::detect(&pose_path, poses).unwrap(),
            TrajectoryFormat::Kitti
        );
        let (t, _) = read_trajectory(&pose_path, None, Some(&times_path)).unwrap();
        assert_eq!(t.timestamps_secs(), &[0.0, 0.15]);
        let p = t.poses()[0];
        assert_eq!(p.translation.vector, Vector3::new(1.0, 2.0, 3.0));
        // world_from_cam maps the camera's x axis to the world's y axis.
        assert!((p.rotation * Vector3::x() - Vector3::y()).norm() < 1e-15);
        // Without its times file: one clear message naming the file.
        let err = read_trajectory(&pose_path, None, None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("times file") && err.contains("poses.txt"),
            "{err}"
        );
        // A times file of another length.
        std::fs::write(&times_path, "0\n").unwrap();
        let err = read_trajectory(&pose_path, None, Some(&times_path))
            .unwrap_err()
            .to_string();
        assert!(err.contains("2 poses") && err.contains("1 time"), "{err}");
        for p in [pose_path, times_path] {
            std::fs::remove_file(p).unwrap();
        }
    }

    #[test]
    fn kitti_rejects_a_matrix_that_is_not_a_rotation() {
        let err = parse_kitti("2 0 0 0 0 1 0 0 0 0 1 0\n", Path::new("bad.txt"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("line 1: expected a rotation"), "{err}");
    }

    #[test]
    fn every_format_round_trips() {
        let t = sample();
        for format in TrajectoryFormat::ALL {
            let path = temp_path(&format!(
                "roundtrip.{}",
                if format == TrajectoryFormat::Euroc {
                    "csv"
                } else {
                    "txt"
                }
            ));
            let times = temp_path("times.txt");
            write_trajectory(&path, &t, format, Some(&times)).unwrap();
            // Detected from the file alone.
            let (back, _) = read_trajectory(&path, None, Some(&times)).unwrap();
            // EuRoC rounds to the nanosecond; the others keep every digit.
            let tol = if format == TrajectoryFormat::Euroc {
                5e-7
            } else {
                0.0
            };
            assert_same(&t, &back, tol);
            std::fs::remove_file(&path).unwrap();
            // Only KITTI writes its times.
            assert_eq!(
                std::fs::remove_file(&times).is_ok(),
                format == TrajectoryFormat::Kitti
            );
        }
    }

    #[test]
    fn unknown_layouts_name_the_file_and_the_formats() {
        let err = TrajectoryFormat::detect(Path::new("x.txt"), "1 2 3\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("x.txt") && err.contains("--format"), "{err}");
        // A comma-separated TUM line with a whole-second stamp stays TUM.
        let tum = "1,0,0,0,0,0,0,1\n";
        assert_eq!(
            TrajectoryFormat::detect(Path::new("t.txt"), tum).unwrap(),
            TrajectoryFormat::Tum
        );
        assert!("KITTI".parse::<TrajectoryFormat>().is_ok());
        assert!(
            "kitty"
                .parse::<TrajectoryFormat>()
                .unwrap_err()
                .contains("tum, euroc or kitti")
        );
    }
}
