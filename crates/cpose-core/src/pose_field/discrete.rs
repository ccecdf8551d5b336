//! BARF's discrete per-frame poses (Lin et al. 2021, `model/barf.py`), made a continuous field by
//! interpolating the se(3) tangents between frames.

use nalgebra::{Isometry3, Matrix3, Vector3};
use num_dual::{Dual2, DualSVec64};
use serde::{Deserialize, Serialize};

use super::lie_dual::{self, Jet, Quat, Scalar};
use super::{Order, ParamKind, PoseBatch, PoseField, PoseFieldError, check_times};
use crate::{Real, TimeRange};

/// Parameters per frame: one se(3) tangent `ξ = (ω, v)`, rotation first.
const PER_FRAME: usize = 6;
/// Local parameters of one evaluation: the tangents of the two frames around `t`.
const LOCAL: usize = 2 * PER_FRAME;

/// One se(3) tangent per frame (BARF's `Embedding(N, 6)`), linearly interpolated in between.
///
/// Parameters: `6N` values of kind [`ParamKind::Pose`], frame by frame `ξ_i = (ω_i, v_i)`
/// (rotation vector in radians first, then the translation tangent), zero at construction so
/// every pose is the identity. The pose at frame time `t_i` is the true se(3) exponential
///
/// `Exp(ξ_i) = (exp(ω_i), V(ω_i)·v_i)`, `V(ω) = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×²`,
///
/// (BARF `camera.py`, docs/methods.md §2.2; refinement `P_i = Exp(δξ_i) ∘ P⁰_i` is the
/// composition of this field with the initial poses).
///
/// **Between frames** (`t_i ≤ t ≤ t_{i+1}`, `u = (t − t_i)/(t_{i+1} − t_i)`) the *tangent* is
/// interpolated linearly and then exponentiated:
///
/// `ξ(t) = (1 − u) ξ_i + u ξ_{i+1}`, `world_from_body(t) = Exp(ξ(t))`.
///
/// The field is continuous and smooth inside each segment, but only C⁰ at interior frame
/// times. There the derivatives are **one-sided from the right**: those of the segment that
/// starts at `t` (at the last frame time, those of the last segment, from the left). Outside
/// `[t_0, t_{N−1}]` evaluation is an [`PoseFieldError::OutOfRange`] error. Since `ξ(t)` is
/// continuous, `q(t) = exp(ω(t)/2)` never flips sign.
#[derive(Clone, Debug)]
pub struct DiscretePoses<S: Real = f32> {
    frame_times_secs: Vec<f64>,
    range: TimeRange,
    xi: Vec<S>,
}

impl<S: Real> DiscretePoses<S> {
    /// Identity poses at `frame_times_secs` (seconds since the sequence origin, strictly
    /// increasing, at least two: a single frame has no time range to interpolate over and is an
    /// error — use a constant field instead).
    pub fn new(frame_times_secs: &[f64]) -> Result<Self, PoseFieldError> {
        if frame_times_secs.len() < 2 {
            return Err(PoseFieldError::Invalid(format!(
                "discrete poses need at least 2 frame times, got {}",
                frame_times_secs.len()
            )));
        }
        if let Some(w) = frame_times_secs.windows(2).find(|w| {
            w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less)
                || !w[0].is_finite()
                || !w[1].is_finite()
        }) {
            return Err(PoseFieldError::Invalid(format!(
                "frame times must be finite and strictly increasing, got {} then {}",
                w[0], w[1]
            )));
        }
        let first = frame_times_secs[0];
        let last = frame_times_secs[frame_times_secs.len() - 1];
        let range = TimeRange::new(first, last)?;
        Ok(Self {
            frame_times_secs: frame_times_secs.to_vec(),
            range,
            xi: vec![S::ZERO; PER_FRAME * frame_times_secs.len()],
        })
    }

    /// Poses `world_from_body[i]` at the frame times, stored as `ξ_i = Log(pose_i)` (see
    /// [`DiscretePoses::set_poses`]).
    pub fn from_poses(
        frame_times_secs: &[f64],
        world_from_body: &[Isometry3<f64>],
    ) -> Result<Self, PoseFieldError> {
        let mut field = Self::new(frame_times_secs)?;
        field.set_poses(world_from_body)?;
        Ok(field)
    }

    /// Overwrites every `ξ_i` with `Log(world_from_body[i])`, in place (e.g. to reset the frames
    /// to a spline fitted to them, the B-spline baseline's "re-fit every 100 steps"). `Log` takes
    /// the rotation angle in `[0, π]` and inverts `Exp` up to rounding, so the field reproduces
    /// the poses at the frame times; between frames the tangents are interpolated, which suits
    /// small per-frame corrections (BARF) rather than poses rotating by more than π in total.
    pub fn set_poses(&mut self, world_from_body: &[Isometry3<f64>]) -> Result<(), PoseFieldError> {
        if world_from_body.len() != self.frame_times_secs.len() {
            return Err(PoseFieldError::Shape {
                what: "poses",
                expected: self.frame_times_secs.len(),
                got: world_from_body.len(),
            });
        }
        for (i, pose) in world_from_body.iter().enumerate() {
            let xi = log_se3(pose)?;
            for k in 0..PER_FRAME {
                self.xi[PER_FRAME * i + k] = S::from_f64(xi[k]);
            }
        }
        Ok(())
    }

    /// The frame times, seconds.
    pub fn frame_times_secs(&self) -> &[f64] {
        &self.frame_times_secs
    }

    /// `ξ_i = (ω_i, v_i)` of frame `i` in `f64`.
    pub fn tangent(&self, i: usize) -> [f64; 6] {
        std::array::from_fn(|k| self.xi[PER_FRAME * i + k].to_f64())
    }

    /// The segment `i` with `t_i ≤ t < t_{i+1}` (the last segment at `t = t_{N−1}`), and
    /// `u = (t − t_i)/(t_{i+1} − t_i)` and `du/dt`.
    fn segment(&self, t_secs: f64) -> (usize, f64, f64) {
        let n = self.frame_times_secs.len();
        let i = self
            .frame_times_secs
            .partition_point(|&tf| tf <= t_secs)
            .saturating_sub(1)
            .min(n - 2);
        let (t0, t1) = (self.frame_times_secs[i], self.frame_times_secs[i + 1]);
        let inv_dt = 1.0 / (t1 - t0);
        (i, (t_secs - t0) * inv_dt, inv_dt)
    }

    fn local_params(&self, i: usize) -> [f64; LOCAL] {
        std::array::from_fn(|k| self.xi[PER_FRAME * i + k].to_f64())
    }
}

/// The pose jet at `u` in a segment from the tangents `a = ξ_i`, `b = ξ_{i+1}` (`θ[0..6]`,
/// `θ[6..12]`): `ξ = (1−u)a + ub`, `ξ̇ = (b − a)·du/dt`, `ξ̈ = 0`, pushed through `Exp` with
/// [`Dual2`] numbers (exact chain rule).
fn segment_jet<D: Scalar>(theta: &[D; LOCAL], u: f64, inv_dt: f64) -> Jet<D> {
    let xi: [Dual2<D>; PER_FRAME] = std::array::from_fn(|k| {
        let (a, b) = (theta[k], theta[PER_FRAME + k]);
        lie_dual::jet2(a * (1.0 - u) + b * u, (b - a) * inv_dt, D::zero())
    });
    let omega = [xi[0], xi[1], xi[2]];
    let v = [xi[3], xi[4], xi[5]];
    let q = lie_dual::exp_rotvec(&omega);
    let p = lie_dual::se3_v_times(&omega, &v);
    Jet {
        q: Jet::quat_from_dual2(&q),
        p: Jet::vec_from_dual2(&p),
    }
}

/// `Log` of SE(3): `ω = log(R)` (angle in `[0, π]`), `v = V(ω)⁻¹ p`.
fn log_se3(pose: &Isometry3<f64>) -> Result<[f64; 6], PoseFieldError> {
    let mut q = *pose.rotation.quaternion();
    if q.w < 0.0 {
        q = -q;
    }
    let omega = lie_dual::log_rotvec(&Quat::constant(&q));
    let mut v_mat = Matrix3::zeros();
    for c in 0..3 {
        let mut e = [0.0; 3];
        e[c] = 1.0;
        let col = lie_dual::se3_v_times(&omega, &e);
        v_mat.set_column(c, &Vector3::from(col));
    }
    let v = v_mat
        .lu()
        .solve(&pose.translation.vector)
        .ok_or_else(|| PoseFieldError::Invalid("singular V(ω) in Log of SE(3)".into()))?;
    Ok([omega[0], omega[1], omega[2], v.x, v.y, v.z])
}

/// `Exp` of SE(3) in `f64` (tests compare frame poses against it).
#[cfg(test)]
pub(crate) fn exp_se3(xi: &[f64; 6]) -> Isometry3<f64> {
    let omega = [xi[0], xi[1], xi[2]];
    let q = lie_dual::exp_rotvec(&omega);
    let p = lie_dual::se3_v_times(&omega, &[xi[3], xi[4], xi[5]]);
    Isometry3::from_parts(
        Vector3::from(p).into(),
        nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
    )
}

impl<S: Real> PoseField<S> for DiscretePoses<S> {
    fn time_range(&self) -> TimeRange {
        self.range
    }

    fn num_params(&self) -> usize {
        self.xi.len()
    }

    fn params(&self, visit: &mut dyn FnMut(ParamKind, &[S])) {
        visit(ParamKind::Pose, &self.xi);
    }

    fn params_mut(&mut self, visit: &mut dyn FnMut(ParamKind, &mut [S])) {
        visit(ParamKind::Pose, &mut self.xi);
    }

    fn evaluate(
        &self,
        times_secs: &[f64],
        order: Order,
        out: &mut PoseBatch,
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        out.reset(times_secs.len(), order);
        for (n, &t) in times_secs.iter().enumerate() {
            let (i, u, inv_dt) = self.segment(t);
            let jet = segment_jet(&self.local_params(i), u, inv_dt);
            lie_dual::write_jet(out, n, &jet);
        }
        Ok(())
    }

    /// Stateless: recomputes each evaluation with `DualSVec64<12>` parameters (forward-mode
    /// AD over `ξ_i, ξ_{i+1}`) and accumulates `Jᵀ · cotangent`.
    fn backward(
        &mut self,
        times_secs: &[f64],
        grad: &PoseBatch,
        param_grad: &mut [S],
    ) -> Result<(), PoseFieldError> {
        check_times(&self.range, times_secs)?;
        grad.check_shape(times_secs.len(), grad.order)?;
        if param_grad.len() != self.xi.len() {
            return Err(PoseFieldError::Shape {
                what: "parameter gradient",
                expected: self.xi.len(),
                got: param_grad.len(),
            });
        }
        for (n, &t) in times_secs.iter().enumerate() {
            let (i, u, inv_dt) = self.segment(t);
            let theta: [DualSVec64<LOCAL>; LOCAL] = lie_dual::seed(&self.local_params(i));
            let jet = segment_jet(&theta, u, inv_dt);
            let g = lie_dual::pullback(&jet, grad, n);
            for k in 0..LOCAL {
                param_grad[PER_FRAME * i + k] += S::from_f64(g[k]);
            }
        }
        Ok(())
    }
}

/// Configuration of [`DiscretePoses`] for the pose-field registry. Nothing to choose: the frame
/// times come from the data, and the poses start at the identity.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiscretePosesConfig {}

impl DiscretePosesConfig {
    /// Identity poses at `frame_times_secs` (see [`DiscretePoses::new`]). `range` is not used:
    /// the field's range is `[t_0, t_{N−1}]` of the frame times.
    pub fn init<S: Real>(
        &self,
        _range: TimeRange,
        frame_times_secs: &[f64],
    ) -> Result<DiscretePoses<S>, PoseFieldError> {
        DiscretePoses::new(frame_times_secs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_field::params_from_slice;
    use crate::testing::{check_f32_matches_f64, check_pose_field};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const FRAMES: [f64; 5] = [0.0, 0.4, 1.0, 1.3, 2.0];

    fn random_params(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-0.8..0.8)).collect()
    }

    fn random_field<S: Real>(seed: u64) -> DiscretePoses<S> {
        let mut f = DiscretePoses::<S>::new(&FRAMES).unwrap();
        let p: Vec<S> = random_params(f.num_params(), seed)
            .into_iter()
            .map(S::from_f64)
            .collect();
        params_from_slice(&mut f, &p).unwrap();
        f
    }

    /// Times strictly between frame times (the field is only C⁰ at frames).
    fn between_frames() -> Vec<f64> {
        vec![0.1, 0.25, 0.55, 0.9, 1.1, 1.25, 1.5, 1.95]
    }

    #[test]
    fn passes_the_conformance_suite() {
        let mut f = random_field::<f64>(1);
        check_pose_field(&mut f, &between_frames());
        // At the all-zero initialisation too (Taylor branches, finite derivatives).
        let mut zero = DiscretePoses::<f64>::new(&FRAMES).unwrap();
        check_pose_field(&mut zero, &between_frames());
    }

    #[test]
    fn frame_poses_are_se3_exponentials_and_roundtrip_from_poses() {
        let f = random_field::<f64>(2);
        let mut out = PoseBatch::default();
        f.evaluate(&FRAMES, Order::Pose, &mut out).unwrap();
        let poses: Vec<_> = (0..FRAMES.len()).map(|i| exp_se3(&f.tangent(i))).collect();
        for i in 0..FRAMES.len() {
            let got = out.world_from_body(i);
            assert!((got.translation.vector - poses[i].translation.vector).norm() < 1e-12);
            assert!(got.rotation.angle_to(&poses[i].rotation) < 1e-12);
        }
        let g = DiscretePoses::<f64>::from_poses(&FRAMES, &poses).unwrap();
        let mut back = PoseBatch::default();
        g.evaluate(&FRAMES, Order::Pose, &mut back).unwrap();
        for i in 0..FRAMES.len() {
            let got = back.world_from_body(i);
            assert!((got.translation.vector - poses[i].translation.vector).norm() < 1e-12);
            assert!(got.rotation.angle_to(&poses[i].rotation) < 1e-12);
        }
    }

    #[test]
    fn continuous_across_frames_with_one_sided_derivatives() {
        let f = random_field::<f64>(3);
        let eps = 1e-9;
        for &t in &FRAMES[1..FRAMES.len() - 1] {
            let mut out = PoseBatch::default();
            f.evaluate(&[t - eps, t, t + eps], Order::Velocity, &mut out)
                .unwrap();
            assert!((out.rotation[0] - out.rotation[2]).norm() < 1e-7);
            assert!((out.translation[0] - out.translation[2]).norm() < 1e-7);
            // At the frame time the derivative is that of the segment starting there.
            assert!((out.rotation_rate[1] - out.rotation_rate[2]).norm() < 1e-6);
            assert!((out.lin_vel_world[1] - out.lin_vel_world[2]).norm() < 1e-6);
        }
    }

    #[test]
    fn f32_matches_f64() {
        let a = random_field::<f32>(4);
        let b = random_field::<f64>(4);
        check_f32_matches_f64(&a, &b, &between_frames(), 1e-4);
    }

    #[test]
    fn bad_construction_is_an_error() {
        assert!(matches!(
            DiscretePoses::<f64>::new(&[0.0, 1.0, 0.5]),
            Err(PoseFieldError::Invalid(_))
        ));
        assert!(matches!(
            DiscretePoses::<f64>::new(&[0.0, 0.0]),
            Err(PoseFieldError::Invalid(_))
        ));
        assert!(matches!(
            DiscretePoses::<f64>::new(&[1.0]),
            Err(PoseFieldError::Invalid(_))
        ));
        assert!(matches!(
            DiscretePoses::<f64>::from_poses(&[0.0, 1.0], &[Isometry3::identity()]),
            Err(PoseFieldError::Shape { .. })
        ));
        let range = TimeRange::new(0.0, 1.0).unwrap();
        assert!(
            DiscretePosesConfig::default()
                .init::<f32>(range, &[0.0, 1.0])
                .is_ok()
        );
        let cfg: DiscretePosesConfig = toml::from_str("").unwrap();
        assert_eq!(cfg, DiscretePosesConfig::default());
        assert!(toml::from_str::<DiscretePosesConfig>("frames = 3").is_err());
    }
}
