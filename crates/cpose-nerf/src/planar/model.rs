//! The three pose models of the planar study, sharing one interface: current warp parameters of
//! every patch, and one optimiser step from their gradients.
//!
//! - `posenet`: a [`PoseField`] of time (PoseNet by default) whose SE(2) part gives the patch
//!   motions: the twist of its rotation about the optical axis (swing–twist decomposition,
//!   `θ = 2 atan2(q_z, q_w)`) and its `x, y` translation. The patch warps are taken relative to
//!   the first patch, `W_i = P(t_0)⁻¹ ∘ P(t_i)`, which fixes the gauge without special cases.
//! - `barf`: free warp parameters per patch, zero at the start, the first patch held at zero
//!   (BARF's `warp_param[0] = 0` after every step).
//! - `spline`: `barf` whose parameters are replaced every `reset_every` steps by their
//!   least-squares cubic B-spline over the patch times (the paper's "BaRF with B-spline").

use cpose_core::nn::Adam;
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, TimeRange, smooth_with_cubic_spline};
use nalgebra::Quaternion;

use super::motion::relative_se2;
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
pub enum PoseModel {
    /// A continuous pose field of time.
    Field(FieldModel),
    /// Free parameters per patch (BARF), optionally reset to a spline.
    Free(FreeModel),
}

impl PoseModel {
    /// The warp parameters of every patch (`kind.dim()` each, patch-major) into `out`.
    pub fn warps(&mut self, out: &mut Vec<f64>) -> anyhow::Result<()> {
        match self {
            Self::Field(m) => m.warps(out),
            Self::Free(m) => {
                out.clear();
                out.extend_from_slice(&m.params);
                Ok(())
            }
        }
    }

    /// One optimiser step from `grad` (`∂L/∂` the output of [`PoseModel::warps`]) at step `it`
    /// (0-based).
    pub fn step(&mut self, grad: &[f64], it: usize) -> anyhow::Result<()> {
        match self {
            Self::Field(m) => m.step(grad),
            Self::Free(m) => {
                m.step(grad, it);
                Ok(())
            }
        }
    }
}

/// [`PoseModel::Field`]: SE(2) motions from a pose field evaluated at the patch times.
pub struct FieldModel {
    field: Box<dyn PoseField>,
    times: Vec<f64>,
    adam: Adam<f32>,
    rates: PoseRates,
    poses: PoseBatch,
    cotangent: PoseBatch,
    grad: Vec<f32>,
    /// `[θ, tx, ty]` of every `P(t_i)` of the last evaluation.
    absolute: Vec<[f64; 3]>,
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
        }
    }

    fn warps(&mut self, out: &mut Vec<f64>) -> anyhow::Result<()> {
        self.field
            .forward(&self.times, Order::Pose, &mut self.poses)?;
        self.absolute.clear();
        for i in 0..self.times.len() {
            let q = self.poses.rotation[i];
            let t = self.poses.translation[i];
            self.absolute
                .push([2.0 * q.k.atan2(q.w), t.x, t.y]);
        }
        out.clear();
        for g in &self.absolute {
            out.extend_from_slice(&relative_se2(&self.absolute[0], g));
        }
        Ok(())
    }

    /// Back-propagates `∂L/∂W_i` through `W_i = P_0⁻¹ ∘ P_i` and the twist angle, then steps.
    ///
    /// With `W_i = (θ_i − θ_0, R(−θ_0)(t_i − t_0))` and `J = [[0, −1], [1, 0]]`:
    /// `∂/∂θ_i = g_θ`, `∂/∂t_i = R(θ_0) g_t`, `∂/∂θ_0 −= g_θ + g_tᵀ J t_rel`,
    /// `∂/∂t_0 −= R(θ_0) g_t`; and `θ = 2 atan2(q_z, q_w)` gives
    /// `∂θ/∂q_w = −2 q_z/(q_w² + q_z²)`, `∂θ/∂q_z = 2 q_w/(q_w² + q_z²)`.
    fn step(&mut self, grad: &[f64]) -> anyhow::Result<()> {
        let n = self.times.len();
        let mut g_abs = vec![[0.0f64; 3]; n];
        let theta0 = self.absolute[0][0];
        let (s0, c0) = theta0.sin_cos();
        for i in 0..n {
            let g = &grad[3 * i..3 * i + 3];
            let rel = relative_se2(&self.absolute[0], &self.absolute[i]);
            let gt = [c0 * g[1] - s0 * g[2], s0 * g[1] + c0 * g[2]];
            g_abs[i][0] += g[0];
            g_abs[i][1] += gt[0];
            g_abs[i][2] += gt[1];
            // J t_rel = (−t_rel_y, t_rel_x)
            g_abs[0][0] -= g[0] + (g[1] * -rel[2] + g[2] * rel[1]);
            g_abs[0][1] -= gt[0];
            g_abs[0][2] -= gt[1];
        }
        self.cotangent.clone_from(&self.poses);
        for i in 0..n {
            let q = self.poses.rotation[i];
            let r2 = q.w * q.w + q.k * q.k;
            let gq = g_abs[i][0] / r2.max(1e-300);
            self.cotangent.rotation[i] = Quaternion::new(-2.0 * q.k * gq, 0.0, 0.0, 2.0 * q.w * gq);
            self.cotangent.translation[i] = nalgebra::Vector3::new(g_abs[i][1], g_abs[i][2], 0.0);
        }
        clear_derivatives(&mut self.cotangent);
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

/// [`PoseModel::Free`]: per-patch warp parameters (BARF), optionally reset to a spline.
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

    fn step(&mut self, grad: &[f64], it: usize) {
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
            && (it + 1) % reset.every == 0
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

    /// The analytic gradient of a linear loss on the relative warps through the pose field
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
            m.warps(&mut w).unwrap();
            w.iter().zip(&weights).map(|(a, b)| a * b).sum()
        };
        // Zero learning rates: the step only fills `grad`.
        let mut model = FieldModel::new(Box::new(net.clone()), times.clone(), PoseRates::ZERO);
        model.warps(&mut Vec::new()).unwrap();
        model.step(&weights).unwrap();
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
        let grad: Vec<f64> = (0..21).map(|j| if j % 2 == 0 { 1.0 } else { -1.0 }).collect();
        m.step(&grad, 0);
        assert!(m.params[..3].iter().all(|&v| v == 0.0));
        assert!(m.params[3] < 0.0, "descends");
        let before = m.params.clone();
        m.step(&grad, 1); // reset after this step
        assert!(m.params[..3].iter().all(|&v| v == 0.0));
        assert_ne!(before, m.params);
        let bad = FreeModel::new(
            WarpKind::Se2,
            vec![0.0, 9.0],
            range,
            rates(),
            Some(reset),
        );
        assert!(bad.check().is_err(), "two patches cannot carry five control points");
    }
}
