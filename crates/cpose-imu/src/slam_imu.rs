//! Task `slam_imu`: RGB-D neural SLAM with an IMU (paper §3.4, its EuRoC table and the
//! supplement's IMU tables). Methods: NICE-SLAM's free pose (`baseline`), PoseNet relative to the
//! previous camera without IMU (`prev`, task `slam`'s; with `imu.velocity_start` its position
//! starts at the last interval's velocity) and started from the IMU's motion over
//! each frame interval (`prev_loose`, `prev_tight`, `prev_accel`, `prev_combined`;
//! [`crate::tracker::RelativeImu`], the primary family), and the experimental absolute PoseNet
//! with the IMU in tracking ([`crate::tracker::ImuPoseNet`]) as `none`, `loose`, `tight`,
//! `accel` or `combined`. A lost frame of an IMU method keeps its IMU-predicted start and is not
//! mapped ([`cpose_slam::slam::TrackReport::recovered`]).
//!
//! Data, either
//! * **`[euroc]`**: the synthetic room rendered along a real flight — a EuRoC sequence's ground
//!   truth, camera `cam0` on its real mount, placed in the room by [`fit_in_room`] — fused with
//!   that flight's **real** IMU readings (real noise, real bias; `bias = "estimate"` removes the
//!   bias estimated over the flight's stationary start, `"ground_truth"` the ground-truth state's
//!   estimate instead, `"raw"` keeps it; `imu.bias_refine` refines the gyroscope's online,
//!   scored against the ground truth's in `metrics.json`); or
//! * any RGB-D sequence of task `slam` (`[data]`) with an IMU simulated from its ground truth as
//!   the paper's ScanNet protocol ([`crate::sim::imu_from_poses`]; `[imu_sim]`), the camera being
//!   the body; `data.stride` then makes the camera slower than the IMU (30 Hz → 5 Hz with 6).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use cpose_core::registry::{Task, TaskInput};
use cpose_core::{Config, RunConfig, gravity_world};
use cpose_slam::data::{RgbdSequence, read_replica};
use cpose_slam::map::MapConfig;
use cpose_slam::slam::{MappingConfig, TrackingConfig};
use cpose_slam::synth::{RoomConfig, fit_in_room, render_room};
use cpose_slam::task::{
    BoundsConfig, DataConfig, MeshConfig, ModelFactory, SlamConfig, SlamSetup, Source,
    ensure_generated, frame_range, open_sequence, run_methods,
};
use cpose_slam::track::{FreePose, PoseModel, PoseNetTrackConfig};
use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use crate::bias::{BiasRemoval, body_readings, gyro_bias_left};
use crate::euroc::EurocSequence;
use crate::sim::{NoiseModel, imu_from_poses};
use crate::tracker::{ImuPoseNet, ImuTrackConfig, RelativeImu};
use crate::{ImuMode, ImuSample};

inventory::submit! {
    Task {
        name: "slam_imu",
        about: "RGB-D neural SLAM with an IMU (paper §3.4): PoseNet tracking with loose, tight and accelerometer coupling vs none and NICE-SLAM's free pose",
        default_config: || {
            [include_str!("../defaults/slam_imu.toml"), &cpose_slam::task::default_tables()].join("\n")
        },
        check: |config, run| Settings::new(config, run).map(drop),
        run,
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    data: DataConfig,
    #[serde(default)]
    synthetic: RoomConfig,
    euroc: Option<EurocConfig>,
    #[serde(default)]
    imu_sim: ImuSimConfig,
    #[serde(default)]
    imu: ImuTrackConfig,
    #[serde(default)]
    bounds: BoundsConfig,
    #[serde(default)]
    map: MapConfig,
    #[serde(default)]
    tracking: TrackingConfig,
    #[serde(default)]
    mapping: MappingConfig,
    #[serde(default)]
    posenet: PoseNetTrackConfig,
    #[serde(default)]
    mesh: MeshConfig,
    slam: SlamConfig<Method>,
}

/// The room along a real EuRoC flight with its real IMU.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct EurocConfig {
    /// The sequence folder (holding `mav0/`).
    path: PathBuf,
    /// `"estimate"` (default): readings minus the biases estimated over the flight's stationary
    /// start ([`crate::bias::bias_at_rest`]); `"ground_truth"`: minus the ground-truth state's estimate (an
    /// ablation: no user has it); `"raw"`: as measured.
    #[serde(default)]
    bias: BiasRemoval,
    /// Longest allowed gap between readings while the frames run, seconds.
    #[serde(default = "default_max_gap")]
    max_gap_secs: f64,
}

fn default_max_gap() -> f64 {
    0.05
}

/// The IMU simulated from a sequence's ground truth (without `[euroc]`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ImuSimConfig {
    /// Readings per second (the paper: 200), at most 10 kHz.
    rate_hz: f64,
    /// White noise and bias random walk of EuRoC's ADIS16448 (`sensor.yaml` densities).
    noise: bool,
}

impl Default for ImuSimConfig {
    fn default() -> Self {
        Self {
            rate_hz: 200.0,
            noise: true,
        }
    }
}

/// The noise densities of EuRoC's ADIS16448 (`imu0/sensor.yaml`), for simulated readings.
const ADIS16448: NoiseModel = NoiseModel {
    gyro_noise_density: 1.6968e-4,
    gyro_random_walk: 1.9393e-5,
    accel_noise_density: 2.0e-3,
    accel_random_walk: 3.0e-3,
    initial_gyro_bias: Vector3::new(0.0, 0.0, 0.0),
    initial_accel_bias: Vector3::new(0.0, 0.0, 0.0),
};

/// A tracking method, by its key in configs and `metrics.json`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
enum Method {
    Baseline,
    Prev,
    /// `prev` with the gyroscope's rotation over each frame interval ([`RelativeImu`]).
    PrevLoose,
    /// `prev` with the gyroscope on the rate of its increments.
    PrevTight,
    /// `prev` with the accelerometer's displacement over each frame interval.
    PrevAccel,
    /// `prev_tight` and `prev_accel`.
    PrevCombined,
    /// The absolute PoseNet with the IMU in tracking ([`ImuPoseNet`]).
    Imu(ImuMode),
}

impl Method {
    const ALL: [Method; 11] = [
        Method::Baseline,
        Method::Prev,
        Method::PrevLoose,
        Method::PrevTight,
        Method::PrevAccel,
        Method::PrevCombined,
        Method::Imu(ImuMode::None),
        Method::Imu(ImuMode::Loose),
        Method::Imu(ImuMode::Tight),
        Method::Imu(ImuMode::Accel),
        Method::Imu(ImuMode::Combined),
    ];

    fn key(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Prev => "prev",
            Method::PrevLoose => "prev_loose",
            Method::PrevTight => "prev_tight",
            Method::PrevAccel => "prev_accel",
            Method::PrevCombined => "prev_combined",
            Method::Imu(mode) => mode.key(),
        }
    }
}

impl TryFrom<String> for Method {
    type Error = String;

    fn try_from(name: String) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.key() == name)
            .ok_or_else(|| {
                let known: Vec<_> = Method::ALL.iter().map(|m| m.key()).collect();
                format!(
                    "unknown method {name:?}; known methods: {}",
                    known.join(", ")
                )
            })
    }
}

/// Frames, IMU readings on the frames' clock, the camera's mount and gravity in the world; the
/// gyroscope's bias random walk (rad/s²/√Hz) and the bias its readings hold at the last frame,
/// where known (rad/s, body frame).
struct ImuRgbd {
    seq: RgbdSequence,
    imu: Vec<ImuSample>,
    body_from_camera: Isometry3<f64>,
    gravity: Vector3<f64>,
    gyro_random_walk: f64,
    gyro_bias_left: Option<Vector3<f64>>,
}

/// Bumped whenever the rendering of a flight through the room changes.
const GENERATOR_VERSION: &str = "room along a EuRoC flight v1";

/// The room along the EuRoC flight of `config`, rendered into `data.path` on first use.
fn euroc_room(
    config: &EurocConfig,
    data: &DataConfig,
    room: &RoomConfig,
    input: &TaskInput,
) -> anyhow::Result<ImuRgbd> {
    if room.trajectory.is_some() {
        bail!("[synthetic] trajectory cannot be combined with [euroc]: the flight is the motion");
    }
    EurocSequence::check_folder(&config.path, "euroc.path")?;
    let seq = EurocSequence::load(&config.path)?;
    let gt = &seq.ground_truth;
    if gt.len() < 2 || seq.imu.len() < 2 {
        bail!(
            "{}: the ground truth and the IMU need at least two entries each",
            config.path.display()
        );
    }
    // The frames' clock starts at the first ground-truth pose plus the offset.
    let origin = gt[0].stamp;
    let gt_times: Vec<f64> = gt.iter().map(|s| s.stamp.secs_since(origin)).collect();
    let start = room.trajectory_offset_s;
    let imu_end = seq.imu[seq.imu.len() - 1].stamp.secs_since(origin);
    let end = gt_times[gt_times.len() - 1].min(imu_end);
    let frame_times: Vec<f64> = (0..room.frames)
        .map(|k| start + k as f64 / room.frame_rate)
        .take_while(|&t| t <= end)
        .collect();
    if frame_times.len() < 2 {
        bail!(
            "{}: the flight's ground truth and IMU overlap for {end:.1} s, fewer than two frames \
             after trajectory_offset_s = {start}",
            config.path.display()
        );
    }
    let body_at = |t: f64| {
        let k = gt_times
            .partition_point(|&x| x <= t)
            .clamp(1, gt_times.len() - 1);
        let s = ((t - gt_times[k - 1]) / (gt_times[k] - gt_times[k - 1])).clamp(0.0, 1.0);
        gt[k - 1]
            .world_from_body
            .lerp_slerp(&gt[k].world_from_body, s)
    };
    let body_from_camera = seq.body_from_cam;
    let cameras: Vec<Isometry3<f64>> = frame_times
        .iter()
        .map(|&t| body_at(t) * body_from_camera)
        .collect();
    let positions: Vec<Vector3<f64>> = cameras.iter().map(|c| c.translation.vector).collect();
    let (room_from_world, clearance) = fit_in_room(&positions, room.scale);
    if clearance < 0.05 {
        bail!(
            "{}: the flight does not fit in the synthetic room (the best placement passes {:.2} \
             m from a surface); shorten it with synthetic.frames",
            config.path.display(),
            clearance
        );
    }
    let cameras: Vec<Isometry3<f64>> = cameras.iter().map(|c| room_from_world * c).collect();
    // The rendered cameras themselves name the flight (not its path, which may be spelt
    // differently for the same flight).
    let mut fingerprint = crc32fast::Hasher::new();
    for c in &cameras {
        for v in c.translation.vector.iter().chain(c.rotation.coords.iter()) {
            fingerprint.update(&v.to_le_bytes());
        }
    }
    let recipe = serde_json::json!({
        "generator": GENERATOR_VERSION,
        "synthetic": room,
        "cameras_crc32": format!("{:08x}", fingerprint.finalize()),
        "frames": cameras.len(),
        "room_from_world": [
            room_from_world.translation.vector.as_slice(),
            room_from_world.rotation.coords.as_slice(),
        ],
    });
    ensure_generated(
        &data.path,
        &recipe,
        cameras.len(),
        input,
        |staging, on_frame| render_room(room, &cameras, staging, on_frame),
    )?;
    input.run_dir.log(format_args!(
        "{}: {} frames at {} Hz from {start} s; placed in the room {:.2} m clear of every surface",
        config.path.display(),
        cameras.len(),
        room.frame_rate,
        clearance
    ));
    let rgbd = read_replica(&data.path, None, data.resolution, room.frame_rate)?;
    let (readings, note) =
        body_readings(&seq, config.bias).with_context(|| format!("{}", config.path.display()))?;
    if let Some(note) = note {
        input.run_dir.log(note);
    }
    // On the frames' clock.
    let imu: Vec<ImuSample> = readings
        .into_iter()
        .map(|s| ImuSample {
            t_secs: s.t_secs - start,
            ..s
        })
        .collect();
    check_coverage(
        &imu,
        &rgbd.times()[..cameras.len().min(rgbd.len())],
        config.max_gap_secs,
    )
    .with_context(|| format!("{}", config.path.join("mav0/imu0/data.csv").display()))?;
    let last = frame_times[frame_times.len() - 1];
    Ok(ImuRgbd {
        seq: rgbd,
        imu,
        body_from_camera,
        gravity: room_from_world.rotation * gravity_world(),
        gyro_random_walk: seq.imu_noise.gyro_random_walk,
        gyro_bias_left: Some(gyro_bias_left(&seq, config.bias, last)),
    })
}

/// The IMU readings must span the frames without a gap longer than `max_gap` seconds.
fn check_coverage(imu: &[ImuSample], frame_times: &[f64], max_gap: f64) -> anyhow::Result<()> {
    let (Some(first), Some(last)) = (frame_times.first(), frame_times.last()) else {
        return Ok(());
    };
    let (Some(a), Some(b)) = (imu.first(), imu.last()) else {
        bail!("no IMU readings");
    };
    if a.t_secs > *first || b.t_secs < *last {
        bail!(
            "the IMU readings cover {:.3}–{:.3} s of the frames' clock, but the frames run from \
             {first:.3} to {last:.3} s",
            a.t_secs,
            b.t_secs
        );
    }
    let lo = imu.partition_point(|s| s.t_secs <= *first).max(1) - 1;
    let hi = imu.partition_point(|s| s.t_secs < *last) + 1;
    if let Some(w) = imu[lo..hi.min(imu.len())]
        .windows(2)
        .find(|w| w[1].t_secs - w[0].t_secs > max_gap)
    {
        bail!(
            "the IMU readings have a gap of {:.3} s at {:.3} s (frames' clock), longer than \
             max_gap_secs = {max_gap}",
            w[1].t_secs - w[0].t_secs,
            w[0].t_secs
        );
    }
    Ok(())
}

/// Any RGB-D sequence with the IMU simulated from its ground truth (the camera is the body).
/// The fastest simulated IMU, Hz (real IMUs run at a few hundred to a few thousand).
const MAX_IMU_RATE_HZ: f64 = 10_000.0;

fn simulated(exp: &Experiment, input: &TaskInput) -> anyhow::Result<ImuRgbd> {
    check_imu_rate(exp.imu_sim.rate_hz)?;
    let seq = open_sequence(&exp.data, &exp.synthetic, input)?;
    let times = seq.times();
    let poses: Vec<Isometry3<f64>> = seq
        .truth
        .iter()
        .enumerate()
        .map(|(i, p)| {
            p.with_context(|| {
                format!(
                    "{}: frame {i} has no ground-truth pose; simulating an IMU needs one for \
                     every frame (use data.frames to stop before it)",
                    seq.root.display()
                )
            })
        })
        .collect::<anyhow::Result<_>>()?;
    let gravity = gravity_world();
    let noise = exp.imu_sim.noise.then_some(&ADIS16448);
    let simulated = imu_from_poses(
        &times,
        &poses,
        exp.imu_sim.rate_hz,
        &gravity,
        noise,
        input.run.seed,
    )
    .with_context(|| {
        format!(
            "{}: cannot simulate an IMU at imu_sim.rate_hz = {} from {} frames with increasing \
             timestamps",
            seq.root.display(),
            exp.imu_sim.rate_hz,
            times.len()
        )
    })?;
    // The bias of the reading nearest the last frame (the readings keep it: nothing removes it).
    let last = times[times.len() - 1];
    let k = simulated
        .samples
        .partition_point(|s| s.t_secs < last)
        .min(simulated.samples.len() - 1);
    let gyro_bias_left = simulated.gyro_bias.get(k).copied();
    let imu = simulated.samples;
    input.run_dir.log(format_args!(
        "IMU simulated from the ground truth: {} readings at {} Hz{}",
        imu.len(),
        exp.imu_sim.rate_hz,
        if noise.is_some() {
            " with ADIS16448 noise"
        } else {
            ", exact"
        }
    ));
    Ok(ImuRgbd {
        seq,
        imu,
        body_from_camera: Isometry3::identity(),
        gravity,
        gyro_random_walk: noise.map_or(0.0, |n| n.gyro_random_walk),
        gyro_bias_left,
    })
}

/// The whole config, decoded and checked before any frame or IMU reading is read or made.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    setup: SlamSetup,
}

impl Settings {
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        if exp.slam.methods.is_empty() {
            bail!(
                "slam.methods is empty: name at least one of baseline, prev, prev_loose, \
                 prev_tight, prev_accel, prev_combined, none, loose, tight, accel, combined"
            );
        }
        exp.imu.validate()?;
        if exp.euroc.is_some() || exp.data.source == Source::Synthetic {
            exp.synthetic.check(config)?;
        }
        if exp.euroc.is_none() {
            check_imu_rate(exp.imu_sim.rate_hz)?;
        }
        let setup = SlamSetup::new(
            run,
            exp.map.clone(),
            exp.tracking.clone(),
            exp.mapping.clone(),
            &exp.bounds,
            &exp.mesh,
        )?;
        Ok(Self { exp, setup })
    }
}

/// `[imu_sim] rate_hz`, checked.
fn check_imu_rate(rate_hz: f64) -> anyhow::Result<()> {
    if !(rate_hz > 0.0 && rate_hz <= MAX_IMU_RATE_HZ) {
        bail!("[imu_sim] rate_hz = {rate_hz}: expected a rate in (0, {MAX_IMU_RATE_HZ}] Hz");
    }
    Ok(())
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let Settings { exp, mut setup } = Settings::new(input.config, input.run)?;
    let data = match &exp.euroc {
        Some(euroc) => euroc_room(euroc, &exp.data, &exp.synthetic, input)?,
        None => simulated(&exp, input)?,
    };
    setup.body_from_camera = data.body_from_camera;
    let seq = data.seq.every(exp.data.stride);
    let n = exp.data.frames_of(seq.len());
    let range = frame_range(&seq, n)?;
    input.run_dir.log(format_args!(
        "{} frames at {:.1} Hz against {} IMU readings",
        n,
        (n - 1) as f64 / range.duration_secs(),
        data.imu.len()
    ));
    let (posenet, imu_config, seed) = (&exp.posenet, &exp.imu, input.run.seed);
    let (imu, gravity, pixels) = (&data.imu, data.gravity, setup.tracking.pixels);
    let (random_walk, bias_left) = (data.gyro_random_walk, data.gyro_bias_left);
    let (lr, factor) = (setup.tracking.lr, setup.tracking.rotation_lr_factor);
    let frame_times = &seq.times();
    let methods: Vec<(String, ModelFactory)> = exp
        .slam
        .methods
        .iter()
        .map(|&method| {
            let factory: ModelFactory = match method {
                Method::Baseline => {
                    Box::new(move || Ok(Box::new(FreePose::new(lr, factor)) as Box<dyn PoseModel>))
                }
                Method::Prev
                | Method::PrevLoose
                | Method::PrevTight
                | Method::PrevAccel
                | Method::PrevCombined => {
                    let mode = match method {
                        Method::PrevTight => ImuMode::Tight,
                        Method::PrevAccel => ImuMode::Accel,
                        Method::PrevCombined => ImuMode::Combined,
                        Method::PrevLoose => ImuMode::Loose,
                        _ => ImuMode::None,
                    };
                    Box::new(move || {
                        Ok(Box::new(
                            RelativeImu::new(
                                posenet,
                                imu_config,
                                mode,
                                imu.clone(),
                                gravity,
                                frame_times.clone(),
                                pixels,
                                range,
                                seed,
                                random_walk,
                            )?
                            .with_bias_truth(bias_left),
                        ) as _)
                    })
                }
                Method::Imu(mode) => Box::new(move || {
                    Ok(Box::new(ImuPoseNet::new(
                        posenet,
                        imu_config,
                        mode,
                        imu.clone(),
                        gravity,
                        pixels,
                        range,
                        seed,
                    )?) as _)
                }),
            };
            (method.key().to_string(), factory)
        })
        .collect();
    run_methods(input, &seq, n, &setup, &methods)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show slam_imu` states the defaults: its values are those of a config with
    /// only the keys that have none.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"slam_imu\"\n[data]\nsource = \"synthetic\"\n\
                        path = \"data/synthetic_room\"\n[slam]\n\
                        methods = [\"baseline\", \"prev\", \"prev_loose\", \"prev_tight\", \"prev_combined\"]\n";
        cpose_core::testing::check_default_config("slam_imu", required, Settings::new);
    }

    fn readings(times: &[f64]) -> Vec<ImuSample> {
        times
            .iter()
            .map(|&t| ImuSample {
                t_secs: t,
                gyro: Vector3::zeros(),
                accel: Vector3::zeros(),
            })
            .collect()
    }

    #[test]
    fn imu_must_cover_the_frames_without_long_gaps() {
        let dense: Vec<f64> = (0..=200).map(|k| k as f64 * 0.005).collect();
        assert!(check_coverage(&readings(&dense), &[0.0, 0.5, 1.0], 0.05).is_ok());
        let late = check_coverage(&readings(&dense[10..]), &[0.0, 0.5, 1.0], 0.05)
            .unwrap_err()
            .to_string();
        assert!(late.contains("cover 0.050–1.000 s"), "{late}");
        let mut gappy = dense.clone();
        gappy.retain(|&t| !(0.3..0.4).contains(&t));
        let gap = check_coverage(&readings(&gappy), &[0.0, 0.5, 1.0], 0.05)
            .unwrap_err()
            .to_string();
        assert!(gap.contains("gap of 0.105 s at 0.295 s"), "{gap}");
        // A gap outside the frames' span is harmless.
        assert!(check_coverage(&readings(&gappy), &[0.5, 1.0], 0.05).is_ok());
    }

    #[test]
    fn methods_parse_as_the_paper_names_them() {
        #[derive(Deserialize)]
        struct M {
            m: Vec<Method>,
        }
        let m: M = toml::from_str(
            r#"m = ["baseline", "prev", "prev_loose", "prev_combined", "none", "tight", "combined"]"#,
        )
        .expect("valid");
        let keys: Vec<&str> = m.m.iter().map(|m| m.key()).collect();
        assert_eq!(
            keys,
            [
                "baseline",
                "prev",
                "prev_loose",
                "prev_combined",
                "none",
                "tight",
                "combined"
            ]
        );
        assert!(toml::from_str::<M>(r#"m = ["tite"]"#).is_err());
    }
}
