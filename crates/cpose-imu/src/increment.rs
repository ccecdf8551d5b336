//! The IMU's motion over a frame interval as a tie on the relative pose of task `slam`'s PoseNet
//! tracker (the loose coupling of the paper's §3.4 in relative form, used by
//! [`crate::tracker::RelativeImu`]): the tracker's [`RelativePoseTerm`] hook.

use cpose_core::nn::l1_subgradient;
use cpose_slam::track::RelativePoseTerm;
use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};

/// A measured motion from the previous pose `T_{i−1}` to the one being tracked — the IMU's
/// integrals over the frame interval, in the tracked (body) frame. It ties PoseNet's relative
/// pose `PN(t_i)` to `T̂_rel = T_ref⁻¹ T_{i−1} ΔT`, what it must be for `T_i = T_ref ∘ PN(t_i)`
/// to move by `ΔT`: `λ_R |q_rel − s q̂_rel|₁ + λ_p ‖t_rel − t̂_rel‖₁`, with `s = ±1` aligning the
/// signs — the relative form of the paper's loose coupling (§3.4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionIncrement {
    /// `Δq = q_{i−1}* ⊗ q_i`.
    pub rotation: UnitQuaternion<f64>,
    /// `λ_R`, in units of the tracking loss.
    pub rotation_weight: f64,
    /// `Δp = R_{i−1}ᵀ (p_i − p_{i−1})` and `λ_p` (per metre), if measured.
    pub translation: Option<(Vector3<f64>, f64)>,
}

impl MotionIncrement {
    /// The tie as a term of the tracker's next frame
    /// ([`PoseNetTracker::set_relative_term`](cpose_slam::track::PoseNetTracker::set_relative_term)).
    pub fn term(self) -> Box<dyn RelativePoseTerm> {
        Box::new(IncrementTie {
            measured: self,
            target: None,
        })
    }
}

/// [`MotionIncrement`] as a term on the network's output.
struct IncrementTie {
    measured: MotionIncrement,
    /// The increment in the network's output, `T̂_rel`, with the same weights (set when the
    /// frame begins).
    target: Option<MotionIncrement>,
}

impl RelativePoseTerm for IncrementTie {
    fn begin(&mut self, reference: &Isometry3<f64>, history: &[Isometry3<f64>]) {
        let inc = &self.measured;
        let previous = &history[history.len() - 1];
        let reference = reference.inverse();
        let translation = inc.translation.map(|(dp, weight)| {
            let p = previous.translation.vector + previous.rotation * dp;
            (
                reference.rotation * p + reference.translation.vector,
                weight,
            )
        });
        self.target = Some(MotionIncrement {
            rotation: reference.rotation * previous.rotation * inc.rotation,
            rotation_weight: inc.rotation_weight,
            translation,
        });
    }

    fn gradient(&self, q: &Quaternion<f64>, t: &Vector3<f64>) -> (Quaternion<f64>, Vector3<f64>) {
        let Some(target) = &self.target else {
            return (Quaternion::new(0.0, 0.0, 0.0, 0.0), Vector3::zeros());
        };
        let grad_q = rotation_tie(q, &target.rotation, target.rotation_weight).1;
        let grad_t = target
            .translation
            .map_or_else(Vector3::zeros, |(translation, weight)| {
                translation_tie(t, &translation, weight).1
            });
        (grad_q, grad_t)
    }
}

/// `λ |q − s q̂|₁` with `s = ±1` the sign of `⟨q, q̂⟩`, and its gradient `λ sign(q − s q̂)` in `q`
/// ([`MotionIncrement`]).
fn rotation_tie(
    q: &Quaternion<f64>,
    target: &UnitQuaternion<f64>,
    weight: f64,
) -> (f64, Quaternion<f64>) {
    let s = if q.coords.dot(&target.coords) < 0.0 {
        -1.0
    } else {
        1.0
    };
    let r = q - target.into_inner() * s;
    (
        weight * r.coords.abs().sum(),
        Quaternion::from(r.coords.map(l1_subgradient)) * weight,
    )
}

/// `λ ‖t − t̂‖₁` and its gradient `λ sign(t − t̂)` in `t` ([`MotionIncrement`]).
fn translation_tie(t: &Vector3<f64>, target: &Vector3<f64>, weight: f64) -> (f64, Vector3<f64>) {
    let r = t - target;
    (weight * r.abs().sum(), r.map(l1_subgradient) * weight)
}

#[cfg(test)]
mod tests {
    use cpose_core::TimeRange;
    use cpose_slam::track::{PoseModel, PoseNetTrackConfig, PoseNetTracker, Reference};
    use nalgebra::Translation3;

    use super::*;

    #[test]
    fn ties_match_central_differences() {
        let target = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.9);
        for q in [
            Quaternion::new(0.8, 0.1, -0.3, 0.4),
            Quaternion::new(-0.5, 0.2, 0.4, -0.7),
        ] {
            let (_, g) = rotation_tie(&q, &target, 1.7);
            for k in 0..4 {
                let h = 1e-7;
                let (mut a, mut b) = (q.coords, q.coords);
                a[k] += h;
                b[k] -= h;
                let numeric = (rotation_tie(&Quaternion::from(a), &target, 1.7).0
                    - rotation_tie(&Quaternion::from(b), &target, 1.7).0)
                    / (2.0 * h);
                assert!(
                    (numeric - g.coords[k]).abs() < 1e-6,
                    "{k}: {numeric} vs {g:?}"
                );
            }
        }
        let (t, target) = (Vector3::new(0.3, -0.2, 0.05), Vector3::new(0.1, 0.4, -0.3));
        let (_, g) = translation_tie(&t, &target, 0.8);
        for k in 0..3 {
            let h = 1e-7;
            let (mut a, mut b) = (t, t);
            a[k] += h;
            b[k] -= h;
            let numeric = (translation_tie(&a, &target, 0.8).0
                - translation_tie(&b, &target, 0.8).0)
                / (2.0 * h);
            assert!((numeric - g[k]).abs() < 1e-6, "{k}: {numeric} vs {g:?}");
        }
    }

    /// With a measured increment and its prediction steps, the frame starts moved by it from the
    /// previous pose; without, PoseNet (at the identity) predicts no motion.
    #[test]
    fn a_motion_increment_moves_the_start_of_the_frame() {
        let range = TimeRange::new(0.0, 1.0).unwrap();
        let config = PoseNetTrackConfig::default();
        let prev = Isometry3::from_parts(
            Translation3::new(0.5, -1.0, 2.0),
            UnitQuaternion::from_euler_angles(0.4, -0.3, 1.0),
        );
        let delta = Isometry3::from_parts(
            Translation3::new(0.04, -0.03, 0.02),
            UnitQuaternion::from_euler_angles(0.05, -0.08, 0.03),
        );
        let truth = prev * delta;
        let errors = |increment: Option<MotionIncrement>| {
            let mut tracker = PoseNetTracker::new(&config, Reference::Previous, range, 0).unwrap();
            tracker.set_relative_term(increment.map(MotionIncrement::term), 60);
            let start = tracker.begin(1, 0.4, &[prev]).unwrap();
            (
                start.rotation.angle_to(&truth.rotation).to_degrees(),
                (start.translation.vector - truth.translation.vector).norm(),
            )
        };
        let without = errors(None);
        let increment = MotionIncrement {
            rotation: delta.rotation,
            rotation_weight: 1.0,
            translation: None,
        };
        let turned = errors(Some(increment));
        let moved = errors(Some(MotionIncrement {
            translation: Some((delta.translation.vector, 1.0)),
            ..increment
        }));
        assert!(without.0 > 5.0 && without.1 > 0.05, "{without:?}");
        assert!(turned.0 < 0.1 * without.0, "{without:?} → {turned:?}");
        // The rotation tie alone leaves the translation network where it was.
        assert!(
            (turned.1 - without.1).abs() < 1e-9,
            "{without:?} → {turned:?}"
        );
        assert!(moved.1 < 0.1 * without.1, "{without:?} → {moved:?}");
    }
}
