//! A pose field written outside cpose, registered by name, and used from a config: the whole
//! `cpose` command line plus one new `kind`.
//!
//! `ConstantTurn` is a car-like motion: constant velocity in the world and a constant yaw rate,
//! `p(t) = p₀ + v τ`, `q(t) = (cos ψ/2, 0, 0, sin ψ/2)` with `ψ = ψ₀ + ω τ`, `τ = t − t_start`.
//! Registering it is one `inventory::submit!`; the conformance suite checks it like any built-in
//! field (`cargo test -p cpose-cli --example custom_pose_field`).
//!
//! Run it on the synthetic trajectory:
//!
//! ```text
//! cargo run --release -p cpose-cli --example custom_pose_field -- \
//!     run crates/cpose-cli/examples/custom_pose_field.toml
//! ```

use std::process::ExitCode;

use cpose_core::config::{ConfigError, Section};
use cpose_core::pose_field::check_times;
use cpose_core::registry::{FieldContext, PoseFieldSpec};
use cpose_core::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, Real, TimeRange};
use nalgebra::{Quaternion, Vector3};

/// Constant velocity and yaw rate; parameters `[p₀ (3), v (3), ψ₀, ω]`, all zero at the start.
struct ConstantTurn<S> {
    range: TimeRange,
    params: [S; 8],
}

impl<S: Real> ConstantTurn<S> {
    fn new(range: TimeRange) -> Self {
        Self {
            range,
            params: [S::ZERO; 8],
        }
    }

    fn p(&self, k: usize) -> f64 {
        self.params[k].to_f64()
    }
}

impl<S: Real> PoseField<S> for ConstantTurn<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        8
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        visit(ParamKind::Pose, &self.params);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        visit(ParamKind::Pose, &mut self.params);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        out.reset(times_secs.len(), order);
        let p0 = Vector3::new(self.p(0), self.p(1), self.p(2));
        let v = Vector3::new(self.p(3), self.p(4), self.p(5));
        let (psi0, omega) = (self.p(6), self.p(7));
        for (i, &t) in times_secs.iter().enumerate() {
            let tau = t - self.range.start_secs;
            let (s, c) = ((psi0 + omega * tau) / 2.0).sin_cos();
            let q = Quaternion::new(c, 0.0, 0.0, s);
            let dq_dpsi = Quaternion::new(-s, 0.0, 0.0, c) * 0.5;
            out.rotation[i] = q;
            out.translation[i] = p0 + v * tau;
            if order >= Order::Velocity {
                out.rotation_rate[i] = dq_dpsi * omega;
                out.lin_vel_world[i] = v;
            }
            if order >= Order::Acceleration {
                out.rotation_acc[i] = q * (-omega * omega / 4.0);
                out.lin_acc_world[i] = Vector3::zeros();
            }
        }
        Ok(())
    }

    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        let (psi0, omega) = (self.p(6), self.p(7));
        let mut g = [0.0f64; 8];
        let dot = |a: &Quaternion<f64>, b: &Quaternion<f64>| a.coords.dot(&b.coords);
        for (i, &t) in times_secs.iter().enumerate() {
            let tau = t - self.range.start_secs;
            let (s, c) = ((psi0 + omega * tau) / 2.0).sin_cos();
            let q = Quaternion::new(c, 0.0, 0.0, s);
            let q1 = Quaternion::new(-s, 0.0, 0.0, c) * 0.5; // dq/dψ
            // ∂(q, q̇, q̈)/∂ψ = (q₁, −ω/4 q, −ω²/4 q₁); ∂q̇/∂ω = q₁ + τ ∂q̇/∂ψ; ∂q̈/∂ω = −ω/2 q + τ ∂q̈/∂ψ.
            let mut d_psi = dot(&grad.rotation[i], &q1);
            let mut d_omega = tau * d_psi;
            for k in 0..3 {
                g[k] += grad.translation[i][k];
                g[3 + k] += grad.translation[i][k] * tau;
            }
            if let (Some(gq), Some(gv)) = (grad.rotation_rate.get(i), grad.lin_vel_world.get(i)) {
                let d = dot(gq, &(q * (-omega / 4.0)));
                d_psi += d;
                d_omega += dot(gq, &q1) + tau * d;
                (0..3).for_each(|k| g[3 + k] += gv[k]);
            }
            if let Some(gq) = grad.rotation_acc.get(i) {
                let d = dot(gq, &(q1 * (-omega * omega / 4.0)));
                d_psi += d;
                d_omega += dot(gq, &(q * (-omega / 2.0))) + tau * d;
            }
            g[6] += d_psi;
            g[7] += d_omega;
        }
        for (acc, gk) in param_grad.iter_mut().zip(g) {
            *acc += S::from_f64(gk);
        }
        Ok(())
    }
}

/// `kind = "constant_turn"` takes no other keys.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ConstantTurnTable {}

fn build(section: &Section<'_>, ctx: &FieldContext) -> Result<Box<dyn PoseField>, ConfigError> {
    let ConstantTurnTable {} = section.decode_params()?;
    Ok(Box::new(ConstantTurn::<f32>::new(ctx.time_range)))
}

inventory::submit! {
    PoseFieldSpec { name: "constant_turn", about: "example: constant velocity and yaw rate (examples/custom_pose_field.rs)", build }
}

fn main() -> ExitCode {
    cpose_cli::main_with_args(std::env::args_os())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_the_conformance_suite() {
        let range = TimeRange::new(1.0, 4.0).unwrap();
        let mut field = ConstantTurn::<f64>::new(range);
        field.params = [0.3, -0.2, 1.0, 0.5, 0.1, -0.3, 0.4, 0.9];
        cpose_core::testing::check_pose_field(&mut field, &[1.0, 1.7, 2.5, 3.9]);
    }

    #[test]
    fn is_registered_next_to_the_builtins() {
        let names: Vec<_> = cpose_core::registry::pose_fields()
            .iter()
            .map(|f| f.name)
            .collect();
        assert!(
            names.contains(&"constant_turn") && names.contains(&"posenet"),
            "{names:?}"
        );
    }
}
