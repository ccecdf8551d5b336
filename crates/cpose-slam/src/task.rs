//! Task `slam`: RGB-D neural SLAM on a Replica, ScanNet or TUM-RGBD sequence, or on the
//! synthetic room (generated on first use), once per tracking method: NICE-SLAM's free pose
//! (`baseline`), PoseNet relative to the previous camera (`prev`), the first camera (`world`)
//! or a randomly perturbed previous camera (`random`), and the intrinsic motion frame
//! (`intrinsic`, two PoseNets with the DOF loss). Writes the trajectories in TUM format and as
//! pose fields for `cpose query` (`field_<condition>_<method>.safetensors`, a `discrete` field
//! of the estimate: the trackers' PoseNets hold only the motion near their reference), the ATE
//! (SE(3) alignment, as `cpose eval ate`), a top-down plot and a rendered view.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use cpose_core::eval::{
    Alignment, AteReport, RpeDelta, Trajectory, align_poses, ate, rpe_report, write_tum,
};
use cpose_core::geometry::rotation_angle_between;
use cpose_core::plot;
use cpose_core::pose_field::saved::SavedPoseField;
use cpose_core::registry::{Task, TaskInput};
use cpose_core::study::{Metrics, Study, Unit, UnitKey};
use cpose_core::{Config, PoseNetConfig, RunConfig, TimeRange};
use cpose_nerf::field3d::SceneBounds;
use cpose_nerf::image::Image;
use cpose_nerf::mesh::Grid;
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::data::{
    RgbdError, RgbdSequence, read_replica, read_scannet, read_seven_scenes, read_tum_rgbd,
};
use crate::map::{DENSITY_SCALE, MapConfig, NeuralMap, PixelSample};
use crate::slam::{MappingConfig, Slam, TrackReport, TrackingConfig};
use crate::surface::{COMPLETION_RADIUS, score_mesh};
use crate::synth::{RoomConfig, generate_room};
use crate::track::{
    FreePose, IntrinsicConfig, IntrinsicTracker, PoseModel, PoseNetTrackConfig, PoseNetTracker,
    Reference,
};

inventory::submit! {
    Task {
        name: "slam",
        about: "RGB-D neural SLAM (paper §4.3): NICE-SLAM's free-pose tracking vs PoseNet (previous camera, world, random reference) and the intrinsic motion frame",
        default_config: || [include_str!("../defaults/slam.toml"), &default_tables()].join("\n"),
        check: |config, run| Settings::new(config, run).map(drop),
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
    #[serde(default)]
    intrinsic: IntrinsicConfig,
    #[serde(default)]
    mesh: MeshConfig,
    slam: SlamConfig<Method>,
}

/// The map's surface, written as `mesh_<method>.ply` after each method; `[mesh]` in a config.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeshConfig {
    /// Grid spacing of the marching tetrahedra, metres (0: no mesh).
    pub voxel: f64,
    /// The density of the surface, 1/m (the map's density scale: on the synthetic room the
    /// iso-surface lies within millimetres of the true one; lower levels sit in front of it).
    pub level: f32,
    /// Triangles more than this far behind every keyframe's measured depth are culled, metres.
    pub margin: f64,
}

impl Default for MeshConfig {
    fn default() -> Self {
        Self {
            voxel: 0.04,
            level: DENSITY_SCALE as f32,
            margin: 0.05,
        }
    }
}

/// Where the frames come from; `[data]` in a config.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// The dataset's layout.
    pub source: Source,
    /// The sequence folder (for `synthetic`: where the room is generated).
    pub path: PathBuf,
    /// Resolution factor in (0, 1].
    #[serde(default = "one")]
    pub resolution: f64,
    /// Pixels cut from every side, for every source (NICE-SLAM: ScanNet 10, TUM 8).
    #[serde(default)]
    pub crop_edge: usize,
    /// The frame rate of datasets whose files have no timestamps (Replica, 7-Scenes), Hz.
    #[serde(default = "thirty")]
    pub frame_rate: f64,
    /// Keep every this many frames (a faster camera: 30 Hz with `stride = 6` is 5 Hz); 0 or 1
    /// keeps all.
    #[serde(default = "one_frame")]
    pub stride: usize,
    /// Use only the first this many frames (after `stride`; 0: all).
    #[serde(default)]
    pub frames: usize,
}

impl DataConfig {
    /// The number of frames to run on out of `available`.
    pub fn frames_of(&self, available: usize) -> usize {
        if self.frames == 0 {
            available
        } else {
            self.frames.min(available)
        }
    }
}

fn one_frame() -> usize {
    1
}

fn one() -> f64 {
    1.0
}

fn thirty() -> f64 {
    30.0
}

/// A dataset layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// The synthetic room in the Replica layout, generated into `path` on first use.
    Synthetic,
    /// NICE-SLAM's Replica.
    Replica,
    /// ScanNet.
    Scannet,
    /// TUM RGB-D.
    Tum,
    /// Microsoft 7-Scenes (a `seq-NN` folder or any flat folder of its frames).
    #[serde(rename = "7scenes")]
    SevenScenes,
}

/// The map's region: either an axis-aligned box (`box = [[x0, x1], [y0, y1], [z0, z1]]`, as
/// NICE-SLAM's `mapping.bound`) or a ball (`centre`, `radius`); the grid covers the cube around
/// it. Default: the synthetic room. `[bounds]` in a config.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BoundsConfig {
    centre: Option<[f64; 3]>,
    radius: Option<f64>,
    #[serde(rename = "box")]
    aabb: Option<[[f64; 2]; 3]>,
}

impl BoundsConfig {
    /// The box to mesh: the configured box, or the cube around the ball.
    pub fn mesh_box(&self) -> anyhow::Result<([f64; 3], [f64; 3])> {
        if let Some(b) = self.aabb {
            return Ok((b.map(|a| a[0]), b.map(|a| a[1])));
        }
        let s = self.scene_bounds()?;
        Ok((
            s.centre.map(|c| c - s.radius),
            s.centre.map(|c| c + s.radius),
        ))
    }

    /// The map's region, checked.
    pub fn scene_bounds(&self) -> anyhow::Result<SceneBounds> {
        let (centre, radius) = match (self.aabb, self.centre, self.radius) {
            (Some(b), None, None) => {
                if b.iter()
                    .any(|[lo, hi]| lo.partial_cmp(hi) != Some(std::cmp::Ordering::Less))
                {
                    bail!("bounds.box = {b:?}: every axis needs [min, max] with min < max");
                }
                let centre = b.map(|[lo, hi]| 0.5 * (lo + hi));
                let radius = b.iter().map(|[lo, hi]| 0.5 * (hi - lo)).fold(0.0, f64::max);
                (centre, radius)
            }
            (None, Some(c), Some(r)) => (c, r),
            (None, None, None) => ([0.0, 0.0, 1.4], 3.3),
            _ => bail!(
                "[bounds]: give either box = [[x0, x1], [y0, y1], [z0, z1]] or centre and radius"
            ),
        };
        let bounds = SceneBounds {
            centre,
            radius,
            unbounded: false,
        };
        bounds.validate()?;
        Ok(bounds)
    }
}

/// `[slam]`: the tracking methods to run, one after the other (checkpoints: `[run]
/// checkpoint_secs`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlamConfig<M> {
    /// The methods, by name.
    pub methods: Vec<M>,
}

/// A tracking method and its key in `metrics.json`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Method {
    Baseline,
    Prev,
    World,
    Random,
    Intrinsic,
}

impl Method {
    fn key(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Prev => "prev",
            Method::World => "world",
            Method::Random => "random",
            Method::Intrinsic => "intrinsic",
        }
    }
}

#[derive(Debug, Serialize)]
struct MethodResult {
    /// ATE statistics (none without ground truth).
    ate_rmse_cm: Option<f64>,
    ate_mean_cm: Option<f64>,
    ate_max_cm: Option<f64>,
    /// `"se3"`, or `"none"` where SE(3) alignment was degenerate.
    ate_alignment: Option<&'static str>,
    /// RMSE of the position error without alignment: the drift from the true first pose, which
    /// every method starts from.
    drift_rmse_cm: Option<f64>,
    /// Relative pose error between consecutive tracked frames (`cpose eval rpe`, delta 1 frame).
    rpe_trans_rmse_cm: Option<f64>,
    rpe_rot_rmse_deg: Option<f64>,
    /// The same for each frame's start against the previous estimate: how far the pose model's
    /// prediction of the motion since the previous frame was off, before tracking.
    start_rpe_trans_rmse_cm: Option<f64>,
    start_rpe_rot_rmse_deg: Option<f64>,
    frames: usize,
    lost_frames: usize,
    /// Lost frames whose estimate fell back to their measured start ([`TrackReport::recovered`]).
    recovered_frames: usize,
    first_lost: Option<usize>,
    /// Frames over the run's wall time (tracking, mapping, reading frames, checkpoints).
    fps: f64,
    /// Tracked frames per second of tracking time, and frames per second of mapping time.
    tracking_fps: f64,
    mapping_fps: f64,
    /// The mesh against the true surface seen in the depth images ([`crate::surface`]).
    mesh_accuracy_cm: Option<f64>,
    mesh_completion: Option<f64>,
    /// Model-specific extras (the intrinsic frame's mean effective DOF).
    #[serde(flatten)]
    extra: BTreeMap<String, f64>,
}

/// The RGB-D sequence `[data]` names (the synthetic room is generated on first use), all its
/// frames, cropped by `data.crop_edge` (`data.stride` is applied by the caller:
/// [`RgbdSequence::every`]).
pub fn open_sequence(
    d: &DataConfig,
    synthetic: &RoomConfig,
    input: &TaskInput,
) -> anyhow::Result<RgbdSequence> {
    let seq = match d.source {
        Source::Synthetic => {
            ensure_synthetic(synthetic, &d.path, input)?;
            read_replica(&d.path, None, d.resolution, synthetic.frame_rate)?
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
        Source::Scannet => {
            if !d.path.is_dir() {
                bail!(
                    "no ScanNet scene at {}: ScanNet (a scene exported by its SensReader into \
                     color/, depth/, pose/ and intrinsic/) is downloaded from the ScanNet project \
                     after accepting its terms of use. Set data.path to the scene folder",
                    d.path.display()
                );
            }
            read_scannet(&d.path, d.resolution)?
        }
        Source::Tum => {
            if !d.path.is_dir() {
                bail!(
                    "no TUM RGB-D sequence at {}: the TUM RGB-D benchmark's sequences (rgb.txt, \
                     depth.txt, groundtruth.txt, rgb/, depth/) are downloaded from TU Munich's \
                     RGB-D SLAM dataset page. Set data.path to the sequence folder",
                    d.path.display()
                );
            }
            read_tum_rgbd(&d.path, None, d.resolution)?
        }
        Source::SevenScenes => {
            if !d.path.is_dir() {
                bail!(
                    "no 7-Scenes sequence at {}: Microsoft's 7-Scenes (a scene's seq-NN folder of \
                     frame-NNNNNN.color.png, .depth.png and .pose.txt) is downloaded from \
                     Microsoft Research; an excerpt of redkitchen ships in ../shared/data/7scenes. \
                     Set data.path to the sequence folder",
                    d.path.display()
                );
            }
            read_seven_scenes(&d.path, d.resolution, d.frame_rate)?
        }
    };
    Ok(seq.cropped(d.crop_edge)?)
}

/// Bumped whenever the room, the walk or the noise model changes, so stale data is rebuilt.
const GENERATOR_VERSION: &str = "synthetic room v1";

/// Generates the synthetic room into `path` unless it already holds this exact configuration.
pub(crate) fn ensure_synthetic(
    config: &RoomConfig,
    path: &Path,
    input: &TaskInput,
) -> anyhow::Result<()> {
    let recipe = serde_json::json!({
        "generator": GENERATOR_VERSION,
        "synthetic": config,
    });
    ensure_generated(path, &recipe, config.frames, input, |staging, on_frame| {
        generate_room(config, staging, on_frame)
    })
}

/// Runs `generate` (which writes a dataset into the folder it is given, reporting `(frame,
/// frames)` as it goes, and returns the number of frames) unless `path` already holds what
/// `recipe` describes, recorded in `path/synthetic.json`. A non-empty folder without that file is
/// refused: it may hold a real dataset, which generating would overwrite.
///
/// The dataset is written into a private folder beside `path`, `.NAME.generating-PID`, and moved
/// into place once complete, replacing an earlier generation there: a run killed half-way leaves
/// no partial dataset at `path` (the next generation removes its folder once its process is gone;
/// Linux), no frame of a longer earlier generation is left behind, and two runs generating at once
/// do not write into each other's files (the second to finish keeps the first one's).
pub fn ensure_generated(
    path: &Path,
    recipe: &serde_json::Value,
    frames: usize,
    input: &TaskInput,
    generate: impl FnOnce(&Path, &mut dyn FnMut(usize, usize)) -> Result<usize, RgbdError>,
) -> anyhow::Result<()> {
    let stamp = path.join("synthetic.json");
    let wanted = serde_json::to_string_pretty(recipe)?;
    let current = || std::fs::read_to_string(&stamp).is_ok_and(|s| s == wanted);
    let reuse = || {
        input
            .run_dir
            .log(format_args!("synthetic data: reusing {}", path.display()));
        Ok(())
    };
    if current() {
        return reuse();
    }
    if path.exists() && !path.is_dir() {
        bail!(
            "{}: expected a folder for the synthetic data, found a file",
            path.display()
        );
    }
    let foreign = !stamp.exists()
        && std::fs::read_dir(path).is_ok_and(|mut entries| entries.next().is_some());
    if foreign {
        bail!(
            "{} is not empty and was not written by the synthetic generator (no synthetic.json); \
             it may hold a real dataset, so nothing is generated there: set data.path to an \
             empty or new folder, or set data.source to the dataset's format",
            path.display()
        );
    }
    let name = path
        .file_name()
        .map_or_else(|| "synthetic".into(), |n| n.to_string_lossy().into_owned());
    let prefix = format!(".{name}.generating-");
    remove_abandoned(path, &prefix);
    let staging = path.with_file_name(format!("{prefix}{}", std::process::id()));
    let started = Instant::now();
    let generated = (|| {
        if staging.exists() {
            std::fs::remove_dir_all(&staging)?;
        }
        std::fs::create_dir_all(&staging)
            .with_context(|| format!("creating {}", staging.display()))?;
        let progress = input.progress(frames as u64, "rendering");
        let n = generate(&staging, &mut |i, n| {
            progress.set_length(n as u64);
            progress.set_position(i as u64);
        })?;
        progress.finish();
        let staged_stamp = staging.join("synthetic.json");
        cpose_core::fs::write_atomic(&staged_stamp, wanted.as_bytes())
            .with_context(|| format!("writing {}", staged_stamp.display()))?;
        anyhow::Ok(n)
    })();
    let placed = generated.and_then(|n| {
        // Another run may have put the same data in place meanwhile.
        if current() {
            return Ok(None);
        }
        if path.exists() {
            // The generator's own folder (checked above): an earlier generation.
            std::fs::remove_dir_all(path)
                .with_context(|| format!("replacing {}", path.display()))?;
        }
        match std::fs::rename(&staging, path) {
            Ok(()) => Ok(Some(n)),
            Err(_) if current() => Ok(None),
            Err(e) => Err(e).with_context(|| format!("moving the data to {}", path.display())),
        }
    });
    // Left only where it was not moved into place.
    let _ = std::fs::remove_dir_all(&staging);
    let Some(n) = placed? else {
        return reuse();
    };
    input.run_dir.log(format_args!(
        "synthetic data: generated {n} frames in {} ({:.1} s)",
        path.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(())
}

/// Removes the staging folders `PREFIX<pid>` beside `path` whose process has ended (generations
/// killed half-way). Only where running processes are listed in `/proc`.
fn remove_abandoned(path: &Path, prefix: &str) {
    let proc = Path::new("/proc/self");
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    let (true, Ok(entries)) = (
        proc.exists(),
        std::fs::read_dir(parent.unwrap_or(Path::new("."))),
    ) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let pid = name
            .strip_prefix(prefix)
            .and_then(|p| p.parse::<u32>().ok());
        if pid.is_some_and(|pid| !Path::new("/proc").join(pid.to_string()).exists()) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// The whole config, decoded and checked before any frame is read or generated.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    setup: SlamSetup,
}

impl Settings {
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        let methods = &exp.slam.methods;
        if methods.is_empty() {
            bail!(
                "slam.methods is empty: name at least one of baseline, prev, world, random, \
                 intrinsic"
            );
        }
        if exp.data.source == Source::Synthetic {
            exp.synthetic.check(config)?;
        }
        let setup = SlamSetup::new(
            run,
            exp.map.clone(),
            exp.tracking.clone(),
            exp.mapping.clone(),
            &exp.bounds,
            &exp.mesh,
        )?;
        if methods.iter().any(|&m| m != Method::Baseline) {
            // The networks' sizes, checked by building one over a unit time range.
            let unit = TimeRange::new(0.0, 1.0).context("a unit time range")?;
            PoseNetTracker::new(&exp.posenet, Reference::Previous, unit, run.seed)?;
        }
        Ok(Self { exp, setup })
    }
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let Settings { exp, setup } = Settings::new(input.config, input.run)?;
    let seq = open_sequence(&exp.data, &exp.synthetic, input)?.every(exp.data.stride);
    let n = exp.data.frames_of(seq.len());
    let range = frame_range(&seq, n)?;
    let (posenet, intrinsic, seed) = (&exp.posenet, &exp.intrinsic, input.run.seed);
    let camera = seq.camera;
    let methods: Vec<(String, ModelFactory)> = exp
        .slam
        .methods
        .iter()
        .map(|&method| {
            let factory: ModelFactory = match method {
                Method::Baseline => {
                    let (lr, factor) = (setup.tracking.lr, setup.tracking.rotation_lr_factor);
                    Box::new(move || Ok(Box::new(FreePose::new(lr, factor)) as Box<dyn PoseModel>))
                }
                Method::Prev | Method::World | Method::Random => {
                    let reference = match method {
                        Method::Prev => Reference::Previous,
                        Method::World => Reference::World,
                        _ => Reference::Random,
                    };
                    Box::new(move || {
                        Ok(Box::new(PoseNetTracker::new(posenet, reference, range, seed)?) as _)
                    })
                }
                Method::Intrinsic => {
                    let view_angle = 2.0 * (0.5 * camera.width as f64 / camera.fx).atan();
                    Box::new(move || {
                        Ok(Box::new(IntrinsicTracker::new(
                            posenet, intrinsic, range, view_angle, seed,
                        )?) as _)
                    })
                }
            };
            (method.key().to_string(), factory)
        })
        .collect();
    run_methods(input, &seq, n, &setup, &methods)?;
    Ok(())
}

/// The tables every SLAM task shares at their defaults, commented: `[bounds]`, `[map]`,
/// `[tracking]`, `[mapping]`, `[posenet]` (its network as `[posenet.network]`), `[mesh]` and
/// the synthetic room's `[synthetic]`.
pub fn default_tables() -> String {
    let network = PoseNetConfig::DEFAULT_TABLE.replacen("[posenet]", "[posenet.network]", 1);
    [
        include_str!("../defaults/slam_tables.toml"),
        &network,
        RoomConfig::DEFAULT_TABLE,
    ]
    .join("\n")
}

/// The time span of the first `n ≥ 2` frames of `seq` (a pose field's domain).
pub fn frame_range(seq: &RgbdSequence, n: usize) -> anyhow::Result<TimeRange> {
    if n < 2 || seq.len() < n {
        bail!(
            "{}: need at least two frames, found {}",
            seq.root.display(),
            n.min(seq.len())
        );
    }
    let times = seq.times();
    TimeRange::new(times[0], times[n - 1])
        .context("frame times must increase from the first to the last frame")
}

/// What every SLAM task shares besides its frames and pose models: the map, tracking and
/// mapping settings (optimiser steps already scaled by `run.iterations_scale`), the map's region,
/// and the mesh grid.
#[derive(Debug)]
pub struct SlamSetup {
    /// `[map]`.
    pub map: MapConfig,
    /// `[tracking]`.
    pub tracking: TrackingConfig,
    /// `[mapping]`.
    pub mapping: MappingConfig,
    /// The map's region.
    pub bounds: SceneBounds,
    /// The grid, level and culling margin of the mesh; none: no mesh.
    pub mesh: Option<(Grid, f32, f64)>,
    /// The camera's mount on the tracked body (identity: the body is the camera).
    pub body_from_camera: Isometry3<f64>,
}

impl SlamSetup {
    /// Checks and assembles the settings; `run.iterations_scale` scales the optimiser steps
    /// (at least one each).
    pub fn new(
        run: &RunConfig,
        map: MapConfig,
        mut tracking: TrackingConfig,
        mut mapping: MappingConfig,
        bounds: &BoundsConfig,
        mesh: &MeshConfig,
    ) -> anyhow::Result<Self> {
        tracking
            .validate()
            .map_err(|e| anyhow::anyhow!("[tracking] {e}"))?;
        map.validate().map_err(|e| anyhow::anyhow!("[map] {e}"))?;
        for steps in [
            &mut tracking.iterations,
            &mut mapping.iterations,
            &mut mapping.first_iterations,
        ] {
            *steps = run.iterations(*steps).max(1);
        }
        let scene_bounds = bounds.scene_bounds()?;
        // 0 turns the mesh off; a negative or non-finite size is an error (`Grid::covering`).
        let mesh = if mesh.voxel != 0.0 {
            let (min, max) = bounds.mesh_box()?;
            let grid = Grid::covering(min, max, mesh.voxel).context("[mesh]")?;
            Some((grid, mesh.level, mesh.margin))
        } else {
            None
        };
        Ok(Self {
            map,
            tracking,
            mapping,
            bounds: scene_bounds,
            mesh,
            body_from_camera: Isometry3::identity(),
        })
    }
}

/// Builds a fresh pose model for one method's run.
pub type ModelFactory<'a> = Box<dyn Fn() -> anyhow::Result<Box<dyn PoseModel>> + Sync + 'a>;

/// Runs SLAM on the first `n` frames of `seq` once per `(key, model)` method, each a unit of
/// a study whose condition is the sequence's folder name, and writes per method
/// `traj_<sequence>_<key>.txt`, `trajectory_…png`, `view_…png`, `mesh_…ply`, `tracking_…csv`
/// (per frame) and its entry in `metrics.json` (also `traj_gt.txt`). On `--resume`, finished
/// methods are kept and an interrupted one continues from its checkpoint.
pub fn run_methods(
    input: &TaskInput,
    seq: &RgbdSequence,
    n: usize,
    setup: &SlamSetup,
    methods: &[(String, ModelFactory)],
) -> anyhow::Result<()> {
    frame_range(seq, n)?;
    let times: Vec<f64> = seq.times()[..n].to_vec();
    // Ground truth: frames with a finite pose (NICE-SLAM drops the others from the ATE).
    let truth = &seq.truth[..n];
    let valid: Vec<usize> = (0..n).filter(|&i| truth[i].is_some()).collect();
    let dropped = n - valid.len();
    let gt = if valid.is_empty() {
        None
    } else {
        let gt = Trajectory::new(
            valid.iter().map(|&i| times[i]).collect(),
            valid.iter().map(|&i| truth[i].expect("valid")).collect(),
        )?;
        write_tum(input.run_dir.file("traj_gt.txt"), &gt)?;
        Some(gt)
    };
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
        methods.iter().map(|m| m.0.as_str()).collect::<Vec<_>>()
    ));
    let start = truth[0].unwrap_or_else(Isometry3::identity);
    let sequence = seq.root.file_name().map_or_else(
        || "sequence".to_owned(),
        |s| s.to_string_lossy().into_owned(),
    );
    let units = methods
        .iter()
        .map(|(key, _)| UnitKey::new(sequence.as_str(), key.as_str(), input.run.seed))
        .collect();
    Study::new(input, units)
        .report_every(100)
        .columns(&[
            "ate_rmse_cm",
            "ate_max_cm",
            "lost_frames",
            "fps",
            "mesh_accuracy_cm",
        ])
        .run(|unit| {
            let key = unit.key().method.clone();
            let factory = &methods
                .iter()
                .find(|(k, _)| *k == key)
                .context("a method of the config")?
                .1;
            let map = NeuralMap::new(&setup.map, setup.bounds)
                .map_err(|m| anyhow::anyhow!("map: {m}"))?;
            let mut slam = Slam::new(
                map,
                seq.camera,
                &setup.tracking,
                &setup.mapping,
                input.run.seed,
            )?;
            slam.set_body_from_camera(setup.body_from_camera);
            let mut model = factory()?;
            let mut lost: Vec<usize> = Vec::new();
            let mut first = 0;
            unit.set_steps(n);
            if let Some((done, mut r)) = unit.resume() {
                first = done as usize;
                lost = r.f64s()?.into_iter().map(|i| i as usize).collect();
                slam.load(&mut r, |i| Ok(seq.load(i)?))?;
                model.load(&mut r)?;
            }
            let mut tracking_log = TrackingLog::open(&unit.file("tracking", "csv"), first)?;
            let session = Instant::now();
            for i in first..n {
                let frame = seq.load(i)?;
                let time = frame.time;
                let report = slam.process(frame, start, model.as_mut())?;
                if let Some(r) = &report {
                    let previous = (&slam.estimates[i - 1], truth[i - 1].as_ref());
                    tracking_log.row(i, time, r, (&slam.estimates[i], truth[i].as_ref()), previous)?;
                }
                if let Some(r) = &report
                    && r.lost
                {
                    if lost.is_empty() {
                        unit.log(format_args!(
                            "track lost at frame {i} (moved {:.3} m while tracking, median depth \
                             error {:.3} m, loss {:.3}){}",
                            r.moved,
                            r.depth_error,
                            r.loss,
                            if r.recovered {
                                "; the frame keeps its start, measured by the IMU, and is not \
                                 mapped (later lost frames too; recovered_frames counts them)"
                            } else {
                                ""
                            }
                        ));
                    }
                    lost.push(i);
                }
                let done = i + 1;
                if unit.report_due(done) {
                    let err_cm = truth[i].map_or(f64::NAN, |t| {
                        100.0 * (t.translation.vector - slam.estimates[i].translation.vector).norm()
                    });
                    let fps = (done - first) as f64 / session.elapsed().as_secs_f64();
                    // The first frame is not tracked: no loss to report.
                    let mut live = vec![("pos_err_cm", err_cm), ("fps", fps)];
                    if let Some(r) = &report {
                        live.insert(0, ("loss", r.loss));
                    }
                    unit.report(done, &live);
                }
                if done < n && unit.checkpoint_due() {
                    // The rows first: a kill between the two writes then loses none of the
                    // rows the checkpoint counts as done (a resume drops the later ones).
                    tracking_log.flush()?;
                    unit.checkpoint(done as u64, |w| {
                        w.f64s(&lost.iter().map(|&i| i as f64).collect::<Vec<_>>());
                        slam.save(w);
                        model.save(w);
                        Ok(())
                    })?;
                }
            }
            tracking_log.flush()?;
            let wall_s = unit.wall_secs();
            let all = Trajectory::new(times.clone(), slam.estimates.clone())?;
            write_tum(unit.file("traj", "txt"), &all)?;
            // Tracking holds PoseNet relative to a recent reference only: the run's whole
            // continuous path is its estimate, saved as a discrete field for `cpose query`.
            SavedPoseField::discrete(&times, &slam.estimates)?
                .write(&unit.file("field", "safetensors"))?;
            let plot = unit.file("trajectory", "png");
            let scored = match &gt {
                Some(gt) => {
                    let est = Trajectory::new(
                        valid.iter().map(|&i| times[i]).collect(),
                        valid.iter().map(|&i| slam.estimates[i]).collect(),
                    )?;
                    let (report, alignment) = score(gt, &est, unit)?;
                    let (_, aligned) = align_poses(gt.poses(), est.poses(), alignment)?;
                    let how = match alignment {
                        Alignment::None => "not aligned",
                        Alignment::Se3 => "SE(3)-aligned",
                        Alignment::Sim3 => "Sim(3)-aligned",
                    };
                    let title = format!(
                        "slam, {sequence}: {key} camera path, {how} to the truth; ATE RMSE {:.2} cm",
                        100.0 * report.rmse_m
                    );
                    let drawn = plot::trajectory_comparison(
                        &plot,
                        &title,
                        gt.timestamps_secs(),
                        Some(gt.poses()),
                        None,
                        (&format!("{key} ({how})"), &aligned),
                    );
                    if let Err(e) = drawn {
                        unit.log(format_args!("no trajectory plot: {e}"));
                    }
                    let drift = ate(gt, &est, Alignment::None, 1e-6)?;
                    let rpe = rpe_report(gt, &est, 1e-6, RpeDelta::Frames(1), Alignment::None)?;
                    Some((report, alignment, drift, rpe))
                }
                None => {
                    unit.log("no ground truth, no ATE");
                    let title = format!("slam, {sequence}: {key} camera path (no ground truth)");
                    let drawn = plot::trajectory_comparison(
                        &plot,
                        &title,
                        &times,
                        None,
                        None,
                        (&key, &slam.estimates),
                    );
                    if let Err(e) = drawn {
                        unit.log(format_args!("no trajectory plot: {e}"));
                    }
                    None
                }
            };
            save_view(&mut slam, seq, n - 1, unit)?;
            let mut surface = None;
            if let Some((grid, level, margin)) = &setup.mesh {
                let mesh = slam.mesh(grid, *level, *margin);
                let path = unit.file("mesh", "ply");
                mesh.write_ply(&path)?;
                surface = score_mesh(&mesh, seq, truth, n)?;
                unit.log(format_args!(
                    "mesh of {} triangles ({:.1} m²) in {}{}",
                    mesh.triangles.len(),
                    mesh.area(),
                    path.display(),
                    surface.map_or(String::new(), |s| format!(
                        "; accuracy {:.2} cm, completion {:.1}% (true surface within {} cm)",
                        100.0 * s.accuracy_m,
                        100.0 * s.completion,
                        100.0 * COMPLETION_RADIUS
                    ))
                ));
            }
            let cm = |f: fn(&AteReport) -> f64| scored.as_ref().map(|(r, ..)| 100.0 * f(r));
            let result = MethodResult {
                ate_rmse_cm: cm(|r| r.rmse_m),
                ate_mean_cm: cm(|r| r.mean_m),
                ate_max_cm: cm(|r| r.max_m),
                ate_alignment: scored.as_ref().map(|(_, a, ..)| a.as_str()),
                drift_rmse_cm: scored.as_ref().map(|(_, _, d, _)| 100.0 * d.rmse_m),
                rpe_trans_rmse_cm: scored.as_ref().map(|(.., r)| 100.0 * r.trans_rmse_m),
                rpe_rot_rmse_deg: scored.as_ref().map(|(.., r)| r.rot_rmse_deg),
                start_rpe_trans_rmse_cm: tracking_log.start_rpe().map(|(cm, _)| cm),
                start_rpe_rot_rmse_deg: tracking_log.start_rpe().map(|(_, deg)| deg),
                frames: n,
                lost_frames: lost.len(),
                recovered_frames: tracking_log.recovered,
                first_lost: lost.first().copied(),
                fps: n as f64 / wall_s,
                tracking_fps: slam.tracking_fps(),
                mapping_fps: slam.mapping_fps(),
                mesh_accuracy_cm: surface.map(|s| 100.0 * s.accuracy_m),
                mesh_completion: surface.map(|s| s.completion),
                extra: model
                    .metrics()
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
            };
            Metrics::from_serialize(&result)
        })?;
    Ok(())
}

/// `tracking_<method>.csv`: one row per tracked frame, where the pose model started it and
/// where tracking left it; with a ground truth, how far each was from the true camera, and how far
/// the start's motion from the previous estimate was from the true motion (the prediction's
/// error, whatever the drift before). It tells a prediction that was already off from a tracking
/// that moved a good start away.
struct TrackingLog {
    path: PathBuf,
    file: BufWriter<File>,
    /// Sums of the squared start-step errors (cm², deg²) and their count.
    start_steps: (f64, f64, usize),
    /// Frames recovered from a lost track ([`TrackReport::recovered`]).
    recovered: usize,
}

impl TrackingLog {
    const HEADER: &str = "frame,time_s,start_error_cm,error_cm,start_rotation_error_deg,\
                          rotation_error_deg,moved_cm,depth_error_cm,loss,lost,recovered,\
                          start_step_error_cm,start_step_rotation_error_deg";

    /// Creates `path`; a resumed run (`first > 0`) keeps the rows of the frames before `first`.
    fn open(path: &Path, first: usize) -> anyhow::Result<Self> {
        let kept: Vec<String> = match first {
            0 => Vec::new(),
            _ => std::fs::read_to_string(path)
                .unwrap_or_default()
                .lines()
                .skip(1)
                .filter(|line| {
                    let frame = line.split(',').next().and_then(|f| f.parse::<usize>().ok());
                    frame.is_some_and(|f| f < first)
                })
                .map(str::to_owned)
                .collect(),
        };
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut log = Self {
            path: path.to_owned(),
            file: BufWriter::new(file),
            start_steps: (0.0, 0.0, 0),
            recovered: 0,
        };
        log.write(format_args!("{}", Self::HEADER))?;
        for line in &kept {
            log.write(format_args!("{line}"))?;
            let fields: Vec<&str> = line.split(',').collect();
            if let [.., recovered, cm, deg] = fields[..]
                && fields.len() == Self::HEADER.split(',').count()
                && let (Ok(cm), Ok(deg)) = (cm.parse(), deg.parse())
            {
                log.add_start_step(cm, deg);
                log.recovered += usize::from(recovered == "1");
            }
        }
        Ok(log)
    }

    fn add_start_step(&mut self, cm: f64, deg: f64) {
        if cm.is_finite() && deg.is_finite() {
            self.start_steps.0 += cm * cm;
            self.start_steps.1 += deg * deg;
            self.start_steps.2 += 1;
        }
    }

    /// The RMS of the start-step errors so far, cm and degrees (`None` without a ground truth).
    fn start_rpe(&self) -> Option<(f64, f64)> {
        let (cm, deg, count) = self.start_steps;
        (count > 0).then(|| ((cm / count as f64).sqrt(), (deg / count as f64).sqrt()))
    }

    /// The row of frame `index` at `time`: its report, the chosen estimate and the truth, and the
    /// previous frame's.
    fn row(
        &mut self,
        index: usize,
        time: f64,
        report: &TrackReport,
        (estimate, truth): (&Isometry3<f64>, Option<&Isometry3<f64>>),
        (previous, previous_truth): (&Isometry3<f64>, Option<&Isometry3<f64>>),
    ) -> anyhow::Result<()> {
        let errors = |pose: &Isometry3<f64>, truth: Option<&Isometry3<f64>>| {
            truth.map_or((f64::NAN, f64::NAN), |t| {
                (
                    100.0 * (pose.translation.vector - t.translation.vector).norm(),
                    rotation_angle_between(&pose.rotation, &t.rotation).to_degrees(),
                )
            })
        };
        let (start_cm, start_deg) = errors(&report.start, truth);
        let (cm, deg) = errors(estimate, truth);
        // The start's motion from the previous estimate against the true motion.
        let true_step = previous_truth.zip(truth).map(|(a, b)| a.inverse() * b);
        let (step_cm, step_deg) = errors(&(previous.inverse() * report.start), true_step.as_ref());
        // Summed as written, so that a resumed run, which reads the earlier rows back, sums the
        // same numbers.
        let (step_cm, step_deg) = (format!("{step_cm:.3}"), format!("{step_deg:.4}"));
        if let (Ok(cm), Ok(deg)) = (step_cm.parse(), step_deg.parse()) {
            self.add_start_step(cm, deg);
        }
        self.recovered += usize::from(report.recovered);
        self.write(format_args!(
            "{index},{time:.6},{start_cm:.3},{cm:.3},{start_deg:.4},{deg:.4},{:.3},{:.3},{:.6},{},\
             {},{step_cm},{step_deg}",
            100.0 * report.moved,
            100.0 * report.depth_error,
            report.loss,
            u8::from(report.lost),
            u8::from(report.recovered)
        ))
    }

    fn write(&mut self, line: std::fmt::Arguments) -> anyhow::Result<()> {
        writeln!(self.file, "{line}").with_context(|| format!("writing {}", self.path.display()))
    }

    fn flush(&mut self) -> anyhow::Result<()> {
        self.file
            .flush()
            .with_context(|| format!("writing {}", self.path.display()))
    }
}

/// The ATE of `est` against `gt` with SE(3) alignment, as NICE-SLAM and `cpose eval ate`; a
/// short, nearly straight run makes the alignment ill-posed, and then the error is taken as it
/// is (frame 0 starts at its true pose, so the frames already agree), and the log says so.
fn score(gt: &Trajectory, est: &Trajectory, unit: &Unit) -> anyhow::Result<(AteReport, Alignment)> {
    match ate(gt, est, Alignment::Se3, 1e-6) {
        Ok(report) => Ok((report, Alignment::Se3)),
        Err(e) => {
            unit.log(format_args!(
                "no SE(3) alignment ({e}); ATE without alignment"
            ));
            Ok((ate(gt, est, Alignment::None, 1e-6)?, Alignment::None))
        }
    }
}

/// Renders frame `index` from the map at its estimated pose (samples placed by the measured
/// depth) beside the input, as `view_<method>.png` (left: input, right: render).
fn save_view(slam: &mut Slam, seq: &RgbdSequence, index: usize, unit: &Unit) -> anyhow::Result<()> {
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
                    ray: cpose_nerf::render::CameraRay::new(
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
    side.save_png(unit.file("view", "png"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show slam` states the defaults: its values are those of a config with only
    /// the keys that have none.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"slam\"\n[data]\nsource = \"synthetic\"\n\
                        path = \"data/synthetic_room\"\n[slam]\n\
                        methods = [\"baseline\", \"prev\", \"world\", \"random\", \"intrinsic\"]\n";
        cpose_core::testing::check_default_config("slam", required, Settings::new);
    }
}
