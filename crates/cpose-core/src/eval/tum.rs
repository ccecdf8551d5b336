//! The TUM RGB-D trajectory format: one pose per line, `timestamp tx ty tz qx qy qz qw`.
//!
//! The quaternion is Hamilton with its real part **last** on disk (evo's
//! `file_interface.read_tum_trajectory_file` rolls it to the front after reading; nalgebra's
//! `Quaternion::new(w, x, y, z)` takes it first). The pose is `world_from_body`: `t` is the body
//! origin in the world, `q` rotates body vectors into the world.
//!
//! Reading accepts what evo accepts and a little more: lines starting with `#` and blank lines are
//! skipped, values are separated by whitespace or by commas, a UTF-8 byte-order mark is ignored.
//! It is strict where evo is lenient or vague: every problem is reported with the 1-based line
//! and the file. Quaternions are normalised on reading (as evo's `quaternion_matrix` does). A
//! timestamp repeated by the next line keeps the later pose and is counted ([`Duplicates`]);
//! evo reads such files too.

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::trajectory::{Duplicates, PoseLines, Trajectory, TrajectoryError};

/// Column names of a TUM line, in file order.
pub const TUM_COLUMNS: [&str; 8] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];

/// Quaternions with a norm below this are rejected as "zero" (they name no rotation).
pub const MIN_QUATERNION_NORM: f64 = 1e-12;

/// Reads a TUM trajectory file. See the module docs for what is accepted.
pub fn read_tum(path: impl AsRef<Path>) -> Result<Trajectory, TrajectoryError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| TrajectoryError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_tum(&text, path)
}

/// Parses the text of a TUM trajectory file; `path` only names the origin in errors. A repeated
/// timestamp keeps the last pose ([`Duplicates`], returned by [`parse_tum_lines`]).
pub fn parse_tum(text: &str, path: &Path) -> Result<Trajectory, TrajectoryError> {
    parse_tum_lines(text, path).map(|(trajectory, _)| trajectory)
}

/// [`parse_tum`], with the lines whose timestamp repeated the line before.
pub fn parse_tum_lines(
    text: &str,
    path: &Path,
) -> Result<(Trajectory, Duplicates), TrajectoryError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut poses = PoseLines::new(path);
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = if trimmed.contains(',') {
            trimmed.split(',').map(str::trim).collect()
        } else {
            trimmed.split_whitespace().collect()
        };
        if fields.len() != TUM_COLUMNS.len() {
            return Err(TrajectoryError::Columns {
                path: path.to_path_buf(),
                line,
                expected: "8 columns `timestamp tx ty tz qx qy qz qw`",
                got: fields.len(),
            });
        }
        let mut values = [0.0_f64; 8];
        for ((value, text), column) in values.iter_mut().zip(&fields).zip(TUM_COLUMNS) {
            let parsed: f64 = text.parse().map_err(|_| TrajectoryError::NotANumber {
                path: path.to_path_buf(),
                line,
                column,
                text: (*text).to_owned(),
            })?;
            if !parsed.is_finite() {
                return Err(TrajectoryError::NotFinite {
                    path: path.to_path_buf(),
                    line,
                    column,
                    text: (*text).to_owned(),
                });
            }
            *value = parsed;
        }
        let [timestamp, tx, ty, tz, qx, qy, qz, qw] = values;
        // Hamilton quaternion, real part first in nalgebra, last on disk.
        let q = Quaternion::new(qw, qx, qy, qz);
        let norm = q.norm();
        if norm < MIN_QUATERNION_NORM {
            return Err(TrajectoryError::ZeroQuaternion {
                path: path.to_path_buf(),
                line,
                norm,
            });
        }
        let world_from_body = Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_quaternion(q),
        );
        poses.push(line, timestamp, world_from_body)?;
    }
    poses.finish()
}

/// Formats a timestamp with at least 9 decimals and without loss: Rust's shortest round-trip
/// decimal (never in exponent notation), padded with zeros to 9 decimals (`1305031098.6659` →
/// `1305031098.665900000`, which reads back to the same `f64`).
fn format_timestamp(t: f64) -> String {
    let mut s = format!("{t}");
    let decimals = match s.find('.') {
        Some(dot) => s.len() - dot - 1,
        None => {
            s.push('.');
            0
        }
    };
    for _ in decimals..9 {
        s.push('0');
    }
    s
}

/// The text of a TUM file for `trajectory`: a `#` header line, then one line per pose. Values use
/// Rust's shortest round-trip formatting, so reading the text back gives the same numbers.
pub fn to_tum_string(trajectory: &Trajectory) -> String {
    use std::fmt::Write as _;
    let mut out = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (t, pose) in trajectory.iter() {
        let p = &pose.translation.vector;
        let q = pose.rotation.quaternion();
        // `writeln!` into a `String` cannot fail.
        let _ = writeln!(
            out,
            "{} {} {} {} {} {} {} {}",
            format_timestamp(t),
            p.x,
            p.y,
            p.z,
            q.i,
            q.j,
            q.k,
            q.w
        );
    }
    out
}

/// Writes `trajectory` as a TUM file, atomically ([`super::write_trajectory`]).
pub fn write_tum(path: impl AsRef<Path>, trajectory: &Trajectory) -> Result<(), TrajectoryError> {
    super::write_trajectory(path, trajectory, super::TrajectoryFormat::Tum, None)
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use nalgebra::Vector3;

    use super::*;

    /// A unique path under the system temp folder for one test file.
    fn temp_path(name: &str) -> PathBuf {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!("cpose-tum-{}-{n}-{name}", std::process::id()))
    }

    /// Writes `text` to a unique temp file, reads it with [`read_tum`], removes the file.
    fn read_text(name: &str, text: &str) -> (Result<Trajectory, TrajectoryError>, PathBuf) {
        let path = temp_path(name);
        std::fs::write(&path, text).unwrap();
        let result = read_tum(&path);
        std::fs::remove_file(&path).unwrap();
        (result, path)
    }

    /// The error message of reading `text`; checks that it names the file.
    fn error_of(name: &str, text: &str) -> (TrajectoryError, String) {
        let (result, path) = read_text(name, text);
        let err = result.unwrap_err();
        let msg = err.to_string();
        assert!(msg.ends_with(&path.display().to_string()), "{msg}");
        (err, msg)
    }

    const GOOD: &str = "# comment\n\n1.0 1 2 3 0 0 0 1\n  # indented comment\n2.5,4,5,6,0,0,0.7071067811865476,0.7071067811865476\n";

    #[test]
    fn reads_comments_blanks_spaces_and_commas() {
        let (t, _) = read_text("good.txt", GOOD);
        let t = t.unwrap();
        assert_eq!(t.timestamps_secs(), &[1.0, 2.5]);
        assert_eq!(t.poses()[0].translation.vector, Vector3::new(1.0, 2.0, 3.0));
        // qw last on disk: the second pose is a 90° rotation about z.
        let rotated = t.poses()[1].rotation * Vector3::x();
        assert!((rotated - Vector3::y()).norm() < 1e-15);
    }

    #[test]
    fn quaternion_order_on_disk_is_xyzw() {
        // qx = 1: a half turn about x maps y to −y.
        let (t, _) = read_text("xyzw.txt", "0 0 0 0 1 0 0 0\n");
        let t = t.unwrap();
        let q = t.poses()[0].rotation;
        assert_eq!((q.i, q.j, q.k, q.w), (1.0, 0.0, 0.0, 0.0));
        assert!((q * Vector3::y() + Vector3::y()).norm() < 1e-15);
    }

    #[test]
    fn write_then_read_is_lossless() {
        let poses = vec![
            Isometry3::new(
                Vector3::new(0.1, -2.0 / 3.0, 1e-20),
                Vector3::new(0.3, -0.2, 0.1),
            ),
            Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(-1.0, 2.0, 0.5)),
        ];
        let t = Trajectory::new(vec![1305031098.6659, 1305031098.6758123], poses).unwrap();
        let path = temp_path("roundtrip.txt");
        write_tum(&path, &t).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("1305031098.665900000 "), "{text}");
        let back = read_tum(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(back.timestamps_secs(), t.timestamps_secs());
        for (a, b) in back.poses().iter().zip(t.poses()) {
            assert_eq!(a.translation, b.translation);
            assert!(a.rotation.angle_to(&b.rotation) < 1e-15);
        }
        // Small timestamps keep full precision too.
        assert_eq!(format_timestamp(0.1234567890123), "0.1234567890123");
        assert_eq!(format_timestamp(2.0), "2.000000000");
        assert_eq!(format_timestamp(-1.5), "-1.500000000");
    }

    #[test]
    fn wrong_column_count() {
        let (err, msg) = error_of("cols.txt", "# c\n1 2 3 4 5 6 7\n");
        assert!(matches!(
            err,
            TrajectoryError::Columns {
                line: 2,
                got: 7,
                ..
            }
        ));
        assert!(
            msg.starts_with("line 2: expected 8 columns `timestamp tx ty tz qx qy qz qw`, got 7"),
            "{msg}"
        );
    }

    #[test]
    fn not_a_number() {
        let (err, msg) = error_of("nan-text.txt", "1 0 0 zero 0 0 0 1\n");
        assert!(matches!(
            err,
            TrajectoryError::NotANumber {
                line: 1,
                column: "tz",
                ..
            }
        ));
        assert!(
            msg.contains("expected a number for `tz`, got `zero`"),
            "{msg}"
        );
    }

    #[test]
    fn nan_and_infinity() {
        let (err, _) = error_of("nan.txt", "1 0 0 0 0 0 0 1\n2 NaN 0 0 0 0 0 1\n");
        assert!(matches!(
            err,
            TrajectoryError::NotFinite {
                line: 2,
                column: "tx",
                ..
            }
        ));
        let (err, _) = error_of("inf.txt", "inf 0 0 0 0 0 0 1\n");
        assert!(matches!(
            err,
            TrajectoryError::NotFinite {
                line: 1,
                column: "timestamp",
                ..
            }
        ));
    }

    #[test]
    fn zero_quaternion() {
        let (err, msg) = error_of("zeroq.txt", "1 0 0 0 0 0 0 0\n");
        assert!(matches!(
            err,
            TrajectoryError::ZeroQuaternion { line: 1, .. }
        ));
        assert!(msg.contains("expected a non-zero quaternion"), "{msg}");
    }

    #[test]
    fn unsorted_and_duplicate_timestamps() {
        let (err, _) = error_of("unsorted.txt", "2 0 0 0 0 0 0 1\n\n1 0 0 0 0 0 0 1\n");
        assert!(matches!(
            err,
            TrajectoryError::UnsortedTimestamp { line: 3, .. }
        ));
        // A repeated timestamp keeps the later line's pose and is counted.
        let text = "1 0 0 0 0 0 0 1\n1 5 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n";
        let (t, duplicates) = parse_tum_lines(text, Path::new("dup.txt")).unwrap();
        assert_eq!(t.timestamps_secs(), &[1.0, 2.0]);
        assert_eq!(t.poses()[0].translation.vector.x, 5.0);
        assert_eq!(duplicates.lines, [2]);
    }

    #[test]
    fn empty_file() {
        let (err, _) = error_of("empty.txt", "");
        assert!(matches!(err, TrajectoryError::Empty { .. }));
        let (err, _) = error_of("comments.txt", "# only\n\n   \n");
        assert!(matches!(err, TrajectoryError::Empty { .. }));
    }

    #[test]
    fn unreadable_file() {
        let path = temp_path("does-not-exist.txt");
        let err = read_tum(&path).unwrap_err();
        assert!(matches!(err, TrajectoryError::Read { .. }));
        assert!(err.to_string().starts_with("cannot read trajectory file "));
        assert!(err.to_string().ends_with(&path.display().to_string()));
        // A folder is not a file either.
        let err = read_tum(std::env::temp_dir()).unwrap_err();
        assert!(matches!(err, TrajectoryError::Read { .. }));
    }
}
