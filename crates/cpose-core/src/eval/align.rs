//! Trajectory alignment: Umeyama's least-squares similarity (evo) and BARF's Procrustes on
//! camera centres, with BARF's pose errors.

use nalgebra::{DMatrix, Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;

use super::EvalError;
use crate::geometry::rotation_angle_between;

/// A similarity transform `x ↦ s·R·x + t` (Sim(3); SE(3) when `scale == 1`), mapping the frame of
/// an estimate into the frame of a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    /// Rotation `R`.
    pub rotation: Rotation3<f64>,
    /// Translation `t`, in reference units.
    pub translation: Vector3<f64>,
    /// Scale `s > 0`.
    pub scale: f64,
}

impl Sim3 {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// `s·R·x + t`.
    pub fn transform_vector(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation * x) + self.translation
    }

    /// Applies the similarity to a pose `world_from_body` as evo's `PosePath3D.align` does
    /// (`scale` then `transform(se3(R, t))`): position `s·R·p + t`, orientation `R·R_p`.
    pub fn transform_pose(&self, world_from_body: &Isometry3<f64>) -> Isometry3<f64> {
        let rotation =
            UnitQuaternion::from_rotation_matrix(&self.rotation) * world_from_body.rotation;
        Isometry3::from_parts(
            Translation3::from(self.transform_vector(&world_from_body.translation.vector)),
            rotation,
        )
    }
}

/// Umeyama's least-squares similarity mapping `source` points onto `target` points, evo's
/// `geometry.umeyama_alignment(x = source, y = target, with_scale)` (Umeyama 1991, eqs. 34–43):
///
/// - `μx, μy` means; `σx² = (1/n) Σ ‖x_i − μx‖²`; `Σxy = (1/n) Σ (y_i − μy)(x_i − μx)ᵀ = U D Vᵀ`;
/// - `S = I`, except `S₃₃ = −1` when `det U · det V < 0`; `R = U S Vᵀ`;
/// - `c = tr(D S) / σx²` if `with_scale`, else 1; `t = μy − c R μx`.
///
/// Errors (never panics): different lengths, no points, or a degenerate covariance (fewer than
/// two singular values above machine epsilon, evo's rank test — e.g. all points collinear).
pub fn umeyama(
    source: &[Vector3<f64>],
    target: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Sim3, EvalError> {
    if source.len() != target.len() {
        return Err(EvalError::LengthMismatch {
            reference: target.len(),
            estimate: source.len(),
        });
    }
    let n = source.len();
    if n == 0 {
        return Err(EvalError::TooFewPoses { needed: 1, got: 0 });
    }
    let inv_n = 1.0 / n as f64;
    let mean_x = source.iter().sum::<Vector3<f64>>() * inv_n;
    let mean_y = target.iter().sum::<Vector3<f64>>() * inv_n;
    let sigma_x2 = source
        .iter()
        .map(|x| (x - mean_x).norm_squared())
        .sum::<f64>()
        * inv_n;
    let mut cov = Matrix3::zeros();
    for (x, y) in source.iter().zip(target) {
        cov += (y - mean_y) * (x - mean_x).transpose();
    }
    cov *= inv_n;
    let Svd3 { u, d, v_t } = svd3(&cov)?;
    let rank = d.iter().filter(|&&s| s > f64::EPSILON).count();
    if rank < 2 {
        return Err(EvalError::Degenerate {
            what: "Umeyama alignment: the point covariance has rank < 2 (points coincide or are collinear)",
        });
    }
    let mut s = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        s[2] = -1.0;
    }
    let r = u * Matrix3::from_diagonal(&s) * v_t;
    let c = if with_scale {
        d.component_mul(&s).sum() / sigma_x2
    } else {
        1.0
    };
    let t = mean_y - c * (r * mean_x);
    Ok(Sim3 {
        rotation: Rotation3::from_matrix_unchecked(r),
        translation: t,
        scale: c,
    })
}

/// `A = U diag(d) Vᵀ`.
struct Svd3 {
    u: Matrix3<f64>,
    d: Vector3<f64>,
    v_t: Matrix3<f64>,
}

/// SVD of a 3×3 matrix, `A = U diag(d) Vᵀ`, singular values in descending order. Runs nalgebra's
/// general Golub–Kahan SVD on a dynamic matrix (nalgebra routes a static `Matrix3` to an
/// eigen-decomposition of `AᵀA`, which squares the condition number).
fn svd3(a: &Matrix3<f64>) -> Result<Svd3, EvalError> {
    let dynamic = DMatrix::from_column_slice(3, 3, a.as_slice());
    let svd = dynamic
        .try_svd(true, true, f64::EPSILON, 10_000)
        .ok_or(EvalError::Degenerate {
            what: "SVD did not converge",
        })?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(EvalError::Degenerate {
            what: "SVD returned no singular vectors",
        });
    };
    let u = Matrix3::from_column_slice(u.as_slice());
    let v_t = Matrix3::from_column_slice(v_t.as_slice());
    let d = Vector3::from_column_slice(svd.singular_values.as_slice());
    Ok(Svd3 { u, d, v_t })
}

/// BARF's Procrustes similarity between camera centres (`camera.procrustes_analysis(X0 = GT,
/// X1 = predicted)`): centres `t0`, `t1` (means), spreads `s0`, `s1` (root-mean-square distance to
/// the mean), and a rotation `R`. A predicted centre maps to the GT frame as
/// `c ↦ s0·R·(c − t1)/s1 + t0`; the scale is the ratio of spreads `s0/s1`, not Umeyama's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarfSim3 {
    /// Mean of the GT centres.
    pub t0: Vector3<f64>,
    /// Mean of the predicted centres.
    pub t1: Vector3<f64>,
    /// RMS spread of the GT centres.
    pub s0: f64,
    /// RMS spread of the predicted centres.
    pub s1: f64,
    /// Rotation from the predicted frame to the GT frame (orthonormal with determinant +1 after
    /// the reflection fix).
    pub rotation: Matrix3<f64>,
    /// Whether the best orthogonal map was a reflection, so that the [`ReflectionFix`] acted.
    pub reflected: bool,
}

/// What Procrustes does when the orthogonal map that best aligns the centres is a reflection
/// (`det(U Vᵀ) < 0`). That happens with near-planar centres — a forward-facing capture such as
/// LLFF's — whenever the estimate is mirrored in the thin direction, however slightly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReflectionFix {
    /// Kabsch's: flip the singular direction of the smallest singular value, `R = U S Vᵀ` with
    /// `S = diag(1, 1, −1)` in that slot — the best proper rotation.
    Kabsch,
    /// BARF's code: negate the third row of `U Vᵀ`, a mirror in the world's z axis. It is not the
    /// best rotation, and can be far from it: on LLFF fern one estimate read 18.9° with it and
    /// 6.5° with [`ReflectionFix::Kabsch`]. Use it only to reproduce BARF's numbers.
    BarfThirdRow,
}

impl BarfSim3 {
    /// A predicted pose `world_from_cam` mapped into the GT frame (BARF `prealign_cameras`):
    /// centre `c_al = s0·R·(c − t1)/s1 + t0`, rotation `R·R_pred` (BARF writes the world-to-camera
    /// rotation `R_pred_w2c·Rᵀ`, the transpose of ours).
    pub fn align_pose(&self, world_from_cam: &Isometry3<f64>) -> Isometry3<f64> {
        let c = world_from_cam.translation.vector;
        let centre = self.s0 * (self.rotation * ((c - self.t1) / self.s1)) + self.t0;
        let rotation = self.rotation * world_from_cam.rotation.to_rotation_matrix().into_inner();
        Isometry3::from_parts(
            Translation3::from(centre),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation)),
        )
    }

    /// The same map as a [`Sim3`]: `Sim3::transform_pose` equals [`BarfSim3::align_pose`]
    /// (scale `s0/s1`, rotation `R`, translation `t0 − (s0/s1)·R·t1`).
    pub fn to_sim3(&self) -> Sim3 {
        let rotation = Rotation3::from_matrix_unchecked(self.rotation);
        let scale = self.s0 / self.s1;
        Sim3 {
            rotation,
            translation: self.t0 - scale * (rotation * self.t1),
            scale,
        }
    }

    /// A GT pose `world_from_cam` mapped into the learned (predicted) frame, the inverse of
    /// [`BarfSim3::align_pose`] (BARF `evaluate_full` for test poses, docs/methods.md §2.3):
    /// `c' = s1·Rᵀ·(c_gt − t0)/s0 + t1`, rotation `Rᵀ·R_gt` (w2c: `R_gt_w2c·R`).
    pub fn gt_to_learned(&self, world_from_cam_gt: &Isometry3<f64>) -> Isometry3<f64> {
        let c = world_from_cam_gt.translation.vector;
        let rt = self.rotation.transpose();
        let centre = self.s1 * (rt * ((c - self.t0) / self.s0)) + self.t1;
        let rotation = rt * world_from_cam_gt.rotation.to_rotation_matrix().into_inner();
        Isometry3::from_parts(
            Translation3::from(centre),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation)),
        )
    }
}

/// BARF's `camera.procrustes_analysis(X0 = gt_centres, X1 = pred_centres)`:
///
/// - `t0, t1` means; `s0 = sqrt(mean ‖X0_i − t0‖²)`, `s1` likewise;
/// - `U S Vᵀ = svd(Σ_i ((X0_i − t0)/s0)((X1_i − t1)/s1)ᵀ)`, `R = U Vᵀ`;
/// - if `det R < 0`, BARF negates the **third row** of `R` (`R[2] *= −1`); `fix` chooses
///   between that and Kabsch's fix.
///
/// Errors when lengths differ, there are fewer than 2 centres, or a set of centres has zero spread.
pub fn procrustes_barf(
    gt_centres: &[Vector3<f64>],
    pred_centres: &[Vector3<f64>],
    fix: ReflectionFix,
) -> Result<BarfSim3, EvalError> {
    if gt_centres.len() != pred_centres.len() {
        return Err(EvalError::LengthMismatch {
            reference: gt_centres.len(),
            estimate: pred_centres.len(),
        });
    }
    let n = gt_centres.len();
    if n < 2 {
        return Err(EvalError::TooFewPoses { needed: 2, got: n });
    }
    let inv_n = 1.0 / n as f64;
    let t0 = gt_centres.iter().sum::<Vector3<f64>>() * inv_n;
    let t1 = pred_centres.iter().sum::<Vector3<f64>>() * inv_n;
    let s0 = (gt_centres
        .iter()
        .map(|x| (x - t0).norm_squared())
        .sum::<f64>()
        * inv_n)
        .sqrt();
    let s1 = (pred_centres
        .iter()
        .map(|x| (x - t1).norm_squared())
        .sum::<f64>()
        * inv_n)
        .sqrt();
    if !(s0 > 0.0 && s1 > 0.0) {
        return Err(EvalError::Degenerate {
            what: "BARF Procrustes: all camera centres coincide (zero spread)",
        });
    }
    let mut m = Matrix3::zeros();
    for (x0, x1) in gt_centres.iter().zip(pred_centres) {
        m += ((x0 - t0) / s0) * ((x1 - t1) / s1).transpose();
    }
    let Svd3 { mut u, d, v_t } = svd3(&m)?;
    let mut rotation = u * v_t;
    let reflected = rotation.determinant() < 0.0;
    if reflected {
        match fix {
            ReflectionFix::Kabsch => {
                u.column_mut(d.imin()).neg_mut();
                rotation = u * v_t;
            }
            ReflectionFix::BarfThirdRow => rotation.row_mut(2).neg_mut(),
        }
    }
    Ok(BarfSim3 {
        t0,
        t1,
        s0,
        s1,
        rotation,
        reflected,
    })
}

/// BARF's pose errors after Procrustes alignment (`evaluate_camera_alignment`), means over frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BarfPoseErrors {
    /// Mean rotation error, degrees.
    pub rot_err_deg: f64,
    /// Mean distance between world-to-camera translation vectors, scene units.
    pub trans_err: f64,
    /// Mean rotation error after also removing the best common rotation of the aligned
    /// orientations, degrees: what the cameras get wrong relative to each other. Procrustes on
    /// the centres fixes the frame's rotation only as well as the centres constrain it; for a
    /// small or near-planar spread of centres (LLFF) a turn of the whole rig with the scene
    /// stays in `rot_err_deg`. Not BARF's; beside it.
    pub rot_err_relative_deg: f64,
    /// Per-frame rotation errors, degrees.
    pub rot_err_deg_per_frame: Vec<f64>,
    /// Per-frame translation errors, scene units.
    pub trans_err_per_frame: Vec<f64>,
    /// The alignment used (not serialised).
    #[serde(skip)]
    pub alignment: BarfSim3,
}

/// BARF's evaluation of predicted camera poses against GT (`prealign_cameras` then
/// `evaluate_camera_alignment`): Procrustes on the camera centres (translations of
/// `world_from_cam`, reflections fixed by `fix`), the predicted poses mapped into the GT frame,
/// then per frame
/// `e_R = |Log(R_gtᵀ R_al)|` in degrees and `e_t = ‖t_al − t_gt‖` between the
/// **world-to-camera** translations `t = −R_w2c·c`; both averaged over frames.
pub fn barf_pose_errors(
    gt_world_from_cam: &[Isometry3<f64>],
    pred_world_from_cam: &[Isometry3<f64>],
    fix: ReflectionFix,
) -> Result<BarfPoseErrors, EvalError> {
    let gt_centres: Vec<_> = gt_world_from_cam
        .iter()
        .map(|p| p.translation.vector)
        .collect();
    let pred_centres: Vec<_> = pred_world_from_cam
        .iter()
        .map(|p| p.translation.vector)
        .collect();
    let alignment = procrustes_barf(&gt_centres, &pred_centres, fix)?;
    let mut rot = Vec::with_capacity(gt_centres.len());
    let mut trans = Vec::with_capacity(gt_centres.len());
    // (true, aligned) rotations, for the relative error.
    let mut pairs = Vec::with_capacity(gt_centres.len());
    for (gt, pred) in gt_world_from_cam.iter().zip(pred_world_from_cam) {
        let aligned = alignment.align_pose(pred);
        // The angle of R_gtᵀ R_al, the same for world-to-camera and camera-to-world rotations.
        // BARF computes it as arccos((tr − 1)/2) clamped at 1 − 1e-7, which reads 0.026° for
        // identical rotations; the quaternion's atan2 form is exact down to zero.
        rot.push(rotation_angle_between(&gt.rotation, &aligned.rotation).to_degrees());
        pairs.push((gt.rotation, aligned.rotation));
        let t_al = aligned.inverse().translation.vector;
        let t_gt = gt.inverse().translation.vector;
        trans.push((t_al - t_gt).norm());
    }
    let n = rot.len() as f64;
    let common = common_rotation(&pairs)?;
    let relative = pairs
        .iter()
        .map(|(r_gt, r_al)| rotation_angle_between(r_gt, &(common * r_al)).to_degrees())
        .sum::<f64>()
        / n;
    Ok(BarfPoseErrors {
        rot_err_deg: rot.iter().sum::<f64>() / n,
        rot_err_relative_deg: relative,
        trans_err: trans.iter().sum::<f64>() / n,
        rot_err_deg_per_frame: rot,
        trans_err_per_frame: trans,
        alignment,
    })
}

/// The rotation `C` that best turns the aligned orientations onto the true ones,
/// `argmax_C Σ_i tr(C R_al,i R_gt,iᵀ)` over the pairs `(R_gt,i, R_al,i)`: the projection of
/// `Σ_i R_gt,i R_al,iᵀ` onto SO(3) (its polar factor, `U diag(1, 1, det(U Vᵀ)) Vᵀ`).
fn common_rotation(
    pairs: &[(UnitQuaternion<f64>, UnitQuaternion<f64>)],
) -> Result<UnitQuaternion<f64>, EvalError> {
    let m: Matrix3<f64> = pairs
        .iter()
        .map(|(r_gt, r_al)| (r_gt * r_al.inverse()).to_rotation_matrix().into_inner())
        .sum();
    let Svd3 { u, v_t, .. } = svd3(&m)?;
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (u * v_t).determinant().signum()));
    Ok(UnitQuaternion::from_matrix(&(u * flip * v_t)))
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    fn random_points(rng: &mut ChaCha8Rng, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|_| {
                Vector3::new(rng.random(), rng.random(), rng.random()) * 4.0 - Vector3::repeat(2.0)
            })
            .collect()
    }

    fn random_poses(rng: &mut ChaCha8Rng, n: usize) -> Vec<Isometry3<f64>> {
        random_points(rng, n)
            .into_iter()
            .map(|p| {
                let axis =
                    Vector3::new(rng.random(), rng.random(), rng.random()) - Vector3::repeat(0.5);
                Isometry3::new(p, axis * 3.0)
            })
            .collect()
    }

    fn known_sim3(scale: f64) -> Sim3 {
        Sim3 {
            rotation: Rotation3::from_scaled_axis(Vector3::new(0.3, -1.2, 2.0)),
            translation: Vector3::new(1.5, -0.25, 3.0),
            scale,
        }
    }

    #[test]
    fn svd3_reconstructs_and_sorts() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..50 {
            let a = Matrix3::from_fn(|_, _| rng.random::<f64>() - 0.5);
            let Svd3 { u, d, v_t } = svd3(&a).unwrap();
            assert!((u * Matrix3::from_diagonal(&d) * v_t - a).norm() < 1e-13);
            assert!(d[0] >= d[1] && d[1] >= d[2] && d[2] >= 0.0);
        }
    }

    #[test]
    fn umeyama_recovers_rigid_and_similarity_transforms() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let x = random_points(&mut rng, 20);
        for (scale, with_scale) in [(1.0, false), (2.5, true), (0.1, true)] {
            let truth = known_sim3(scale);
            let y: Vec<_> = x.iter().map(|p| truth.transform_vector(p)).collect();
            let est = umeyama(&x, &y, with_scale).unwrap();
            assert!((est.rotation.matrix() - truth.rotation.matrix()).norm() < 1e-12);
            assert!((est.translation - truth.translation).norm() < 1e-12);
            assert!((est.scale - scale).abs() < 1e-12);
        }
    }

    #[test]
    fn umeyama_handles_reflection_and_rejects_degenerate_input() {
        // A mirrored point set: the best rotation still has det +1.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x = random_points(&mut rng, 10);
        let y: Vec<_> = x.iter().map(|p| Vector3::new(p.x, p.y, -p.z)).collect();
        let est = umeyama(&x, &y, false).unwrap();
        assert!((est.rotation.matrix().determinant() - 1.0).abs() < 1e-12);
        // Collinear points, a single point, no points, mismatched lengths: errors, not panics.
        let line: Vec<_> = (0..5)
            .map(|i| Vector3::new(i as f64, 2.0 * i as f64, 0.0))
            .collect();
        assert!(matches!(
            umeyama(&line, &line, true),
            Err(EvalError::Degenerate { .. })
        ));
        assert!(matches!(
            umeyama(&x[..1], &y[..1], false),
            Err(EvalError::Degenerate { .. })
        ));
        assert!(matches!(
            umeyama(&[], &[], false),
            Err(EvalError::TooFewPoses { .. })
        ));
        assert!(matches!(
            umeyama(&x, &y[..3], false),
            Err(EvalError::LengthMismatch { .. })
        ));
        // Planar (rank 2) input is fine, as in evo.
        let plane: Vec<_> = x.iter().map(|p| Vector3::new(p.x, p.y, 0.0)).collect();
        let truth = known_sim3(1.0);
        let moved: Vec<_> = plane.iter().map(|p| truth.transform_vector(p)).collect();
        let est = umeyama(&plane, &moved, false).unwrap();
        assert!((est.rotation.matrix() - truth.rotation.matrix()).norm() < 1e-10);
    }

    #[test]
    fn transform_pose_moves_position_and_orientation() {
        let s = known_sim3(2.0);
        let pose = Isometry3::new(Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.5));
        let moved = s.transform_pose(&pose);
        let expected_p = s.scale * (s.rotation * pose.translation.vector) + s.translation;
        assert!((moved.translation.vector - expected_p).norm() < 1e-14);
        let expected_r = s.rotation * pose.rotation.to_rotation_matrix();
        assert!(
            (moved.rotation.to_rotation_matrix().matrix() - expected_r.matrix()).norm() < 1e-14
        );
    }

    #[test]
    fn procrustes_on_scaled_rotated_copy_gives_zero_error() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let gt = random_poses(&mut rng, 15);
        // pred = gt expressed in another frame: world_pred_from_world_gt applied, scaled by 0.3.
        let s = known_sim3(0.3);
        let pred: Vec<_> = gt.iter().map(|p| s.transform_pose(p)).collect();
        let errors = barf_pose_errors(&gt, &pred, ReflectionFix::BarfThirdRow).unwrap();
        // No floor: BARF's clamped arccos would read 0.0256° here.
        assert!(errors.rot_err_deg < 1e-9, "{}", errors.rot_err_deg);
        assert!(errors.rot_err_relative_deg < 1e-9);
        assert!(errors.trans_err < 1e-12, "{}", errors.trans_err);
        assert!((errors.alignment.s0 / errors.alignment.s1 - 1.0 / 0.3).abs() < 1e-12);
        // The alignment as a similarity maps poses as it does.
        let sim3 = errors.alignment.to_sim3();
        for p in &pred {
            let (a, b) = (errors.alignment.align_pose(p), sim3.transform_pose(p));
            assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
            assert!(a.rotation.angle_to(&b.rotation) < 1e-12);
        }
        // Round trip through the learned frame (docs/methods.md §2.3).
        for (g, p) in gt.iter().zip(&pred) {
            let back = errors.alignment.gt_to_learned(g);
            assert!((back.translation.vector - p.translation.vector).norm() < 1e-12);
            assert!(back.rotation.angle_to(&p.rotation) < 1e-7);
        }
    }

    #[test]
    fn barf_errors_of_one_rotated_camera() {
        // Same centres (so the Procrustes similarity is the identity), camera 3 turned by 10°
        // about its own z axis. By hand: e_R = 10° for camera 3, 0 elsewhere;
        // e_t = ‖R_w2c,al·c − R_w2c,gt·c‖ = ‖(Rz(10°)ᵀ − I)·R_gtᵀ·c‖ = 2·sin(5°)·‖c_xy in cam‖.
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let gt = random_poses(&mut rng, 8);
        let mut pred = gt.clone();
        let turn = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 10f64.to_radians()));
        pred[3].rotation *= turn;
        let errors = barf_pose_errors(&gt, &pred, ReflectionFix::BarfThirdRow).unwrap();
        assert!((errors.alignment.rotation - Matrix3::identity()).norm() < 1e-12);
        let c_in_cam = gt[3].rotation.inverse() * gt[3].translation.vector;
        let expected_t = 2.0 * 5f64.to_radians().sin() * c_in_cam.xy().norm();
        for k in 0..8 {
            let (r, t) = (
                errors.rot_err_deg_per_frame[k],
                errors.trans_err_per_frame[k],
            );
            if k == 3 {
                assert!((r - 10.0).abs() < 1e-9, "{r}");
                assert!((t - expected_t).abs() < 1e-12, "{t} vs {expected_t}");
            } else {
                assert!(r < 1e-9 && t < 1e-12, "{k}: {r} {t}");
            }
        }
        assert!((errors.rot_err_deg - 10.0 / 8.0).abs() < 1e-9);
        assert!((errors.trans_err - expected_t / 8.0).abs() < 1e-12);
    }

    /// Cameras in pairs at one true orientation, each turned by `±θ` about an axis of its
    /// own frame, then every orientation by a common `C₀`, centres exact (so
    /// Procrustes is the identity). BARF's error sees `C₀`; the relative error removes it
    /// (the pairs' sum is symmetric, so the best common rotation is exactly `C₀ᵀ`) and reads
    /// `θ` on every frame.
    #[test]
    fn relative_rotation_error_removes_a_turn_of_the_whole_rig() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let base = random_poses(&mut rng, 5);
        let gt: Vec<_> = base.iter().flat_map(|p| [*p, *p]).collect();
        let common = UnitQuaternion::from_scaled_axis(Vector3::new(0.1, -0.25, 0.15));
        let theta = 4f64.to_radians();
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        let pred: Vec<_> = gt
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                let own = UnitQuaternion::from_scaled_axis(axis * (sign * theta));
                Isometry3::from_parts(p.translation, common * p.rotation * own)
            })
            .collect();
        let errors = barf_pose_errors(&gt, &pred, ReflectionFix::Kabsch).unwrap();
        assert!((errors.alignment.rotation - Matrix3::identity()).norm() < 1e-9);
        assert!(
            (errors.rot_err_relative_deg - 4.0).abs() < 1e-6,
            "{}",
            errors.rot_err_relative_deg
        );
        assert!(errors.rot_err_deg > 10.0, "{}", errors.rot_err_deg);
        // Without the common turn both read θ.
        let no_turn: Vec<_> = pred
            .iter()
            .map(|p| Isometry3::from_parts(p.translation, common.inverse() * p.rotation))
            .collect();
        let errors = barf_pose_errors(&gt, &no_turn, ReflectionFix::Kabsch).unwrap();
        assert!((errors.rot_err_deg - 4.0).abs() < 1e-6);
        assert!((errors.rot_err_relative_deg - 4.0).abs() < 1e-6);
    }

    #[test]
    fn procrustes_reflection_fix_negates_third_row() {
        // Mirror the predicted centres: U Vᵀ has det −1 and BARF flips row 2.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let gt = random_points(&mut rng, 12);
        let pred: Vec<_> = gt.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let sim = procrustes_barf(&gt, &pred, ReflectionFix::BarfThirdRow).unwrap();
        assert!(sim.reflected);
        assert!((sim.rotation.determinant() - 1.0).abs() < 1e-12);
        // Without the fix the rotation would be diag(−1, 1, 1); the fix makes it diag(−1, 1, −1).
        assert!(
            (sim.rotation - Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, -1.0))).norm() < 1e-9
        );
        let unmirrored = procrustes_barf(&gt, &gt, ReflectionFix::BarfThirdRow).unwrap();
        assert!(!unmirrored.reflected);
        assert!(matches!(
            procrustes_barf(&gt[..1], &pred[..1], ReflectionFix::Kabsch),
            Err(EvalError::TooFewPoses { .. })
        ));
        let same = vec![Vector3::new(1.0, 1.0, 1.0); 4];
        assert!(matches!(
            procrustes_barf(&same, &same, ReflectionFix::Kabsch),
            Err(EvalError::Degenerate { .. })
        ));
    }

    #[test]
    fn kabsch_fix_beats_barf_fix_on_near_planar_centres() {
        // Centres within ±1 cm of a tilted plane (a forward-facing capture); the estimate is
        // mirrored through that plane, turned by 20° and scaled. The best proper rotation
        // (the 20° turn, up to the 1 cm mirror) is Kabsch's; BARF's third-row negation
        // mirrors the world z axis instead, which is far from it.
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let tilt = Rotation3::from_scaled_axis(Vector3::new(0.4, -0.3, 0.2));
        let in_plane: Vec<Vector3<f64>> = (0..20)
            .map(|_| {
                let thin = 0.02 * rng.random::<f64>() - 0.01;
                Vector3::new(rng.random::<f64>() * 2.0, rng.random::<f64>(), thin)
            })
            .collect();
        let gt: Vec<_> = in_plane.iter().map(|c| tilt * c).collect();
        let turn = Rotation3::from_scaled_axis(Vector3::new(0.1, 0.3, 0.2).normalize() * 0.35);
        let pred: Vec<_> = in_plane
            .iter()
            .map(|c| 0.5 * (turn * (tilt * Vector3::new(c.x, c.y, -c.z))))
            .collect();
        let kabsch = procrustes_barf(&gt, &pred, ReflectionFix::Kabsch).unwrap();
        let barf = procrustes_barf(&gt, &pred, ReflectionFix::BarfThirdRow).unwrap();
        assert!(kabsch.reflected && barf.reflected);
        assert!((kabsch.rotation.determinant() - 1.0).abs() < 1e-12);
        let residual = |sim: &BarfSim3| {
            gt.iter()
                .zip(&pred)
                .map(|(g, p)| {
                    let mapped = sim.s0 * (sim.rotation * ((p - sim.t1) / sim.s1)) + sim.t0;
                    (mapped - g).norm()
                })
                .fold(0.0, f64::max)
        };
        assert!(residual(&kabsch) < 0.021, "{}", residual(&kabsch));
        assert!(residual(&barf) > 0.1, "{}", residual(&barf));
    }
}
