//! Fitting a [`PoseField`] to timed poses, optionally with gyroscope and accelerometer readings
//! (the paper's §3.4): Adam on
//!
//! `L = w_p L_pose + w_g L_gyro + w_a L_accel`
//!
//! until the poses it was given are within a tolerance, the pose loss reaches a plateau (the
//! learning rates fall, then the fit ends: [`StopRule`]) or the step budget is spent. The losses
//! are in [`losses`]; [`ImuMode`] chooses which IMU terms enter.
//!
//! A field is fitted in a normalised frame ([`normalising_frame`]): the poses' mean rotation is
//! its identity and their bounding box fits in `[−⅔, ⅔]³`, so a field that starts at the identity
//! (PoseNet) starts near the data and its bounded translation head covers it. [`fit`] returns
//! that frame; [`sample`] gives poses and velocities in the world.
//!
//! Choosing a field for the sample spacing: PoseNet's encoding with `bands` frequencies
//! resolves periods down to about `duration / 2^(bands−1)`; with only a few poses over the range,
//! fewer bands keep it from oscillating between them (13 poses over 3 s want 2 bands, not 5).
//!
//! ```
//! use cpose_core::fit::{self, FitData, FitSettings, ImuMode};
//! use cpose_core::{PoseNetConfig, TimeRange};
//! use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
//!
//! // Nine poses along a turning arc, one every 0.25 s.
//! let times: Vec<f64> = (0..9).map(|i| 0.25 * i as f64).collect();
//! let poses: Vec<Isometry3<f64>> = times
//!     .iter()
//!     .map(|&t| {
//!         Isometry3::from_parts(
//!             Translation3::new(t.cos(), t.sin(), 0.1 * t),
//!             UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, t)),
//!         )
//!     })
//!     .collect();
//! let range = TimeRange::new(0.0, 2.0).expect("a valid range");
//! let config = PoseNetConfig { bands: 2, ..PoseNetConfig::default() };
//! let mut field = config.init::<f32>(range)?;
//! let settings = FitSettings { iterations: 3000, ..FitSettings::default() };
//! let data = FitData { times: &times, poses: &poses, imu: &[] };
//! let (frame, report) = fit::fit(&mut field, data, &settings, ImuMode::None, 0)?;
//! assert!(report.known_rot_err_deg < 0.5, "{report:?}");
//!
//! // Poses and velocities between the samples, in the world.
//! let between = fit::sample(&field, &frame, &[1.1])?;
//! assert!((between[0].ang_vel_body.z - 1.0).abs() < 0.3);
//! # Ok::<(), anyhow::Error>(())
//! ```

mod imu;
pub mod losses;

use anyhow::{Context as _, bail, ensure};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

pub use imu::{ImuMode, ImuSample};

use crate::checkpoint::{Reader, Writer};
use crate::eval::{Sim3, ape_rotation_angle, ape_translation, error_stats};
use crate::geometry::gravity_world;
use crate::nn::{Adam, Convergence, StopReason, StopRule};
use crate::pose_field::saved::FieldSample;
use crate::{Order, ParamKind, PoseBatch, PoseField};

/// What a fit is supervised with, in the world frame.
#[derive(Clone, Copy, Debug)]
pub struct FitData<'a> {
    /// Seconds, inside the field's time range.
    pub times: &'a [f64],
    /// `world_from_body` at `times`.
    pub poses: &'a [Isometry3<f64>],
    /// IMU readings with the bias removed, sorted by time, inside the field's time range
    /// (empty for [`ImuMode::None`]).
    pub imu: &'a [ImuSample],
}

/// The schedule and weights of a fit. The defaults are the paper's rates (Adam, `1e-3` for
/// translation and `2e-4` for rotation parameters) with a budget that lets PoseNet converge:
/// fitted to poses alone it reaches the tolerance, or a plateau twice, long before 20000 steps.
#[derive(Clone, Debug, PartialEq)]
pub struct FitSettings {
    /// The step budget.
    pub iterations: usize,
    /// The fit has converged when the mean errors on the given poses are within both.
    pub tolerance_deg: f64,
    /// See `tolerance_deg`; metres.
    pub tolerance_m: f64,
    /// Plateau detection and learning-rate drops.
    pub stop: StopRule,
    /// Weight of the pose loss (squared error of quaternions and of normalised positions: about
    /// 1e-4 at 1° of rotation error). Against the L1 gyroscope residual of real data (about
    /// 0.1 rad/s of noise and vibration) a weight near 1000 balances the two; exact readings
    /// want 1.
    pub pose_weight: f64,
    /// Weight of the gyroscope loss (paper: 1).
    pub gyro_weight: f64,
    /// Weight of the accelerometer loss (paper: 1).
    pub accel_weight: f64,
    /// IMU readings per step (a seeded shuffle is cycled through); for [`ImuMode::Loose`],
    /// windows per step.
    pub imu_batch: usize,
    /// Length of the windows the gyroscope is integrated over in [`ImuMode::Loose`], seconds.
    pub loose_window_secs: f64,
    /// Initial learning rate of translation parameters (paper: 1e-3).
    pub lr_translation: f64,
    /// Initial learning rate of rotation parameters (paper: 2e-4).
    pub lr_rotation: f64,
    /// Initial learning rate of joint pose parameters (splines, per-frame poses).
    pub lr_pose: f64,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            iterations: 20000,
            tolerance_deg: 0.01,
            tolerance_m: 1e-4,
            stop: StopRule::default(),
            pose_weight: 1.0,
            gyro_weight: 1.0,
            accel_weight: 1.0,
            imu_batch: 64,
            loose_window_secs: 0.1,
            lr_translation: 1e-3,
            lr_rotation: 2e-4,
            lr_pose: 1e-2,
        }
    }
}

impl FitSettings {
    /// Checks every range; the message names the setting, its value and the range.
    pub fn validate(&self) -> Result<(), String> {
        self.stop.validate()?;
        let non_negative = [
            ("tolerance_deg", self.tolerance_deg),
            ("tolerance_m", self.tolerance_m),
            ("pose_weight", self.pose_weight),
            ("gyro_weight", self.gyro_weight),
            ("accel_weight", self.accel_weight),
        ];
        for (key, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!("{key} = {value} must be a number ≥ 0"));
            }
        }
        let positive = [
            ("lr_translation", self.lr_translation),
            ("lr_rotation", self.lr_rotation),
            ("lr_pose", self.lr_pose),
            ("loose_window_secs", self.loose_window_secs),
        ];
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{key} = {value} must be a positive number"));
            }
        }
        if self.imu_batch == 0 {
            return Err("imu_batch = 0 must be at least 1".into());
        }
        Ok(())
    }
}

/// How a fit ended: its steps, why it stopped, and its mean errors on the poses it was given
/// (within the tolerance when it converged).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FitReport {
    /// Steps taken.
    #[serde(rename = "fit_steps")]
    pub steps: usize,
    /// Why it stopped.
    #[serde(rename = "fit_stop")]
    pub stop: StopReason,
    /// Whether the errors on the given poses are within the tolerance.
    #[serde(rename = "fit_converged")]
    pub converged: bool,
    /// Mean rotation error on the given poses, degrees.
    pub known_rot_err_deg: f64,
    /// Mean translation error on the given poses, metres.
    pub known_trans_err_m: f64,
    /// The pose loss: the mean of the last plateau window, else of the last step.
    #[serde(skip)]
    pub final_loss: f64,
}

/// The frame to fit a field to `poses` in, as `world_from_field` (see the module docs): the
/// chordal mean of their rotations, and their bounding box in that frame centred and scaled so
/// that its largest half-extent is ⅔.
///
/// # Panics
/// If `poses` is empty.
pub fn normalising_frame(poses: &[Isometry3<f64>]) -> Sim3 {
    let first = *poses[0].rotation.quaternion();
    let sum = poses
        .iter()
        .fold(Quaternion::new(0.0, 0.0, 0.0, 0.0), |acc, p| {
            let q = *p.rotation.quaternion();
            if q.coords.dot(&first.coords) < 0.0 {
                acc - q
            } else {
                acc + q
            }
        });
    let rotation = UnitQuaternion::new_normalize(sum);
    let rotated = poses
        .iter()
        .map(|p| rotation.inverse_transform_vector(&p.translation.vector));
    let lo = rotated
        .clone()
        .fold(Vector3::repeat(f64::INFINITY), |a, p| a.inf(&p));
    let hi = rotated.fold(Vector3::repeat(f64::NEG_INFINITY), |a, p| a.sup(&p));
    Sim3 {
        rotation: rotation.to_rotation_matrix(),
        translation: rotation * ((lo + hi) / 2.0),
        scale: 1.5 * ((hi - lo) / 2.0).max().max(1e-3),
    }
}

/// Poses and velocities of `field`, fitted in `frame`, in the world at `times_secs` (each
/// inside the field's range).
pub fn sample(
    field: &dyn PoseField,
    frame: &Sim3,
    times_secs: &[f64],
) -> anyhow::Result<Vec<FieldSample>> {
    let mut out = PoseBatch::default();
    field.evaluate(times_secs, Order::Velocity, &mut out)?;
    Ok((0..times_secs.len())
        .map(|i| FieldSample {
            t_secs: times_secs[i],
            pose: frame.transform_pose(&out.world_from_body(i)),
            ang_vel_body: out.ang_vel_body(i),
            lin_vel_world: frame.scale * (frame.rotation * out.lin_vel_world[i]),
        })
        .collect())
}

/// Fits `field` to `data` in the frame [`normalising_frame`] chooses, with the IMU terms of
/// `mode` and shuffles drawn from `seed`; returns the frame and how the fit ended.
pub fn fit(
    field: &mut dyn PoseField,
    data: FitData<'_>,
    settings: &FitSettings,
    mode: ImuMode,
    seed: u64,
) -> anyhow::Result<(Sim3, FitReport)> {
    ensure!(!data.poses.is_empty(), "a fit needs at least one pose");
    let frame = normalising_frame(data.poses);
    let mut fit = Fit::new(&*field, data, frame, settings, mode, seed)?;
    while !fit.step(field)? {}
    Ok((frame, fit.report(&*field)?))
}

/// One fit, a step at a time: for callers that report, checkpoint or resume it ([`fit`] runs
/// one to its end).
#[derive(Debug)]
pub struct Fit<'a> {
    data: FitData<'a>,
    settings: &'a FitSettings,
    mode: ImuMode,
    frame: Sim3,
    /// The poses in the field's frame.
    targets: Vec<Isometry3<f64>>,
    /// Gravity in the field's frame.
    gravity: Vector3<f64>,
    adam: Adam<f32>,
    grad: Vec<f32>,
    out: PoseBatch,
    cot: PoseBatch,
    imu_times: Vec<f64>,
    gyro: Vec<Vector3<f64>>,
    accel: Vec<Vector3<f64>>,
    pairs: Vec<(usize, usize, UnitQuaternion<f64>)>,
    /// A shuffle of the IMU readings and the next one to use.
    imu_order: Vec<usize>,
    cursor: usize,
    rng: ChaCha8Rng,
    convergence: Convergence,
    steps: usize,
    /// The total and the pose loss of the last step.
    loss: f64,
    pose_loss: f64,
    stopped: Option<StopReason>,
}

impl<'a> Fit<'a> {
    /// A fit of `field` to `data` in `frame` (`world_from_field`), not yet started. Errors on
    /// settings out of range, poses and times of different lengths, and an IMU mode without
    /// readings.
    pub fn new(
        field: &dyn PoseField,
        data: FitData<'a>,
        frame: Sim3,
        settings: &'a FitSettings,
        mode: ImuMode,
        seed: u64,
    ) -> anyhow::Result<Self> {
        settings.validate().map_err(anyhow::Error::msg)?;
        ensure!(
            data.times.len() == data.poses.len() && !data.poses.is_empty(),
            "a fit needs one time per pose and at least one pose, got {} times and {} poses",
            data.times.len(),
            data.poses.len()
        );
        ensure!(
            mode == ImuMode::None || !data.imu.is_empty(),
            "IMU mode {} needs IMU readings, got none",
            mode.key()
        );
        let field_from_world = frame.rotation.transpose();
        let targets = data
            .poses
            .iter()
            .map(|p| {
                let position = field_from_world * (p.translation.vector - frame.translation);
                Isometry3::from_parts(
                    Translation3::from(position / frame.scale),
                    UnitQuaternion::from_rotation_matrix(&field_from_world) * p.rotation,
                )
            })
            .collect();
        let batch = settings.imu_batch.min(data.imu.len()).max(1);
        Ok(Self {
            data,
            settings,
            mode,
            frame,
            targets,
            gravity: field_from_world * gravity_world(),
            adam: Adam::new(field.num_params()),
            grad: vec![0.0; field.num_params()],
            out: PoseBatch::default(),
            cot: PoseBatch::default(),
            imu_times: Vec::with_capacity(2 * batch),
            gyro: Vec::with_capacity(batch),
            accel: Vec::with_capacity(batch),
            pairs: Vec::with_capacity(batch),
            imu_order: (0..data.imu.len()).collect(),
            cursor: data.imu.len(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            convergence: Convergence::new(settings.stop),
            steps: 0,
            loss: f64::NAN,
            pose_loss: f64::NAN,
            stopped: None,
        })
    }

    /// The frame the field is fitted in (`world_from_field`).
    pub fn frame(&self) -> &Sim3 {
        &self.frame
    }

    /// Steps taken.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The loss of the last step, all terms weighted.
    pub fn loss(&self) -> f64 {
        self.loss
    }

    /// The next IMU reading of the seeded shuffle.
    fn next_reading(&mut self) -> usize {
        if self.cursor == self.imu_order.len() {
            self.imu_order.shuffle(&mut self.rng);
            self.cursor = 0;
        }
        self.cursor += 1;
        self.imu_order[self.cursor - 1]
    }

    /// One Adam step on the loss, then (every `stop.check_every` steps) the stop rule; returns
    /// whether the fit has ended (converged, on its last plateau or out of
    /// steps; later calls do nothing). Errors when the loss or its gradient is not finite.
    pub fn step(&mut self, field: &mut dyn PoseField) -> anyhow::Result<bool> {
        if self.stopped.is_some() {
            return Ok(true);
        }
        let s = self.settings;
        self.grad.fill(0.0);
        let times = self.data.times;
        field.forward(times, Order::Pose, &mut self.out)?;
        self.cot.reset(times.len(), Order::Pose);
        let mut loss = losses::pose_l2(
            &self.out,
            &self.targets,
            s.pose_weight,
            (1.0, 1.0),
            &mut self.cot,
        );
        field.backward(times, &self.cot, &mut self.grad)?;
        // The stop rule watches the pose term alone: IMU terms on real readings keep a floor of
        // sensor noise that would pass for a plateau while the poses are still far off.
        self.pose_loss = loss;
        let batch = s.imu_batch.min(self.data.imu.len()).max(1);
        if self.mode == ImuMode::Loose {
            // Windows [t, t + window] from the shuffled readings: the gyroscope integrated over
            // each supervises the rotation between its ends.
            self.imu_times.clear();
            self.pairs.clear();
            for _ in 0..batch {
                let t0 = self.data.imu[self.next_reading()].t_secs;
                let t1 = t0 + s.loose_window_secs;
                if let Some(dq) = losses::integrate_gyro(self.data.imu, t0, t1) {
                    let k = self.imu_times.len();
                    self.pairs.push((k, k + 1, dq));
                    self.imu_times.extend([t0, t1]);
                }
            }
            if !self.pairs.is_empty() {
                field.forward(&self.imu_times, Order::Pose, &mut self.out)?;
                self.cot.reset(self.imu_times.len(), Order::Pose);
                loss += losses::gyro_loose_l1(&self.out, &self.pairs, s.gyro_weight, &mut self.cot);
                field.backward(&self.imu_times, &self.cot, &mut self.grad)?;
            }
        } else if self.mode != ImuMode::None {
            self.imu_times.clear();
            self.gyro.clear();
            self.accel.clear();
            for _ in 0..batch {
                let r = self.data.imu[self.next_reading()];
                self.imu_times.push(r.t_secs);
                self.gyro.push(r.gyro);
                self.accel.push(r.accel);
            }
            let order = self.mode.order();
            field.forward(&self.imu_times, order, &mut self.out)?;
            self.cot.reset(batch, order);
            if self.mode.gyro() {
                loss += losses::gyro_tight_l1(&self.out, &self.gyro, s.gyro_weight, &mut self.cot);
            }
            if self.mode.accel() {
                loss += losses::accel_l1(
                    &self.out,
                    &self.accel,
                    &self.gravity,
                    self.frame.scale,
                    s.accel_weight,
                    &mut self.cot,
                );
            }
            field.backward(&self.imu_times, &self.cot, &mut self.grad)?;
        }
        if !loss.is_finite() || self.grad.iter().any(|x| !x.is_finite()) {
            bail!(
                "the loss or its gradient became {loss} at step {}; stopping this fit",
                self.steps
            );
        }
        let scale = self.convergence.lr_scale();
        self.adam.step_pose_field(field, &self.grad, |kind| {
            scale
                * match kind {
                    ParamKind::Translation => s.lr_translation,
                    ParamKind::Rotation => s.lr_rotation,
                    ParamKind::Pose => s.lr_pose,
                }
        });
        self.loss = loss;
        self.steps += 1;
        if self.convergence.observe(self.pose_loss) {
            let known = self.known_errors(&*field)?;
            self.stopped = self.convergence.check(self.within_tolerance(known));
        }
        if self.stopped.is_none() && self.steps >= s.iterations {
            self.stopped = Some(StopReason::Budget);
        }
        Ok(self.stopped.is_some())
    }

    /// Mean rotation (degrees) and translation (metres) errors of `field` in the world at
    /// `times` against `truth`.
    pub fn errors_at(
        &self,
        field: &dyn PoseField,
        times: &[f64],
        truth: &[Isometry3<f64>],
    ) -> anyhow::Result<(f64, f64)> {
        let estimated: Vec<Isometry3<f64>> = sample(field, &self.frame, times)?
            .iter()
            .map(|s| s.pose)
            .collect();
        let rot = error_stats(&ape_rotation_angle(truth, &estimated)?)?.mean;
        let trans = error_stats(&ape_translation(truth, &estimated)?)?.mean;
        Ok((rot.to_degrees(), trans))
    }

    /// Mean errors on the poses the fit is given.
    pub fn known_errors(&self, field: &dyn PoseField) -> anyhow::Result<(f64, f64)> {
        self.errors_at(field, self.data.times, self.data.poses)
    }

    fn within_tolerance(&self, (rot_deg, trans_m): (f64, f64)) -> bool {
        rot_deg <= self.settings.tolerance_deg && trans_m <= self.settings.tolerance_m
    }

    /// How the fit stands (or ended).
    pub fn report(&self, field: &dyn PoseField) -> anyhow::Result<FitReport> {
        let known = self.known_errors(field)?;
        Ok(FitReport {
            steps: self.steps,
            stop: self.stopped.unwrap_or(StopReason::Budget),
            converged: self.within_tolerance(known),
            known_rot_err_deg: known.0,
            known_trans_err_m: known.1,
            final_loss: self.convergence.last_mean().unwrap_or(self.pose_loss),
        })
    }

    /// Writes the field and the fit's state into a checkpoint.
    pub fn save(&self, field: &dyn PoseField, w: &mut Writer) {
        w.pose_field(field);
        w.adam(&self.adam);
        w.rng(&self.rng);
        let order: Vec<f64> = self.imu_order.iter().map(|&i| i as f64).collect();
        w.f64s(&order);
        w.u64(self.cursor as u64);
        w.f64(self.pose_loss);
        w.f64s(&self.convergence.state());
    }

    /// Restores the field and the fit's state from a checkpoint [`Fit::save`] wrote after
    /// `steps` steps.
    pub fn restore(
        &mut self,
        field: &mut dyn PoseField,
        steps: u64,
        r: &mut Reader,
    ) -> anyhow::Result<()> {
        r.pose_field(field)?;
        r.adam(&mut self.adam)?;
        self.rng = r.rng()?;
        let order = r.f64s()?;
        ensure!(
            order.len() == self.imu_order.len() && order.iter().all(|&i| i >= 0.0),
            "{}: the checkpoint's IMU order does not match",
            r.path().display()
        );
        self.imu_order = order.into_iter().map(|i| i as usize).collect();
        self.cursor = r.u64()? as usize;
        ensure!(
            self.cursor <= self.imu_order.len(),
            "{}: the checkpoint's IMU cursor is out of range",
            r.path().display()
        );
        self.pose_loss = r.f64()?;
        let state = r.f64s()?;
        self.convergence
            .set_state(state.as_slice().try_into().with_context(|| {
                format!(
                    "{}: the checkpoint's fit state is corrupt",
                    r.path().display()
                )
            })?);
        self.steps = steps as usize;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TimeRange;
    use crate::pose_field::SinusoidMotion;

    /// A hand-held motion, its poses at 20 Hz and its exact IMU at 200 Hz.
    fn motion_and_data() -> (
        SinusoidMotion<f64>,
        Vec<f64>,
        Vec<Isometry3<f64>>,
        Vec<ImuSample>,
    ) {
        let range = TimeRange::new(0.0, 2.0).unwrap();
        let motion = SinusoidMotion::<f64>::handheld(range, 3);
        let times: Vec<f64> = (0..=40).map(|i| 0.05 * i as f64).collect();
        let mut out = PoseBatch::default();
        motion.evaluate(&times, Order::Pose, &mut out).unwrap();
        let poses = (0..times.len()).map(|i| out.world_from_body(i)).collect();
        let imu_times: Vec<f64> = (0..=400).map(|i| 0.005 * i as f64).collect();
        motion
            .evaluate(&imu_times, Order::Acceleration, &mut out)
            .unwrap();
        let imu = imu_times
            .iter()
            .enumerate()
            .map(|(i, &t_secs)| ImuSample {
                t_secs,
                gyro: out.ang_vel_body(i),
                accel: crate::geometry::specific_force_body(
                    &out.world_from_body(i).rotation,
                    &out.lin_acc_world[i],
                    &gravity_world(),
                ),
            })
            .collect();
        (motion, times, poses, imu)
    }

    #[test]
    fn the_normalising_frame_maps_the_poses_into_the_unit_box_and_back() {
        let (_, _, poses, _) = motion_and_data();
        let frame = normalising_frame(&poses);
        let field_from_world = frame.rotation.transpose();
        for p in &poses {
            let x = field_from_world * (p.translation.vector - frame.translation) / frame.scale;
            assert!(x.amax() <= 2.0 / 3.0 + 1e-12, "{x}");
            let back = frame.transform_vector(&x);
            assert!((back - p.translation.vector).norm() < 1e-12);
        }
    }

    /// A spline fitted to poses and the exact IMU moves towards them, and a checkpoint taken on
    /// the way resumes to the same parameters as the uninterrupted fit.
    #[test]
    fn a_fit_converges_and_resumes_from_a_checkpoint_exactly() {
        let (_, times, poses, imu) = motion_and_data();
        let range = TimeRange::new(0.0, 2.0).unwrap();
        let settings = FitSettings {
            iterations: 600,
            ..FitSettings::default()
        };
        let data = FitData {
            times: &times,
            poses: &poses,
            imu: &imu,
        };
        let spline = || {
            let config = crate::SplineConfig {
                control_points: 24,
                ..Default::default()
            };
            config.init::<f32>(range, &[]).unwrap()
        };
        let mut whole = spline();
        let frame = normalising_frame(&poses);
        let mut fit = Fit::new(&whole, data, frame, &settings, ImuMode::Combined, 5).unwrap();
        let start = fit.report(&whole).unwrap();
        let mut saved = None;
        while !fit.step(&mut whole).unwrap() {
            if fit.steps() == 50 {
                let mut w = Writer::new();
                fit.save(&whole, &mut w);
                saved = Some(w);
            }
        }
        let report = fit.report(&whole).unwrap();
        assert!(
            report.known_rot_err_deg < 0.6 * start.known_rot_err_deg
                && report.known_trans_err_m < 0.6 * start.known_trans_err_m,
            "{start:?} to {report:?}"
        );

        let dir = crate::testing::TempDir::new("fit-resume");
        let path = dir.join("fit.bin");
        saved.unwrap().save(&path).unwrap();
        let mut resumed = spline();
        let mut fit = Fit::new(&resumed, data, frame, &settings, ImuMode::Combined, 5).unwrap();
        fit.restore(&mut resumed, 50, &mut Reader::open(&path).unwrap())
            .unwrap();
        while !fit.step(&mut resumed).unwrap() {}
        assert_eq!(fit.report(&resumed).unwrap(), report);
        let (a, b) = (
            crate::pose_field::params_to_vec(&whole),
            crate::pose_field::params_to_vec(&resumed),
        );
        assert_eq!(a, b);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (_, times, poses, _) = motion_and_data();
        let range = TimeRange::new(0.0, 2.0).unwrap();
        let field = SinusoidMotion::<f32>::handheld(range, 1);
        let settings = FitSettings::default();
        let frame = normalising_frame(&poses);
        let short = FitData {
            times: &times[1..],
            poses: &poses,
            imu: &[],
        };
        let err = Fit::new(&field, short, frame, &settings, ImuMode::None, 0).unwrap_err();
        assert!(
            err.to_string().contains("got 40 times and 41 poses"),
            "{err}"
        );
        let data = FitData {
            times: &times,
            poses: &poses,
            imu: &[],
        };
        let err = Fit::new(&field, data, frame, &settings, ImuMode::Tight, 0).unwrap_err();
        assert!(
            err.to_string()
                .contains("IMU mode tight needs IMU readings"),
            "{err}"
        );
        let bad = FitSettings {
            lr_rotation: f64::NAN,
            ..FitSettings::default()
        };
        let err = Fit::new(&field, data, frame, &bad, ImuMode::None, 0).unwrap_err();
        assert!(err.to_string().contains("lr_rotation = NaN"), "{err}");
    }
}
