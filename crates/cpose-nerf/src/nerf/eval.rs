//! Evaluation of a trained run, as BARF (algorithms.md §2.4–2.5): pose errors after Procrustes
//! alignment of the camera centres, novel views rendered from the ground-truth test poses
//! mapped into the learned frame, with and without test-time photometric refinement of each
//! test pose, PSNR and SSIM; and a top-down trajectory plot.

use cpose_core::geometry::se3_exp;
use cpose_core::nn::Adam;
use nalgebra::{Isometry3, Vector6};
use rand::seq::index::sample;
use rand_chacha::ChaCha8Rng;

use crate::camera::{PinholeCamera, PoseGradient};
use crate::field3d::RadianceField;
use crate::image::Image;
use crate::render::{CameraRay, Composited, RenderSettings, Renderer};

/// Test-time photometric refinement (BARF `evaluate_test_time_photometric_optim`): a fresh
/// camera-frame correction `δ ∈ se(3)` of the pose, `world_from_camera · Exp(δ)`, fitted by Adam
/// to `rays` random pixels of `image` per step, the field frozen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refinement {
    /// Steps (BARF: 100).
    pub iterations: usize,
    /// Random pixels per step (BARF: 1024).
    pub rays: usize,
    /// Adam learning rate (BARF: the initial pose learning rate).
    pub lr: f64,
}

/// Refines `pose` against `image` (see [`Refinement`]); returns the refined pose.
pub fn refine_pose(
    renderer: &mut Renderer,
    field: &mut dyn RadianceField,
    settings: &RenderSettings,
    camera: &PinholeCamera,
    image: &Image,
    pose: &Isometry3<f64>,
    refinement: &Refinement,
    rng: &mut ChaCha8Rng,
) -> Isometry3<f64> {
    let (w, h) = (camera.width, camera.height);
    let mut delta = [0.0f64; 6];
    let mut adam = Adam::<f64>::new(6);
    let mut rays = Vec::with_capacity(refinement.rays);
    let mut grads = Vec::with_capacity(refinement.rays);
    let mut sink = vec![0.0f32; field.num_params()];
    let current = |delta: &[f64; 6]| pose * se3_exp(&Vector6::from_column_slice(delta));
    for _ in 0..refinement.iterations {
        let now = current(&delta);
        let pixels = sample(rng, w * h, refinement.rays.min(w * h));
        rays.clear();
        rays.extend(
            pixels
                .iter()
                .map(|p| CameraRay::new(0, &now, camera.ray_direction_cam(p % w, p / w))),
        );
        let out = renderer.forward(field, settings, &rays, Some(&mut *rng));
        let scale = 2.0 / (3 * out.len()) as f32;
        grads.clear();
        grads.extend(out.iter().zip(pixels.iter()).map(|(o, p)| {
            let y = image.pixel(p % w, p / w);
            let mut g = Composited::default();
            for c in 0..3 {
                g.rgb[c] = scale * (o.rgb[c] - y[c]);
            }
            g
        }));
        let mut pose_grad = [PoseGradient::new()];
        renderer.backward(
            field,
            settings,
            &rays,
            &grads,
            &mut sink,
            Some(&mut pose_grad),
        );
        let g = pose_grad[0].right_se3(&now);
        adam.step(&mut delta, g.as_slice(), refinement.lr);
    }
    current(&delta)
}

/// Colours of the trajectory plot.
const TRUE_RGB: [f32; 3] = [0.1, 0.6, 0.2];
const INITIAL_RGB: [f32; 3] = [0.85, 0.2, 0.15];
const ESTIMATE_RGB: [f32; 3] = [0.15, 0.3, 0.9];

/// A top-down (world x–y) plot of camera centres with a short tick along each viewing
/// direction: true cameras green, initial red, estimated (aligned to the truth) blue, each
/// sequence joined in time order.
pub fn trajectory_plot(
    size_px: usize,
    truth: &[Isometry3<f64>],
    initial: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
) -> Image {
    let mut image = Image::from_fn(size_px, size_px, |_, _| [1.0; 3]);
    let all = truth.iter().chain(initial).chain(estimate);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all.clone() {
        let c = p.translation.vector;
        for k in 0..2 {
            if c[k].is_finite() {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let tick = 0.06 * span;
    let margin = 0.08 * size_px as f64;
    let scale = (size_px as f64 - 2.0 * margin) / span;
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    // World y up on the page.
    let to_px = |x: f64, y: f64| {
        [
            size_px as f64 / 2.0 + (x - mid[0]) * scale,
            size_px as f64 / 2.0 - (y - mid[1]) * scale,
        ]
    };
    for (poses, rgb) in [
        (truth, TRUE_RGB),
        (initial, INITIAL_RGB),
        (estimate, ESTIMATE_RGB),
    ] {
        for pair in poses.windows(2) {
            let (a, b) = (pair[0].translation.vector, pair[1].translation.vector);
            image.draw_line(to_px(a.x, a.y), to_px(b.x, b.y), rgb, 1.0);
        }
        for p in poses {
            let c = p.translation.vector;
            let z = p.rotation * nalgebra::Vector3::z();
            image.draw_line(
                to_px(c.x, c.y),
                to_px(c.x + tick * z.x, c.y + tick * z.y),
                rgb,
                1.0,
            );
            image.draw_marker(to_px(c.x, c.y), rgb, 3.0);
        }
    }
    image
}
