//! The losses of the relative tracker's IMU tie: the gyroscope at both ends of a frame interval
//! supervises a network of increments ([`increment_gyro_l1`]), or of what the readings integrated
//! over the interval miss ([`GyroWindow::residual`]). The absolute losses (poses,
//! gyroscope, accelerometer) are `cpose_core`'s, re-exported here.

use cpose_core::PoseBatch;
pub use cpose_core::fit::losses::*;
use nalgebra::Vector3;

use crate::ImuSample;

/// The gyroscope at both ends of a window `[τ − Δ, τ]`, for a network of increments
/// ([`increment_gyro_l1`]); body frame, bias removed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroWindow {
    /// `ω(τ)`.
    pub gyro: Vector3<f64>,
    /// `ω₀ = ω(τ − Δ)`.
    pub gyro_start: Vector3<f64>,
}

impl GyroWindow {
    /// The readings of `imu` (sorted by time) at `tau` and `tau − delta`, linearly interpolated;
    /// `None` unless `imu` covers `[tau − delta, tau]`.
    pub fn at(imu: &[ImuSample], tau: f64, delta: f64) -> Option<Self> {
        Some(Self {
            gyro: interpolate(imu, tau)?.gyro,
            gyro_start: interpolate(imu, tau - delta)?.gyro,
        })
    }

    /// The window of a network that holds what the readings' own rotation over the window
    /// misses, `N(τ) = P(τ)⁻¹ T(τ − Δ)⁻¹ T(τ)` with `P(τ)` the gyroscope integrated over
    /// `(τ − Δ, τ]`: `P` obeys the kinematics at both ends of the window, which leaves
    /// `q̇_N = ½ (q_N ⊗ (0, ω(τ)) − (0, ω(τ)) ⊗ q_N)`, the relation with `ω₀ = ω(τ)`.
    pub fn residual(gyro: Vector3<f64>) -> Self {
        Self {
            gyro,
            gyro_start: gyro,
        }
    }
}

/// The reading at `t`, linearly interpolated between its neighbours in `imu` (sorted by time);
/// `None` outside the readings.
pub fn interpolate(imu: &[ImuSample], t: f64) -> Option<ImuSample> {
    let (first, last) = (imu.first()?, imu.last()?);
    if !(first.t_secs <= t && t <= last.t_secs) {
        return None;
    }
    let k = imu.partition_point(|s| s.t_secs <= t);
    if k == imu.len() {
        return Some(*last);
    }
    let (a, b) = (&imu[k - 1], &imu[k]);
    let s = (t - a.t_secs) / (b.t_secs - a.t_secs);
    Some(ImuSample {
        t_secs: t,
        gyro: a.gyro.lerp(&b.gyro, s),
        accel: a.accel.lerp(&b.accel, s),
    })
}

/// Tight gyroscope coupling for PoseNet relative to the previous frame (§3.4 with the
/// supplement's IMU reference `T_{b_{i−1}, b_i}`). As a function of time that network is the
/// motion over the last frame interval, `N(τ) = T(τ − Δ)⁻¹ T(τ)`; with `q̇ = ½ q ⊗ (0, ω)` at both
/// ends its rotation obeys `q̇_N = ½ (q_N ⊗ e − e₀ ⊗ q_N)`, `e = (0, ω(τ))`, `e₀ = (0, ω₀)`.
/// `L = w/n Σ_i |q̇_N − ½ (q_N ⊗ e − e₀ ⊗ q_N)|₁`.
pub fn increment_gyro_l1(
    out: &PoseBatch,
    readings: &[GyroWindow],
    weight: f64,
    grad: &mut PoseBatch,
) -> f64 {
    let rates = readings.iter().map(|r| (r.gyro, r.gyro_start));
    rate_l1(out, rates, weight, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::testing::check_batch_loss_gradient;
    use nalgebra::UnitQuaternion;

    /// A hand-held motion over `[0, seconds]` (`seed`) and its exact IMU at 1 kHz.
    fn exact_imu(
        seconds: f64,
        seed: u64,
    ) -> (cpose_core::pose_field::SinusoidMotion<f64>, Vec<ImuSample>) {
        let range = cpose_core::TimeRange::new(0.0, seconds).unwrap();
        let mut motion = cpose_core::pose_field::SinusoidMotion::<f64>::handheld(range, seed);
        let times: Vec<f64> = (0..=(seconds * 1000.0) as usize)
            .map(|k| k as f64 / 1000.0)
            .collect();
        let imu =
            crate::sim::simulate_imu(&mut motion, &times, &cpose_core::gravity_world(), None, 0)
                .unwrap()
                .samples;
        (motion, imu)
    }

    #[test]
    fn increment_gyro_loss_gradient() {
        let v = |a: f64, b: f64, c: f64| Vector3::new(a, b, c);
        let readings = [0.0, 1.0, 2.0].map(|x| GyroWindow {
            gyro: v(0.3 - x, -0.1, 0.8),
            gyro_start: v(-0.5, 0.2 + x, 0.1),
        });
        check_batch_loss_gradient(|b, g| increment_gyro_l1(b, &readings, 1.3, g));
    }

    /// The relation's residual at `tau` for the rotation `rotation(τ)`, its rate taken by a
    /// central difference of 1 ms.
    fn relation_residual(
        rotation: impl Fn(f64) -> UnitQuaternion<f64>,
        tau: f64,
        window: GyroWindow,
    ) -> f64 {
        let h = 1e-3;
        let (minus, mid, plus) = (rotation(tau - h), rotation(tau), rotation(tau + h));
        let sign = |q: &UnitQuaternion<f64>| q.into_inner() * q.coords.dot(&mid.coords).signum();
        let mut out = PoseBatch::zeros(1, cpose_core::Order::Velocity);
        out.rotation[0] = mid.into_inner();
        out.rotation_rate[0] = (sign(&plus) - sign(&minus)) / (2.0 * h);
        let mut g = PoseBatch::zeros(1, cpose_core::Order::Velocity);
        increment_gyro_l1(&out, &[window], 1.0, &mut g)
    }

    /// Along a known motion with its exact IMU, the increment `N(τ) = T(τ − Δ)⁻¹ T(τ)` — its
    /// rate taken here by central differences of the poses — satisfies the relation.
    #[test]
    fn increment_gyro_relation_holds_on_a_known_motion() {
        use cpose_core::{Order, PoseField};
        let (motion, imu) = exact_imu(3.0, 3);
        let delta = 0.2;
        let increment = |tau: f64| {
            let mut out = PoseBatch::default();
            motion
                .evaluate(&[tau - delta, tau], Order::Pose, &mut out)
                .unwrap();
            (out.world_from_body(0).inverse() * out.world_from_body(1)).rotation
        };
        let mut residual = 0.0_f64;
        for tau in [0.83, 1.57, 2.41] {
            let window = GyroWindow::at(&imu, tau, delta).unwrap();
            residual = residual.max(relation_residual(increment, tau, window));
            // A wrong window leaves a residual: the relation does tie Δ.
            let wrong = GyroWindow::at(&imu, tau, 0.5 * delta).unwrap();
            assert!(relation_residual(increment, tau, wrong) > 0.05);
        }
        // A central difference with h = 1 ms, readings at 1 kHz: measured 2e-6.
        assert!(residual < 1e-4, "{residual}");
        assert!(GyroWindow::at(&imu, 0.1, delta).is_none());
    }

    /// The same motion with the gyroscope's rotation over each window taken out, `N(τ) =
    /// P(τ)⁻¹ T(τ − Δ)⁻¹ T(τ)`, satisfies the residual's relation ([`GyroWindow::residual`]).
    #[test]
    fn the_residual_of_the_integrated_gyroscope_satisfies_its_relation() {
        use cpose_core::{Order, PoseField};
        let (motion, imu) = exact_imu(3.0, 5);
        let delta = 0.2;
        let residual_at = |tau: f64| {
            let mut out = PoseBatch::default();
            motion
                .evaluate(&[tau - delta, tau], Order::Pose, &mut out)
                .unwrap();
            let turn = integrate_gyro(&imu, tau - delta, tau).unwrap();
            turn.inverse() * (out.world_from_body(0).inverse() * out.world_from_body(1)).rotation
        };
        let (mut worst, mut plain) = (0.0_f64, f64::INFINITY);
        for tau in [0.83, 1.57, 2.41] {
            let window = GyroWindow::residual(interpolate(&imu, tau).unwrap().gyro);
            worst = worst.max(relation_residual(residual_at, tau, window));
            // The increment's own window does not fit the residual.
            let increment = GyroWindow::at(&imu, tau, delta).unwrap();
            plain = plain.min(relation_residual(residual_at, tau, increment));
        }
        // The readings integrated by the trapezoid rule at 1 kHz, a central difference of 1 ms.
        assert!(worst < 1e-3, "{worst}");
        assert!(plain > 20.0 * worst, "{plain} vs {worst}");
    }
}
