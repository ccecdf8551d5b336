//! One alignment run: a neural image and a pose model fitted jointly to the patches of one
//! ground-truth motion, then scored.

use std::time::Instant;

use cpose_core::nn::Adam;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::model::PoseModel;
use crate::field2d::ImageField;
use crate::image::{Image, NormalizedFrame, psnr};
use crate::warp2d::{self, Warp, WarpKind};

/// The patch layout on the working image: the centre crop and its pixel grid.
#[derive(Clone, Debug)]
pub struct Layout {
    /// Warp family.
    pub warp: WarpKind,
    /// Normalised coordinates of every crop pixel centre, row-major (`side²`).
    pub grid: Vec<[f64; 2]>,
    /// The crop's corners (normalised), for the corner error and the renders.
    pub corners: [[f64; 2]; 4],
    /// The original image's frame: corner errors are in its pixels.
    pub frame: NormalizedFrame,
}

impl Layout {
    /// The square centre crop of `crop_px` pixels of an image of `original_size` (width,
    /// height), sampled on a `side × side` grid of pixel centres.
    pub fn centre_crop(
        warp: WarpKind,
        original_size: [usize; 2],
        crop_px: f64,
        side: usize,
    ) -> Self {
        let long = original_size[0].max(original_size[1]) as f64;
        let half = crop_px / long;
        let grid = (0..side * side)
            .map(|k| {
                let (u, v) = ((k % side) as f64 + 0.5, (k / side) as f64 + 0.5);
                [
                    half * (2.0 * u / side as f64 - 1.0),
                    half * (2.0 * v / side as f64 - 1.0),
                ]
            })
            .collect();
        Self {
            warp,
            grid,
            corners: [[-half, -half], [half, -half], [half, half], [-half, half]],
            frame: NormalizedFrame::new(original_size[0], original_size[1]),
        }
    }
}

/// Training settings shared by every method.
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    /// Optimiser steps.
    pub iterations: usize,
    /// Pixels drawn per step over all patches (all pixels when ≥ their number).
    pub pixels_per_step: usize,
    /// Learning rate of the neural image.
    pub lr_field: f64,
    /// Steps during which the warps are held while the neural image fits the patches as they
    /// are (the warps' gradients are not even computed).
    pub pose_hold: usize,
}

/// What one run measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunResult {
    /// Mean corner error over patches 1.. and their 4 corners, pixels of the original image.
    pub corner_err_px: f64,
    /// PSNR of the neural image against the image inside the patches' true footprint.
    pub psnr_db: f64,
    /// Final training loss (MSE).
    pub final_loss: f64,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
    /// Estimated warp parameters per patch.
    pub warps: Vec<Vec<f64>>,
}

/// Ground-truth patch colours: the image through each true warp, `[patch][pixel]`.
pub fn sample_patches(image: &Image, layout: &Layout, truth: &[Vec<f64>]) -> Vec<Vec<[f32; 3]>> {
    truth
        .iter()
        .map(|p| {
            let w = Warp::new(layout.warp, p);
            layout
                .grid
                .iter()
                .map(|&x| image.sample_bilinear(w.apply(x)))
                .collect()
        })
        .collect()
}

/// Called after every training step with the steps done, the step's loss and the warp
/// parameters it was computed with.
pub type OnStep<'a> = dyn FnMut(usize, f64, &[f64]) -> anyhow::Result<()> + 'a;

/// One method on one motion: the neural image, the pose model and the step's buffers (reused, so
/// a step does not allocate).
pub struct Trainer<'a> {
    field: &'a mut dyn ImageField,
    model: &'a mut dyn PoseModel,
    layout: &'a Layout,
    patches: &'a [Vec<[f32; 3]>],
    schedule: Schedule,
    rng: ChaCha8Rng,
    adam: Adam<f32>,
    field_grad: Vec<f32>,
    points: Vec<f32>,
    rgb: Vec<f32>,
    grad_rgb: Vec<f32>,
    grad_points: Vec<f32>,
    picks: Vec<usize>,
    params: Vec<f64>,
    warp_grad: Vec<f64>,
    warps: Vec<Warp>,
    it: usize,
}

impl<'a> Trainer<'a> {
    /// A trainer at step 0; `seed` drives the pixel draws.
    pub fn new(
        field: &'a mut dyn ImageField,
        model: &'a mut dyn PoseModel,
        layout: &'a Layout,
        patches: &'a [Vec<[f32; 3]>],
        schedule: Schedule,
        seed: u64,
    ) -> Self {
        let total = patches.len() * layout.grid.len();
        let batch = schedule.pixels_per_step.min(total);
        let n_params = field.num_params();
        Self {
            field,
            model,
            layout,
            patches,
            schedule,
            rng: ChaCha8Rng::seed_from_u64(seed),
            adam: Adam::new(n_params),
            field_grad: vec![0.0; n_params],
            points: vec![0.0; 2 * batch],
            rgb: vec![0.0; 3 * batch],
            grad_rgb: vec![0.0; 3 * batch],
            grad_points: vec![0.0; 2 * batch],
            picks: vec![0; batch],
            params: Vec::new(),
            warp_grad: vec![0.0; layout.warp.dim() * patches.len()],
            warps: Vec::with_capacity(patches.len()),
            it: 0,
        }
    }

    /// One step: draw pixels, render them through the current warps, MSE against the patches,
    /// back-propagate to the neural image and through the warp Jacobians to the pose model.
    /// Returns the loss before the step.
    pub fn step(&mut self) -> anyhow::Result<f64> {
        let (per_patch, dim) = (self.layout.grid.len(), self.layout.warp.dim());
        let total = self.patches.len() * per_patch;
        let batch = self.picks.len();
        let progress = self.it as f64 / self.schedule.iterations.max(1) as f64;
        self.field.set_progress(progress);
        self.model.warps(&mut self.params, progress)?;
        self.warps.clear();
        self.warps.extend(
            self.params
                .chunks(dim)
                .map(|p| Warp::new(self.layout.warp, p)),
        );
        for (b, pick) in self.picks.iter_mut().enumerate() {
            *pick = if batch == total {
                b
            } else {
                self.rng.random_range(0..total)
            };
        }
        for (b, &pick) in self.picks.iter().enumerate() {
            let [x, y] = self.warps[pick / per_patch].apply(self.layout.grid[pick % per_patch]);
            self.points[2 * b] = x as f32;
            self.points[2 * b + 1] = y as f32;
        }
        self.field.forward(&self.points, &mut self.rgb);
        // MSE over pixels and channels (BARF's `MSE_loss`): ∂L/∂rgb = 2 (rgb − target)/(3B).
        let scale = 2.0 / (3 * batch) as f32;
        let mut loss = 0.0f64;
        for (b, &pick) in self.picks.iter().enumerate() {
            let target = self.patches[pick / per_patch][pick % per_patch];
            for c in 0..3 {
                let d = self.rgb[3 * b + c] - target[c];
                loss += f64::from(d * d);
                self.grad_rgb[3 * b + c] = scale * d;
            }
        }
        let loss = loss / (3 * batch) as f64;
        if !loss.is_finite() {
            anyhow::bail!(
                "the loss became {loss} at step {}; lower the learning rates",
                self.it
            );
        }
        self.field_grad.fill(0.0);
        self.field
            .backward(&self.grad_rgb, &mut self.field_grad, &mut self.grad_points);
        self.adam.step(
            self.field.params_mut(),
            &self.field_grad,
            self.schedule.lr_field,
        );
        if self.it < self.schedule.pose_hold {
            self.it += 1;
            return Ok(loss);
        }
        self.warp_grad.fill(0.0);
        for (b, &pick) in self.picks.iter().enumerate() {
            let i = pick / per_patch;
            let (_, jac) = self.warps[i].apply_jacobian(self.layout.grid[pick % per_patch]);
            let g = [
                f64::from(self.grad_points[2 * b]),
                f64::from(self.grad_points[2 * b + 1]),
            ];
            for k in 0..dim {
                self.warp_grad[i * dim + k] += g[0] * jac[k][0] + g[1] * jac[k][1];
            }
        }
        self.model.step(&self.warp_grad, self.it)?;
        self.it += 1;
        Ok(loss)
    }

    /// Runs the remaining steps and returns the last loss and the final warp parameters per
    /// patch. After each step, `on_step` gets the steps done, the step's loss and the warp
    /// parameters that loss was computed with.
    pub fn run(mut self, on_step: &mut OnStep<'_>) -> anyhow::Result<(f64, Vec<Vec<f64>>)> {
        let mut loss = f64::NAN;
        while self.it < self.schedule.iterations {
            loss = self.step()?;
            on_step(self.it, loss, &self.params)?;
        }
        self.field.set_progress(1.0);
        self.model.warps(&mut self.params, 1.0)?;
        let dim = self.layout.warp.dim();
        Ok((loss, self.params.chunks(dim).map(<[f64]>::to_vec).collect()))
    }
}

/// Warps expressed relative to the first patch, `W_0⁻¹ ∘ W_i`: the gauge in which the ground
/// truth is given (BARF's, whose first warp is held at the identity). Rigid warps are composed
/// exactly; homography models hold their first patch at zero, so theirs are returned as they are.
pub fn relative_to_first(kind: WarpKind, warps: &[Vec<f64>]) -> Vec<Vec<f64>> {
    match (kind, warps.first()) {
        (WarpKind::Se2, Some(first)) => {
            let first = [first[0], first[1], first[2]];
            warps
                .iter()
                .map(|w| super::motion::relative_se2(&first, &[w[0], w[1], w[2]]).to_vec())
                .collect()
        }
        _ => warps.to_vec(),
    }
}

/// Corner error (pixels of the original image) averaged over patches `1..` and their corners,
/// of warps relative to the first patch (see [`relative_to_first`]; the first is exact by
/// construction).
pub fn corner_error_px(layout: &Layout, estimated: &[Vec<f64>], truth: &[Vec<f64>]) -> f64 {
    let errors: Vec<f64> = estimated
        .iter()
        .zip(truth)
        .skip(1)
        .map(|(e, t)| warp2d::corner_error_px(layout.warp, e, t, &layout.corners, &layout.frame))
        .collect();
    errors.iter().sum::<f64>() / errors.len().max(1) as f64
}

/// The neural image rendered at every pixel of a `width × height` frame (normalised as BARF),
/// seen through the first patch's estimated warp `first` (the image frame is where the first
/// patch puts the centre crop).
pub fn render(field: &mut dyn ImageField, width: usize, height: usize, first: &Warp) -> Image {
    let long = width.max(height) as f64;
    let mut points = Vec::with_capacity(2 * width * height);
    for y in 0..height {
        for x in 0..width {
            let [u, v] = first.apply([
                (2.0 * (x as f64 + 0.5) - width as f64) / long,
                (2.0 * (y as f64 + 0.5) - height as f64) / long,
            ]);
            points.push(u as f32);
            points.push(v as f32);
        }
    }
    let mut rgb = vec![0.0f32; 3 * width * height];
    field.forward(&points, &mut rgb);
    Image::from_fn(width, height, |x, y| {
        let o = 3 * (y * width + x);
        [rgb[o], rgb[o + 1], rgb[o + 2]]
    })
}

/// PSNR of `rendered` against `image` over the pixels inside any true patch footprint.
pub fn region_psnr(rendered: &Image, image: &Image, layout: &Layout, truth: &[Vec<f64>]) -> f64 {
    let mask = footprint(image.width(), image.height(), layout, truth);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for y in 0..image.height() {
        for x in 0..image.width() {
            if mask[y * image.width() + x] {
                a.extend_from_slice(&rendered.pixel(x, y));
                b.extend_from_slice(&image.pixel(x, y));
            }
        }
    }
    psnr(&a, &b)
}

/// Pixels of a `width × height` frame covered by at least one true patch: a pixel centre is
/// inside warp `W` if `W⁻¹` maps it into the crop square.
fn footprint(width: usize, height: usize, layout: &Layout, truth: &[Vec<f64>]) -> Vec<bool> {
    let long = width.max(height) as f64;
    let half = layout.corners[2][0].abs();
    let inverses: Vec<_> = truth
        .iter()
        .filter_map(|p| Warp::new(layout.warp, p).matrix().try_inverse())
        .collect();
    let mut mask = vec![false; width * height];
    for y in 0..height {
        for x in 0..width {
            let xn = (2.0 * (x as f64 + 0.5) - width as f64) / long;
            let yn = (2.0 * (y as f64 + 0.5) - height as f64) / long;
            mask[y * width + x] = inverses.iter().any(|hi| {
                let v = hi * nalgebra::Vector3::new(xn, yn, 1.0);
                let (u, w) = (v.x / v.z, v.y / v.z);
                u.abs() <= half && w.abs() <= half
            });
        }
    }
    mask
}

/// Times a closure, in seconds.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let started = Instant::now();
    let out = f();
    (out, started.elapsed().as_secs_f64())
}
