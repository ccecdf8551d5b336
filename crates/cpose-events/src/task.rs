//! Task `events`: NeRF from colour events with a pose at every window end (paper §4.2, its
//! interpolation table and calibration figures).
//!
//! The scene is learnt from events alone with EventNeRF's loss ([`crate::train`]); the methods
//! differ only in the poses at the window ends, `C(τ) ∘ init(τ)`:
//! - `eventnerf`: `init` as it is (EventNeRF, poses fixed);
//! - `posenet`: `C` is PoseNet on time, learnt jointly with the scene (held at the known views
//!   by the anchor when there are some);
//! - `true_poses`: the ground truth (the reference).
//!
//! Experiments (`[experiment] kind`):
//! - `interpolation`: only `K` views of the revolution are known, at `i T / K` (`i = 0…K`, the
//!   last closing the revolution); `init` interpolates them (slerp and a straight line), which
//!   cuts the circle's chords. One condition per `known_poses` entry.
//! - `calibration` (synthetic data): `init` is the turntable about the nominal axis while the
//!   data turned about an axis tilted by each of `axis_offsets_deg`.
//!
//! Data (`[data] source`): `synthetic` simulates the built-in scene on a turntable
//! ([`crate::simulate`], `[simulation]`); `eventnerf` reads a scene folder by path, whose views
//! are the truth (interpolated between them).
//!
//! Pose errors are measured at `eval.pose_samples` times spread over the recording: mean
//! rotation (°) and translation (scene units) error against the truth as they are, and after
//! BARF's Procrustes alignment — a similarity, because events fix neither the scene's frame nor
//! its scale: a scene scaled by `s` seen from a path scaled by `s` fires the same events, and
//! known views pin the scale only through the windows that touch them (`train.anchor_windows`,
//! [`crate::train`]). Held-out views are rendered at the true poses mapped by
//! that alignment, as BARF evaluates, and scored with PSNR and SSIM after EventNeRF's colour
//! correction ([`ColourCorrection`]).
//!
//! The run is a study ([`cpose_core::study`]): one unit per condition (`K<k>`, e.g. `K20`, or
//! `offset<deg>deg`, e.g. `offset1.5deg`) and method, run one after the other. Every 100 steps
//! (`[run] report_every`) a unit reports the mean event loss of its last 100 steps and its
//! current rotation (°) and translation error at the evaluation times; every
//! `[run] checkpoint_secs` it saves its whole training state (field and pose correction with
//! their Adam moments, the random generator, the recent losses), from which
//! `cpose run --resume` continues exactly.
//!
//! Outputs, besides the study's (`metrics.json` as `{condition: {method: {rot_err_deg,
//! trans_err_su, …, psnr_db, ssim, final_loss, wall_s}}}`, `curves.csv`, `units/`):
//! - `traj_gt.txt`: the truth at the evaluation times (TUM);
//! - `traj_<condition>_<method>.txt`: the method's path there (TUM);
//! - `field_<condition>_posenet.safetensors`: PoseNet's whole camera path, `C(t) ∘ init(t)` over
//!   the recording, as one pose field for `cpose query` (the initial path sampled 2000 times);
//! - `trajectory_<condition>_<method>.png`: truth, initial and learnt path seen from above;
//! - `view_<k>_<condition>_<method>.png`: held-out view `k` rendered and colour-corrected,
//!   beside the truth; `depth_<k>_<condition>_<method>.png`: its depth;
//! - `own_view_<condition>_<method>.png`: the first held-out view from the method's own camera
//!   at that time, beside the truth.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use cpose_core::eval::{ReflectionFix, Trajectory, barf_pose_errors, write_tum};
use cpose_core::geometry::rotation_angle_between;
use cpose_core::nn::ExponentialDecay;
use cpose_core::registry::{Task, TaskInput};
use cpose_core::study::{Metrics, Study, Unit, UnitKey};
use cpose_core::{Config, PoseField, PoseNetConfig, RunConfig, TimeRange};
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::field3d::{RadianceField, RadianceFieldConfig, SceneBounds};
use cpose_nerf::image::{Image, psnr};
use cpose_nerf::metrics::ssim;
use cpose_nerf::poses::{FramePoses, PoseSchedules, PoseTiming};
use cpose_nerf::render::{
    Clip, LastInterval, RenderSettings, Renderer, Sampling, depth_image, render_view_with,
};
use cpose_nerf::scene::SyntheticScene;
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::colour::ColourCorrection;
use crate::eventnerf::{EventNerfOptions, EventNerfScene, read_eventnerf};
use crate::loss::EventLoss;
use crate::simulate::{SimulatorConfig, SyntheticEventsConfig, simulate_eventnerf_scene};
use crate::train::{EventSchedule, EventTrainer, InitialPath, KeyedPoses, pixel_directions};
use crate::turntable::Turntable;

inventory::submit! {
    Task {
        name: "events",
        about: "NeRF from colour events (paper §4.2): PoseNet vs interpolated or mis-calibrated poses",
        default_config: || {
            [
                include_str!("../defaults/events.toml"),
                RadianceFieldConfig::DEFAULT_TABLE,
                PoseNetConfig::DEFAULT_TABLE,
            ]
            .join("\n")
        },
        check: |config, run| Settings::new(config, run).map(drop),
        run,
    }
}

/// The config file of the task.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    #[serde(default)]
    data: DataConfig,
    #[serde(default)]
    simulation: SimulationConfig,
    #[serde(default)]
    experiment: ExperimentConfig,
    #[serde(default)]
    train: TrainConfig,
    #[serde(default)]
    render: RenderConfig,
    #[serde(default)]
    eval: EvalConfig,
    /// The radiance field, `kind = "grid"` or `"mlp"`.
    #[serde(rename = "field", default)]
    _field: serde::de::IgnoredAny,
    /// PoseNet's settings ([`PoseNetConfig`]).
    #[serde(rename = "posenet", default)]
    _posenet: serde::de::IgnoredAny,
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum Source {
    #[default]
    Synthetic,
    Eventnerf,
}

/// `[data]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct DataConfig {
    source: Source,
    /// EventNeRF scene folder (with `train/` and optionally `validation/`).
    path: Option<PathBuf>,
    /// The split with the events.
    split: String,
}

impl Default for DataConfig {
    fn default() -> Self {
        Self {
            source: Source::Synthetic,
            path: None,
            split: "train".to_owned(),
        }
    }
}

/// `[simulation]`: the synthetic recording.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct SimulationConfig {
    width: usize,
    height: usize,
    fov_x_deg: f64,
    /// Turntable: camera distance from the axis, height, seconds per revolution.
    radius: f64,
    camera_height: f64,
    duration_secs: f64,
    /// Renders over the revolution (events interpolated in between).
    render_steps: usize,
    supersample: usize,
    held_out_views: usize,
    threshold: f64,
    threshold_sigma: f64,
    refractory_secs: f64,
    eps: f64,
}

impl Default for SimulationConfig {
    fn default() -> Self {
        let s = SyntheticEventsConfig::default();
        Self {
            width: s.camera.width,
            height: s.camera.height,
            fov_x_deg: 50.0,
            radius: s.turntable.radius,
            camera_height: s.turntable.height,
            duration_secs: s.turntable.duration_secs,
            render_steps: s.render_steps,
            supersample: s.supersample,
            held_out_views: s.held_out_views,
            threshold: s.simulator.threshold,
            threshold_sigma: s.simulator.threshold_sigma,
            refractory_secs: s.simulator.refractory_secs,
            eps: s.simulator.eps,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum Kind {
    #[default]
    Interpolation,
    Calibration,
}

/// `[experiment]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ExperimentConfig {
    kind: Kind,
    /// Interpolation: known views per revolution, one condition each.
    known_poses: Vec<usize>,
    /// Calibration: axis tilts, degrees, one condition each.
    axis_offsets_deg: Vec<f64>,
}

impl Default for ExperimentConfig {
    fn default() -> Self {
        Self {
            kind: Kind::Interpolation,
            known_poses: vec![20, 10, 6],
            axis_offsets_deg: vec![0.24, 1.5, 2.85],
        }
    }
}

/// A pose model, named as in `metrics.json`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
enum Method {
    Eventnerf,
    Posenet,
    TruePoses,
}

impl Method {
    fn key(self) -> &'static str {
        match self {
            Self::Eventnerf => "eventnerf",
            Self::Posenet => "posenet",
            Self::TruePoses => "true_poses",
        }
    }
}

/// `[train]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct TrainConfig {
    methods: Vec<Method>,
    iterations: usize,
    rays_per_step: usize,
    windows_per_step: usize,
    /// Window lengths `[min, max]` as fractions of the recording (EventNeRF: up to 50 of 1000
    /// views).
    window: [f64; 2],
    neg_ratio: f64,
    /// The loss' threshold `θ` (default: the simulator's) and `ε`.
    threshold: Option<f64>,
    eps: f64,
    lr_field: BTreeMap<String, [f64; 2]>,
    /// PoseNet: `[start, end]` for the translation and rotation networks.
    posenet_lr_translation: [f64; 2],
    posenet_lr_rotation: [f64; 2],
    /// Fraction of the steps during which the poses are held while the field fits the given
    /// poses ([`PoseSchedules::hold`]).
    pose_hold: f64,
    /// Fraction of the steps after the hold over which the pose learning rates ramp up from 0.
    pose_warmup: f64,
    /// Weight of the anchor at the known views.
    anchor_weight: f64,
    /// Share of the windows with one end at a known view.
    anchor_windows: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            methods: vec![Method::Eventnerf, Method::Posenet],
            iterations: 3000,
            rays_per_step: 1024,
            windows_per_step: 8,
            window: [0.002, 0.05],
            neg_ratio: 0.1,
            threshold: None,
            eps: 0.1,
            lr_field: BTreeMap::from([
                ("grid".to_owned(), [1e-2, 1e-3]),
                ("mlp".to_owned(), [1e-3, 1e-4]),
            ]),
            posenet_lr_translation: [1e-3, 1e-5],
            posenet_lr_rotation: [2e-4, 2e-6],
            pose_hold: 0.0,
            pose_warmup: 0.1,
            anchor_weight: 1.0,
            anchor_windows: 0.0,
        }
    }
}

/// `[render]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RenderConfig {
    samples: usize,
    near: f64,
    far: f64,
    /// Constant colour behind the object (EventNeRF: 159/255 grey; the synthetic scene's is white).
    background: Option<[f32; 3]>,
    /// Radius of the sphere around the origin that holds the object (default: the synthetic
    /// scene's bounding radius).
    scene_radius: Option<f64>,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            samples: 48,
            near: 1.0,
            far: 9.0,
            background: None,
            scene_radius: None,
        }
    }
}

/// `[eval]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct EvalConfig {
    /// Times at which poses are compared with the truth.
    pose_samples: usize,
    /// Held-out views saved as PNG (the first ones).
    saved_views: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            pose_samples: 200,
            saved_views: 2,
        }
    }
}

/// The recording: events, the true path, held-out views, and the camera.
struct Recording {
    scene: EventNerfScene,
    truth: InitialPath,
    /// Seconds of the recording (view 0 to the last view).
    duration: f64,
    /// What loading found worth saying.
    note: String,
}

/// The simulation `[simulation]` describes, checked.
fn synthetic_config(s: &SimulationConfig) -> anyhow::Result<SyntheticEventsConfig> {
    if s.width == 0 || s.height == 0 || !(s.fov_x_deg > 0.0 && s.fov_x_deg < 180.0) {
        bail!("[simulation]: need width, height ≥ 1 and 0 < fov_x_deg < 180");
    }
    let config = SyntheticEventsConfig {
        turntable: Turntable {
            radius: s.radius,
            height: s.camera_height,
            duration_secs: s.duration_secs,
            ..Turntable::default()
        },
        camera: PinholeCamera::from_fov_x(s.width, s.height, s.fov_x_deg.to_radians()),
        render_steps: s.render_steps,
        supersample: s.supersample,
        views: 2,
        held_out_views: s.held_out_views,
        held_out_supersample: 2,
        simulator: SimulatorConfig {
            threshold: s.threshold,
            threshold_sigma: s.threshold_sigma,
            refractory_secs: s.refractory_secs,
            eps: s.eps,
            ..SimulatorConfig::default()
        },
    };
    config.validate().context("[simulation]")?;
    Ok(config)
}

fn synthetic_recording(exp: &Experiment) -> anyhow::Result<Recording> {
    let s = &exp.simulation;
    let config = synthetic_config(s)?;
    let turntable = config.turntable.clone();
    let (scene, _) = simulate_eventnerf_scene(&SyntheticScene::object_centric(), &config)
        .context("[simulation]")?;
    Ok(Recording {
        scene,
        duration: turntable.duration_secs,
        truth: InitialPath::Turntable(turntable),
        note: format!("simulated with θ = {}", s.threshold),
    })
}

fn eventnerf_recording(exp: &Experiment) -> anyhow::Result<Recording> {
    let Some(path) = &exp.data.path else {
        bail!("[data] path: the EventNeRF scene folder is required for source = \"eventnerf\"");
    };
    if !path.is_dir() {
        bail!(
            "[data] path: no EventNeRF scene folder at {}: EventNeRF's scenes (train/ and val/ with \
             pose/, intrinsics/, rgb/ and the events) come from the EventNeRF authors' data \
             release. Set data.path to a scene folder",
            path.display()
        );
    }
    let options = EventNerfOptions {
        split: exp.data.split.clone(),
        ..EventNerfOptions::default()
    };
    let (scene, report) = read_eventnerf(path, &options)?;
    let note = format!(
        "{}: {report}; radial distortion {:?}",
        path.display(),
        scene.distortion
    );
    let times: Vec<f64> = scene.view_times.iter().map(|t| t.as_secs_f64()).collect();
    let duration = times.last().copied().unwrap_or(0.0);
    let truth = KeyedPoses::new(times, scene.world_from_camera.clone())
        .with_context(|| format!("{}: view poses", path.display()))?;
    Ok(Recording {
        scene,
        truth: InitialPath::Keyed(truth),
        duration,
        note,
    })
}

/// One condition: what is known of the path, and the anchors.
struct Condition {
    name: String,
    initial: InitialPath,
    anchors: Vec<(f64, Isometry3<f64>)>,
}

fn conditions(exp: &Experiment, rec: &Recording) -> anyhow::Result<Vec<Condition>> {
    let e = &exp.experiment;
    let mut out = Vec::new();
    match e.kind {
        Kind::Interpolation => {
            for &k in &e.known_poses {
                if k < 2 {
                    bail!("[experiment] known_poses: need at least 2 known views, got {k}");
                }
                let times: Vec<f64> = (0..=k)
                    .map(|i| i as f64 * rec.duration / k as f64)
                    .collect();
                let poses: Vec<_> = times.iter().map(|&t| rec.truth.at(t)).collect();
                let anchors = times.iter().copied().zip(poses.iter().copied()).collect();
                out.push(Condition {
                    name: format!("K{k}"),
                    initial: InitialPath::Keyed(KeyedPoses::new(times, poses)?),
                    anchors,
                });
            }
        }
        Kind::Calibration => {
            let InitialPath::Turntable(truth) = &rec.truth else {
                bail!(
                    "[experiment] kind = \"calibration\" needs [data] source = \"synthetic\": \
                     a recording's own turntable axis is not known"
                );
            };
            for &deg in &e.axis_offsets_deg {
                if deg.is_nan() || deg.abs() >= 45.0 {
                    bail!("[experiment] axis_offsets_deg: expected |offset| < 45°, got {deg}");
                }
                // The data turned about the true axis; training assumes one tilted by `deg`.
                let nominal = Turntable {
                    axis_tilt_rad: deg.to_radians(),
                    ..truth.clone()
                };
                out.push(Condition {
                    name: format!("offset{deg}deg"),
                    initial: InitialPath::Turntable(nominal),
                    anchors: Vec::new(),
                });
            }
        }
    }
    // A repeated entry is one condition.
    let mut seen = std::collections::BTreeSet::new();
    out.retain(|c| seen.insert(c.name.clone()));
    if out.is_empty() {
        bail!("[experiment]: no conditions (known_poses or axis_offsets_deg is empty)");
    }
    Ok(out)
}

/// One unit's results, as in `metrics.json` (the study adds `wall_s` and `cpu_s`).
#[derive(Debug, Serialize)]
struct MethodResult {
    /// Mean rotation / translation error against the truth at the evaluation times.
    rot_err_deg: f64,
    trans_err_su: f64,
    trans_err_max_su: f64,
    /// The same after BARF's Procrustes alignment (a similarity: events fix neither the
    /// scene's scale nor its frame).
    rot_err_aligned_deg: f64,
    trans_err_aligned_su: f64,
    /// The aligned rotation error left after removing the best common rotation of all cameras
    /// ([`cpose_core::eval::BarfPoseErrors::rot_err_relative_deg`]).
    rot_err_relative_deg: f64,
    /// Held-out views after colour correction.
    psnr_db: Option<f64>,
    ssim: Option<f64>,
    /// Mean event loss of the last 100 steps.
    final_loss: f64,
    iterations: usize,
}

fn decay(lr: [f64; 2], iterations: usize) -> ExponentialDecay {
    ExponentialDecay {
        lr0: lr[0],
        lr_end: lr[1],
        max_iter: iterations as u64,
    }
}

/// Everything the units share.
struct Setup<'a> {
    input: &'a TaskInput<'a>,
    exp: &'a Experiment,
    rec: &'a Recording,
    field: RadianceFieldConfig,
    bounds: SceneBounds,
    settings: RenderSettings,
    iterations: usize,
    threshold: f64,
    posenet: Option<PoseNetConfig>,
    /// Where windows are drawn: the recording's span where there are events, seconds.
    span: [f64; 2],
    /// Where poses are compared with the truth, and the truth there.
    eval_times: Vec<f64>,
    truth: Vec<Isometry3<f64>>,
}

fn render_settings(r: &RenderConfig) -> anyhow::Result<(RenderSettings, SceneBounds)> {
    if !(r.near > 0.0 && r.far > r.near && r.samples > 0) {
        bail!("[render]: need samples ≥ 1 and 0 < near < far");
    }
    let radius = r
        .scene_radius
        .unwrap_or_else(|| SyntheticScene::object_centric().bounding_radius());
    if !(radius.is_finite() && radius > 0.0) {
        bail!("[render] scene_radius = {radius}: expected a finite radius > 0");
    }
    let bounds = SceneBounds {
        centre: [0.0; 3],
        radius,
        unbounded: false,
    };
    let settings = RenderSettings {
        samples: r.samples,
        sampling: Sampling::Metric {
            near: r.near,
            far: r.far,
        },
        background: Some(r.background.unwrap_or([1.0; 3])),
        clip: Some(Clip {
            centre: bounds.centre,
            radius,
        }),
        last_interval: LastInterval::Closed,
    };
    Ok((settings, bounds))
}

/// The whole config, decoded and checked before the recording is read or simulated.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    field: RadianceFieldConfig,
    render: RenderSettings,
    bounds: SceneBounds,
    /// The loss' contrast threshold.
    threshold: f64,
    /// `[train] methods` without repeats.
    methods: Vec<Method>,
    iterations: usize,
    /// `[posenet]`, when PoseNet runs.
    posenet: Option<PoseNetConfig>,
}

impl Settings {
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        let field = RadianceFieldConfig::from_section(&config.section("field"), run.seed)?;
        let (render, bounds) = render_settings(&exp.render)?;
        if exp.data.source == Source::Synthetic {
            synthetic_config(&exp.simulation)?;
        }
        let train = &exp.train;
        let threshold = train.threshold.unwrap_or(exp.simulation.threshold);
        if !(threshold > 0.0 && train.eps > 0.0) {
            bail!("[train]: need threshold > 0 and eps > 0");
        }
        ExponentialDecay::check_train_rates(
            &[
                ("posenet_lr_translation", train.posenet_lr_translation),
                ("posenet_lr_rotation", train.posenet_lr_rotation),
            ],
            &train.lr_field,
        )
        .map_err(anyhow::Error::msg)?;
        let iterations = run.iterations(train.iterations);
        PoseTiming {
            hold: train.pose_hold,
            warmup: train.pose_warmup,
            rotation_warmup: train.pose_warmup,
        }
        .steps(iterations)?;
        let mut methods: Vec<Method> = Vec::new();
        for &m in &train.methods {
            if !methods.contains(&m) {
                methods.push(m);
            }
        }
        if methods.is_empty() {
            bail!("[train] methods: no methods to run");
        }
        let posenet = methods
            .contains(&Method::Posenet)
            .then(|| PoseNetConfig::from_section(&config.section("posenet"), run.seed))
            .transpose()?;
        Ok(Self {
            exp,
            field,
            render,
            bounds,
            threshold,
            methods,
            iterations,
            posenet,
        })
    }
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let Settings {
        exp,
        field,
        render: settings,
        bounds,
        threshold,
        methods,
        iterations,
        posenet,
    } = Settings::new(input.config, input.run)?;
    let train = &exp.train;
    let started = Instant::now();
    let rec = match exp.data.source {
        Source::Synthetic => synthetic_recording(&exp)?,
        Source::Eventnerf => eventnerf_recording(&exp)?,
    };
    let conditions = conditions(&exp, &rec)?;
    let camera = rec.scene.camera;
    input.run_dir.log(format_args!(
        "{} events of a {}×{} sensor over {:.2} s ({}; {:.1} s to load); {} held-out views; conditions {:?}; methods {:?}; {} steps of {} ray pairs in {} windows",
        rec.scene.events.len(),
        camera.width,
        camera.height,
        rec.duration,
        rec.note,
        started.elapsed().as_secs_f64(),
        rec.scene.held_out.len(),
        conditions.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
        methods.iter().map(|m| m.key()).collect::<Vec<_>>(),
        iterations,
        train.rays_per_step,
        train.windows_per_step,
    ));
    let span = match rec.scene.events.time_span() {
        Some((first, last)) => [
            first.as_secs_f64().max(0.0),
            last.as_secs_f64().min(rec.duration),
        ],
        None => bail!("the recording has no events"),
    };
    if span[0] >= span[1] {
        bail!(
            "no events within the views' time span [0, {}] s",
            rec.duration
        );
    }
    let samples = exp.eval.pose_samples.max(2);
    let eval_times: Vec<f64> = (0..samples)
        .map(|i| (i as f64 + 0.5) * rec.duration / samples as f64)
        .collect();
    let truth: Vec<_> = eval_times.iter().map(|&t| rec.truth.at(t)).collect();
    write_trajectory(input.run_dir.file("traj_gt.txt"), &eval_times, &truth)?;
    let setup = Setup {
        input,
        exp: &exp,
        rec: &rec,
        field,
        bounds,
        settings,
        iterations,
        threshold,
        posenet,
        span,
        eval_times,
        truth,
    };

    // One unit per condition and method, all with the run's seed.
    let names: Vec<&str> = conditions.iter().map(|c| c.name.as_str()).collect();
    let keys: Vec<&str> = methods.iter().map(|m| m.key()).collect();
    let units = UnitKey::grid(&names, &keys, &[input.run.seed]);
    Study::new(input, units)
        .columns(&[
            "rot_err_deg",
            "trans_err_su",
            "rot_err_aligned_deg",
            "trans_err_aligned_su",
            "psnr_db",
            "ssim",
            "final_loss",
        ])
        .report_every(100)
        .run(|unit| {
            let condition = conditions
                .iter()
                .find(|c| c.name == unit.key().condition)
                .context("a condition of the config")?;
            let method = *methods
                .iter()
                .find(|m| m.key() == unit.key().method)
                .context("a method of the config")?;
            Metrics::from_serialize(&run_method(&setup, condition, method, unit)?)
        })?;
    Ok(())
}

/// Losses kept for the running mean (live reports, `final_loss`).
const RECENT: usize = 100;

/// Trains one method in one condition, reporting and checkpointing through `unit`, and
/// evaluates it.
/// Samples of the initial path in a saved PoseNet field (`field_<condition>_posenet.safetensors`).
const SAVED_PATH_SAMPLES: usize = 2000;

fn run_method(
    setup: &Setup<'_>,
    condition: &Condition,
    method: Method,
    unit: &mut Unit,
) -> anyhow::Result<MethodResult> {
    let Setup {
        input,
        exp,
        rec,
        iterations,
        ..
    } = *setup;
    let train = &exp.train;
    let mut field = setup.field.init::<f32>(setup.bounds)?;
    let initial = if method == Method::TruePoses {
        rec.truth.clone()
    } else {
        condition.initial.clone()
    };
    let correction = match method {
        Method::Posenet => {
            let range = TimeRange::new(0.0, rec.duration)
                .context("the recording needs a positive duration")?;
            let config = setup
                .posenet
                .as_ref()
                .context("[posenet] decoded for PoseNet")?;
            Some(Box::new(config.init::<f32>(range)?) as Box<dyn PoseField>)
        }
        _ => None,
    };
    // Every method draws the same windows (`anchor_windows` among them); the anchor term acts
    // only on a correction.
    let (hold, warmup, rotation_warmup) = PoseTiming {
        hold: train.pose_hold,
        warmup: train.pose_warmup,
        rotation_warmup: train.pose_warmup,
    }
    .steps(iterations)?;
    let trained = iterations - hold as usize;
    let schedules = PoseSchedules {
        rotation: decay(train.posenet_lr_rotation, trained),
        translation: decay(train.posenet_lr_translation, trained),
        pose: decay(train.posenet_lr_translation, trained),
        hold,
        warmup,
        rotation_warmup,
    };
    let mut poses = FramePoses::new(Vec::new(), Vec::new(), correction, schedules);
    let schedule = EventSchedule {
        iterations: iterations as u64,
        rays_per_step: train.rays_per_step,
        windows_per_step: train.windows_per_step,
        window_secs: train.window.map(|f| f * rec.duration),
        time_span: Some(setup.span),
        neg_ratio: train.neg_ratio,
        loss: EventLoss {
            threshold: setup.threshold as f32,
            eps: train.eps as f32,
        },
        field_lr: train.lr_field.clone(),
        anchor_weight: train.anchor_weight,
        anchor_windows: train.anchor_windows,
        seed: input.run.seed,
    };
    let mut trainer = EventTrainer::new(
        field.as_mut(),
        &mut poses,
        &initial,
        condition.anchors.clone(),
        &rec.scene.events,
        rec.scene.camera,
        setup.settings,
        schedule,
    )
    .context("[train]")?
    .with_distortion(rec.scene.distortion);
    unit.set_steps(iterations);
    // The last `RECENT` losses, a ring.
    let mut recent = vec![0.0f64; RECENT];
    let mut first = 0;
    if let Some((done, mut r)) = unit.resume() {
        trainer.read_state(&mut r)?;
        recent = r.f64s()?;
        if recent.len() != RECENT {
            bail!("{}: corrupt loss history", r.path().display());
        }
        first = done as usize;
    }
    let mean_loss = |recent: &[f64], done: usize| {
        let n = done.clamp(1, RECENT);
        recent[..n].iter().sum::<f64>() / n as f64
    };
    for it in first..iterations {
        let stats = trainer.step(it as u64).context("training stopped")?;
        recent[it % RECENT] = stats.loss;
        let done = it + 1;
        if unit.report_due(done) {
            let path = trainer.path_at(&setup.eval_times, done as f64 / iterations as f64)?;
            let (rot, trans, _) = pose_errors(&setup.truth, &path);
            unit.report(
                done,
                &[
                    ("loss", mean_loss(&recent, done)),
                    ("rot_err_deg", rot),
                    ("trans_err_su", trans),
                ],
            );
        }
        if done < iterations && unit.checkpoint_due() {
            unit.checkpoint(done as u64, |w| {
                trainer.write_state(w);
                w.f64s(&recent);
                Ok(())
            })?;
        }
    }
    let estimate = trainer.path_at(&setup.eval_times, 1.0)?;
    // The method's own camera at the first held-out view's time.
    let own_pose = match rec.scene.held_out.first().and_then(|v| v.time) {
        Some(t) => Some(trainer.path_at(&[t.as_secs_f64()], 1.0)?[0]),
        None => None,
    };
    drop(trainer);
    if let (Method::Posenet, Some(config)) = (method, &setup.posenet) {
        // The initial path sampled densely enough that interpolating between samples is exact
        // to well below the poses' f32 precision; the frame is the trajectory files' own.
        let times: Vec<f64> = (0..=SAVED_PATH_SAMPLES)
            .map(|k| rec.duration * k as f64 / SAVED_PATH_SAMPLES as f64)
            .collect();
        let init: Vec<_> = times.iter().map(|&t| initial.at(t)).collect();
        cpose_nerf::poses::save_corrected_field(
            &unit.file("field", "safetensors"),
            (&config.field_table(), poses.params()),
            &times,
            &init,
            cpose_core::eval::Sim3::identity(),
        )?;
    }
    let init: Vec<_> = setup.eval_times.iter().map(|&t| initial.at(t)).collect();
    evaluate(
        setup,
        unit,
        field.as_mut(),
        Paths {
            estimate: &estimate,
            init: &init,
            own_pose,
        },
        mean_loss(&recent, iterations),
    )
}

fn write_trajectory(path: PathBuf, times: &[f64], poses: &[Isometry3<f64>]) -> anyhow::Result<()> {
    write_tum(path, &Trajectory::new(times.to_vec(), poses.to_vec())?)?;
    Ok(())
}

/// Mean rotation (°), mean and max translation error of `estimate` against `truth`.
fn pose_errors(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> (f64, f64, f64) {
    let n = truth.len().max(1) as f64;
    let (mut rot, mut trans, mut max) = (0.0, 0.0, 0.0f64);
    for (t, e) in truth.iter().zip(estimate) {
        rot += rotation_angle_between(&t.rotation, &e.rotation).to_degrees() / n;
        let d = (t.translation.vector - e.translation.vector).norm();
        trans += d / n;
        max = max.max(d);
    }
    (rot, trans, max)
}

/// A method's path at the evaluation times, its initial path there, and its own camera at the
/// first held-out view's time.
struct Paths<'a> {
    estimate: &'a [Isometry3<f64>],
    init: &'a [Isometry3<f64>],
    own_pose: Option<Isometry3<f64>>,
}

/// Scores a trained unit and writes its files.
fn evaluate(
    setup: &Setup<'_>,
    unit: &Unit,
    field: &mut dyn RadianceField,
    paths: Paths<'_>,
    final_loss: f64,
) -> anyhow::Result<MethodResult> {
    let Setup {
        exp,
        rec,
        settings,
        iterations,
        ..
    } = *setup;
    let (times, truth) = (&setup.eval_times, &setup.truth);
    let Paths {
        estimate,
        init,
        own_pose,
    } = paths;
    let (rot_err_deg, trans_err, max_trans_err) = pose_errors(truth, estimate);
    let aligned = barf_pose_errors(truth, estimate, ReflectionFix::Kabsch)?;
    write_trajectory(unit.file("traj", "txt"), times, estimate)?;
    let key = unit.key();
    let title = format!(
        "events, {} / {}: camera path against the truth; mean rotation error {rot_err_deg:.2}°",
        key.condition, key.method
    );
    if let Err(e) = cpose_core::plot::trajectory_comparison(
        unit.file("trajectory", "png"),
        &title,
        times,
        Some(truth),
        Some(("initial poses", init)),
        (key.method.as_str(), estimate),
    ) {
        unit.log(format_args!("no trajectory plot: {e}"));
    }

    let held_out = &rec.scene.held_out;
    let (mut psnr_db, mut ssim_mean) = (None, None);
    if !held_out.is_empty() {
        let mut renderer = Renderer::default();
        // Through the recording's lens, as its held-out images were taken.
        let camera = &rec.scene.camera;
        let directions = pixel_directions(camera, rec.scene.distortion);
        let size = (camera.width, camera.height);
        let render =
            |renderer: &mut Renderer, field: &mut dyn RadianceField, pose: Isometry3<f64>| {
                let direction = |x, y| directions[y * size.0 + x];
                render_view_with(renderer, field, &settings, size, direction, &pose, 4096)
            };
        let renders: Vec<_> = held_out
            .iter()
            .map(|view| {
                let pose = aligned.alignment.gt_to_learned(&view.world_from_camera);
                render(&mut renderer, field, pose)
            })
            .collect();
        let images: Vec<Image> = renders.iter().map(|r| r.image.clone()).collect();
        let truths: Vec<Image> = held_out.iter().map(|v| v.image.clone()).collect();
        let correction = ColourCorrection::fit(&images, &truths);
        let (mut p, mut s) = (0.0, 0.0);
        let (near, far) = (exp.render.near, exp.render.far);
        for (k, ((render, image), truth)) in renders.iter().zip(&images).zip(&truths).enumerate() {
            let corrected = correction.apply(image);
            p += psnr(corrected.data(), truth.data());
            s += ssim(&corrected, truth);
            if k < exp.eval.saved_views {
                let (w, h) = (truth.width(), truth.height());
                corrected
                    .beside(truth)
                    .save_png(unit.file(&format!("view_{k}"), "png"))?;
                depth_image(w, h, &render.depth, &render.opacity, near, far)
                    .save_png(unit.file(&format!("depth_{k}"), "png"))?;
            }
        }
        if let Some(pose) = own_pose {
            // What the method's own camera sees (a mis-calibrated path shows the object
            // off-centre), beside the true view.
            let view = render(&mut renderer, field, pose);
            correction
                .apply(&view.image)
                .beside(&truths[0])
                .save_png(unit.file("own_view", "png"))?;
        }
        let n = held_out.len() as f64;
        psnr_db = Some(p / n);
        ssim_mean = Some(s / n);
    }
    Ok(MethodResult {
        rot_err_deg,
        trans_err_su: trans_err,
        trans_err_max_su: max_trans_err,
        rot_err_aligned_deg: aligned.rot_err_deg,
        trans_err_aligned_su: aligned.trans_err,
        rot_err_relative_deg: aligned.rot_err_relative_deg,
        psnr_db,
        ssim: ssim_mean,
        final_loss,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show events` states the defaults: its values are those of an empty config.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"events\"\n";
        cpose_core::testing::check_default_config("events", required, Settings::new);
    }
}
