//! [`SinusoidMotion`]: a smooth analytic trajectory made of sums of sines, with exact time
//! derivatives and parameter gradients — the built-in synthetic hand-held motion and a source of
//! exact IMU readings.

use nalgebra::{Quaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, check_times};
use crate::geometry::QuatJet;
use crate::{Real, TimeRange};

/// Number of channels: x, y, z (metres), roll, pitch, yaw (radians).
pub const NUM_CHANNELS: usize = 6;

/// A trajectory whose six channels — `x, y, z` in metres and `roll, pitch, yaw` in radians —
/// are each `c(t) = b_c + Σ_k a_{c,k} sin(ω_k t + φ_{c,k})`, `t` in seconds since the sequence
/// origin. The pose is `p = (x, y, z)` and `q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll)` (intrinsic
/// Z-Y-X, [`crate::geometry::EulerZyx`]).
///
/// Parameters (one slice, [`ParamKind::Pose`]), channel by channel: `[b_c, a_{c,0}, …,
/// a_{c,K−1}]`. Frequencies `ω_k` (shared by the channels) and phases `φ_{c,k}` are fixed.
///
/// Derivatives are exact: `ċ = Σ a ω cos(·)`, `c̈ = −Σ a ω² sin(·)`; each single-axis factor
/// `q_e(θ) = (cos(θ/2), sin(θ/2) e)` has `dq_e/dθ = ½ q_e ⊗ (0, e)` and `d²q_e/dθ² = −¼ q_e`, so
/// its jet is `(q_e, θ̇ q_e', θ̈ q_e' − ¼ θ̇² q_e)`, and the three are multiplied by the product
/// rule ([`QuatJet::mul`]). The reverse pass runs the same steps backwards ([`QuatJet::mul_backward`]).
#[derive(Clone, Debug)]
pub struct SinusoidMotion<S: Real = f32> {
    range: TimeRange,
    /// `ω_k`, rad/s.
    omegas: Vec<f64>,
    /// `φ_{c,k}` at `c·K + k`, rad.
    phases: Vec<f64>,
    /// `[b_c, a_{c,0..K}]` per channel.
    params: Vec<S>,
}

/// A channel's value and first two time derivatives.
#[derive(Clone, Copy, Debug, Default)]
struct Channel {
    value: f64,
    rate: f64,
    acc: f64,
}

/// The unit axes of the rotation channels roll, pitch, yaw.
const AXES: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `(q_e(θ), dq_e/dθ)` for the unit axis `e`.
fn axis_quat(theta: f64, axis: usize) -> (Quaternion<f64>, Quaternion<f64>) {
    let (s, c) = (0.5 * theta).sin_cos();
    let e = Vector3::from(AXES[axis]);
    (
        Quaternion::from_parts(c, e * s),
        Quaternion::from_parts(-0.5 * s, e * (0.5 * c)),
    )
}

/// The jet of `q_e(θ(t))` from the channel jet `(θ, θ̇, θ̈)`.
fn axis_jet(ch: &Channel, axis: usize) -> QuatJet {
    let (a, b) = axis_quat(ch.value, axis);
    QuatJet::new(a, b * ch.rate, b * ch.acc - a * (0.25 * ch.rate * ch.rate))
}

/// Maps the cotangent of an axis jet back onto `(θ, θ̇, θ̈)` (transpose of the Jacobian of
/// [`axis_jet`]: `∂/∂θ` of the three parts is `(B, −¼θ̇ A, −¼θ̈ A − ¼θ̇² B)`, `∂/∂θ̇` is
/// `(0, B, −½θ̇ A)`, `∂/∂θ̈` is `(0, 0, B)` with `A = q_e`, `B = dq_e/dθ`).
fn axis_jet_backward(ch: &Channel, axis: usize, g: &QuatJet) -> Channel {
    let (a, b) = axis_quat(ch.value, axis);
    let dot = |x: &Quaternion<f64>, y: &Quaternion<f64>| x.coords.dot(&y.coords);
    let gb = dot(&g.value, &b);
    let (ra, rb) = (dot(&g.rate, &a), dot(&g.rate, &b));
    let (aa, ab) = (dot(&g.acc, &a), dot(&g.acc, &b));
    Channel {
        value: gb - 0.25 * ch.rate * ra - 0.25 * ch.acc * aa - 0.25 * ch.rate * ch.rate * ab,
        rate: rb - 0.5 * ch.rate * aa,
        acc: ab,
    }
}

impl<S: Real> SinusoidMotion<S> {
    /// A motion from explicit frequencies `omegas_rad_s` (`K` values), phases (`6·K`, channel
    /// by channel), amplitudes (`6·K`, channel by channel) and offsets (`6`). Errors on
    /// mismatched lengths or non-finite values.
    pub fn new(
        range: TimeRange,
        omegas_rad_s: Vec<f64>,
        phases_rad: Vec<f64>,
        amplitudes: &[f64],
        offsets: &[f64; NUM_CHANNELS],
    ) -> Result<Self, PoseFieldError> {
        let k = omegas_rad_s.len();
        for (what, got) in [
            ("phases", phases_rad.len()),
            ("amplitudes", amplitudes.len()),
        ] {
            if got != NUM_CHANNELS * k {
                return Err(PoseFieldError::Shape {
                    what,
                    expected: NUM_CHANNELS * k,
                    got,
                });
            }
        }
        let all_finite = omegas_rad_s
            .iter()
            .chain(&phases_rad)
            .chain(amplitudes)
            .chain(offsets)
            .all(|x| x.is_finite());
        if !all_finite {
            return Err(PoseFieldError::Invalid(
                "sinusoid motion: non-finite frequency, phase, amplitude or offset".into(),
            ));
        }
        let mut params = Vec::with_capacity(NUM_CHANNELS * (k + 1));
        for c in 0..NUM_CHANNELS {
            params.push(S::from_f64(offsets[c]));
            params.extend(
                amplitudes[c * k..(c + 1) * k]
                    .iter()
                    .map(|&a| S::from_f64(a)),
            );
        }
        Ok(Self {
            range,
            omegas: omegas_rad_s,
            phases: phases_rad,
            params,
        })
    }

    /// Random sums of `num_terms` sines from `seed`: frequencies uniform in
    /// `[freq_min_hz, freq_max_hz]`, phases uniform in `[0, 2π)`, and per channel amplitudes
    /// whose sum (the largest possible excursion) is uniform in `[½, 1]` times
    /// `max_translation_m` for x, y, z and `max_angle_rad` for roll, pitch, yaw; offsets 0.
    pub fn random(
        range: TimeRange,
        seed: u64,
        num_terms: usize,
        max_translation_m: f64,
        max_angle_rad: f64,
        freq_min_hz: f64,
        freq_max_hz: f64,
    ) -> Result<Self, PoseFieldError> {
        if num_terms == 0 || !(freq_min_hz > 0.0 && freq_max_hz >= freq_min_hz) {
            return Err(PoseFieldError::Invalid(format!(
                "sinusoid motion: need num_terms > 0 and 0 < freq_min_hz <= freq_max_hz, got {num_terms}, {freq_min_hz}, {freq_max_hz}"
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let tau = std::f64::consts::TAU;
        let omegas: Vec<f64> = (0..num_terms)
            .map(|_| tau * rng.random_range(freq_min_hz..=freq_max_hz))
            .collect();
        let phases: Vec<f64> = (0..NUM_CHANNELS * num_terms)
            .map(|_| rng.random_range(0.0..tau))
            .collect();
        let mut amplitudes = Vec::with_capacity(NUM_CHANNELS * num_terms);
        for c in 0..NUM_CHANNELS {
            let max = if c < 3 {
                max_translation_m
            } else {
                max_angle_rad
            };
            let weights: Vec<f64> = (0..num_terms).map(|_| rng.random_range(0.2..1.0)).collect();
            let total: f64 = weights.iter().sum();
            let excursion = max * rng.random_range(0.5..1.0);
            amplitudes.extend(weights.iter().map(|w| excursion * w / total));
        }
        Self::new(range, omegas, phases, &amplitudes, &[0.0; NUM_CHANNELS])
    }

    /// A realistic hand-held motion: 4 sines per channel at 0.1–1.5 Hz, excursions up to
    /// ±0.3 m and ±15° about the origin and the identity rotation.
    pub fn handheld(range: TimeRange, seed: u64) -> Self {
        Self::random(range, seed, 4, 0.3, 15f64.to_radians(), 0.1, 1.5)
            .expect("the hand-held constants are valid")
    }

    /// Number of sine terms per channel, `K`.
    pub fn num_terms(&self) -> usize {
        self.omegas.len()
    }

    /// The six channels and their derivatives at `t_secs` (seconds since the origin).
    fn channels(&self, t_secs: f64) -> [Channel; NUM_CHANNELS] {
        let k = self.num_terms();
        let mut out = [Channel::default(); NUM_CHANNELS];
        for (c, ch) in out.iter_mut().enumerate() {
            let p = &self.params[c * (k + 1)..(c + 1) * (k + 1)];
            ch.value = p[0].to_f64();
            for j in 0..k {
                let a = p[j + 1].to_f64();
                let w = self.omegas[j];
                let (s, co) = (w * t_secs + self.phases[c * k + j]).sin_cos();
                ch.value += a * s;
                ch.rate += a * w * co;
                ch.acc -= a * w * w * s;
            }
        }
        out
    }

    /// The rotation jets of yaw, pitch and roll, and the jet of `q_z ⊗ q_y`.
    fn rotation_jets(ch: &[Channel; NUM_CHANNELS]) -> [QuatJet; 4] {
        let roll = axis_jet(&ch[3], 0);
        let pitch = axis_jet(&ch[4], 1);
        let yaw = axis_jet(&ch[5], 2);
        let yaw_pitch = yaw.mul(&pitch);
        [yaw, pitch, roll, yaw_pitch]
    }
}

impl<S: Real> PoseField<S> for SinusoidMotion<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        self.params.len()
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
        for (i, &t) in times_secs.iter().enumerate() {
            let ch = self.channels(t);
            let [_, _, roll, yaw_pitch] = Self::rotation_jets(&ch);
            let q = yaw_pitch.mul(&roll);
            out.rotation[i] = q.value;
            out.translation[i] = Vector3::new(ch[0].value, ch[1].value, ch[2].value);
            if order >= Order::Velocity {
                out.rotation_rate[i] = q.rate;
                out.lin_vel_world[i] = Vector3::new(ch[0].rate, ch[1].rate, ch[2].rate);
            }
            if order >= Order::Acceleration {
                out.rotation_acc[i] = q.acc;
                out.lin_acc_world[i] = Vector3::new(ch[0].acc, ch[1].acc, ch[2].acc);
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
        grad.check_shape(times_secs.len(), grad.order)?;
        if param_grad.len() != self.params.len() {
            return Err(PoseFieldError::Shape {
                what: "parameter gradient",
                expected: self.params.len(),
                got: param_grad.len(),
            });
        }
        let k = self.num_terms();
        let zq = Quaternion::new(0.0, 0.0, 0.0, 0.0);
        for (i, &t) in times_secs.iter().enumerate() {
            let ch = self.channels(t);
            // Cotangents of the channel jets (value, rate, acc).
            let mut g_ch = [Channel::default(); NUM_CHANNELS];
            let has1 = grad.order >= Order::Velocity;
            let has2 = grad.order >= Order::Acceleration;
            for c in 0..3 {
                g_ch[c].value = grad.translation[i][c];
                if has1 {
                    g_ch[c].rate = grad.lin_vel_world[i][c];
                }
                if has2 {
                    g_ch[c].acc = grad.lin_acc_world[i][c];
                }
            }
            let g_q = QuatJet::new(
                grad.rotation[i],
                if has1 { grad.rotation_rate[i] } else { zq },
                if has2 { grad.rotation_acc[i] } else { zq },
            );
            let [yaw, pitch, roll, yaw_pitch] = Self::rotation_jets(&ch);
            // q = (q_z ⊗ q_y) ⊗ q_x
            let (g_yaw_pitch, g_roll) = yaw_pitch.mul_backward(&roll, &g_q);
            let (g_yaw, g_pitch) = yaw.mul_backward(&pitch, &g_yaw_pitch);
            g_ch[3] = axis_jet_backward(&ch[3], 0, &g_roll);
            g_ch[4] = axis_jet_backward(&ch[4], 1, &g_pitch);
            g_ch[5] = axis_jet_backward(&ch[5], 2, &g_yaw);
            // Channel jets to parameters: ∂c/∂b = (1, 0, 0),
            // ∂c/∂a_k = (sin, ω cos, −ω² sin)(ω_k t + φ).
            for (c, g) in g_ch.iter().enumerate() {
                let base = c * (k + 1);
                param_grad[base] += S::from_f64(g.value);
                for j in 0..k {
                    let w = self.omegas[j];
                    let (s, co) = (w * t + self.phases[c * k + j]).sin_cos();
                    param_grad[base + j + 1] +=
                        S::from_f64(g.value * s + g.rate * w * co - g.acc * w * w * s);
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{EulerZyx, quat_from_euler_zyx};
    use crate::testing::{check_f32_matches_f64, check_pose_field};

    fn range() -> TimeRange {
        TimeRange::new(0.5, 4.0).unwrap()
    }

    fn times() -> Vec<f64> {
        (0..9)
            .map(|i| 0.5 + 3.5 * (i as f64 + 0.37) / 9.0)
            .collect()
    }

    #[test]
    fn sinusoid_motion_passes_the_conformance_suite() {
        let mut field = SinusoidMotion::<f64>::handheld(range(), 3);
        check_pose_field(&mut field, &times());
        // With non-zero offsets (a rotation far from the identity) too.
        let mut field = SinusoidMotion::<f64>::random(range(), 8, 3, 1.0, 1.2, 0.2, 2.0).unwrap();
        field.params_mut(&mut |_, p| {
            for c in 0..NUM_CHANNELS {
                p[c * 4] = 0.3 * (c as f64 + 1.0);
            }
        });
        check_pose_field(&mut field, &times());
    }

    #[test]
    fn time_derivatives_match_forward_mode_autodiff() {
        use num_dual::{Dual2_64, DualNum, second_derivative};
        type D = Dual2_64;
        // An oracle independent of the product rule: q(t) evaluated in second-order dual numbers.
        let mut field = SinusoidMotion::<f64>::random(range(), 8, 3, 1.0, 1.2, 0.2, 2.0).unwrap();
        field.params_mut(&mut |_, p| p[5 * 4] = 2.5); // yaw offset far from 0
        let k = field.num_terms();
        let chan = |c: usize, t: D| -> D {
            let p = &field.params[c * (k + 1)..(c + 1) * (k + 1)];
            let mut v = D::from_re(p[0]);
            for j in 0..k {
                v += (t * field.omegas[j] + field.phases[c * k + j]).sin() * p[j + 1];
            }
            v
        };
        let hamilton = |a: [D; 4], b: [D; 4]| -> [D; 4] {
            [
                a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
            ]
        };
        let axis_q = |theta: D, axis: usize| -> [D; 4] {
            let half = theta * 0.5;
            let mut q = [
                half.cos(),
                D::from_re(0.0),
                D::from_re(0.0),
                D::from_re(0.0),
            ];
            q[axis + 1] = half.sin();
            q
        };
        let ts = times();
        let mut out = PoseBatch::default();
        field.evaluate(&ts, Order::Acceleration, &mut out).unwrap();
        for (i, &t) in ts.iter().enumerate() {
            let q: [(f64, f64, f64); 4] = second_derivative(
                |t: D| {
                    let zy = hamilton(axis_q(chan(5, t), 2), axis_q(chan(4, t), 1));
                    hamilton(zy, axis_q(chan(3, t), 0))
                },
                t,
            );
            let wxyz = |x: &Quaternion<f64>| [x.w, x.i, x.j, x.k];
            for (m, (v, d1, d2)) in q.iter().enumerate() {
                assert!((wxyz(&out.rotation[i])[m] - v).abs() < 1e-14);
                assert!((wxyz(&out.rotation_rate[i])[m] - d1).abs() < 1e-13);
                assert!((wxyz(&out.rotation_acc[i])[m] - d2).abs() < 1e-12);
            }
            for c in 0..3 {
                let (v, d1, d2) = second_derivative(|t: D| chan(c, t), t);
                assert!((out.translation[i][c] - v).abs() < 1e-14);
                assert!((out.lin_vel_world[i][c] - d1).abs() < 1e-13);
                assert!((out.lin_acc_world[i][c] - d2).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn sinusoid_rotation_is_zyx_euler_of_its_channels() {
        let field = SinusoidMotion::<f64>::handheld(range(), 5);
        let mut out = PoseBatch::default();
        field.evaluate(&times(), Order::Pose, &mut out).unwrap();
        for (i, &t) in times().iter().enumerate() {
            let ch = field.channels(t);
            let q = quat_from_euler_zyx(&EulerZyx {
                yaw: ch[5].value,
                pitch: ch[4].value,
                roll: ch[3].value,
            });
            assert!((q.into_inner() - out.rotation[i]).norm() < 1e-15);
        }
    }

    #[test]
    fn handheld_magnitudes_are_realistic() {
        let field = SinusoidMotion::<f64>::handheld(TimeRange::new(0.0, 60.0).unwrap(), 1);
        let ts: Vec<f64> = (0..6001).map(|i| i as f64 * 0.01).collect();
        let mut out = PoseBatch::default();
        field.evaluate(&ts, Order::Velocity, &mut out).unwrap();
        let max_p = out.translation.iter().map(|p| p.amax()).fold(0.0, f64::max);
        assert!((0.1..=0.3).contains(&max_p), "max |p_i| = {max_p}");
        let max_angle = (0..ts.len())
            .map(|i| {
                crate::geometry::so3_log(&nalgebra::UnitQuaternion::new_unchecked(out.rotation[i]))
                    .norm()
            })
            .fold(0.0, f64::max);
        // Three axes of at most 15° each.
        assert!(max_angle > 5f64.to_radians() && max_angle < 27f64.to_radians());
        assert!(field.omegas.iter().all(|w| {
            let hz = w / std::f64::consts::TAU;
            (0.1..=1.5).contains(&hz)
        }));
    }

    #[test]
    fn f32_sinusoid_matches_f64() {
        let a = SinusoidMotion::<f32>::handheld(range(), 9);
        let b = SinusoidMotion::<f64>::handheld(range(), 9);
        check_f32_matches_f64(&a, &b, &times(), 1e-6);
    }

    #[test]
    fn invalid_construction_is_an_error() {
        assert!(SinusoidMotion::<f64>::random(range(), 0, 0, 1.0, 1.0, 0.1, 1.0).is_err());
        let r = SinusoidMotion::<f64>::new(range(), vec![1.0], vec![0.0; 5], &[0.0; 6], &[0.0; 6]);
        assert!(matches!(r, Err(PoseFieldError::Shape { .. })));
    }
}
