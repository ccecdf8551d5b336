//! Evaluation of a trained run, as BARF (docs/methods.md §2.3): pose errors after Procrustes
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
        renderer.backward(field, settings, &rays, &grads, None, Some(&mut pose_grad));
        let g = pose_grad[0].right_se3(&now);
        adam.step(&mut delta, g.as_slice(), refinement.lr);
    }
    current(&delta)
}
