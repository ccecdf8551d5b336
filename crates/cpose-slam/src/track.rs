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
//!   frame PoseNet goes back to the weights of that best candidate and is re-fitted on the list
//!   (a batch of earlier frames plus the newest), so it stays a consistent function of time. Two hooks add terms of other sensors to a frame's
//!   objective: on the network's relative pose at the frame ([`RelativePoseTerm`], e.g. a
//!   measured motion since the previous frame) and on the network itself ([`NetworkObjective`],
//!   e.g. on its time derivatives); `cpose-imu` implements both. A third gives the previous
//!   camera a predicted motion ([`PoseNetTracker::set_prediction`]): `T_ref = T_{i−1} ∘ P_i`, so
//!   the network learns only what the prediction misses.
//! * [`IntrinsicTracker`], the paper's intrinsic motion frame: the relative motion
//!   `T_o ∘ T_I ∘ T_o⁻¹` from two such PoseNets, with the DOF loss on the intrinsic motion `T_I`.
//!
//! All receive the gradient of the loss with respect to `world_from_camera` as raw partials
//! `(∂L/∂q, ∂L/∂t)` ([`cpose_nerf::camera::PoseGradient::quaternion_translation`]).

use cpose_core::nn::{Adam, l1_subgradient};
use cpose_core::pose_field::posenet::PoseNetConfig;
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, TimeRange};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use cpose_core::checkpoint::{Reader, Writer};

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
    /// The current pose is the best candidate of the frame so far: a model whose parameters
    /// produced it keeps them, to end the frame from them rather than from its last step.
    fn keep_best(&mut self) {}
    /// Ends frame `index` with its chosen pose (the best-loss candidate).
    fn finish(&mut self, index: usize, time: f64, pose: &Isometry3<f64>) -> anyhow::Result<()>;
    /// Writes what a resumed run needs to continue exactly (nothing for a per-frame model).
    fn save(&self, w: &mut Writer) {
        let _ = w;
    }
    /// Restores [`PoseModel::save`].
    fn load(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        let _ = r;
        Ok(())
    }
    /// Extra metrics of the run so far, `(key, value)`.
    fn metrics(&self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// Whether the frame's start is another sensor's measurement of the motion (an IMU's) rather
    /// than the model's own extrapolation: a frame whose track is lost then falls back to it
    /// ([`crate::slam::TrackReport::recovered`]).
    fn start_is_measured(&self) -> bool {
        false
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
    /// A new tracking optimiser for every frame, as the authors' PoseNet tracking (and NICE-SLAM's
    /// free pose), and again once an objective's prediction steps end
    /// ([`PoseNetTracker::set_objective`]); `false` keeps the Adam moments from frame to frame.
    /// Re-fitting has its own optimiser, kept for the whole run.
    pub fresh_optimizer: bool,
    /// Rotation spread of the random reference, radians.
    pub random_rotation: f64,
    /// Translation spread of the random reference, metres.
    pub random_translation: f64,
}

impl Default for PoseNetTrackConfig {
    fn default() -> Self {
        Self {
            // The paper's tracking network: 8 layers of 256 with the skip at the 4th (4×128 with
            // the skip at the 2nd is the smaller option measured on the SLAM results page).
            network: PoseNetConfig::default(),
            lr_translation: 1e-3,
            lr_rotation: 5e-4,
            refit_steps: 5,
            refit_batch: 32,
            fresh_optimizer: true,
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
    /// Tracking's optimiser ([`PoseNetTrackConfig::fresh_optimizer`]).
    adam: Adam<f32>,
    /// Re-fitting's optimiser.
    refit_adam: Adam<f32>,
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
    /// The weights of the frame's best candidate so far (empty: none kept yet).
    best: Vec<f32>,
    seed: u64,
    /// Drawn afresh for each frame from `seed` and its index (resumable runs).
    rng: ChaCha8Rng,
    /// A term on the relative pose of the next frame to begin, and its prediction steps
    /// ([`PoseNetTracker::set_relative_term`]).
    next_relative_term: Option<(Box<dyn RelativePoseTerm>, usize)>,
    /// The term on the relative pose of the frame being tracked.
    relative_term: Option<Box<dyn RelativePoseTerm>>,
    /// A term on the network itself for the next frame, and its prediction steps
    /// ([`PoseNetTracker::set_objective`]).
    objective: Option<(Box<dyn NetworkObjective>, usize)>,
    /// The predicted motion `P_i` of the next frame to begin ([`PoseNetTracker::set_prediction`]).
    prediction: Option<Isometry3<f64>>,
}

/// A term of a frame's objective on PoseNet itself rather than on the frame's pose — e.g. another
/// sensor's terms on the network's time derivatives ([`PoseNetTracker::set_objective`]).
pub trait NetworkObjective: Send {
    /// Adds the term's gradient with respect to the network's parameters to `grad`; returns the
    /// term's value.
    fn accumulate(&mut self, net: &mut dyn PoseField<f32>, grad: &mut [f32])
    -> anyhow::Result<f64>;
    /// The prediction has ended and tracking begins: terms meant for the prediction alone drop.
    fn start_tracking(&mut self) {}
}

/// A term of a frame's objective on PoseNet's relative pose at the frame, `PN(t_i) = (q, t)`
/// (`T_i = T_ref ∘ PN(t_i)`), e.g. a tie to a motion since the previous frame measured by
/// another sensor ([`PoseNetTracker::set_relative_term`]).
pub trait RelativePoseTerm: Send {
    /// The frame begins with the reference `reference` (`T_ref`) after the frames `history`
    /// (`history.len()` is the frame's index, at least 1): the term fixes its target.
    fn begin(&mut self, reference: &Isometry3<f64>, history: &[Isometry3<f64>]);
    /// The term's gradient `(∂/∂q, ∂/∂t)` at the relative pose `(q, t)` (raw partials, `q`
    /// unnormalised).
    fn gradient(&self, q: &Quaternion<f64>, t: &Vector3<f64>) -> (Quaternion<f64>, Vector3<f64>);
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
            refit_adam: Adam::new(n),
            grad: vec![0.0; n],
            batch: PoseBatch::default(),
            cotangent: PoseBatch::default(),
            current_ref: Isometry3::identity(),
            current_rel: Isometry3::identity(),
            time: 0.0,
            memory: Vec::new(),
            best: Vec::new(),
            seed,
            rng: ChaCha8Rng::seed_from_u64(seed),
            next_relative_term: None,
            relative_term: None,
            objective: None,
            prediction: None,
        })
    }

    /// The next frame to begin is referred to the previous camera moved by `motion`, `T_ref =
    /// T_{i−1} ∘ P_i` (in the previous camera's frame), instead of the previous camera itself:
    /// the frame starts at `T_{i−1} ∘ P_i ∘ PN(t_i)`, and the network holds what the prediction
    /// misses, `PN(t_j) = P_j⁻¹ T_{j−1}⁻¹ T_j` ([`Reference::Previous`] only).
    pub fn set_prediction(&mut self, motion: Option<Isometry3<f64>>) {
        self.prediction = motion;
    }

    /// A term on the relative pose of the next frame to begin, which then starts with
    /// `predict_steps` Adam steps on its terms alone (`None`: no term); it lasts until that frame
    /// ends.
    pub fn set_relative_term(
        &mut self,
        term: Option<Box<dyn RelativePoseTerm>>,
        predict_steps: usize,
    ) {
        self.next_relative_term = term.map(|t| (t, predict_steps));
    }

    /// A term added to every step of the next frame to begin, which then starts with
    /// `predict_steps` Adam steps on its ties and this term alone (`None`: no term); it lasts until
    /// that frame ends.
    pub fn set_objective(
        &mut self,
        objective: Option<Box<dyn NetworkObjective>>,
        predict_steps: usize,
    ) {
        self.objective = objective.map(|o| (o, predict_steps));
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
            self.refit_adam
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
        self.start_frame(index);
        let prediction = self.prediction.take();
        if prediction.is_some() && self.reference != Reference::Previous {
            anyhow::bail!("a predicted motion needs PoseNet relative to the previous camera");
        }
        self.current_ref = match self.reference {
            Reference::Previous => {
                history[index - 1] * prediction.unwrap_or_else(Isometry3::identity)
            }
            Reference::World => history[0],
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
        self.relative_term = None;
        let mut predict_steps = 0;
        if let Some((mut term, steps)) = self.next_relative_term.take() {
            term.begin(&self.current_ref, &history[..index]);
            self.relative_term = Some(term);
            predict_steps = steps;
        }
        if let Some((_, steps)) = &self.objective {
            predict_steps = predict_steps.max(*steps);
        }
        for step in 1..=predict_steps {
            self.update(&Quaternion::new(0.0, 0.0, 0.0, 0.0), &Vector3::zeros())?;
            // The relative term reads the network at t_i on every step, the frame's start once.
            if self.relative_term.is_some() || step == predict_steps {
                self.evaluate()?;
            }
        }
        if let Some((objective, steps)) = &mut self.objective {
            objective.start_tracking();
            if *steps > 0 && self.config.fresh_optimizer {
                // The objective's prediction gradients would scale tracking's steps down.
                self.adam.reset();
            }
        }
        Ok(self.pose())
    }

    fn pose(&self) -> Isometry3<f64> {
        self.current_ref * self.current_rel
    }

    fn step(&mut self, grad_q: &Quaternion<f64>, grad_t: &Vector3<f64>) -> anyhow::Result<()> {
        // T = A ∘ P: q = q_A ⊗ q_P, t = R_A t_P + t_A, so ∂L/∂q_P = q_A* ⊗ ∂L/∂q and
        // ∂L/∂t_P = R_Aᵀ ∂L/∂t (left multiplication by a unit quaternion is orthogonal).
        let a = &self.current_ref;
        let gq = a.rotation.conjugate().into_inner() * grad_q;
        let gt = a.rotation.inverse() * grad_t;
        self.step_relative(&gq, &gt)
    }

    fn keep_best(&mut self) {
        self.keep_best_weights();
    }

    fn finish(&mut self, _index: usize, time: f64, pose: &Isometry3<f64>) -> anyhow::Result<()> {
        self.objective = None;
        self.relative_term = None;
        self.restore_best()?;
        let rel = self.current_ref.inverse() * pose;
        self.memorise(time, rel)
    }

    fn save(&self, w: &mut Writer) {
        w.f32s(&self.state());
        for adam in [&self.adam, &self.refit_adam] {
            let (m, v, t) = adam.state();
            w.f32s(m);
            w.f32s(v);
            w.u64(t);
        }
        w.f64s(&self.memory.iter().map(|m| m.0).collect::<Vec<_>>());
        w.poses(&self.memory.iter().map(|m| m.1).collect::<Vec<_>>());
    }

    fn load(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        self.restore(&r.f32s()?)?;
        for adam in [&mut self.adam, &mut self.refit_adam] {
            let (m, v, t) = (r.f32s()?, r.f32s()?, r.u64()?);
            if !adam.set_state(&m, &v, t) {
                anyhow::bail!("the checkpoint's PoseNet optimiser does not match this network");
            }
        }
        let (times, poses) = (r.f64s()?, r.poses()?);
        if times.len() != poses.len() {
            anyhow::bail!("corrupt PoseNet memory in the checkpoint");
        }
        self.memory = times.into_iter().zip(poses).collect();
        Ok(())
    }
}

impl PoseNetTracker {
    /// Prepares frame `index`: its own generator (random references, re-fitting batches; resumable
    /// runs) and, if configured, a new tracking optimiser.
    fn start_frame(&mut self, index: usize) {
        self.rng = ChaCha8Rng::seed_from_u64(
            (self.seed ^ 0x5EED_7AC4).wrapping_add((index as u64).wrapping_mul(0x9E37_79B9)),
        );
        if self.config.fresh_optimizer {
            self.adam.reset();
        }
        self.best.clear();
    }

    /// Keeps the current weights as the frame's best candidate's.
    fn keep_best_weights(&mut self) {
        self.best.clear();
        let best = &mut self.best;
        self.net.params(&mut |_, p| best.extend_from_slice(p));
    }

    /// Goes back to the weights of the frame's best candidate, if one was kept.
    fn restore_best(&mut self) -> anyhow::Result<()> {
        if !self.best.is_empty() {
            let best = std::mem::take(&mut self.best);
            self.restore(&best)?;
            self.evaluate()?;
        }
        Ok(())
    }

    /// The network's parameters, flat.
    pub fn state(&self) -> Vec<f32> {
        cpose_core::pose_field::params_to_vec(self.net.as_ref())
    }

    /// Overwrites the network's parameters from [`PoseNetTracker::state`].
    pub fn restore(&mut self, state: &[f32]) -> anyhow::Result<()> {
        cpose_core::pose_field::params_from_slice(self.net.as_mut(), state)?;
        Ok(())
    }

    /// One Adam step from the cotangent `(∂L/∂q, ∂L/∂t)` of the network's own output at the
    /// current time; re-evaluates it.
    fn step_relative(&mut self, gq: &Quaternion<f64>, gt: &Vector3<f64>) -> anyhow::Result<()> {
        self.update(gq, gt)?;
        self.evaluate()
    }

    /// One Adam step from the cotangent `(∂L/∂q, ∂L/∂t)` of the network's output at the current
    /// time (its last evaluation) plus the relative term's and the objective's.
    fn update(&mut self, gq: &Quaternion<f64>, gt: &Vector3<f64>) -> anyhow::Result<()> {
        let (mut gq, mut gt) = (*gq, *gt);
        if let Some(term) = &self.relative_term {
            // On the network's output at t_i (the last evaluation).
            let (dq, dt) = term.gradient(&self.batch.rotation[0], &self.batch.translation[0]);
            gq += dq;
            gt += dt;
        }
        self.grad.fill(0.0);
        // A prediction step on the objective alone has nothing to back-propagate at t_i.
        if gq != Quaternion::new(0.0, 0.0, 0.0, 0.0) || gt != Vector3::zeros() {
            self.cotangent.reset(1, Order::Pose);
            self.cotangent.rotation[0] = gq;
            self.cotangent.translation[0] = gt;
            self.net
                .backward(&[self.time], &self.cotangent, &mut self.grad)?;
        }
        if let Some((objective, _)) = &mut self.objective {
            objective.accumulate(self.net.as_mut(), &mut self.grad)?;
        }
        let (lr_r, lr_t) = (
            self.lr(ParamKind::Rotation),
            self.lr(ParamKind::Translation),
        );
        self.adam
            .step_pose_field(self.net.as_mut(), &self.grad, |kind| match kind {
                ParamKind::Rotation => lr_r,
                _ => lr_t,
            });
        Ok(())
    }

    /// Keeps `(time, relative)` as the network's target there and re-fits it on its memory.
    fn memorise(&mut self, time: f64, relative: Isometry3<f64>) -> anyhow::Result<()> {
        self.memory.push((time, relative));
        self.refit()
    }
}

/// The rotation vector `ω = θ n` of a unit quaternion `q = (w, u)` with `w ≥ 0` and its Jacobian
/// with respect to `(w, u)`: `ω = s(r, w) u`, `r = ‖u‖`, `s = 2 atan2(r, w)/r`, so
/// `∂ω/∂u = s I + (∂s/∂r) u uᵀ/r` and `∂ω/∂w = (∂s/∂w) u` with `∂s/∂w = −2/(r² + w²)` and
/// `∂s/∂r = 2 (r w/(r² + w²) − atan2(r, w))/r²` (`→ −4r/(3w³)` as `r → 0`, where `s → 2/w`).
fn rotation_vector_jacobian(q: &Quaternion<f64>) -> (Vector3<f64>, nalgebra::Matrix3x4<f64>) {
    let (w, u) = (q.w, q.imag());
    let r = u.norm();
    let n2 = r * r + w * w;
    let (s, ds_dr) = if r < 1e-6 {
        (2.0 / w, -4.0 * r / (3.0 * w * w * w))
    } else {
        let a = r.atan2(w);
        (2.0 * a / r, 2.0 * (r * w / n2 - a) / (r * r))
    };
    let ds_dw = -2.0 / n2;
    let omega = u * s;
    let mut jac = nalgebra::Matrix3x4::zeros();
    jac.set_column(0, &(u * ds_dw));
    let du = nalgebra::Matrix3::identity() * s
        + if r > 0.0 {
            u * u.transpose() * (ds_dr / r)
        } else {
            nalgebra::Matrix3::zeros()
        };
    jac.fixed_view_mut::<3, 3>(0, 1).copy_from(&du);
    (omega, jac)
}

/// The paper's DOF loss of an intrinsic motion `T_I = (q, v)` (§3.3, ℓ₀ relaxed to ℓ₁):
/// `Σ_k |2 ω_k/γ| + Σ_k |v_k|/(‖v‖ + ε)` with `ω` the rotation vector of `q` (the paper's Euler
/// angles, equal to first order for inter-frame rotations), `γ` the view angle and `ε = 10⁻³` m;
/// returns the loss and its raw partials `(∂/∂q, ∂/∂v)`.
pub fn dof_loss(
    q: &Quaternion<f64>,
    v: &Vector3<f64>,
    view_angle: f64,
) -> (f64, Quaternion<f64>, Vector3<f64>) {
    let flip = if q.w < 0.0 { -1.0 } else { 1.0 };
    let (omega, jac) = rotation_vector_jacobian(&(q * flip));
    let k = 2.0 / view_angle;
    let g_omega = omega.map(|x| k * l1_subgradient(x));
    let gq = jac.transpose() * g_omega * flip;
    let norm = v.norm() + DOF_EPS;
    let sign = v.map(l1_subgradient);
    let l1 = v.abs().sum();
    // ∂/∂v of Σ|v_k|/(‖v‖ + ε) = sign/(‖v‖ + ε) − Σ|v_k| v/(‖v‖ (‖v‖ + ε)²).
    let gv = if v.norm() > 0.0 {
        sign / norm - v * (l1 / (v.norm() * norm * norm))
    } else {
        sign / norm
    };
    let loss = k * omega.abs().sum() + l1 / norm;
    (loss, Quaternion::new(gq[0], gq[1], gq[2], gq[3]), gv)
}

/// `∂/∂q ⟨g, R(q) x⟩` in the homogeneous form of [`PoseGradient`].
fn rotated_vector_cotangent(
    q: &UnitQuaternion<f64>,
    x: &Vector3<f64>,
    g: &Vector3<f64>,
) -> Quaternion<f64> {
    let mut lever = cpose_nerf::camera::PoseGradient::new();
    lever.add_ray((*x).into(), [0.0; 3], (*g).into());
    lever.quaternion_translation(q).0
}

/// `ε` of the DOF loss's translation normalisation, metres.
const DOF_EPS: f64 = 1e-3;

/// The effective DOF of a relative motion `(q, v)` (the paper's figure counts the active DOF of
/// the motion and of the intrinsic motion): the rotation-vector components of at least a tenth
/// of the largest, if the rotation exceeds 0.01°, plus the translation components of at least a
/// tenth of the largest, if it exceeds 1 mm.
pub fn effective_dof(q: &UnitQuaternion<f64>, v: &Vector3<f64>) -> usize {
    let active = |x: Vector3<f64>, floor: f64| {
        let max = x.amax();
        if max <= floor {
            0
        } else {
            x.iter().filter(|c| c.abs() >= 0.1 * max).count()
        }
    };
    active(q.scaled_axis(), 0.01f64.to_radians()) + active(*v, DOF_EPS)
}

/// Intrinsic-motion tracking settings; `[intrinsic]` in a `slam` config.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntrinsicConfig {
    /// Weight of the DOF loss on `T_I` (in units of the summed tracking loss; the paper gives
    /// none: 10 made tracking diverge on the synthetic room, 1 cost accuracy, 0.1 is stable).
    pub dof_weight: f64,
    /// Weight of `L_o = ‖v_o‖₁` on the intrinsic transform's translation.
    pub origin_weight: f64,
    /// `f_o` is optimised only while tracking every this many frames (the paper: 10).
    pub origin_every: usize,
    /// How `T_o` and `T_I` make the relative motion ([`Composition`]).
    pub composition: Composition,
}

/// How the intrinsic transform `T_o` and the intrinsic motion `T_I` make the relative motion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Composition {
    /// `T_o ∘ T_I ∘ T_o⁻¹`: `T_I` is the motion expressed in the intrinsic frame, so a rotation
    /// about a fixed axis is one DOF in a frame aligned with it, and a small rotation lets the
    /// axis point `v_o` run off — the two facts the paper states of its intrinsic frame.
    #[default]
    Conjugate,
    /// `T_o ∘ T_I`, the paper's equation (8) read literally; `T_o`'s rotation then adds to
    /// `T_I`'s, which cannot become sparser than the motion.
    Product,
}

impl Default for IntrinsicConfig {
    fn default() -> Self {
        Self {
            dof_weight: 0.1,
            origin_weight: 0.1,
            origin_every: 10,
            composition: Composition::Conjugate,
        }
    }
}

/// The paper's intrinsic motion frame (§3.3): the relative motion from the previous camera is
/// `T_o(t) ∘ T_I(t) ∘ T_o(t)⁻¹` ([`Composition`]), two PoseNets — the slowly changing intrinsic
/// transform `f_o` and the low-DOF intrinsic motion `f_I` — with the DOF loss on `T_I` and
/// `‖v_o‖₁` on `T_o`.
pub struct IntrinsicTracker {
    origin: PoseNetTracker,
    motion: PoseNetTracker,
    config: IntrinsicConfig,
    view_angle: f64,
    update_origin: bool,
    prev: Isometry3<f64>,
    /// `(effective DOF of T_o ∘ T_I, of T_I)` per tracked frame.
    pub dof: Vec<(usize, usize)>,
}

impl IntrinsicTracker {
    /// Two PoseNets over `range` at the identity; `view_angle` (radians) normalises the DOF loss.
    pub fn new(
        posenet: &PoseNetTrackConfig,
        config: &IntrinsicConfig,
        range: TimeRange,
        view_angle: f64,
        seed: u64,
    ) -> anyhow::Result<Self> {
        if config.origin_every == 0 {
            anyhow::bail!("intrinsic.origin_every must be ≥ 1");
        }
        Ok(Self {
            origin: PoseNetTracker::new(posenet, Reference::Previous, range, seed)?,
            motion: PoseNetTracker::new(posenet, Reference::Previous, range, seed.wrapping_add(1))?,
            config: config.clone(),
            view_angle,
            update_origin: true,
            prev: Isometry3::identity(),
            dof: Vec::new(),
        })
    }

    fn relative(&self) -> Isometry3<f64> {
        let (o, m) = (&self.origin.current_rel, &self.motion.current_rel);
        match self.config.composition {
            Composition::Conjugate => o * m * o.inverse(),
            Composition::Product => o * m,
        }
    }
}

impl PoseModel for IntrinsicTracker {
    fn begin(
        &mut self,
        index: usize,
        time: f64,
        history: &[Isometry3<f64>],
    ) -> anyhow::Result<Isometry3<f64>> {
        self.prev = history[index - 1];
        self.update_origin = index.is_multiple_of(self.config.origin_every);
        // Both networks only evaluate at `time`; the reference is applied here.
        self.origin.time = time;
        self.motion.time = time;
        self.origin.start_frame(index);
        self.motion.start_frame(index);
        self.origin.evaluate()?;
        self.motion.evaluate()?;
        Ok(self.pose())
    }

    fn pose(&self) -> Isometry3<f64> {
        self.prev * self.relative()
    }

    fn step(&mut self, grad_q: &Quaternion<f64>, grad_t: &Vector3<f64>) -> anyhow::Result<()> {
        let [(gq_o, gt_o), (gq_i, gt_i)] = self.cotangents(grad_q, grad_t);
        self.motion.step_relative(&gq_i, &gt_i)?;
        if self.update_origin {
            self.origin.step_relative(&gq_o, &gt_o)?;
        }
        Ok(())
    }

    fn keep_best(&mut self) {
        self.origin.keep_best_weights();
        self.motion.keep_best_weights();
    }

    fn finish(&mut self, index: usize, time: f64, pose: &Isometry3<f64>) -> anyhow::Result<()> {
        self.origin.restore_best()?;
        self.motion.restore_best()?;
        let rel = self.prev.inverse() * pose;
        // Split the chosen relative pose at the current intrinsic transform.
        let o = self.origin.current_rel;
        let motion = match self.config.composition {
            Composition::Conjugate => o.inverse() * rel * o,
            Composition::Product => o.inverse() * rel,
        };
        self.dof.push((
            effective_dof(&rel.rotation, &rel.translation.vector),
            effective_dof(&motion.rotation, &motion.translation.vector),
        ));
        self.motion.memorise(time, motion)?;
        if self.update_origin || index == 1 {
            self.origin.memorise(time, o)?;
        }
        Ok(())
    }

    fn metrics(&self) -> Vec<(&'static str, f64)> {
        let n = self.dof.len().max(1) as f64;
        vec![
            (
                "dof_motion",
                self.dof.iter().map(|d| d.0 as f64).sum::<f64>() / n,
            ),
            (
                "dof_intrinsic",
                self.dof.iter().map(|d| d.1 as f64).sum::<f64>() / n,
            ),
        ]
    }

    fn save(&self, w: &mut Writer) {
        self.origin.save(w);
        self.motion.save(w);
        let flat: Vec<f64> = self
            .dof
            .iter()
            .flat_map(|d| [d.0 as f64, d.1 as f64])
            .collect();
        w.f64s(&flat);
    }

    fn load(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        self.origin.load(r)?;
        self.motion.load(r)?;
        self.dof = r
            .f64s()?
            .chunks_exact(2)
            .map(|d| (d[0] as usize, d[1] as usize))
            .collect();
        Ok(())
    }
}

impl IntrinsicTracker {
    /// The cotangents `(∂/∂q, ∂/∂t)` of the outputs of `f_o` and `f_I`, in that order, from the
    /// cotangent of the pose `T = A ∘ R` (`R` the relative motion of [`Composition`]), with the
    /// DOF loss on `I` and `‖v_o‖₁` on `O` added.
    ///
    /// Conjugate, `q_R = q_o ⊗ q_I ⊗ q_o*`, `t_R = R_o t_I + v_o − R_R v_o`: with `G` the
    /// cotangent of `q_R` (including `−R_R v_o`'s), `∂/∂q_I = q_o* ⊗ G ⊗ q_o`,
    /// `∂/∂q_o = G ⊗ q_o ⊗ q_I* + G* ⊗ q_o ⊗ q_I` plus `R_o t_I`'s, `∂/∂t_I = R_oᵀ g_t` and
    /// `∂/∂v_o = g_t − R_Rᵀ g_t`.
    fn cotangents(
        &self,
        grad_q: &Quaternion<f64>,
        grad_t: &Vector3<f64>,
    ) -> [(Quaternion<f64>, Vector3<f64>); 2] {
        // Cotangent of R: as PoseNetTracker::step with reference A.
        let a = &self.prev;
        let gq_rel = a.rotation.conjugate().into_inner() * grad_q;
        let gt_rel = a.rotation.inverse() * grad_t;
        let (o, m) = (self.origin.current_rel, self.motion.current_rel);
        let (q_o, q_i) = (o.rotation.into_inner(), m.rotation.into_inner());
        let (gq_o, mut gt_o, mut gq_i, mut gt_i) = match self.config.composition {
            Composition::Conjugate => {
                let q_r = o.rotation * m.rotation * o.rotation.inverse();
                let g = gq_rel + rotated_vector_cotangent(&q_r, &o.translation.vector, &-gt_rel);
                (
                    g * q_o * q_i.conjugate()
                        + g.conjugate() * q_o * q_i
                        + rotated_vector_cotangent(&o.rotation, &m.translation.vector, &gt_rel),
                    gt_rel - q_r.inverse() * gt_rel,
                    q_o.conjugate() * g * q_o,
                    o.rotation.inverse() * gt_rel,
                )
            }
            Composition::Product => (
                // q_R = q_o ⊗ q_I, t_R = R_o t_I + v_o.
                gq_rel * q_i.conjugate()
                    + rotated_vector_cotangent(&o.rotation, &m.translation.vector, &gt_rel),
                gt_rel,
                q_o.conjugate() * gq_rel,
                o.rotation.inverse() * gt_rel,
            ),
        };
        let (_, dq, dv) = dof_loss(&q_i, &m.translation.vector, self.view_angle);
        gq_i += dq * self.config.dof_weight;
        gt_i += dv * self.config.dof_weight;
        gt_o += o.translation.vector.map(l1_subgradient) * self.config.origin_weight;
        [(gq_o, gt_o), (gq_i, gt_i)]
    }

    /// Both networks' parameters, flat (origin first).
    pub fn state(&self) -> Vec<f32> {
        let mut s = self.origin.state();
        s.extend(self.motion.state());
        s
    }

    /// Overwrites both networks' parameters from [`IntrinsicTracker::state`].
    pub fn restore(&mut self, state: &[f32]) -> anyhow::Result<()> {
        let n = self.origin.net.num_params();
        if state.len() != n + self.motion.net.num_params() {
            anyhow::bail!(
                "{} values for the intrinsic frame's parameters",
                state.len()
            );
        }
        self.origin.restore(&state[..n])?;
        self.motion.restore(&state[n..])
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

    /// A PoseNet small enough for central differences over all its parameters.
    fn tiny_network() -> PoseNetConfig {
        PoseNetConfig {
            depth: 3,
            width: 8,
            skip_layer: 0,
            ..PoseNetConfig::default()
        }
    }

    /// The gradient PoseNetTracker passes to the network matches central differences of the
    /// loss of `T_ref ∘ PN(t)` in the network's parameters.
    #[test]
    fn posenet_relative_gradient_matches_central_differences() {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let config = PoseNetTrackConfig {
            network: tiny_network(),
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

    /// A frame ends from the weights of its best candidate, not from its last step: without
    /// re-fitting, the network then gives the best candidate's pose again.
    #[test]
    fn a_frame_ends_from_its_best_candidates_weights() {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let config = PoseNetTrackConfig {
            refit_steps: 0,
            network: PoseNetConfig {
                depth: 3,
                width: 16,
                skip_layer: 0,
                ..PoseNetConfig::default()
            },
            ..PoseNetTrackConfig::default()
        };
        let mut tracker = PoseNetTracker::new(&config, Reference::Previous, range, 0).unwrap();
        let prev = Isometry3::translation(0.1, 0.0, 0.0);
        let best = tracker.begin(1, 0.5, &[prev]).unwrap();
        tracker.keep_best();
        for _ in 0..5 {
            tracker
                .step(
                    &Quaternion::new(0.0, 0.3, -0.2, 0.1),
                    &Vector3::new(1.0, -2.0, 0.5),
                )
                .unwrap();
        }
        let last = tracker.pose();
        assert!((last.translation.vector - best.translation.vector).norm() > 1e-4);
        tracker.finish(1, 0.5, &best).unwrap();
        let now = tracker.pose();
        assert!((now.translation.vector - best.translation.vector).norm() < 1e-9);
        assert!(now.rotation.angle_to(&best.rotation) < 1e-9);
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

    #[test]
    fn dof_loss_matches_central_differences() {
        let gamma = 1.2;
        for (q, v) in [
            (
                Quaternion::new(0.9, 0.1, -0.3, 0.2),
                Vector3::new(0.02, -0.01, 0.005),
            ),
            (
                Quaternion::new(-0.7, 0.4, 0.1, -0.5),
                Vector3::new(-0.3, 0.2, 0.6),
            ),
            // The small-angle series (‖u‖ < 10⁻⁶); the step stays below every |u_k|.
            (
                Quaternion::new(1.0, 4e-7, -5e-7, 3e-7),
                Vector3::new(0.0, 0.0, 1e-3),
            ),
        ] {
            let q = q.normalize();
            let (_, gq, gv) = dof_loss(&q, &v, gamma);
            let f = |q: Quaternion<f64>, v: Vector3<f64>| dof_loss(&q, &v, gamma).0;
            let h = 1e-8;
            for k in 0..4 {
                let mut a = q.coords;
                a[k] += h;
                let mut b = q.coords;
                b[k] -= h;
                let numeric = (f(Quaternion::from(a), v) - f(Quaternion::from(b), v)) / (2.0 * h);
                let analytic = gq.coords[k];
                assert!(
                    (numeric - analytic).abs() < 1e-5 * (1.0 + numeric.abs()),
                    "q[{k}]: {analytic} vs {numeric}"
                );
            }
            for k in 0..3 {
                let (mut a, mut b) = (v, v);
                a[k] += 1e-9;
                b[k] -= 1e-9;
                let numeric = (f(q, a) - f(q, b)) / 2e-9;
                assert!(
                    (numeric - gv[k]).abs() < 1e-4 * (1.0 + numeric.abs()),
                    "v[{k}]: {} vs {numeric}",
                    gv[k]
                );
            }
        }
        // One axis of rotation and one of translation: the least the loss can be for a motion.
        let (pure, _, _) = dof_loss(
            &UnitQuaternion::from_euler_angles(0.0, 0.1, 0.0).into_inner(),
            &Vector3::new(0.0, 0.0, 0.05),
            gamma,
        );
        let (mixed, _, _) = dof_loss(
            &UnitQuaternion::from_scaled_axis(Vector3::new(0.0577, 0.0577, 0.0577)).into_inner(),
            &Vector3::new(0.0289, 0.0289, 0.0289),
            gamma,
        );
        assert!(pure < mixed, "{pure} vs {mixed}");
    }

    #[test]
    fn effective_dof_counts_active_components() {
        let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05);
        assert_eq!(effective_dof(&yaw, &Vector3::new(0.01, 0.0, 0.0)), 2);
        let all = UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.02, 0.02));
        assert_eq!(effective_dof(&all, &Vector3::new(0.01, 0.01, -0.01)), 6);
        assert_eq!(
            effective_dof(&UnitQuaternion::identity(), &Vector3::zeros()),
            0
        );
    }

    /// The gradient the intrinsic tracker gives both networks matches central differences of
    /// `L(T_prev ∘ R) + λ_DOF DOF(T_I) + λ_o ‖v_o‖₁` in their parameters, for both ways `R` is
    /// made of `T_o` and `T_I` ([`Composition`]).
    #[test]
    fn intrinsic_gradient_matches_central_differences() {
        for composition in [Composition::Conjugate, Composition::Product] {
            intrinsic_gradient_check(composition);
        }
    }

    fn intrinsic_gradient_check(composition: Composition) {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let posenet = PoseNetTrackConfig {
            network: tiny_network(),
            ..PoseNetTrackConfig::default()
        };
        let config = IntrinsicConfig {
            dof_weight: 0.3,
            origin_weight: 0.2,
            origin_every: 1,
            composition,
        };
        let view_angle = 1.5;
        let mut tracker = IntrinsicTracker::new(&posenet, &config, range, view_angle, 2).unwrap();
        let mut params = tracker.state();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for p in &mut params {
            *p += rng.random_range(-0.3f32..0.3);
        }
        tracker.restore(&params).unwrap();
        let prev = Isometry3::from_parts(
            Translation3::new(-0.5, 1.0, 0.3),
            UnitQuaternion::from_euler_angles(-0.2, 0.5, 0.8),
        );
        let total = |t: &IntrinsicTracker| {
            let (o, m) = (t.origin.current_rel, t.motion.current_rel);
            let dof = dof_loss(&m.rotation.into_inner(), &m.translation.vector, view_angle).0;
            loss(&t.pose())
                + config.dof_weight * dof
                + config.origin_weight * o.translation.vector.abs().sum()
        };
        tracker.begin(1, 0.6, &[prev]).unwrap();
        let (gq, gt) = grad(&tracker.pose());
        // Analytic: the cotangents of both outputs, then each network's backward.
        let cotangents = tracker.cotangents(&gq, &gt);
        let n_o = tracker.origin.net.num_params();
        let mut analytic = vec![0.0f32; params.len()];
        let (head, tail) = analytic.split_at_mut(n_o);
        for ((net, (cq, ct)), out) in [&mut tracker.origin, &mut tracker.motion]
            .into_iter()
            .zip(cotangents)
            .zip([head, tail])
        {
            net.cotangent.reset(1, Order::Pose);
            net.cotangent.rotation[0] = cq;
            net.cotangent.translation[0] = ct;
            net.net.backward(&[0.6], &net.cotangent, out).unwrap();
        }
        let n = params.len();
        for &k in &[0, 5, n_o / 2, n_o - 1, n_o, n_o + 9, (n_o + n) / 2, n - 1] {
            let h = 1e-3f32;
            let mut at = |v: f32| {
                let mut p = params.clone();
                p[k] = v;
                tracker.restore(&p).unwrap();
                tracker.begin(1, 0.6, &[prev]).unwrap();
                total(&tracker)
            };
            let numeric = (at(params[k] + h) - at(params[k] - h)) / (2.0 * h as f64);
            let a = analytic[k] as f64;
            assert!(
                (a - numeric).abs() < 2e-3 * (1.0 + numeric.abs()),
                "{composition:?}, param {k}: {a} vs {numeric}"
            );
        }
    }
}
