//! The camera poses of the training frames as a correction of their initial poses in world
//! coordinates: `world_from_cam_i = C(t_i) ∘ init_i`. This is the paper's supplement
//! (`T_{c',w} = T_init ∘ T_refine` on camera-from-world poses, `C = T_refine⁻¹`) and BARF's
//! `compose([Exp(δξ_i), P⁰_i])`, where `compose([a, b])` applies `a` first, to world points. The
//! initial noise acts the same way ([`crate::scene::PoseNoise`]), so a correction can undo it
//! exactly. The correction `C` is any [`PoseField`] that starts at the identity — PoseNet on
//! time, BARF's free se(3) per frame, a B-spline — or none (poses held fixed, e.g. at the truth
//! for the reference run).
//!
//! # Gradient
//!
//! With `init = (q₀, t₀)` and `C = (q_c, t_c)`: `q = q_c ⊗ q₀`, `t = R(q_c) t₀ + t_c`. Right
//! multiplication by the unit `q₀` is an orthogonal map of R⁴, so the first term of `∂L/∂q_c`
//! is `∂L/∂q ⊗ q₀*`; the second is the quaternion gradient of `R(q_c) t₀` for the cotangent
//! `∂L/∂t` (the homogeneous rotation of [`PoseGradient`], one "ray" of direction `t₀`); and
//! `∂L/∂t_c = ∂L/∂t`.

use cpose_core::checkpoint::{Reader, Writer};
use cpose_core::eval::Sim3;
use cpose_core::nn::{Adam, ExponentialDecay};
use cpose_core::pose_field::saved::SavedPoseField;
use cpose_core::{FieldContext, TimeRange};
use cpose_core::{Order, ParamKind, PoseBatch, PoseField};
use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};

use crate::camera::PoseGradient;

/// Learning-rate schedules of a correction, by parameter kind. The decays run over the steps
/// after the hold: a held pose starts its schedule when the hold ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseSchedules {
    /// Rotation parameters (PoseNet's rotation network).
    pub rotation: ExponentialDecay,
    /// Translation parameters (PoseNet's translation network).
    pub translation: ExponentialDecay,
    /// Parameters that move both (per-frame se(3), spline control poses).
    pub pose: ExponentialDecay,
    /// Steps during which the poses are held: not moved, their gradients not even computed,
    /// while the field learns to explain the images from the initial poses. A field that is
    /// still blank or blurred gives pose gradients that move even true poses by degrees.
    pub hold: u64,
    /// Steps after the hold over which every rate ramps up linearly from 0 (0: none).
    pub warmup: u64,
    /// Steps after the hold over which the rotation rates ramp up instead (PoseNet's rotation
    /// network; per-frame and spline parameters, which move both, follow `warmup`).
    pub rotation_warmup: u64,
}

impl PoseSchedules {
    /// Whether the poses are held at iteration `it`.
    pub fn is_held(&self, it: u64) -> bool {
        it < self.hold
    }

    /// The learning rate of `kind`'s parameters at iteration `it`: 0 during the hold, then the
    /// warm-up ramp on the rate decaying from the hold's end.
    pub fn lr(&self, kind: ParamKind, it: u64) -> f64 {
        let Some(after) = it.checked_sub(self.hold) else {
            return 0.0;
        };
        match kind {
            ParamKind::Rotation => ramp(after, self.rotation_warmup) * self.rotation.lr(after),
            ParamKind::Translation => ramp(after, self.warmup) * self.translation.lr(after),
            ParamKind::Pose => ramp(after, self.warmup) * self.pose.lr(after),
        }
    }
}

/// A task's pose hold and warm-ups, as fractions of its steps (the `[train]` keys
/// `pose_hold`, `pose_warmup` and `rotation_warmup`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseTiming {
    /// The hold ([`PoseSchedules::hold`]).
    pub hold: f64,
    /// The warm-up after it ([`PoseSchedules::warmup`]).
    pub warmup: f64,
    /// The rotation's warm-up after it ([`PoseSchedules::rotation_warmup`]).
    pub rotation_warmup: f64,
}

impl PoseTiming {
    /// `(hold, warmup, rotation_warmup)` in steps of a run of `iterations`. Errors name the
    /// `[train]` key that is not a fraction, or a hold that leaves the poses no steps once its
    /// warm-ups are done.
    pub fn steps(&self, iterations: usize) -> anyhow::Result<(u64, u64, u64)> {
        for (key, value) in [
            ("pose_hold", self.hold),
            ("pose_warmup", self.warmup),
            ("rotation_warmup", self.rotation_warmup),
        ] {
            if !(0.0..=1.0).contains(&value) {
                anyhow::bail!(
                    "[train] {key} = {value} must lie in [0, 1] (a fraction of the steps)"
                );
            }
        }
        let longest = self.warmup.max(self.rotation_warmup);
        if self.hold >= 1.0 || self.hold + longest > 1.0 {
            anyhow::bail!(
                "[train] pose_hold = {} with a warm-up of {longest} is longer than the schedule: \
                 the poses would not reach their full rate in {iterations} steps; hold + warm-up \
                 must be at most 1",
                self.hold
            );
        }
        let steps = |fraction: f64| (fraction * iterations as f64).round() as u64;
        Ok((
            steps(self.hold),
            steps(self.warmup),
            steps(self.rotation_warmup),
        ))
    }
}

/// The warm-up factor at iteration `it`, `min(1, (it + 1) / steps)`; 1 when `steps` is 0.
fn ramp(it: u64, steps: u64) -> f64 {
    if steps == 0 {
        1.0
    } else {
        ((it + 1) as f64 / steps as f64).min(1.0)
    }
}

/// Per-frame poses `C(t_i) ∘ init_i` and their optimiser.
pub struct FramePoses {
    init: Vec<Isometry3<f64>>,
    times: Vec<f64>,
    correction: Option<Box<dyn PoseField>>,
    schedules: PoseSchedules,
    adam: Adam<f32>,
    batch: PoseBatch,
    cotangent: PoseBatch,
    grad: Vec<f32>,
    current: Vec<Isometry3<f64>>,
}

impl FramePoses {
    /// Poses `correction(t_i) ∘ init_i`; `correction = None` keeps `init`.
    pub fn new(
        init: Vec<Isometry3<f64>>,
        times: Vec<f64>,
        correction: Option<Box<dyn PoseField>>,
        schedules: PoseSchedules,
    ) -> Self {
        assert_eq!(init.len(), times.len(), "one initial pose per frame time");
        let n = correction.as_ref().map_or(0, |c| c.num_params());
        Self {
            current: init.clone(),
            init,
            times,
            correction,
            schedules,
            adam: Adam::new(n),
            batch: PoseBatch::default(),
            cotangent: PoseBatch::default(),
            grad: vec![0.0; n],
        }
    }

    /// Whether the poses are optimised at all.
    pub fn is_trainable(&self) -> bool {
        self.correction.is_some()
    }

    /// Whether the poses are optimised at iteration `it`: trainable and not held
    /// ([`PoseSchedules::hold`]).
    pub fn is_trained_at(&self, it: u64) -> bool {
        self.is_trainable() && !self.schedules.is_held(it)
    }

    /// Replaces the frames — their initial poses and times — keeping the correction and its
    /// optimiser state: for poses queried at new times every step (event windows). Reuses the
    /// buffers.
    pub fn set_frames(&mut self, init: &[Isometry3<f64>], times: &[f64]) {
        assert_eq!(init.len(), times.len(), "one initial pose per frame time");
        self.init.clear();
        self.init.extend_from_slice(init);
        self.times.clear();
        self.times.extend_from_slice(times);
        self.current.clear();
        self.current.extend_from_slice(init);
    }

    /// The frame times.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Evaluates the correction at `progress` (its coarse-to-fine schedule) and returns the
    /// current `world_from_cam` of every frame.
    pub fn update(&mut self, progress: f64) -> anyhow::Result<&[Isometry3<f64>]> {
        if let Some(c) = self.correction.as_mut() {
            c.set_progress(progress);
            c.forward(&self.times, Order::Pose, &mut self.batch)?;
            for (i, (pose, init)) in self.current.iter_mut().zip(&self.init).enumerate() {
                *pose = self.batch.world_from_body(i) * init;
            }
        }
        Ok(&self.current)
    }

    /// The poses of the last [`FramePoses::update`].
    pub fn current(&self) -> &[Isometry3<f64>] {
        &self.current
    }

    /// The initial poses.
    pub fn initial(&self) -> &[Isometry3<f64>] {
        &self.init
    }

    /// One optimiser step at iteration `it` from `∂L/∂q` (raw, w first) and `∂L/∂t` of every
    /// frame's `world_from_cam` as returned by the last [`FramePoses::update`]; nothing while
    /// the poses are held.
    pub fn step(
        &mut self,
        grads: &[(Quaternion<f64>, Vector3<f64>)],
        it: u64,
    ) -> anyhow::Result<()> {
        let Some(c) = self.correction.as_mut() else {
            return Ok(());
        };
        if self.schedules.is_held(it) {
            return Ok(());
        }
        let n = self.times.len();
        assert_eq!(grads.len(), n, "one pose gradient per frame");
        self.cotangent.reset(n, Order::Pose);
        for (i, ((gq, gt), init)) in grads.iter().zip(&self.init).enumerate() {
            let q_c = UnitQuaternion::new_normalize(self.batch.rotation[i]);
            (self.cotangent.rotation[i], self.cotangent.translation[i]) =
                correction_cotangent(init, &q_c, gq, gt);
        }
        self.grad.fill(0.0);
        c.backward(&self.times, &self.cotangent, &mut self.grad)?;
        let s = self.schedules;
        self.adam
            .step_pose_field(c.as_mut(), &self.grad, |kind| s.lr(kind, it));
        Ok(())
    }

    /// The correction's parameters, flat.
    pub fn params(&self) -> Vec<f32> {
        self.correction
            .as_deref()
            .map(cpose_core::pose_field::params_to_vec)
            .unwrap_or_default()
    }

    /// Writes the correction's parameters and its optimiser's state to a checkpoint.
    pub fn write_state(&self, w: &mut Writer) {
        w.u64(u64::from(self.correction.is_some()));
        if let Some(c) = self.correction.as_deref() {
            w.pose_field(c);
        }
        w.adam(&self.adam);
    }

    /// Restores what [`FramePoses::write_state`] wrote, into poses of the same kind and size.
    pub fn read_state(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        let stored = r.u64()? == 1;
        if stored != self.correction.is_some() {
            anyhow::bail!(
                "{}: the checkpoint's poses {} a correction, these {}",
                r.path().display(),
                if stored { "have" } else { "have no" },
                if stored { "none" } else { "one" },
            );
        }
        if let Some(c) = self.correction.as_deref_mut() {
            r.pose_field(c)?;
        }
        r.adam(&mut self.adam)
    }
}

/// `(∂L/∂q_c, ∂L/∂t_c)` of the correction `C = (q_c, t_c)` in `C ∘ init` from `(∂L/∂q, ∂L/∂t)`
/// of the composed pose (module docs).
pub fn correction_cotangent(
    init: &Isometry3<f64>,
    q_c: &UnitQuaternion<f64>,
    grad_q: &Quaternion<f64>,
    grad_t: &Vector3<f64>,
) -> (Quaternion<f64>, Vector3<f64>) {
    let mut lever = PoseGradient::new();
    lever.add_ray(init.translation.vector.into(), [0.0; 3], (*grad_t).into());
    let (g_rot, _) = lever.quaternion_translation(q_c);
    (
        grad_q * init.rotation.conjugate().into_inner() + g_rot,
        *grad_t,
    )
}

/// Saves the cameras `C(t) ∘ init(t)` of a trained correction as one pose field at `path`, for
/// `cpose query`: a `composed` field of the correction (`table`, the registry's `kind` and
/// settings, and its flat parameters) and `init`, the initial poses at `times`, as a `discrete`
/// field (exact at those times up to its `f32` parameters, about 1e-4 of the scene's size;
/// between them, their se(3) tangents are interpolated), expressed in `frame`.
pub fn save_corrected_field(
    path: &std::path::Path,
    (table, mut params): (&str, Vec<f32>),
    times: &[f64],
    init: &[Isometry3<f64>],
    frame: Sim3,
) -> anyhow::Result<()> {
    let discrete = cpose_core::DiscretePoses::<f32>::from_poses(times, init)?;
    params.extend(cpose_core::pose_field::params_to_vec(&discrete));
    let saved = SavedPoseField {
        config: format!(
            "[field]\nkind = \"composed\"\n[field.a]\n{table}[field.b]\nkind = \"discrete\"\n"
        ),
        context: FieldContext {
            time_range: TimeRange::new(times[0], times[times.len() - 1])?,
            frame_times_secs: times.to_vec(),
            seed: 0,
        },
        frame,
        params,
    };
    saved.write(path)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector4};

    use super::*;

    /// A smooth function of a raw quaternion and a translation.
    fn loss(q: &Quaternion<f64>, t: &Vector3<f64>) -> f64 {
        let a = Vector4::new(0.3, -1.2, 0.7, 0.4);
        (q.coords.dot(&a)).sin() + q.coords.norm_squared() * t.x + t.y * t.z - 0.5 * t.x
    }

    fn grad(q: &Quaternion<f64>, t: &Vector3<f64>) -> (Quaternion<f64>, Vector3<f64>) {
        let a = Vector4::new(0.3, -1.2, 0.7, 0.4);
        let gq = a * q.coords.dot(&a).cos() + q.coords * (2.0 * t.x);
        let gt = Vector3::new(q.coords.norm_squared() - 0.5, t.z, t.y);
        (Quaternion::from(gq), gt)
    }

    #[test]
    fn warmups_ramp_linearly_to_one_the_rotation_over_its_own_steps() {
        let decay = ExponentialDecay {
            lr0: 1e-3,
            lr_end: 1e-5,
            max_iter: 100,
        };
        let s = PoseSchedules {
            rotation: decay,
            translation: decay,
            pose: decay,
            hold: 0,
            warmup: 4,
            rotation_warmup: 8,
        };
        let factors: Vec<f64> = (0..6).map(|it| ramp(it, s.warmup)).collect();
        assert_eq!(factors, [0.25, 0.5, 0.75, 1.0, 1.0, 1.0]);
        let rate = |kind, it| s.lr(kind, it) / decay.lr(it);
        assert!((rate(ParamKind::Translation, 1) - 0.5).abs() < 1e-12);
        assert!((rate(ParamKind::Pose, 1) - 0.5).abs() < 1e-12);
        assert!((rate(ParamKind::Rotation, 1) - 0.25).abs() < 1e-12);
        assert!((rate(ParamKind::Rotation, 7) - 1.0).abs() < 1e-12);
        assert_eq!(ramp(0, 0), 1.0);
    }

    #[test]
    fn timings_in_steps_and_holds_longer_than_the_schedule_are_errors() {
        let timing = PoseTiming {
            hold: 0.1,
            warmup: 0.05,
            rotation_warmup: 0.2,
        };
        assert_eq!(timing.steps(1000).unwrap(), (100, 50, 200));
        let long = PoseTiming {
            hold: 0.9,
            ..timing
        };
        let e = long.steps(1000).unwrap_err().to_string();
        assert!(
            e.contains("pose_hold = 0.9") && e.contains("longer than the schedule"),
            "{e}"
        );
        let bad = PoseTiming {
            warmup: f64::NAN,
            ..timing
        };
        assert!(
            bad.steps(1000)
                .unwrap_err()
                .to_string()
                .contains("pose_warmup")
        );
    }

    #[test]
    fn a_hold_keeps_the_rates_at_zero_then_the_warm_up_starts() {
        let decay = ExponentialDecay {
            lr0: 1e-3,
            lr_end: 1e-5,
            max_iter: 100,
        };
        let s = PoseSchedules {
            rotation: decay,
            translation: decay,
            pose: decay,
            hold: 10,
            warmup: 4,
            rotation_warmup: 4,
        };
        assert!(s.is_held(9) && !s.is_held(10));
        for kind in [ParamKind::Rotation, ParamKind::Translation, ParamKind::Pose] {
            assert_eq!(s.lr(kind, 9), 0.0);
            // The decay starts where the hold ends.
            assert!((s.lr(kind, 10) / decay.lr(0) - 0.25).abs() < 1e-12);
            assert!((s.lr(kind, 13) / decay.lr(3) - 1.0).abs() < 1e-12);
        }
    }

    /// The loss of `(q_c, t_c) ∘ init` with the composition written on raw quaternions,
    /// `q = q_c ⊗ q₀`, `t = q_c ⊗ (0, t₀) ⊗ q_c* + t_c`, against central differences in
    /// `(q_c, t_c)` at a unit `q_c`.
    #[test]
    fn correction_cotangent_matches_central_differences() {
        let init = Isometry3::from_parts(
            Translation3::new(0.4, -2.0, 1.1),
            UnitQuaternion::from_euler_angles(0.3, 1.2, -0.8),
        );
        let qc = Quaternion::new(0.9, 0.1, -0.3, 0.2).normalize();
        let tc = Vector3::new(0.2, 0.5, -0.1);
        let composed = |qc: &Quaternion<f64>, tc: &Vector3<f64>| {
            let q = qc * init.rotation.into_inner();
            let t0 = Quaternion::from_imag(init.translation.vector);
            let t = (qc * t0 * qc.conjugate()).imag() + tc;
            loss(&q, &t)
        };
        let unit = UnitQuaternion::new_unchecked(qc);
        let q = qc * init.rotation.into_inner();
        let t = unit * init.translation.vector + tc;
        let (gq, gt) = grad(&q, &t);
        let (gqc, gtc) = correction_cotangent(&init, &unit, &gq, &gt);
        let h = 1e-6;
        for k in 0..4 {
            let mut e = Vector4::zeros();
            e[k] = h;
            let fd = (composed(&Quaternion::from(qc.coords + e), &tc)
                - composed(&Quaternion::from(qc.coords - e), &tc))
                / (2.0 * h);
            assert!(
                (fd - gqc.coords[k]).abs() < 1e-8,
                "q[{k}]: {fd} vs {}",
                gqc.coords[k]
            );
        }
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let fd = (composed(&qc, &(tc + e)) - composed(&qc, &(tc - e))) / (2.0 * h);
            assert!((fd - gtc[k]).abs() < 1e-8, "t[{k}]: {fd} vs {}", gtc[k]);
        }
    }
}
