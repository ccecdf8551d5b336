//! The views of task `nerf`: training images with their true poses and times, held-out views
//! to score novel-view synthesis on, and how to render the scene, from the built-in synthetic
//! scene or a dataset (`[data]`, `[render]`).

use std::path::PathBuf;

use anyhow::bail;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::camera::PinholeCamera;
use crate::data::colmap_scene::{ColmapScene, load_colmap_scene};
use crate::data::nerfstudio::{NerfstudioScene, load_nerfstudio};
use crate::data::{Dataset, blender, llff};
use crate::field3d::SceneBounds;
use crate::image::Image;
use crate::render::{Clip, LastInterval, RenderSettings, Sampling};
use crate::scene::{MonocularOrbit, SyntheticScene};

/// Where the images come from.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(super) enum Source {
    /// The built-in scene along the monocular orbit.
    #[default]
    Synthetic,
    /// An LLFF forward-facing scene.
    Llff,
    /// A NeRF-synthetic (Blender) scene.
    Blender,
    /// A COLMAP reconstruction of forward-facing photos (`images/`, `sparse/0/`), LLFF's
    /// setting for a user's own capture; the refined poses are written back as COLMAP models.
    Colmap,
    /// nerfstudio's `transforms.json` of photos taken around an object (Blender's setting with
    /// a real background); the refined poses are written back as `transforms.json` files.
    Nerfstudio,
}

impl Source {
    fn name(self) -> &'static str {
        match self {
            Source::Synthetic => "synthetic",
            Source::Llff => "LLFF",
            Source::Blender => "Blender",
            Source::Colmap => "COLMAP",
            Source::Nerfstudio => "nerfstudio",
        }
    }
}

/// `[data]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(super) struct DataConfig {
    pub(super) source: Source,
    /// Scene folder (llff, blender, colmap).
    path: Option<PathBuf>,
    /// Downscale factor: LLFF reads `images_N` (default 8), COLMAP `images_N` if there is one
    /// (default 1), else both average `images` down, as Blender does (default 1).
    factor: Option<u32>,
    /// Keep every k-th training frame (a faster camera); in a sequence, the frames between are
    /// held out.
    subsample: usize,
    /// Blender: the split trained on, `transforms_<split>.json` (default `"train"`).
    split: String,
    /// Blender: the split's frames are one recording in time, ordered by the number their file
    /// names end in (`r_<k>.png`: `t = k`); the views between training frames are held out.
    sequence: bool,
    /// Blender: a split of novel views to score as well (`"val"`, `"test"`), `eval_views` of
    /// them evenly spaced; without a sequence these are the held-out views.
    eval_split: Option<String>,
    eval_views: usize,
    /// Blender: at most this many frames.
    max_frames: Option<usize>,
    /// Synthetic: image size and horizontal field of view.
    width: usize,
    height: usize,
    fov_x_deg: f64,
    /// Synthetic: sub-pixel rays per side.
    supersample: usize,
    /// Synthetic and Blender: held-out views (in a sequence, evenly spread over the views
    /// between training frames).
    test_views: usize,
}

impl Default for DataConfig {
    fn default() -> Self {
        Self {
            source: Source::Synthetic,
            path: None,
            factor: None,
            subsample: 1,
            split: "train".to_owned(),
            sequence: false,
            eval_split: None,
            eval_views: 10,
            max_frames: None,
            width: 100,
            height: 100,
            fov_x_deg: 40.0,
            supersample: 2,
            test_views: 10,
        }
    }
}

/// `[render]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(super) struct RenderConfig {
    samples: usize,
    /// Depth range; synthetic default `[2, 6]` (orbit radius 4), LLFF `[1, inf]` in disparity.
    near: Option<f64>,
    far: Option<f64>,
    /// `"metric"` or `"inverse"` (LLFF default).
    sampling: Option<String>,
    /// Background colour (white for object scenes; none for LLFF).
    background: Option<[f32; 3]>,
    /// Bounded scenes: sample only the chord through the bounding sphere, empty outside.
    clip: bool,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            samples: 64,
            near: None,
            far: None,
            sampling: None,
            background: None,
            clip: true,
        }
    }
}

/// Views to score novel-view synthesis on.
pub(super) struct TestViews {
    /// What the set is called in metric keys: `None` for the held-out views (`psnr_db`), the
    /// split's name for a further split (`psnr_val_db`).
    pub(super) name: Option<String>,
    pub(super) images: Vec<Image>,
    pub(super) truth: Vec<Isometry3<f64>>,
}

/// Training and test views with their true poses, and how to render the scene.
pub(super) struct Views {
    /// What the data is called in `metrics.json`.
    pub(super) condition: String,
    pub(super) camera: PinholeCamera,
    pub(super) train_images: Vec<Image>,
    pub(super) train_times: Vec<f64>,
    pub(super) train_truth: Vec<Isometry3<f64>>,
    /// The held-out views first, then any further split.
    pub(super) tests: Vec<TestViews>,
    pub(super) settings: RenderSettings,
    pub(super) bounds: SceneBounds,
    /// Size of the camera path (the orbit diameter; the spread of LLFF cameras), for noise.
    pub(super) diameter: f64,
    /// A user's capture (COLMAP, nerfstudio): how to write the refined training poses back.
    pub(super) export: Option<PoseExport>,
    /// What loading found worth a line in the log.
    pub(super) notes: Vec<String>,
}

/// A user's capture and the normalisation from its world frame to the training frame, to write
/// refined poses back in the capture's own format, frame and units.
pub(super) struct PoseExport {
    pub(super) capture: Capture,
    pub(super) normalisation: Normalisation,
    /// The dataset index of each training view.
    pub(super) train_indices: Vec<usize>,
}

/// The file formats poses are written back in.
pub(super) enum Capture {
    Colmap(ColmapScene),
    Nerfstudio(NerfstudioScene),
}

impl PoseExport {
    /// Writes `estimate` (one pose per training view, training frame) beside the unit's other
    /// files: `colmap_<condition>_<method>/` or `transforms_<condition>_<method>.json`, replacing
    /// what an interrupted attempt left there.
    pub(super) fn write(
        &self,
        unit: &cpose_core::study::Unit,
        estimate: &[Isometry3<f64>],
    ) -> anyhow::Result<()> {
        let poses: Vec<_> = estimate
            .iter()
            .map(|p| self.normalisation.undo(p))
            .collect();
        match &self.capture {
            Capture::Colmap(scene) => {
                scene.write_refined(&unit.folder("colmap"), &self.train_indices, &poses, true)?
            }
            Capture::Nerfstudio(scene) => scene.write_refined(
                &unit.file("transforms", "json"),
                &self.train_indices,
                &poses,
            )?,
        }
        Ok(())
    }
}

/// A capture's change of frame: translations scaled by `scale`, then every pose expressed
/// relative to `mean`: `normalised = mean⁻¹ ∘ scaled(pose)`.
pub(super) struct Normalisation {
    scale: f64,
    mean: Isometry3<f64>,
}

impl Normalisation {
    fn apply(&self, pose: &Isometry3<f64>) -> Isometry3<f64> {
        let mut scaled = *pose;
        scaled.translation.vector *= self.scale;
        self.mean.inverse() * scaled
    }

    /// The pose in the capture's frame of a pose in the normalised one.
    fn undo(&self, pose: &Isometry3<f64>) -> Isometry3<f64> {
        let mut scaled = self.mean * pose;
        scaled.translation.vector /= self.scale;
        scaled
    }
}

impl Views {
    /// The views `[data]` names, rendered with `[render]`; `orbit` moves the built-in scene's
    /// camera.
    pub(super) fn load(
        data: &DataConfig,
        orbit: &MonocularOrbit,
        render: &RenderConfig,
    ) -> anyhow::Result<Self> {
        let views = match data.source {
            Source::Synthetic => synthetic_views(data, orbit, render),
            Source::Llff | Source::Blender | Source::Colmap | Source::Nerfstudio => {
                dataset_views(data, render)
            }
        }?;
        let (w, h) = (views.camera.width, views.camera.height);
        let least = crate::metrics::SSIM_WINDOW;
        if w < least || h < least {
            bail!(
                "[data]: the views are {w}×{h} pixels; the novel-view scores need at least \
                 {least}×{least} (SSIM's window): lower data.factor or raise the size"
            );
        }
        Ok(views)
    }
}

fn resolve_settings(
    render: &RenderConfig,
    default: (Sampling, Option<[f32; 3]>),
    bounds: &SceneBounds,
) -> anyhow::Result<RenderSettings> {
    let (default_sampling, default_bg) = default;
    let (dn, df) = match default_sampling {
        Sampling::Metric { near, far } | Sampling::InverseDepth { near, far } => (near, far),
    };
    let (near, far) = (render.near.unwrap_or(dn), render.far.unwrap_or(df));
    if !(near > 0.0 && far > near) {
        bail!("[render]: need 0 < near < far, got near = {near}, far = {far}");
    }
    let sampling = match render.sampling.as_deref() {
        None => match default_sampling {
            Sampling::Metric { .. } => Sampling::Metric { near, far },
            Sampling::InverseDepth { .. } => Sampling::InverseDepth { near, far },
        },
        Some("metric") if far.is_finite() => Sampling::Metric { near, far },
        Some("inverse") => Sampling::InverseDepth { near, far },
        Some(other) => bail!(
            "[render] sampling: expected \"metric\" (finite far) or \"inverse\", got {other:?}"
        ),
    };
    if render.samples == 0 {
        bail!("[render] samples: expected at least 1");
    }
    Ok(RenderSettings {
        last_interval: LastInterval::Closed,
        samples: render.samples,
        sampling,
        background: render.background.or(default_bg),
        clip: (render.clip && !bounds.unbounded).then_some(Clip {
            centre: bounds.centre,
            radius: bounds.radius,
        }),
    })
}

fn subsample<T: Clone>(items: &[T], every: usize) -> Vec<T> {
    items.iter().step_by(every.max(1)).cloned().collect()
}

/// The most pixels the synthetic scene renders over all views (a hundred million, 1.2 GB of
/// colour): 100 views of 1000 × 1000.
const MAX_SYNTHETIC_PIXELS: usize = 100_000_000;

fn synthetic_views(
    d: &DataConfig,
    orbit: &MonocularOrbit,
    render_config: &RenderConfig,
) -> anyhow::Result<Views> {
    if d.width == 0 || d.height == 0 || !(d.fov_x_deg > 0.0 && d.fov_x_deg < 180.0) {
        bail!("[data]: need width, height ≥ 1 and 0 < fov_x_deg < 180");
    }
    orbit.validate()?;
    let camera = PinholeCamera::from_fov_x(d.width, d.height, d.fov_x_deg.to_radians());
    let scene = SyntheticScene::object_centric();
    let times = orbit.frame_times();
    let frames = subsample(&times, d.subsample);
    // Sizes are checked before anything is rendered: every view is kept in memory.
    let pixels = (frames.len() + d.test_views) as f64 * d.width as f64 * d.height as f64;
    if pixels > MAX_SYNTHETIC_PIXELS as f64 {
        bail!(
            "[data]: {} views of width × height = {} × {} are {pixels:.3e} pixels; at most \
             {MAX_SYNTHETIC_PIXELS} are rendered (lower width and height, orbit.frames or \
             data.test_views)",
            frames.len() + d.test_views,
            d.width,
            d.height
        );
    }
    let render = |t: &f64| {
        let pose = orbit.world_from_camera(*t);
        (
            scene.render(&camera, &pose, d.supersample.max(1)).image,
            pose,
        )
    };
    let (train_images, train_truth): (Vec<_>, Vec<_>) = frames.iter().map(render).unzip();
    // Held-out views half-way between training frames of the full sequence.
    let n = times.len();
    let test_times: Vec<f64> = (0..d.test_views)
        .map(|k| times[((2 * k + 1) * (n - 1)) / (2 * d.test_views.max(1))] + 0.5)
        .collect();
    let (test_images, test_truth) = test_times.iter().map(render).unzip();
    let bounds = SceneBounds {
        centre: [0.0; 3],
        radius: scene.bounding_radius(),
        unbounded: false,
    };
    let settings = resolve_settings(
        render_config,
        (
            Sampling::Metric {
                near: 2.0,
                far: 6.0,
            },
            Some([1.0; 3]),
        ),
        &bounds,
    )?;
    Ok(Views {
        condition: "synthetic".to_owned(),
        camera,
        train_images,
        train_times: frames,
        train_truth,
        tests: vec![TestViews {
            name: None,
            images: test_images,
            truth: test_truth,
        }],
        settings,
        bounds,
        diameter: orbit.diameter(),
        export: None,
        notes: Vec::new(),
    })
}

/// BARF's LLFF normalisation, applied to the dataset's poses: scale so that the smallest near
/// bound becomes `1/0.75`, then express every pose relative to the mean camera (mean centre;
/// rotation from the mean viewing and up axes, orthonormalised).
fn normalise_forward_facing(dataset: &mut Dataset) -> anyhow::Result<Normalisation> {
    let Some(bounds) = &dataset.bounds else {
        bail!("forward-facing data without depth bounds");
    };
    let near = bounds.iter().map(|b| b[0]).fold(f64::INFINITY, f64::min);
    if !(near > 0.0 && near.is_finite()) {
        bail!("the near depth bounds must be positive, got {near}");
    }
    let scale = 1.0 / (0.75 * near);
    let n = dataset.len() as f64;
    let mut centre = Vector3::zeros();
    let (mut z, mut y) = (Vector3::zeros(), Vector3::zeros());
    for p in &dataset.world_from_camera {
        centre += scale * p.translation.vector / n;
        z += p.rotation * Vector3::z();
        y += p.rotation * Vector3::y();
    }
    let z = z.normalize();
    let x = y.cross(&z).normalize();
    let y = z.cross(&x);
    let normalisation = Normalisation {
        scale,
        mean: Isometry3::from_parts(
            Translation3::from(centre),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                Matrix3::from_columns(&[x, y, z]),
            )),
        ),
    };
    for p in &mut dataset.world_from_camera {
        *p = normalisation.apply(p);
    }
    Ok(normalisation)
}

/// `", undistorted (pixels moved by up to 3.72)"` for the log, or nothing for a pinhole camera.
fn undistorted(max_shift_px: f64) -> String {
    if max_shift_px > 0.0 {
        format!(", undistorted (pixels moved by up to {max_shift_px:.2})")
    } else {
        String::new()
    }
}

/// The distance of the cameras from the object after [`normalise_object_centric`], Blender's
/// orbit radius.
const OBJECT_CAMERA_DISTANCE: f64 = 4.0;

/// A capture around an object, as Blender's: centred on the mean camera centre (about the
/// object when the cameras surround it), scaled so that the cameras' mean distance from it is
/// [`OBJECT_CAMERA_DISTANCE`]; orientations unchanged.
fn normalise_object_centric(dataset: &mut Dataset) -> anyhow::Result<Normalisation> {
    let n = dataset.len() as f64;
    let centre: Vector3<f64> = dataset
        .world_from_camera
        .iter()
        .map(|p| p.translation.vector)
        .sum::<Vector3<f64>>()
        / n;
    let spread = dataset
        .world_from_camera
        .iter()
        .map(|p| (p.translation.vector - centre).norm())
        .sum::<f64>()
        / n;
    if !(spread > 0.0 && spread.is_finite()) {
        bail!("the cameras of a capture around an object must not share one centre");
    }
    let scale = OBJECT_CAMERA_DISTANCE / spread;
    let normalisation = Normalisation {
        scale,
        mean: Isometry3::translation(scale * centre.x, scale * centre.y, scale * centre.z),
    };
    for p in &mut dataset.world_from_camera {
        *p = normalisation.apply(p);
    }
    Ok(normalisation)
}

/// `count` indices of `0..n` evenly spread (the middle of each of `count` equal parts).
fn evenly_spaced(n: usize, count: usize) -> Vec<usize> {
    let count = count.min(n);
    (0..count).map(|k| (2 * k + 1) * n / (2 * count)).collect()
}

fn blender_options(d: &DataConfig, split: &str, sequence: bool) -> blender::BlenderOptions {
    blender::BlenderOptions {
        split: split.to_owned(),
        max_frames: d.max_frames,
        // A sequence must have every frame; an excerpt of a split may ship only some images.
        only_existing_images: !sequence,
        ..Default::default()
    }
}

/// The dataset downscaled by `factor` (images averaged down, the camera scaled); a factor
/// larger than the images' sides is an error.
fn downscaled(mut dataset: Dataset, factor: u32) -> anyhow::Result<Dataset> {
    let (w, h) = (dataset.camera.width, dataset.camera.height);
    if factor as usize > w.min(h) {
        bail!(
            "[data] factor = {factor}: expected at most {}, the side of the {w}×{h} images",
            w.min(h)
        );
    }
    if factor > 1 {
        let scale = 1.0 / f64::from(factor);
        dataset.images = dataset.images.iter().map(|i| i.resized(scale)).collect();
        dataset.camera = dataset.camera.scaled(scale);
    }
    Ok(dataset)
}

fn dataset_views(d: &DataConfig, render_config: &RenderConfig) -> anyhow::Result<Views> {
    let Some(path) = &d.path else {
        bail!(
            "[data] path: the {} scene folder is required for source = \"{}\"",
            d.source.name(),
            d.source.name().to_lowercase()
        );
    };
    if !path.exists() {
        let origin = match d.source {
            Source::Llff => {
                "LLFF's forward-facing scenes (poses_bounds.npy, images_N/) come from the NeRF \
                 authors' nerf_llff_data release; fern ships in ../shared/data/llff/fern"
            }
            Source::Blender => {
                "NeRF-synthetic scenes (transforms_<split>.json and their PNGs) come from the NeRF \
                 authors' nerf_synthetic release; lego ships in ../shared/data/nerf_synthetic/lego"
            }
            Source::Colmap => {
                "a COLMAP capture is the folder COLMAP reconstructs into: the photos in images/, \
                 the sparse model in sparse/0/ (colmap automatic_reconstructor --workspace_path \
                 DIR --image_path DIR/images)"
            }
            _ => {
                "nerfstudio's transforms.json is what ns-process-data images|video writes for \
                 your photos or video"
            }
        };
        bail!(
            "[data] path: no {} scene at {}: {origin}. Set data.path to it",
            d.source.name(),
            path.display()
        );
    }
    let forward_facing = matches!(d.source, Source::Llff | Source::Colmap);
    if forward_facing && (d.sequence || d.eval_split.is_some() || d.split != "train") {
        bail!(
            "[data] split, sequence and eval_split are for Blender scenes; {} images are one \
             sequence in file-name order already",
            d.source.name()
        );
    }
    if d.subsample == 0 {
        bail!("[data] subsample = 0: expected at least 1");
    }
    if d.factor == Some(0) {
        bail!("[data] factor = 0: expected at least 1");
    }
    let forward = (
        Sampling::InverseDepth {
            near: 1.0,
            far: f64::INFINITY,
        },
        None,
    );
    let mut notes = Vec::new();
    let mut capture = None;
    let (mut dataset, settings_default, unbounded) = match d.source {
        Source::Llff => (llff::load_llff(path, d.factor.unwrap_or(8))?, forward, true),
        Source::Colmap => {
            let (dataset, colmap) = load_colmap_scene(path, d.factor.unwrap_or(1))?;
            notes.push(format!(
                "COLMAP model {}: {} registered images of camera {}{}{}",
                colmap.model_dir.display(),
                dataset.len(),
                colmap.camera.model.name(),
                undistorted(colmap.max_distortion_px),
                if colmap.unregistered.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; {} image files not registered, skipped (e.g. {})",
                        colmap.unregistered.len(),
                        colmap.unregistered[0]
                    )
                },
            ));
            capture = Some(Capture::Colmap(colmap));
            (dataset, forward, true)
        }
        Source::Nerfstudio => {
            let (dataset, scene) = load_nerfstudio(path, d.factor.unwrap_or(1))?;
            notes.push(format!(
                "nerfstudio {}: {} frames{}",
                scene.json_path.display(),
                dataset.len(),
                undistorted(scene.max_distortion_px)
            ));
            capture = Some(Capture::Nerfstudio(scene));
            // Around the object, the background beyond: samples uniform in disparity from the
            // nearest object depth (cameras at distance 4, object radius about 1.5).
            let around = (
                Sampling::InverseDepth {
                    near: 2.0,
                    far: f64::INFINITY,
                },
                None,
            );
            (dataset, around, true)
        }
        _ => (
            downscaled(
                blender::load_blender(path, &blender_options(d, &d.split, d.sequence))?,
                d.factor.unwrap_or(1),
            )?,
            (
                Sampling::Metric {
                    near: 2.0,
                    far: 6.0,
                },
                Some([1.0; 3]),
            ),
            false,
        ),
    };
    if dataset.len() < 3 {
        bail!(
            "{}: need at least 3 images, found {}",
            path.display(),
            dataset.len()
        );
    }
    let normalisation = if forward_facing {
        Some(normalise_forward_facing(&mut dataset)?)
    } else if d.source == Source::Nerfstudio {
        Some(normalise_object_centric(&mut dataset)?)
    } else {
        None
    };
    let n = dataset.len();
    let split_views = |name: &str, count: usize| -> anyhow::Result<TestViews> {
        let other = downscaled(
            blender::load_blender(path, &blender_options(d, name, false))?,
            d.factor.unwrap_or(1),
        )?;
        let picked = evenly_spaced(other.len(), count);
        Ok(TestViews {
            name: Some(name.to_owned()),
            images: picked.iter().map(|&i| other.images[i].clone()).collect(),
            truth: picked.iter().map(|&i| other.world_from_camera[i]).collect(),
        })
    };
    // Frame times, the frames trained on, and the held-out views.
    let (times, keep, tests): (Vec<f64>, Vec<usize>, Vec<TestViews>) = if d.sequence {
        let json = path.join(format!("transforms_{}.json", d.split));
        let numbers = blender::sequence_numbers(&dataset.names, &json)?;
        let keep: Vec<usize> = (0..n).step_by(d.subsample).collect();
        let between: Vec<usize> = (0..n).filter(|i| i % d.subsample != 0).collect();
        if between.is_empty() && d.eval_split.is_none() {
            bail!(
                "[data] sequence with subsample = 1 holds no views out between the training \
                 frames; set subsample = 2 (every other view trained on) or an eval_split"
            );
        }
        let held: Vec<usize> = evenly_spaced(between.len(), d.test_views)
            .into_iter()
            .map(|k| between[k])
            .collect();
        let mut tests = Vec::new();
        if !held.is_empty() {
            tests.push(TestViews {
                name: None,
                images: held.iter().map(|&i| dataset.images[i].clone()).collect(),
                truth: held.iter().map(|&i| dataset.world_from_camera[i]).collect(),
            });
        }
        if let Some(name) = &d.eval_split {
            let mut split = split_views(name, d.eval_views)?;
            if tests.is_empty() {
                split.name = None;
            }
            tests.push(split);
        }
        (numbers.iter().map(|&k| k as f64).collect(), keep, tests)
    } else if let Some(name) = &d.eval_split {
        let mut test = split_views(name, d.eval_views)?;
        test.name = None;
        let keep = (0..n).step_by(d.subsample).collect();
        ((0..n).map(|i| i as f64).collect(), keep, vec![test])
    } else {
        // BARF: the last 10% (at least one) held out.
        let held_out = if forward_facing || d.source == Source::Nerfstudio {
            (n / 10).max(1)
        } else {
            d.test_views.min(n / 5).max(1)
        };
        let split = n - held_out;
        let test = TestViews {
            name: None,
            images: dataset.images[split..].to_vec(),
            truth: dataset.world_from_camera[split..].to_vec(),
        };
        let keep = (0..split).step_by(d.subsample).collect();
        ((0..n).map(|i| i as f64).collect(), keep, vec![test])
    };
    if tests.iter().any(|t| t.images.is_empty()) {
        bail!("[data]: no views are held out to score novel views on (test_views, eval_views)");
    }
    let centres: Vec<Vector3<f64>> = dataset
        .world_from_camera
        .iter()
        .map(|p| p.translation.vector)
        .collect();
    let mean = centres.iter().sum::<Vector3<f64>>() / n as f64;
    let spread = centres
        .iter()
        .map(|c| (c - mean).norm())
        .fold(0.0, f64::max);
    let bounds = if d.source == Source::Nerfstudio {
        // Around the object at the origin; the background contracted beyond.
        SceneBounds {
            centre: [0.0; 3],
            radius: 2.0,
            unbounded: true,
        }
    } else if unbounded {
        SceneBounds {
            centre: [0.0, 0.0, 2.0],
            radius: 2.0,
            unbounded: true,
        }
    } else {
        SceneBounds {
            centre: [0.0; 3],
            radius: 1.5,
            unbounded: false,
        }
    };
    // A scene folder's name (the folder of a file such as a transforms.json).
    let folder = if path.is_file() {
        path.parent().unwrap_or(path)
    } else {
        path
    };
    let condition = format!(
        "{}{}",
        folder
            .file_name()
            .map_or("scene".into(), |s| s.to_string_lossy()),
        if d.subsample > 1 {
            format!("/{}", d.subsample)
        } else {
            String::new()
        }
    );
    let export = capture
        .zip(normalisation)
        .map(|(capture, normalisation)| PoseExport {
            capture,
            normalisation,
            train_indices: keep.clone(),
        });
    Ok(Views {
        condition,
        camera: dataset.camera,
        train_images: keep.iter().map(|&i| dataset.images[i].clone()).collect(),
        train_times: keep.iter().map(|&i| times[i]).collect(),
        train_truth: keep.iter().map(|&i| dataset.world_from_camera[i]).collect(),
        tests,
        settings: resolve_settings(render_config, settings_default, &bounds)?,
        bounds,
        diameter: 2.0 * spread.max(1e-9),
        export,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_synthetic_scene_too_large_to_hold_is_refused_before_rendering() {
        let data = DataConfig {
            width: 100_000,
            height: 100_000,
            ..DataConfig::default()
        };
        let e = Views::load(&data, &MonocularOrbit::default(), &RenderConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("width × height = 100000 × 100000") && e.contains("at most"),
            "{e}"
        );
    }

    /// The Lego orbit as a sequence: every other view trained on at its own number as its time,
    /// held-out views from between them, and a further split scored beside them.
    #[test]
    fn a_blender_sequence_trains_on_every_other_view_and_holds_out_the_rest() {
        let Some(data_dir) = cpose_core::fs::shared_data_dir() else {
            println!("skipped: shared data folder ../shared/data not found");
            return;
        };
        let data = DataConfig {
            source: Source::Blender,
            path: Some(data_dir.join("nerf_synthetic/lego")),
            factor: Some(4),
            subsample: 2,
            split: "test".to_owned(),
            sequence: true,
            eval_split: Some("val".to_owned()),
            eval_views: 3,
            max_frames: Some(20),
            test_views: 4,
            ..DataConfig::default()
        };
        let views =
            Views::load(&data, &MonocularOrbit::default(), &RenderConfig::default()).unwrap();
        assert_eq!(views.condition, "lego/2");
        assert_eq!((views.camera.width, views.camera.height), (100, 100));
        let expected: Vec<f64> = (0..10).map(|k| (2 * k) as f64).collect();
        assert_eq!(views.train_times, expected);
        assert_eq!(views.tests.len(), 2);
        assert_eq!(views.tests[0].name, None);
        assert_eq!(views.tests[0].images.len(), 4);
        assert_eq!(views.tests[1].name.as_deref(), Some("val"));
        assert_eq!(views.tests[1].truth.len(), 3);
        // The held-out views lie between training views: none coincides with one.
        for truth in &views.tests[0].truth {
            assert!(
                views
                    .train_truth
                    .iter()
                    .all(|t| (t.translation.vector - truth.translation.vector).norm() > 0.1)
            );
        }
        // Without views between the training frames and without a further split: an error.
        let none_held = DataConfig {
            subsample: 1,
            eval_split: None,
            ..data
        };
        let e = Views::load(
            &none_held,
            &MonocularOrbit::default(),
            &RenderConfig::default(),
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("subsample = 2"), "{e}");
    }
}
