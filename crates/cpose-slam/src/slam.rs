//! The SLAM loop (NICE-SLAM's, single process, bundle adjustment off as in the paper): frame 0
//! takes its true pose and initialises the map; every later frame is tracked against the frozen
//! map with a [`PoseModel`], the best-loss pose is kept, and every `mapping.every` frames the map
//! is trained over a window of keyframes plus the current frame at their estimated poses.

use std::time::Instant;

use cpose_nerf::camera::{PinholeCamera, PoseGradient};
use cpose_nerf::render::CameraRay;
use nalgebra::Isometry3;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::data::{DepthImage, RgbdFrame};
use crate::map::{NeuralMap, PixelSample};
use crate::track::PoseModel;
use cpose_core::checkpoint::{Reader, Writer};
use cpose_nerf::mesh::{Grid, Mesh};

/// Tracking settings; `[tracking]` in a config.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingConfig {
    /// Optimiser steps per frame (NICE-SLAM Replica: 10).
    pub iterations: usize,
    /// Pixels with a depth reading per step (NICE-SLAM Replica: 200).
    pub pixels: usize,
    /// Pixels ignored at every image border (NICE-SLAM Replica: 100 of 1200).
    pub edge: usize,
    /// Learning rate of the free pose (NICE-SLAM Replica: 1e-3).
    pub lr: f64,
    /// Factor on the free pose's rotation rate (NICE-SLAM TUM: 0.2).
    pub rotation_lr_factor: f64,
    /// A frame whose pose moves farther than this from its start (metres) is reported lost.
    pub lost_translation: f64,
    /// A frame whose median depth error `|D̂ − D|` at the chosen pose exceeds this (metres) is
    /// reported lost: the map does not explain it (a track that drifts off slowly).
    pub lost_depth_error: f64,
}

impl TrackingConfig {
    /// Checks the values; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("lr", self.lr),
            ("rotation_lr_factor", self.rotation_lr_factor),
            ("lost_translation", self.lost_translation),
            ("lost_depth_error", self.lost_depth_error),
        ];
        for (key, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{key} = {value} must be a positive number"));
            }
        }
        if self.pixels == 0 {
            return Err("pixels = 0 must be at least 1".into());
        }
        Ok(())
    }
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            iterations: 20,
            pixels: 400,
            edge: 10,
            lr: 1e-3,
            rotation_lr_factor: 1.0,
            lost_translation: 0.5,
            lost_depth_error: 0.2,
        }
    }
}

/// Mapping settings; `[mapping]` in a config.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct MappingConfig {
    /// Map every this many frames (NICE-SLAM: 5).
    pub every: usize,
    /// Optimiser steps per mapping call (NICE-SLAM: 60).
    pub iterations: usize,
    /// Steps on frame 0 (NICE-SLAM: 1500).
    pub first_iterations: usize,
    /// Pixels per step, split over the window's frames (NICE-SLAM Replica: 1000).
    pub pixels: usize,
    /// Frames in a mapping window: keyframes, the last keyframe and the current frame
    /// (NICE-SLAM Replica: 5).
    pub window: usize,
    /// A keyframe every this many frames (NICE-SLAM: 50).
    pub keyframe_every: usize,
}

impl Default for MappingConfig {
    fn default() -> Self {
        Self {
            every: 5,
            iterations: 30,
            first_iterations: 300,
            pixels: 1024,
            window: 5,
            keyframe_every: 25,
        }
    }
}

/// What one tracked frame reports.
#[derive(Clone, Copy, Debug)]
pub struct TrackReport {
    /// `world_from_camera` the frame started from: the pose model's prediction.
    pub start: Isometry3<f64>,
    /// Best tracking loss.
    pub loss: f64,
    /// Distance of the chosen pose from the starting prediction, metres.
    pub moved: f64,
    /// Median depth error at the chosen pose, metres.
    pub depth_error: f64,
    /// Whether the track counts as lost ([`TrackingConfig::lost_translation`],
    /// [`TrackingConfig::lost_depth_error`]).
    pub lost: bool,
    /// A lost frame whose start was measured ([`PoseModel::start_is_measured`]): its estimate is
    /// the start instead of the lost track, and it is left out of the map.
    pub recovered: bool,
}

/// The state of one SLAM run.
pub struct Slam {
    /// The map.
    pub map: NeuralMap,
    camera: PinholeCamera,
    tracking: TrackingConfig,
    mapping: MappingConfig,
    /// Estimated `world_from_camera` of every processed frame.
    pub estimates: Vec<Isometry3<f64>>,
    /// The same as `world_from_body` ([`Slam::set_body_from_camera`]), what the model tracks.
    bodies: Vec<Isometry3<f64>>,
    /// The camera's mount on the tracked body (identity: the body is the camera).
    body_from_camera: Isometry3<f64>,
    /// Keyframes with their run index.
    keyframes: Vec<(usize, RgbdFrame)>,
    seed: u64,
    pixels: Vec<PixelSample>,
    pose_grads: Vec<PoseGradient>,
    /// Time spent tracking and mapping so far (kept across a resume).
    pub timing: StageTimes,
}

/// Seconds spent in each stage of a run, for the tracking and mapping speeds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Seconds tracking frames (every frame after the first).
    pub tracking_s: f64,
    /// Seconds training the map, over every processed frame (mapping runs every
    /// [`MappingConfig::every`] frames).
    pub mapping_s: f64,
}

impl Slam {
    /// A run on frames of `camera` with a fresh `map`.
    pub fn new(
        map: NeuralMap,
        camera: PinholeCamera,
        tracking: &TrackingConfig,
        mapping: &MappingConfig,
        seed: u64,
    ) -> anyhow::Result<Self> {
        if tracking.pixels == 0 || mapping.pixels == 0 || mapping.every == 0 {
            anyhow::bail!("tracking.pixels, mapping.pixels and mapping.every must be ≥ 1");
        }
        if mapping.window < 2 || mapping.keyframe_every == 0 {
            anyhow::bail!("mapping.window must be ≥ 2 and mapping.keyframe_every ≥ 1");
        }
        if 2 * tracking.edge >= camera.width.min(camera.height) {
            anyhow::bail!(
                "tracking.edge = {} leaves no pixels of a {}×{} image",
                tracking.edge,
                camera.width,
                camera.height
            );
        }
        Ok(Self {
            map,
            camera,
            tracking: tracking.clone(),
            mapping: mapping.clone(),
            estimates: Vec::new(),
            bodies: Vec::new(),
            body_from_camera: Isometry3::identity(),
            keyframes: Vec::new(),
            seed,
            pixels: Vec::new(),
            pose_grads: Vec::new(),
            timing: StageTimes::default(),
        })
    }

    /// Mounts the camera on a body (a sensor rig) at `body_from_camera`: from then on the pose
    /// model tracks `world_from_body`, and frames are seen from `world_from_body ∘
    /// body_from_camera` (the estimates stay camera poses). Set it before the first frame.
    pub fn set_body_from_camera(&mut self, body_from_camera: Isometry3<f64>) {
        self.body_from_camera = body_from_camera;
    }

    /// Frames per second of tracking alone (every frame after the first is tracked).
    pub fn tracking_fps(&self) -> f64 {
        self.estimates.len().saturating_sub(1) as f64 / self.timing.tracking_s
    }

    /// Frames per second of mapping alone: the processed frames over the mapping time, so
    /// mapping's cost is spread over the frames it runs for.
    pub fn mapping_fps(&self) -> f64 {
        self.estimates.len() as f64 / self.timing.mapping_s
    }

    /// A mesh of the map on `grid` at density `level`, culled to the space the keyframes saw:
    /// a triangle stays if some keyframe sees its centre no more than `margin` metres behind the
    /// measured depth (NICE-SLAM culls its meshes to the cameras' frusta likewise).
    pub fn mesh(&mut self, grid: &Grid, level: f32, margin: f64) -> Mesh {
        let views: Vec<(Isometry3<f64>, &DepthImage)> = self
            .keyframes
            .iter()
            .filter_map(|(i, kf)| Some((self.estimates.get(*i)?.inverse(), &kf.depth)))
            .collect();
        let camera = &self.camera;
        let observed = |p: [f64; 3]| {
            views.iter().any(|(camera_from_world, depth)| {
                let q = camera_from_world * nalgebra::Point3::from(p);
                let Some([u, v]) = camera.project(&q.coords) else {
                    return false;
                };
                if u < 0.0 || v < 0.0 {
                    return false;
                }
                let (x, y) = (u as usize, v as usize);
                if x >= depth.width() || y >= depth.height() {
                    return false;
                }
                let d = depth.at(x, y) as f64;
                d > 0.0 && q.z <= d + margin
            })
        };
        self.map.mesh(grid, level, observed)
    }

    /// Writes the run's state after its last processed frame: estimates, keyframes, map, stage
    /// times.
    pub fn save(&self, w: &mut Writer) {
        w.poses(&self.estimates);
        w.f64s(
            &self
                .keyframes
                .iter()
                .map(|(i, _)| *i as f64)
                .collect::<Vec<_>>(),
        );
        self.map.save(w);
        let t = &self.timing;
        w.f64s(&[t.tracking_s, t.mapping_s]);
    }

    /// Restores [`Slam::save`]; `frame(i)` reloads the keyframes' data.
    pub fn load(
        &mut self,
        r: &mut Reader,
        mut frame: impl FnMut(usize) -> anyhow::Result<RgbdFrame>,
    ) -> anyhow::Result<()> {
        self.estimates = r.poses()?;
        let camera_from_body = self.body_from_camera.inverse();
        self.bodies = self
            .estimates
            .iter()
            .map(|c| c * camera_from_body)
            .collect();
        self.keyframes.clear();
        for i in r.f64s()? {
            let i = i as usize;
            self.keyframes.push((i, frame(i)?));
        }
        self.map.load(r)?;
        let [tracking_s, mapping_s] = r.f64s()?[..] else {
            anyhow::bail!("checkpoint: expected two stage times");
        };
        self.timing = StageTimes {
            tracking_s,
            mapping_s,
        };
        Ok(())
    }

    /// A generator for frame `index` and stage `stage`: runs are reproducible frame by frame.
    fn rng(&self, index: usize, stage: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(
            self.seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add((index as u64) << 8 | stage),
        )
    }

    /// Processes the next frame: frame 0 is placed at `start` (its true camera pose) and initialises
    /// the map; later frames are tracked with `model`. Maps when due. Returns the tracking
    /// report (none for frame 0).
    pub fn process(
        &mut self,
        frame: RgbdFrame,
        start: Isometry3<f64>,
        model: &mut dyn PoseModel,
    ) -> anyhow::Result<Option<TrackReport>> {
        let index = self.estimates.len();
        let report = if index == 0 {
            self.estimates.push(start);
            self.bodies.push(start * self.body_from_camera.inverse());
            None
        } else {
            let started = Instant::now();
            let r = self.track(&frame, index, model)?;
            self.timing.tracking_s += started.elapsed().as_secs_f64();
            Some(r)
        };
        // A recovered frame's pose is a prediction the images did not confirm: not mapped.
        let mapped = !report.is_some_and(|r| r.recovered);
        let is_keyframe = mapped && index.is_multiple_of(self.mapping.keyframe_every);
        let started = Instant::now();
        if index == 0 {
            self.map_window(&frame, index, self.mapping.first_iterations);
        } else if mapped && index.is_multiple_of(self.mapping.every) {
            self.map_window(&frame, index, self.mapping.iterations);
        }
        self.timing.mapping_s += started.elapsed().as_secs_f64();
        if is_keyframe {
            self.keyframes.push((index, frame));
        }
        Ok(report)
    }

    /// Tracks `frame` (index `index ≥ 1`).
    fn track(
        &mut self,
        frame: &RgbdFrame,
        index: usize,
        model: &mut dyn PoseModel,
    ) -> anyhow::Result<TrackReport> {
        let mount = self.body_from_camera;
        let start = model.begin(index, frame.time, &self.bodies)?;
        let mut rng = self.rng(index, 1);
        let mut best = (f64::INFINITY, start, 0.0);
        self.pose_grads.resize(1, PoseGradient::new());
        for _ in 0..self.tracking.iterations {
            let body = model.pose();
            let pose = body * mount;
            let edge = self.tracking.edge;
            sample_pixels(
                frame,
                &self.camera,
                &pose,
                0,
                self.tracking.pixels,
                edge,
                &mut rng,
                &mut self.pixels,
            );
            if self.pixels.is_empty() {
                anyhow::bail!("frame {index} has no pixel with a depth reading to track");
            }
            self.pose_grads[0] = PoseGradient::new();
            let loss = self
                .map
                .tracking_loss(&self.pixels, &mut rng, &mut self.pose_grads);
            if !loss.is_finite() {
                anyhow::bail!("tracking loss is {loss} at frame {index}");
            }
            if loss < best.0 {
                best = (loss, body, self.map.depth_error());
                model.keep_best();
            }
            let (gq, gt) = self.pose_grads[0]
                .to_body(&mount)
                .quaternion_translation(&body.rotation);
            model.step(&gq, &gt)?;
        }
        let (loss, tracked, depth_error) = best;
        let moved = (tracked.translation.vector - start.translation.vector).norm();
        let lost =
            moved > self.tracking.lost_translation || depth_error > self.tracking.lost_depth_error;
        let recovered = lost && model.start_is_measured();
        let body = if recovered { start } else { tracked };
        model.finish(index, frame.time, &body)?;
        self.bodies.push(body);
        self.estimates.push(body * mount);
        Ok(TrackReport {
            start: start * mount,
            loss: loss / self.tracking.pixels as f64,
            moved,
            depth_error,
            lost,
            recovered,
        })
    }

    /// Trains the map on a window: random earlier keyframes, the last keyframe and `frame`.
    fn map_window(&mut self, frame: &RgbdFrame, index: usize, iterations: usize) {
        let mut rng = self.rng(index, 2);
        let mut window: Vec<usize> = Vec::new();
        if let Some(last) = self.keyframes.len().checked_sub(1) {
            let mut earlier: Vec<usize> = (0..last).collect();
            earlier.shuffle(&mut rng);
            window.extend(
                earlier
                    .into_iter()
                    .take(self.mapping.window.saturating_sub(2)),
            );
            window.push(last);
        }
        let frames: Vec<(&RgbdFrame, Isometry3<f64>)> = window
            .iter()
            .map(|&k| {
                let (i, kf) = &self.keyframes[k];
                (kf, self.estimates[*i])
            })
            .chain(std::iter::once((frame, self.estimates[index])))
            .collect();
        let per_frame = self.mapping.pixels.div_ceil(frames.len());
        let mut batch = Vec::with_capacity(per_frame * frames.len());
        let mut scratch = Vec::new();
        for _ in 0..iterations {
            batch.clear();
            for (c, (f, pose)) in frames.iter().enumerate() {
                sample_pixels(
                    f,
                    &self.camera,
                    pose,
                    c,
                    per_frame,
                    0,
                    &mut rng,
                    &mut scratch,
                );
                batch.extend_from_slice(&scratch);
            }
            if !batch.is_empty() {
                self.map.mapping_step(&batch, &mut rng);
            }
        }
    }
}

/// Samples up to `n` pixels with a depth reading, uniformly inside the `edge` border, as rays
/// of camera `camera_index` at `pose` (at most `4n` draws).
pub fn sample_pixels<R: RngExt + ?Sized>(
    frame: &RgbdFrame,
    camera: &PinholeCamera,
    pose: &Isometry3<f64>,
    camera_index: usize,
    n: usize,
    edge: usize,
    rng: &mut R,
    out: &mut Vec<PixelSample>,
) {
    out.clear();
    let (w, h) = (camera.width, camera.height);
    for _ in 0..4 * n {
        if out.len() == n {
            break;
        }
        let x = rng.random_range(edge..w - edge);
        let y = rng.random_range(edge..h - edge);
        let depth = frame.depth.at(x, y);
        if depth <= 0.0 {
            continue;
        }
        out.push(PixelSample {
            ray: CameraRay::new(camera_index, pose, camera.ray_direction_cam(x, y)),
            color: frame.color.pixel(x, y),
            depth,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::RgbdFrame;
    use crate::synth::{RoomConfig, RoomMotion, render_frame, room_scene};
    use crate::track::{FreePose, PoseNetTrackConfig, PoseNetTracker, Reference};
    use cpose_core::TimeRange;
    use cpose_nerf::field3d::SceneBounds;
    use nalgebra::{Quaternion, Vector3};
    use std::path::Path;

    /// The walk through the room at 128×73 for `frames` frames, its camera and true poses.
    fn walk(frames: usize) -> (RoomConfig, PinholeCamera, Vec<Isometry3<f64>>) {
        let config = RoomConfig {
            width: 128,
            frames,
            ..RoomConfig::default()
        };
        let intrinsics = config.intrinsics();
        let camera = intrinsics
            .camera_for(intrinsics.width, intrinsics.height, Path::new("test"))
            .unwrap();
        let poses = RoomMotion::from_config(&config).unwrap().camera_poses();
        (config, camera, poses)
    }

    /// A fresh run over the room's box.
    fn room_slam(
        camera: PinholeCamera,
        tracking: &TrackingConfig,
        mapping: &MappingConfig,
    ) -> Slam {
        let bounds = SceneBounds {
            centre: [0.0, 0.0, 1.4],
            radius: 3.3,
            unbounded: false,
        };
        let map = NeuralMap::new(&crate::map::MapConfig::default(), bounds).unwrap();
        Slam::new(map, camera, tracking, mapping, 0).unwrap()
    }

    /// Frame `i` of the room seen from `pose`, with depth noise.
    fn room_frame(
        config: &RoomConfig,
        camera: &PinholeCamera,
        pose: &Isometry3<f64>,
        i: usize,
    ) -> RgbdFrame {
        let (color, depth) = render_frame(&room_scene(), camera, pose, 1, true, 0, i, 1.0);
        RgbdFrame {
            index: i,
            time: i as f64 / config.frame_rate,
            color,
            depth,
        }
    }

    /// A pose model that stays where it is put (tracking cannot move it).
    struct Fixed(Isometry3<f64>);

    impl PoseModel for Fixed {
        fn begin(
            &mut self,
            _: usize,
            _: f64,
            _: &[Isometry3<f64>],
        ) -> anyhow::Result<Isometry3<f64>> {
            Ok(self.0)
        }
        fn pose(&self) -> Isometry3<f64> {
            self.0
        }
        fn step(&mut self, _: &Quaternion<f64>, _: &Vector3<f64>) -> anyhow::Result<()> {
            Ok(())
        }
        fn finish(&mut self, _: usize, _: f64, _: &Isometry3<f64>) -> anyhow::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_frame_the_map_does_not_explain_is_reported_lost() {
        let (config, camera, poses) = walk(3);
        let mapping = MappingConfig {
            first_iterations: 200,
            pixels: 512,
            ..MappingConfig::default()
        };
        let mut slam = room_slam(camera, &TrackingConfig::default(), &mapping);
        let frame = |i: usize| room_frame(&config, &camera, &poses[i], i);
        slam.process(frame(0), poses[0], &mut Fixed(poses[0]))
            .unwrap();
        // At the true pose the map explains the frame; 40 cm to the side and turned by 60°, a
        // pose that moves nothing while tracking, it does not.
        let good = slam
            .process(frame(1), poses[0], &mut Fixed(poses[1]))
            .unwrap()
            .unwrap();
        assert!(!good.lost && good.depth_error < 0.05, "{good:?}");
        let off =
            poses[2] * Isometry3::new(Vector3::new(0.4, 0.0, 0.0), Vector3::new(0.0, 1.05, 0.0));
        let bad = slam
            .process(frame(2), poses[0], &mut Fixed(off))
            .unwrap()
            .unwrap();
        assert!(bad.lost && bad.moved == 0.0, "{bad:?}");
    }

    /// Starts at a pose and tracks to another at once.
    struct Jumping {
        start: Isometry3<f64>,
        to: Isometry3<f64>,
        measured: bool,
    }

    impl PoseModel for Jumping {
        fn begin(
            &mut self,
            _: usize,
            _: f64,
            _: &[Isometry3<f64>],
        ) -> anyhow::Result<Isometry3<f64>> {
            Ok(self.start)
        }
        fn pose(&self) -> Isometry3<f64> {
            self.to
        }
        fn step(&mut self, _: &Quaternion<f64>, _: &Vector3<f64>) -> anyhow::Result<()> {
            Ok(())
        }
        fn finish(&mut self, _: usize, _: f64, _: &Isometry3<f64>) -> anyhow::Result<()> {
            Ok(())
        }
        fn start_is_measured(&self) -> bool {
            self.measured
        }
    }

    /// A track lost 1 m away from a measured start falls back to the start; from the model's own
    /// extrapolation, it keeps the tracked pose (and is only reported).
    #[test]
    fn a_lost_frame_falls_back_to_a_measured_start() {
        let (config, camera, poses) = walk(2);
        let mapping = MappingConfig {
            first_iterations: 20,
            ..MappingConfig::default()
        };
        let tracking = TrackingConfig {
            iterations: 2,
            ..TrackingConfig::default()
        };
        let far = poses[1] * Isometry3::translation(1.0, 0.0, 0.0);
        for measured in [true, false] {
            let mut slam = room_slam(camera, &tracking, &mapping);
            let frame = |i: usize| room_frame(&config, &camera, &poses[i], i);
            slam.process(frame(0), poses[0], &mut Fixed(poses[0]))
                .unwrap();
            let mut model = Jumping {
                start: poses[1],
                to: far,
                measured,
            };
            let report = slam
                .process(frame(1), poses[0], &mut model)
                .unwrap()
                .unwrap();
            assert!(report.lost && report.recovered == measured, "{report:?}");
            let kept = if measured { poses[1] } else { far };
            let estimate = slam.estimates[1] * slam.body_from_camera.inverse();
            assert!(
                (estimate.translation.vector - kept.translation.vector).norm() < 1e-12,
                "{measured}: {estimate:?}"
            );
        }
    }

    /// Runs `frames` frames of the synthetic room at 128×73 and returns the mean position error
    /// of the tracked frames, the mean distance the camera moved from frame 0, and the run.
    fn run(model: &mut dyn PoseModel, frames: usize) -> (f64, f64, Slam) {
        let (config, camera, poses) = walk(frames);
        let tracking = TrackingConfig {
            edge: 2,
            pixels: 200,
            ..TrackingConfig::default()
        };
        let mapping = MappingConfig {
            first_iterations: 300,
            iterations: 15,
            pixels: 512,
            ..MappingConfig::default()
        };
        let mut slam = room_slam(camera, &tracking, &mapping);
        for (i, pose) in poses.iter().enumerate() {
            slam.process(room_frame(&config, &camera, pose, i), poses[0], model)
                .unwrap();
        }
        let n = frames - 1;
        let error = (1..frames)
            .map(|i| (slam.estimates[i].translation.vector - poses[i].translation.vector).norm())
            .sum::<f64>()
            / n as f64;
        let motion = (1..frames)
            .map(|i| (poses[0].translation.vector - poses[i].translation.vector).norm())
            .sum::<f64>()
            / n as f64;
        (error, motion, slam)
    }

    #[test]
    fn free_pose_and_posenet_track_the_walk_through_the_room() {
        let (error, motion, mut slam) = run(&mut FreePose::new(1e-3, 1.0), 16);
        // At 128 px across, a quarter of the motion is left unexplained (4.4 cm of 12.4).
        assert!(
            error < motion / 2.0,
            "free pose: {error} m vs motion {motion} m"
        );
        // Every frame after the first was tracked and timed; the times survive a checkpoint.
        assert_eq!(slam.estimates.len(), 16);
        assert!(slam.timing.tracking_s > 0.0 && slam.timing.mapping_s > 0.0);
        assert!(slam.tracking_fps().is_finite() && slam.mapping_fps().is_finite());
        let mut w = Writer::new();
        slam.save(&mut w);
        let timing = slam.timing;
        slam.timing = StageTimes::default();
        let mut r = Reader::from_bytes(Path::new("test"), w.into_bytes()).unwrap();
        let (config, camera, poses) = walk(16);
        slam.load(&mut r, |i| Ok(room_frame(&config, &camera, &poses[i], i)))
            .unwrap();
        assert_eq!(slam.timing, timing);
        // The map holds real surfaces: its mesh lies on the room's, seen from the first camera.
        let grid = Grid::covering([-3.0, -2.5, 0.0], [3.0, 2.5, 2.8], 0.05).unwrap();
        let mesh = slam.mesh(&grid, 30.0, 0.05);
        assert!(
            mesh.triangles.len() > 1000,
            "{} triangles",
            mesh.triangles.len()
        );
        let scene = room_scene();
        let eye = slam.estimates[0].translation.vector;
        let mut offsets: Vec<f64> = mesh
            .vertices
            .iter()
            .filter_map(|v| {
                let to = nalgebra::Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64) - eye;
                let hit = scene.trace(&eye, &to.normalize())?;
                Some((hit.t - to.norm()).abs())
            })
            .collect();
        offsets.sort_by(f64::total_cmp);
        let median = offsets[offsets.len() / 2];
        assert!(median < 0.02, "median mesh offset {median} m");
        let range = TimeRange::new(0.0, 15.0 / 30.0).unwrap();
        let mut posenet = PoseNetTracker::new(
            &PoseNetTrackConfig::default(),
            Reference::Previous,
            range,
            0,
        )
        .unwrap();
        let (error, motion, _) = run(&mut posenet, 16);
        assert!(
            error < motion / 2.0,
            "posenet: {error} m vs motion {motion} m"
        );
    }
}
