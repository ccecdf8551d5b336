//! Initial poses for NeRF from noisy or unknown poses: perturbations of the ground truth.
//!
//! * [`PoseNoise::TimeCorrelated`] — the paper's (supplement, "Implementation details"):
//!   rotation and translation perturbed separately, drawn at a subset of frames (anchors) and
//!   interpolated between them, so that the maximal deviation is set exactly. By default the
//!   anchors drift — the error accumulates with time, "due to drift and error accumulation" as
//!   the supplement motivates it ([`AnchorDraws`]).
//! * [`PoseNoise::Iid`] — BARF's: an independent se(3) draw per frame.
//! * [`PoseNoise::Identity`] — unknown poses (the LLFF protocol): every initial pose is the
//!   identity.
//! * [`PoseNoise::None`] — the ground truth itself (the reference run with true poses).
//!
//! All randomness comes from a `ChaCha8Rng` seeded with the variant's `seed`.

use cpose_core::geometry::se3_exp;
use cpose_core::random::standard_normal;
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3, Vector6};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::SceneError;

/// How initial poses are made from the ground truth. A `[noise]` TOML table tagged by `kind`:
/// `"time_correlated"`, `"iid"`, `"identity"` or `"none"`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", deny_unknown_fields)]
pub enum PoseNoise {
    /// Anchors at frames `0, M, 2M, …` and always the last frame (`M = anchor_every`; a last
    /// gap shorter than `M / 2` is merged into the previous segment). Per anchor draw a rotation
    /// vector `r` (axis uniform on the sphere, angle `u`, `u ~ U(0, 1)`) and a centre
    /// displacement `d` (direction uniform, length `u' ~ U(0, 1)`); with
    /// [`AnchorDraws::Drift`] anchor `k` carries the sums of the draws of anchors `1..=k`
    /// (anchor 0 is exact), with [`AnchorDraws::Independent`] its own draw. All rotation
    /// vectors are then scaled by one factor so that the largest angle is `max_rotation_deg`,
    /// all displacements so that the largest is `max_translation · diameter`; `R_k = Exp(r_k)`,
    /// `Δc_k = d_k`. Between anchors `R_δ` is the slerp and `Δc` the linear interpolation in
    /// the frame index. The noise acts
    /// in world coordinates, as BARF's and the paper's (`T_init = T_{c,w} ∘ T_noise`):
    /// `world_from_camera_init = (R_δ, Δc) ∘ world_from_camera_gt`, i.e. `R_init = R_δ R_gt`,
    /// `c_init = R_δ c_gt + Δc` — a rotation about the world origin (the orbit's centre) and a
    /// shift. The orientation error of every frame is exactly `angle(R_δ)`.
    #[serde(rename = "time_correlated")]
    TimeCorrelated {
        /// Largest rotation error over the frames, degrees (0 … 180; attained at an anchor).
        #[serde(default = "default_max_rotation_deg")]
        max_rotation_deg: f64,
        /// Largest camera-centre error, as a fraction of the orbit diameter (≥ 0).
        #[serde(default = "default_max_translation")]
        max_translation: f64,
        /// Frames between anchors (≥ 1; 1 perturbs every frame independently).
        #[serde(default = "default_anchor_every")]
        anchor_every: usize,
        /// Whether the anchors' perturbations accumulate (`"drift"`) or are drawn apart
        /// (`"independent"`).
        #[serde(default)]
        anchors: AnchorDraws,
        /// Seed of the draw.
        #[serde(default)]
        seed: u64,
    },
    /// BARF's synthetic perturbation: per frame `ξ = (ω, v) ~ N(0, σ² I₆)` (rotation first) and
    /// `cam_from_world_init = cam_from_world_gt · Exp(ξ)`, i.e. `world_from_camera_init =
    /// Exp(ξ)⁻¹ · world_from_camera_gt`, with the true SE(3) exponential
    /// [`cpose_core::geometry::se3_exp`] (translation `J_l(ω) v`). This is the order of BARF's
    /// `camera.pose.compose([pose_noise, pose_GT])` (`model/barf.py`, `get_pose`), whose poses are
    /// `cam_from_world`, and of the paper's supplement (`T_init = T_{c,w} ∘ T_noise`): the
    /// noise acts in world coordinates, a rotation about the world origin.
    #[serde(rename = "iid")]
    Iid {
        /// Standard deviation of each of the six components (BARF: 0.15).
        #[serde(default = "default_sigma")]
        sigma: f64,
        /// Seed of the draw.
        #[serde(default)]
        seed: u64,
    },
    /// Unknown poses: every initial pose is the identity. (Empty braces rather than a unit
    /// variant: serde's internally tagged unit variants ignore unknown keys.)
    #[serde(rename = "identity")]
    Identity {},
    /// Initial poses are the ground truth.
    #[serde(rename = "none")]
    None {},
}

/// How the anchors of [`PoseNoise::TimeCorrelated`] relate to each other.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnchorDraws {
    /// A random walk from the true pose of frame 0: the error grows with time, as an odometry's
    /// does. Neighbouring anchors share most of their perturbation.
    #[default]
    Drift,
    /// Every anchor is perturbed on its own, so neighbouring anchors may err in opposite
    /// directions, and no frame is exact.
    Independent,
}

fn default_max_rotation_deg() -> f64 {
    60.0
}
fn default_max_translation() -> f64 {
    0.2
}
fn default_anchor_every() -> usize {
    10
}
fn default_sigma() -> f64 {
    0.15
}

impl Default for PoseNoise {
    /// The paper's time-correlated noise with the defaults above (60°, 20 % of the diameter,
    /// an anchor every 10 frames, seed 0).
    fn default() -> Self {
        Self::TimeCorrelated {
            max_rotation_deg: default_max_rotation_deg(),
            max_translation: default_max_translation(),
            anchor_every: default_anchor_every(),
            anchors: AnchorDraws::default(),
            seed: 0,
        }
    }
}

impl PoseNoise {
    /// Checks the ranges given in the field docs; the error names the `noise.*` key.
    pub fn validate(&self) -> Result<(), SceneError> {
        let invalid = |key: &'static str, expected: &'static str, found: String| {
            Err(SceneError::Invalid {
                key,
                expected,
                found,
            })
        };
        match *self {
            Self::TimeCorrelated {
                max_rotation_deg,
                max_translation,
                anchor_every,
                ..
            } => {
                if !(0.0..=180.0).contains(&max_rotation_deg) {
                    return invalid(
                        "noise.max_rotation_deg",
                        "a value in [0, 180]",
                        max_rotation_deg.to_string(),
                    );
                }
                if !(max_translation >= 0.0 && max_translation.is_finite()) {
                    return invalid(
                        "noise.max_translation",
                        "a finite value ≥ 0",
                        max_translation.to_string(),
                    );
                }
                if anchor_every == 0 {
                    return invalid("noise.anchor_every", "at least 1", "0".to_owned());
                }
            }
            Self::Iid { sigma, .. } => {
                if !(sigma >= 0.0 && sigma.is_finite()) {
                    return invalid("noise.sigma", "a finite value ≥ 0", sigma.to_string());
                }
            }
            Self::Identity {} | Self::None {} => {}
        }
        Ok(())
    }

    /// The initial `world_from_camera` of every frame from the ground truth `gt` (in frame
    /// order; time-correlated noise interpolates over the index). `diameter` scales
    /// `max_translation` (the orbit's [`diameter`](super::MonocularOrbit::diameter)).
    ///
    /// # Panics
    /// If the parameters are out of range (call [`PoseNoise::validate`] first).
    pub fn apply(&self, gt: &[Isometry3<f64>], diameter: f64) -> Vec<Isometry3<f64>> {
        if let Err(e) = self.validate() {
            panic!("PoseNoise::apply on invalid parameters: {e}");
        }
        match *self {
            Self::TimeCorrelated {
                max_rotation_deg,
                max_translation,
                anchor_every,
                anchors,
                seed,
            } => {
                let (rotations, shifts) = time_correlated_perturbations(
                    gt.len(),
                    max_rotation_deg.to_radians(),
                    max_translation * diameter,
                    anchor_every,
                    anchors,
                    seed,
                );
                gt.iter()
                    .zip(rotations.iter().zip(&shifts))
                    .map(|(pose, (r_delta, dc))| {
                        Isometry3::from_parts(Translation3::from(*dc), *r_delta) * pose
                    })
                    .collect()
            }
            Self::Iid { sigma, seed } => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                gt.iter()
                    .map(|pose| {
                        let xi = Vector6::from_fn(|_, _| sigma * standard_normal(&mut rng));
                        se3_exp(&xi).inverse() * pose
                    })
                    .collect()
            }
            Self::Identity {} => vec![Isometry3::identity(); gt.len()],
            Self::None {} => gt.to_vec(),
        }
    }
}

/// The rotation perturbations `R_δ` and centre displacements `Δc` of `n` frames for
/// [`PoseNoise::TimeCorrelated`] (`max_angle` in radians, `max_shift` in scene units).
fn time_correlated_perturbations(
    n: usize,
    max_angle: f64,
    max_shift: f64,
    anchor_every: usize,
    model: AnchorDraws,
    seed: u64,
) -> (Vec<UnitQuaternion<f64>>, Vec<Vector3<f64>>) {
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let anchors = anchor_frames(n, anchor_every);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Per anchor: (rotation vector, displacement), in drawing order.
    let mut draws: Vec<(Vector3<f64>, Vector3<f64>)> = anchors
        .iter()
        .map(|_| {
            let r = uniform_direction(&mut rng).into_inner() * rng.random::<f64>();
            let d = uniform_direction(&mut rng).into_inner() * rng.random::<f64>();
            (r, d)
        })
        .collect();
    if model == AnchorDraws::Drift {
        draws[0] = (Vector3::zeros(), Vector3::zeros());
        for k in 1..draws.len() {
            let (r, d) = draws[k - 1];
            draws[k].0 += r;
            draws[k].1 += d;
        }
    }
    // Rescale so that the stated maxima are attained (by the largest anchor).
    let largest_angle = draws.iter().map(|(r, _)| r.norm()).fold(0.0, f64::max);
    let largest_length = draws.iter().map(|(_, d)| d.norm()).fold(0.0, f64::max);
    let angle_scale = if largest_angle > 0.0 {
        max_angle / largest_angle
    } else {
        0.0
    };
    let length_scale = if largest_length > 0.0 {
        max_shift / largest_length
    } else {
        0.0
    };
    let rot: Vec<UnitQuaternion<f64>> = draws
        .iter()
        .map(|(r, _)| UnitQuaternion::from_scaled_axis(r * angle_scale))
        .collect();
    let shift: Vec<Vector3<f64>> = draws.iter().map(|(_, d)| d * length_scale).collect();
    let mut rotations = Vec::with_capacity(n);
    let mut shifts = Vec::with_capacity(n);
    let mut k = 0;
    for i in 0..n {
        while k + 1 < anchors.len() && anchors[k + 1] < i {
            k += 1;
        }
        if k + 1 == anchors.len() {
            // Only with a single anchor (n = 1).
            rotations.push(rot[k]);
            shifts.push(shift[k]);
            continue;
        }
        let (a, b) = (anchors[k], anchors[k + 1]);
        let s = (i - a) as f64 / (b - a) as f64;
        // Shortest-path slerp; antipodal quaternions are the same rotation.
        rotations.push(rot[k].try_slerp(&rot[k + 1], s, 0.0).unwrap_or(rot[k]));
        shifts.push(shift[k].lerp(&shift[k + 1], s));
    }
    (rotations, shifts)
}

/// Anchor frames of [`PoseNoise::TimeCorrelated`] for `n ≥ 1` frames: `0, M, 2M, …` and the
/// last frame `n − 1`. When the last gap would be shorter than `M / 2` frames, the last regular
/// anchor is moved to `n − 1` instead (a final segment of `M` to `1.5 M` frames), so that no
/// segment is much shorter than `M` and neighbouring frames never jump by more than
/// `2 · max / (M / 2)`.
fn anchor_frames(n: usize, anchor_every: usize) -> Vec<usize> {
    let mut anchors: Vec<usize> = (0..n).step_by(anchor_every).collect();
    match anchors.last() {
        Some(&last) if last == n - 1 => {}
        Some(&last) if anchors.len() > 1 && 2 * (n - 1 - last) < anchor_every => {
            let k = anchors.len() - 1;
            anchors[k] = n - 1;
        }
        _ => anchors.push(n - 1),
    }
    anchors
}

/// A direction uniform on the unit sphere: `z ~ U(−1, 1)`, azimuth `~ U(0, 2π)` (Archimedes).
fn uniform_direction(rng: &mut ChaCha8Rng) -> Unit<Vector3<f64>> {
    let z = 2.0 * rng.random::<f64>() - 1.0;
    let phi = std::f64::consts::TAU * rng.random::<f64>();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Unit::new_unchecked(Vector3::new(r * phi.cos(), r * phi.sin(), z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::MonocularOrbit;
    use cpose_core::geometry::{rotation_angle_between, se3_log};

    fn orbit_poses(frames: usize) -> (Vec<Isometry3<f64>>, f64) {
        let orbit = MonocularOrbit {
            frames,
            ..Default::default()
        };
        (orbit.poses(), orbit.diameter())
    }

    /// Per frame: (orientation error in degrees, centre error).
    fn errors(gt: &[Isometry3<f64>], init: &[Isometry3<f64>]) -> Vec<(f64, f64)> {
        gt.iter()
            .zip(init)
            .map(|(g, i)| {
                (
                    rotation_angle_between(&g.rotation, &i.rotation).to_degrees(),
                    (g.translation.vector - i.translation.vector).norm(),
                )
            })
            .collect()
    }

    #[test]
    fn time_correlated_attains_the_stated_maxima_and_is_continuous() {
        let (gt, diameter) = orbit_poses(100);
        let cases = [(0, 10), (1, 10), (7, 7), (3, 1)];
        for ((seed, anchor_every), model) in cases
            .into_iter()
            .flat_map(|c| [(c, AnchorDraws::Drift), (c, AnchorDraws::Independent)])
        {
            let noise = PoseNoise::TimeCorrelated {
                max_rotation_deg: 60.0,
                max_translation: 0.2,
                anchor_every,
                anchors: model,
                seed,
            };
            let init = noise.apply(&gt, diameter);
            assert_eq!(init, noise.apply(&gt, diameter), "deterministic");
            let err = errors(&gt, &init);
            let max_rot = err.iter().map(|e| e.0).fold(0.0, f64::max);
            // The maximum is attained at an anchor (convexity of the distance along a geodesic
            // of radius < π/2), and exactly.
            assert!((max_rot - 60.0).abs() < 1e-9, "{max_rot}");
            let anchors = anchor_frames(100, anchor_every);
            let argmax = (0..100).max_by(|&a, &b| err[a].0.total_cmp(&err[b].0));
            assert!(argmax.is_some_and(|i| anchors.contains(&i)));
            // Continuity: neighbouring frames' perturbations differ by at most (distance between
            // the enclosing anchors) / (segment length) ≤ 2 max / (shortest segment).
            let (rot_delta, shift) = time_correlated_perturbations(
                100,
                60f64.to_radians(),
                0.2 * diameter,
                anchor_every,
                model,
                seed,
            );
            let max_shift = shift.iter().map(|d| d.norm()).fold(0.0, f64::max);
            assert!((max_shift - 0.2 * diameter).abs() < 1e-9, "{max_shift}");
            for i in 1..100 {
                let step_rot = rotation_angle_between(&rot_delta[i - 1], &rot_delta[i]);
                let step_shift = (shift[i] - shift[i - 1]).norm();
                let m = anchors.windows(2).map(|w| w[1] - w[0]).min().unwrap_or(1) as f64;
                assert!(step_rot <= 2.0 * 60f64.to_radians() / m + 1e-12);
                assert!(step_shift <= 2.0 * 0.2 * diameter / m + 1e-12);
                // The perturbation acts in the world frame: `(R_δ, Δc) ∘ gt`; the orientation
                // error is exactly its angle.
                let want =
                    Isometry3::from_parts(Translation3::from(shift[i]), rot_delta[i]) * gt[i];
                assert!((want.translation.vector - init[i].translation.vector).norm() < 1e-12);
                assert!(rotation_angle_between(&want.rotation, &init[i].rotation) < 1e-12);
                assert!((err[i].0 - rot_delta[i].angle().to_degrees()).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn time_correlated_anchors_include_the_last_frame_and_interpolate() {
        // 26 frames, anchors 0, 10, 20, 25: frame 22 is 40 % of the way from 20 to 25.
        assert_eq!(anchor_frames(26, 10), [0, 10, 20, 25]);
        let (rot, shift) = time_correlated_perturbations(26, 1.0, 2.0, 10, AnchorDraws::Drift, 5);
        let between = rot[20].slerp(&rot[25], 0.4);
        assert!(rotation_angle_between(&between, &rot[22]) < 1e-12);
        assert!((shift[22] - (0.6 * shift[20] + 0.4 * shift[25])).norm() < 1e-12);
        assert!((shift[13] - (0.7 * shift[10] + 0.3 * shift[20])).norm() < 1e-12);
        // 25 frames: the last gap (4 < 10 / 2) is merged into the previous segment.
        assert_eq!(anchor_frames(25, 10), [0, 10, 24]);
        assert_eq!(
            anchor_frames(100, 10),
            [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 99]
        );
        assert_eq!(anchor_frames(100, 7)[13..], [91, 99]); // not 98, 99
        assert_eq!(anchor_frames(5, 10), [0, 4]);
        assert_eq!(anchor_frames(2, 1), [0, 1]);
        assert_eq!(anchor_frames(1, 3), [0]);
        // One frame: the single independent anchor carries both maxima; a drift starts exact.
        let one = |model| time_correlated_perturbations(1, 1.0, 2.0, 10, model, 5);
        let (rot, shift) = one(AnchorDraws::Independent);
        assert!((rot[0].angle() - 1.0).abs() < 1e-12 && (shift[0].norm() - 2.0).abs() < 1e-12);
        let (rot, shift) = one(AnchorDraws::Drift);
        assert!(rot[0].angle() == 0.0 && shift[0] == Vector3::zeros());
        let none = time_correlated_perturbations(0, 1.0, 2.0, 10, AnchorDraws::Drift, 5);
        assert!(none.0.is_empty());
    }

    #[test]
    fn drift_starts_exact_and_grows_while_independent_anchors_jump() {
        // Averaged over seeds: a drift's error grows with time, and its neighbouring anchors
        // are closer to each other than independent ones of the same maximum.
        let (mut early, mut late) = (0.0, 0.0);
        let mut anchor_step = [0.0; 2];
        for seed in 0..20 {
            for (m, model) in [AnchorDraws::Drift, AnchorDraws::Independent]
                .into_iter()
                .enumerate()
            {
                let (rot, shift) = time_correlated_perturbations(100, 1.0, 1.0, 10, model, seed);
                let anchors = anchor_frames(100, 10);
                anchor_step[m] += anchors
                    .windows(2)
                    .map(|w| rotation_angle_between(&rot[w[0]], &rot[w[1]]))
                    .sum::<f64>();
                if model == AnchorDraws::Drift {
                    assert!(rot[0].angle() == 0.0 && shift[0] == Vector3::zeros());
                    early += rot[..33].iter().map(|r| r.angle()).sum::<f64>();
                    late += rot[67..].iter().map(|r| r.angle()).sum::<f64>();
                }
            }
        }
        assert!(late > 2.0 * early, "early {early}, late {late}");
        assert!(
            anchor_step[0] < 0.6 * anchor_step[1],
            "drift {}, independent {}",
            anchor_step[0],
            anchor_step[1]
        );
    }

    #[test]
    fn iid_matches_barf_statistics_and_order() {
        let (gt, diameter) = orbit_poses(100);
        let gt: Vec<_> = gt.iter().cycle().take(1000).copied().collect();
        let sigma = 0.15;
        let init = PoseNoise::Iid { sigma, seed: 11 }.apply(&gt, diameter);
        // Recover ξ from cam_from_world_init = cam_from_world_gt · Exp(ξ):
        // Exp(ξ) = world_from_camera_gt · world_from_camera_init⁻¹.
        let xis: Vec<Vector6<f64>> = gt
            .iter()
            .zip(&init)
            .map(|(g, i)| se3_log(&(g * i.inverse())))
            .collect();
        for k in 0..6 {
            let mean = xis.iter().map(|x| x[k]).sum::<f64>() / 1000.0;
            let std = (xis.iter().map(|x| (x[k] - mean).powi(2)).sum::<f64>() / 1000.0).sqrt();
            assert!(
                mean.abs() < 4.0 * sigma / 1000f64.sqrt(),
                "k {k}: mean {mean}"
            );
            assert!((std / sigma - 1.0).abs() < 0.1, "k {k}: std {std}");
        }
        // The same draw, rebuilt: first frame equals Exp(ξ₀)⁻¹ · gt₀.
        let rebuilt = se3_exp(&xis[0]).inverse() * gt[0];
        assert!((rebuilt.to_homogeneous() - init[0].to_homogeneous()).norm() < 1e-12);
        assert_ne!(
            init,
            PoseNoise::Iid { sigma, seed: 12 }.apply(&gt, diameter)
        );
    }

    #[test]
    fn identity_and_none() {
        let (gt, diameter) = orbit_poses(5);
        assert_eq!(
            PoseNoise::Identity {}.apply(&gt, diameter),
            vec![Isometry3::identity(); 5]
        );
        assert_eq!(PoseNoise::None {}.apply(&gt, diameter), gt);
    }

    #[test]
    fn toml_spellings_defaults_and_validation() {
        let parse = |s: &str| toml::from_str::<PoseNoise>(s);
        assert_eq!(
            parse("kind = \"time_correlated\"\nseed = 3").unwrap(),
            PoseNoise::TimeCorrelated {
                max_rotation_deg: 60.0,
                max_translation: 0.2,
                anchor_every: 10,
                anchors: AnchorDraws::Drift,
                seed: 3
            }
        );
        assert_eq!(
            parse("kind = \"iid\"").unwrap(),
            PoseNoise::Iid {
                sigma: 0.15,
                seed: 0
            }
        );
        assert_eq!(
            parse("kind = \"identity\"").unwrap(),
            PoseNoise::Identity {}
        );
        assert_eq!(parse("kind = \"none\"").unwrap(), PoseNoise::None {});
        assert!(parse("kind = \"Iid\"").is_err());
        assert!(parse("kind = \"identity\"\nseed = 3").is_err());
        assert!(parse("kind = \"none\"\nsigma = 0.1").is_err());
        assert!(parse("seed = 3").is_err());
        let independent = parse("kind = \"time_correlated\"\nanchors = \"independent\"").unwrap();
        assert!(matches!(
            independent,
            PoseNoise::TimeCorrelated {
                anchors: AnchorDraws::Independent,
                ..
            }
        ));
        let err = parse("kind = \"time_correlated\"\nanchors = \"walk\"").unwrap_err();
        assert!(err.to_string().contains("drift"), "{err}");
        let err = parse("kind = \"iid\"\nsigmaa = 0.1").unwrap_err();
        assert!(err.to_string().contains("sigmaa"), "{err}");
        let err = parse("kind = \"time_correlated\"\nsigma = 0.1").unwrap_err();
        assert!(err.to_string().contains("sigma"), "{err}");
        // Round trip through TOML.
        let noise = PoseNoise::default();
        let text = toml::to_string(&noise).unwrap();
        assert_eq!(parse(&text).unwrap(), noise);
        for (bad, key) in [
            (
                PoseNoise::TimeCorrelated {
                    max_rotation_deg: 200.0,
                    max_translation: 0.2,
                    anchor_every: 10,
                    anchors: AnchorDraws::Drift,
                    seed: 0,
                },
                "noise.max_rotation_deg",
            ),
            (
                PoseNoise::TimeCorrelated {
                    max_rotation_deg: 10.0,
                    max_translation: -0.2,
                    anchor_every: 10,
                    anchors: AnchorDraws::Drift,
                    seed: 0,
                },
                "noise.max_translation",
            ),
            (
                PoseNoise::TimeCorrelated {
                    max_rotation_deg: 10.0,
                    max_translation: 0.2,
                    anchor_every: 0,
                    anchors: AnchorDraws::Drift,
                    seed: 0,
                },
                "noise.anchor_every",
            ),
            (
                PoseNoise::Iid {
                    sigma: f64::NAN,
                    seed: 0,
                },
                "noise.sigma",
            ),
        ] {
            let err = bad.validate().unwrap_err();
            assert!(err.to_string().starts_with(key), "{err}");
        }
    }
}
