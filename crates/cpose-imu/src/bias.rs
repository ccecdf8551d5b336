//! The IMU's biases estimated from the recording itself: at rest the gyroscope reads its bias and
//! the accelerometer gravity plus its bias, so a stationary start gives both without any ground
//! truth (EuRoC's flights begin with the vehicle standing on the floor).
//!
//! The start is at rest while every window of [`WINDOW_SECS`] is as quiet as the sensor's white
//! noise allows: each gyroscope axis's standard deviation within [`NOISE_MULTIPLE`] times
//! `σ_g = gyro_noise_density · √rate`, the specific force's norm within that multiple of
//! `σ_a = accel_noise_density · √rate` and its mean within [`GRAVITY_TOLERANCE`] of gravity, and
//! the window's mean gyroscope reading within that multiple of its standard error from the first
//! window's (a steady turn is quiet too). The first window that is not — motors starting, a hand
//! picking the camera up — ends the rest.
//!
//! Over the rest, the gyroscope bias is the mean reading. Of the accelerometer bias only the part
//! along the measured specific force is observable without the orientation: `b_a = (|f̄| − g) f̄ /
//! |f̄|` (the rest of it is indistinguishable from a tilt).

use anyhow::Context as _;
use cpose_core::geometry::GRAVITY_M_S2;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::ImuSample;
use crate::euroc::{EurocSequence, ImuNoise, RawImuSample};

/// Length of the windows the rest test looks at, seconds.
pub const WINDOW_SECS: f64 = 0.25;
/// A window is at rest while its spread stays within this many white-noise standard deviations.
pub const NOISE_MULTIPLE: f64 = 5.0;
/// A window is at rest only if its mean specific force is this close to gravity, m/s².
pub const GRAVITY_TOLERANCE: f64 = 0.5;

/// The biases estimated over a stationary start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestBias {
    /// Gyroscope bias in the IMU frame, rad/s.
    pub gyro: Vector3<f64>,
    /// The observable part of the accelerometer bias (along gravity), IMU frame, m/s².
    pub accel: Vector3<f64>,
    /// How long the start was at rest, seconds.
    pub rest_secs: f64,
    /// Readings averaged.
    pub readings: usize,
}

/// How a real recording's IMU bias is removed (`bias` in the configs that read EuRoC).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BiasRemoval {
    /// Minus the biases estimated over the recording's stationary start ([`bias_at_rest`]).
    #[default]
    Estimate,
    /// Minus the ground-truth state's estimate nearest each reading (an ablation: no user has
    /// it).
    GroundTruth,
    /// As measured.
    Raw,
}

/// The readings of `seq` in the body frame, on the ground truth's clock (seconds since its first
/// state), with the bias removed as `removal` says; for [`BiasRemoval::Estimate`] also a line for
/// the log comparing the estimate with the ground truth's. Errors when the estimate is asked for
/// and the recording does not start at rest.
pub fn body_readings(
    seq: &EurocSequence,
    removal: BiasRemoval,
) -> anyhow::Result<(Vec<ImuSample>, Option<String>)> {
    let gt = &seq.ground_truth;
    let origin = gt[0].stamp;
    let gt_times: Vec<f64> = gt.iter().map(|s| s.stamp.secs_since(origin)).collect();
    let rest = match removal {
        BiasRemoval::Estimate => Some(
            bias_at_rest(&seq.imu, &seq.imu_noise, GRAVITY_M_S2).with_context(|| {
                format!(
                    "bias = \"estimate\" needs the recording to start at rest (its first \
                     {WINDOW_SECS} s as quiet as the IMU's noise); use bias = \"raw\" or \
                     \"ground_truth\""
                )
            })?,
        ),
        BiasRemoval::GroundTruth | BiasRemoval::Raw => None,
    };
    let note = rest.map(|rest| {
        format!(
            "IMU bias estimated over the first {:.2} s at rest ({} readings): gyroscope {:.4?} \
             rad/s, {:.4} rad/s from the ground truth's {:.4?}; accelerometer along gravity \
             {:.3?} m/s² (the ground truth's {:.3?})",
            rest.rest_secs,
            rest.readings,
            rest.gyro.as_slice(),
            (rest.gyro - gt[0].gyro_bias).norm(),
            gt[0].gyro_bias.as_slice(),
            rest.accel.as_slice(),
            gt[0].accel_bias.as_slice(),
        )
    });
    // EuRoC's imu0 is the body frame (T_BS = I); a lever arm is not modelled.
    let imu_rotation = seq.body_from_imu.rotation;
    let readings = seq
        .imu
        .iter()
        .map(|s| {
            let t = s.stamp.secs_since(origin);
            let (gyro, accel) = match &rest {
                Some(rest) => (s.gyro - rest.gyro, s.accel - rest.accel),
                None if removal == BiasRemoval::Raw => (s.gyro, s.accel),
                None => {
                    let k = gt_times.partition_point(|&x| x < t).min(gt.len() - 1);
                    (s.gyro - gt[k].gyro_bias, s.accel - gt[k].accel_bias)
                }
            };
            ImuSample {
                t_secs: t,
                gyro: imu_rotation * gyro,
                accel: imu_rotation * accel,
            }
        })
        .collect();
    Ok((readings, note))
}

/// The gyroscope bias that [`body_readings`] of `seq` with `removal` still hold at `t` seconds of
/// the ground truth's clock, by the ground-truth state's estimate, in the body frame, rad/s (for
/// scoring a bias estimated online).
pub fn gyro_bias_left(seq: &EurocSequence, removal: BiasRemoval, t: f64) -> Vector3<f64> {
    let gt = &seq.ground_truth;
    let origin = gt[0].stamp;
    let k = gt
        .partition_point(|s| s.stamp.secs_since(origin) < t)
        .min(gt.len() - 1);
    let removed = match removal {
        BiasRemoval::Estimate => bias_at_rest(&seq.imu, &seq.imu_noise, GRAVITY_M_S2)
            .map_or_else(Vector3::zeros, |rest| rest.gyro),
        BiasRemoval::GroundTruth => gt[k].gyro_bias,
        BiasRemoval::Raw => Vector3::zeros(),
    };
    seq.body_from_imu.rotation * (gt[k].gyro_bias - removed)
}

/// The biases over the stationary start of `imu` (sorted by time), with the noise densities
/// and rate of `noise` and gravity's magnitude `gravity_m_s2`; `None` unless at least the first
/// window is at rest.
pub fn bias_at_rest(imu: &[RawImuSample], noise: &ImuNoise, gravity_m_s2: f64) -> Option<RestBias> {
    let origin = imu.first()?.stamp;
    let sigma_g = noise.gyro_noise_density * noise.rate_hz.sqrt();
    let sigma_a = noise.accel_noise_density * noise.rate_hz.sqrt();
    // A window with fewer than half the readings its length should hold is a gap or the end.
    let min_readings = ((0.5 * WINDOW_SECS * noise.rate_hz) as usize).max(2);
    // Windows [k·W, (k+1)·W) from the first reading, while they are at rest and their mean
    // gyroscope reading stays the first window's.
    let (mut end, mut k, mut first_mean) = (0, 0, None);
    loop {
        let until = (k + 1) as f64 * WINDOW_SECS;
        let len = imu[end..]
            .iter()
            .take_while(|s| s.stamp.secs_since(origin) < until)
            .count();
        let window = &imu[end..end + len];
        if len < min_readings {
            break;
        }
        let Some(mean) = quiet_mean(window, sigma_g, sigma_a, gravity_m_s2) else {
            break;
        };
        // Two means of n readings differ by σ_g·√(2/n) (one standard deviation).
        let tolerance = NOISE_MULTIPLE * sigma_g * (2.0 / len as f64).sqrt();
        if (mean - *first_mean.get_or_insert(mean)).amax() > tolerance {
            break;
        }
        end += len;
        k += 1;
    }
    if end == 0 {
        return None;
    }
    let rest = &imu[..end];
    let n = rest.len() as f64;
    let gyro = rest.iter().map(|s| s.gyro).sum::<Vector3<f64>>() / n;
    let force = rest.iter().map(|s| s.accel).sum::<Vector3<f64>>() / n;
    let norm = force.norm();
    Some(RestBias {
        gyro,
        accel: force * ((norm - gravity_m_s2) / norm),
        rest_secs: rest[end - 1].stamp.secs_since(origin) + 1.0 / noise.rate_hz,
        readings: end,
    })
}

/// The mean gyroscope reading of a window whose readings are as quiet as the white noise and
/// read gravity; `None` for a window in motion.
fn quiet_mean(
    window: &[RawImuSample],
    sigma_g: f64,
    sigma_a: f64,
    gravity: f64,
) -> Option<Vector3<f64>> {
    let n = window.len() as f64;
    let mean = window.iter().map(|s| s.gyro).sum::<Vector3<f64>>() / n;
    let var = window
        .iter()
        .map(|s| (s.gyro - mean).component_mul(&(s.gyro - mean)))
        .sum::<Vector3<f64>>()
        / n;
    let norms: Vec<f64> = window.iter().map(|s| s.accel.norm()).collect();
    let norm_mean = norms.iter().sum::<f64>() / n;
    let norm_var = norms.iter().map(|a| (a - norm_mean).powi(2)).sum::<f64>() / n;
    let limit_g = NOISE_MULTIPLE * sigma_g;
    let quiet = var.iter().all(|v| v.sqrt() <= limit_g)
        && norm_var.sqrt() <= NOISE_MULTIPLE * sigma_a
        && (norm_mean - gravity).abs() <= GRAVITY_TOLERANCE;
    quiet.then_some(mean)
}

/// The gyroscope bias left in the readings, refined online from the tracked rotations: a Kalman
/// filter on a constant-plus-random-walk bias, one scalar variance for the three axes.
///
/// Readings `ω_m = ω + β` integrated over a frame interval `Δ` with the estimate `β̂` removed turn
/// by `R_imu ≈ R Exp((β − β̂) Δ)`, where `R` is the true motion; the tracked motion `R_track`
/// measures `R` with an error of `σ_r` per interval, so the residual `r = Log(R_imu⁻¹ R_track)`
/// reads `β − β̂ ≈ −r / Δ` with variance `(σ_r / Δ)²` per axis. Between intervals the bias walks:
/// the variance grows by `σ_w² Δ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroBiasFilter {
    /// `β̂`, rad/s, in the readings' frame.
    pub estimate: Vector3<f64>,
    /// The estimate's variance per axis, (rad/s)².
    pub variance: f64,
    /// `σ_w`, rad/s²/√Hz.
    random_walk: f64,
    /// `σ_r`, rad per frame interval.
    rotation_noise: f64,
}

impl GyroBiasFilter {
    /// A filter starting at `β̂ = 0` with standard deviation `prior` (rad/s), the bias walking
    /// with density `random_walk` (rad/s²/√Hz), tracked rotations `rotation_noise` (rad) off per
    /// frame interval.
    pub fn new(prior: f64, random_walk: f64, rotation_noise: f64) -> Self {
        Self {
            estimate: Vector3::zeros(),
            variance: prior * prior,
            random_walk,
            rotation_noise,
        }
    }

    /// The bias walks for `dt` seconds.
    pub fn predict(&mut self, dt: f64) {
        self.variance += self.random_walk * self.random_walk * dt;
    }

    /// Takes in the residual rotation `r = Log(R_imu⁻¹ R_track)` (rad, the scaled axis) of an
    /// interval of `dt` seconds integrated with the current estimate removed.
    pub fn update(&mut self, residual: &Vector3<f64>, dt: f64) {
        let noise = (self.rotation_noise / dt).powi(2);
        let gain = self.variance / (self.variance + noise);
        self.estimate -= residual * (gain / dt);
        self.variance *= 1.0 - gain;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::Timestamp;
    use cpose_core::geometry::GRAVITY_M_S2;
    use cpose_core::random::standard_normal;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const NOISE: ImuNoise = ImuNoise {
        gyro_noise_density: 1.7e-4,
        gyro_random_walk: 2e-5,
        accel_noise_density: 2e-3,
        accel_random_walk: 3e-3,
        rate_hz: 200.0,
    };

    /// 1.5 s at rest, tilted, with biases and white noise, then a steady turn at 1 rad/s.
    #[test]
    fn a_simulated_rest_gives_the_biases_and_its_length() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (bg, ba) = (
            Vector3::new(0.02, -0.01, 0.07),
            Vector3::new(0.1, 0.05, -0.2),
        );
        let up = Vector3::new(0.3, -0.2, 1.0).normalize() * GRAVITY_M_S2;
        let sigma = |density: f64| density * NOISE.rate_hz.sqrt();
        let (sg, sa) = (
            sigma(NOISE.gyro_noise_density),
            sigma(NOISE.accel_noise_density),
        );
        let imu: Vec<RawImuSample> = (0..600)
            .map(|k| {
                let t = k as f64 / NOISE.rate_hz;
                let turn = if t < 1.5 { 0.0 } else { 1.0 };
                let mut noisy = |s: f64| s * Vector3::from_fn(|_, _| standard_normal(&mut rng));
                RawImuSample {
                    stamp: Timestamp::from_secs_f64(100.0 + t),
                    gyro: Vector3::new(0.0, 0.0, turn) + bg + noisy(sg),
                    accel: up + ba + noisy(sa),
                }
            })
            .collect();
        let rest = bias_at_rest(&imu, &NOISE, GRAVITY_M_S2).unwrap();
        assert!((rest.rest_secs - 1.5).abs() < 1e-9, "{rest:?}");
        assert_eq!(rest.readings, 300);
        // The mean of 300 readings: σ_g / √300 ≈ 1.4e-4 rad/s per axis.
        assert!((rest.gyro - bg).amax() < 6e-4, "{rest:?}");
        let along = up.normalize();
        assert!(
            (rest.accel - ba.dot(&along) * along).norm() < 0.01,
            "{rest:?}"
        );
        // Starting in motion (a turn that speeds up and slows down): no rest to estimate from.
        // (A steady turn from the first reading on cannot be told from a bias by the readings.)
        let moving: Vec<RawImuSample> = imu
            .iter()
            .map(|s| RawImuSample {
                gyro: s.gyro + Vector3::new(0.0, 0.0, (3.0 * s.stamp.as_secs_f64()).sin()),
                ..*s
            })
            .collect();
        assert!(bias_at_rest(&moving, &NOISE, GRAVITY_M_S2).is_none());
    }

    /// Rotations tracked with noise over intervals integrated from biased readings: the filter
    /// finds the bias, to the standard deviation it states, and it is the sign the readings need.
    #[test]
    fn the_bias_filter_finds_the_bias_of_integrated_readings() {
        use nalgebra::UnitQuaternion;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let bias = Vector3::new(0.004, -0.002, 0.003);
        let (dt, sigma_r) = (0.1, 0.2_f64.to_radians());
        let mut filter = GyroBiasFilter::new(0.01, 2e-5, sigma_r);
        let mut errors = Vec::new();
        for k in 0..2000 {
            filter.predict(dt);
            // A turn at a varying rate; the IMU's, integrated from the biased rate minus β̂.
            let rate = Vector3::new((0.3 * k as f64).sin(), 0.5, -0.2);
            let truth = UnitQuaternion::from_scaled_axis(rate * dt);
            let imu = UnitQuaternion::from_scaled_axis((rate + bias - filter.estimate) * dt);
            let noise = Vector3::from_fn(|_, _| sigma_r * standard_normal(&mut rng));
            let tracked = truth * UnitQuaternion::from_scaled_axis(noise);
            filter.update(&(imu.inverse() * tracked).scaled_axis(), dt);
            if k >= 1000 {
                errors.push((filter.estimate - bias).norm_squared() / 3.0);
            }
        }
        // After N intervals σ ≈ σ_r / (Δ √N): 1.1e-3 rad/s at 1000, 7.8e-4 at 2000.
        let rms = (errors.iter().sum::<f64>() / errors.len() as f64).sqrt();
        let stated = filter.variance.sqrt();
        assert!(stated > 7e-4 && stated < 9e-4, "{stated}");
        assert!(
            rms < 2.0 * stated && rms > 0.3 * stated,
            "{rms} against {stated}"
        );
        // Without measurements the variance only grows, by σ_w² per second.
        let before = filter.variance;
        filter.predict(100.0);
        assert!((filter.variance - before - 100.0 * 4e-10).abs() < 1e-15);
    }

    /// EuRoC V1_02 begins on the floor: the gyroscope bias from its first fraction of a second
    /// agrees with the ground truth's estimate to a few thousandths of a rad/s.
    #[test]
    fn the_euroc_excerpt_starts_at_rest_with_the_ground_truths_gyro_bias() {
        let Some(dir) = cpose_core::fs::shared_data_dir()
            .map(|d| d.join("euroc/V1_02_excerpt"))
            .filter(|d| d.is_dir())
        else {
            eprintln!("skipped: shared data folder not found (set CPOSE_DATA_DIR)");
            return;
        };
        let seq = crate::euroc::EurocSequence::load(&dir).unwrap();
        let rest = bias_at_rest(&seq.imu, &seq.imu_noise, GRAVITY_M_S2).unwrap();
        let truth = seq.ground_truth[0].gyro_bias;
        let error = (rest.gyro - truth).norm();
        eprintln!(
            "EuRoC V1_02: at rest for {:.2} s ({} readings), gyro bias {:.4?} against the ground \
             truth's {:.4?} ({error:.4} rad/s apart)",
            rest.rest_secs, rest.readings, rest.gyro, truth
        );
        assert!(rest.rest_secs >= 0.25 && rest.rest_secs < 5.0, "{rest:?}");
        assert!(error < 0.004, "{error}");
    }
}
