//! Bounded fuzzing of every reader of text and binary files: a valid file per reader, mutated at
//! random (seeded, so a failure repeats) by flipped, replaced, deleted, inserted and repeated
//! bytes, truncation and hostile numbers. Every reader must return `Ok` or `Err` on every input,
//! never panic; a panic names the reader, the seed and the input's file, kept for a regression
//! case. Two thousand inputs per reader keep the whole run to seconds.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use cpose_core::Config;
use cpose_core::eval::{self, Trajectory};
use cpose_nerf::data::npy::NpyArray;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::util::temp_dir;

/// Mutated inputs per reader.
const CASES: u64 = 2000;

/// Numbers a mutation writes over a run of digits.
const HOSTILE: [&str; 10] = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e308",
    "-1e308",
    "99999999999999999999",
    "1e-320",
    "",
];

/// Applies one to four random mutations to `bytes`.
fn mutate(rng: &mut ChaCha8Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let len = out.len();
        let at = if len == 0 {
            0
        } else {
            rng.random_range(0..len)
        };
        match rng.random_range(0..7) {
            0 if len > 0 => out[at] ^= 1 << rng.random_range(0..8),
            1 if len > 0 => out[at] = rng.random(),
            2 if len > 0 => {
                let end = (at + rng.random_range(1..=16)).min(len);
                out.drain(at..end);
            }
            3 => {
                let n = rng.random_range(1..=8);
                let junk: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                out.splice(at..at, junk);
            }
            4 if len > 0 => {
                let end = (at + rng.random_range(1..=64)).min(len);
                let copy = out[at..end].to_vec();
                out.splice(end..end, copy);
            }
            5 => out.truncate(at),
            _ => {
                // A run of digits becomes a hostile number.
                if let Some(start) = (at..len).find(|&i| out[i].is_ascii_digit()) {
                    let end = (start..len)
                        .find(|&i| !(out[i].is_ascii_digit() || out[i] == b'.'))
                        .unwrap_or(len);
                    let word = HOSTILE[rng.random_range(0..HOSTILE.len())];
                    out.splice(start..end, word.bytes());
                }
            }
        }
    }
    out
}

/// Feeds `CASES` mutations of `seed_input` to `read`; a panic fails the test with the reader's
/// name, the case's seed and the input, written to a file that is kept.
fn fuzz(name: &str, seed_input: &[u8], read: impl Fn(&[u8])) {
    read(seed_input);
    for case in 0..CASES {
        let mut rng = ChaCha8Rng::seed_from_u64(case);
        let input = mutate(&mut rng, seed_input);
        if catch_unwind(AssertUnwindSafe(|| read(&input))).is_err() {
            let kept = std::env::temp_dir().join(format!("cpose-fuzz-{name}-{case}"));
            std::fs::write(&kept, &input).expect("the failing input is kept");
            panic!(
                "{name} panicked on case {case}; its input is {}",
                kept.display()
            );
        }
    }
}

/// A short trajectory with distinct times and turning orientations.
fn trajectory() -> Trajectory {
    let times: Vec<f64> = (0..6)
        .map(|i| 1_403_636_580.0 + 0.05 * f64::from(i))
        .collect();
    let poses = (0..6)
        .map(|i| {
            let a = 0.1 * f64::from(i);
            Isometry3::from_parts(
                Translation3::new(a, -a, 0.5 * a),
                UnitQuaternion::from_euler_angles(a, -0.5 * a, 0.2),
            )
        })
        .collect();
    Trajectory::new(times, poses).expect("increasing times")
}

#[test]
fn trajectory_readers_never_panic() {
    let path = Path::new("fuzz.txt");
    let trajectory = trajectory();
    let text = |bytes: &[u8]| String::from_utf8_lossy(bytes).into_owned();
    fuzz("tum", eval::to_tum_string(&trajectory).as_bytes(), |b| {
        let t = text(b);
        let _ = eval::parse_tum(&t, path);
        let _ = eval::TrajectoryFormat::detect(path, &t);
    });
    fuzz(
        "euroc",
        eval::to_euroc_string(&trajectory).as_bytes(),
        |b| {
            let _ = eval::parse_euroc(&text(b), path);
        },
    );
    fuzz(
        "kitti",
        eval::to_kitti_string(&trajectory).as_bytes(),
        |b| {
            let _ = eval::parse_kitti(&text(b), path);
        },
    );
    fuzz("times", b"0.0\n0.1\n0.2\n0.3\n", |b| {
        let _ = eval::parse_times(&text(b), path);
    });
}

#[test]
fn binary_readers_never_panic() {
    let dir = temp_dir("fuzz-binary");
    let npy = NpyArray::from_f64(&(0..34).map(f64::from).collect::<Vec<_>>())
        .reshaped(vec![2, 17])
        .unwrap();
    fuzz("npy", &npy.to_bytes(), |b| {
        let _ = NpyArray::parse(b);
    });
    let npy_file = dir.join("poses_bounds.npy");
    fuzz("npy_matrix", &npy.to_bytes(), |b| {
        std::fs::write(&npy_file, b).unwrap();
        let _ = cpose_nerf::data::llff::read_npy_f64_matrix(&npy_file, 17);
    });

    let npz_file = dir.join("events.npz");
    let xs = NpyArray::from_u16(&[1, 2, 3, 4]);
    let ts = NpyArray::from_f64(&[0.0, 0.1, 0.2, 0.3]);
    cpose_events::npz::write_npz(&npz_file, &[("x", &xs), ("t", &ts)]).unwrap();
    let npz = std::fs::read(&npz_file).unwrap();
    fuzz("npz", &npz, |b| {
        std::fs::write(&npz_file, b).unwrap();
        let _ = cpose_events::npz::read_npz(&npz_file);
    });

    let png_file = dir.join("depth.png");
    let depth =
        cpose_slam::data::DepthImage::new(8, 6, (0..48).map(|i| 0.5 + 0.01 * i as f32).collect())
            .unwrap();
    depth.save_png(&png_file, 1000.0).unwrap();
    let png = std::fs::read(&png_file).unwrap();
    fuzz("depth_png", &png, |b| {
        std::fs::write(&png_file, b).unwrap();
        let _ = cpose_slam::data::DepthImage::load_png(&png_file, 1000.0);
    });
}

#[test]
fn euroc_readers_never_panic() {
    let dir = temp_dir("fuzz-euroc");
    let file = dir.join("data.csv");
    let imu = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],\
               a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n\
               1403715273262142976,-0.0991,0.1264,0.0265,8.1932,-0.0408,-3.2854\n\
               1403715273267142912,-0.0949,0.1278,0.0223,8.1442,-0.0980,-3.3344\n\
               1403715273272143104,-0.0852,0.1320,0.0209,8.1523,-0.1552,-3.3181\n";
    fuzz("euroc_imu", imu.as_bytes(), |b| {
        std::fs::write(&file, b).unwrap();
        let _ = cpose_imu::euroc::read_imu(&file);
    });
    let truth = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], \
                 q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], \
                 b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], \
                 b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n\
                 1403715273262142976,0.878,2.142,0.947,0.060,-0.828,-0.058,-0.554,0.004,-0.001,\
                 0.004,-0.002,0.021,0.076,-0.012,0.105,0.093\n\
                 1403715273267142912,0.878,2.142,0.947,0.060,-0.828,-0.058,-0.554,0.004,-0.001,\
                 0.004,-0.002,0.021,0.076,-0.012,0.105,0.093\n";
    fuzz("euroc_ground_truth", truth.as_bytes(), |b| {
        std::fs::write(&file, b).unwrap();
        let _ = cpose_imu::euroc::read_ground_truth(&file);
    });
    let yaml = "sensor_type: imu\nrate_hz: 200\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, \
                0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n\
                gyroscope_noise_density: 1.6968e-04\n";
    fuzz("euroc_sensor_yaml", yaml.as_bytes(), |b| {
        std::fs::write(&file, b).unwrap();
        if let Ok(sensor) = cpose_imu::euroc::read_sensor_yaml(&file) {
            let _ = sensor.t_bs();
            let _ = sensor.number("rate_hz");
        }
    });
}

/// Configs: the default config of tasks whose check allocates nothing, mutated, then loaded,
/// looked up and checked as `cpose config check` does.
#[test]
fn config_checks_never_panic() {
    for task in ["nerf", "events", "trajectory"] {
        let registered = cpose_core::registry::find_task(task).unwrap();
        let text = format!(
            "{}\n{}",
            (registered.default_config)(),
            cpose_core::config::RUN_TABLE_DEFAULTS
        );
        fuzz(&format!("config_{task}"), text.as_bytes(), |b| {
            let config = Config::from_text("fuzz.toml", String::from_utf8_lossy(b));
            let Ok(run) = config.run_config() else { return };
            if let Ok(found) = cpose_core::registry::task_for(&config) {
                let _ = (found.check)(&config, &run);
            }
        });
    }
}

#[test]
fn colmap_readers_never_panic() {
    use cpose_nerf::data::colmap::{
        CameraModel, ColmapCamera, ColmapFormat, ColmapImage, ColmapModel, ColmapPoint,
        read_colmap_model, write_colmap_model,
    };
    let pose = |x: f64| {
        Isometry3::from_parts(
            Translation3::new(x, 0.5, -1.0),
            UnitQuaternion::from_euler_angles(0.1, 0.2 * x, -0.3),
        )
    };
    let model = ColmapModel {
        cameras: vec![
            ColmapCamera {
                id: 1,
                model: CameraModel::SimpleRadial,
                width: 64,
                height: 48,
                params: vec![50.0, 32.0, 24.0, 0.01],
            },
            ColmapCamera {
                id: 2,
                model: CameraModel::Pinhole,
                width: 64,
                height: 48,
                params: vec![50.0, 51.0, 32.0, 24.0],
            },
        ],
        images: Some(vec![
            ColmapImage {
                id: 1,
                camera_id: 1,
                name: "a.png".into(),
                world_from_camera: pose(0.0),
                points2d: vec![([10.0, 12.5], Some(7)), ([3.0, 4.0], None)],
            },
            ColmapImage {
                id: 2,
                camera_id: 2,
                name: "b.png".into(),
                world_from_camera: pose(1.0),
                points2d: vec![([20.0, 2.5], Some(7))],
            },
        ]),
        points: Some(vec![ColmapPoint {
            id: 7,
            xyz: [0.1, -0.2, 3.0],
            rgb: [200, 100, 50],
            error: 0.4,
            track: vec![(1, 0), (2, 0)],
        }]),
    };
    for (format, ext) in [(ColmapFormat::Binary, "bin"), (ColmapFormat::Text, "txt")] {
        let dir = temp_dir(&format!("fuzz-colmap-{ext}"));
        write_colmap_model(&dir, &model, format, false).unwrap();
        for part in ["cameras", "images", "points3D"] {
            let file = dir.join(format!("{part}.{ext}"));
            let valid = std::fs::read(&file).unwrap();
            fuzz(&format!("colmap_{part}_{ext}"), &valid, |b| {
                std::fs::write(&file, b).unwrap();
                let _ = read_colmap_model(&dir);
            });
            std::fs::write(&file, &valid).unwrap();
        }
    }
}
