//! Task `planar`: the 2-D image-alignment study of the paper (§4.1.1, "Image alignment" table).
//!
//! A neural image is fitted to patches of one photograph, each patch seen through an unknown
//! warp, and the warps are recovered jointly. The warps follow a smooth motion in time
//! ([`motion`]); three pose models compete with everything else shared ([`model`]): PoseNet on
//! time, BARF's free per-patch parameters, and BARF with a B-spline reset every 100 steps. Each
//! runs on `trajectories` motions drawn from consecutive seeds; a run succeeds when its corner
//! error is below 1 px of the original image.
//!
//! Protocol, where the paper is silent (defaults of `configs/planar*.toml`):
//! - 10 random SE(2) poses (σ 3° and 0.08 normalised units ≈ 19 px) at times 0…9, a cubic spline
//!   through them per dimension, and **7 patches** at uniformly spaced times over 0…9 ("we
//!   interpolate on 7 uniformly spaced points"); warps relative to the first patch, which is the
//!   180×180 centre crop. All estimates start at the identity (the centre crop).
//! - BARF and the spline baseline use the paper's rates (1e-3 translation, 2e-4 rotation).
//!   PoseNet (8×256, F = 5) uses them divided by 10: at 1e-3, Adam moves every weight of the
//!   deep network at once and the tanh heads saturate within a few hundred steps.
//! - The neural image is a multi-resolution grid with a tiny MLP (coarse-to-fine over levels
//!   during the first 40% of training), trained on 4096 random patch pixels per step for 2000
//!   steps at half resolution; BARF's positional-encoding MLP is `[field] kind = "mlp"`.
//!
//! Coordinates are BARF's normalised image coordinates (the long side spans `[−1, 1]`), so the
//! study may run on a downscaled copy of the image (`[image] scale`) while corner errors are
//! reported in pixels of the original.
//!
//! Pictures of the first `[motion] render_trajectories` motions: `patches_<image>_s<k>.png` (the
//! true patches in time order) and `overlay_<image>_<method>[_s<k>].png` (the image with the
//! true and estimated patch outlines beside the neural image, with a title and a legend,
//! [`render::overlay`]).

pub mod model;
pub mod motion;
pub mod train;

use std::path::PathBuf;

use anyhow::Context;
use cpose_core::plot::SeriesStyle;
use cpose_core::registry::{Task, TaskInput};
use cpose_core::study::{Metrics, Study, UnitKey};
use cpose_core::{Config, PoseNetConfig, RunConfig, Section};
use serde::{Deserialize, Serialize};

use crate::field2d::{GridConfig, ImageField, PeMlpConfig};
use crate::image::{Image, procedural_texture};
use crate::warp2d::{Warp, WarpKind};
use model::{FieldModel, FreeModel, PoseModel, PoseRates, SplineReset};
use motion::{Motion, MotionSpec};
use train::{Layout, RunResult, Schedule, Trainer};

inventory::submit! {
    Task {
        name: "planar",
        about: "2-D image alignment (paper §4.1.1): PoseNet vs BARF vs B-spline on patches of one image",
        default_config: || [include_str!("../../defaults/planar.toml"), PoseNetConfig::DEFAULT_TABLE].join("\n"),
        check: |config, run| Settings::new(config, run).map(drop),
        run,
    }
}

/// The most patches per motion (the paper has 7; each is a view of the crop).
const MAX_PATCHES: usize = 1000;

/// The config file of the task.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Experiment {
    #[serde(default)]
    image: ImageConfig,
    #[serde(default)]
    motion: MotionConfig,
    #[serde(default)]
    train: TrainConfig,
    /// The neural image, `kind = "grid"` or `"mlp"`, decoded by kind ([`FieldChoice`]).
    #[serde(rename = "field", default)]
    _field: serde::de::IgnoredAny,
    /// PoseNet's settings, decoded as a [`PoseNetConfig`].
    #[serde(rename = "posenet", default)]
    _posenet: serde::de::IgnoredAny,
}

/// `[image]`: the photograph.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ImageConfig {
    /// A PNG or JPEG; none for the built-in procedural texture.
    path: Option<PathBuf>,
    /// Size of the procedural texture, pixels `[width, height]`.
    procedural_size: [usize; 2],
    /// Working resolution relative to the image (errors stay in original pixels).
    scale: f64,
    /// Side of the square centre crop every patch shows, pixels of the original image.
    crop_px: f64,
}

impl Default for ImageConfig {
    fn default() -> Self {
        Self {
            path: None,
            procedural_size: [480, 360],
            scale: 0.5,
            crop_px: 180.0,
        }
    }
}

/// `[motion]`: the ground-truth motions.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct MotionConfig {
    /// `"se2"` (the paper) or `"homography"` (BARF's protocol).
    warp: WarpKind,
    /// Patches per motion.
    patches: usize,
    /// Random SE(2) poses the ground-truth spline passes through.
    control_points: usize,
    /// σ of their rotation, degrees.
    rotation_deg: f64,
    /// σ of their translation (homography: the diagonal offset), normalised units.
    translation: f64,
    /// Homography: σ of every sl(3) parameter.
    homography_noise: f64,
    /// Motions (trajectories) per method; motion `k` is drawn from seed `run.seed · 1000 + k`.
    trajectories: usize,
    /// Motions whose renders are saved (the first ones).
    render_trajectories: usize,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            warp: WarpKind::Se2,
            patches: 7,
            control_points: 10,
            rotation_deg: 3.0,
            translation: 0.08,
            homography_noise: 0.1,
            trajectories: 20,
            render_trajectories: 1,
        }
    }
}

/// `[train]`: optimisation, shared by every method.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct TrainConfig {
    /// Methods to run: `posenet`, `barf`, `spline`.
    methods: Vec<Method>,
    /// Steps per run.
    iterations: usize,
    /// Pixels per step over all patches.
    pixels_per_step: usize,
    /// Learning rate of the neural image.
    lr_field: f64,
    /// Fraction of the steps during which the warps are held while the neural image fits the
    /// patches as they are (default 0: measured not to help here, `docs/results/planar.md`).
    pose_hold: f64,
    /// Learning rate of the free translations (BARF, spline; the paper's 1e-3).
    lr_translation: f64,
    /// Learning rate of the free rotations (BARF, spline; the paper's 2e-4).
    lr_rotation: f64,
    /// Learning rate of PoseNet's translation network.
    posenet_lr_translation: f64,
    /// Learning rate of PoseNet's rotation network.
    posenet_lr_rotation: f64,
    /// Learning rate of homography parameters.
    lr_homography: f64,
    /// B-spline baseline: control points.
    spline_control_points: usize,
    /// B-spline baseline: steps between resets.
    spline_reset_every: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            methods: vec![Method::Posenet, Method::Barf, Method::Spline],
            iterations: 2000,
            pixels_per_step: 4096,
            lr_field: 1e-3,
            pose_hold: 0.0,
            lr_translation: 1e-3,
            lr_rotation: 2e-4,
            posenet_lr_translation: 1e-4,
            posenet_lr_rotation: 2e-5,
            lr_homography: 1e-3,
            spline_control_points: 5,
            spline_reset_every: 100,
        }
    }
}

/// A pose model, named as in `metrics.json`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
enum Method {
    /// PoseNet on time.
    Posenet,
    /// Free per-patch parameters.
    Barf,
    /// Free parameters reset to a B-spline.
    Spline,
}

impl Method {
    fn key(self) -> &'static str {
        match self {
            Self::Posenet => "posenet",
            Self::Barf => "barf",
            Self::Spline => "spline",
        }
    }
}

/// The neural image chosen by `[field] kind`.
#[derive(Clone, Debug)]
enum FieldChoice {
    Grid(GridConfig),
    Mlp(PeMlpConfig),
}

impl FieldChoice {
    fn from_section(section: &Section<'_>) -> anyhow::Result<Self> {
        if !section.exists()? {
            return Ok(Self::Grid(GridConfig::default()));
        }
        let (kind, at) = section.kind()?;
        Ok(match kind.as_str() {
            "grid" => Self::Grid(section.decode_params()?),
            "mlp" => Self::Mlp(section.decode_params()?),
            other => {
                return Err(section
                    .config()
                    .error_at(
                        Some(at),
                        format!("unknown neural image kind {other:?}; known kinds: grid, mlp"),
                    )
                    .into());
            }
        })
    }

    fn init(&self, seed: u64) -> anyhow::Result<Box<dyn ImageField>> {
        Ok(match self {
            Self::Grid(c) => {
                let mut c = c.clone();
                c.seed = c.seed.wrapping_add(seed);
                Box::new(c.init::<f32>()?)
            }
            Self::Mlp(c) => {
                let mut c = c.clone();
                c.seed = c.seed.wrapping_add(seed);
                Box::new(c.init::<f32>()?)
            }
        })
    }

    fn name(&self) -> &'static str {
        match self {
            Self::Grid(_) => "grid",
            Self::Mlp(_) => "mlp",
        }
    }
}

/// Everything a run needs, validated.
struct Setup {
    image: Image,
    name: String,
    original_size: [usize; 2],
    layout: Layout,
    settings: Settings,
}

/// The config, decoded and checked without reading the image.
#[derive(Debug)]
struct Settings {
    exp: Experiment,
    spec: MotionSpec,
    field: FieldChoice,
    posenet: PoseNetConfig,
    schedule: Schedule,
    rates: PoseRates,
    posenet_rates: PoseRates,
    reset: SplineReset,
    methods: Vec<Method>,
    trajectories: usize,
    render_trajectories: usize,
}

impl Settings {
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let exp: Experiment = config.parse_params()?;
        let bad = |what: String| anyhow::anyhow!("{}: {what}", config.path().display());
        let [w, h] = exp.image.procedural_size;
        if exp.image.path.is_none() && !((8..=8192).contains(&w) && (8..=8192).contains(&h)) {
            return Err(bad(format!(
                "[image] procedural_size {w}×{h}: each side must lie in 8..=8192"
            )));
        }
        let scale = exp.image.scale;
        if !(scale > 0.0 && scale <= 1.0) {
            return Err(bad(format!("[image] scale must be in (0, 1], got {scale}")));
        }
        let m = &exp.motion;
        if !(2..=MAX_PATCHES).contains(&m.patches) {
            return Err(bad(format!(
                "[motion] patches must lie in 2..={MAX_PATCHES}, got {}",
                m.patches
            )));
        }
        if m.control_points < 4 {
            return Err(bad(format!(
                "[motion] control_points must be at least 4 (a cubic spline), got {}",
                m.control_points
            )));
        }
        if m.trajectories == 0 {
            return Err(bad("[motion] trajectories must be at least 1".into()));
        }
        for (key, v) in [
            ("rotation_deg", m.rotation_deg),
            ("translation", m.translation),
            ("homography_noise", m.homography_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(format!(
                    "[motion] {key} must be finite and ≥ 0, got {v}"
                )));
            }
        }
        let t = &exp.train;
        for (key, v) in [
            ("lr_field", t.lr_field),
            ("lr_translation", t.lr_translation),
            ("lr_rotation", t.lr_rotation),
            ("posenet_lr_translation", t.posenet_lr_translation),
            ("posenet_lr_rotation", t.posenet_lr_rotation),
            ("lr_homography", t.lr_homography),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(format!(
                    "[train] {key} must be finite and ≥ 0, got {v}"
                )));
            }
        }
        if t.pixels_per_step == 0 || t.methods.is_empty() {
            return Err(bad(
                "[train] pixels_per_step must be ≥ 1 and methods must name at least one method"
                    .into(),
            ));
        }
        if m.warp == WarpKind::Homography && t.methods.contains(&Method::Posenet) {
            return Err(bad(
                "[train] methods: posenet models rigid motions (warp = \"se2\"); with \
                 warp = \"homography\" use methods = [\"barf\", \"spline\"]"
                    .into(),
            ));
        }
        let posenet_section = config.section("posenet");
        let posenet: PoseNetConfig = if posenet_section.exists()? {
            posenet_section.decode()?
        } else {
            PoseNetConfig::default()
        };
        let spec = MotionSpec {
            warp: m.warp,
            patches: m.patches,
            control_points: m.control_points,
            rotation_std_rad: m.rotation_deg.to_radians(),
            translation_std: m.translation,
            homography_std: m.homography_noise,
        };
        let reset = SplineReset {
            control_points: t.spline_control_points,
            every: t.spline_reset_every,
        };
        if t.methods.contains(&Method::Spline) {
            FreeModel::new(
                m.warp,
                spec.patch_times(),
                spec.time_range(),
                PoseRates::ZERO,
                Some(reset),
            )
            .check()
            .map_err(|e| bad(format!("[train] {e}")))?;
        }
        if t.methods.contains(&Method::Posenet) {
            posenet
                .init::<f32>(spec.time_range())
                .map_err(|e| bad(format!("[posenet] {e}")))?;
        }
        let field = FieldChoice::from_section(&config.section("field"))?;
        field.init(0).map_err(|e| bad(format!("[field] {e}")))?;
        let iterations = run.iterations(t.iterations);
        if !(0.0..1.0).contains(&t.pose_hold) {
            return Err(bad(format!(
                "[train] pose_hold = {} must lie in [0, 1): a fraction of the {iterations} steps \
                 that leaves some to align the patches",
                t.pose_hold
            )));
        }
        let mut methods = t.methods.clone();
        methods.sort();
        methods.dedup();
        Ok(Self {
            spec,
            field,
            posenet,
            schedule: Schedule {
                iterations,
                pixels_per_step: t.pixels_per_step,
                lr_field: t.lr_field,
                pose_hold: (t.pose_hold * iterations as f64).round() as usize,
            },
            rates: PoseRates {
                translation: t.lr_translation,
                rotation: t.lr_rotation,
                homography: t.lr_homography,
            },
            posenet_rates: PoseRates {
                translation: t.posenet_lr_translation,
                rotation: t.posenet_lr_rotation,
                homography: 0.0,
            },
            reset,
            methods,
            trajectories: m.trajectories,
            render_trajectories: m.render_trajectories,
            exp,
        })
    }

    fn model(&self, method: Method, seed: u64) -> anyhow::Result<Box<dyn PoseModel>> {
        let times = self.spec.patch_times();
        let range = self.spec.time_range();
        Ok(match method {
            Method::Posenet => {
                let mut c = self.posenet.clone();
                c.seed = c.seed.wrapping_add(seed);
                Box::new(FieldModel::new(
                    Box::new(c.init::<f32>(range)?),
                    times,
                    self.posenet_rates,
                ))
            }
            Method::Barf => Box::new(FreeModel::new(
                self.spec.warp,
                times,
                range,
                self.rates,
                None,
            )),
            Method::Spline => Box::new(FreeModel::new(
                self.spec.warp,
                times,
                range,
                self.rates,
                Some(self.reset),
            )),
        })
    }
}

impl Setup {
    /// The checked settings with the image they name, read (or drawn) and cut into patches.
    fn new(config: &Config, run: &RunConfig) -> anyhow::Result<Self> {
        let settings = Settings::new(config, run)?;
        let exp = &settings.exp;
        let bad = |what: String| anyhow::anyhow!("{}: {what}", config.path().display());
        let (original, name) = match &exp.image.path {
            Some(path) => (
                Image::load(path)?,
                path.file_stem()
                    .map_or("image".into(), |s| s.to_string_lossy().into_owned()),
            ),
            None => {
                let [w, h] = exp.image.procedural_size;
                (procedural_texture(w, h, run.seed), "procedural".into())
            }
        };
        let scale = exp.image.scale;
        let (w0, h0) = (original.width(), original.height());
        let crop = exp.image.crop_px;
        let side = (crop * scale).round() as usize;
        if crop.is_nan() || crop <= 0.0 || crop > w0.min(h0) as f64 || side < 4 {
            return Err(bad(format!(
                "[image] crop_px = {crop} does not fit the {w0}×{h0} image at scale {scale} \
                 (the crop must lie inside the image and span at least 4 working pixels)"
            )));
        }
        let image = if scale < 1.0 {
            original.resized(scale)
        } else {
            original
        };
        let layout = Layout::centre_crop(exp.motion.warp, [w0, h0], crop, side);
        Ok(Self {
            image,
            name,
            original_size: [w0, h0],
            layout,
            settings,
        })
    }

    fn motion(&self, seed: u64, k: usize) -> anyhow::Result<Motion> {
        let [w, h] = [self.image.width() as f64, self.image.height() as f64];
        let long = w.max(h);
        self.settings
            .spec
            .sample(
                seed * 1000 + k as u64,
                &self.layout.corners,
                [w / long, h / long],
            )
            .map_err(|e| anyhow::anyhow!("motion {k}: {e}"))
    }
}

/// The metrics of one method over its motions (the seeds of the study): mean and median corner
/// error, mean PSNR, the fraction of motions aligned to within 1 px, and the summed wall time.
fn summarise(runs: &[&Metrics]) -> Metrics {
    let n = runs.len() as f64;
    let values = |key: &str| -> Vec<f64> {
        runs.iter()
            .map(|m| m.number(key).unwrap_or(f64::NAN))
            .collect()
    };
    let mut errs = values("corner_err_px");
    errs.sort_by(f64::total_cmp);
    Metrics::new()
        .with("corner_err_px", errs.iter().sum::<f64>() / n)
        .with("corner_err_median_px", median(&errs))
        .with("psnr_db", values("psnr_db").iter().sum::<f64>() / n)
        .with(
            "success_rate",
            errs.iter().filter(|&&e| e < 1.0).count() as f64 / n,
        )
        .with("wall_s", values("wall_s").iter().sum::<f64>())
        .with("trajectories", runs.len())
}

fn run(input: &TaskInput) -> anyhow::Result<()> {
    let study = Setup::new(input.config, input.run)?;
    let seed = input.run.seed;
    let motions = (0..study.settings.trajectories)
        .map(|k| study.motion(seed, k))
        .collect::<anyhow::Result<Vec<_>>>()?;
    input.run_dir.log(format_args!(
        "{}: {}×{} image, working {}×{}; {} patches of {}×{} working pixels, warp {:?}; \
         neural image {}; {} trajectories × {:?}; {} steps of {} pixels",
        study.name,
        study.original_size[0],
        study.original_size[1],
        study.image.width(),
        study.image.height(),
        study.settings.spec.patches,
        (study.layout.grid.len() as f64).sqrt(),
        (study.layout.grid.len() as f64).sqrt(),
        study.settings.spec.warp,
        study.settings.field.name(),
        study.settings.trajectories,
        study
            .settings
            .methods
            .iter()
            .map(|m| m.key())
            .collect::<Vec<_>>(),
        study.settings.schedule.iterations,
        study.settings.schedule.pixels_per_step,
    ));
    for k in 0..study
        .settings
        .render_trajectories
        .min(study.settings.trajectories)
    {
        let patches = train::sample_patches(&study.image, &study.layout, &motions[k].params);
        render::patch_strip(&patches, &study.layout).save_png(
            input
                .run_dir
                .file(format!("patches_{}_s{k}.png", study.name)),
        )?;
    }
    // One unit per method and motion; the motion's index is the unit's seed.
    let mut units = Vec::new();
    for k in 0..study.settings.trajectories {
        for m in &study.settings.methods {
            units.push(UnitKey::new(study.name.as_str(), m.key(), k as u64));
        }
    }
    Study::new(input, units)
        .parallel(true)
        .report_every(200)
        .columns(&[
            "corner_err_px",
            "corner_err_median_px",
            "psnr_db",
            "success_rate",
        ])
        .summarise(summarise)
        .run(|unit| {
            let k = unit.key().seed as usize;
            let method = *study
                .settings
                .methods
                .iter()
                .find(|m| m.key() == unit.key().method)
                .context("a method of the config")?;
            let motion = &motions[k];
            let patches = train::sample_patches(&study.image, &study.layout, &motion.params);
            // The same neural-image initialisation and pixel draws for every method.
            let job_seed = seed.wrapping_mul(1000).wrapping_add(k as u64);
            let mut field = study.settings.field.init(job_seed)?;
            let mut model = study.settings.model(method, job_seed)?;
            unit.set_steps(study.settings.schedule.iterations);
            let (outcome, wall_s) = train::timed(|| {
                Trainer::new(
                    field.as_mut(),
                    model.as_mut(),
                    &study.layout,
                    &patches,
                    study.settings.schedule,
                    job_seed,
                )
                .run(&mut |done, loss, params| {
                    if unit.report_due(done) {
                        let dim = study.settings.spec.warp.dim();
                        let warps: Vec<Vec<f64>> =
                            params.chunks(dim).map(<[f64]>::to_vec).collect();
                        let warps = train::relative_to_first(study.settings.spec.warp, &warps);
                        let corner = train::corner_error_px(&study.layout, &warps, &motion.params);
                        unit.report(done, &[("loss", loss), ("corner_err_px", corner)]);
                    }
                    Ok(())
                })
            });
            let (final_loss, warps) = outcome?;
            let first = Warp::new(study.settings.spec.warp, &warps[0]);
            let rendered = train::render(
                field.as_mut(),
                study.image.width(),
                study.image.height(),
                &first,
            );
            let warps = train::relative_to_first(study.settings.spec.warp, &warps);
            let corner_err_px = train::corner_error_px(&study.layout, &warps, &motion.params);
            let psnr_db =
                train::region_psnr(&rendered, &study.image, &study.layout, &motion.params);
            if k < study.settings.render_trajectories {
                let title = format!(
                    "planar {}, motion {k}: {}; corner error {corner_err_px:.2} px, \
                     PSNR {psnr_db:.1} dB",
                    study.name,
                    method.key()
                );
                let estimate = render::Estimate {
                    label: &format!("estimated patch outlines ({})", method.key()),
                    style: SeriesStyle::Estimate(method as usize),
                    warps: &warps,
                };
                let drawn = render::overlay(
                    unit.file("overlay", "png"),
                    &title,
                    (&study.image, study.original_size),
                    &rendered,
                    &study.layout,
                    &motion.params,
                    estimate,
                );
                if let Err(e) = drawn {
                    unit.log(format_args!("no overlay: {e}"));
                }
            }
            Metrics::from_serialize(&RunResult {
                corner_err_px,
                psnr_db,
                final_loss,
                wall_s,
                warps,
            })
        })?;
    Ok(())
}

fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}

pub mod render {
    //! PNG renders of the study: true and estimated patch outlines, the neural image, patches.

    use std::path::Path;

    use cpose_core::plot::{self, ImagePanel, Outline, PlotError, SeriesStyle};

    use super::train::Layout;
    use crate::image::Image;
    use crate::warp2d::Warp;

    /// The estimated warps of one method, as [`overlay`] draws them.
    #[derive(Clone, Copy, Debug)]
    pub struct Estimate<'a> {
        /// Legend text, e.g. `"estimated patch outlines (posenet)"`.
        pub label: &'a str,
        /// The method's colour.
        pub style: SeriesStyle,
        /// Warp parameters per patch, relative to the first patch.
        pub warps: &'a [Vec<f64>],
    }

    /// Draws a PNG at `path` ([`plot::image_panels`]): on the left the image (shown at its
    /// working resolution, axes in pixels of the original of size `original_size`) with every
    /// patch's true outline (black, wide) and estimated one (the method's colour) over it; on
    /// the right `rendered`, the neural image rendered in the image frame; `title` above and a
    /// legend naming the outlines.
    pub fn overlay(
        path: impl AsRef<Path>,
        title: &str,
        (image, original_size): (&Image, [usize; 2]),
        rendered: &Image,
        layout: &Layout,
        truth: &[Vec<f64>],
        estimate: Estimate,
    ) -> Result<(), PlotError> {
        let [w, h] = original_size.map(|s| s as f64);
        let long = w.max(h);
        // Normalised coordinates (the long side spans [−1, 1]) to pixels of the original.
        let to_px = |p: [f64; 2]| ((p[0] * long + w) / 2.0, (p[1] * long + h) / 2.0);
        let outlines_of = |params: &[Vec<f64>]| -> Vec<Vec<(f64, f64)>> {
            params
                .iter()
                .map(|p| {
                    let warp = Warp::new(layout.warp, p);
                    layout
                        .corners
                        .iter()
                        .map(|&c| to_px(warp.apply(c)))
                        .collect()
                })
                .collect()
        };
        let outlines = [
            Outline {
                label: "true patch outlines".into(),
                style: SeriesStyle::Truth,
                polygons: outlines_of(truth),
            },
            Outline {
                label: estimate.label.to_owned(),
                style: estimate.style,
                polygons: outlines_of(estimate.warps),
            },
        ];
        let panels = [
            ("image with the patch outlines", image, &outlines[..]),
            ("neural image, rendered in the image frame", rendered, &[]),
        ]
        .map(|(title, picture, outlines)| ImagePanel {
            title,
            size: (picture.width(), picture.height()),
            rgb: picture.data(),
            extent: (w, h),
            outlines,
        });
        plot::image_panels(path, title, &panels)
    }

    /// The ground-truth patches in a row, in time order, 2 pixels apart.
    pub fn patch_strip(patches: &[Vec<[f32; 3]>], layout: &Layout) -> Image {
        let side = (layout.grid.len() as f64).sqrt().round() as usize;
        let gap = 2;
        let n = patches.len();
        Image::from_fn(n * side + (n - 1) * gap, side, |x, y| {
            let (i, u) = (x / (side + gap), x % (side + gap));
            if u >= side {
                [1.0; 3]
            } else {
                patches[i][y * side + u]
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpose config show planar` states the defaults: its values are those of an empty config.
    #[test]
    fn the_default_config_holds_the_defaults() {
        let required = "task = \"planar\"\n";
        cpose_core::testing::check_default_config("planar", required, Settings::new);
    }
}
