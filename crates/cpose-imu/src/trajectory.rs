//! Task `trajectory`: fit pose fields to a trajectory from poses at a subset of its timestamps,
//! optionally supervised by the gyroscope (integrated over windows, or through the fields' `q̇`)
//! and the accelerometer (through `p̈`), and report the pose error at every held-out timestamp.
//!
//! Sources: a built-in synthetic hand-held motion (exact IMU from its analytic derivatives), a
//! TUM trajectory file, or a EuRoC sequence (real IMU, the bias estimated over the flight's
//! stationary start removed; `[data] bias`). Every pose
//! field named in `[fields.NAME]` is fitted once per IMU mode; slerp/linear interpolation of the
//! known poses is the reference (`interp`).
//!
//! Every field is fitted by `cpose_core::fit` in its normalised frame (rotated to the mean known
//! orientation, centred and scaled so that PoseNet's tanh-bounded translation fits); errors are
//! reported in degrees and metres of the original world.
//!
//! Besides `traj_<imu>_<method>.txt`, every unit draws `trajectory_<imu>_<method>.png` (the
//! estimate against the truth and the known poses, evo_traj's layout) and
//! `errors_<imu>_<method>.png` (its rotation and position errors at the held-out poses over
//! time, beside those of the reference: slerp and linear interpolation of the known poses).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, bail};
use cpose_core::config::Config;
use cpose_core::eval::{self, Sim3, Trajectory};
use cpose_core::fit::{self, Fit, FitData, FitReport, FitSettings, normalising_frame};
use cpose_core::nn::StopRule;
use cpose_core::plot::{self, Line, Panel, SeriesStyle, TrajectorySeries, YScale};
use cpose_core::pose_field::saved::SavedPoseField;
use cpose_core::pose_field::sinusoid::SinusoidMotion;
use cpose_core::registry::{self, FieldContext, Task, TaskInput, build_pose_field};
use cpose_core::study::{Metrics, Study, Unit, UnitKey};
use cpose_core::{Order, PoseBatch, PoseField, TimeRange};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::bias::{BiasRemoval, body_readings};
use crate::euroc::EurocSequence;
use crate::{ImuMode, ImuSample};
use cpose_core::gravity_world;

inventory::submit! {
    Task {
        name: "trajectory",
        about: "fit pose fields to a trajectory from a subset of its poses (optionally with gyro/accel) and score held-out poses",
        default_config: || include_str!("../defaults/trajectory.toml").to_owned(),
        check: |config, _| Settings::new(config).map(drop),
        run,
    }
}

/// The config file of the task.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    data: DataConfig,
    #[serde(default)]
    fit: FitConfig,
    /// Pose fields by name; each table is decoded by the pose-field registry.
    fields: BTreeMap<String, serde::de::IgnoredAny>,
}

/// Where the trajectory comes from.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum Source {
    /// The built-in hand-held-like motion with exact IMU readings.
    Synthetic,
    /// A TUM trajectory file (`timestamp tx ty tz qx qy qz qw`); no IMU.
    Tum,
    /// A EuRoC sequence folder (ground truth and the real IMU).
    Euroc,
}

/// The most samples (poses or IMU readings) the synthetic source generates: ten million, some
/// 14 hours at 200 Hz.
const MAX_SYNTHETIC_SAMPLES: usize = 10_000_000;

/// `[data]`: the trajectory and which of its poses supervise the fit.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DataConfig {
    /// `"synthetic"`, `"tum"` or `"euroc"`.
    source: Source,
    /// TUM file or EuRoC folder (relative paths are relative to the current directory).
    path: Option<PathBuf>,
    /// Synthetic only: length of the motion, seconds (default 10).
    #[serde(default = "default_duration")]
    duration_secs: f64,
    /// Synthetic only: pose sample rate, Hz (default 100).
    #[serde(default = "default_pose_rate")]
    pose_rate_hz: f64,
    /// Synthetic only: IMU sample rate, Hz (default 200).
    #[serde(default = "default_imu_rate")]
    imu_rate_hz: f64,
    /// Crop: first time used, seconds after the first pose (default 0).
    #[serde(default)]
    start_secs: f64,
    /// Crop: length used, seconds (default: to the end).
    crop_secs: Option<f64>,
    /// Keep every N-th pose as supervision; the others are held out (default 20).
    #[serde(default = "default_known_every")]
    known_every: usize,
    /// EuRoC only: how the IMU bias is removed, `"estimate"` (default, from the flight's
    /// stationary start), `"ground_truth"` (an ablation) or `"raw"` ([`BiasRemoval`]).
    #[serde(default)]
    bias: BiasRemoval,
}

impl DataConfig {
    /// The synthetic source's rates and duration, checked before anything is allocated.
    fn check_synthetic(&self, config: &Config) -> anyhow::Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.duration_secs)
            && positive(self.pose_rate_hz)
            && positive(self.imu_rate_hz))
        {
            bail!(
                "{}: [data] duration_secs = {}, pose_rate_hz = {} and imu_rate_hz = {} must be \
                 positive finite numbers",
                config.path().display(),
                self.duration_secs,
                self.pose_rate_hz,
                self.imu_rate_hz
            );
        }
        let samples = self.duration_secs * self.pose_rate_hz.max(self.imu_rate_hz);
        if samples > MAX_SYNTHETIC_SAMPLES as f64 {
            bail!(
                "{}: [data] duration_secs × the larger of pose_rate_hz and imu_rate_hz is \
                 {samples:.3e} samples; at most {MAX_SYNTHETIC_SAMPLES} are generated",
                config.path().display()
            );
        }
        Ok(())
    }
}

fn default_duration() -> f64 {
    10.0
}
fn default_pose_rate() -> f64 {
    100.0
}
fn default_imu_rate() -> f64 {
    200.0
}
fn default_known_every() -> usize {
    20
}

/// `[fit]`: optimisation shared by every field.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct FitConfig {
    /// The step budget of a fit (scaled by `[run] iterations_scale`); it stops sooner on the
    /// tolerance or a plateau ([`StopRule`]).
    iterations: usize,
    /// A fit has converged when its mean errors on the known poses are within both.
    tolerance_deg: f64,
    tolerance_m: f64,
    /// Steps between convergence checks; a plateau is `plateau_steps` without a window whose
    /// mean loss is `plateau_rel` below the best. At a plateau the learning rates fall by
    /// `lr_factor`, up to `lr_drops` times; the next plateau ends the fit ([`StopRule`]).
    check_every: usize,
    plateau_steps: usize,
    plateau_rel: f64,
    lr_factor: f64,
    lr_drops: usize,
    /// IMU modes to compare: `"none"`, `"loose"`, `"tight"`, `"accel"`, `"combined"`.
    imu: Vec<ImuMode>,
    /// The `[fields.<name>]` to fit (default: all of them).
    fields: Option<Vec<String>>,
    /// Weight of the pose loss (squared error of quaternions and of normalised positions: about
    /// 1e-4 at 1° of rotation error). Against the L1 gyro residual of real data (about 0.1 rad/s
    /// of noise and vibration) a weight near 1000 balances the two; exact IMU readings want 1.
    pose_weight: f64,
    /// Weight of the gyroscope loss (paper: 1).
    gyro_weight: f64,
    /// Weight of the accelerometer loss (paper: 1).
    accel_weight: f64,
    /// IMU samples per step (a seeded shuffle is cycled through); for `loose`, windows per step.
    imu_batch: usize,
    /// Length of the windows the gyroscope is integrated over in `loose` mode, seconds.
    loose_window_secs: f64,
    /// Initial learning rate of translation parameters (paper: 1e-3).
    lr_translation: f64,
    /// Initial learning rate of rotation parameters (paper: 2e-4).
    lr_rotation: f64,
    /// Initial learning rate of joint pose parameters (splines, per-frame poses).
    lr_pose: f64,
}

impl Default for FitConfig {
    fn default() -> Self {
        let s = FitSettings::default();
        Self {
            iterations: s.iterations,
            tolerance_deg: s.tolerance_deg,
            tolerance_m: s.tolerance_m,
            check_every: s.stop.check_every,
            plateau_steps: s.stop.plateau_steps,
            plateau_rel: s.stop.plateau_rel,
            lr_factor: s.stop.lr_factor,
            lr_drops: s.stop.lr_drops,
            imu: vec![ImuMode::None, ImuMode::Tight],
            fields: None,
            pose_weight: s.pose_weight,
            gyro_weight: s.gyro_weight,
            accel_weight: s.accel_weight,
            imu_batch: s.imu_batch,
            loose_window_secs: s.loose_window_secs,
            lr_translation: s.lr_translation,
            lr_rotation: s.lr_rotation,
            lr_pose: s.lr_pose,
        }
    }
}

impl FitConfig {
    /// The fit's settings with a budget of `iterations` steps.
    fn settings(&self, iterations: usize) -> FitSettings {
        FitSettings {
            iterations,
            tolerance_deg: self.tolerance_deg,
            tolerance_m: self.tolerance_m,
            stop: StopRule {
                check_every: self.check_every,
                plateau_steps: self.plateau_steps,
                plateau_rel: self.plateau_rel,
                lr_factor: self.lr_factor,
                lr_drops: self.lr_drops,
            },
            pose_weight: self.pose_weight,
            gyro_weight: self.gyro_weight,
            accel_weight: self.accel_weight,
            imu_batch: self.imu_batch,
            loose_window_secs: self.loose_window_secs,
            lr_translation: self.lr_translation,
            lr_rotation: self.lr_rotation,
            lr_pose: self.lr_pose,
        }
    }

    /// Errors naming the key of a setting out of range.
    fn validate(&self) -> Result<(), String> {
        self.settings(self.iterations).validate()
    }
}

/// A trajectory cropped to the fitted range, times in seconds since its first known pose.
struct Sequence {
    /// What loading found worth a line in the log.
    note: Option<String>,
    /// Absolute time of `t = 0` (for TUM output).
    origin_secs: f64,
    times: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
    /// Indices of the supervising poses (every `known_every`-th, first and last included).
    known: Vec<usize>,
    /// Their times.
    known_times: Vec<f64>,
    imu: Vec<ImuSample>,
}

/// A whole trajectory as read: absolute time of `t = 0`, times, poses and IMU readings.
struct Loaded {
    origin_secs: f64,
    times: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
    imu: Vec<ImuSample>,
    /// What loading found worth a line in the log (the estimated IMU bias).
    note: Option<String>,
}

fn load(config: &Config, data: &DataConfig, seed: u64) -> anyhow::Result<Loaded> {
    let path = || -> anyhow::Result<&PathBuf> {
        data.path.as_ref().with_context(|| {
            format!(
                "{}: [data] source = {:?} needs a `path`",
                config.path().display(),
                data.source
            )
        })
    };
    Ok(match data.source {
        Source::Synthetic => {
            data.check_synthetic(config)?;
            let range = TimeRange::new(0.0, data.duration_secs).context("duration_secs")?;
            let motion = SinusoidMotion::<f64>::handheld(range, seed);
            let sample = |rate: f64| -> Vec<f64> {
                let n = (data.duration_secs * rate).floor() as usize + 1;
                (0..n)
                    .map(|k| (k as f64 / rate).min(data.duration_secs))
                    .collect()
            };
            let times = sample(data.pose_rate_hz);
            let mut out = PoseBatch::default();
            motion.evaluate(&times, Order::Pose, &mut out)?;
            let poses = (0..times.len()).map(|i| out.world_from_body(i)).collect();
            let imu_times = sample(data.imu_rate_hz);
            motion.evaluate(&imu_times, Order::Acceleration, &mut out)?;
            let g = gravity_world();
            let imu = (0..imu_times.len())
                .map(|i| {
                    let rotation = UnitQuaternion::new_normalize(out.rotation[i]);
                    ImuSample {
                        t_secs: imu_times[i],
                        gyro: out.ang_vel_body(i),
                        accel: rotation.inverse_transform_vector(&(out.lin_acc_world[i] - g)),
                    }
                })
                .collect();
            Loaded {
                origin_secs: 0.0,
                times,
                poses,
                imu,
                note: None,
            }
        }
        Source::Tum => {
            let trajectory = eval::read_tum(path()?)?;
            let origin = trajectory.timestamps_secs()[0];
            let times = trajectory
                .timestamps_secs()
                .iter()
                .map(|t| t - origin)
                .collect();
            Loaded {
                origin_secs: origin,
                times,
                poses: trajectory.poses().to_vec(),
                imu: Vec::new(),
                note: None,
            }
        }
        Source::Euroc => {
            let folder = path()?;
            EurocSequence::check_folder(folder, "data.path")?;
            let seq = EurocSequence::load(folder)?;
            let origin = seq.ground_truth[0].stamp;
            let times: Vec<f64> = seq
                .ground_truth
                .iter()
                .map(|s| s.stamp.secs_since(origin))
                .collect();
            let poses = seq.ground_truth.iter().map(|s| s.world_from_body).collect();
            let (imu, note) =
                body_readings(&seq, data.bias).with_context(|| format!("{}", folder.display()))?;
            Loaded {
                origin_secs: origin.as_secs_f64(),
                times,
                poses,
                imu,
                note,
            }
        }
    })
}

impl Sequence {
    fn new(config: &Config, data: &DataConfig, seed: u64) -> anyhow::Result<Self> {
        if data.known_every == 0 {
            bail!(
                "{}: [data] known_every must be at least 1",
                config.path().display()
            );
        }
        let Loaded {
            origin_secs: origin,
            times,
            poses,
            imu,
            note,
        } = load(config, data, seed)?;
        let start = data.start_secs;
        let end = data.crop_secs.map_or(f64::INFINITY, |c| start + c);
        let keep: Vec<usize> = (0..times.len())
            .filter(|&i| times[i] >= start && times[i] <= end)
            .collect();
        // The fitted range ends at the last known pose, so no held-out pose is an extrapolation.
        let n_known = (keep.len().saturating_sub(1)) / data.known_every + 1;
        let keep = &keep[..((n_known - 1) * data.known_every + 1).min(keep.len())];
        if n_known < 4 || keep.len() < 2 {
            bail!(
                "{}: the cropped trajectory has {} poses and {n_known} known ones; at least 4 known poses are needed",
                config.path().display(),
                keep.len()
            );
        }
        let t0 = times[keep[0]];
        let t1 = times[keep[keep.len() - 1]];
        let known: Vec<usize> = (0..keep.len()).step_by(data.known_every).collect();
        Ok(Self {
            note,
            origin_secs: origin + t0,
            times: keep.iter().map(|&i| times[i] - t0).collect(),
            poses: keep.iter().map(|&i| poses[i]).collect(),
            known_times: known.iter().map(|&i| times[keep[i]] - t0).collect(),
            known,
            imu: imu
                .into_iter()
                .filter(|s| s.t_secs >= t0 && s.t_secs <= t1)
                .map(|s| ImuSample {
                    t_secs: s.t_secs - t0,
                    ..s
                })
                .collect(),
        })
    }

    fn range(&self) -> TimeRange {
        TimeRange {
            start_secs: 0.0,
            end_secs: *self.times.last().expect("non-empty"),
        }
    }

    fn held_out(&self) -> Vec<usize> {
        let mut is_known = vec![false; self.times.len()];
        self.known.iter().for_each(|&i| is_known[i] = true);
        (0..self.times.len()).filter(|&i| !is_known[i]).collect()
    }
}

/// Errors of one method, in the units of their names.
#[derive(Debug, Serialize)]
struct MethodMetrics {
    rot_err_deg: f64,
    rot_rmse_deg: f64,
    trans_err_m: f64,
    trans_rmse_m: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    ang_vel_rmse_rad_s: Option<f64>,
    held_out_poses: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    num_params: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    final_loss: Option<f64>,
    /// How the fit ended (none for the interpolation reference).
    #[serde(flatten)]
    fit: Option<FitReport>,
}

/// Mean and RMSE of the rotation (degrees) and translation (metres) errors: evo's APE
/// rotation-angle and translation parts, without alignment.
fn pose_errors(
    estimated: &[Isometry3<f64>],
    truth: &[Isometry3<f64>],
) -> anyhow::Result<(f64, f64, f64, f64)> {
    let rot_deg: Vec<f64> = eval::ape_rotation_angle(truth, estimated)?
        .into_iter()
        .map(f64::to_degrees)
        .collect();
    let rot = eval::error_stats(&rot_deg)?;
    let trans = eval::error_stats(&eval::ape_translation(truth, estimated)?)?;
    Ok((rot.mean, rot.rmse, trans.mean, trans.rmse))
}

/// Rotation (degrees) and position (centimetres) errors at each held-out pose.
struct HeldOutErrors {
    rot_deg: Vec<f64>,
    pos_cm: Vec<f64>,
}

impl HeldOutErrors {
    fn new(estimated: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> anyhow::Result<Self> {
        Ok(Self {
            rot_deg: eval::ape_rotation_angle(truth, estimated)?
                .into_iter()
                .map(f64::to_degrees)
                .collect(),
            pos_cm: eval::ape_translation(truth, estimated)?
                .into_iter()
                .map(|e| 100.0 * e)
                .collect(),
        })
    }
}

/// What a unit's plots share with the other units.
struct UnitPlots<'a> {
    seq: &'a Sequence,
    known_poses: &'a [Isometry3<f64>],
    held_times: &'a [f64],
    /// The interpolation reference's errors, drawn beside a method's.
    reference: Option<&'a HeldOutErrors>,
}

/// Legend text of the interpolation reference.
const INTERP_LABEL: &str = "interpolation of known poses";

impl UnitPlots<'_> {
    /// Draws `trajectory_<imu>_<method>.png` and `errors_<imu>_<method>.png` of the unit whose
    /// poses at every time are `all`; `(rot_err_deg, trans_err_m)` are its mean held-out
    /// errors. A plot that fails is logged; the unit goes on.
    fn draw(
        &self,
        unit: &Unit,
        all: &[Isometry3<f64>],
        errors: &HeldOutErrors,
        (rot_err_deg, trans_err_m): (f64, f64),
    ) {
        let key = unit.key();
        let label = if key.method == INTERP {
            INTERP_LABEL.to_owned()
        } else {
            format!("{}, imu = {}", key.method, key.condition)
        };
        let mean = format!(
            "held-out error {rot_err_deg:.2}° and {:.2} cm (mean)",
            100.0 * trans_err_m
        );
        let series = [
            TrajectorySeries {
                label: "ground truth (all poses)".into(),
                times_secs: self.seq.times.clone(),
                poses: self.seq.poses.clone(),
                style: SeriesStyle::Truth,
            },
            TrajectorySeries {
                label: "known poses (supervision)".into(),
                times_secs: self.seq.known_times.clone(),
                poses: self.known_poses.to_vec(),
                style: SeriesStyle::Initial,
            },
            TrajectorySeries {
                label: label.clone(),
                times_secs: self.seq.times.clone(),
                poses: all.to_vec(),
                style: SeriesStyle::Estimate(0),
            },
        ];
        let title = format!("Trajectory fit: {label}; {mean}");
        if let Err(e) = plot::trajectories(unit.file("trajectory", "png"), &title, &series) {
            unit.log(format_args!("no trajectory plot: {e}"));
        }

        let line = |label: &str, y: &[f64], style| Line {
            label: label.to_owned(),
            x: self.held_times.to_vec(),
            y: y.to_vec(),
            style,
        };
        let panel = |y_label: &str, pick: fn(&HeldOutErrors) -> &[f64]| {
            let mut lines = Vec::new();
            if let Some(reference) = self.reference {
                lines.push(line(INTERP_LABEL, pick(reference), SeriesStyle::Reference));
            }
            lines.push(line(&label, pick(errors), SeriesStyle::Estimate(0)));
            Panel {
                y_label: y_label.to_owned(),
                y_scale: YScale::LinearFromZero,
                lines,
            }
        };
        let panels = [
            panel("rotation error (°)", |e| &e.rot_deg),
            panel("position error (cm)", |e| &e.pos_cm),
        ];
        let title = format!(
            "Errors at {} held-out poses: {label}",
            self.held_times.len()
        );
        let path = unit.file("errors", "png");
        if let Err(e) = plot::stacked_line_charts(path, &title, "time (s)", &panels) {
            unit.log(format_args!("no error plot: {e}"));
        }
    }
}

/// RMS of a set of errors; `None` when there are none.
fn rms(errors: impl Iterator<Item = f64>) -> Option<f64> {
    eval::error_stats(&errors.collect::<Vec<_>>())
        .ok()
        .map(|s| s.rmse)
}

/// Slerp/linear interpolation of the known poses at time `t`, and the body angular velocity of
/// that interpolation (constant between two known poses).
fn interpolate(seq: &Sequence, t: f64) -> (Isometry3<f64>, Vector3<f64>) {
    let known_times = &seq.known_times;
    let k = known_times
        .partition_point(|&x| x <= t)
        .clamp(1, known_times.len() - 1);
    let (a, b) = (&seq.poses[seq.known[k - 1]], &seq.poses[seq.known[k]]);
    let (ta, tb) = (known_times[k - 1], known_times[k]);
    let u = (t - ta) / (tb - ta);
    let rotation = a.rotation.slerp(&b.rotation, u);
    let translation = a.translation.vector.lerp(&b.translation.vector, u);
    let omega = (a.rotation.inverse() * b.rotation).scaled_axis() / (tb - ta);
    (
        Isometry3::from_parts(Translation3::from(translation), rotation),
        omega,
    )
}

/// What every method's fit shares: the known poses and IMU readings, the frame, the schedule,
/// and the held-out poses its live errors are measured on.
struct Fitting<'a> {
    data: FitData<'a>,
    frame: Sim3,
    settings: FitSettings,
    held_times: &'a [f64],
    held_truth: &'a [Isometry3<f64>],
}

impl Fitting<'_> {
    /// Fits `field` with the IMU terms of `mode` ([`Fit`]), reporting the loss and the known and
    /// held-out errors and checkpointing through `unit`; returns how the fit ended.
    fn run(
        &self,
        field: &mut dyn PoseField,
        mode: ImuMode,
        seed: u64,
        unit: &mut Unit,
    ) -> anyhow::Result<FitReport> {
        let s = &self.settings;
        let mut fit = Fit::new(&*field, self.data, self.frame, s, mode, seed)?;
        unit.set_steps(s.iterations);
        if let Some((done, mut r)) = unit.resume() {
            fit.restore(field, done, &mut r)?;
        }
        loop {
            let stopped = fit.step(field)?;
            let done = fit.steps();
            if unit.report_due(done) {
                let (rot, trans) = fit.errors_at(&*field, self.held_times, self.held_truth)?;
                let (known_rot, known_trans) = fit.known_errors(&*field)?;
                unit.report(
                    done,
                    &[
                        ("loss", fit.loss()),
                        ("known_rot_err_deg", known_rot),
                        ("known_trans_err_m", known_trans),
                        ("rot_err_deg", rot),
                        ("trans_err_m", trans),
                    ],
                );
            }
            if stopped {
                break;
            }
            if unit.checkpoint_due() {
                unit.checkpoint(done as u64, |w| {
                    fit.save(&*field, w);
                    Ok(())
                })?;
            }
        }
        let report = fit.report(&*field)?;
        let verdict = if report.converged {
            "within"
        } else {
            "warning: above"
        };
        unit.log(format_args!(
            "fit stopped after {} steps ({}): known poses {:.4}° and {:.2e} m, {verdict} the \
             tolerance {}° and {} m",
            report.steps,
            report.stop.key(),
            report.known_rot_err_deg,
            report.known_trans_err_m,
            s.tolerance_deg,
            s.tolerance_m
        ));
        Ok(report)
    }
}

/// The method key of the interpolation reference.
const INTERP: &str = "interp";

/// The whole config, decoded and checked before the trajectory is read or generated.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    /// The names of the fields to fit.
    fitted: Vec<String>,
}

impl Settings {
    fn new(config: &Config) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        exp.fit
            .validate()
            .map_err(|e| anyhow::anyhow!("{}: [fit] {e}", config.path().display()))?;
        if exp.fields.is_empty() {
            bail!(
                "{}: no pose fields to fit; add a table such as [fields.posenet] with kind = \"posenet\"",
                config.path().display()
            );
        }
        let fitted: Vec<String> = match &exp.fit.fields {
            None => exp.fields.keys().cloned().collect(),
            Some(names) => {
                if let Some(unknown) = names.iter().find(|n| !exp.fields.contains_key(*n)) {
                    bail!(
                        "{}: [fit] fields names {unknown:?}, which has no [fields.{unknown}] table \
                     (tables: {})",
                        config.path().display(),
                        exp.fields.keys().cloned().collect::<Vec<_>>().join(", ")
                    );
                }
                names.clone()
            }
        };
        if exp.fields.contains_key(INTERP) {
            bail!(
                "{}: [fields.{INTERP}] is the name of the interpolation reference; call the field otherwise",
                config.path().display()
            );
        }
        if exp.data.source == Source::Synthetic {
            exp.data.check_synthetic(config)?;
        }
        for name in &fitted {
            let section = config.section(&format!("fields.{name}"));
            let (kind, at) = section.kind()?;
            registry::find_pose_field(&kind)
                .map_err(|e| config.error_at(Some(at), e.to_string()))?;
        }
        Ok(Self { exp, fitted })
    }
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let config = input.config;
    let seed = input.run.seed;
    let Settings { exp, fitted } = Settings::new(config)?;
    let seq = Sequence::new(config, &exp.data, seed)?;
    if let Some(note) = &seq.note {
        input.run_dir.log(note);
    }
    if seq.imu.is_empty() && exp.fit.imu.iter().any(|m| *m != ImuMode::None) {
        bail!(
            "{}: [fit] imu = {:?} needs IMU data, but source {:?} has none; use imu = [\"none\"]",
            config.path().display(),
            exp.fit.imu,
            exp.data.source
        );
    }
    let known_poses: Vec<Isometry3<f64>> = seq.known.iter().map(|&i| seq.poses[i]).collect();
    let frame = normalising_frame(&known_poses);
    let held_out = seq.held_out();
    let held_times: Vec<f64> = held_out.iter().map(|&i| seq.times[i]).collect();
    let held_truth: Vec<Isometry3<f64>> = held_out.iter().map(|&i| seq.poses[i]).collect();
    let imu_times: Vec<f64> = seq.imu.iter().map(|s| s.t_secs).collect();
    input.run_dir.log(format_args!(
        "{} poses over {:.2} s, {} known (every {}), {} held out, {} IMU samples; fields work in a frame rotated to the mean known orientation, centred at {:.3?} m in it and scaled by 1/{:.3} m",
        seq.times.len(),
        seq.range().end_secs,
        seq.known.len(),
        exp.data.known_every,
        held_out.len(),
        seq.imu.len(),
        (frame.rotation.transpose() * frame.translation).as_slice(),
        frame.scale
    ));

    let write_trajectory = |path: PathBuf, times: &[f64], poses: Vec<Isometry3<f64>>| {
        let absolute = times.iter().map(|t| t + seq.origin_secs).collect();
        let trajectory = Trajectory::new(absolute, poses)?;
        eval::write_tum(path, &trajectory)?;
        anyhow::Ok(())
    };
    write_trajectory(
        input.run_dir.file("traj_gt.txt"),
        &seq.times,
        seq.poses.clone(),
    )?;
    let known_times = &seq.known_times;
    write_trajectory(
        input.run_dir.file("traj_known.txt"),
        known_times,
        known_poses.clone(),
    )?;

    let fitting = Fitting {
        data: FitData {
            times: known_times,
            poses: &known_poses,
            imu: &seq.imu,
        },
        frame,
        settings: exp.fit.settings(input.run.iterations(exp.fit.iterations)),
        held_times: &held_times,
        held_truth: &held_truth,
    };
    let mut modes = exp.fit.imu.clone();
    modes.dedup();
    // Units: the interpolation reference once (it uses no IMU), then every field per IMU mode.
    let mut units = vec![UnitKey::new(ImuMode::None.key(), INTERP, seed)];
    for &mode in &modes {
        for name in &fitted {
            units.push(UnitKey::new(mode.key(), name.as_str(), seed));
        }
    }
    // The interpolation reference's errors at the held-out poses, drawn beside every method's.
    let interp_errors = {
        let estimated: Vec<Isometry3<f64>> =
            held_times.iter().map(|&t| interpolate(&seq, t).0).collect();
        HeldOutErrors::new(&estimated, &held_truth)?
    };
    let ctx = FieldContext {
        time_range: seq.range(),
        frame_times_secs: known_times.clone(),
        seed,
    };
    Study::new(input, units)
        .columns(&[
            "rot_err_deg",
            "trans_err_m",
            "ang_vel_rmse_rad_s",
            "known_rot_err_deg",
            "fit_steps",
        ])
        .report_every(100)
        .run(|unit| {
            let (mode_key, name) = (unit.key().condition.clone(), unit.key().method.clone());
            let (all, num_params, fitted, ang_vel_rmse_rad_s) = if name == INTERP {
                let all: Vec<Isometry3<f64>> =
                    seq.times.iter().map(|&t| interpolate(&seq, t).0).collect();
                let ang_vel = rms(seq
                    .imu
                    .iter()
                    .map(|s| (interpolate(&seq, s.t_secs).1 - s.gyro).norm()));
                (all, None, None, ang_vel)
            } else {
                let mode = *modes
                    .iter()
                    .find(|m| m.key() == mode_key)
                    .context("an IMU mode of the config")?;
                let section = config.section(&format!("fields.{name}"));
                let mut field = build_pose_field(&section, &ctx)?;
                let fitted = fitting
                    .run(field.as_mut(), mode, seed, unit)
                    .with_context(|| format!("fitting [fields.{name}] with imu = {mode_key:?}"))?;
                SavedPoseField::capture(&section, &ctx, frame, field.as_ref())?
                    .write(&unit.file("field", "safetensors"))?;
                let all: Vec<Isometry3<f64>> = fit::sample(field.as_ref(), &frame, &seq.times)?
                    .iter()
                    .map(|s| s.pose)
                    .collect();
                let ang_vel = if imu_times.is_empty() {
                    None
                } else {
                    let samples = fit::sample(field.as_ref(), &frame, &imu_times)?;
                    rms(samples
                        .iter()
                        .zip(&seq.imu)
                        .map(|(f, s)| (f.ang_vel_body - s.gyro).norm()))
                };
                (all, Some(field.num_params()), Some(fitted), ang_vel)
            };
            let estimated: Vec<Isometry3<f64>> = held_out.iter().map(|&i| all[i]).collect();
            let (rot_err_deg, rot_rmse_deg, trans_err_m, trans_rmse_m) =
                pose_errors(&estimated, &held_truth)?;
            let plots = UnitPlots {
                seq: &seq,
                known_poses: &known_poses,
                held_times: &held_times,
                reference: (name != INTERP).then_some(&interp_errors),
            };
            let errors = HeldOutErrors::new(&estimated, &held_truth)?;
            plots.draw(unit, &all, &errors, (rot_err_deg, trans_err_m));
            write_trajectory(unit.file("traj", "txt"), &seq.times, all)?;
            Metrics::from_serialize(&MethodMetrics {
                rot_err_deg,
                rot_rmse_deg,
                trans_err_m,
                trans_rmse_m,
                ang_vel_rmse_rad_s,
                held_out_poses: held_out.len(),
                num_params,
                final_loss: fitted.map(|f| f.final_loss),
                fit: fitted,
            })
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show trajectory` states the defaults: its values are those of a config
    /// with only the keys that have none.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"trajectory\"\n[data]\nsource = \"synthetic\"\n\
                        [fields.posenet]\nkind = \"posenet\"\n[fields.spline]\nkind = \"spline\"\n\
                        [fields.lie_spline]\nkind = \"lie_spline\"\n";
        cpose_core::testing::check_default_config("trajectory", required, |config, _| {
            Settings::new(config)
        });
    }

    fn synthetic(known_every: usize) -> (Config, DataConfig) {
        let config = Config::from_text("test.toml", "task = \"trajectory\"\n");
        let data = DataConfig {
            source: Source::Synthetic,
            path: None,
            duration_secs: 4.0,
            pose_rate_hz: 50.0,
            imu_rate_hz: 200.0,
            start_secs: 0.5,
            crop_secs: Some(3.0),
            known_every,
            bias: BiasRemoval::Estimate,
        };
        (config, data)
    }

    #[test]
    fn cropping_keeps_first_and_last_pose_known_and_imu_inside() {
        let (config, data) = synthetic(7);
        let seq = Sequence::new(&config, &data, 0).unwrap();
        // 0.5..3.5 s at 50 Hz is 151 poses; the range ends at the last known one (index 147).
        assert_eq!(seq.times.len(), 148);
        assert_eq!(seq.known.first(), Some(&0));
        assert_eq!(seq.known.last(), Some(&147));
        assert_eq!(seq.known.len(), 22);
        assert_eq!(seq.held_out().len(), 148 - 22);
        assert!((seq.origin_secs - 0.5).abs() < 1e-12);
        let end = seq.range().end_secs;
        assert!(seq.imu.iter().all(|s| s.t_secs >= 0.0 && s.t_secs <= end));
        assert!(seq.imu.len() > 580);
    }

    #[test]
    fn impossible_or_huge_synthetic_sizes_are_refused_before_allocating() {
        let (config, data) = synthetic(5);
        for (duration_secs, pose_rate_hz, expect) in [
            (f64::INFINITY, 50.0, "duration_secs = inf"),
            (4.0, f64::NAN, "pose_rate_hz = NaN"),
            (1e12, 50.0, "2.000e14 samples"),
            (4.0, 1e9, "4.000e9 samples"),
        ] {
            let data = DataConfig {
                duration_secs,
                pose_rate_hz,
                ..data.clone()
            };
            let e = Sequence::new(&config, &data, 0).err().unwrap().to_string();
            assert!(e.contains("test.toml: [data]") && e.contains(expect), "{e}");
        }
    }

    #[test]
    fn synthetic_imu_is_exact_for_the_true_motion() {
        // The losses vanish on the motion the readings were simulated from.
        let range = TimeRange::new(0.0, 4.0).unwrap();
        let motion = SinusoidMotion::<f64>::handheld(range, 0);
        let (config, mut data) = synthetic(5);
        data.start_secs = 0.0;
        data.crop_secs = None;
        let seq = Sequence::new(&config, &data, 0).unwrap();
        let times: Vec<f64> = seq.imu.iter().map(|s| s.t_secs).collect();
        let mut out = PoseBatch::default();
        motion
            .evaluate(&times, Order::Acceleration, &mut out)
            .unwrap();
        let gyro: Vec<_> = seq.imu.iter().map(|s| s.gyro).collect();
        let accel: Vec<_> = seq.imu.iter().map(|s| s.accel).collect();
        let mut cot = PoseBatch::zeros(times.len(), Order::Acceleration);
        assert!(fit::losses::gyro_tight_l1(&out, &gyro, 1.0, &mut cot) < 1e-12);
        assert!(fit::losses::accel_l1(&out, &accel, &gravity_world(), 1.0, 1.0, &mut cot) < 1e-12);
        // Hand-held motion adds a few m/s² to gravity's 9.81.
        let mean_norm = accel.iter().map(|a| a.norm()).sum::<f64>() / accel.len() as f64;
        assert!((mean_norm - 9.81).abs() < 2.0, "{mean_norm}");
    }

    #[test]
    fn interpolation_hits_known_poses() {
        let (config, data) = synthetic(10);
        let seq = Sequence::new(&config, &data, 0).unwrap();
        for (&i, &t) in seq.known.iter().zip(&seq.known_times) {
            let (pose, _) = interpolate(&seq, t);
            assert!((pose.translation.vector - seq.poses[i].translation.vector).norm() < 1e-12);
        }
        // Halfway between two known poses: the slerp midpoint.
        let (a, b) = (&seq.poses[seq.known[3]], &seq.poses[seq.known[4]]);
        let (mid, omega) = interpolate(&seq, (seq.known_times[3] + seq.known_times[4]) / 2.0);
        assert!(mid.rotation.angle_to(&a.rotation.slerp(&b.rotation, 0.5)) < 1e-12);
        let dt = seq.known_times[4] - seq.known_times[3];
        assert!(((a.rotation.inverse() * b.rotation).angle() - omega.norm() * dt).abs() < 1e-12);
    }
}
