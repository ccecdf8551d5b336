//! Losses that supervise a pose field with poses and IMU readings, each returning its value and
//! accumulating its gradient with respect to the field's outputs (a cotangent [`PoseBatch`],
//! which [`crate::PoseField::backward`] takes to the parameters).
//!
//! All losses are means over their samples, times a weight.

use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};

use super::ImuSample;
use crate::PoseBatch;
use crate::nn::l1_subgradient;

/// The sign of each component, 0 at 0 (the L1 subgradient).
fn sign_q(q: &Quaternion<f64>) -> Quaternion<f64> {
    Quaternion::new(
        l1_subgradient(q.w),
        l1_subgradient(q.i),
        l1_subgradient(q.j),
        l1_subgradient(q.k),
    )
}
fn sign_v(v: &Vector3<f64>) -> Vector3<f64> {
    v.map(l1_subgradient)
}
fn l1_q(q: &Quaternion<f64>) -> f64 {
    q.coords.abs().sum()
}

/// Squared pose error against target poses:
/// `L = w/n Σ_i (|q_i − s_i q̂_i|² / ρ² + |p_i − p̂_i|² / σ²)`, where `s_i = ±1` aligns the
/// target quaternion's sign with the estimate (q and −q are the same rotation) and `ρ`
/// (quaternion units) and `σ` (metres) are the errors that cost one unit each.
pub fn pose_l2(
    out: &PoseBatch,
    targets: &[Isometry3<f64>],
    weight: f64,
    (rho, sigma): (f64, f64),
    grad: &mut PoseBatch,
) -> f64 {
    let n = targets.len() as f64;
    let (inv_r2, inv_s2) = (1.0 / (rho * rho), 1.0 / (sigma * sigma));
    let mut loss = 0.0;
    for (i, target) in targets.iter().enumerate() {
        let q = out.rotation[i];
        let mut qt = *target.rotation.quaternion();
        if q.coords.dot(&qt.coords) < 0.0 {
            qt = -qt;
        }
        let dq = q - qt;
        let dp = out.translation[i] - target.translation.vector;
        loss += dq.norm_squared() * inv_r2 + dp.norm_squared() * inv_s2;
        grad.rotation[i] += dq * (2.0 * weight * inv_r2 / n);
        grad.translation[i] += dp * (2.0 * weight * inv_s2 / n);
    }
    weight * loss / n
}

/// The paper's tight gyroscope coupling (§3.4, "Tight coupling"):
/// `L = w/n Σ_i |q̇_i − ½ q_i ⊗ (0, ω_i)|₁`, with `ω_i` the measured body angular velocity
/// (bias removed) at the field's evaluation times.
///
/// Gradient: with `r = q̇ − ½ q ⊗ e`, `e = (0, ω)` and `s = sign(r)`,
/// `∂L/∂q̇ = w s / n` and `∂L/∂q = −½ w (s ⊗ e*) / n` (because `⟨s, q ⊗ e⟩ = ⟨s ⊗ e*, q⟩`).
pub fn gyro_tight_l1(
    out: &PoseBatch,
    gyro_body: &[Vector3<f64>],
    weight: f64,
    grad: &mut PoseBatch,
) -> f64 {
    let rates = gyro_body.iter().map(|w| (*w, Vector3::zeros()));
    rate_l1(out, rates, weight, grad)
}

/// `L = w/n Σ_i |q̇_i − ½ (q_i ⊗ e_i − e₀ᵢ ⊗ q_i)|₁` over `(ω_i, ω₀ᵢ)`, `e = (0, ω)`,
/// `e₀ = (0, ω₀)`: [`gyro_tight_l1`] (`ω₀ = 0`) and the increment loss of `cpose-imu`'s relative
/// tracker. Gradient: with
/// `s = sign(r)`, `∂L/∂q̇ = w s/n` and `∂L/∂q = w (s ⊗ e − e₀ ⊗ s)/(2n)`
/// (`⟨s, q ⊗ e⟩ = ⟨s ⊗ e*, q⟩`, `⟨s, e₀ ⊗ q⟩ = ⟨e₀* ⊗ s, q⟩`, `e* = −e`).
pub fn rate_l1(
    out: &PoseBatch,
    rates: impl ExactSizeIterator<Item = (Vector3<f64>, Vector3<f64>)>,
    weight: f64,
    grad: &mut PoseBatch,
) -> f64 {
    let n = rates.len() as f64;
    let mut loss = 0.0;
    for (i, (w, w0)) in rates.enumerate() {
        let (e, e0) = (Quaternion::from_imag(w), Quaternion::from_imag(w0));
        let q = out.rotation[i];
        let residual = out.rotation_rate[i] - (q * e - e0 * q) * 0.5;
        loss += l1_q(&residual);
        let s = sign_q(&residual) * (weight / n);
        grad.rotation_rate[i] += s;
        grad.rotation[i] += (s * e - e0 * s) * 0.5;
    }
    weight * loss / n
}

/// The rotation the gyroscope measures from `t0` to `t1`: `Δq = Π_k Exp(ω_k Δt_k)` over the
/// readings' intervals clipped to `[t0, t1]`, each interval rotating at the mean of its two
/// readings (right-multiplied: body-frame rates). `imu` must be sorted by time and cover
/// `[t0, t1]`; `None` otherwise.
pub fn integrate_gyro(imu: &[ImuSample], t0: f64, t1: f64) -> Option<UnitQuaternion<f64>> {
    integrate_gyro_minus(imu, t0, t1, &Vector3::zeros())
}

/// [`integrate_gyro`] of the readings minus a constant `bias` (rad/s); bit for bit the same for
/// a zero bias.
pub fn integrate_gyro_minus(
    imu: &[ImuSample],
    t0: f64,
    t1: f64,
    bias: &Vector3<f64>,
) -> Option<UnitQuaternion<f64>> {
    let twice = bias * 2.0;
    Some(clipped_intervals(imu, t0, t1)?.fold(
        UnitQuaternion::identity(),
        |dq, (a, b, from, to)| {
            dq * UnitQuaternion::from_scaled_axis((a.gyro + b.gyro - twice) * (0.5 * (to - from)))
        },
    ))
}

/// The intervals between consecutive readings clipped to `[t0, t1]`, in order, as `(a, b, from,
/// to)` with `from < to` the clipped ends; `None` unless `imu` (sorted by time) covers
/// `[t0, t1]`, `t0 ≤ t1`.
pub fn clipped_intervals(
    imu: &[ImuSample],
    t0: f64,
    t1: f64,
) -> Option<impl Iterator<Item = (&ImuSample, &ImuSample, f64, f64)>> {
    let (first, last) = (imu.first()?, imu.last()?);
    if !(t0 <= t1 && first.t_secs <= t0 && t1 <= last.t_secs) {
        return None;
    }
    let start = imu.partition_point(|s| s.t_secs <= t0).max(1) - 1;
    Some(
        imu[start..]
            .windows(2)
            .take_while(move |pair| pair[0].t_secs < t1)
            .filter_map(move |pair| {
                let (from, to) = (pair[0].t_secs.max(t0), pair[1].t_secs.min(t1));
                (to > from).then_some((&pair[0], &pair[1], from, to))
            }),
    )
}

/// The paper's loose gyroscope coupling (§3.4, "Loose coupling"): the rotation integrated from
/// the gyroscope between two evaluation times supervises the field's rotations there,
/// `L = w/n Σ_(a,b) |q_b − s q_a ⊗ Δq_ab|₁` over `pairs = (a, b, Δq_ab)` of batch indices,
/// with `s = ±1` aligning the prediction's sign with `q_b`.
///
/// Gradient: with `r = q_b − s q_a ⊗ Δq` and `S = sign(r)`, `∂L/∂q_b = w S / n` and
/// `∂L/∂q_a = −s w (S ⊗ Δq*) / n` (because `⟨S, q_a ⊗ Δq⟩ = ⟨S ⊗ Δq*, q_a⟩`).
pub fn gyro_loose_l1(
    out: &PoseBatch,
    pairs: &[(usize, usize, UnitQuaternion<f64>)],
    weight: f64,
    grad: &mut PoseBatch,
) -> f64 {
    let n = pairs.len() as f64;
    let mut loss = 0.0;
    for (a, b, dq) in pairs {
        let dq = dq.quaternion();
        let predicted = out.rotation[*a] * dq;
        let s = if predicted.coords.dot(&out.rotation[*b].coords) < 0.0 {
            -1.0
        } else {
            1.0
        };
        let r = out.rotation[*b] - predicted * s;
        loss += l1_q(&r);
        let g = sign_q(&r) * (weight / n);
        grad.rotation[*b] += g;
        grad.rotation[*a] -= g * dq.conjugate() * s;
    }
    weight * loss / n
}

/// Accelerometer supervision through the second derivative (paper supplement, "Full IMU
/// fusion"): `L = w/n Σ_i |R_iᵀ (scale · p̈_i − g_world) − f_i|₁`, with `f_i` the measured
/// specific force (bias removed) and `scale` the metres per unit of the field's translation
/// (the field may work in normalised coordinates). Gravity is removed in the world frame, where
/// its direction is known, rather than estimated.
///
/// Gradient: with `a = scale·p̈ − g`, `f̂ = Rᵀ a = vec(q* ⊗ (0, a) ⊗ q)` for unit `q` and
/// `s = sign(f̂ − f)`: `∂L/∂p̈ = w·scale·R s / n`, and `∂L/∂q = −2 w (0,a) ⊗ q ⊗ (0,s) / n`
/// from the product rule on `q* ⊗ A ⊗ q` (both factors contribute `−A ⊗ q ⊗ S`, as `A* = −A`).
pub fn accel_l1(
    out: &PoseBatch,
    accel_body: &[Vector3<f64>],
    gravity_world: &Vector3<f64>,
    scale: f64,
    weight: f64,
    grad: &mut PoseBatch,
) -> f64 {
    let n = accel_body.len() as f64;
    let mut loss = 0.0;
    for (i, f) in accel_body.iter().enumerate() {
        let q = out.rotation[i];
        let a = out.lin_acc_world[i] * scale - gravity_world;
        let qa = Quaternion::from_imag(a);
        let predicted = (q.conjugate() * qa * q).imag();
        let residual = predicted - f;
        loss += residual.abs().sum();
        let s = sign_v(&residual) * (weight / n);
        let r = UnitQuaternion::new_normalize(q);
        grad.lin_acc_world[i] += r * s * scale;
        grad.rotation[i] -= qa * q * Quaternion::from_imag(s) * 2.0;
    }
    weight * loss / n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Order;
    use crate::testing::{arbitrary_batch, check_batch_loss_gradient};
    use nalgebra::Translation3;

    #[test]
    fn pose_loss_gradient() {
        let targets: Vec<_> = (0..3)
            .map(|i| {
                Isometry3::from_parts(
                    Translation3::new(0.1 * i as f64, 0.3, -0.2),
                    UnitQuaternion::from_scaled_axis(Vector3::new(0.2, 0.1 * i as f64, -0.6)),
                )
            })
            .collect();
        check_batch_loss_gradient(|b, g| pose_l2(b, &targets, 0.7, (0.3, 0.5), g));
    }

    #[test]
    fn gyro_loss_gradient_and_zero_at_consistent_rates() {
        let gyro = [
            Vector3::new(0.3, -0.1, 0.8),
            Vector3::new(-0.5, 0.2, 0.1),
            Vector3::new(0.05, 0.4, -0.3),
        ];
        check_batch_loss_gradient(|b, g| gyro_tight_l1(b, &gyro, 1.3, g));
        // q̇ = ½ q ⊗ (0, ω) makes the loss vanish.
        let mut b = arbitrary_batch();
        for i in 0..3 {
            b.rotation_rate[i] = b.rotation[i] * Quaternion::from_imag(gyro[i]) * 0.5;
            assert!((b.ang_vel_body(i) - gyro[i]).norm() < 1e-12);
        }
        assert!(gyro_tight_l1(&b, &gyro, 1.0, &mut PoseBatch::zeros(3, Order::Velocity)) < 1e-15);
    }

    #[test]
    fn loose_gyro_loss_gradient_and_zero_for_the_integrated_rotation() {
        let pairs = [
            (
                0,
                1,
                UnitQuaternion::from_scaled_axis(Vector3::new(0.1, -0.3, 0.2)),
            ),
            (
                1,
                2,
                UnitQuaternion::from_scaled_axis(Vector3::new(-0.2, 0.05, 0.4)),
            ),
            // A pair whose prediction has the opposite sign from q_b.
            (
                2,
                0,
                UnitQuaternion::from_scaled_axis(Vector3::new(2.9, 0.3, -0.1)),
            ),
        ];
        check_batch_loss_gradient(|b, g| gyro_loose_l1(b, &pairs, 0.8, g));
        // q_b = q_a ⊗ Δq (up to sign) makes it vanish.
        let mut b = arbitrary_batch();
        b.rotation[1] = -(b.rotation[0] * pairs[0].2.quaternion());
        assert!(gyro_loose_l1(&b, &pairs[..1], 1.0, &mut PoseBatch::zeros(3, Order::Pose)) < 1e-15);
    }

    /// A hand-held motion over `[0, seconds]` (`seed`) and its exact gyroscope at 1 kHz.
    fn exact_gyro(
        seconds: f64,
        seed: u64,
    ) -> (crate::pose_field::SinusoidMotion<f64>, Vec<ImuSample>) {
        use crate::PoseField;
        let range = crate::TimeRange::new(0.0, seconds).unwrap();
        let motion = crate::pose_field::SinusoidMotion::<f64>::handheld(range, seed);
        let times: Vec<f64> = (0..=(seconds * 1000.0) as usize)
            .map(|k| k as f64 / 1000.0)
            .collect();
        let mut out = PoseBatch::default();
        motion.evaluate(&times, Order::Velocity, &mut out).unwrap();
        let imu = times
            .iter()
            .enumerate()
            .map(|(i, &t_secs)| ImuSample {
                t_secs,
                gyro: out.ang_vel_body(i),
                accel: Vector3::zeros(),
            })
            .collect();
        (motion, imu)
    }

    #[test]
    fn integrated_gyro_matches_the_motion_it_was_simulated_from() {
        use crate::PoseField;
        let (motion, imu) = exact_gyro(4.0, 5);
        let (t0, t1) = (0.8137, 1.0137);
        let dq = integrate_gyro(&imu, t0, t1).unwrap();
        let mut out = PoseBatch::default();
        motion.evaluate(&[t0, t1], Order::Pose, &mut out).unwrap();
        let truth = out.world_from_body(0).rotation.inverse() * out.world_from_body(1).rotation;
        // Trapezoidal rates at 1 kHz over 0.2 s: error O(Δt²).
        assert!(dq.angle_to(&truth) < 1e-5, "{}", dq.angle_to(&truth));
        assert!(integrate_gyro(&imu, 3.9, 4.1).is_none());
        assert!(integrate_gyro(&imu, 1.0, 0.5).is_none());
    }

    #[test]
    fn accel_loss_gradient_and_gravity_at_rest() {
        let accel = [
            Vector3::new(0.3, -0.1, 9.8),
            Vector3::new(-0.5, 0.2, 9.1),
            Vector3::new(1.05, 0.4, -0.3),
        ];
        let g = crate::gravity_world();
        check_batch_loss_gradient(|b, gr| accel_l1(b, &accel, &g, 2.0, 0.9, gr));
        // At rest and level, the accelerometer reads +9.81 along body z.
        let mut b = PoseBatch::zeros(1, Order::Acceleration);
        b.rotation[0] = Quaternion::identity();
        let at_rest = [Vector3::new(0.0, 0.0, crate::geometry::GRAVITY_M_S2)];
        assert!(
            accel_l1(
                &b,
                &at_rest,
                &g,
                1.0,
                1.0,
                &mut PoseBatch::zeros(1, Order::Acceleration)
            ) < 1e-12
        );
    }
}
