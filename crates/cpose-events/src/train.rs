//! EventNeRF training with a pose at every window end (paper §4.2; docs/methods.md §3.1–3.3).
//!
//! EventNeRF sums the events between two stored views and renders both views. Here the two
//! ends of every window are arbitrary times `τ_s < τ_e`, and the cameras there are
//! `C(τ) ∘ init(τ)` ([`FramePoses`]): `init` is what is known of the path — poses interpolated
//! between a few known views ([`KeyedPoses`]), or a nominal turntable — and `C` the pose
//! correction (PoseNet; none for EventNeRF's fixed poses). Each step:
//!
//! 1. draws `windows_per_step` windows, `τ_e ~ U` over the recording and `τ_e − τ_s ~ U` over
//!    `[min, max]` window lengths — with known views, a share `anchor_windows` of them with one
//!    end on a known view — and evaluates all `2W` poses (and the anchors') in one batched call
//!    of the correction;
//! 2. per window sums the polarities of `[τ_s, τ_e)` per pixel (`E`), takes `1 − neg_ratio` of
//!    its rays at pixels with `E ≠ 0` (with replacement) and the rest uniformly over the
//!    sensor (EventNeRF's negative sampling);
//! 3. renders each pixel at both ends with the same jittered depth strata (one batch), and takes
//!    one Adam step on the field and one on the correction from [`EventLoss`] plus, with known
//!    views, the anchor `λ Σ_k (‖t(t_k) − t_k‖² + ‖q(t_k) − q_k‖²) / K` that holds the corrected
//!    path at them.
//!
//! Why windows at known views: events fix no scale (a scene scaled by `s` seen from a path scaled
//! by `s` fires the same events). With the anchor alone, PoseNet met the known views in narrow
//! notches and drew the rest of the turntable circle at the interpolated polygon's mean radius
//! (4.29 for 4.5 at `K = 6`); with half the windows ending on known views the event loss sees the
//! anchored poses and the radius came to 4.41 (translation error 0.20 → 0.11).

use std::collections::BTreeMap;

use anyhow::bail;
use cpose_core::Timestamp;
use cpose_core::checkpoint::{Reader, Writer};
use cpose_nerf::camera::{PinholeCamera, PoseGradient};
use cpose_nerf::field3d::FieldOptimizer;
use cpose_nerf::field3d::RadianceField;
use cpose_nerf::poses::FramePoses;
use cpose_nerf::render::{CameraRay, Composited, RenderSettings, Renderer};
use nalgebra::{Isometry3, Quaternion, Translation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::loss::EventLoss;
use crate::simulate::bayer_channel;
use crate::stream::EventStream;
use crate::turntable::Turntable;

/// Poses known at increasing times, interpolated in between: slerp for the rotation and a
/// straight line for the position (the paper's interpolation baseline). Constant outside.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyedPoses {
    times: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
}

impl KeyedPoses {
    /// Errors unless there is one pose per time and the times strictly increase.
    pub fn new(times: Vec<f64>, poses: Vec<Isometry3<f64>>) -> anyhow::Result<Self> {
        if times.is_empty() || times.len() != poses.len() {
            bail!("{} key times for {} key poses", times.len(), poses.len());
        }
        if let Some(w) = times
            .windows(2)
            .find(|w| w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less))
        {
            bail!("key times must increase, found {} then {}", w[0], w[1]);
        }
        Ok(Self { times, poses })
    }

    /// The key times.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// The key poses.
    pub fn poses(&self) -> &[Isometry3<f64>] {
        &self.poses
    }

    /// The interpolated pose at `t`.
    pub fn at(&self, t: f64) -> Isometry3<f64> {
        let i = self.times.partition_point(|&k| k <= t);
        if i == 0 {
            return self.poses[0];
        }
        if i == self.times.len() {
            return self.poses[i - 1];
        }
        let (a, b) = (&self.poses[i - 1], &self.poses[i]);
        let s = (t - self.times[i - 1]) / (self.times[i] - self.times[i - 1]);
        let rotation = a
            .rotation
            .try_slerp(&b.rotation, s, 1e-12)
            .unwrap_or(a.rotation);
        let position = a.translation.vector.lerp(&b.translation.vector, s);
        Isometry3::from_parts(Translation3::from(position), rotation)
    }
}

/// Camera-frame directions through every pixel centre of `camera` (row-major), with EventNeRF's
/// radial undistortion: normalised coordinates `(x, y)` become `(x, y) / (1 + k1 r² + k2 r⁴)`,
/// `r² = x² + y²`, at `z = 1`.
pub fn pixel_directions(camera: &PinholeCamera, [k1, k2]: [f64; 2]) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(camera.width * camera.height);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let [u, v, _] = camera.ray_direction_cam(x, y);
            let r2 = u * u + v * v;
            let f = 1.0 + k1 * r2 + k2 * r2 * r2;
            out.push([u / f, v / f, 1.0]);
        }
    }
    out
}

/// What is known of the camera path before training.
#[derive(Clone, Debug, PartialEq)]
pub enum InitialPath {
    /// Known views, interpolated in between.
    Keyed(KeyedPoses),
    /// A turntable revolution (e.g. about a mis-calibrated axis).
    Turntable(Turntable),
}

impl InitialPath {
    /// `world_from_camera` at `t` seconds.
    pub fn at(&self, t: f64) -> Isometry3<f64> {
        match self {
            Self::Keyed(k) => k.at(t),
            Self::Turntable(tt) => tt.world_from_camera(t),
        }
    }
}

/// Settings of one EventNeRF training run.
#[derive(Clone, Debug, PartialEq)]
pub struct EventSchedule {
    /// Steps.
    pub iterations: u64,
    /// Ray pairs per step, over all windows.
    pub rays_per_step: usize,
    /// Windows per step (each with its own two poses).
    pub windows_per_step: usize,
    /// Window lengths `[min, max]`, seconds.
    pub window_secs: [f64; 2],
    /// Where windows are drawn, seconds (e.g. where the poses are known); `None`: the events'
    /// time span.
    pub time_span: Option<[f64; 2]>,
    /// Share of each window's rays drawn uniformly over the sensor (EventNeRF: 0.1).
    pub neg_ratio: f64,
    /// The loss' threshold and `ε`.
    pub loss: EventLoss,
    /// Learning rate `[start, end]` (exponential decay) per parameter group of the field.
    pub field_lr: BTreeMap<String, [f64; 2]>,
    /// Weight `λ` of the anchor at the known views.
    pub anchor_weight: f64,
    /// Share of the windows with one end at a known view (with anchors): the event loss then
    /// sees the anchored pose, so the scene's scale must agree with the known views.
    pub anchor_windows: f64,
    /// Seed of the window, pixel and depth draws.
    pub seed: u64,
}

/// One step's numbers.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// EventNeRF's loss (mean over rays × 3 channels).
    pub loss: f64,
    /// The anchor term (0 without anchors).
    pub anchor: f64,
    /// Events summed in the step's windows.
    pub events: usize,
}

/// One EventNeRF training run's state.
pub struct EventTrainer<'a> {
    field: &'a mut dyn RadianceField,
    poses: &'a mut FramePoses,
    initial: &'a InitialPath,
    /// Known `(time, pose)` the corrected path is held at.
    anchors: Vec<(f64, Isometry3<f64>)>,
    events: &'a EventStream,
    camera: PinholeCamera,
    /// Camera-frame direction of every pixel ([`pixel_directions`]).
    directions: Vec<[f64; 3]>,
    settings: RenderSettings,
    schedule: EventSchedule,
    /// The recording's time span, seconds.
    span: [f64; 2],
    optimizer: FieldOptimizer,
    rng: ChaCha8Rng,
    renderer: Renderer,
    /// The step's rays: every pair's start, then every pair's end.
    rays: Vec<CameraRay>,
    ends: Vec<CameraRay>,
    /// Stratum offsets, the same for both rays of a pair.
    offsets: Vec<f64>,
    /// Per ray pair: its pixel's polarity sum and Bayer channel.
    sums: Vec<f32>,
    channels: Vec<u8>,
    /// The event frame of the current window (zero outside `touched`).
    frame: Vec<f32>,
    touched: Vec<usize>,
    nonzero: Vec<usize>,
    times: Vec<f64>,
    init: Vec<Isometry3<f64>>,
    grad_out: Vec<Composited<f32>>,
    grad_params: Vec<f32>,
    pose_grads: Vec<PoseGradient>,
    pose_cotangents: Vec<(Quaternion<f64>, Vector3<f64>)>,
}

impl<'a> EventTrainer<'a> {
    /// A run over `events` (time origin 0 s, sensor of `camera`'s size) with poses
    /// `poses' correction ∘ initial`, holding the path at `anchors` when given.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        field: &'a mut dyn RadianceField,
        poses: &'a mut FramePoses,
        initial: &'a InitialPath,
        anchors: Vec<(f64, Isometry3<f64>)>,
        events: &'a EventStream,
        camera: PinholeCamera,
        settings: RenderSettings,
        schedule: EventSchedule,
    ) -> anyhow::Result<Self> {
        if (usize::from(events.width()), usize::from(events.height()))
            != (camera.width, camera.height)
        {
            bail!(
                "events of a {}×{} sensor for a {}×{} camera",
                events.width(),
                events.height(),
                camera.width,
                camera.height
            );
        }
        let Some((first, last)) = events.time_span() else {
            bail!("no events to train on");
        };
        let span = schedule
            .time_span
            .unwrap_or([first.as_secs_f64(), last.as_secs_f64()]);
        let [w_min, w_max] = schedule.window_secs;
        if !(w_min > 0.0 && w_max >= w_min && w_max < span[1] - span[0]) {
            bail!(
                "window lengths [{w_min}, {w_max}] s: need 0 < min ≤ max < the {} s the windows are drawn from",
                span[1] - span[0]
            );
        }
        if schedule.windows_per_step == 0 || schedule.rays_per_step < schedule.windows_per_step {
            bail!(
                "need at least one window per step and one ray per window ({} rays, {} windows)",
                schedule.rays_per_step,
                schedule.windows_per_step
            );
        }
        for (name, v) in [
            ("neg_ratio", schedule.neg_ratio),
            ("anchor_windows", schedule.anchor_windows),
        ] {
            if !(0.0..=1.0).contains(&v) {
                bail!("{name} = {v} must lie in [0, 1]");
            }
        }
        let optimizer = FieldOptimizer::new(&*field, &schedule.field_lr, schedule.iterations)?;
        let n = field.num_params();
        let pixels = camera.width * camera.height;
        Ok(Self {
            optimizer,
            grad_params: vec![0.0; n],
            rng: ChaCha8Rng::seed_from_u64(schedule.seed),
            frame: vec![0.0; pixels],
            directions: pixel_directions(&camera, [0.0; 2]),
            field,
            poses,
            initial,
            anchors,
            events,
            camera,
            settings,
            schedule,
            span,
            renderer: Renderer::default(),
            rays: Vec::new(),
            ends: Vec::new(),
            offsets: Vec::new(),
            sums: Vec::new(),
            channels: Vec::new(),
            touched: Vec::new(),
            nonzero: Vec::new(),
            times: Vec::new(),
            init: Vec::new(),
            grad_out: Vec::new(),
            pose_grads: Vec::new(),
            pose_cotangents: Vec::new(),
        })
    }

    /// Rays through a lens with EventNeRF's radial distortion `[k1, k2]` ([`pixel_directions`]).
    pub fn with_distortion(mut self, distortion: [f64; 2]) -> Self {
        self.directions = pixel_directions(&self.camera, distortion);
        self
    }

    /// The poses being optimised (those of the last step's windows and anchors).
    pub fn poses(&self) -> &FramePoses {
        self.poses
    }

    /// The current path `C(t) ∘ init(t)` at `times` (at the end of training: `progress = 1`).
    pub fn path_at(&mut self, times: &[f64], progress: f64) -> anyhow::Result<Vec<Isometry3<f64>>> {
        self.init.clear();
        self.init.extend(times.iter().map(|&t| self.initial.at(t)));
        self.poses.set_frames(&self.init, times);
        Ok(self.poses.update(progress)?.to_vec())
    }

    /// Draws the step's windows: `[τ_s, τ_e]` pairs into `times`.
    fn draw_windows(&mut self) {
        let [w_min, w_max] = self.schedule.window_secs;
        let [t0, t1] = self.span;
        self.times.clear();
        for _ in 0..self.schedule.windows_per_step {
            let len = self.rng.random_range(w_min..=w_max);
            let at_anchor =
                !self.anchors.is_empty() && self.rng.random_bool(self.schedule.anchor_windows);
            let (start, end) = if at_anchor {
                // One end on a known view, the window inside the span.
                let t = self.anchors[self.rng.random_range(0..self.anchors.len())].0;
                if (self.rng.random_bool(0.5) && t - len >= t0) || t + len > t1 {
                    (t - len, t)
                } else {
                    (t, t + len)
                }
            } else {
                let end = self.rng.random_range(t0 + w_min..=t1);
                (end - len.min(end - t0), end)
            };
            self.times.extend([start.max(t0), end.min(t1)]);
        }
    }

    /// Sums the polarities of `[start, end)` into `frame`, listing the pixels with `E ≠ 0`;
    /// returns the number of events.
    fn accumulate(&mut self, start: f64, end: f64) -> anyhow::Result<usize> {
        for &p in &self.touched {
            self.frame[p] = 0.0;
        }
        self.touched.clear();
        self.nonzero.clear();
        let window = self.events.window(
            Timestamp::from_secs_f64(start),
            Timestamp::from_secs_f64(end),
        )?;
        let w = self.camera.width;
        for ((&x, &y), &p) in window.x().iter().zip(window.y()).zip(window.p()) {
            let i = usize::from(y) * w + usize::from(x);
            if self.frame[i] == 0.0 {
                self.touched.push(i);
            }
            self.frame[i] += f32::from(p);
        }
        // A pixel touched twice with opposite polarities may be listed twice or be back at 0.
        self.touched.sort_unstable();
        self.touched.dedup();
        self.nonzero
            .extend(self.touched.iter().filter(|&&i| self.frame[i] != 0.0));
        Ok(window.len())
    }

    /// One step at iteration `it`.
    pub fn step(&mut self, it: u64) -> anyhow::Result<StepStats> {
        let progress = it as f64 / self.schedule.iterations.max(1) as f64;
        self.field.set_progress(progress);
        self.draw_windows();
        let windows = self.schedule.windows_per_step;
        self.times.extend(self.anchors.iter().map(|a| a.0));
        self.init.clear();
        self.init
            .extend(self.times.iter().map(|&t| self.initial.at(t)));
        self.poses.set_frames(&self.init, &self.times);
        self.poses.update(progress)?;

        // Rays: window w's start camera is 2w, its end camera 2w + 1.
        let (w, h) = (self.camera.width, self.camera.height);
        let per_window = self.schedule.rays_per_step / windows;
        let positives = ((1.0 - self.schedule.neg_ratio) * per_window as f64).round() as usize;
        self.rays.clear();
        self.ends.clear();
        self.sums.clear();
        self.channels.clear();
        let mut events = 0;
        for k in 0..windows {
            let (start, end) = (self.times[2 * k], self.times[2 * k + 1]);
            events += self.accumulate(start, end)?;
            for j in 0..per_window {
                let p = if j < positives && !self.nonzero.is_empty() {
                    self.nonzero[self.rng.random_range(0..self.nonzero.len())]
                } else {
                    self.rng.random_range(0..w * h)
                };
                let (x, y) = (p % w, p / w);
                let d_cam = self.directions[p];
                let current = self.poses.current();
                self.rays
                    .push(CameraRay::new(2 * k, &current[2 * k], d_cam));
                self.ends
                    .push(CameraRay::new(2 * k + 1, &current[2 * k + 1], d_cam));
                self.sums.push(self.frame[p]);
                self.channels.push(bayer_channel(x, y) as u8);
            }
        }

        // Both ends at the same depth strata: the same jitter offsets.
        let n = self.ends.len();
        self.rays.append(&mut self.ends);
        let k = self.settings.samples;
        self.offsets.clear();
        for _ in 0..n * k {
            self.offsets.push(self.rng.random());
        }
        self.offsets.extend_from_within(..);
        let out = self.renderer.forward_with_offsets(
            &mut *self.field,
            &self.settings,
            &self.rays,
            &self.offsets,
        );
        let scale = 1.0 / (3 * n) as f32;
        self.grad_out.clear();
        self.grad_out.resize(2 * n, Composited::default());
        let mut loss = 0.0f64;
        for i in 0..n {
            let c = usize::from(self.channels[i]);
            let (v, gs, ge) = self.schedule.loss.value_and_grad(
                out[i].rgb[c],
                out[n + i].rgb[c],
                self.sums[i],
                scale,
            );
            loss += f64::from(v);
            self.grad_out[i].rgb[c] = gs;
            self.grad_out[n + i].rgb[c] = ge;
        }
        if !loss.is_finite() {
            bail!("the event loss is {loss} at iteration {it}");
        }

        self.grad_params.fill(0.0);
        let trainable = self.poses.is_trained_at(it);
        self.pose_grads.clear();
        self.pose_grads
            .resize(self.times.len(), PoseGradient::new());
        self.renderer.backward(
            &mut *self.field,
            &self.settings,
            &self.rays,
            &self.grad_out,
            Some(&mut self.grad_params),
            trainable.then_some(&mut self.pose_grads[..]),
        );
        self.optimizer.step(&mut *self.field, &self.grad_params, it);
        let mut anchor = 0.0;
        if trainable {
            let current = self.poses.current();
            self.pose_cotangents.clear();
            for (g, pose) in self.pose_grads.iter().zip(current) {
                self.pose_cotangents
                    .push(g.quaternion_translation(&pose.rotation));
            }
            // The anchor term on the composed poses at the known times.
            let weight = self.schedule.anchor_weight / self.anchors.len().max(1) as f64;
            for (k, (_, known)) in self.anchors.iter().enumerate() {
                let pose = &current[2 * windows + k];
                let dt = pose.translation.vector - known.translation.vector;
                let (q, qk) = (pose.rotation.coords, known.rotation.coords);
                let dq = if q.dot(&qk) < 0.0 { q + qk } else { q - qk };
                anchor += weight * (dt.norm_squared() + dq.norm_squared());
                let (gq, gt) = &mut self.pose_cotangents[2 * windows + k];
                *gq += Quaternion::from(dq * (2.0 * weight));
                *gt += dt * (2.0 * weight);
            }
            self.poses.step(&self.pose_cotangents, it)?;
        }
        Ok(StepStats {
            loss,
            anchor,
            events,
        })
    }

    /// Writes the training state to a checkpoint: the field's parameters and their optimiser,
    /// the pose correction and its optimiser, and the random generator (the step count is the
    /// caller's).
    pub fn write_state(&self, w: &mut Writer) {
        w.f32s(self.field.params());
        w.adam(self.optimizer.adam());
        self.poses.write_state(w);
        w.rng(&self.rng);
    }

    /// Restores what [`EventTrainer::write_state`] wrote, into a trainer of the same setup; the
    /// next step continues exactly where the saved run stopped.
    pub fn read_state(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        r.f32s_into(self.field.params_mut(), "field")?;
        r.adam(self.optimizer.adam_mut())?;
        self.poses.read_state(r)?;
        self.rng = r.rng()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use cpose_core::nn::ExponentialDecay;
    use nalgebra::UnitQuaternion;

    use super::*;

    /// A small recording: the default turntable seen by a 43 × 32 sensor, 120 renders.
    fn tiny() -> (crate::EventNerfScene, Turntable) {
        let config = crate::SyntheticEventsConfig {
            camera: crate::SyntheticEventsConfig::default().camera.scaled(0.25),
            render_steps: 120,
            held_out_views: 0,
            ..Default::default()
        };
        let scene = cpose_nerf::scene::SyntheticScene::object_centric();
        let (data, _) = crate::simulate_eventnerf_scene(&scene, &config).unwrap();
        (data, config.turntable)
    }

    fn settings() -> RenderSettings {
        RenderSettings {
            samples: 24,
            sampling: cpose_nerf::render::Sampling::Metric {
                near: 1.0,
                far: 9.0,
            },
            background: Some([1.0; 3]),
            clip: Some(cpose_nerf::render::Clip {
                centre: [0.0; 3],
                radius: 1.8,
            }),
            last_interval: cpose_nerf::render::LastInterval::Closed,
        }
    }

    fn schedule(iterations: u64) -> EventSchedule {
        EventSchedule {
            iterations,
            rays_per_step: 256,
            windows_per_step: 4,
            window_secs: [0.05, 0.5],
            time_span: None,
            neg_ratio: 0.1,
            loss: EventLoss {
                threshold: 0.25,
                eps: 0.1,
            },
            field_lr: BTreeMap::from([
                ("grid".to_owned(), [1e-2, 1e-3]),
                ("mlp".to_owned(), [1e-3, 1e-4]),
            ]),
            anchor_weight: 1.0,
            anchor_windows: 0.0,
            seed: 1,
        }
    }

    /// The default hash grid in the sphere of radius 1.8 around the object.
    fn field() -> Box<dyn RadianceField> {
        let bounds = cpose_nerf::field3d::SceneBounds {
            centre: [0.0; 3],
            radius: 1.8,
            unbounded: false,
        };
        cpose_nerf::field3d::RadianceFieldConfig::default()
            .init::<f32>(bounds)
            .unwrap()
    }

    fn fixed_poses() -> FramePoses {
        let decay = ExponentialDecay {
            lr0: 0.0,
            lr_end: 0.0,
            max_iter: 1,
        };
        let schedules = cpose_nerf::poses::PoseSchedules {
            rotation: decay,
            translation: decay,
            pose: decay,
            hold: 0,
            warmup: 0,
            rotation_warmup: 0,
        };
        FramePoses::new(Vec::new(), Vec::new(), None, schedules)
    }

    /// With the true poses, EventNeRF's loss falls well below that of the blank field.
    #[test]
    fn training_on_true_poses_lowers_the_event_loss() {
        let (data, tt) = tiny();
        let initial = InitialPath::Turntable(tt);
        let mut field = field();
        let mut poses = fixed_poses();
        let steps = 300;
        let mut trainer = EventTrainer::new(
            field.as_mut(),
            &mut poses,
            &initial,
            Vec::new(),
            &data.events,
            data.camera,
            settings(),
            schedule(steps),
        )
        .unwrap();
        let losses: Vec<f64> = (0..steps)
            .map(|it| trainer.step(it).unwrap().loss)
            .collect();
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        let (first, last) = (mean(&losses[..30]), mean(&losses[steps as usize - 30..]));
        assert!(last < 0.7 * first, "first {first}, last {last}");
    }

    /// With `anchor_windows = 1` every window has an end on a known view, and stays inside the
    /// span with its drawn length.
    #[test]
    fn anchor_windows_end_on_known_views() {
        let (data, tt) = tiny();
        let known = [0.0, 2.5, 5.0, 7.5, 10.0];
        let anchors: Vec<_> = known
            .iter()
            .map(|&t| (t, tt.world_from_camera(t)))
            .collect();
        let initial = InitialPath::Turntable(tt);
        let mut field = field();
        let mut poses = fixed_poses();
        let mut s = schedule(1);
        s.anchor_windows = 1.0;
        s.time_span = Some([0.0, 10.0]);
        let mut trainer = EventTrainer::new(
            field.as_mut(),
            &mut poses,
            &initial,
            anchors,
            &data.events,
            data.camera,
            settings(),
            s,
        )
        .unwrap();
        for _ in 0..50 {
            trainer.draw_windows();
            for w in trainer.times.chunks(2) {
                let on_known = known.iter().any(|&k| k == w[0] || k == w[1]);
                assert!(on_known, "{w:?}");
                assert!(
                    0.0 <= w[0] && w[1] <= 10.0 && w[1] - w[0] >= 0.05 - 1e-12,
                    "{w:?}"
                );
            }
        }
    }

    /// A trainer restored from a checkpoint after 3 steps takes the same next steps as the one
    /// that went on: field, optimisers, PoseNet and the random draws all continue.
    #[test]
    fn a_restored_trainer_continues_exactly() {
        let (data, tt) = tiny();
        let anchors: Vec<_> = [0.0, 5.0, 10.0]
            .iter()
            .map(|&t| (t, tt.world_from_camera(t)))
            .collect();
        let initial = InitialPath::Turntable(tt);
        let posenet = || {
            let config = cpose_core::PoseNetConfig {
                width: 16,
                ..Default::default()
            };
            let range = cpose_core::TimeRange::new(0.0, 10.0).unwrap();
            let decay = ExponentialDecay {
                lr0: 1e-3,
                lr_end: 1e-4,
                max_iter: 6,
            };
            let schedules = cpose_nerf::poses::PoseSchedules {
                rotation: decay,
                translation: decay,
                pose: decay,
                hold: 0,
                warmup: 0,
                rotation_warmup: 0,
            };
            let field: Box<dyn cpose_core::PoseField> =
                Box::new(config.init::<f32>(range).unwrap());
            FramePoses::new(Vec::new(), Vec::new(), Some(field), schedules)
        };
        let mut s = schedule(6);
        s.anchor_windows = 0.5;
        let run = |restore: Option<&[u8]>, from: u64| {
            let (mut field, mut poses) = (field(), posenet());
            let mut trainer = EventTrainer::new(
                field.as_mut(),
                &mut poses,
                &initial,
                anchors.clone(),
                &data.events,
                data.camera,
                settings(),
                s.clone(),
            )
            .unwrap();
            if let Some(bytes) = restore {
                let path = std::path::Path::new("state.bin");
                let mut r = Reader::from_bytes(path, bytes.to_vec()).unwrap();
                trainer.read_state(&mut r).unwrap();
            }
            let mut losses = Vec::new();
            let mut saved = None;
            for it in from..6 {
                losses.push(trainer.step(it).unwrap().loss);
                if it == 2 {
                    let mut w = Writer::new();
                    trainer.write_state(&mut w);
                    saved = Some(w.into_bytes());
                }
            }
            (losses, saved, trainer.path_at(&[2.5, 7.5], 1.0).unwrap())
        };
        let (whole, saved, path) = run(None, 0);
        let (rest, _, resumed_path) = run(saved.as_deref(), 3);
        assert_eq!(rest, whole[3..]);
        assert_eq!(resumed_path, path);
    }

    #[test]
    fn bad_setups_are_errors() {
        let (data, tt) = tiny();
        let initial = InitialPath::Turntable(tt);
        let mut field = field();
        let mut poses = fixed_poses();
        let mut check = |events: &EventStream, camera: PinholeCamera, s: EventSchedule, what| {
            let err = EventTrainer::new(
                field.as_mut(),
                &mut poses,
                &initial,
                Vec::new(),
                events,
                camera,
                settings(),
                s,
            )
            .err()
            .unwrap_or_else(|| panic!("{what} accepted"));
            err.to_string()
        };
        let empty = EventStream::new(data.events.width(), data.events.height()).unwrap();
        assert!(check(&empty, data.camera, schedule(1), "no events").contains("no events"));
        let wrong = data.camera.scaled(2.0);
        assert!(check(&data.events, wrong, schedule(1), "a wrong sensor").contains("sensor"));
        let mut long = schedule(1);
        long.window_secs = [0.1, 20.0];
        assert!(check(&data.events, data.camera, long, "a long window").contains("window"));
        let mut none = schedule(1);
        none.windows_per_step = 0;
        assert!(check(&data.events, data.camera, none, "no windows").contains("window"));
    }

    #[test]
    fn pixel_directions_undistort_radially() {
        let camera = PinholeCamera::centred(9, 7, 5.0);
        let plain = pixel_directions(&camera, [0.0; 2]);
        assert_eq!(plain[2 * 9 + 3], camera.ray_direction_cam(3, 2));
        let (k1, k2) = (-0.2, 0.05);
        let bent = pixel_directions(&camera, [k1, k2]);
        for (p, b) in plain.iter().zip(&bent) {
            let r2 = p[0] * p[0] + p[1] * p[1];
            let f = 1.0 + k1 * r2 + k2 * r2 * r2;
            assert!((b[0] * f - p[0]).abs() < 1e-15 && (b[1] * f - p[1]).abs() < 1e-15);
            assert_eq!(b[2], 1.0);
        }
    }

    #[test]
    fn keyed_poses_interpolate_by_slerp_and_line() {
        let a = Isometry3::from_parts(Translation3::new(1.0, 0.0, 0.0), UnitQuaternion::identity());
        let b = Isometry3::from_parts(
            Translation3::new(0.0, 1.0, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0),
        );
        let keyed = KeyedPoses::new(vec![0.0, 2.0], vec![a, b]).unwrap();
        let mid = keyed.at(1.0);
        assert!((mid.translation.vector - Vector3::new(0.5, 0.5, 0.0)).norm() < 1e-12);
        assert!((mid.rotation.angle() - 0.5).abs() < 1e-12);
        assert_eq!(keyed.at(-1.0), a);
        assert_eq!(keyed.at(5.0), b);
        assert_eq!(keyed.at(2.0), b);
        assert!(KeyedPoses::new(vec![0.0, 0.0], vec![a, b]).is_err());
        assert!(KeyedPoses::new(vec![0.0], vec![a, b]).is_err());
    }

    /// Slerp between two poses of a turntable is exact for the rotation (one axis, constant
    /// rate); the position cuts the chord, `r (1 − cos(π/K))` inside the circle half-way.
    #[test]
    fn interpolating_a_turntable_errs_by_the_chord_sag() {
        let tt = Turntable::default();
        let k = 6;
        let times: Vec<f64> = (0..=k)
            .map(|i| i as f64 * tt.duration_secs / k as f64)
            .collect();
        let poses = times.iter().map(|&t| tt.world_from_camera(t)).collect();
        let keyed = KeyedPoses::new(times, poses).unwrap();
        let t = 0.5 * tt.duration_secs / k as f64;
        let (truth, interp) = (tt.world_from_camera(t), keyed.at(t));
        assert!(truth.rotation.angle_to(&interp.rotation) < 1e-9);
        let sag = tt.radius * (1.0 - (std::f64::consts::PI / k as f64).cos());
        let err = (truth.translation.vector - interp.translation.vector).norm();
        assert!((err - sag).abs() < 1e-9, "{err} vs {sag}");
    }
}
