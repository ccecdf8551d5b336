//! Ground-truth patch motions of the planar study.
//!
//! **Rigid (the paper, §4.1.1).** Draw `control_points` random SE(2) poses
//! `(θ_k, t_k) ~ (N(0, σ_θ²), N(0, σ_t² I))` at times `k = 0, 1, …`, fit a cubic B-spline through
//! them per dimension (as many control points as samples: an interpolating spline), and evaluate
//! it at `patches` uniformly spaced times over the same span. Patch `i` then sees the image
//! through `W_i = G_0⁻¹ ∘ G_i`, so the first patch is the centre crop (identity) and fixes the
//! gauge of the learned image.
//!
//! **Homography (BARF's own protocol, docs/methods.md §2.1).** Patch `i ≥ 1` gets 8 sl(3)
//! parameters `N(0, σ_h²)` plus a translation offset `(±δ, ±δ)` cycling through the four
//! diagonals; patch 0 is the identity. There is no time correlation.
//!
//! Both resample until every warped crop corner lies inside the image.

use cpose_core::random::standard_normal;
use cpose_core::{PerDimSplinePoses, PoseField, TimeRange};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::warp2d::{Warp, WarpKind};

/// How ground-truth motions are drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionSpec {
    /// Rigid (se2) or BARF's homography.
    pub warp: WarpKind,
    /// Number of patches (≥ 2).
    pub patches: usize,
    /// Rigid: random poses the spline passes through (≥ 4).
    pub control_points: usize,
    /// Rigid: σ of the rotation, radians.
    pub rotation_std_rad: f64,
    /// Rigid: σ of each translation component; homography: the diagonal offset δ. Normalised
    /// image units (the long side spans 2).
    pub translation_std: f64,
    /// Homography: σ of every sl(3) parameter.
    pub homography_std: f64,
}

/// One ground-truth motion: patch times and the warp parameters of every patch.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    /// Patch times (the control points' time unit: 0 … control_points − 1).
    pub times: Vec<f64>,
    /// Warp parameters per patch (`warp.dim()` each); patch 0 is the identity.
    pub params: Vec<Vec<f64>>,
}

/// At most this many draws per motion before giving up.
const MAX_DRAWS: usize = 10_000;

impl MotionSpec {
    /// Time span of the patches: `[0, control_points − 1]` (rigid) or `[0, patches − 1]`.
    pub fn time_range(&self) -> TimeRange {
        let end = match self.warp {
            WarpKind::Se2 => self.control_points - 1,
            WarpKind::Homography => self.patches - 1,
        };
        TimeRange {
            start_secs: 0.0,
            end_secs: end as f64,
        }
    }

    /// Patch times: uniformly spaced over [`MotionSpec::time_range`].
    pub fn patch_times(&self) -> Vec<f64> {
        let end = self.time_range().end_secs;
        let n = self.patches;
        (0..n).map(|i| end * i as f64 / (n - 1) as f64).collect()
    }

    /// Draws a motion from `seed` whose warped `corners` (normalised) all fall inside
    /// `bounds = [x_max, y_max]` (the image is `[−x_max, x_max] × [−y_max, y_max]`).
    pub fn sample(
        &self,
        seed: u64,
        corners: &[[f64; 2]],
        bounds: [f64; 2],
    ) -> Result<Motion, String> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let times = self.patch_times();
        for _ in 0..MAX_DRAWS {
            let params = match self.warp {
                WarpKind::Se2 => self.draw_rigid(&mut rng, &times)?,
                WarpKind::Homography => self.draw_homography(&mut rng),
            };
            let inside = params.iter().all(|p| {
                let w = Warp::new(self.warp, p);
                corners.iter().all(|&c| {
                    let [x, y] = w.apply(c);
                    x.abs() < bounds[0] && y.abs() < bounds[1]
                })
            });
            if inside {
                return Ok(Motion { times, params });
            }
        }
        Err(format!(
            "no motion in {MAX_DRAWS} draws keeps every patch inside the image; \
             lower [motion] rotation_deg / translation or the crop size"
        ))
    }

    fn draw_rigid(&self, rng: &mut ChaCha8Rng, times: &[f64]) -> Result<Vec<Vec<f64>>, String> {
        let k = self.control_points;
        let knot_times: Vec<f64> = (0..k).map(|i| i as f64).collect();
        let poses: Vec<Isometry3<f64>> = (0..k)
            .map(|_| {
                let theta = self.rotation_std_rad * standard_normal(rng);
                let t = self.translation_std
                    * Vector3::new(standard_normal(rng), standard_normal(rng), 0.0);
                Isometry3::from_parts(
                    Translation3::from(t),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta),
                )
            })
            .collect();
        let spline =
            PerDimSplinePoses::<f64>::from_samples(self.time_range(), k, &knot_times, &poses)
                .map_err(|e| e.to_string())?;
        let mut out = cpose_core::PoseBatch::default();
        spline
            .evaluate(times, cpose_core::Order::Pose, &mut out)
            .map_err(|e| e.to_string())?;
        let se2: Vec<[f64; 3]> = (0..times.len())
            .map(|i| {
                let pose = out.world_from_body(i);
                let theta = pose.rotation.scaled_axis().z;
                [theta, pose.translation.x, pose.translation.y]
            })
            .collect();
        Ok(se2
            .iter()
            .map(|g| relative_se2(&se2[0], g).to_vec())
            .collect())
    }

    fn draw_homography(&self, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        let d = self.translation_std;
        let offsets = [[-d, -d], [-d, d], [d, -d], [d, d]];
        (0..self.patches)
            .map(|i| {
                if i == 0 {
                    return vec![0.0; 8];
                }
                let mut p: Vec<f64> = (0..8)
                    .map(|_| self.homography_std * standard_normal(rng))
                    .collect();
                p[0] += offsets[(i - 1) % 4][0];
                p[1] += offsets[(i - 1) % 4][1];
                p
            })
            .collect()
    }
}

/// `a⁻¹ ∘ b` for SE(2) parameters `[θ, tx, ty]` (`x ↦ R(θ) x + t`).
pub fn relative_se2(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    let (s, c) = a[0].sin_cos();
    let (dx, dy) = (b[1] - a[1], b[2] - a[2]);
    [b[0] - a[0], c * dx + s * dy, -s * dx + c * dy]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(warp: WarpKind) -> MotionSpec {
        MotionSpec {
            warp,
            patches: 7,
            control_points: 10,
            rotation_std_rad: 0.15,
            translation_std: 0.2,
            homography_std: 0.1,
        }
    }

    const CORNERS: [[f64; 2]; 4] = [
        [-0.375, -0.375],
        [0.375, -0.375],
        [0.375, 0.375],
        [-0.375, 0.375],
    ];

    #[test]
    fn rigid_motions_start_at_identity_stay_inside_and_are_smooth() {
        let s = spec(WarpKind::Se2);
        let m = s.sample(3, &CORNERS, [1.0, 0.75]).unwrap();
        assert_eq!(m.times.len(), 7);
        assert_eq!(m.times[6], 9.0);
        assert!(m.params[0].iter().all(|v| v.abs() < 1e-12));
        for p in &m.params {
            let w = Warp::new(WarpKind::Se2, p);
            for c in CORNERS {
                let [x, y] = w.apply(c);
                assert!(x.abs() < 1.0 && y.abs() < 0.75);
            }
        }
        assert_eq!(m, s.sample(3, &CORNERS, [1.0, 0.75]).unwrap(), "seeded");
        assert_ne!(m, s.sample(4, &CORNERS, [1.0, 0.75]).unwrap());
    }

    #[test]
    fn relative_se2_inverts_composition() {
        let a = [0.3, 0.1, -0.2];
        let b = [-0.2, 0.4, 0.05];
        let r = relative_se2(&a, &b);
        // a ∘ r == b
        let (s, c) = a[0].sin_cos();
        let composed = [
            a[0] + r[0],
            a[1] + c * r[1] - s * r[2],
            a[2] + s * r[1] + c * r[2],
        ];
        for k in 0..3 {
            assert!((composed[k] - b[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn homography_motions_follow_barf() {
        let mut s = spec(WarpKind::Homography);
        s.patches = 5;
        let m = s.sample(0, &CORNERS, [1.0, 0.75]).unwrap();
        assert!(m.params[0].iter().all(|&v| v == 0.0));
        assert_eq!(m.params[1].len(), 8);
        assert!(m.params[1][0] < 0.0 || m.params[1][0].abs() < 0.5);
    }

    #[test]
    fn impossible_motions_are_an_error() {
        let mut s = spec(WarpKind::Se2);
        s.translation_std = 50.0;
        assert!(s.sample(0, &CORNERS, [1.0, 0.75]).is_err());
    }
}
