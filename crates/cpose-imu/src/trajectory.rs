//! Task `trajectory`: fit pose fields to a trajectory from poses at a subset of its timestamps,
//! optionally supervised by the gyroscope (integrated over windows, or through the fields' `q̇`)
//! and the accelerometer (through `p̈`), and report the pose error at every held-out timestamp.
//!
//! Sources: a built-in synthetic hand-held motion (exact IMU from its analytic derivatives), a
//! TUM trajectory file, or a EuRoC sequence (real IMU, ground-truth biases removed). Every pose
//! field named in `[fields.NAME]` is fitted once per IMU mode; slerp/linear interpolation of the
//! known poses is the reference (`interp`).
//!
//! Fields work in a normalised frame (rotated to the mean known orientation, centred and scaled
//! so that PoseNet's tanh-bounded translation fits; see `Normalisation`); errors are reported in
//! degrees and metres of the original world.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, bail};
use cpose_core::config::Config;
use cpose_core::eval::{self, Trajectory};
use cpose_core::nn::{Adam, ExponentialDecay};
use cpose_core::pose_field::sinusoid::SinusoidMotion;
use cpose_core::registry::{FieldContext, Task, TaskInput, build_pose_field};
use cpose_core::study::{Metrics, Study, Unit, UnitKey};
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, TimeRange};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::euroc::EurocSequence;
use crate::imu::{ImuMode, ImuSample};
use crate::losses;
use cpose_core::gravity_world;

inventory::submit! {
    Task {
        name: "trajectory",
        about: "fit pose fields to a trajectory from a subset of its poses (optionally with gyro/accel) and score held-out poses",
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

/// `[data]`: the trajectory and which of its poses supervise the fit.
#[derive(Debug, Deserialize)]
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
    /// Adam steps per fit (scaled by `[run] iterations_scale`).
    iterations: usize,
    /// IMU modes to compare: `"none"`, `"loose"`, `"tight"`, `"accel"`, `"combined"`.
    imu: Vec<ImuMode>,
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
    /// Learning rates decay exponentially to `lr · lr_decay` at the last step (paper: 0.01).
    lr_decay: f64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            iterations: 3000,
            imu: vec![ImuMode::None, ImuMode::Tight],
            pose_weight: 1.0,
            gyro_weight: 1.0,
            accel_weight: 1.0,
            imu_batch: 64,
            loose_window_secs: 0.1,
            lr_translation: 1e-3,
            lr_rotation: 2e-4,
            lr_pose: 1e-2,
            lr_decay: 0.1,
        }
    }
}

/// A trajectory cropped to the fitted range, times in seconds since its first known pose.
struct Sequence {
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
            if !(data.duration_secs > 0.0 && data.pose_rate_hz > 0.0 && data.imu_rate_hz > 0.0) {
                bail!(
                    "{}: [data] duration_secs, pose_rate_hz and imu_rate_hz must be positive",
                    config.path().display()
                );
            }
            let range = TimeRange::new(0.0, data.duration_secs).context("duration")?;
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
            }
        }
        Source::Euroc => {
            let seq = EurocSequence::load(path()?)?;
            let origin = seq.ground_truth[0].stamp;
            let times: Vec<f64> = seq
                .ground_truth
                .iter()
                .map(|s| s.stamp.secs_since(origin))
                .collect();
            let poses = seq.ground_truth.iter().map(|s| s.world_from_body).collect();
            // Remove the ground-truth bias of the nearest state and express the readings in the
            // body frame (EuRoC's imu0 is the body frame: T_BS = I; a lever arm is not modelled).
            let imu_rotation = seq.body_from_imu.rotation;
            let imu = seq
                .imu
                .iter()
                .map(|s| {
                    let t = s.stamp.secs_since(origin);
                    let k = times.partition_point(|&x| x < t).min(times.len() - 1);
                    let state = &seq.ground_truth[k];
                    ImuSample {
                        t_secs: t,
                        gyro: imu_rotation * (s.gyro - state.gyro_bias),
                        accel: imu_rotation * (s.accel - state.accel_bias),
                    }
                })
                .collect();
            Loaded {
                origin_secs: origin.as_secs_f64(),
                times,
                poses,
                imu,
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

/// The frame the fields work in: `R_n = R_refᵀ R` and `p_n = (R_refᵀ p − c) / s`. The reference
/// rotation (the mean of the known rotations) puts every field's identity start near the data,
/// so no method starts up to 180° away from it; centring and scaling (the bounding box of the
/// known positions in that frame, scaled by 1.5× its largest half-extent) keep PoseNet's
/// tanh-bounded translation in range.
struct Normalisation {
    world_from_field: UnitQuaternion<f64>,
    centre: Vector3<f64>,
    scale: f64,
}

impl Normalisation {
    fn fit(poses: &[Isometry3<f64>]) -> Self {
        // Chordal mean: sign-aligned quaternions, averaged, normalised.
        let first = *poses[0].rotation.quaternion();
        let sum = poses
            .iter()
            .fold(nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0), |acc, p| {
                let q = *p.rotation.quaternion();
                if q.coords.dot(&first.coords) < 0.0 {
                    acc - q
                } else {
                    acc + q
                }
            });
        let world_from_field = UnitQuaternion::new_normalize(sum);
        let rotated = poses
            .iter()
            .map(|p| world_from_field.inverse_transform_vector(&p.translation.vector));
        let lo = rotated
            .clone()
            .fold(Vector3::repeat(f64::INFINITY), |a, p| a.inf(&p));
        let hi = rotated.fold(Vector3::repeat(f64::NEG_INFINITY), |a, p| a.sup(&p));
        Self {
            world_from_field,
            centre: (lo + hi) / 2.0,
            scale: 1.5 * ((hi - lo) / 2.0).max().max(1e-3),
        }
    }
    fn to_field_frame(&self, pose: &Isometry3<f64>) -> Isometry3<f64> {
        let field_from_world = self.world_from_field.inverse();
        let p = (field_from_world * pose.translation.vector - self.centre) / self.scale;
        Isometry3::from_parts(Translation3::from(p), field_from_world * pose.rotation)
    }
    fn to_world_frame(&self, pose: &Isometry3<f64>) -> Isometry3<f64> {
        let p = self.world_from_field * (pose.translation.vector * self.scale + self.centre);
        Isometry3::from_parts(Translation3::from(p), self.world_from_field * pose.rotation)
    }
    /// Gravity in the field's frame.
    fn gravity(&self) -> Vector3<f64> {
        self.world_from_field.inverse() * gravity_world()
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

/// Everything one fit needs, allocated once.
struct Fit<'a> {
    seq: &'a Sequence,
    norm: &'a Normalisation,
    cfg: &'a FitConfig,
    known_targets: Vec<Isometry3<f64>>,
    /// Held-out times and poses, for the live error.
    held_times: &'a [f64],
    held_truth: &'a [Isometry3<f64>],
}

impl Fit<'_> {
    /// Held-out rotation (degrees) and translation (metres) errors of `field` now.
    fn held_out_errors(&self, field: &dyn PoseField) -> anyhow::Result<(f64, f64)> {
        let mut out = PoseBatch::default();
        field.evaluate(self.held_times, Order::Pose, &mut out)?;
        let estimated: Vec<Isometry3<f64>> = (0..self.held_times.len())
            .map(|i| self.norm.to_world_frame(&out.world_from_body(i)))
            .collect();
        let (rot, _, trans, _) = pose_errors(&estimated, self.held_truth)?;
        Ok((rot, trans))
    }

    /// Adam on `L = L_pose + w_g L_gyro + w_a L_accel`, reporting the loss and the held-out
    /// errors and checkpointing through `unit`; returns the last loss.
    fn run(
        &self,
        field: &mut dyn PoseField,
        mode: ImuMode,
        iterations: usize,
        seed: u64,
        unit: &mut Unit,
    ) -> anyhow::Result<f64> {
        let mut adam = Adam::<f32>::new(field.num_params());
        let mut grad = vec![0.0f32; field.num_params()];
        let (mut out, mut cot) = (PoseBatch::default(), PoseBatch::default());
        let batch = self.cfg.imu_batch.min(self.seq.imu.len()).max(1);
        let (mut imu_times, mut gyro, mut accel) = (
            Vec::with_capacity(batch),
            Vec::with_capacity(batch),
            Vec::with_capacity(batch),
        );
        let mut imu_order: Vec<usize> = (0..self.seq.imu.len()).collect();
        let mut pairs = Vec::with_capacity(batch);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut cursor = imu_order.len();
        let mut first = 0;
        let mut loss = f64::NAN;
        unit.set_steps(iterations);
        if let Some((done, mut r)) = unit.resume() {
            r.pose_field(field)?;
            r.adam(&mut adam)?;
            rng = r.rng()?;
            let order = r.f64s()?;
            if order.len() != imu_order.len() {
                bail!(
                    "{}: the checkpoint's IMU order does not match",
                    r.path().display()
                );
            }
            imu_order = order.into_iter().map(|i| i as usize).collect();
            cursor = r.u64()? as usize;
            loss = r.f64()?;
            first = done as usize;
        }
        let decay = |lr: f64| ExponentialDecay {
            lr0: lr,
            lr_end: lr * self.cfg.lr_decay,
            max_iter: iterations as u64,
        };
        let (lr_t, lr_r, lr_p) = (
            decay(self.cfg.lr_translation),
            decay(self.cfg.lr_rotation),
            decay(self.cfg.lr_pose),
        );
        let g = self.norm.gravity();
        for it in first..iterations {
            grad.fill(0.0);
            let n = self.seq.known_times.len();
            field.forward(&self.seq.known_times, Order::Pose, &mut out)?;
            cot.reset(n, Order::Pose);
            loss = losses::pose_l2(
                &out,
                &self.known_targets,
                self.cfg.pose_weight,
                (1.0, 1.0),
                &mut cot,
            );
            field.backward(&self.seq.known_times, &cot, &mut grad)?;
            if mode == ImuMode::Loose {
                // Windows [t_k, t_k + window] from a shuffled IMU index; the gyro integrated
                // over each supervises the rotation between its ends.
                imu_times.clear();
                pairs.clear();
                for _ in 0..batch {
                    if cursor == imu_order.len() {
                        imu_order.shuffle(&mut rng);
                        cursor = 0;
                    }
                    let t0 = self.seq.imu[imu_order[cursor]].t_secs;
                    cursor += 1;
                    let t1 = t0 + self.cfg.loose_window_secs;
                    if let Some(dq) = losses::integrate_gyro(&self.seq.imu, t0, t1) {
                        pairs.push((imu_times.len(), imu_times.len() + 1, dq));
                        imu_times.extend([t0, t1]);
                    }
                }
                if !pairs.is_empty() {
                    field.forward(&imu_times, Order::Pose, &mut out)?;
                    cot.reset(imu_times.len(), Order::Pose);
                    loss += losses::gyro_loose_l1(&out, &pairs, self.cfg.gyro_weight, &mut cot);
                    field.backward(&imu_times, &cot, &mut grad)?;
                }
            } else if mode != ImuMode::None {
                imu_times.clear();
                gyro.clear();
                accel.clear();
                for _ in 0..batch {
                    if cursor == imu_order.len() {
                        imu_order.shuffle(&mut rng);
                        cursor = 0;
                    }
                    let s = &self.seq.imu[imu_order[cursor]];
                    cursor += 1;
                    imu_times.push(s.t_secs);
                    gyro.push(s.gyro);
                    accel.push(s.accel);
                }
                let order = mode.order();
                field.forward(&imu_times, order, &mut out)?;
                cot.reset(batch, order);
                if mode.gyro() {
                    loss += losses::gyro_tight_l1(&out, &gyro, self.cfg.gyro_weight, &mut cot);
                }
                if mode.accel() {
                    loss += losses::accel_l1(
                        &out,
                        &accel,
                        &g,
                        self.norm.scale,
                        self.cfg.accel_weight,
                        &mut cot,
                    );
                }
                field.backward(&imu_times, &cot, &mut grad)?;
            }
            if !loss.is_finite() || grad.iter().any(|x| !x.is_finite()) {
                bail!(
                    "the loss or its gradient became {loss} at iteration {it}; stopping this fit \
                     (the last good checkpoint is kept)"
                );
            }
            let step = it as u64;
            adam.step_pose_field(field, &grad, |kind| match kind {
                ParamKind::Translation => lr_t.lr(step),
                ParamKind::Rotation => lr_r.lr(step),
                ParamKind::Pose => lr_p.lr(step),
            });
            let done = it + 1;
            if unit.report_due(done) {
                let (rot, trans) = self.held_out_errors(field)?;
                unit.report(
                    done,
                    &[("loss", loss), ("rot_err_deg", rot), ("trans_err_m", trans)],
                );
            }
            if done < iterations && unit.checkpoint_due() {
                unit.checkpoint(done as u64, |w| {
                    w.pose_field(field);
                    w.adam(&adam);
                    w.rng(&rng);
                    w.f64s(&imu_order.iter().map(|&i| i as f64).collect::<Vec<_>>());
                    w.u64(cursor as u64);
                    w.f64(loss);
                    Ok(())
                })?;
            }
        }
        Ok(loss)
    }
}

/// The method key of the interpolation reference.
const INTERP: &str = "interp";

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let config = input.config;
    let exp: Experiment = config.parse_params()?;
    let seed = input.run.seed;
    let seq = Sequence::new(config, &exp.data, seed)?;
    if seq.imu.is_empty() && exp.fit.imu.iter().any(|m| *m != ImuMode::None) {
        bail!(
            "{}: [fit] imu = {:?} needs IMU data, but source {:?} has none; use imu = [\"none\"]",
            config.path().display(),
            exp.fit.imu,
            exp.data.source
        );
    }
    if exp.fit.imu.contains(&ImuMode::Loose)
        && !(exp.fit.loose_window_secs > 0.0 && exp.fit.loose_window_secs.is_finite())
    {
        bail!(
            "{}: [fit] loose_window_secs = {} must be a positive number of seconds",
            config.path().display(),
            exp.fit.loose_window_secs
        );
    }
    if exp.fields.is_empty() {
        bail!(
            "{}: no pose fields to fit; add a table such as [fields.posenet] with kind = \"posenet\"",
            config.path().display()
        );
    }
    if exp.fields.contains_key(INTERP) {
        bail!(
            "{}: [fields.{INTERP}] is the name of the interpolation reference; call the field otherwise",
            config.path().display()
        );
    }
    let known_poses: Vec<Isometry3<f64>> = seq.known.iter().map(|&i| seq.poses[i]).collect();
    let norm = Normalisation::fit(&known_poses);
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
        norm.centre.as_slice(),
        norm.scale
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

    let fit = Fit {
        seq: &seq,
        norm: &norm,
        cfg: &exp.fit,
        known_targets: known_poses.iter().map(|p| norm.to_field_frame(p)).collect(),
        held_times: &held_times,
        held_truth: &held_truth,
    };
    let iterations = input.run.iterations(exp.fit.iterations);
    let mut modes = exp.fit.imu.clone();
    modes.dedup();
    // Units: the interpolation reference once (it uses no IMU), then every field per IMU mode.
    let mut units = vec![UnitKey::new(ImuMode::None.key(), INTERP, seed)];
    for &mode in &modes {
        for name in exp.fields.keys() {
            units.push(UnitKey::new(mode.key(), name.as_str(), seed));
        }
    }
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
            "final_loss",
        ])
        .report_every(100)
        .run(|unit| {
            let (mode_key, name) = (unit.key().condition.clone(), unit.key().method.clone());
            let (all, num_params, final_loss, ang_vel_rmse_rad_s) = if name == INTERP {
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
                let final_loss = fit
                    .run(field.as_mut(), mode, iterations, seed, unit)
                    .with_context(|| format!("fitting [fields.{name}] with imu = {mode_key:?}"))?;
                let mut out = PoseBatch::default();
                field.evaluate(&seq.times, Order::Pose, &mut out)?;
                let all: Vec<Isometry3<f64>> = (0..seq.times.len())
                    .map(|i| norm.to_world_frame(&out.world_from_body(i)))
                    .collect();
                let ang_vel = if imu_times.is_empty() {
                    None
                } else {
                    field.evaluate(&imu_times, Order::Velocity, &mut out)?;
                    rms(seq
                        .imu
                        .iter()
                        .enumerate()
                        .map(|(i, s)| (out.ang_vel_body(i) - s.gyro).norm()))
                };
                (all, Some(field.num_params()), Some(final_loss), ang_vel)
            };
            let estimated: Vec<Isometry3<f64>> = held_out.iter().map(|&i| all[i]).collect();
            let (rot_err_deg, rot_rmse_deg, trans_err_m, trans_rmse_m) =
                pose_errors(&estimated, &held_truth)?;
            write_trajectory(unit.file("traj", "txt"), &seq.times, all)?;
            Metrics::from_serialize(&MethodMetrics {
                rot_err_deg,
                rot_rmse_deg,
                trans_err_m,
                trans_rmse_m,
                ang_vel_rmse_rad_s,
                held_out_poses: held_out.len(),
                num_params,
                final_loss,
            })
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(losses::gyro_tight_l1(&out, &gyro, 1.0, &mut cot) < 1e-12);
        assert!(losses::accel_l1(&out, &accel, &gravity_world(), 1.0, 1.0, &mut cot) < 1e-12);
        // Hand-held motion adds a few m/s² to gravity's 9.81.
        let mean_norm = accel.iter().map(|a| a.norm()).sum::<f64>() / accel.len() as f64;
        assert!((mean_norm - 9.81).abs() < 2.0, "{mean_norm}");
    }

    #[test]
    fn normalisation_round_trips_and_interpolation_hits_known_poses() {
        let (config, data) = synthetic(10);
        let seq = Sequence::new(&config, &data, 0).unwrap();
        let known: Vec<_> = seq.known.iter().map(|&i| seq.poses[i]).collect();
        let norm = Normalisation::fit(&known);
        for pose in &known {
            // Known positions land inside [-1/1.5, 1/1.5], well within PoseNet's tanh range.
            assert!(norm.to_field_frame(pose).translation.vector.amax() <= 1.0 / 1.5 + 1e-12);
        }
        for pose in &seq.poses {
            let back = norm.to_world_frame(&norm.to_field_frame(pose));
            assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
            assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
        }
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
