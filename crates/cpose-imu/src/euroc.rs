//! The EuRoC MAV dataset layout (ASL format): `mav0/imu0/data.csv`,
//! `mav0/state_groundtruth_estimate0/data.csv`, `mav0/{cam0,imu0}/sensor.yaml`.
//!
//! Timestamps are integer nanoseconds; the ground-truth quaternion is stored `q_w q_x q_y q_z`
//! (real part first, unlike TUM files). The ground truth is the pose of the body (IMU) frame `S`
//! in the world frame `R`, so `world_from_body`; `T_BS` in `sensor.yaml` is `body_from_sensor`.

use std::path::{Path, PathBuf};

use cpose_core::Timestamp;
use cpose_core::geometry::{MAX_ROTATION_DEFECT, isometry_from_rows};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::DataError;

/// One row of `state_groundtruth_estimate0/data.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTruthState {
    /// Time of the state.
    pub stamp: Timestamp,
    /// Pose of the body (IMU) frame in the world frame.
    pub world_from_body: Isometry3<f64>,
    /// Velocity of the body in the world frame, m/s.
    pub lin_vel_world: Vector3<f64>,
    /// Gyroscope bias estimate, rad/s (body frame).
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias estimate, m/s² (body frame).
    pub accel_bias: Vector3<f64>,
}

/// One row of `imu0/data.csv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawImuSample {
    /// Time of the reading.
    pub stamp: Timestamp,
    /// Angular velocity in the IMU frame, rad/s.
    pub gyro: Vector3<f64>,
    /// Specific force in the IMU frame, m/s².
    pub accel: Vector3<f64>,
}

/// Noise densities from `imu0/sensor.yaml`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuNoise {
    /// Gyroscope white noise, rad/s/√Hz.
    pub gyro_noise_density: f64,
    /// Gyroscope bias random walk, rad/s²/√Hz.
    pub gyro_random_walk: f64,
    /// Accelerometer white noise, m/s²/√Hz.
    pub accel_noise_density: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_random_walk: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
}

/// A EuRoC sequence: ground truth, IMU readings and the rig calibration.
#[derive(Clone, Debug)]
pub struct EurocSequence {
    /// Ground-truth states, sorted by time.
    pub ground_truth: Vec<GroundTruthState>,
    /// IMU readings, sorted by time.
    pub imu: Vec<RawImuSample>,
    /// `T_BS` of `imu0`: `body_from_imu`.
    pub body_from_imu: Isometry3<f64>,
    /// `T_BS` of `cam0`: `body_from_cam` (OpenCV camera axes).
    pub body_from_cam: Isometry3<f64>,
    /// IMU noise parameters.
    pub imu_noise: ImuNoise,
}

impl EurocSequence {
    /// An error naming `key` and where EuRoC flights come from when `dir` is not a folder: the
    /// message for a config whose path points nowhere.
    pub fn check_folder(dir: &Path, key: &str) -> anyhow::Result<()> {
        if !dir.is_dir() {
            anyhow::bail!(
                "{key}: no EuRoC flight folder at {}: the EuRoC MAV flights (ASL format: mav0/ with \
                 state_groundtruth_estimate0/, imu0/, cam0/) come from ETH Zurich's EuRoC MAV \
                 dataset; an excerpt of V1_02 ships in ../shared/data/euroc/V1_02_excerpt. Set \
                 {key} to a flight's folder",
                dir.display()
            );
        }
        Ok(())
    }

    /// Loads a sequence from its folder (the one holding `mav0/`, or `mav0/` itself).
    pub fn load(dir: &Path) -> Result<Self, DataError> {
        let mav0 = if dir.join("mav0").is_dir() {
            dir.join("mav0")
        } else {
            dir.to_path_buf()
        };
        let file = |rel: &str| -> PathBuf { mav0.join(rel) };
        let gt_path = file("state_groundtruth_estimate0/data.csv");
        let ground_truth = read_ground_truth(&gt_path)?;
        let imu = read_imu(&file("imu0/data.csv"))?;
        let imu_yaml = read_sensor_yaml(&file("imu0/sensor.yaml"))?;
        let cam_yaml = read_sensor_yaml(&file("cam0/sensor.yaml"))?;
        let imu_noise = ImuNoise {
            gyro_noise_density: imu_yaml.number("gyroscope_noise_density")?,
            gyro_random_walk: imu_yaml.number("gyroscope_random_walk")?,
            accel_noise_density: imu_yaml.number("accelerometer_noise_density")?,
            accel_random_walk: imu_yaml.number("accelerometer_random_walk")?,
            rate_hz: imu_yaml.number("rate_hz")?,
        };
        Ok(Self {
            ground_truth,
            imu,
            body_from_imu: imu_yaml.t_bs()?,
            body_from_cam: cam_yaml.t_bs()?,
            imu_noise,
        })
    }
}

/// Splits a CSV line into `expected` numbers, or says which line and what was wrong.
fn numbers(
    path: &Path,
    line_no: usize,
    line: &str,
    expected: usize,
    header: &str,
) -> Result<Vec<f64>, DataError> {
    let values: Vec<&str> = line.split(',').map(str::trim).collect();
    if values.len() != expected {
        return Err(DataError::parse(
            path,
            line_no,
            format!(
                "expected {expected} comma-separated columns ({header}), got {}",
                values.len()
            ),
        ));
    }
    values
        .iter()
        .map(|v| match v.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(DataError::parse(
                path,
                line_no,
                format!("expected a finite number, got {v:?}"),
            )),
        })
        .collect()
}

/// Parses the integer-nanosecond first column exactly (an `f64` would lose the last digits).
fn stamp(path: &Path, line_no: usize, line: &str) -> Result<Timestamp, DataError> {
    let first = line.split(',').next().unwrap_or("").trim();
    first
        .parse::<i64>()
        .map(Timestamp::from_nanos)
        .map_err(|_| {
            DataError::parse(
                path,
                line_no,
                format!("expected an integer timestamp in nanoseconds, got {first:?}"),
            )
        })
}

/// Data lines (1-based number, text) of a CSV file, skipping `#` comments and blank lines;
/// checks that timestamps strictly increase.
fn csv_rows(path: &Path) -> Result<Vec<(usize, String)>, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let rows: Vec<(usize, String)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|(i, l)| (i + 1, l.to_owned()))
        .collect();
    if rows.is_empty() {
        return Err(DataError::parse(
            path,
            1,
            "expected at least one data row, the file has none".into(),
        ));
    }
    Ok(rows)
}

fn check_increasing(path: &Path, stamps: &[(usize, Timestamp)]) -> Result<(), DataError> {
    for w in stamps.windows(2) {
        if w[1].1 <= w[0].1 {
            let what = if w[1].1 == w[0].1 {
                "a duplicate"
            } else {
                "an earlier"
            };
            return Err(DataError::parse(
                path,
                w[1].0,
                format!(
                    "expected increasing timestamps, got {what} timestamp {} after {}",
                    w[1].1.as_nanos(),
                    w[0].1.as_nanos()
                ),
            ));
        }
    }
    Ok(())
}

/// Reads `state_groundtruth_estimate0/data.csv` (17 columns: ns, p xyz, q wxyz, v xyz, b_w xyz, b_a xyz).
pub fn read_ground_truth(path: &Path) -> Result<Vec<GroundTruthState>, DataError> {
    const HEADER: &str = "timestamp, p xyz, q wxyz, v xyz, b_w xyz, b_a xyz";
    let mut out = Vec::new();
    let mut stamps = Vec::new();
    for (line_no, line) in csv_rows(path)? {
        let v = numbers(path, line_no, &line, 17, HEADER)?;
        let t = stamp(path, line_no, &line)?;
        let q = Quaternion::new(v[4], v[5], v[6], v[7]);
        if q.norm() < 1e-6 {
            return Err(DataError::parse(
                path,
                line_no,
                "expected a unit quaternion q_w q_x q_y q_z, got a zero quaternion".into(),
            ));
        }
        out.push(GroundTruthState {
            stamp: t,
            world_from_body: Isometry3::from_parts(
                Translation3::new(v[1], v[2], v[3]),
                UnitQuaternion::from_quaternion(q),
            ),
            lin_vel_world: Vector3::new(v[8], v[9], v[10]),
            gyro_bias: Vector3::new(v[11], v[12], v[13]),
            accel_bias: Vector3::new(v[14], v[15], v[16]),
        });
        stamps.push((line_no, t));
    }
    check_increasing(path, &stamps)?;
    Ok(out)
}

/// Reads `imu0/data.csv` (7 columns: ns, ω xyz in rad/s, a xyz in m/s²).
pub fn read_imu(path: &Path) -> Result<Vec<RawImuSample>, DataError> {
    const HEADER: &str = "timestamp, w xyz, a xyz";
    let mut out = Vec::new();
    let mut stamps = Vec::new();
    for (line_no, line) in csv_rows(path)? {
        let v = numbers(path, line_no, &line, 7, HEADER)?;
        let t = stamp(path, line_no, &line)?;
        out.push(RawImuSample {
            stamp: t,
            gyro: Vector3::new(v[1], v[2], v[3]),
            accel: Vector3::new(v[4], v[5], v[6]),
        });
        stamps.push((line_no, t));
    }
    check_increasing(path, &stamps)?;
    Ok(out)
}

/// The few keys of a EuRoC `sensor.yaml` that cpose uses (a purpose-built reader for this flat
/// layout: `key: value` lines and the `T_BS: data: [...]` list, `#` comments).
pub struct SensorYaml {
    path: PathBuf,
    text: String,
}

/// Reads a `sensor.yaml`.
pub fn read_sensor_yaml(path: &Path) -> Result<SensorYaml, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    Ok(SensorYaml {
        path: path.to_path_buf(),
        text,
    })
}

impl SensorYaml {
    fn uncommented(&self) -> impl Iterator<Item = (usize, &str)> {
        self.text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("")))
    }

    /// The number after `key:` at the start of a line.
    pub fn number(&self, key: &str) -> Result<f64, DataError> {
        for (line_no, line) in self.uncommented() {
            if let Some(rest) = line
                .trim_start()
                .strip_prefix(key)
                .and_then(|r| r.trim_start().strip_prefix(':'))
            {
                return rest.trim().parse().map_err(|_| {
                    DataError::parse(
                        &self.path,
                        line_no,
                        format!("expected a number for {key}, got {:?}", rest.trim()),
                    )
                });
            }
        }
        Err(DataError::parse(
            &self.path,
            1,
            format!("expected a key {key:?}, found none"),
        ))
    }

    /// `T_BS` as an isometry (its 16 row-major values after `data:`).
    pub fn t_bs(&self) -> Result<Isometry3<f64>, DataError> {
        let start = self
            .uncommented()
            .find(|(_, l)| l.trim_start().starts_with("T_BS"))
            .map(|(n, _)| n);
        let Some(start) = start else {
            return Err(DataError::parse(
                &self.path,
                1,
                "expected a T_BS entry, found none".into(),
            ));
        };
        let mut collected = String::new();
        let mut inside = false;
        for (_, line) in self.uncommented().skip(start) {
            let mut l = line;
            if !inside {
                match l.find("data:") {
                    Some(i) => l = &l[i + 5..],
                    None => continue,
                }
                inside = true;
            }
            collected.push_str(l);
            if l.contains(']') {
                break;
            }
        }
        let values: Result<Vec<f64>, _> = collected
            .trim()
            .trim_start_matches('[')
            .split(']')
            .next()
            .unwrap_or("")
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect();
        let values = match values {
            Ok(v) if v.len() == 16 => v,
            _ => {
                return Err(DataError::parse(
                    &self.path,
                    start,
                    "expected T_BS data with 16 numbers (a row-major 4×4 matrix)".into(),
                ));
            }
        };
        isometry_from_rows(&values).map_err(|defect| {
            DataError::parse(
                &self.path,
                start,
                format!(
                    "expected T_BS with a rotation block (within {MAX_ROTATION_DEFECT} of one), \
                     got a matrix {defect:.2e} from it"
                ),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn excerpt() -> Option<PathBuf> {
        let dir = cpose_core::fs::shared_data_dir()?.join("euroc/V1_02_excerpt");
        dir.is_dir().then_some(dir)
    }

    #[test]
    fn reads_the_real_excerpt() {
        let Some(dir) = excerpt() else {
            eprintln!("skipped: shared data folder not found (set CPOSE_DATA_DIR)");
            return;
        };
        let seq = EurocSequence::load(&dir).unwrap();
        assert_eq!(seq.ground_truth.len(), 3340);
        assert_eq!(seq.imu.len(), 7999);
        let first = &seq.ground_truth[0];
        assert_eq!(first.stamp.as_nanos(), 1_403_715_524_922_140_000);
        // q_RS is stored w first: (0.161869, 0.790012, -0.205215, 0.554587).
        let q = first.world_from_body.rotation.quaternion();
        assert!((q.w - 0.161869).abs() < 1e-5 && (q.i - 0.790012).abs() < 1e-5);
        assert_eq!(
            seq.imu[0].gyro,
            Vector3::new(-0.0006981317, 0.0195476876, 0.0767944871)
        );
        assert!(seq.body_from_imu.translation.vector.norm() == 0.0);
        // cam0's T_BS: the camera sits about 6.5 cm along −y of the body, its z axis ≈ body z.
        assert!((seq.body_from_cam.translation.vector.y + 0.064676986768).abs() < 1e-12);
        assert!((seq.body_from_cam.rotation * Vector3::z() - Vector3::z()).norm() < 0.05);
        assert_eq!(seq.imu_noise.rate_hz, 200.0);
        assert_eq!(seq.imu_noise.gyro_noise_density, 1.6968e-04);
    }

    fn temp_file(name: &str, text: &str) -> PathBuf {
        let path = std::env::temp_dir().join(format!("cpose-euroc-{}-{name}", std::process::id()));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn malformed_files_name_the_line_and_the_expectation() {
        let wrong_cols = temp_file("cols.csv", "#header\n1,0.1,0.2,0.3,1,2\n");
        let err = read_imu(&wrong_cols).unwrap_err().to_string();
        assert!(
            err.contains("line 2 of") && err.contains("expected 7 comma-separated columns"),
            "{err}"
        );
        let nan = temp_file("nan.csv", "1,0.1,nan,0.3,1,2,3\n");
        let err = read_imu(&nan).unwrap_err().to_string();
        assert!(
            err.contains("line 1") && err.contains("finite number"),
            "{err}"
        );
        let unsorted = temp_file("unsorted.csv", "2,0,0,0,0,0,0\n2,0,0,0,0,0,0\n");
        let err = read_imu(&unsorted).unwrap_err().to_string();
        assert!(err.contains("line 2") && err.contains("duplicate"), "{err}");
        let missing = std::env::temp_dir().join("cpose-does-not-exist.csv");
        let err = read_imu(&missing).unwrap_err().to_string();
        assert!(err.contains("cpose-does-not-exist.csv"), "{err}");
        // A T_BS whose rotation block is scaled is refused, not re-orthonormalised.
        let yaml = temp_file(
            "sensor.yaml",
            "sensor_type: imu\nT_BS:\n  cols: 4\n  rows: 4\n  data: [2.0, 0.0, 0.0, 0.1,\n         \
             0.0, 1.0, 0.0, 0.0,\n         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\n",
        );
        let err = read_sensor_yaml(&yaml)
            .and_then(|y| y.t_bs())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("line 2") && err.contains("rotation block") && err.contains("3.00e0"),
            "{err}"
        );
        for p in [wrong_cols, nan, unsorted, yaml] {
            std::fs::remove_file(p).unwrap();
        }
    }
}
