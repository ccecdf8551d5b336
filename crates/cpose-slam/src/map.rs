//! The neural map: a multiresolution hash-grid radiance field ([`HashGridField`]) over the
//! scene's bounding box, trained from scratch on RGB-D keyframes, rendered along camera rays at
//! depths placed by the measured depth (NICE-SLAM §3.2 places its samples the same way).
//!
//! A ray with measured depth `D` gets `n_u` stratified samples in `[near, D·(1 + b)]` and `n_s`
//! stratified samples in `[D(1 − b), D(1 + b)]` (`b` = `surface_band`), merged in depth order.
//! Rendering gives colour `Ĉ`, depth `D̂ = Σ w_j s_j` and depth variance
//! `Var = Σ w_j (s_j − D̂)²` ([`Renderer::depth_variances`]).
//!
//! * **Mapping loss** (NICE-SLAM eq. 7, means instead of sums): `mean |D − D̂| + λ_c mean |C − Ĉ|₁`,
//!   `λ_c = 0.2`, over pixels with a depth reading; Adam on the field's parameters.
//! * **Tracking loss** (NICE-SLAM eq. 9): `Σ_m |D − D̂| / sqrt(Var + 10⁻¹⁰) + λ_t Σ_m |C − Ĉ|₁`,
//!   `λ_t = 0.5`, `Var` constant, over the mask `m` of pixels whose normalised depth residual is
//!   below 10 × its median (NICE-SLAM's `handle_dynamic`); the gradient reaches the camera pose.

use cpose_core::nn::Adam;
use cpose_nerf::camera::PoseGradient;
use cpose_nerf::field3d::{
    HashGridConfig, HashGridField, Interpolation, RadianceField, SceneBounds,
};
use cpose_nerf::mesh::{Grid, Mesh};
use cpose_nerf::render::{CameraRay, Composited, LastInterval, RenderSettings, Renderer, Sampling};
use rand::RngExt;
use serde::{Deserialize, Serialize};

use cpose_core::checkpoint::{Reader, Writer};

/// Weight of the colour term in mapping (NICE-SLAM: 0.2).
pub const MAPPING_COLOR_WEIGHT: f32 = 0.2;

/// Weight of the colour term in tracking (NICE-SLAM: 0.5).
pub const TRACKING_COLOR_WEIGHT: f32 = 0.5;

/// The map's density scale ([`HashGridConfig::density_scale`]), per metre: with open rays the
/// depth loss has to build opaque surfaces a few centimetres thick, hundreds per metre.
pub const DENSITY_SCALE: f64 = 30.0;

/// Most samples per ray.
const MAX_SAMPLES: usize = 256;

/// How the map is built and rendered; `[map]` in a config.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapConfig {
    /// The hash grid (levels, table size, resolutions, decoder).
    pub grid: HashGridConfig,
    /// Stratified samples from `near` to just behind the measured depth.
    pub uniform_samples: usize,
    /// Stratified samples in the band around the measured depth.
    pub surface_samples: usize,
    /// Half-width of the surface band as a fraction of the measured depth.
    pub surface_band: f64,
    /// First sample depth, metres.
    pub near: f64,
    /// Adam learning rate of the grid's features.
    pub lr_grid: f64,
    /// Adam learning rate of the decoder MLP.
    pub lr_mlp: f64,
}

impl Default for MapConfig {
    fn default() -> Self {
        Self {
            grid: HashGridConfig {
                levels: 10,
                features: 2,
                log2_table_size: 16,
                base_resolution: 8,
                finest_resolution: 256,
                width: 32,
                hidden_layers: 1,
                c2f: None,
                init_scale: 1e-4,
                density_scale: DENSITY_SCALE,
                interpolation: Interpolation::Smoothstep,
                seed: 0,
            },
            uniform_samples: 8,
            surface_samples: 8,
            surface_band: 0.05,
            near: 0.1,
            lr_grid: 1e-2,
            lr_mlp: 1e-3,
        }
    }
}

impl MapConfig {
    /// Samples per ray.
    pub fn samples(&self) -> usize {
        self.uniform_samples + self.surface_samples
    }

    /// Checks the values; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        if self.surface_samples == 0 || self.samples() > MAX_SAMPLES {
            return Err(format!(
                "surface_samples = {} must be ≥ 1 and uniform_samples + surface_samples ≤ {MAX_SAMPLES}",
                self.surface_samples
            ));
        }
        if !(self.surface_band > 0.0 && self.surface_band < 1.0) {
            return Err(format!(
                "surface_band = {} must lie in (0, 1)",
                self.surface_band
            ));
        }
        if !(self.near.is_finite() && self.near >= 0.0) {
            return Err(format!("near = {} must be ≥ 0", self.near));
        }
        for (key, lr) in [("lr_grid", self.lr_grid), ("lr_mlp", self.lr_mlp)] {
            if !(lr.is_finite() && lr > 0.0) {
                return Err(format!("{key} = {lr} must be positive"));
            }
        }
        Ok(())
    }
}

/// One pixel to render: its ray and what the sensor measured there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelSample {
    /// The camera ray (its `camera` indexes the pose gradients of a batch).
    pub ray: CameraRay,
    /// Measured colour.
    pub color: [f32; 3],
    /// Measured depth, metres (> 0).
    pub depth: f32,
}

/// The map: field, optimiser and reusable buffers.
pub struct NeuralMap {
    field: HashGridField<f32>,
    config: MapConfig,
    settings: RenderSettings,
    adam: Adam<f32>,
    groups: Vec<(std::ops::Range<usize>, f64)>,
    renderer: Renderer<f32>,
    depths: Vec<f32>,
    rays: Vec<CameraRay>,
    grad_params: Vec<f32>,
    cotangents: Vec<Composited<f32>>,
    variances: Vec<f32>,
    residuals: Vec<f32>,
    scratch: Vec<f32>,
    outputs: Vec<Composited<f32>>,
    /// Median `|D̂ − D|` of the last [`NeuralMap::tracking_loss`], metres.
    depth_error: f64,
}

impl NeuralMap {
    /// A fresh map over `bounds` (the grid covers the cube around its sphere).
    pub fn new(config: &MapConfig, bounds: SceneBounds) -> Result<Self, String> {
        config.validate()?;
        let field = config
            .grid
            .init::<f32>(bounds)
            .map_err(|e| format!("map.grid: {e}"))?;
        let groups = field
            .param_groups()
            .into_iter()
            .map(|(name, range)| {
                let lr = if name == "mlp" {
                    config.lr_mlp
                } else {
                    config.lr_grid
                };
                (range, lr)
            })
            .collect();
        let n = field.num_params();
        Ok(Self {
            settings: RenderSettings {
                last_interval: LastInterval::Open,
                samples: config.samples(),
                sampling: Sampling::Metric {
                    near: config.near,
                    far: config.near + 1.0,
                },
                background: None,
                clip: None,
            },
            field,
            config: config.clone(),
            adam: Adam::new(n),
            groups,
            renderer: Renderer::default(),
            depths: Vec::new(),
            rays: Vec::new(),
            grad_params: vec![0.0; n],
            cotangents: Vec::new(),
            variances: Vec::new(),
            residuals: Vec::new(),
            scratch: Vec::new(),
            outputs: Vec::new(),
            depth_error: 0.0,
        })
    }

    /// The surface `σ = level` on `grid`, keeping the triangles whose centroid satisfies `keep`
    /// ([`cpose_nerf::mesh::extract`]).
    pub fn mesh(&mut self, grid: &Grid, level: f32, keep: impl Fn([f64; 3]) -> bool) -> Mesh {
        cpose_nerf::mesh::extract(&mut self.field, grid, level, keep)
    }

    /// Writes the field's parameters and its optimiser's state.
    pub fn save(&self, w: &mut Writer) {
        w.f32s(self.field.params());
        let (m, v, t) = self.adam.state();
        w.f32s(m);
        w.f32s(v);
        w.u64(t);
    }

    /// Restores [`NeuralMap::save`] of a map with the same config.
    pub fn load(&mut self, r: &mut Reader) -> anyhow::Result<()> {
        let params = r.f32s()?;
        let p = self.field.params_mut();
        if p.len() != params.len() {
            anyhow::bail!(
                "the checkpoint holds {} map parameters, this map has {} (another [map] config?)",
                params.len(),
                p.len()
            );
        }
        p.copy_from_slice(&params);
        let (m, v, t) = (r.f32s()?, r.f32s()?, r.u64()?);
        if !self.adam.set_state(&m, &v, t) {
            anyhow::bail!("the checkpoint's map optimiser does not match this map");
        }
        Ok(())
    }

    /// Places the sample depths of `pixels` (module docs) into the buffer, jittered by `rng`.
    fn place_samples<R: RngExt + ?Sized>(&mut self, pixels: &[PixelSample], rng: &mut R) {
        let (nu, ns) = (self.config.uniform_samples, self.config.surface_samples);
        let k = nu + ns;
        let b = self.config.surface_band;
        self.depths.clear();
        self.depths.reserve(pixels.len() * k);
        let mut merged = [0f32; MAX_SAMPLES];
        for p in pixels {
            let d = p.depth as f64;
            let (lo, hi) = (d * (1.0 - b), d * (1.0 + b));
            let near = self.config.near.min(lo);
            let slots = &mut merged[..k];
            for j in 0..nu {
                let x = (j as f64 + rng.random::<f64>()) / nu as f64;
                slots[j] = (near + x * (hi - near)) as f32;
            }
            for j in 0..ns {
                let x = (j as f64 + rng.random::<f64>()) / ns as f64;
                slots[nu + j] = (lo + x * (hi - lo)) as f32;
            }
            slots.sort_unstable_by(f32::total_cmp);
            self.depths.extend_from_slice(slots);
        }
    }

    /// Renders `pixels` (forward only, jittered samples): colour, depth and opacity per pixel.
    pub fn render<R: RngExt + ?Sized>(
        &mut self,
        pixels: &[PixelSample],
        rng: &mut R,
    ) -> &[Composited<f32>] {
        self.place_samples(pixels, rng);
        self.rays.clear();
        self.rays.extend(pixels.iter().map(|p| p.ray));
        let out = self.renderer.forward_at_depths(
            &mut self.field,
            &self.settings,
            &self.rays,
            &self.depths,
        );
        self.outputs.clear();
        self.outputs.extend_from_slice(out);
        &self.outputs
    }

    /// One mapping step on `pixels`: the mapping loss, its gradient and an Adam step on the
    /// field. Returns the loss.
    pub fn mapping_step<R: RngExt + ?Sized>(&mut self, pixels: &[PixelSample], rng: &mut R) -> f64 {
        let n = pixels.len();
        self.render(pixels, rng);
        let out = &self.outputs;
        let inv = 1.0 / n as f32;
        let mut loss = 0.0f64;
        self.cotangents.clear();
        for (p, o) in pixels.iter().zip(out) {
            let dd = o.depth - p.depth;
            let mut g = Composited {
                depth: dd.signum() * inv,
                ..Composited::default()
            };
            loss += dd.abs() as f64;
            for c in 0..3 {
                let dc = o.rgb[c] - p.color[c];
                loss += (MAPPING_COLOR_WEIGHT * dc.abs()) as f64;
                g.rgb[c] = MAPPING_COLOR_WEIGHT * dc.signum() * inv;
            }
            self.cotangents.push(g);
        }
        self.backward(true, None);
        self.adam.begin_step();
        let params = self.field.params_mut();
        for (range, lr) in &self.groups {
            self.adam.update(
                range.start,
                &mut params[range.clone()],
                &self.grad_params[range.clone()],
                *lr,
            );
        }
        loss / n as f64
    }

    /// The tracking loss of `pixels` (module docs) and its gradient with respect to each
    /// camera's pose, accumulated into `pose_grads[ray.camera]`. The field is not changed.
    pub fn tracking_loss<R: RngExt + ?Sized>(
        &mut self,
        pixels: &[PixelSample],
        rng: &mut R,
        pose_grads: &mut [PoseGradient],
    ) -> f64 {
        let n = pixels.len();
        self.render(pixels, rng);
        let out = &self.outputs;
        self.variances.resize(n, 0.0);
        self.renderer
            .depth_variances(&self.settings, &mut self.variances);
        // Normalised depth residuals and NICE-SLAM's robust mask (10 × the median).
        self.residuals.clear();
        for ((p, o), var) in pixels.iter().zip(out).zip(&self.variances) {
            self.residuals
                .push((o.depth - p.depth).abs() / (var + 1e-10).sqrt());
        }
        self.scratch.clear();
        self.scratch.extend_from_slice(&self.residuals);
        let mid = self.scratch.len() / 2;
        let median = if self.scratch.is_empty() {
            0.0
        } else {
            *self.scratch.select_nth_unstable_by(mid, f32::total_cmp).1
        };
        self.scratch.clear();
        self.scratch.extend(
            pixels
                .iter()
                .zip(out)
                .map(|(p, o)| (o.depth - p.depth).abs()),
        );
        self.depth_error = if self.scratch.is_empty() {
            0.0
        } else {
            *self.scratch.select_nth_unstable_by(mid, f32::total_cmp).1 as f64
        };
        let mut loss = 0.0f64;
        self.cotangents.clear();
        for (i, (p, o)) in pixels.iter().zip(out).enumerate() {
            let mut g = Composited::default();
            if self.residuals[i] < 10.0 * median || median == 0.0 {
                let scale = 1.0 / (self.variances[i] + 1e-10).sqrt();
                let dd = o.depth - p.depth;
                loss += (dd.abs() * scale) as f64;
                g.depth = dd.signum() * scale;
                for c in 0..3 {
                    let dc = o.rgb[c] - p.color[c];
                    loss += (TRACKING_COLOR_WEIGHT * dc.abs()) as f64;
                    g.rgb[c] = TRACKING_COLOR_WEIGHT * dc.signum();
                }
            }
            self.cotangents.push(g);
        }
        // The field is held fixed: only the points' gradient is taken.
        self.backward(false, Some(pose_grads));
        loss
    }

    /// The reverse pass of the last render with `self.cotangents`: the field's gradient into
    /// `self.grad_params` (cleared first) when `params`, the poses' into `pose_grads` when given.
    fn backward(&mut self, params: bool, pose_grads: Option<&mut [PoseGradient]>) {
        let grad_params = params.then(|| {
            self.grad_params.fill(0.0);
            &mut self.grad_params[..]
        });
        self.renderer.backward(
            &mut self.field,
            &self.settings,
            &self.rays,
            &self.cotangents,
            grad_params,
            pose_grads,
        );
    }

    /// The median depth error `|D̂ − D|` of the last [`NeuralMap::tracking_loss`], metres.
    pub fn depth_error(&self) -> f64 {
        self.depth_error
    }
}
