//! An IMU simulated from any pose field's analytic derivatives: the gyroscope reads the body's
//! angular velocity `ω_body` (`Ṙ = R [ω]×`), the accelerometer the specific force
//! `f = Rᵀ (p̈ − g)` ([`cpose_core::geometry::specific_force_body`]), both in the body frame of
//! the field's `world_from_body`. Optional noise as EuRoC's `sensor.yaml` models it: white noise
//! of density `σ` (discrete standard deviation `σ/√Δt`) on top of a bias that follows a random
//! walk of density `σ_b` (`b_{k+1} = b_k + σ_b √Δt n_k`).

use cpose_core::random::standard_normal;
use cpose_core::{Order, PoseBatch, PoseField, PoseFieldError};
use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::euroc::ImuNoise;
use crate::imu::ImuSample;

/// Noise of a simulated IMU (continuous-time densities, as in EuRoC's `sensor.yaml`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseModel {
    /// Gyroscope white noise, rad/s/√Hz.
    pub gyro_noise_density: f64,
    /// Gyroscope bias random walk, rad/s²/√Hz.
    pub gyro_random_walk: f64,
    /// Accelerometer white noise, m/s²/√Hz.
    pub accel_noise_density: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_random_walk: f64,
    /// Gyroscope bias at the first sample, rad/s.
    pub initial_gyro_bias: Vector3<f64>,
    /// Accelerometer bias at the first sample, m/s².
    pub initial_accel_bias: Vector3<f64>,
}

impl From<&ImuNoise> for NoiseModel {
    /// The densities of a real sensor, with zero initial biases.
    fn from(n: &ImuNoise) -> Self {
        Self {
            gyro_noise_density: n.gyro_noise_density,
            gyro_random_walk: n.gyro_random_walk,
            accel_noise_density: n.accel_noise_density,
            accel_random_walk: n.accel_random_walk,
            initial_gyro_bias: Vector3::zeros(),
            initial_accel_bias: Vector3::zeros(),
        }
    }
}

/// Simulated readings and the biases inside them.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedImu {
    /// The readings, one per requested time.
    pub samples: Vec<ImuSample>,
    /// The gyroscope bias in each reading (zero without noise).
    pub gyro_bias: Vec<Vector3<f64>>,
    /// The accelerometer bias in each reading (zero without noise).
    pub accel_bias: Vec<Vector3<f64>>,
}

/// Simulates the IMU rigidly attached to the body of `field` at `times` (increasing, inside the
/// field's range) under `gravity` (world frame), with `noise` drawn from `seed`.
pub fn simulate_imu(
    field: &mut dyn PoseField<f64>,
    times: &[f64],
    gravity: &Vector3<f64>,
    noise: Option<&NoiseModel>,
    seed: u64,
) -> Result<SimulatedImu, PoseFieldError> {
    let mut batch = PoseBatch::default();
    field.evaluate(times, Order::Acceleration, &mut batch)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal3 = || {
        Vector3::new(
            standard_normal(&mut rng),
            standard_normal(&mut rng),
            standard_normal(&mut rng),
        )
    };
    let n = times.len();
    let mut out = SimulatedImu {
        samples: Vec::with_capacity(n),
        gyro_bias: Vec::with_capacity(n),
        accel_bias: Vec::with_capacity(n),
    };
    let (mut bg, mut ba) = noise.map_or((Vector3::zeros(), Vector3::zeros()), |m| {
        (m.initial_gyro_bias, m.initial_accel_bias)
    });
    for (i, &t) in times.iter().enumerate() {
        let rotation = UnitQuaternion::new_normalize(batch.rotation[i]);
        let mut gyro = batch.ang_vel_body(i);
        let mut accel = rotation.inverse_transform_vector(&(batch.lin_acc_world[i] - gravity));
        if let Some(m) = noise {
            // The sampling interval: the spacing to the neighbouring time.
            let dt = match (i.checked_sub(1), times.get(i + 1)) {
                (Some(p), _) => t - times[p],
                (None, Some(next)) => next - t,
                (None, None) => 1.0,
            };
            if i > 0 {
                bg += normal3() * (m.gyro_random_walk * dt.sqrt());
                ba += normal3() * (m.accel_random_walk * dt.sqrt());
            }
            gyro += bg + normal3() * (m.gyro_noise_density / dt.sqrt());
            accel += ba + normal3() * (m.accel_noise_density / dt.sqrt());
        }
        out.samples.push(ImuSample {
            t_secs: t,
            gyro,
            accel,
        });
        out.gyro_bias.push(bg);
        out.accel_bias.push(ba);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::euroc::EurocSequence;
    use cpose_core::pose_field::LieSplinePoses;
    use cpose_core::pose_field::sinusoid::SinusoidMotion;
    use cpose_core::{TimeRange, gravity_world};
    use nalgebra::Isometry3;

    fn rms(v: impl Iterator<Item = f64>) -> f64 {
        let (mut s, mut n) = (0.0, 0);
        for x in v {
            s += x * x;
            n += 1;
        }
        (s / n as f64).sqrt()
    }

    #[test]
    fn noise_and_bias_walk_have_the_stated_densities() {
        let range = TimeRange::new(0.0, 50.0).unwrap();
        let mut motion = SinusoidMotion::<f64>::handheld(range, 3);
        let rate = 200.0;
        let times: Vec<f64> = (0..10_000).map(|k| k as f64 / rate).collect();
        let g = gravity_world();
        let clean = simulate_imu(&mut motion, &times, &g, None, 0).unwrap();
        let model = NoiseModel {
            gyro_noise_density: 1.7e-4,
            gyro_random_walk: 1.9e-5,
            accel_noise_density: 2.0e-3,
            accel_random_walk: 3.0e-3,
            initial_gyro_bias: Vector3::new(0.01, -0.02, 0.005),
            initial_accel_bias: Vector3::zeros(),
        };
        let noisy = simulate_imu(&mut motion, &times, &g, Some(&model), 9).unwrap();
        assert_eq!(noisy.gyro_bias[0], model.initial_gyro_bias);
        // White noise: reading − truth − bias has σ/√Δt per axis.
        let white = |f: fn(&ImuSample) -> Vector3<f64>, bias: &[Vector3<f64>]| {
            rms((0..times.len()).flat_map(|i| {
                (f(&noisy.samples[i]) - f(&clean.samples[i]) - bias[i])
                    .iter()
                    .copied()
                    .collect::<Vec<_>>()
            }))
        };
        let gyro_sd = white(|s| s.gyro, &noisy.gyro_bias);
        let accel_sd = white(|s| s.accel, &noisy.accel_bias);
        let (want_g, want_a) = (1.7e-4 * rate.sqrt(), 2.0e-3 * rate.sqrt());
        assert!(
            (gyro_sd / want_g - 1.0).abs() < 0.02,
            "{gyro_sd} vs {want_g}"
        );
        assert!(
            (accel_sd / want_a - 1.0).abs() < 0.02,
            "{accel_sd} vs {want_a}"
        );
        // Bias random walk: increments of σ_b √Δt.
        let step_sd = rms(noisy
            .accel_bias
            .windows(2)
            .flat_map(|w| (w[1] - w[0]).iter().copied().collect::<Vec<_>>()));
        let want = 3.0e-3 / rate.sqrt();
        assert!((step_sd / want - 1.0).abs() < 0.02, "{step_sd} vs {want}");
    }

    /// The gyroscope simulated from EuRoC's ground truth (a cumulative cubic B-spline through
    /// its 200 Hz poses) against the real one with the ground-truth bias removed.
    #[test]
    fn simulated_gyro_agrees_with_the_real_one_on_euroc() {
        let Some(dir) = cpose_core::fs::shared_data_dir()
            .map(|d| d.join("euroc/V1_02_excerpt"))
            .filter(|d| d.is_dir())
        else {
            eprintln!("skipped: shared data folder not found (set CPOSE_DATA_DIR)");
            return;
        };
        let seq = EurocSequence::load(&dir).unwrap();
        let origin = seq.ground_truth[0].stamp;
        let gt_times: Vec<f64> = seq
            .ground_truth
            .iter()
            .map(|s| s.stamp.secs_since(origin))
            .collect();
        let poses: Vec<Isometry3<f64>> =
            seq.ground_truth.iter().map(|s| s.world_from_body).collect();
        // Ground truth at any time: slerp/lerp between its samples, clamped at the ends.
        let at = |t: f64| -> Isometry3<f64> {
            let k = gt_times
                .partition_point(|&x| x <= t)
                .clamp(1, gt_times.len() - 1);
            let s = ((t - gt_times[k - 1]) / (gt_times[k] - gt_times[k - 1])).clamp(0.0, 1.0);
            poses[k - 1].lerp_slerp(&poses[k], s)
        };
        let range = TimeRange::new(0.0, *gt_times.last().unwrap()).unwrap();
        // Knots every 10 ms (2 ground-truth samples; 20, 50 and 80 ms give 0.032, 0.040 and
        // 0.047 rad/s).
        let knots = (range.duration_secs() / 0.01).round() as usize + 3;
        let mut spline = LieSplinePoses::<f64>::from_trajectory(range, knots, at).unwrap();
        let g = gravity_world();
        // The real readings inside the ground truth's span, bias removed, in the body frame.
        let (mut times, mut real) = (Vec::new(), Vec::new());
        for s in &seq.imu {
            let t = s.stamp.secs_since(origin);
            if t < 0.1 || t > range.end_secs - 0.1 {
                continue;
            }
            let k = gt_times.partition_point(|&x| x < t).min(gt_times.len() - 1);
            times.push(t);
            real.push(seq.body_from_imu.rotation * (s.gyro - seq.ground_truth[k].gyro_bias));
        }
        let sim = simulate_imu(&mut spline, &times, &g, None, 0).unwrap();
        let simulated: Vec<Vector3<f64>> = sim.samples.iter().map(|s| s.gyro).collect();
        let rms_diff = |a: &[Vector3<f64>], b: &[Vector3<f64>]| {
            rms(a
                .iter()
                .zip(b)
                .flat_map(|(x, y)| (x - y).iter().copied().collect::<Vec<_>>()))
        };
        // Both through a 50 ms moving average: what remains above it is vibration of the
        // airframe, which the ground truth (a smoothed estimate) does not hold.
        let smooth = |v: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
            v.windows(10)
                .map(|w| w.iter().sum::<Vector3<f64>>() / 10.0)
                .collect()
        };
        let diff = rms_diff(&simulated, &real);
        let low = rms_diff(&smooth(&simulated), &smooth(&real));
        let signal = rms(real
            .iter()
            .flat_map(|r| r.iter().copied().collect::<Vec<_>>()));
        eprintln!(
            "EuRoC V1_02 excerpt, gyro simulated from the ground truth vs real (bias removed): \
             RMS {diff:.4} rad/s per axis, {low:.4} below 20 Hz (signal {signal:.3}, sensor \
             white noise {:.4})",
            seq.imu_noise.gyro_noise_density * seq.imu_noise.rate_hz.sqrt()
        );
        // Measured: 0.031 (0.0024 would be the sensor's noise alone); shifting the simulated
        // times by ±5 ms makes it worse (0.034), so the clocks agree.
        assert!(
            diff < 0.04 && low < diff,
            "RMS difference {diff} ({low} smoothed)"
        );
    }
}
