//! Continuous rigid-body trajectories `t ↦ world_from_body(t) ∈ SE(3)`, differentiable in time
//! and in their parameters.
//!
//! A [`PoseField`] is evaluated on a batch of times at once. It returns, per time,
//! - the unit quaternion `q(t)` (Hamilton, `world_from_body` rotation) and the translation `p(t)`
//!   (body origin in the world frame);
//! - on request the first derivatives `q̇ = dq/dt` and `ṗ = v_world`;
//! - on request the second derivatives `q̈` and `p̈ = a_world`.
//!
//! Body angular velocity and acceleration follow from these (`ω_body = 2 vec(q* ⊗ q̇)`,
//! `α_body = 2 vec(q* ⊗ q̈)`, see [`PoseBatch::ang_vel_body`]); their gradients are mapped back
//! onto `q, q̇, q̈` by [`PoseBatch::add_ang_vel_body_grad`] and friends, so every field only has
//! to differentiate `q, q̇, q̈, p, ṗ, p̈`.
//!
//! The reverse pass takes a [`PoseBatch`] of cotangents (gradients of a scalar loss with respect
//! to each output; empty vectors mean zero) and *accumulates* the gradient with respect to the
//! field's parameters into a flat slice laid out as [`PoseField::params`] visits them.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use thiserror::Error;

use crate::{Real, TimeRange};

mod builtin;
pub mod composed;
mod discrete;
mod lie_dual;
pub mod posenet;
pub mod saved;
pub mod sinusoid;
mod spline;

pub use composed::Composed;
pub use discrete::{DiscretePoses, DiscretePosesConfig};
pub use posenet::{PoseNet, PoseNetConfig};
pub use sinusoid::SinusoidMotion;
pub use spline::{
    LieSplinePoses, PerDimSplinePoses, SplineConfig, SplineKind, SplinePoses,
    smooth_with_cubic_spline,
};

/// The highest time derivative an evaluation computes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Order {
    /// `q, p` only.
    #[default]
    Pose = 0,
    /// Also `q̇, ṗ`.
    Velocity = 1,
    /// Also `q̈, p̈`.
    Acceleration = 2,
}

/// What a block of parameters controls; optimisers pick learning rates by it (the paper uses
/// 1e-3 for translation and 2e-4 for rotation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamKind {
    /// Parameters that move only the translation (PoseNet's translation network).
    Translation,
    /// Parameters that move only the rotation (PoseNet's rotation network).
    Rotation,
    /// Parameters that move both (coupled PoseNet, se(3) per frame, spline control poses).
    Pose,
}

/// Errors of pose-field evaluation and construction.
#[derive(Debug, Error, PartialEq)]
pub enum PoseFieldError {
    /// A query time lies outside the field's valid range.
    #[error("time {t_secs} s is outside the pose field's time range {range}")]
    OutOfRange {
        /// The offending time, seconds.
        t_secs: f64,
        /// The field's valid range.
        range: TimeRange,
    },
    /// A buffer has the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    Shape {
        /// Which buffer.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// Gradients were requested for a higher derivative than the forward pass computed.
    #[error(
        "backward needs derivatives up to {needed:?}, but the forward pass computed {computed:?}"
    )]
    Order {
        /// Order of the cotangents.
        needed: Order,
        /// Order of the cached forward pass.
        computed: Order,
    },
    /// Invalid construction parameters.
    #[error("invalid pose field: {0}")]
    Invalid(String),
}

/// Poses and their time derivatives at a batch of times (structure of arrays, `f64`).
///
/// The same type carries cotangents in the reverse pass: each entry is then `∂L/∂(output)`, and
/// an empty vector stands for zero.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseBatch {
    /// Highest derivative present.
    pub order: Order,
    /// `q(t)`: unit quaternion (Hamilton, `w + xi + yj + zk`) of `world_from_body`.
    pub rotation: Vec<Quaternion<f64>>,
    /// `p(t)`: translation of `world_from_body`, the body origin in world coordinates.
    pub translation: Vec<Vector3<f64>>,
    /// `q̇ = dq/dt` (empty below [`Order::Velocity`]).
    pub rotation_rate: Vec<Quaternion<f64>>,
    /// `ṗ = dp/dt`, linear velocity in the world frame (empty below [`Order::Velocity`]).
    pub lin_vel_world: Vec<Vector3<f64>>,
    /// `q̈ = d²q/dt²` (empty below [`Order::Acceleration`]).
    pub rotation_acc: Vec<Quaternion<f64>>,
    /// `p̈ = d²p/dt²`, linear acceleration in the world frame (empty below [`Order::Acceleration`]).
    pub lin_acc_world: Vec<Vector3<f64>>,
}

impl PoseBatch {
    /// A batch of `n` zero entries up to `order` (a zero cotangent, or a buffer to fill).
    pub fn zeros(n: usize, order: Order) -> Self {
        let mut batch = Self::default();
        batch.reset(n, order);
        batch
    }

    /// Resizes to `n` zero entries up to `order`, keeping allocations.
    pub fn reset(&mut self, n: usize, order: Order) {
        fn fill<T: Clone>(v: &mut Vec<T>, n: usize, zero: T) {
            v.clear();
            v.resize(n, zero);
        }
        let zq = Quaternion::new(0.0, 0.0, 0.0, 0.0);
        let zv = Vector3::zeros();
        self.order = order;
        fill(&mut self.rotation, n, zq);
        fill(&mut self.translation, n, zv);
        let (n1, n2) = match order {
            Order::Pose => (0, 0),
            Order::Velocity => (n, 0),
            Order::Acceleration => (n, n),
        };
        fill(&mut self.rotation_rate, n1, zq);
        fill(&mut self.lin_vel_world, n1, zv);
        fill(&mut self.rotation_acc, n2, zq);
        fill(&mut self.lin_acc_world, n2, zv);
    }

    /// Number of times in the batch.
    pub fn len(&self) -> usize {
        self.rotation.len()
    }

    /// Whether the batch is empty.
    pub fn is_empty(&self) -> bool {
        self.rotation.is_empty()
    }

    /// `world_from_body` at entry `i` (the quaternion is renormalised against rounding).
    pub fn world_from_body(&self, i: usize) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.translation[i]),
            UnitQuaternion::new_normalize(self.rotation[i]),
        )
    }

    /// Body angular velocity `ω_body = 2 vec(q* ⊗ q̇)`, defined by `Ṙ = R [ω_body]×`.
    pub fn ang_vel_body(&self, i: usize) -> Vector3<f64> {
        (self.rotation[i].conjugate() * self.rotation_rate[i]).imag() * 2.0
    }

    /// World angular velocity `ω_world = 2 vec(q̇ ⊗ q*) = R ω_body`.
    pub fn ang_vel_world(&self, i: usize) -> Vector3<f64> {
        (self.rotation_rate[i] * self.rotation[i].conjugate()).imag() * 2.0
    }

    /// Body angular acceleration `α_body = dω_body/dt = 2 vec(q* ⊗ q̈)` (the term `q̇* ⊗ q̇ =
    /// |q̇|²` is real and drops out of the vector part).
    pub fn ang_acc_body(&self, i: usize) -> Vector3<f64> {
        (self.rotation[i].conjugate() * self.rotation_acc[i]).imag() * 2.0
    }

    /// Linear velocity in the body frame, `Rᵀ ṗ`.
    pub fn lin_vel_body(&self, i: usize) -> Vector3<f64> {
        UnitQuaternion::new_normalize(self.rotation[i])
            .inverse_transform_vector(&self.lin_vel_world[i])
    }

    /// Accumulates into this cotangent batch the gradient of a loss whose gradient with respect
    /// to `ω_body(i)` is `g`: with `ω = 2 vec(q* ⊗ q̇)`, `∂L/∂q̇ = 2 q ⊗ (0, g)` and
    /// `∂L/∂q = −2 q̇ ⊗ (0, g)`. `primal` holds the forward values.
    pub fn add_ang_vel_body_grad(&mut self, primal: &PoseBatch, i: usize, g: &Vector3<f64>) {
        let e = Quaternion::from_imag(*g);
        self.rotation_rate[i] += primal.rotation[i] * e * 2.0;
        self.rotation[i] -= primal.rotation_rate[i] * e * 2.0;
    }

    /// As [`PoseBatch::add_ang_vel_body_grad`] for `α_body = 2 vec(q* ⊗ q̈)`:
    /// `∂L/∂q̈ = 2 q ⊗ (0, g)` and `∂L/∂q = −2 q̈ ⊗ (0, g)`.
    pub fn add_ang_acc_body_grad(&mut self, primal: &PoseBatch, i: usize, g: &Vector3<f64>) {
        let e = Quaternion::from_imag(*g);
        self.rotation_acc[i] += primal.rotation[i] * e * 2.0;
        self.rotation[i] -= primal.rotation_acc[i] * e * 2.0;
    }

    /// Checks lengths and order against `n` and `order`.
    pub fn check_shape(&self, n: usize, order: Order) -> Result<(), PoseFieldError> {
        let lens = [
            ("rotation", self.rotation.len(), n),
            ("translation", self.translation.len(), n),
            (
                "rotation_rate",
                self.rotation_rate.len(),
                if order >= Order::Velocity { n } else { 0 },
            ),
            (
                "lin_vel_world",
                self.lin_vel_world.len(),
                if order >= Order::Velocity { n } else { 0 },
            ),
            (
                "rotation_acc",
                self.rotation_acc.len(),
                if order >= Order::Acceleration { n } else { 0 },
            ),
            (
                "lin_acc_world",
                self.lin_acc_world.len(),
                if order >= Order::Acceleration { n } else { 0 },
            ),
        ];
        for (what, got, expected) in lens {
            if got != expected {
                return Err(PoseFieldError::Shape {
                    what,
                    expected,
                    got,
                });
            }
        }
        Ok(())
    }
}

/// Returns the first time outside `range` as an error.
pub fn check_times(range: &TimeRange, times_secs: &[f64]) -> Result<(), PoseFieldError> {
    match times_secs.iter().find(|t| !range.contains(**t)) {
        Some(&t_secs) => Err(PoseFieldError::OutOfRange {
            t_secs,
            range: *range,
        }),
        None => Ok(()),
    }
}

/// A rigid-body trajectory `t ↦ world_from_body(t) ∈ SE(3)` with parameters of scalar type `S`.
///
/// Fields are generic over `S` so that the same code runs in `f32` for training and in `f64` for
/// gradient checks; `dyn PoseField` means `dyn PoseField<f32>`.
///
/// Contract, checked for every implementation by `cpose_core::testing::check_pose_field`
/// (feature `testing`):
/// - `rotation` is a unit quaternion and continuous in `t` (no sign flips);
/// - `rotation_rate = dq/dt`, `rotation_acc = d²q/dt²`, `lin_vel_world = dp/dt`,
///   `lin_acc_world = d²p/dt²` exactly (not by finite differences);
/// - [`PoseField::backward`] accumulates `Σ_outputs ⟨cotangent, ∂output/∂θ⟩` into the gradient.
///
/// ```
/// use cpose_core::{Order, PoseBatch, PoseField, SinusoidMotion, TimeRange};
///
/// let range = TimeRange::new(0.0, 10.0).expect("start < end");
/// let field = SinusoidMotion::<f64>::handheld(range, 0);
/// let mut out = PoseBatch::default();
/// // Poses and their exact first and second time derivatives, in one batched call.
/// field.evaluate(&[1.0, 2.5], Order::Acceleration, &mut out)?;
/// let pose = out.world_from_body(1); // nalgebra Isometry3, world_from_body at 2.5 s
/// let omega = out.ang_vel_body(1); // rad/s, body frame
/// assert!((out.rotation[1].norm() - 1.0).abs() < 1e-12 && omega.norm().is_finite());
/// # let _ = pose;
/// // Outside its time range a field refuses to extrapolate.
/// assert!(field.evaluate(&[11.0], Order::Pose, &mut out).is_err());
/// # Ok::<(), cpose_core::PoseFieldError>(())
/// ```
pub trait PoseField<S: Real = f32>: Send + Sync {
    /// Times (seconds since the sequence origin) at which the field may be evaluated.
    fn time_range(&self) -> TimeRange;

    /// Total number of parameters over all slices visited by [`PoseField::params`].
    fn num_params(&self) -> usize;

    /// Visits the parameter slices in storage order; gradients use the same flat layout.
    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S]));

    /// Visits the parameter slices mutably, in the same order as [`PoseField::params`].
    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S]));

    /// Advances coarse-to-fine schedules (e.g. PoseNet's `c2f`) to `progress`, the fraction of
    /// training done (0–1). Fields without one ignore it.
    fn set_progress(&mut self, progress: f64) {
        let _ = progress;
    }

    /// Evaluates at `times_secs` up to `order` into `out` (resized). An out-of-range time is an
    /// error. Caches nothing.
    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError>;

    /// As [`PoseField::evaluate`], and keeps what [`PoseField::backward`] needs.
    fn forward(
        &mut self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        self.evaluate(times_secs, order, out)
    }

    /// Accumulates into `param_grad` (length [`PoseField::num_params`]) the gradient of a loss
    /// given its cotangents `grad` with respect to the outputs of the last
    /// [`PoseField::forward`] at the same `times_secs`.
    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError>;
}

/// Copies all parameters into one flat vector (for checkpoints and tests).
pub fn params_to_vec<S: Real>(field: &dyn PoseField<S>) -> Vec<S> {
    let mut all = Vec::with_capacity(field.num_params());
    field.params(&mut |_, p| all.extend_from_slice(p));
    all
}

/// Overwrites all parameters from one flat vector laid out as [`params_to_vec`].
pub fn params_from_slice<S: Real>(
    field: &mut dyn PoseField<S>,
    values: &[S],
) -> Result<(), PoseFieldError> {
    if values.len() != field.num_params() {
        return Err(PoseFieldError::Shape {
            what: "parameters",
            expected: field.num_params(),
            got: values.len(),
        });
    }
    let mut offset = 0;
    field.params_mut(&mut |_, p| {
        p.copy_from_slice(&values[offset..offset + p.len()]);
        offset += p.len();
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quaternion path with known derivatives: q(t) = exp(t·a/2) for a fixed axis-angle rate a.
    fn batch_at(t: f64) -> PoseBatch {
        let a = Vector3::new(0.3, -0.2, 0.5);
        let q = |t: f64| *UnitQuaternion::from_scaled_axis(a * t).quaternion();
        let h = 1e-5;
        let mut b = PoseBatch::zeros(1, Order::Acceleration);
        b.rotation[0] = q(t);
        b.rotation_rate[0] = (q(t + h) - q(t - h)) / (2.0 * h);
        b.rotation_acc[0] = (q(t + h) - q(t) * 2.0 + q(t - h)) / (h * h);
        b
    }

    #[test]
    fn constant_rate_rotation_has_that_body_angular_velocity() {
        let b = batch_at(0.7);
        let w = b.ang_vel_body(0);
        assert!((w - Vector3::new(0.3, -0.2, 0.5)).norm() < 1e-8, "{w}");
        assert!(b.ang_acc_body(0).norm() < 1e-4);
        // For rotation about a fixed axis, body and world angular velocity coincide.
        assert!((b.ang_vel_world(0) - w).norm() < 1e-8);
    }

    #[test]
    fn angular_velocity_gradient_matches_central_differences() {
        let primal = batch_at(0.4);
        let g = Vector3::new(0.7, -1.1, 0.4);
        let mut cot = PoseBatch::zeros(1, Order::Velocity);
        cot.add_ang_vel_body_grad(&primal, 0, &g);
        let loss = |b: &PoseBatch| b.ang_vel_body(0).dot(&g);
        let h = 1e-6;
        for k in 0..4 {
            for rate in [false, true] {
                let mut plus = primal.clone();
                let mut minus = primal.clone();
                let (qp, qm) = if rate {
                    (&mut plus.rotation_rate[0], &mut minus.rotation_rate[0])
                } else {
                    (&mut plus.rotation[0], &mut minus.rotation[0])
                };
                qp.coords[k] += h;
                qm.coords[k] -= h;
                let fd = (loss(&plus) - loss(&minus)) / (2.0 * h);
                let an = if rate {
                    cot.rotation_rate[0].coords[k]
                } else {
                    cot.rotation[0].coords[k]
                };
                assert!(
                    (fd - an).abs() < 1e-7,
                    "component {k} rate={rate}: fd {fd} vs {an}"
                );
            }
        }
    }

    #[test]
    fn out_of_range_time_is_an_error() {
        let r = TimeRange::new(0.0, 1.0).unwrap();
        assert_eq!(check_times(&r, &[0.0, 0.5, 1.0]), Ok(()));
        assert_eq!(
            check_times(&r, &[0.5, 1.5]),
            Err(PoseFieldError::OutOfRange {
                t_secs: 1.5,
                range: r
            })
        );
    }
}
