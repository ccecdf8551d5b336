//! 2-D neural image fields for planar image alignment (BARF §4.1; docs/methods.md §2.1).
//!
//! A field maps a point in BARF's normalised image coordinates (the long side spans `[−1, 1]`,
//! e.g. `[−1, 1] × [−0.75, 0.75]` for a 4:3 landscape image) to an RGB colour in `(0, 1)`, and
//! differentiates the colour with respect to its parameters *and* to the point, which is what
//! the warp (pose) parameters need.
//!
//! - [`PeMlpField`]: BARF's neural image, a ReLU MLP on `[x, y, PE(x), PE(y)]` with
//!   coarse-to-fine weighted frequency bands.
//! - [`GridField`]: dense multi-resolution 2-D feature grids with bilinear interpolation and a
//!   tiny MLP, coarse to fine over the levels; much cheaper per point.
//!
//! Both are built from a config (`init` validates it) and used through the object-safe
//! [`ImageField`] trait. A field is single-threaded; run independent fields in parallel.
//! Buffers are kept between calls and grow with the batch, so a training loop does not
//! allocate in its steady state.
//!
//! Not for: 3-D radiance fields, image metrics or warps (see the modules that own them).

mod grid;
mod mlp;

use cpose_core::Real;
use cpose_core::nn::Activation;

use crate::field_common::Invalid;

pub use grid::{GridConfig, GridField};
pub use mlp::{PeMlpConfig, PeMlpField};

/// A 2-D neural field: normalised image coordinates → RGB in (0, 1).
pub trait ImageField<S: Real = f32>: Send {
    /// Number of trainable parameters.
    fn num_params(&self) -> usize;
    /// All trainable parameters, one flat vector (layout documented by each field).
    fn params(&self) -> &[S];
    /// Mutable access to the parameters (for the optimiser).
    fn params_mut(&mut self) -> &mut [S];
    /// Coarse-to-fine: `progress` = fraction of training done (0–1).
    fn set_progress(&mut self, progress: f64);
    /// Colours at `points` (`n × 2` interleaved x,y) into `rgb` (`n × 3` interleaved). Keeps
    /// what `backward` needs; allocates only when n grows.
    fn forward(&mut self, points: &[S], rgb: &mut [S]);
    /// Reverse pass of the last `forward`: ADDS ∂L/∂θ into `grad` (len num_params) and WRITES
    /// ∂L/∂points into `grad_points` (n × 2).
    fn backward(&mut self, grad_rgb: &[S], grad: &mut [S], grad_points: &mut [S]);
}

/// Invalid construction parameters of a 2-D field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Field2dError {
    /// A configuration value is out of its valid range.
    #[error("invalid {key}: expected {expected}, got {got}")]
    Invalid {
        /// The config key (as spelled in TOML).
        key: &'static str,
        /// What the key accepts.
        expected: String,
        /// The value given.
        got: String,
    },
}

impl From<Invalid> for Field2dError {
    fn from(e: Invalid) -> Self {
        Field2dError::Invalid {
            key: e.key,
            expected: e.expected,
            got: e.got,
        }
    }
}

/// Sigmoid head: `rgb = σ(z)` for the pre-activations `z` (`[n × 3]` column-major). Writes
/// `rgb` interleaved and keeps a column-major copy in `rgb_cm` for [`sigmoid_backward`].
fn sigmoid_forward<S: Real>(z: &[S], n: usize, rgb_cm: &mut [S], rgb: &mut [S]) {
    for c in 0..3 {
        for i in 0..n {
            let (s, _) = Activation::Sigmoid.value_and_slope(z[c * n + i]);
            rgb_cm[c * n + i] = s;
            rgb[3 * i + c] = s;
        }
    }
}

/// `∂L/∂z = ∂L/∂rgb · σ(1 − σ)` into `grad_z` (`[n × 3]` column-major) from the interleaved
/// `grad_rgb`.
fn sigmoid_backward<S: Real>(rgb_cm: &[S], grad_rgb: &[S], n: usize, grad_z: &mut [S]) {
    for c in 0..3 {
        for i in 0..n {
            let s = rgb_cm[c * n + i];
            grad_z[c * n + i] = grad_rgb[3 * i + c] * s * (S::ONE - s);
        }
    }
}

/// Batch size of interleaved buffers, asserting their lengths agree (a caller bug otherwise).
fn batch_len<S>(points: &[S], rgb: &[S]) -> usize {
    let n = points.len() / 2;
    assert!(
        points.len() == 2 * n && rgb.len() == 3 * n,
        "points must be n × 2 and rgb n × 3, got {} and {}",
        points.len(),
        rgb.len()
    );
    n
}

/// Shared checks for the fields' tests.
#[cfg(test)]
mod test_support {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::ImageField;

    /// `n` points (interleaved) uniform in `[−0.98, 0.98] × [−0.75, 0.75]`, skipping any for
    /// which `reject(x, y)` holds (e.g. too close to a grid line, where the field has a kink).
    pub fn points(n: usize, seed: u64, reject: impl Fn(f64, f64) -> bool) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut p = Vec::with_capacity(2 * n);
        while p.len() < 2 * n {
            let (x, y) = (rng.random_range(-0.98..0.98), rng.random_range(-0.75..0.75));
            if !reject(x, y) {
                p.extend([x, y]);
            }
        }
        p
    }

    /// The `f32` field `b` agrees with the `f64` field `a` (same parameters and progress) on
    /// colours (1e-5) and on parameter and point gradients (1e-4 of the largest), at `points`.
    pub fn assert_f32_matches_f64(
        a: &mut dyn ImageField<f64>,
        b: &mut dyn ImageField<f32>,
        points: &[f64],
    ) {
        let n = points.len() / 2;
        let pts32: Vec<f32> = points.iter().map(|&p| p as f32).collect();
        let pts: Vec<f64> = pts32.iter().map(|&p| f64::from(p)).collect();
        let (mut ra, mut rb) = (vec![0.0; 3 * n], vec![0.0f32; 3 * n]);
        a.forward(&pts, &mut ra);
        b.forward(&pts32, &mut rb);
        for (x, y) in ra.iter().zip(&rb) {
            assert!((x - f64::from(*y)).abs() < 1e-5, "{x} vs {y}");
        }
        let g: Vec<f64> = (0..3 * n).map(|k| (k as f64 * 0.37).sin()).collect();
        let g32: Vec<f32> = g.iter().map(|&v| v as f32).collect();
        let (mut ga, mut gb) = (vec![0.0; a.num_params()], vec![0.0f32; b.num_params()]);
        let (mut pa, mut pb) = (vec![0.0; 2 * n], vec![0.0f32; 2 * n]);
        a.backward(&g, &mut ga, &mut pa);
        b.backward(&g32, &mut gb, &mut pb);
        for (x, y) in [(ga, gb), (pa, pb)] {
            let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (x, y) in x.iter().zip(&y) {
                assert!((x - f64::from(*y)).abs() < 1e-4 * scale, "{x} vs {y}");
            }
        }
    }

    /// `L = Σ c ⊙ rgb` with fixed cotangents `c`.
    fn loss(field: &mut dyn ImageField<f64>, points: &[f64], c: &[f64]) -> f64 {
        let mut rgb = vec![0.0; c.len()];
        field.forward(points, &mut rgb);
        rgb.iter().zip(c).map(|(a, b)| a * b).sum()
    }

    /// Parameter gradients (at `indices`) and point gradients of `L = Σ c ⊙ rgb` against
    /// central differences, `h = 1e-6`: truncation `h²|L'''|/6` and rounding `ε|L|/h ≈ 1e-10`
    /// stay well below `tol` relative to the largest compared magnitude. Also checks that
    /// `backward` adds into `grad` and overwrites `grad_points`.
    pub fn check_gradients(
        field: &mut dyn ImageField<f64>,
        points: &[f64],
        indices: &[usize],
        tol: f64,
    ) {
        let n = points.len() / 2;
        let c: Vec<f64> = (0..3 * n)
            .map(|k| ((k * 7 % 13) as f64 - 6.0) * 0.1)
            .collect();
        let mut rgb = vec![0.0; 3 * n];
        field.forward(points, &mut rgb);
        let (pre, junk) = (0.25, 7.0);
        let mut grad = vec![pre; field.num_params()];
        let mut grad_points = vec![junk; 2 * n];
        field.backward(&c, &mut grad, &mut grad_points);
        let h = 1e-6;
        let fd = |field: &mut dyn ImageField<f64>, k: usize| {
            let p0 = field.params()[k];
            field.params_mut()[k] = p0 + h;
            let lp = loss(field, points, &c);
            field.params_mut()[k] = p0 - h;
            let lm = loss(field, points, &c);
            field.params_mut()[k] = p0;
            (lp - lm) / (2.0 * h)
        };
        let pairs: Vec<(usize, f64, f64)> = indices
            .iter()
            .map(|&k| (k, fd(field, k), grad[k] - pre))
            .collect();
        let scale = pairs.iter().map(|p| p.1.abs()).fold(1e-3, f64::max);
        for (k, fd, an) in pairs {
            assert!(
                (fd - an).abs() <= tol * scale,
                "param {k}: central difference {fd} vs backward {an}"
            );
        }
        let point_fd: Vec<f64> = (0..2 * n)
            .map(|k| {
                let (mut pp, mut pm) = (points.to_vec(), points.to_vec());
                pp[k] += h;
                pm[k] -= h;
                (loss(field, &pp, &c) - loss(field, &pm, &c)) / (2.0 * h)
            })
            .collect();
        let scale = point_fd.iter().map(|g| g.abs()).fold(1e-3, f64::max);
        for (k, (fd, an)) in point_fd.iter().zip(&grad_points).enumerate() {
            assert!(
                (fd - an).abs() <= tol * scale,
                "point coordinate {k}: central difference {fd} vs backward {an}"
            );
        }
    }
}
