//! Task `slam`: RGB-D neural SLAM on a Replica, ScanNet or TUM-RGBD sequence, or on the
//! synthetic room (generated on first use), once per tracking method: NICE-SLAM's free pose
//! (`baseline`) and PoseNet relative to the previous camera (`prev`), the first camera (`world`)
//! or a randomly perturbed previous camera (`random`). Writes the trajectories in TUM format,
//! the ATE (SE(3) alignment, as `cpose eval ate`), a top-down plot and a rendered view.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use cpose_core::TimeRange;
use cpose_core::eval::{Alignment, Trajectory, align_poses, ate, write_tum};
use cpose_core::registry::{Task, TaskInput};
use cpose_nerf::field3d::SceneBounds;
use cpose_nerf::image::Image;
use cpose_nerf::nerf::eval::trajectory_plot;
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::data::{RgbdSequence, read_replica, read_scannet, read_tum_rgbd};
use crate::map::{MapConfig, NeuralMap, PixelSample};
use crate::slam::{MappingConfig, Slam, TrackingConfig};
use crate::synth::{RoomConfig, generate_room};
use crate::track::{FreePose, PoseModel, PoseNetTrackConfig, PoseNetTracker, Reference};

inventory::submit! {
    Task {
        name: "slam",
        about: "RGB-D neural SLAM (paper §4.3): NICE-SLAM's free-pose tracking vs PoseNet relative to the previous camera, the world or a random reference",
        run,
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    data: DataConfig,
    #[serde(default)]
    synthetic: RoomConfig,
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
    slam: SlamConfig,
}

/// Where the frames come from.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DataConfig {
    source: Source,
    /// The sequence folder (for `synthetic`: where the room is generated).
    path: PathBuf,
    /// Resolution factor in (0, 1].
    #[serde(default = "one")]
    resolution: f64,
    /// Pixels cut from every side (NICE-SLAM: ScanNet 10, TUM 8).
    #[serde(default)]
    crop_edge: usize,
    /// Replica's frame rate (its files have no timestamps).
    #[serde(default = "thirty")]
    frame_rate: f64,
    /// Use only the first this many frames (0: all).
    #[serde(default)]
    frames: usize,
}

fn one() -> f64 {
    1.0
}

fn thirty() -> f64 {
    30.0
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Source {
    Synthetic,
    Replica,
    Scannet,
    Tum,
}

/// The map's region: a ball (the grid covers its cube). Default: the synthetic room.
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct BoundsConfig {
    centre: [f64; 3],
    radius: f64,
}

impl Default for BoundsConfig {
    fn default() -> Self {
        Self {
            centre: [0.0, 0.0, 1.4],
            radius: 3.3,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SlamConfig {
    methods: Vec<Method>,
}

/// A tracking method and its key in `metrics.json`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Method {
    Baseline,
    Prev,
    World,
    Random,
}

impl Method {
    fn key(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Prev => "prev",
            Method::World => "world",
            Method::Random => "random",
        }
    }
}

#[derive(Debug, Serialize)]
struct MethodResult {
    ate_rmse_cm: f64,
    ate_mean_cm: f64,
    ate_max_cm: f64,
    frames: usize,
    lost_frames: usize,
    first_lost: Option<usize>,
    fps: f64,
    wall_s: f64,
}

fn open_sequence(exp: &Experiment, input: &TaskInput) -> anyhow::Result<RgbdSequence> {
    let d = &exp.data;
    let seq = match d.source {
        Source::Synthetic => {
            ensure_synthetic(&exp.synthetic, &d.path, input)?;
            read_replica(&d.path, None, d.resolution, exp.synthetic.frame_rate)?
        }
        Source::Replica => {
            if !d.path.join("results").is_dir() {
                bail!(
                    "no Replica scene at {}: NICE-SLAM's Replica (results/frame*.jpg, depth*.png, \
                     traj.txt) comes from its download script (bash scripts/download_replica.sh in \
                     the NICE-SLAM repository); set data.path to it. A synthetic stand-in in the \
                     same layout: cpose run configs/synth_room.toml --set output.path={}",
                    d.path.display(),
                    d.path.display()
                );
            }
            read_replica(&d.path, None, d.resolution, d.frame_rate)?
        }
        Source::Scannet => read_scannet(&d.path, d.resolution, d.crop_edge)?,
        Source::Tum => read_tum_rgbd(&d.path, None, d.resolution, d.crop_edge)?,
    };
    Ok(seq)
}

/// Generates the synthetic room into `path` unless it already holds this exact configuration
/// (recorded in `synthetic.json` once every frame is written).
fn ensure_synthetic(config: &RoomConfig, path: &Path, input: &TaskInput) -> anyhow::Result<()> {
    let stamp = path.join("synthetic.json");
    let wanted = serde_json::to_string_pretty(config)?;
    if std::fs::read_to_string(&stamp).is_ok_and(|s| s == wanted) {
        input
            .run_dir
            .log(format_args!("synthetic room: reusing {}", path.display()));
        return Ok(());
    }
    let started = Instant::now();
    let progress = input.progress(config.frames as u64, "rendering room");
    let n = generate_room(config, path, |i, n| {
        progress.set_length(n as u64);
        progress.set_position(i as u64);
    })?;
    progress.finish();
    cpose_core::fs::write_atomic(&stamp, wanted.as_bytes())
        .with_context(|| format!("writing {}", stamp.display()))?;
    input.run_dir.log(format_args!(
        "synthetic room: generated {n} frames in {} ({:.1} s)",
        path.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(())
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let mut exp: Experiment = input.config.parse_params()?;
    // `run.iterations_scale` scales the optimiser steps (at least one each).
    for steps in [
        &mut exp.tracking.iterations,
        &mut exp.mapping.iterations,
        &mut exp.mapping.first_iterations,
    ] {
        *steps = input.run.iterations(*steps).max(1);
    }
    if exp.slam.methods.is_empty() {
        bail!("slam.methods is empty: name at least one of baseline, prev, world, random");
    }
    let seq = open_sequence(&exp, input)?;
    let n = if exp.data.frames == 0 {
        seq.len()
    } else {
        exp.data.frames.min(seq.len())
    };
    if n < 2 {
        bail!(
            "{}: need at least two frames, found {n}",
            seq.root.display()
        );
    }
    let times: Vec<f64> = seq.times()[..n].to_vec();
    // Ground truth: frames with a finite pose (NICE-SLAM drops the others from the ATE).
    let truth = &seq.truth[..n];
    let valid: Vec<usize> = (0..n).filter(|&i| truth[i].is_some()).collect();
    let dropped = n - valid.len();
    let gt = Trajectory::new(
        valid.iter().map(|&i| times[i]).collect(),
        valid.iter().map(|&i| truth[i].expect("valid")).collect(),
    )?;
    write_tum(input.run_dir.file("traj_gt.txt"), &gt)?;
    input.run_dir.log(format_args!(
        "{}: {n} frames of {}×{}{}; methods {:?}",
        seq.root.display(),
        seq.camera.width,
        seq.camera.height,
        if dropped > 0 {
            format!(" ({dropped} without a ground-truth pose, left out of the ATE)")
        } else {
            String::new()
        },
        exp.slam.methods.iter().map(|m| m.key()).collect::<Vec<_>>()
    ));
    let start = truth[0].unwrap_or_else(Isometry3::identity);
    let bounds = SceneBounds {
        centre: exp.bounds.centre,
        radius: exp.bounds.radius,
        unbounded: false,
    };
    bounds.validate()?;
    let range = TimeRange::new(times[0], times[n - 1])
        .context("frame times must increase from the first to the last frame")?;
    let mut results = BTreeMap::new();
    for &method in &exp.slam.methods {
        let started = Instant::now();
        let map = NeuralMap::new(&exp.map, bounds).map_err(|m| anyhow::anyhow!("map: {m}"))?;
        let mut slam = Slam::new(map, seq.camera, &exp.tracking, &exp.mapping, input.run.seed)?;
        let mut model: Box<dyn PoseModel> = match method {
            Method::Baseline => Box::new(FreePose::new(
                exp.tracking.lr,
                exp.tracking.rotation_lr_factor,
            )),
            Method::Prev | Method::World | Method::Random => {
                let reference = match method {
                    Method::Prev => Reference::Previous,
                    Method::World => Reference::World,
                    _ => Reference::Random,
                };
                Box::new(PoseNetTracker::new(
                    &exp.posenet,
                    reference,
                    range,
                    input.run.seed,
                )?)
            }
        };
        let progress = input.progress(n as u64, method.key());
        let mut lost = Vec::new();
        for i in 0..n {
            let frame = seq.load(i)?;
            let report = slam.process(frame, start, model.as_mut())?;
            if let Some(r) = report
                && r.lost
            {
                if lost.is_empty() {
                    input.run_dir.log(format_args!(
                        "{}: track lost at frame {i} (moved {:.3} m while tracking, loss {:.3})",
                        method.key(),
                        r.moved,
                        r.loss
                    ));
                }
                lost.push(i);
            }
            progress.inc(1);
            if (i + 1) % 100 == 0 || i + 1 == n {
                let err = truth[i].map_or(f64::NAN, |t| {
                    (t.translation.vector - slam.estimates[i].translation.vector).norm()
                });
                input.run_dir.log(format_args!(
                    "{} {}/{n}: position error {:.2} cm, {:.2} frames/s",
                    method.key(),
                    i + 1,
                    100.0 * err,
                    (i + 1) as f64 / started.elapsed().as_secs_f64()
                ));
            }
        }
        progress.finish();
        let wall_s = started.elapsed().as_secs_f64();
        let est = Trajectory::new(
            valid.iter().map(|&i| times[i]).collect(),
            valid.iter().map(|&i| slam.estimates[i]).collect(),
        )?;
        let all = Trajectory::new(times.clone(), slam.estimates.clone())?;
        write_tum(
            input.run_dir.file(format!("traj_{}.txt", method.key())),
            &all,
        )?;
        let report = ate(&gt, &est, Alignment::Se3, 1e-6)?;
        let (_, aligned) = align_poses(gt.poses(), est.poses(), Alignment::Se3)?;
        trajectory_plot(512, gt.poses(), &[], &aligned).save_png(
            input
                .run_dir
                .file(format!("trajectory_{}.png", method.key())),
        )?;
        save_view(&mut slam, &seq, n - 1, input, method.key())?;
        let result = MethodResult {
            ate_rmse_cm: 100.0 * report.rmse_m,
            ate_mean_cm: 100.0 * report.mean_m,
            ate_max_cm: 100.0 * report.max_m,
            frames: n,
            lost_frames: lost.len(),
            first_lost: lost.first().copied(),
            fps: n as f64 / wall_s,
            wall_s,
        };
        input.run_dir.log(format_args!(
            "{}: ATE RMSE {:.2} cm (mean {:.2}, max {:.2}), {:.2} frames/s, {:.0} s",
            method.key(),
            result.ate_rmse_cm,
            result.ate_mean_cm,
            result.ate_max_cm,
            result.fps,
            wall_s
        ));
        results.insert(method.key().to_string(), result);
        input.run_dir.write_json("metrics.json", &results)?;
    }
    Ok(())
}

/// Renders frame `index` from the map at its estimated pose (samples placed by the measured
/// depth) beside the input, as `view_<method>.png` (left: input, right: render).
fn save_view(
    slam: &mut Slam,
    seq: &RgbdSequence,
    index: usize,
    input: &TaskInput,
    key: &str,
) -> anyhow::Result<()> {
    let frame = seq.load(index)?;
    let camera = seq.camera;
    let pose = slam.estimates[index];
    let mut pixels = Vec::new();
    let mut where_ = Vec::new();
    for y in 0..camera.height {
        for x in 0..camera.width {
            let depth = frame.depth.at(x, y);
            if depth > 0.0 {
                pixels.push(PixelSample {
                    ray: cpose_nerf::nerf::render::CameraRay::new(
                        0,
                        &pose,
                        camera.ray_direction_cam(x, y),
                    ),
                    color: [0.0; 3],
                    depth,
                });
                where_.push(y * camera.width + x);
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut rendered = vec![[0.0f32; 3]; camera.width * camera.height];
    for (chunk, idx) in pixels.chunks(4096).zip(where_.chunks(4096)) {
        let out = slam.map.render(chunk, &mut rng);
        for (o, &i) in out.iter().zip(idx) {
            rendered[i] = o.rgb;
        }
    }
    let w = camera.width;
    let side = Image::from_fn(2 * w, camera.height, |x, y| {
        if x < w {
            frame.color.pixel(x, y)
        } else {
            rendered[y * w + x - w]
        }
    });
    side.save_png(input.run_dir.file(format!("view_{key}.png")))?;
    Ok(())
}
