//! The three pose models of the planar study, sharing one interface: current warp parameters of
//! every patch, and one optimiser step from their gradients.
//!
//! - `posenet`: a [`PoseField`] of time (PoseNet by default) whose SE(2) part gives the patch
//!   motions: the twist of its rotation about the optical axis (swing–twist decomposition,
//!   `θ = 2 atan2(q_z, q_w)`) and its `x, y` translation, taken relative to their mean:
//!   `W_i = P̄⁻¹ ∘ P(t_i)` with `P̄ = (mean θ, mean t)`. A motion common to all patches then
//!   changes nothing, so the neural image's frame cannot drift with the poses; the evaluation
//!   expresses all warps relative to the first patch, `W_0⁻¹ ∘ W_i` (BARF's gauge). Anchoring
//!   to the first patch during training instead (`P(t_0)⁻¹ ∘ P(t_i)`, or `W_0` held at the
//!   identity) leaves the whole sequence to one patch's data and falls into minima where every
//!   other patch shares one offset.
//! - `barf`: free warp parameters per patch, zero at the start, the first patch held at zero
//!   (BARF's `warp_param[0] = 0` after every step).
//! - `spline`: `barf` whose parameters are replaced every `reset_every` steps by their
//!   least-squares cubic B-spline over the patch times (the paper's "BaRF with B-spline").

use cpose_core::nn::Adam;

use super::motion::relative_se2;
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, TimeRange, smooth_with_cubic_spline};
use nalgebra::Quaternion;

use crate::warp2d::WarpKind;

/// Learning rates of the pose models (constant, as BARF's planar experiment).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRates {
    /// Translation (and PoseNet's translation network).
    pub translation: f64,
    /// Rotation (and PoseNet's rotation network).
    pub rotation: f64,
    /// Every homography parameter.
    pub homography: f64,
}

impl PoseRates {
    /// All rates zero (a model that does not move).
    pub const ZERO: Self = Self {
        translation: 0.0,
        rotation: 0.0,
        homography: 0.0,
    };
}

/// The spline reset of the B-spline baseline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplineReset {
    /// Control points of the cubic B-spline (the paper: 5).
    pub control_points: usize,
    /// Steps between resets (the paper: 100).
    pub every: usize,
}

/// A pose model: warp parameters per patch, updated from their gradients.
pub trait PoseModel: Send {
    /// The warp parameters of every patch (`kind.dim()` each, patch-major) into `out`, at
    /// `progress` (fraction of training done) of the model's coarse-to-fine schedule.
    fn warps(&mut self, out: &mut Vec<f64>, progress: f64) -> anyhow::Result<()>;

    /// One optimiser step from `grad` (`∂L/∂` the output of the last [`PoseModel::warps`]) at
    /// step `it` (0-based).
    fn step(&mut self, grad: &[f64], it: usize) -> anyhow::Result<()>;
}

/// SE(2) motions from a pose field evaluated at the patch times (`posenet`).
pub struct FieldModel {
    field: Box<dyn PoseField>,
    times: Vec<f64>,
    adam: Adam<f32>,
    rates: PoseRates,
    poses: PoseBatch,
    cotangent: PoseBatch,
    grad: Vec<f32>,
    /// `[θ, tx, ty]` of every `P(t_i)` and their mean, from the last evaluation.
    absolute: Vec<[f64; 3]>,
    mean: [f64; 3],
    /// Gradient with respect to `absolute` (reused).
    g_abs: Vec<[f64; 3]>,
}

impl FieldModel {
    /// A model over `field`, queried at the patch `times`.
    pub fn new(field: Box<dyn PoseField>, times: Vec<f64>, rates: PoseRates) -> Self {
        let n = field.num_params();
        Self {
            field,
            times,
            adam: Adam::new(n),
            rates,
            poses: PoseBatch::default(),
            cotangent: PoseBatch::default(),
            grad: vec![0.0; n],
            absolute: Vec::new(),
            mean: [0.0; 3],
            g_abs: Vec::new(),
        }
    }
}

impl PoseModel for FieldModel {
    fn warps(&mut self, out: &mut Vec<f64>, progress: f64) -> anyhow::Result<()> {
        self.field.set_progress(progress);
        self.field
            .forward(&self.times, Order::Pose, &mut self.poses)?;
        let n = self.times.len();
        self.absolute.clear();
        self.absolute.extend((0..n).map(|i| {
            let (q, t) = (self.poses.rotation[i], self.poses.translation[i]);
            [2.0 * q.k.atan2(q.w), t.x, t.y]
        }));
        self.mean = [0.0; 3];
        for p in &self.absolute {
            for c in 0..3 {
                self.mean[c] += p[c] / n as f64;
            }
        }
        out.clear();
        for p in &self.absolute {
            out.extend_from_slice(&relative_se2(&self.mean, p));
        }
        Ok(())
    }

    /// Back-propagates `∂L/∂W_i = (g_θ, g_t)` through the mean gauge and the twist angle, then
    /// steps. With `W_i = (θ_i − θ̄, R(−θ̄)(t_i − t̄))`, `u_i = R(θ̄) g_t,i` and
    /// `J = [[0, −1], [1, 0]]`: `∂L/∂θ_i = g_θ,i`, `∂L/∂t_i = u_i`,
    /// `∂L/∂θ̄ = −Σ_i (g_θ,i + g_t,iᵀ J W_t,i)`, `∂L/∂t̄ = −Σ_i u_i`, each shared `1/N` by every
    /// patch through the mean. Then `θ = 2 atan2(q_z, q_w)`: `∂θ/∂q_w = −2 q_z/(q_w² + q_z²)`,
    /// `∂θ/∂q_z = 2 q_w/(q_w² + q_z²)`.
    fn step(&mut self, grad: &[f64], _it: usize) -> anyhow::Result<()> {
        let n = self.times.len();
        let (s, c) = self.mean[0].sin_cos();
        let mut g_abs = std::mem::take(&mut self.g_abs);
        g_abs.clear();
        let mut g_mean = [0.0f64; 3];
        for (g, p) in grad.chunks(3).zip(&self.absolute) {
            let w = relative_se2(&self.mean, p);
            let u = [c * g[1] - s * g[2], s * g[1] + c * g[2]];
            g_abs.push([g[0], u[0], u[1]]);
            g_mean[0] -= g[0] + (-g[1] * w[2] + g[2] * w[1]);
            g_mean[1] -= u[0];
            g_mean[2] -= u[1];
        }
        self.cotangent.clone_from(&self.poses);
        clear_derivatives(&mut self.cotangent);
        for (i, g) in g_abs.iter().enumerate() {
            let g: [f64; 3] = std::array::from_fn(|k| g[k] + g_mean[k] / n as f64);
            let q = self.poses.rotation[i];
            let gq = g[0] / (q.w * q.w + q.k * q.k).max(f64::MIN_POSITIVE);
            self.cotangent.rotation[i] = Quaternion::new(-2.0 * q.k * gq, 0.0, 0.0, 2.0 * q.w * gq);
            self.cotangent.translation[i] = nalgebra::Vector3::new(g[1], g[2], 0.0);
        }
        self.g_abs = g_abs;
        self.grad.fill(0.0);
        self.field
            .backward(&self.times, &self.cotangent, &mut self.grad)?;
        let rates = self.rates;
        self.adam
            .step_pose_field(self.field.as_mut(), &self.grad, |kind| match kind {
                ParamKind::Rotation => rates.rotation,
                ParamKind::Translation | ParamKind::Pose => rates.translation,
            });
        Ok(())
    }
}

/// Empties the derivative streams of a cotangent (only the pose is supervised).
fn clear_derivatives(c: &mut PoseBatch) {
    c.rotation_rate.clear();
    c.rotation_acc.clear();
    c.lin_vel_world.clear();
    c.lin_acc_world.clear();
}

/// Per-patch warp parameters (`barf`), optionally reset to a spline (`spline`).
pub struct FreeModel {
    kind: WarpKind,
    params: Vec<f64>,
    adam: Adam<f64>,
    rates: PoseRates,
    times: Vec<f64>,
    range: TimeRange,
    reset: Option<SplineReset>,
    grad: Vec<f64>,
}

impl FreeModel {
    /// Zero warps (identity) for the patches at `times` over `range`.
    pub fn new(
        kind: WarpKind,
        times: Vec<f64>,
        range: TimeRange,
        rates: PoseRates,
        reset: Option<SplineReset>,
    ) -> Self {
        let n = kind.dim() * times.len();
        Self {
            kind,
            params: vec![0.0; n],
            adam: Adam::new(n),
            rates,
            times,
            range,
            reset,
            grad: vec![0.0; n],
        }
    }

    /// Checks that the spline reset is possible for these patches.
    pub fn check(&self) -> Result<(), String> {
        if let Some(reset) = self.reset {
            let mut probe = self.params.clone();
            smooth_with_cubic_spline(
                self.range,
                reset.control_points,
                &self.times,
                &mut probe,
                self.kind.dim(),
            )
            .map_err(|e| format!("spline reset: {e}"))?;
            if reset.every == 0 {
                return Err("spline reset: reset_every must be ≥ 1".into());
            }
        }
        Ok(())
    }
}

impl PoseModel for FreeModel {
    fn warps(&mut self, out: &mut Vec<f64>, _progress: f64) -> anyhow::Result<()> {
        out.clear();
        out.extend_from_slice(&self.params);
        Ok(())
    }

    fn step(&mut self, grad: &[f64], it: usize) -> anyhow::Result<()> {
        let k = self.kind.dim();
        self.grad.copy_from_slice(grad);
        self.grad[..k].fill(0.0);
        self.adam.begin_step();
        let n = self.times.len();
        for i in 0..n {
            for c in 0..k {
                let lr = match (self.kind, c) {
                    (WarpKind::Se2, 0) => self.rates.rotation,
                    (WarpKind::Se2, _) => self.rates.translation,
                    (WarpKind::Homography, _) => self.rates.homography,
                };
                let j = i * k + c;
                self.adam
                    .update(j, &mut self.params[j..=j], &self.grad[j..=j], lr);
            }
        }
        if let Some(reset) = self.reset
            && (it + 1).is_multiple_of(reset.every)
        {
            // The spline is fitted through every patch; a failure (too few patches for the
            // control points) is caught when the model is built.
            if smooth_with_cubic_spline(
                self.range,
                reset.control_points,
                &self.times,
                &mut self.params,
                k,
            )
            .is_ok()
            {
                self.params[..k].fill(0.0);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::PoseNetConfig;

    fn rates() -> PoseRates {
        PoseRates {
            translation: 1e-3,
            rotation: 2e-4,
            homography: 1e-3,
        }
    }

    /// The analytic gradient of a linear loss on the warps through the pose field
    /// matches central differences of the same loss in a few network parameters (f32 field,
    /// so a loose tolerance).
    #[test]
    fn field_model_gradient_matches_finite_differences() {
        use cpose_core::pose_field::{params_from_slice, params_to_vec};
        let times: Vec<f64> = (0..5).map(|i| i as f64 * 2.0).collect();
        let range = TimeRange {
            start_secs: 0.0,
            end_secs: 8.0,
        };
        let config = PoseNetConfig {
            width: 16,
            depth: 3,
            skip_layer: 0,
            seed: 7,
            ..PoseNetConfig::default()
        };
        let mut net = config.init::<f32>(range).unwrap();
        // Move the output layers off their near-zero start so the warps are not trivial.
        let mut p = params_to_vec(&net);
        for (j, v) in p.iter_mut().enumerate() {
            *v += 0.05 * ((j * 37 % 11) as f32 / 11.0 - 0.5);
        }
        params_from_slice(&mut net, &p).unwrap();
        let weights: Vec<f64> = (0..15).map(|j| ((j * 7 % 5) as f64 - 2.0) * 0.3).collect();
        let loss = |params: &[f32]| -> f64 {
            let mut field = net.clone();
            params_from_slice(&mut field, params).unwrap();
            let mut m = FieldModel::new(Box::new(field), times.clone(), rates());
            let mut w = Vec::new();
            m.warps(&mut w, 1.0).unwrap();
            w.iter().zip(&weights).map(|(a, b)| a * b).sum()
        };
        // Zero learning rates: the step only fills `grad`.
        let mut model = FieldModel::new(Box::new(net.clone()), times.clone(), PoseRates::ZERO);
        model.warps(&mut Vec::new(), 1.0).unwrap();
        model.step(&weights, 0).unwrap();
        let n = p.len();
        for j in [0, n / 7, n / 3, n / 2, n - 5, n - 1] {
            let h = 1e-2f32;
            let (mut plus, mut minus) = (p.clone(), p.clone());
            plus[j] += h;
            minus[j] -= h;
            let fd = (loss(&plus) - loss(&minus)) / (2.0 * h as f64);
            let an = model.grad[j] as f64;
            assert!(
                (fd - an).abs() <= 2e-3 + 2e-2 * an.abs().max(fd.abs()),
                "param {j}: fd {fd} vs analytic {an}"
            );
        }
    }

    #[test]
    fn free_model_keeps_the_first_patch_and_resets_to_a_spline() {
        let times: Vec<f64> = (0..7).map(|i| i as f64 * 1.5).collect();
        let range = TimeRange {
            start_secs: 0.0,
            end_secs: 9.0,
        };
        let reset = SplineReset {
            control_points: 5,
            every: 2,
        };
        let mut m = FreeModel::new(WarpKind::Se2, times, range, rates(), Some(reset));
        m.check().unwrap();
        let grad: Vec<f64> = (0..21)
            .map(|j| if j % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        m.step(&grad, 0).unwrap();
        assert!(m.params[..3].iter().all(|&v| v == 0.0));
        assert!(m.params[3] > 0.0, "moves against its gradient (−1)");
        let before = m.params.clone();
        m.step(&grad, 1).unwrap(); // reset after this step
        assert!(m.params[..3].iter().all(|&v| v == 0.0));
        assert_ne!(before, m.params);
        let bad = FreeModel::new(WarpKind::Se2, vec![0.0, 9.0], range, rates(), Some(reset));
        assert!(
            bad.check().is_err(),
            "two patches cannot carry five control points"
        );
    }
}
