//! Pose models for tracking: how the camera pose of the frame being tracked is parametrised
//! while the tracking loss is minimised, and what is kept afterwards.
//!
//! * [`FreePose`], NICE-SLAM's baseline: a free quaternion and translation of
//!   `world_from_camera` (the quaternion unnormalised; the rotation is that of `q/‖q‖`), started
//!   from the constant-velocity prediction `T_{i−1} T_{i−2}⁻¹ T_{i−1}`.
//! * [`PoseNetTracker`], the paper's §3.3: `T_i = T_ref ∘ PN(t_i)` where PoseNet gives the motion
//!   relative to a reference frame — the previous camera `T_{i−1}` (the paper's default), the first
//!   camera (`world`), or the previous camera perturbed by a random transform (`random`). The
//!   network's weights are what tracking optimises, so it starts every frame from its own
//!   prediction `PN(t_i)`. The best relative pose of every tracked frame is kept, and after each
//!   frame PoseNet is re-fitted on that list (a batch of earlier frames plus the newest), so it
//!   stays a consistent function of time.
//!
//! Both receive the gradient of the loss with respect to `world_from_camera` as raw partials
//! `(∂L/∂q, ∂L/∂t)` ([`cpose_nerf::camera::PoseGradient::quaternion_translation`]).

use cpose_core::nn::Adam;
use cpose_core::pose_field::posenet::PoseNetConfig;
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, TimeRange};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A parametrisation of the tracked pose.
pub trait PoseModel: Send {
    /// Starts tracking frame `index` at `time` (seconds) given the estimates of the frames before
    /// it (`history.len() == index ≥ 1`); returns the starting pose.
    fn begin(
        &mut self,
        index: usize,
        time: f64,
        history: &[Isometry3<f64>],
    ) -> anyhow::Result<Isometry3<f64>>;
    /// The current pose.
    fn pose(&self) -> Isometry3<f64>;
    /// One optimiser step from the loss gradient at [`PoseModel::pose`].
    fn step(&mut self, grad_q: &Quaternion<f64>, grad_t: &Vector3<f64>) -> anyhow::Result<()>;
    /// Ends frame `index` with its chosen pose (the best-loss candidate).
    fn finish(&mut self, index: usize, time: f64, pose: &Isometry3<f64>) -> anyhow::Result<()>;
    /// Parameters to checkpoint (flat).
    fn state(&self) -> Vec<f32> {
        Vec::new()
    }
    /// Restores [`PoseModel::state`].
    fn restore(&mut self, state: &[f32]) -> anyhow::Result<()> {
        let _ = state;
        Ok(())
    }
}

/// `∂L/∂q` of the unit quaternion `q/‖q‖` pulled back to the raw `q`:
/// `(I − q̂ q̂ᵀ) g / ‖q‖`.
fn through_normalisation(q: &Quaternion<f64>, g: &Quaternion<f64>) -> Quaternion<f64> {
    let n = q.norm();
    let u = q.coords / n;
    Quaternion::from((g.coords - u * u.dot(&g.coords)) / n)
}

/// NICE-SLAM's free pose: Adam on `(q, t)`, rotation learning rate `lr · rotation_lr_factor`.
pub struct FreePose {
    q: Quaternion<f64>,
    t: Vector3<f64>,
    adam: Adam<f64>,
    lr: f64,
    rotation_lr_factor: f64,
}

impl FreePose {
    /// A free pose with learning rate `lr` (NICE-SLAM Replica 1e-3) and the rotation's factor
    /// (TUM's `seperate_LR`: 0.2; otherwise 1).
    pub fn new(lr: f64, rotation_lr_factor: f64) -> Self {
        Self {
            q: Quaternion::identity(),
            t: Vector3::zeros(),
            adam: Adam::new(7),
            lr,
            rotation_lr_factor,
        }
    }
}

impl PoseModel for FreePose {
    fn begin(
        &mut self,
        index: usize,
        _time: f64,
        history: &[Isometry3<f64>],
    ) -> anyhow::Result<Isometry3<f64>> {
        let prev = history[index - 1];
        let start = if index >= 2 {
            prev * history[index - 2].inverse() * prev
        } else {
            prev
        };
        self.q = start.rotation.into_inner();
        self.t = start.translation.vector;
        self.adam = Adam::new(7); // a new optimiser per frame, as NICE-SLAM
        Ok(start)
    }

    fn pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.t),
            UnitQuaternion::new_normalize(self.q),
        )
    }

    fn step(&mut self, grad_q: &Quaternion<f64>, grad_t: &Vector3<f64>) -> anyhow::Result<()> {
        let gq = through_normalisation(&self.q, grad_q);
        let mut p = [self.q.w, self.q.i, self.q.j, self.q.k];
        let g = [gq.w, gq.i, gq.j, gq.k];
        let mut t: [f64; 3] = self.t.into();
        self.adam.begin_step();
        self.adam
            .update(0, &mut p, &g, self.lr * self.rotation_lr_factor);
        self.adam
            .update(4, &mut t, &[grad_t.x, grad_t.y, grad_t.z], self.lr);
        self.q = Quaternion::new(p[0], p[1], p[2], p[3]);
        self.t = Vector3::from(t);
        Ok(())
    }

    fn finish(&mut self, _index: usize, _time: f64, _pose: &Isometry3<f64>) -> anyhow::Result<()> {
        Ok(())
    }
}

/// The frame PoseNet's relative motion is expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Reference {
    /// The previous camera, `T_ref = T_{i−1}` (the paper's default).
    Previous,
    /// The first camera, `T_ref = T_0` (the paper's "world").
    World,
    /// The previous camera moved by a random transform drawn per frame,
    /// `T_ref = T_{i−1} ∘ Exp(ξ)`, `ξ ~ N(0, diag(σ_r² I, σ_t² I))`.
    Random,
}

/// PoseNet tracking settings; `[posenet]` in a `slam` config (its network under
/// `[posenet.network]`).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PoseNetTrackConfig {
    /// The network (bands, depth, width, translation bound …).
    pub network: PoseNetConfig,
    /// Adam learning rate of the translation network while tracking.
    pub lr_translation: f64,
    /// Adam learning rate of the rotation network while tracking.
    pub lr_rotation: f64,
    /// Re-fitting steps after each frame.
    pub refit_steps: usize,
    /// Earlier frames per re-fitting step (plus the newest).
    pub refit_batch: usize,
    /// Rotation spread of the random reference, radians.
    pub random_rotation: f64,
    /// Translation spread of the random reference, metres.
    pub random_translation: f64,
}

impl Default for PoseNetTrackConfig {
    fn default() -> Self {
        Self {
            network: PoseNetConfig {
                bands: 5,
                depth: 4,
                width: 128,
                skip_layer: 2,
                ..PoseNetConfig::default()
            },
            lr_translation: 1e-3,
            lr_rotation: 5e-4,
            refit_steps: 5,
            refit_batch: 32,
            random_rotation: 0.05,
            random_translation: 0.05,
        }
    }
}

/// PoseNet relative to a reference frame (module docs).
pub struct PoseNetTracker {
    net: Box<dyn PoseField<f32>>,
    config: PoseNetTrackConfig,
    reference: Reference,
    adam: Adam<f32>,
    grad: Vec<f32>,
    batch: PoseBatch,
    cotangent: PoseBatch,
    /// The reference of the frame being tracked.
    current_ref: Isometry3<f64>,
    /// PoseNet's output at the frame being tracked.
    current_rel: Isometry3<f64>,
    time: f64,
    /// `(t_j, T_ref_j⁻¹ T_j)` of every tracked frame.
    memory: Vec<(f64, Isometry3<f64>)>,
    first: Isometry3<f64>,
    rng: ChaCha8Rng,
}

impl PoseNetTracker {
    /// A PoseNet over the sequence's `range` at the identity.
    pub fn new(
        config: &PoseNetTrackConfig,
        reference: Reference,
        range: TimeRange,
        seed: u64,
    ) -> anyhow::Result<Self> {
        let mut network = config.network.clone();
        network.seed = network.seed.wrapping_add(seed);
        let net: Box<dyn PoseField<f32>> = Box::new(network.init::<f32>(range)?);
        let n = net.num_params();
        Ok(Self {
            net,
            config: config.clone(),
            reference,
            adam: Adam::new(n),
            grad: vec![0.0; n],
            batch: PoseBatch::default(),
            cotangent: PoseBatch::default(),
            current_ref: Isometry3::identity(),
            current_rel: Isometry3::identity(),
            time: 0.0,
            memory: Vec::new(),
            first: Isometry3::identity(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_7AC4),
        })
    }

    /// Evaluates the network at the current time.
    fn evaluate(&mut self) -> anyhow::Result<()> {
        self.net
            .forward(&[self.time], Order::Pose, &mut self.batch)?;
        self.current_rel = self.batch.world_from_body(0);
        Ok(())
    }

    fn lr(&self, kind: ParamKind) -> f64 {
        match kind {
            ParamKind::Rotation => self.config.lr_rotation,
            _ => self.config.lr_translation,
        }
    }

    /// Re-fits the network on its memory: a few Adam steps on the mean squared pose error
    /// (quaternion sign-aligned) over the newest frame and a random batch of earlier ones.
    fn refit(&mut self) -> anyhow::Result<()> {
        let n = self.memory.len();
        if n == 0 {
            return Ok(());
        }
        let mut picks: Vec<usize> = (0..n - 1).collect();
        for _ in 0..self.config.refit_steps {
            picks.shuffle(&mut self.rng);
            let mut chosen: Vec<usize> = picks
                .iter()
                .take(self.config.refit_batch)
                .copied()
                .collect();
            chosen.push(n - 1);
            let times: Vec<f64> = chosen.iter().map(|&j| self.memory[j].0).collect();
            self.net.forward(&times, Order::Pose, &mut self.batch)?;
            self.cotangent.reset(times.len(), Order::Pose);
            let w = 1.0 / times.len() as f64;
            for (k, &j) in chosen.iter().enumerate() {
                let target = &self.memory[j].1;
                let mut tq = target.rotation.into_inner();
                let q = self.batch.rotation[k];
                if q.coords.dot(&tq.coords) < 0.0 {
                    tq = -tq;
                }
                self.cotangent.rotation[k] = (q - tq) * (2.0 * w);
                self.cotangent.translation[k] =
                    (self.batch.translation[k] - target.translation.vector) * (2.0 * w);
            }
            self.grad.fill(0.0);
            self.net.backward(&times, &self.cotangent, &mut self.grad)?;
            let (lr_r, lr_t) = (self.config.lr_rotation, self.config.lr_translation);
            self.adam
                .step_pose_field(self.net.as_mut(), &self.grad, |kind| match kind {
                    ParamKind::Rotation => lr_r,
                    _ => lr_t,
                });
        }
        Ok(())
    }
}

impl PoseModel for PoseNetTracker {
    fn begin(
        &mut self,
        index: usize,
        time: f64,
        history: &[Isometry3<f64>],
    ) -> anyhow::Result<Isometry3<f64>> {
        self.first = history[0];
        self.current_ref = match self.reference {
            Reference::Previous => history[index - 1],
            Reference::World => self.first,
            Reference::Random => {
                let g = |rng: &mut ChaCha8Rng| {
                    let u1: f64 = rng.random::<f64>().max(1e-300);
                    let u2: f64 = rng.random();
                    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
                };
                let (sr, st) = (self.config.random_rotation, self.config.random_translation);
                let w = Vector3::new(g(&mut self.rng), g(&mut self.rng), g(&mut self.rng)) * sr;
                let v = Vector3::new(g(&mut self.rng), g(&mut self.rng), g(&mut self.rng)) * st;
                history[index - 1]
                    * Isometry3::from_parts(
                        Translation3::from(v),
                        UnitQuaternion::from_scaled_axis(w),
                    )
            }
        };
        self.time = time;
        self.evaluate()?;
        Ok(self.pose())
    }

    fn pose(&self) -> Isometry3<f64> {
        self.current_ref * self.current_rel
    }

    fn step(&mut self, grad_q: &Quaternion<f64>, grad_t: &Vector3<f64>) -> anyhow::Result<()> {
        // T = A ∘ P: q = q_A ⊗ q_P, t = R_A t_P + t_A, so ∂L/∂q_P = q_A* ⊗ ∂L/∂q and
        // ∂L/∂t_P = R_Aᵀ ∂L/∂t (left multiplication by a unit quaternion is orthogonal).
        let a = &self.current_ref;
        self.cotangent.reset(1, Order::Pose);
        self.cotangent.rotation[0] = a.rotation.conjugate().into_inner() * grad_q;
        self.cotangent.translation[0] = a.rotation.inverse() * grad_t;
        self.grad.fill(0.0);
        self.net
            .backward(&[self.time], &self.cotangent, &mut self.grad)?;
        let (lr_r, lr_t) = (
            self.lr(ParamKind::Rotation),
            self.lr(ParamKind::Translation),
        );
        self.adam
            .step_pose_field(self.net.as_mut(), &self.grad, |kind| match kind {
                ParamKind::Rotation => lr_r,
                _ => lr_t,
            });
        self.evaluate()
    }

    fn finish(&mut self, _index: usize, time: f64, pose: &Isometry3<f64>) -> anyhow::Result<()> {
        self.memory.push((time, self.current_ref.inverse() * pose));
        self.refit()
    }

    fn state(&self) -> Vec<f32> {
        cpose_core::pose_field::params_to_vec(self.net.as_ref())
    }

    fn restore(&mut self, state: &[f32]) -> anyhow::Result<()> {
        cpose_core::pose_field::params_from_slice(self.net.as_mut(), state)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth loss of a pose and its raw partials (w first), for gradient checks.
    fn loss(pose: &Isometry3<f64>) -> f64 {
        let p = pose * nalgebra::Point3::new(0.3, -0.2, 1.5);
        let r = pose.rotation * Vector3::new(1.0, 0.5, -0.25);
        p.coords.norm_squared() + 0.7 * r.x - 0.2 * (r.y * p.z).sin()
    }

    /// `(∂L/∂q, ∂L/∂t)` of [`loss`] by central differences in the homogeneous form.
    fn grad(pose: &Isometry3<f64>) -> (Quaternion<f64>, Vector3<f64>) {
        let h = 1e-6;
        let q = pose.rotation.into_inner();
        let mut gq = [0.0; 4];
        for k in 0..4 {
            let mut c = [q.w, q.i, q.j, q.k];
            c[k] += h;
            let plus = loss(&Isometry3::from_parts(
                pose.translation,
                UnitQuaternion::new_normalize(Quaternion::new(c[0], c[1], c[2], c[3])),
            ));
            c[k] -= 2.0 * h;
            let minus = loss(&Isometry3::from_parts(
                pose.translation,
                UnitQuaternion::new_normalize(Quaternion::new(c[0], c[1], c[2], c[3])),
            ));
            gq[k] = (plus - minus) / (2.0 * h);
        }
        let mut gt = Vector3::zeros();
        for k in 0..3 {
            let mut t = pose.translation.vector;
            t[k] += h;
            let plus = loss(&Isometry3::from_parts(Translation3::from(t), pose.rotation));
            t[k] -= 2.0 * h;
            let minus = loss(&Isometry3::from_parts(Translation3::from(t), pose.rotation));
            gt[k] = (plus - minus) / (2.0 * h);
        }
        (Quaternion::new(gq[0], gq[1], gq[2], gq[3]), gt)
    }

    #[test]
    fn free_pose_descends_a_smooth_loss() {
        let mut model = FreePose::new(1e-2, 1.0);
        let start = Isometry3::from_parts(
            Translation3::new(0.1, 0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
        );
        model.begin(1, 0.0, &[start]).unwrap();
        let before = loss(&model.pose());
        for _ in 0..50 {
            let (gq, gt) = grad(&model.pose());
            model.step(&gq, &gt).unwrap();
        }
        assert!(
            loss(&model.pose()) < before - 0.1,
            "{before} → {}",
            loss(&model.pose())
        );
    }

    #[test]
    fn constant_velocity_start() {
        let mut model = FreePose::new(1e-3, 1.0);
        let step = Isometry3::from_parts(
            Translation3::new(0.05, 0.0, 0.01),
            UnitQuaternion::from_euler_angles(0.0, 0.02, 0.0),
        );
        let t0 = Isometry3::from_parts(
            Translation3::new(1.0, 2.0, 3.0),
            UnitQuaternion::from_euler_angles(0.3, 0.1, -0.4),
        );
        let t1 = step * t0;
        let start = model.begin(2, 0.0, &[t0, t1]).unwrap();
        let want = step * t1;
        assert!((start.translation.vector - want.translation.vector).norm() < 1e-12);
        assert!(start.rotation.angle_to(&want.rotation) < 1e-12);
    }

    /// The gradient PoseNetTracker passes to the network matches central differences of the
    /// loss of `T_ref ∘ PN(t)` in the network's parameters.
    #[test]
    fn posenet_relative_gradient_matches_central_differences() {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let config = PoseNetTrackConfig {
            network: PoseNetConfig {
                depth: 3,
                width: 8,
                skip_layer: 0,
                ..PoseNetConfig::default()
            },
            ..PoseNetTrackConfig::default()
        };
        let mut tracker = PoseNetTracker::new(&config, Reference::Previous, range, 3).unwrap();
        // Move the network off the identity so every term is exercised.
        let mut params = tracker.state();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for p in &mut params {
            *p += rng.random_range(-0.3f32..0.3);
        }
        tracker.restore(&params).unwrap();
        let prev = Isometry3::from_parts(
            Translation3::new(0.5, -1.0, 2.0),
            UnitQuaternion::from_euler_angles(0.4, -0.3, 1.0),
        );
        tracker.begin(1, 0.4, &[prev]).unwrap();
        let (gq, gt) = grad(&tracker.pose());
        // Analytic: the cotangent through T_ref, then the network's backward.
        tracker.cotangent.reset(1, Order::Pose);
        tracker.cotangent.rotation[0] = prev.rotation.conjugate().into_inner() * gq;
        tracker.cotangent.translation[0] = prev.rotation.inverse() * gt;
        let mut analytic = vec![0.0f32; params.len()];
        tracker
            .net
            .backward(&[0.4], &tracker.cotangent, &mut analytic)
            .unwrap();
        // Numeric, on a few parameters of each network.
        let n = params.len();
        for &k in &[0, 7, n / 3, n / 2 + 5, n - 1] {
            let h = 1e-3f32;
            let mut at = |v: f32| {
                let mut p = params.clone();
                p[k] = v;
                tracker.restore(&p).unwrap();
                tracker.begin(1, 0.4, &[prev]).unwrap();
                loss(&tracker.pose())
            };
            let numeric = (at(params[k] + h) - at(params[k] - h)) / (2.0 * h as f64);
            let a = analytic[k] as f64;
            assert!(
                (a - numeric).abs() < 2e-3 * (1.0 + numeric.abs()),
                "param {k}: {a} vs {numeric}"
            );
        }
    }

    #[test]
    fn refitting_memorises_relative_poses() {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let config = PoseNetTrackConfig {
            refit_steps: 1,
            lr_translation: 1e-3,
            lr_rotation: 1e-3,
            ..PoseNetTrackConfig::default()
        };
        let mut tracker = PoseNetTracker::new(&config, Reference::World, range, 0).unwrap();
        let first = Isometry3::identity();
        let target = |t: f64| {
            Isometry3::from_parts(
                Translation3::new(0.3 * t, -0.1 * t, 0.05),
                UnitQuaternion::from_euler_angles(0.0, 0.2 * t, 0.0),
            )
        };
        let error = |tracker: &mut PoseNetTracker| {
            (1..=10)
                .map(|i| {
                    let t = i as f64 / 10.0;
                    tracker.begin(1, t, &[first]).unwrap();
                    (tracker.pose().translation.vector - target(t).translation.vector).norm()
                })
                .sum::<f64>()
        };
        let before = error(&mut tracker);
        for _ in 0..40 {
            for i in 1..=10 {
                let t = i as f64 / 10.0;
                tracker.begin(1, t, &[first]).unwrap();
                tracker.finish(i, t, &target(t)).unwrap();
            }
            tracker.memory.clear();
        }
        let after = error(&mut tracker);
        assert!(after < 0.2 * before, "{before} → {after}");
    }
}
