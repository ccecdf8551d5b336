//! Task `nerf`: NeRF from noisy or unknown camera poses (paper §4.1.2, its supplement's noise
//! tables and the LLFF table; BARF's protocol, docs/methods.md §2.2–2.3).
//!
//! A radiance field is trained from images whose poses are wrong, and the poses are refined
//! jointly as a correction of the initial ones, `world_from_cam_i = C(t_i) ∘ init_i`
//! ([`crate::poses`]). The methods differ only in `C`: PoseNet on time (`posenet`), BARF's free se(3)
//! per frame (`barf`), a cubic B-spline of control poses (`spline`), or no correction at all —
//! `true_poses` trains with the ground truth (the reference for PSNR) and `fixed` with the
//! initial poses. Everything else is shared: field, sampling, rays and seeds.
//!
//! One departure from the paper: the poses are held for the first `[train] pose_hold` of the
//! steps, then their learning rates ramp up linearly over `[train] pose_warmup` of them
//! ([`PoseSchedules`]). Before the field can explain the images its pose gradients are noise,
//! and poses moved at full rate against a blank or blurred field move away from the truth, even
//! from the true poses (measured in `docs/results/nerf.md`). `[train] rotation_warmup` gives
//! PoseNet's rotation network a ramp of its own.
//!
//! An option beyond the paper for large noise: `[train] field_restart_every = K` restarts the
//! field every `K` steps up to `field_restart_until` (a fraction of the steps) while the poses
//! keep their state ([`train`]). At 60° + 10% the field otherwise fits the wrong poses and holds
//! them there (a consistent but wrong pair).
//!
//! The field's region (and, for bounded scenes, the sphere rays are clipped to) is the scene's
//! bounding ball widened by the largest shift the initial poses give the scene
//! ([`crate::field3d::SceneBounds::widened_for`]), the same for every method. Without it a camera shifted by
//! more than the scene's radius sees the object where the field cannot hold it: at 60° / 20%
//! noise even the field trained on the fixed initial poses stayed at a blank 11 dB.
//!
//! Data (`[data] source`):
//! - `synthetic` (default): the built-in textured scene rendered along the paper's monocular
//!   orbit (a circle in the xy-plane, up and down in z at constant speed), 100 frames of
//!   100×100, perturbed by time-correlated noise (`[noise]`); held-out views are rendered
//!   half-way between training frames.
//! - `llff`: a forward-facing scene (`poses_bounds.npy`, `images_N/`) normalised as BARF
//!   (scaled so the nearest bound is 4/3, centred on the mean camera), the last 10% of the
//!   images held out; `[noise] kind = "identity"` is the paper's unknown-pose start.
//! - `blender`: a NeRF-synthetic scene (`transforms_train.json`); BARF's i.i.d. noise.
//! - `colmap`: a user's own forward-facing capture as COLMAP reconstructs it (`images/`,
//!   `sparse/0/`; [`crate::data::colmap_scene`]), normalised and held out as `llff`; the poses
//!   start at COLMAP's (`[noise] kind = "none"`) and are refined.
//! - `nerfstudio`: a user's capture around an object as nerfstudio's `transforms.json`
//!   ([`crate::data::nerfstudio`]): centred on the mean camera, scaled to cameras 4 units away,
//!   the background contracted beyond; the last 10% held out; the poses start at the file's.
//!
//! Pose errors are BARF's (Procrustes on the camera centres, then mean rotation and translation
//! errors) with one change: when the centres align best through a reflection — near-planar
//! centres, as LLFF's — Kabsch's fix replaces BARF's third-row negation, which can misalign by
//! many degrees ([`ReflectionFix`]); the log and `metrics.json` then also give BARF's reading.
//!
//! Outputs: `metrics.json`
//! (`{condition: {method: {rot_err_deg, rot_err_relative_deg, trans_err_su, psnr_db, ssim, …}}}`),
//! `traj_<condition>_<method>.txt` (estimated, aligned to the truth) and, for the methods that
//! learn a correction, `field_<condition>_<method>.safetensors` (those cameras as one pose field,
//! for `cpose query`), `traj_gt.txt`,
//! `traj_init.txt` (TUM), `trajectory_<condition>_<method>.png` (true, initial and estimated
//! training cameras in evo_traj's layout, [`cpose_core::plot::trajectory_comparison`]),
//! `view_<k>_<condition>_<method>.png` (rendered | truth), `depth_<k>_<condition>_<method>.png`,
//! for a user's capture the training images' poses, not aligned, in the capture's own frame and
//! units: `colmap_<condition>_<method>/` (a COLMAP model in the format read,
//! [`crate::data::colmap_scene::ColmapScene::write_refined`]) or
//! `transforms_<condition>_<method>.json` ([`crate::data::nerfstudio::NerfstudioScene::write_refined`]),
//! and the study's `curves.csv`, `curves.png` and `units/` ([`cpose_core::study`]).

pub mod eval;
pub mod train;
mod views;

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, bail};
use cpose_core::eval::{ReflectionFix, Trajectory, barf_pose_errors, write_tum};
use cpose_core::nn::ExponentialDecay;
use cpose_core::plot;
use cpose_core::registry::{Task, TaskInput};
use cpose_core::study::{Metrics, Study, Unit, UnitKey};
use cpose_core::{Config, PoseField, PoseNetConfig, RunConfig, TimeRange};
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::camera::PinholeCamera;
use crate::field3d::{RadianceField, RadianceFieldConfig};
use crate::metrics::ssim;
use crate::poses::{FramePoses, PoseSchedules, PoseTiming};
use crate::render::{Renderer, Sampling, depth_image, render_view};

use crate::scene::{MonocularOrbit, PoseNoise};
use eval::Refinement;
use train::{Schedule, Trainer};
use views::{DataConfig, RenderConfig, Source, Views};

inventory::submit! {
    Task {
        name: "nerf",
        about: "NeRF from noisy or unknown poses (paper §4.1.2): PoseNet vs BARF vs B-spline",
        default_config,
        check: |config, run| Settings::new(config, run).map(drop),
        run,
    }
}

/// The task's defaults: `cpose config show nerf`.
fn default_config() -> String {
    [
        include_str!("../../defaults/nerf.toml"),
        RadianceFieldConfig::DEFAULT_TABLE,
        PoseNetConfig::DEFAULT_TABLE,
    ]
    .join("\n")
}

/// The config file of the task.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    #[serde(default)]
    data: DataConfig,
    #[serde(default)]
    orbit: MonocularOrbit,
    #[serde(default)]
    render: RenderConfig,
    #[serde(default)]
    train: TrainConfig,
    #[serde(default)]
    eval: EvalConfig,
    /// The pose noise, decoded by kind.
    #[serde(rename = "noise", default)]
    _noise: serde::de::IgnoredAny,
    /// The radiance field, `kind = "grid"` or `"mlp"`.
    #[serde(rename = "field", default)]
    _field: serde::de::IgnoredAny,
    /// PoseNet's settings ([`PoseNetConfig`]).
    #[serde(rename = "posenet", default)]
    _posenet: serde::de::IgnoredAny,
}

/// A pose model, named as in `metrics.json`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
enum Method {
    Posenet,
    Barf,
    Spline,
    TruePoses,
    Fixed,
}

impl Method {
    fn key(self) -> &'static str {
        match self {
            Self::Posenet => "posenet",
            Self::Barf => "barf",
            Self::Spline => "spline",
            Self::TruePoses => "true_poses",
            Self::Fixed => "fixed",
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
    /// `[start, end]` learning rate per field parameter group (`grid`, `mlp`).
    lr_field: BTreeMap<String, [f64; 2]>,
    /// PoseNet: `[start, end]` for the translation and rotation networks.
    posenet_lr_translation: [f64; 2],
    posenet_lr_rotation: [f64; 2],
    /// BARF and spline: `[start, end]` for their se(3) parameters.
    lr_pose: [f64; 2],
    /// Fraction of the steps during which the poses are held while the field fits the initial
    /// poses (not in the paper; [`PoseSchedules::hold`]). For poses that are nearly right (a
    /// calibrated capture), not for noisy ones, where the field locks in the initial error
    /// (`docs/results/nerf.md`, "The pose hold"); 0 by default.
    pose_hold: f64,
    /// Fraction of the steps after the hold over which the pose learning rates ramp up
    /// linearly from 0 ([`PoseSchedules::warmup`]).
    pose_warmup: f64,
    /// The same for PoseNet's rotation network alone (default: `pose_warmup`).
    rotation_warmup: Option<f64>,
    /// Restart the field every this many steps while the poses are refined (0: never;
    /// [`train::Schedule::field_restart_every`]). Runs with fixed poses never restart.
    field_restart_every: usize,
    /// The fraction of the steps after which no restart begins; the last round runs to the end.
    field_restart_until: f64,
    /// Spline: frames per control pose.
    spline_frames_per_control: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            methods: vec![Method::Posenet, Method::Barf, Method::TruePoses],
            iterations: 6000,
            rays_per_step: 1024,
            lr_field: BTreeMap::from([
                ("grid".to_owned(), [1e-2, 1e-3]),
                ("mlp".to_owned(), [1e-3, 1e-4]),
            ]),
            posenet_lr_translation: [1e-3, 1e-5],
            posenet_lr_rotation: [2e-4, 1e-6],
            lr_pose: [1e-3, 1e-5],
            pose_hold: 0.0,
            pose_warmup: 0.1,
            rotation_warmup: None,
            field_restart_every: 0,
            field_restart_until: 1.0,
            spline_frames_per_control: 5.0,
        }
    }
}

/// `[eval]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct EvalConfig {
    /// Test-time photometric refinement steps (0: off).
    refine_iterations: usize,
    refine_rays: usize,
    /// Views saved as PNG (the first ones).
    saved_views: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            refine_iterations: 100,
            refine_rays: 1024,
            saved_views: 3,
        }
    }
}

/// One method's results, as in `metrics.json`.
#[derive(Debug, Serialize)]
struct MethodResult {
    /// Mean rotation error after Procrustes alignment (BARF's, with Kabsch's reflection fix),
    /// degrees.
    rot_err_deg: f64,
    /// The rotation error left after removing the best common rotation of all cameras
    /// ([`cpose_core::eval::BarfPoseErrors::rot_err_relative_deg`]), degrees.
    rot_err_relative_deg: f64,
    /// Mean translation error after alignment, scene units.
    trans_err_su: f64,
    /// Only when the centres' best orthogonal map was a reflection: the errors with BARF's own
    /// third-row fix, for comparison with BARF's code ([`ReflectionFix::BarfThirdRow`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    rot_err_barf_fix_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    trans_err_barf_fix_su: Option<f64>,
    /// The same errors of the initial poses (none when they all coincide: unknown poses).
    init_rot_err_deg: Option<f64>,
    init_rot_err_relative_deg: Option<f64>,
    init_trans_err_su: Option<f64>,
    /// Held-out views rendered from the aligned true poses.
    psnr_db: f64,
    ssim: f64,
    /// With test-time photometric refinement of each test pose.
    psnr_refined_db: Option<f64>,
    ssim_refined: Option<f64>,
    /// The same four on a further split of novel views (`psnr_val_db`, `ssim_val`,
    /// `psnr_val_refined_db`, `ssim_val_refined`).
    #[serde(flatten)]
    further_splits: BTreeMap<String, f64>,
    /// Mean squared error of the last 100 training steps.
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

/// The pose correction of `method` (none for fixed poses), and its table as the pose-field
/// registry reads it (`kind` and its settings), for the saved field.
fn correction(
    method: Method,
    posenet: Option<&PoseNetConfig>,
    views: &Views,
    train: &TrainConfig,
) -> anyhow::Result<Option<(Box<dyn PoseField>, String)>> {
    let times = &views.train_times;
    let range = TimeRange::new(times[0], times[times.len() - 1])
        .context("need at least two training frames at distinct times")?;
    Ok(match method {
        Method::TruePoses | Method::Fixed => None,
        Method::Posenet => {
            let config = posenet.context("[posenet] is decoded when PoseNet runs")?;
            let table = config.field_table();
            Some((Box::new(config.init::<f32>(range)?), table))
        }
        Method::Barf => Some((
            Box::new(cpose_core::DiscretePoses::<f32>::new(times)?),
            "kind = \"discrete\"\n".to_owned(),
        )),
        Method::Spline => {
            let span = times.len() as f64 / train.spline_frames_per_control.max(1e-9);
            let config = cpose_core::SplineConfig {
                kind: cpose_core::SplineKind::Lie,
                control_points: (span.round() as usize).max(4),
                knot_spacing_secs: None,
            };
            let table = format!(
                "kind = \"lie_spline\"\ncontrol_points = {}\n",
                config.control_points
            );
            Some((Box::new(config.init::<f32>(range, times)?), table))
        }
    })
}

/// The whole config, decoded and checked: every table, before any data is read.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    noise: PoseNoise,
    field_config: RadianceFieldConfig,
    /// `[posenet]`, when a method uses it.
    posenet: Option<PoseNetConfig>,
    iterations: usize,
    /// Steps of the pose hold, the pose warm-up and PoseNet's rotation warm-up.
    pose_steps: (u64, u64, u64),
}

impl Settings {
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        if exp.data.source == Source::Synthetic {
            exp.orbit.validate()?;
        }
        let noise_section = config.section("noise");
        let field_config = RadianceFieldConfig::from_section(&config.section("field"), run.seed)?;
        let noise: PoseNoise = if noise_section.exists()? {
            noise_section.decode()?
        } else if exp.data.source == Source::Llff {
            PoseNoise::Identity {}
        } else if matches!(exp.data.source, Source::Colmap | Source::Nerfstudio) {
            PoseNoise::None {}
        } else {
            PoseNoise::default()
        };
        noise.validate()?;
        let train = &exp.train;
        if train.rays_per_step == 0 {
            bail!("[train] rays_per_step = 0: expected at least 1");
        }
        ExponentialDecay::check_train_rates(
            &[
                ("posenet_lr_translation", train.posenet_lr_translation),
                ("posenet_lr_rotation", train.posenet_lr_rotation),
                ("lr_pose", train.lr_pose),
            ],
            &train.lr_field,
        )
        .map_err(anyhow::Error::msg)?;
        if !(0.0..=1.0).contains(&train.field_restart_until) {
            bail!(
                "[train] field_restart_until = {} must lie in [0, 1] (a fraction of the steps)",
                train.field_restart_until
            );
        }
        let iterations = run.iterations(train.iterations);
        let pose_steps = PoseTiming {
            hold: train.pose_hold,
            warmup: train.pose_warmup,
            rotation_warmup: train.rotation_warmup.unwrap_or(train.pose_warmup),
        }
        .steps(iterations)?;
        let posenet = train
            .methods
            .contains(&Method::Posenet)
            .then(|| PoseNetConfig::from_section(&config.section("posenet"), run.seed))
            .transpose()?;
        Ok(Self {
            exp,
            noise,
            field_config,
            posenet,
            iterations,
            pose_steps,
        })
    }
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let Settings {
        exp,
        noise,
        field_config,
        posenet,
        iterations,
        pose_steps: (hold, warmup, rotation_warmup),
    } = Settings::new(input.config, input.run)?;
    let mut views = Views::load(&exp.data, &exp.orbit, &exp.render)?;
    for note in &views.notes {
        input.run_dir.log(note);
    }
    let initial = noise.apply(&views.train_truth, views.diameter);
    let widened = views.bounds.widened_for(&views.train_truth, &initial);
    if widened.radius > views.bounds.radius * (1.0 + 1e-9) {
        input.run_dir.log(format_args!(
            "region of interest widened for the initial poses: radius {:.3} → {:.3}",
            views.bounds.radius, widened.radius
        ));
    }
    let lost = centre_leaves_view(
        &views.camera,
        views.bounds.centre,
        &views.train_truth,
        &initial,
    );
    if lost > 0 {
        input.run_dir.log(format_args!(
            "the initial poses put the scene's centre outside the image in {lost} of {} \
             training views",
            initial.len()
        ));
    }
    views.bounds = widened;
    if let Some(clip) = views.settings.clip.as_mut() {
        clip.radius = widened.radius;
    }
    let seed = input.run.seed;
    let steps = |fraction: f64| (fraction * iterations as f64).round() as u64;
    let train = &exp.train;
    input.run_dir.log(format_args!(
        "{}: {} training views of {}×{}, {} held out; field {}; noise {:?}; {} steps of {} rays × {} samples; methods {:?}",
        views.condition,
        views.train_images.len(),
        views.camera.width,
        views.camera.height,
        views.tests.iter().map(|t| t.images.len()).sum::<usize>(),
        match field_config {
            RadianceFieldConfig::Grid(_) => "grid",
            RadianceFieldConfig::Mlp(_) => "mlp",
        },
        noise,
        iterations,
        train.rays_per_step,
        views.settings.samples,
        train.methods.iter().map(|m| m.key()).collect::<Vec<_>>(),
    ));
    if let Some(posenet) = &posenet {
        // PoseNet's translation head is bounded, |t_k| < s (`posenet.translation_scale`); the
        // correction that undoes the noise is `truth ∘ init⁻¹`.
        let scale = posenet.translation_scale;
        let needed = views
            .train_truth
            .iter()
            .zip(&initial)
            .map(|(truth, init)| (truth * init.inverse()).translation.vector.amax())
            .fold(0.0, f64::max);
        if needed > 0.9 * scale {
            input.run_dir.log(format_args!(
                "warning: undoing the noise needs PoseNet translations up to {needed:.2}, at or \
                 beyond its bound posenet.translation_scale = {scale}; raise it"
            ));
        }
    }
    let file = |name: &str| input.run_dir.file(name);
    write_trajectory(file("traj_gt.txt"), &views.train_times, &views.train_truth)?;
    write_trajectory(file("traj_init.txt"), &views.train_times, &initial)?;

    let units = train
        .methods
        .iter()
        .map(|m| UnitKey::new(views.condition.as_str(), m.key(), seed))
        .collect();
    Study::new(input, units)
        .report_every(500)
        .columns(&[
            "rot_err_deg",
            "rot_err_relative_deg",
            "trans_err_su",
            "psnr_db",
            "ssim",
            "psnr_refined_db",
        ])
        .run(|unit| {
            let method = *train
                .methods
                .iter()
                .find(|m| m.key() == unit.key().method)
                .context("a method of the config")?;
            let mut field = field_config.init::<f32>(views.bounds)?;
            let init = if method == Method::TruePoses {
                views.train_truth.clone()
            } else {
                initial.clone()
            };
            let trained = iterations - hold as usize;
            let schedules = PoseSchedules {
                rotation: decay(train.posenet_lr_rotation, trained),
                translation: decay(train.posenet_lr_translation, trained),
                pose: decay(train.lr_pose, trained),
                hold,
                warmup,
                rotation_warmup,
            };
            let (correction, table) = correction(method, posenet.as_ref(), &views, train)?.unzip();
            let mut poses = FramePoses::new(init, views.train_times.clone(), correction, schedules);
            let schedule = Schedule {
                iterations: iterations as u64,
                rays_per_step: train.rays_per_step,
                field_lr: train.lr_field.clone(),
                seed,
                field_restart_every: if poses.is_trainable() {
                    train.field_restart_every as u64
                } else {
                    0
                },
                field_restart_until: steps(train.field_restart_until),
            };
            let final_loss = {
                let mut trainer = Trainer::new(
                    field.as_mut(),
                    &mut poses,
                    &views.train_images,
                    views.camera,
                    views.settings,
                    schedule,
                )?;
                train_steps(&mut trainer, unit, method, iterations, &views.train_truth)?
            };
            let result = evaluate(
                unit,
                &exp,
                &views,
                field.as_mut(),
                &poses,
                table.as_deref(),
                final_loss,
                iterations,
                seed,
            )?;
            Metrics::from_serialize(&result)
        })?;
    Ok(())
}

/// How many views see the point `centre` inside the image from their true pose but not from
/// their initial one. Noise that turns cameras about the scene keeps it in view; a shift across
/// the view direction moves it towards the border and beyond.
fn centre_leaves_view(
    camera: &PinholeCamera,
    centre: [f64; 3],
    truth: &[Isometry3<f64>],
    initial: &[Isometry3<f64>],
) -> usize {
    let centre = nalgebra::Point3::from(centre);
    let in_view = |world_from_camera: &Isometry3<f64>| {
        let p = world_from_camera.inverse_transform_point(&centre).coords;
        camera.project(&p).is_some_and(|[u, v]| {
            (0.0..camera.width as f64).contains(&u) && (0.0..camera.height as f64).contains(&v)
        })
    };
    truth
        .iter()
        .zip(initial)
        .filter(|(t, i)| in_view(t) && !in_view(i))
        .count()
}

/// Losses kept for the reported (and final) loss: the mean of the latest ones.
const RECENT: usize = 100;

/// Steps `trainer` to `iterations` (from the unit's checkpoint after a resume), reporting the
/// mean loss of the latest [`RECENT`] steps and the pose errors against `truth`, and saving
/// the whole training state when a checkpoint is due; returns the final mean loss. A failed
/// step or checkpoint ends the run with one error naming the method and the last good
/// checkpoint (a diverged state never overwrites it, see [`Trainer::save_state`]) or saying
/// there is none.
fn train_steps(
    trainer: &mut Trainer<'_>,
    unit: &mut Unit,
    method: Method,
    iterations: usize,
    truth: &[Isometry3<f64>],
) -> anyhow::Result<f64> {
    let mut recent = [0.0f64; RECENT];
    let mut first = 0;
    unit.set_steps(iterations);
    if let Some((done, mut r)) = unit.resume() {
        trainer.load_state(&mut r, done)?;
        let saved = r.f64s()?;
        if saved.len() != RECENT {
            bail!("{}: corrupt loss history", r.path().display());
        }
        recent.copy_from_slice(&saved);
        first = done as usize;
    }
    let stopped = |unit: &Unit| {
        let last = match unit.last_checkpoint() {
            Some((path, steps)) => {
                format!(
                    "last good checkpoint: {}, after {steps} steps",
                    path.display()
                )
            }
            None => "no checkpoint yet".to_owned(),
        };
        format!("method {}: training stopped ({last})", method.key())
    };
    let mean = |recent: &[f64; RECENT], done: usize| {
        let n = done.clamp(1, RECENT);
        recent[..n].iter().sum::<f64>() / n as f64
    };
    for it in first..iterations {
        let loss = trainer.step(it as u64).with_context(|| stopped(unit))?;
        recent[it % RECENT] = loss;
        let done = it + 1;
        if unit.report_due(done) {
            let loss = mean(&recent, done);
            // Undefined while the cameras' centres still coincide (an unknown-pose start).
            let errors = barf_pose_errors(truth, trainer.poses().current(), ReflectionFix::Kabsch)
                .map_or([f64::NAN; 3], |e| {
                    [e.rot_err_deg, e.rot_err_relative_deg, e.trans_err]
                });
            unit.report(
                done,
                &[
                    ("loss", loss),
                    ("psnr_train_db", -10.0 * loss.log10()),
                    ("rot_err_deg", errors[0]),
                    ("rot_err_relative_deg", errors[1]),
                    ("trans_err_su", errors[2]),
                ],
            );
        }
        if done < iterations && unit.checkpoint_due() {
            let saved = unit.checkpoint(done as u64, |w| {
                trainer.save_state(w)?;
                w.f64s(&recent);
                Ok(())
            });
            saved.with_context(|| stopped(unit))?;
        }
    }
    Ok(mean(&recent, iterations))
}

fn write_trajectory(path: PathBuf, times: &[f64], poses: &[Isometry3<f64>]) -> anyhow::Result<()> {
    let trajectory = Trajectory::new(times.to_vec(), poses.to_vec())?;
    write_tum(path, &trajectory)?;
    Ok(())
}

fn evaluate(
    unit: &Unit,
    exp: &Experiment,
    views: &Views,
    field: &mut dyn RadianceField,
    poses: &FramePoses,
    correction_table: Option<&str>,
    final_loss: f64,
    iterations: usize,
    seed: u64,
) -> anyhow::Result<MethodResult> {
    let estimate = poses.current();
    let errors = barf_pose_errors(&views.train_truth, estimate, ReflectionFix::Kabsch)?;
    let barf_fix = if errors.alignment.reflected {
        let barf = barf_pose_errors(&views.train_truth, estimate, ReflectionFix::BarfThirdRow)?;
        unit.log(format_args!(
            "the camera centres align best through a reflection (near-planar centres); with \
             Kabsch's fix rotation {:.3}°, translation {:.4}; with BARF's third-row fix {:.3}°, \
             {:.4}",
            errors.rot_err_deg, errors.trans_err, barf.rot_err_deg, barf.trans_err,
        ));
        Some(barf)
    } else {
        None
    };
    let init_errors =
        barf_pose_errors(&views.train_truth, poses.initial(), ReflectionFix::Kabsch).ok();
    let aligned: Vec<_> = estimate
        .iter()
        .map(|p| errors.alignment.align_pose(p))
        .collect();
    let init_aligned: Vec<_> = match &init_errors {
        Some(e) => poses
            .initial()
            .iter()
            .map(|p| e.alignment.align_pose(p))
            .collect(),
        None => Vec::new(),
    };
    write_trajectory(unit.file("traj", "txt"), &views.train_times, &aligned)?;
    if let Some(table) = correction_table {
        // In the frame of `traj_<condition>_<method>.txt`, the Procrustes alignment to the truth.
        crate::poses::save_corrected_field(
            &unit.file("field", "safetensors"),
            (table, poses.params()),
            poses.times(),
            poses.initial(),
            errors.alignment.to_sim3(),
        )?;
    }
    if let Some(export) = &views.export {
        export.write(unit, estimate)?;
    }
    let key = unit.key();
    let title = format!(
        "nerf {}: {} cameras, Procrustes-aligned to the truth; rotation error {:.2}°",
        key.condition, key.method, errors.rot_err_deg
    );
    let drawn = plot::trajectory_comparison(
        unit.file("trajectory", "png"),
        &title,
        &views.train_times,
        Some(&views.train_truth),
        Some(("initial poses (aligned)", &init_aligned)),
        (&format!("{} (aligned)", key.method), &aligned),
    );
    if let Err(e) = drawn {
        unit.log(format_args!("no trajectory plot: {e}"));
    }

    let mut renderer = Renderer::default();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7e57);
    let refinement = Refinement {
        iterations: exp.eval.refine_iterations,
        rays: exp.eval.refine_rays,
        lr: exp.train.lr_pose[0],
    };
    let (near, far) = match views.settings.sampling {
        Sampling::Metric { near, far } => (near, far),
        Sampling::InverseDepth { near, .. } => (near, 10.0 * near),
    };
    let mut scores = Vec::with_capacity(views.tests.len());
    for test in &views.tests {
        let (mut psnr, mut ssim_sum, mut psnr_ref, mut ssim_ref) = (0.0, 0.0, 0.0, 0.0);
        for (k, (image, truth)) in test.images.iter().zip(&test.truth).enumerate() {
            let pose = errors.alignment.gt_to_learned(truth);
            let view = render_view(
                &mut renderer,
                field,
                &views.settings,
                &views.camera,
                &pose,
                4096,
            );
            psnr += crate::image::psnr(view.image.data(), image.data());
            ssim_sum += ssim(&view.image, image);
            if test.name.is_none() && k < exp.eval.saved_views {
                view.image
                    .beside(image)
                    .save_png(unit.file(&format!("view_{k}"), "png"))?;
                depth_image(
                    views.camera.width,
                    views.camera.height,
                    &view.depth,
                    &view.opacity,
                    near,
                    far,
                )
                .save_png(unit.file(&format!("depth_{k}"), "png"))?;
            }
            if refinement.iterations > 0 {
                let refined = eval::refine_pose(
                    &mut renderer,
                    field,
                    &views.settings,
                    &views.camera,
                    image,
                    &pose,
                    &refinement,
                    &mut rng,
                );
                let view = render_view(
                    &mut renderer,
                    field,
                    &views.settings,
                    &views.camera,
                    &refined,
                    4096,
                );
                psnr_ref += crate::image::psnr(view.image.data(), image.data());
                ssim_ref += ssim(&view.image, image);
            }
        }
        let n = test.images.len().max(1) as f64;
        let refined = refinement.iterations > 0;
        scores.push((
            test.name.clone(),
            [
                psnr / n,
                ssim_sum / n,
                if refined { psnr_ref / n } else { f64::NAN },
                if refined { ssim_ref / n } else { f64::NAN },
            ],
        ));
    }
    let [psnr, ssim_mean, psnr_ref, ssim_ref] = scores[0].1;
    let mut further_splits = BTreeMap::new();
    for (name, [psnr, ssim, psnr_ref, ssim_ref]) in &scores[1..] {
        let name = name.as_deref().unwrap_or("other");
        further_splits.insert(format!("psnr_{name}_db"), *psnr);
        further_splits.insert(format!("ssim_{name}"), *ssim);
        if refinement.iterations > 0 {
            further_splits.insert(format!("psnr_{name}_refined_db"), *psnr_ref);
            further_splits.insert(format!("ssim_{name}_refined"), *ssim_ref);
        }
    }
    let refined = refinement.iterations > 0;
    Ok(MethodResult {
        rot_err_deg: errors.rot_err_deg,
        rot_err_relative_deg: errors.rot_err_relative_deg,
        trans_err_su: errors.trans_err,
        rot_err_barf_fix_deg: barf_fix.as_ref().map(|e| e.rot_err_deg),
        trans_err_barf_fix_su: barf_fix.as_ref().map(|e| e.trans_err),
        init_rot_err_deg: init_errors.as_ref().map(|e| e.rot_err_deg),
        init_rot_err_relative_deg: init_errors.as_ref().map(|e| e.rot_err_relative_deg),
        init_trans_err_su: init_errors.as_ref().map(|e| e.trans_err),
        psnr_db: psnr,
        ssim: ssim_mean,
        psnr_refined_db: refined.then_some(psnr_ref),
        ssim_refined: refined.then_some(ssim_ref),
        further_splits,
        final_loss,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use std::ops::Range;

    use super::*;
    use train::tests::Tiny;

    /// `cpose config show nerf` states the defaults: its values are those of an empty config.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"nerf\"\n";
        cpose_core::testing::check_default_config("nerf", required, Settings::new);
    }

    /// A field whose parameters all turn NaN at the start of step `poison_at` (the trainer sets
    /// the progress once per step).
    struct NanFrom {
        inner: Box<dyn RadianceField>,
        poison_at: usize,
        steps: usize,
    }

    impl RadianceField for NanFrom {
        fn num_params(&self) -> usize {
            self.inner.num_params()
        }
        fn params(&self) -> &[f32] {
            self.inner.params()
        }
        fn params_mut(&mut self) -> &mut [f32] {
            self.inner.params_mut()
        }
        fn param_groups(&self) -> Vec<(&'static str, Range<usize>)> {
            self.inner.param_groups()
        }
        fn set_progress(&mut self, progress: f64) {
            if self.steps == self.poison_at {
                self.inner.params_mut().fill(f32::NAN);
            }
            self.steps += 1;
            self.inner.set_progress(progress);
        }
        fn forward(&mut self, points: &[f32], sigma: &mut [f32], rgb: &mut [f32]) {
            self.inner.forward(points, sigma, rgb);
        }
        fn backward(
            &mut self,
            grad_sigma: &[f32],
            grad_rgb: &[f32],
            grad: &mut [f32],
            grad_points: &mut [f32],
        ) {
            self.inner.backward(grad_sigma, grad_rgb, grad, grad_points);
        }
    }

    /// Runs 8 steps as one unit of a study in a temporary folder, checkpointing after every
    /// step when `checkpoints` (else never), the field turning NaN at step `poison_at`; returns
    /// the error message (the folder written as `DIR`) and the checkpoint's steps, if any.
    fn diverging_run(checkpoints: bool, poison_at: usize) -> (String, Option<u64>) {
        use cpose_core::run_dir::{RunDir, RunDirOptions};
        let dir =
            cpose_core::testing::TempDir::new(&format!("nerf-diverge-{checkpoints}-{poison_at}"));
        let secs = if checkpoints { 0.0 } else { 1e9 };
        let config = cpose_core::Config::from_text(
            "x.toml",
            format!("task = \"nerf\"\n[run]\ncheckpoint_secs = {secs}\n"),
        );
        let run = config.run_config().unwrap();
        let options = RunDirOptions {
            out: Some(dir.to_path_buf()),
            ..Default::default()
        };
        let run_dir = RunDir::create("nerf", &options).unwrap();
        let input = TaskInput {
            config: &config,
            run_dir: &run_dir,
            run: &run,
            show_progress: false,
            resume: false,
        };
        let losses = std::sync::atomic::AtomicU64::new(0);
        let err = Study::new(&input, vec![UnitKey::new("tiny", "barf", 0)])
            .run(|unit| {
                let mut tiny = Tiny::new();
                let inner = tiny.field;
                tiny.field = Box::new(NanFrom {
                    inner,
                    poison_at,
                    steps: 0,
                });
                let truth = tiny.poses.initial().to_vec();
                let mut trainer = tiny.trainer(8);
                let result = train_steps(&mut trainer, unit, Method::Barf, 8, &truth);
                let steps = unit.last_checkpoint().map_or(0, |(_, s)| s);
                losses.store(steps, std::sync::atomic::Ordering::Relaxed);
                result.map(|_| Metrics::new())
            })
            .unwrap_err();
        let message = format!("{err:#}").replace(&dir.display().to_string(), "DIR");
        let saved = std::fs::read(dir.join("units/tiny_barf/checkpoint.bin"))
            .ok()
            .map(|_| losses.load(std::sync::atomic::Ordering::Relaxed));
        (message, saved)
    }

    #[test]
    fn a_sideways_shift_moves_the_centre_out_of_view_and_a_turn_about_it_does_not() {
        // 100×100 at 40°: at 4 units the image spans ±1.46 across the view.
        let camera = PinholeCamera::from_fov_x(100, 100, 40f64.to_radians());
        let truth = [Isometry3::translation(0.0, 0.0, -4.0)];
        let moved = |delta: Isometry3<f64>| {
            centre_leaves_view(&camera, [0.0; 3], &truth, &[delta * truth[0]])
        };
        let turn = Isometry3::rotation(nalgebra::Vector3::y() * 60f64.to_radians());
        assert_eq!(moved(turn), 0);
        assert_eq!(moved(Isometry3::translation(1.2, 0.0, 0.0)), 0);
        assert_eq!(moved(Isometry3::translation(1.7, 0.0, 0.0)), 1);
        assert_eq!(moved(Isometry3::translation(0.0, -1.7, 0.0)), 1);
        // Behind the camera is out of view too.
        assert_eq!(moved(Isometry3::translation(0.0, 0.0, 5.0)), 1);
    }

    /// Issue "a NaN loss — one clear message, the last good checkpoint kept": the task's error
    /// names the method, the iteration and the checkpoint that is still good.
    #[test]
    fn a_nan_loss_ends_training_with_one_line_naming_the_last_good_checkpoint() {
        let (message, saved) = diverging_run(true, 5);
        assert_eq!(
            message,
            "unit tiny_barf: method barf: training stopped (last good checkpoint: \
             DIR/units/tiny_barf/checkpoint.bin, after 5 steps): the loss is NaN at iteration 5"
        );
        // The checkpoint of step 5, written before the field diverged, is kept.
        assert_eq!(saved, Some(5));
        let (message, saved) = diverging_run(false, 3);
        assert_eq!(
            message,
            "unit tiny_barf: method barf: training stopped (no checkpoint yet): the loss is NaN \
             at iteration 3"
        );
        assert_eq!(saved, None);
    }
}
