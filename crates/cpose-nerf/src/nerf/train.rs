//! Joint optimisation of a radiance field and the training cameras' poses (BARF's loop).
//!
//! Every step draws the same `rays_per_step / N` random pixels in each of the `N` training
//! images (BARF: `train_data.all` with shared pixel indices), renders them from the current
//! poses with jittered depths, and takes one Adam step on the field (per parameter group) and
//! one on the pose correction, from the mean squared colour error
//! `L = 1/(3R) Σ_r ‖C_r − y_r‖²`.
//!
//! Field restarts ([`Schedule::field_restart_every`], not in the paper or BARF): every `K`
//! steps the field goes back to its initial parameters except its coarsest part
//! ([`RadianceField::kept_on_restart`], the hash grid's first level), the poses keep their
//! state, and each round runs the field's coarse-to-fine schedule and learning-rate decay
//! afresh. A field whose fine levels have converged on wrong poses holds them there; in each
//! round's coarse phase the poses move on, and the kept coarse level carries the scene's shape
//! from one round to the next.

use std::collections::BTreeMap;

use anyhow::bail;
use cpose_core::checkpoint::{Reader, Writer};
use nalgebra::{Quaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::camera::{PinholeCamera, PoseGradient};
use crate::field3d::{FieldOptimizer, RadianceField};
use crate::image::Image;
use crate::poses::FramePoses;
use crate::render::{CameraRay, Composited, RenderSettings, Renderer};

/// Optimisation settings of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Steps.
    pub iterations: u64,
    /// Rays per step over all training images.
    pub rays_per_step: usize,
    /// Learning rate `[start, end]` (exponential decay) per parameter group of the field.
    pub field_lr: BTreeMap<String, [f64; 2]>,
    /// Seed of the pixel and depth draws.
    pub seed: u64,
    /// Restart the field every this many steps (0: never) ...
    pub field_restart_every: u64,
    /// ... up to this step: the last restart is the last multiple of `field_restart_every`
    /// at or before it and before `iterations`, and its round runs to the end ([`field_round`]).
    pub field_restart_until: u64,
}

/// The field's round at iteration `it`, `(first step, steps)`: the field restarts at `k·every`
/// for every `k ≥ 1` with `k·every ≤ until` and `k·every < iterations`; the last round runs to
/// the end. One round of all `iterations` when `every` is 0 or no restart falls in range.
pub fn field_round(it: u64, every: u64, until: u64, iterations: u64) -> (u64, u64) {
    if every == 0 {
        return (0, iterations);
    }
    let last = (until.min(iterations.saturating_sub(1)) / every) * every;
    let start = (it / every * every).min(last);
    let end = if start == last {
        iterations
    } else {
        start + every
    };
    (start, end - start)
}

/// One training run's state (the field's coarse-to-fine progress is the step's place in its
/// [`field_round`]; the poses' is `it / iterations`).
pub struct Trainer<'a> {
    field: &'a mut dyn RadianceField,
    poses: &'a mut FramePoses,
    images: &'a [Image],
    camera: PinholeCamera,
    settings: RenderSettings,
    schedule: Schedule,
    optimizer: FieldOptimizer,
    rng: ChaCha8Rng,
    /// A permutation of the pixel indices `0..w·h`, the state of [`draw_distinct`].
    pixels: Vec<usize>,
    renderer: Renderer,
    rays: Vec<CameraRay>,
    targets: Vec<[f32; 3]>,
    grad_out: Vec<Composited<f32>>,
    grad_params: Vec<f32>,
    pose_grads: Vec<PoseGradient>,
    pose_cotangents: Vec<(Quaternion<f64>, Vector3<f64>)>,
    /// The field's parameters before the first step, for restarts (empty without them).
    initial_field: Vec<f32>,
}

impl<'a> Trainer<'a> {
    /// A run over `images` (one per frame of `poses`, all of `camera`'s size).
    pub fn new(
        field: &'a mut dyn RadianceField,
        poses: &'a mut FramePoses,
        images: &'a [Image],
        camera: PinholeCamera,
        settings: RenderSettings,
        schedule: Schedule,
    ) -> anyhow::Result<Self> {
        if images.len() != poses.times().len() || images.is_empty() {
            bail!(
                "{} training images for {} frame poses",
                images.len(),
                poses.times().len()
            );
        }
        let (_, first_round) = field_round(
            0,
            schedule.field_restart_every,
            schedule.field_restart_until,
            schedule.iterations,
        );
        let optimizer = FieldOptimizer::new(&*field, &schedule.field_lr, first_round)?;
        let n = field.num_params();
        let restarts = first_round < schedule.iterations;
        Ok(Self {
            initial_field: if restarts {
                field.params().to_vec()
            } else {
                Vec::new()
            },
            optimizer,
            grad_params: vec![0.0; n],
            rng: ChaCha8Rng::seed_from_u64(schedule.seed),
            pixels: (0..camera.width * camera.height).collect(),
            pose_grads: vec![PoseGradient::new(); images.len()],
            pose_cotangents: Vec::with_capacity(images.len()),
            field,
            poses,
            images,
            camera,
            settings,
            schedule,
            renderer: Renderer::default(),
            rays: Vec::new(),
            targets: Vec::new(),
            grad_out: Vec::new(),
        })
    }

    /// The poses being optimised.
    pub fn poses(&self) -> &FramePoses {
        self.poses
    }

    /// One step at iteration `it`; returns the loss (mean squared error) before the step.
    pub fn step(&mut self, it: u64) -> anyhow::Result<f64> {
        let progress = it as f64 / self.schedule.iterations.max(1) as f64;
        let (start, steps) = field_round(
            it,
            self.schedule.field_restart_every,
            self.schedule.field_restart_until,
            self.schedule.iterations,
        );
        if it == start && it > 0 && !self.initial_field.is_empty() {
            let kept = self.field.kept_on_restart();
            let params = self.field.params_mut();
            params[..kept.start].copy_from_slice(&self.initial_field[..kept.start]);
            params[kept.end..].copy_from_slice(&self.initial_field[kept.end..]);
            self.optimizer.restart(steps);
        }
        let field_it = it - start;
        self.field
            .set_progress(field_it as f64 / steps.max(1) as f64);
        let poses = self.poses.update(progress)?;
        let (w, h) = (self.camera.width, self.camera.height);
        let per_image = (self.schedule.rays_per_step / self.images.len()).clamp(1, w * h);
        let pixels = draw_distinct(&mut self.rng, &mut self.pixels, per_image);
        self.rays.clear();
        self.targets.clear();
        for (i, (pose, image)) in poses.iter().zip(self.images).enumerate() {
            for &p in pixels.iter() {
                let (x, y) = (p % w, p / w);
                self.rays
                    .push(CameraRay::new(i, pose, self.camera.ray_direction_cam(x, y)));
                self.targets.push(image.pixel(x, y));
            }
        }
        let out = self.renderer.forward(
            &mut *self.field,
            &self.settings,
            &self.rays,
            Some(&mut self.rng),
        );
        let r = out.len();
        let scale = 2.0 / (3 * r) as f32;
        let mut sse = 0.0f64;
        self.grad_out.clear();
        for (o, y) in out.iter().zip(&self.targets) {
            let mut g = Composited::default();
            for c in 0..3 {
                let e = o.rgb[c] - y[c];
                sse += (e as f64) * (e as f64);
                g.rgb[c] = scale * e;
            }
            self.grad_out.push(g);
        }
        let loss = sse / (3 * r) as f64;
        if !loss.is_finite() {
            bail!("the loss is {loss} at iteration {it}");
        }
        self.grad_params.fill(0.0);
        let trainable = self.poses.is_trained_at(it);
        for g in &mut self.pose_grads {
            *g = PoseGradient::new();
        }
        self.renderer.backward(
            &mut *self.field,
            &self.settings,
            &self.rays,
            &self.grad_out,
            Some(&mut self.grad_params),
            trainable.then_some(&mut self.pose_grads[..]),
        );
        self.optimizer
            .step(&mut *self.field, &self.grad_params, field_it);
        if trainable {
            self.pose_cotangents.clear();
            for (g, pose) in self.pose_grads.iter().zip(self.poses.current()) {
                self.pose_cotangents
                    .push(g.quaternion_translation(&pose.rotation));
            }
            self.poses.step(&self.pose_cotangents, it)?;
        }
        Ok(loss)
    }

    /// Writes everything the next steps depend on (the field and its optimiser, the random
    /// generator and pixel permutation, the pose correction and its optimiser), so that a run
    /// resumed by [`Trainer::load_state`] continues exactly. Errors without writing when a
    /// parameter is not finite (a diverged run), so the last good checkpoint stays.
    pub fn save_state(&self, w: &mut Writer) -> anyhow::Result<()> {
        let bad = self
            .field
            .params()
            .iter()
            .filter(|v| !v.is_finite())
            .count();
        let bad_pose = self
            .poses
            .params()
            .iter()
            .filter(|v| !v.is_finite())
            .count();
        if bad + bad_pose > 0 {
            bail!(
                "{bad} field and {bad_pose} pose parameters are not finite; not overwriting the \
                 last good checkpoint"
            );
        }
        w.f32s(self.field.params());
        w.adam(self.optimizer.adam());
        w.rng(&self.rng);
        w.f64s(&self.pixels.iter().map(|&p| p as f64).collect::<Vec<_>>());
        self.poses.write_state(w);
        Ok(())
    }

    /// Restores [`Trainer::save_state`] written after `it` steps into a trainer built with the
    /// same config.
    pub fn load_state(&mut self, r: &mut Reader, it: u64) -> anyhow::Result<()> {
        r.f32s_into(self.field.params_mut(), "field")?;
        let (start, steps) = field_round(
            it,
            self.schedule.field_restart_every,
            self.schedule.field_restart_until,
            self.schedule.iterations,
        );
        if start > 0 && !self.initial_field.is_empty() {
            self.optimizer.restart(steps);
        }
        r.adam(self.optimizer.adam_mut())?;
        self.rng = r.rng()?;
        let pixels = r.f64s()?;
        if pixels.len() != self.pixels.len() {
            bail!(
                "{}: the checkpoint's images have another size",
                r.path().display()
            );
        }
        self.pixels = pixels.into_iter().map(|p| p as usize).collect();
        self.poses.read_state(r)
    }
}

/// `k` distinct entries of `permutation` drawn uniformly at random, in random order: a partial
/// Fisher–Yates shuffle, which swaps entry `i = 0, …, k − 1` with a uniform `j ∈ [i, n)` and
/// returns the first `k`. The result is uniform over ordered `k`-subsets whatever order the
/// buffer is in, so the buffer is kept between calls instead of being reset (no allocation).
///
/// # Panics
/// If `k > permutation.len()`.
fn draw_distinct<'p>(rng: &mut impl RngExt, permutation: &'p mut [usize], k: usize) -> &'p [usize] {
    let n = permutation.len();
    assert!(k <= n, "cannot draw {k} distinct entries of {n}");
    for i in 0..k {
        permutation.swap(i, rng.random_range(i..n));
    }
    &permutation[..k]
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::field3d::{HashGridConfig, SceneBounds};
    use crate::poses::PoseSchedules;
    use crate::render::{LastInterval, Sampling};
    use crate::scene::{MonocularOrbit, SyntheticScene};
    use cpose_core::nn::ExponentialDecay;

    /// A small run on the synthetic scene: 4 views of 16×16 along the orbit, a small hash grid,
    /// BARF's per-frame correction starting at the true poses.
    pub(in crate::nerf) struct Tiny {
        pub field: Box<dyn RadianceField>,
        pub poses: FramePoses,
        pub images: Vec<Image>,
        pub camera: PinholeCamera,
    }

    impl Tiny {
        pub fn new() -> Self {
            let orbit = MonocularOrbit {
                frames: 4,
                ..MonocularOrbit::default()
            };
            let camera = PinholeCamera::from_fov_x(16, 16, 40f64.to_radians());
            let scene = SyntheticScene::object_centric();
            let times = orbit.frame_times();
            let truth: Vec<_> = times.iter().map(|&t| orbit.world_from_camera(t)).collect();
            let images = truth
                .iter()
                .map(|pose| scene.render(&camera, pose, 1).image)
                .collect();
            let bounds = SceneBounds {
                centre: [0.0; 3],
                radius: scene.bounding_radius(),
                unbounded: false,
            };
            let grid = HashGridConfig {
                levels: 4,
                log2_table_size: 10,
                ..HashGridConfig::default()
            };
            let decay = |lr0| ExponentialDecay {
                lr0,
                lr_end: lr0,
                max_iter: 10,
            };
            let correction = cpose_core::DiscretePoses::<f32>::new(&times).unwrap();
            Self {
                field: Box::new(grid.init::<f32>(bounds).unwrap()),
                poses: FramePoses::new(
                    truth,
                    times,
                    Some(Box::new(correction)),
                    PoseSchedules {
                        rotation: decay(1e-3),
                        translation: decay(1e-3),
                        pose: decay(1e-3),
                        warmup: 0,
                        hold: 0,
                        rotation_warmup: 0,
                    },
                ),
                images,
                camera,
            }
        }

        /// A trainer of `iterations` steps of 64 rays × 16 samples, seed 0.
        pub fn trainer(&mut self, iterations: u64) -> Trainer<'_> {
            self.trainer_restarting(iterations, 0)
        }

        /// The same with the field restarted every `every` steps to the end.
        pub fn trainer_restarting(&mut self, iterations: u64, every: u64) -> Trainer<'_> {
            let settings = RenderSettings {
                last_interval: LastInterval::Closed,
                samples: 16,
                sampling: Sampling::Metric {
                    near: 2.0,
                    far: 6.0,
                },
                background: Some([1.0; 3]),
                clip: None,
            };
            let schedule = Schedule {
                iterations,
                rays_per_step: 64,
                field_lr: BTreeMap::from([
                    ("grid".to_owned(), [1e-2, 1e-3]),
                    ("mlp".to_owned(), [1e-3, 1e-4]),
                ]),
                seed: 0,
                field_restart_every: every,
                field_restart_until: iterations,
            };
            Trainer::new(
                self.field.as_mut(),
                &mut self.poses,
                &self.images,
                self.camera,
                settings,
                schedule,
            )
            .unwrap()
        }
    }

    #[test]
    fn draw_distinct_is_uniform_over_distinct_entries_and_seeded() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut permutation: Vec<usize> = (0..10).collect();
        let mut counts = [0usize; 10];
        let draws = 20_000;
        for _ in 0..draws {
            let drawn = draw_distinct(&mut rng, &mut permutation, 4);
            let mut sorted = drawn.to_vec();
            sorted.sort();
            sorted.dedup();
            assert_eq!(sorted.len(), 4, "{drawn:?}");
            for &p in drawn {
                counts[p] += 1;
            }
        }
        // Each entry is drawn with probability 4/10: 8000 of 20,000, binomial standard
        // deviation sqrt(20,000 · 0.4 · 0.6) ≈ 69, so ±400 is about 6σ.
        for (p, &c) in counts.iter().enumerate() {
            assert!(c.abs_diff(8000) < 400, "entry {p}: {c}");
        }
        // Still a permutation; all of it when k = n.
        let mut all = draw_distinct(&mut rng, &mut permutation, 10).to_vec();
        all.sort();
        assert_eq!(all, (0..10).collect::<Vec<_>>());
        // The same seed and buffer give the same draws.
        let draw = |seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut permutation: Vec<usize> = (0..100).collect();
            (0..3)
                .map(|_| draw_distinct(&mut rng, &mut permutation, 5).to_vec())
                .collect::<Vec<_>>()
        };
        assert_eq!(draw(1), draw(1));
        assert_ne!(draw(1), draw(2));
    }

    #[test]
    fn steps_are_deterministic_for_a_seed() {
        let losses = || {
            let mut tiny = Tiny::new();
            let mut trainer = tiny.trainer(3);
            (0..3)
                .map(|it| trainer.step(it).unwrap())
                .collect::<Vec<_>>()
        };
        let first = losses();
        assert!(first.iter().all(|l| l.is_finite() && *l > 0.0), "{first:?}");
        assert_eq!(first, losses());
    }

    #[test]
    fn field_rounds_restart_every_k_steps_until_the_last_which_runs_to_the_end() {
        let rounds = |every, until, iterations| {
            let mut starts: Vec<(u64, u64)> = (0..iterations)
                .map(|it| field_round(it, every, until, iterations))
                .collect();
            starts.dedup();
            starts
        };
        assert_eq!(rounds(0, 10, 10), [(0, 10)]);
        assert_eq!(rounds(6, 5, 10), [(0, 10)]);
        assert_eq!(rounds(5, 10, 10), [(0, 5), (5, 5)]);
        assert_eq!(rounds(3, 10, 10), [(0, 3), (3, 3), (6, 3), (9, 1)]);
        assert_eq!(rounds(3, 7, 10), [(0, 3), (3, 3), (6, 4)]);
        assert_eq!(rounds(4, 3, 11), [(0, 11)]);
        let long = rounds(750, 4500, 6000);
        assert_eq!(long.len(), 7);
        assert_eq!(long[6], (4500, 1500));
    }

    /// A restart puts the field back to its initial parameters but for its first grid level,
    /// with fresh Adam moments and schedules, and leaves the poses where they are. One Adam step
    /// moves a parameter by at most its group's learning rate, so after the restart at step 2
    /// and one more step no parameter outside the first level is further than that from its
    /// start; three steps without the restart move some further (in the first level too), and
    /// the per-frame poses keep the three steps they took (each at most 1e-3).
    #[test]
    fn a_restart_reinitialises_the_field_and_keeps_the_poses() {
        let run = |every| {
            let mut tiny = Tiny::new();
            let initial = tiny.field.params().to_vec();
            let mut trainer = tiny.trainer_restarting(4, every);
            for it in 0..3 {
                trainer.step(it).unwrap();
            }
            // Each parameter's distance from its start in steps of its learning rate.
            let mut moved = vec![0.0f64; initial.len()];
            for (group, range) in trainer.field.param_groups() {
                let lr = trainer.schedule.field_lr[group][0];
                for k in range {
                    moved[k] = f64::from((trainer.field.params()[k] - initial[k]).abs()) / lr;
                }
            }
            let first = trainer.field.kept_on_restart();
            let furthest =
                |ks: &mut dyn Iterator<Item = usize>| ks.map(|k| moved[k]).fold(0.0, f64::max);
            let coarse = furthest(&mut first.clone());
            let rest = furthest(&mut (0..first.start).chain(first.end..moved.len()));
            let poses = trainer
                .poses
                .params()
                .iter()
                .fold(0.0f32, |m, v| m.max(v.abs()));
            (coarse, rest, poses)
        };
        let (coarse, rest, poses) = run(0);
        let (restarted_coarse, restarted_rest, restarted_poses) = run(2);
        assert!(coarse > 1.5 && rest > 1.5, "{coarse} {rest}");
        assert!(restarted_coarse > 1.5, "{restarted_coarse}");
        assert!(restarted_rest <= 1.0 + 1e-3, "{restarted_rest}");
        assert!(
            poses > 1.5e-3 && restarted_poses > 1.5e-3,
            "{poses} {restarted_poses}"
        );
    }

    /// A state saved after `k` steps and loaded into a new trainer continues exactly as the
    /// original, with and without field restarts (a restart at step 2, resumed inside and at
    /// the start of a round).
    #[test]
    fn a_saved_state_continues_bit_for_bit() {
        for (restart_every, k) in [(0, 3), (2, 3), (2, 4)] {
            let losses = |resume_at: Option<u64>| -> Vec<f64> {
                let mut tiny = Tiny::new();
                let mut trainer = if restart_every > 0 {
                    tiny.trainer_restarting(8, restart_every)
                } else {
                    tiny.trainer(8)
                };
                let mut out = Vec::new();
                let mut it = 0;
                if let Some(k) = resume_at {
                    for i in 0..k {
                        trainer.step(i).unwrap();
                    }
                    let mut w = Writer::new();
                    trainer.save_state(&mut w).unwrap();
                    let path = std::path::Path::new("state.bin");
                    let mut r = Reader::from_bytes(path, w.into_bytes()).unwrap();
                    let mut fresh = Tiny::new();
                    let mut resumed = if restart_every > 0 {
                        fresh.trainer_restarting(8, restart_every)
                    } else {
                        fresh.trainer(8)
                    };
                    resumed.load_state(&mut r, k).unwrap();
                    for i in k..8 {
                        out.push(resumed.step(i).unwrap());
                    }
                    return out;
                }
                while it < 8 {
                    let loss = trainer.step(it).unwrap();
                    if it >= k {
                        out.push(loss);
                    }
                    it += 1;
                }
                out
            };
            assert_eq!(
                losses(Some(k)),
                losses(None),
                "restart every {restart_every}, k {k}"
            );
        }
    }

    /// Issue "a NaN loss — one clear message, the last good checkpoint kept": a diverged state
    /// is not saved.
    #[test]
    fn a_non_finite_loss_stops_the_step_and_its_state_is_not_saved() {
        let mut tiny = Tiny::new();
        let mut trainer = tiny.trainer(10);
        trainer.step(0).unwrap();
        trainer.save_state(&mut Writer::new()).unwrap();
        // Every field parameter NaN: the loss of the next step is NaN.
        trainer.field.params_mut().fill(f32::NAN);
        let err = trainer.step(1).unwrap_err().to_string();
        assert_eq!(err, "the loss is NaN at iteration 1");
        let err = trainer
            .save_state(&mut Writer::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("not finite") && err.contains("not overwriting the last good checkpoint"),
            "{err}"
        );
        assert_eq!(err.lines().count(), 1, "{err}");
    }
}
