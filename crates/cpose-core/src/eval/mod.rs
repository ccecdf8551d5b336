//! Trajectory evaluation that agrees with evo: TUM I/O, association by timestamp, Umeyama
//! alignment in SE(3) and Sim(3), ATE/APE and RPE statistics, and BARF's Procrustes alignment
//! with its rotation and translation errors.
//!
//! Poses are `world_from_body` (`world_from_cam` for cameras) [`Isometry3<f64>`]; the estimate is
//! aligned onto the reference, never the reverse. Sources of each formula are named beside the
//! code: evo (`MichaelGrupp/evo`, `evo/core/{sync,geometry,metrics,trajectory}.py`) and BARF
//! (`chenhsuanlin/bundle-adjusting-NeRF`, `camera.py`, `model/barf.py`).
//!
//! ```
//! # use cpose_core::eval::{ate, Alignment, Trajectory};
//! # use nalgebra::Isometry3;
//! let ts = vec![0.0, 1.0, 2.0, 3.0];
//! let gt: Vec<_> = [(0., 0., 0.), (1., 0., 0.), (1., 1., 0.), (0., 1., 1.)]
//!     .iter()
//!     .map(|&(x, y, z)| Isometry3::translation(x, y, z))
//!     .collect();
//! let gt = Trajectory::new(ts.clone(), gt).unwrap();
//! let report = ate(&gt, &gt, Alignment::Se3, 0.01).unwrap();
//! assert!(report.rmse_m < 1e-12 && report.num_matched == 4);
//! ```

mod align;
mod associate;
mod formats;
mod metrics;
mod trajectory;
mod tum;

use std::fmt;
use std::str::FromStr;

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

pub use align::{
    BarfPoseErrors, BarfSim3, ReflectionFix, Sim3, barf_pose_errors, procrustes_barf, umeyama,
};
pub use associate::{Association, DEFAULT_MAX_DIFF_SECS, associate, associate_with_offset};
pub use formats::{
    EUROC_HEADER, TrajectoryFormat, parse_euroc, parse_kitti, parse_times, read_trajectory,
    to_euroc_string, to_kitti_string, write_trajectory,
};
pub use metrics::{
    ErrorStats, RpeDelta, RpeErrors, ape_rotation_angle, ape_translation, error_stats,
    rotation_angle, rpe, rpe_pairs, rpe_with,
};
pub use trajectory::{Duplicates, Trajectory, TrajectoryError};
pub use tum::{
    MIN_QUATERNION_NORM, TUM_COLUMNS, parse_tum, parse_tum_lines, read_tum, to_tum_string,
    write_tum,
};

/// Errors of association, alignment and metrics.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Reference and estimate have different numbers of poses.
    #[error("expected as many estimated poses as reference poses ({reference}), got {estimate}")]
    LengthMismatch {
        /// Number of reference poses.
        reference: usize,
        /// Number of estimated poses.
        estimate: usize,
    },
    /// Too few poses for the computation.
    #[error("expected at least {needed} poses, got {got}")]
    TooFewPoses {
        /// Minimum needed.
        needed: usize,
        /// Number given.
        got: usize,
    },
    /// The input makes the alignment undefined (e.g. collinear or coincident positions).
    #[error("degenerate input: {what}")]
    Degenerate {
        /// What is degenerate.
        what: &'static str,
    },
    /// Association found no timestamp pair within the tolerance.
    #[error(
        "expected matching timestamps within {max_diff_secs} s (offset {offset_second_secs} s), got none between trajectories of {first_len} and {second_len} poses"
    )]
    NoMatches {
        /// Poses in the first trajectory.
        first_len: usize,
        /// Poses in the second trajectory.
        second_len: usize,
        /// The tolerance, seconds.
        max_diff_secs: f64,
        /// The time offset of the second trajectory, seconds.
        offset_second_secs: f64,
    },
    /// A negative or non-finite association tolerance.
    #[error("expected a finite, non-negative max_diff in seconds, got {max_diff_secs}")]
    InvalidMaxDiff {
        /// The tolerance given.
        max_diff_secs: f64,
    },
    /// A non-finite time offset.
    #[error("expected a finite time offset in seconds, got {offset_second_secs}")]
    InvalidOffset {
        /// The offset given.
        offset_second_secs: f64,
    },
    /// An RPE step of zero frames, or of metres not finite and positive.
    #[error("expected an RPE delta of at least 1 frame or a positive number of metres")]
    InvalidDelta,
    /// An RPE step that leaves no pair of poses.
    #[error("RPE delta {delta} leaves no pair among {poses} poses; try a smaller delta")]
    NoPairs {
        /// The delta with its unit.
        delta: String,
        /// Number of poses.
        poses: usize,
    },
    /// An alignment name that is not `none`, `se3` or `sim3`.
    #[error("expected alignment `none`, `se3` or `sim3`, got `{got}`")]
    UnknownAlignment {
        /// The text given.
        got: String,
    },
    /// Reading or building a trajectory failed.
    #[error(transparent)]
    Trajectory(#[from] TrajectoryError),
}

/// How the estimate is aligned to the reference before computing absolute errors (evo
/// `evo_ape` flags: none, `-a`, `-as`). Parses from and serialises as `"none"`, `"se3"`, `"sim3"`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// No alignment.
    #[default]
    None,
    /// Rigid Umeyama alignment (rotation and translation), evo `-a`.
    Se3,
    /// Similarity Umeyama alignment (rotation, translation and scale), evo `-as`.
    Sim3,
}

impl Alignment {
    /// All values, in order.
    pub const ALL: [Alignment; 3] = [Alignment::None, Alignment::Se3, Alignment::Sim3];

    /// The name used in configs and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Alignment::None => "none",
            Alignment::Se3 => "se3",
            Alignment::Sim3 => "sim3",
        }
    }
}

impl fmt::Display for Alignment {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Alignment {
    type Err = EvalError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Alignment::ALL
            .into_iter()
            .find(|a| a.as_str() == s)
            .ok_or_else(|| EvalError::UnknownAlignment { got: s.to_owned() })
    }
}

/// The similarity applied to the estimate, in serialisable form.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AlignmentTransform {
    /// Rotation matrix, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation, metres (the trajectories' unit).
    pub translation_m: [f64; 3],
    /// Scale (1 unless Sim(3)).
    pub scale: f64,
}

impl From<&Sim3> for AlignmentTransform {
    fn from(s: &Sim3) -> Self {
        let m = s.rotation.matrix();
        Self {
            rotation: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
            ],
            translation_m: [s.translation.x, s.translation.y, s.translation.z],
            scale: s.scale,
        }
    }
}

/// Result of [`ate`]: statistics of the translation APE (evo `evo_ape … --pose_relation trans_part`)
/// in metres (the trajectories' unit), the number of associated poses and the alignment used.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AteReport {
    /// Root mean square error.
    pub rmse_m: f64,
    /// Mean error.
    pub mean_m: f64,
    /// Median error.
    pub median_m: f64,
    /// Population standard deviation of the errors.
    pub std_m: f64,
    /// Smallest error.
    pub min_m: f64,
    /// Largest error.
    pub max_m: f64,
    /// Sum of squared errors, m².
    pub sse_m2: f64,
    /// Number of associated pose pairs compared.
    pub num_matched: usize,
    /// The kind of alignment.
    pub alignment: Alignment,
    /// The similarity applied to the estimate (identity for [`Alignment::None`]).
    pub transform: AlignmentTransform,
}

/// Absolute trajectory error as `evo_ape tum GT EST [-a | -as] --t_max_diff max_diff_secs`:
/// association by nearest timestamp ([`associate`]`(gt, est, max_diff_secs)`), Umeyama alignment
/// of the associated estimated positions onto the GT positions ([`umeyama`]) applied to the
/// estimate, then [`error_stats`] of [`ape_translation`].
///
/// ```
/// use cpose_core::eval::{Alignment, Trajectory, ate};
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion};
///
/// let times = vec![0.0, 0.1, 0.2, 0.3];
/// let at = |x: f64, y: f64| Isometry3::from_parts(Translation3::new(x, y, 0.0), UnitQuaternion::identity());
/// let gt = Trajectory::new(times.clone(), vec![at(0.0, 0.0), at(1.0, 0.0), at(1.0, 1.0), at(2.0, 1.0)])?;
/// // The estimate is the same path, 5 m ahead and 1 cm to the side.
/// let est = Trajectory::new(times, vec![at(5.0, 0.01), at(6.0, 0.01), at(6.0, 1.01), at(7.0, 1.01)])?;
/// let raw = ate(&gt, &est, Alignment::None, 0.01)?;
/// assert!((raw.rmse_m - (25.0f64 + 1e-4).sqrt()).abs() < 1e-9);
/// // After SE(3) alignment (evo's `-a`), nothing is left.
/// let aligned = ate(&gt, &est, Alignment::Se3, 0.01)?;
/// assert!(aligned.rmse_m < 1e-9 && aligned.num_matched == 4);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn ate(
    gt: &Trajectory,
    est: &Trajectory,
    align: Alignment,
    max_diff_secs: f64,
) -> Result<AteReport, EvalError> {
    let association = associate(gt, est, max_diff_secs)?;
    let (reference, estimate) = association.poses(gt, est);
    let (sim3, aligned) = align_poses(&reference, &estimate, align)?;
    let errors = ape_translation(&reference, &aligned)?;
    let s = error_stats(&errors)?;
    Ok(AteReport {
        rmse_m: s.rmse,
        mean_m: s.mean,
        median_m: s.median,
        std_m: s.std,
        min_m: s.min,
        max_m: s.max,
        sse_m2: s.sse,
        num_matched: association.len(),
        alignment: align,
        transform: AlignmentTransform::from(&sim3),
    })
}

/// Result of [`rpe_report`]: evo's RPE statistics, translation part in metres (the
/// trajectories' unit) and rotation angle in degrees.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RpeReport {
    /// RMSE of the relative translation errors.
    pub trans_rmse_m: f64,
    /// Mean of the relative translation errors.
    pub trans_mean_m: f64,
    /// Median of the relative translation errors.
    pub trans_median_m: f64,
    /// Population standard deviation of the relative translation errors.
    pub trans_std_m: f64,
    /// Smallest relative translation error.
    pub trans_min_m: f64,
    /// Largest relative translation error.
    pub trans_max_m: f64,
    /// RMSE of the relative rotation angles.
    pub rot_rmse_deg: f64,
    /// Mean of the relative rotation angles.
    pub rot_mean_deg: f64,
    /// Median of the relative rotation angles.
    pub rot_median_deg: f64,
    /// Population standard deviation of the relative rotation angles.
    pub rot_std_deg: f64,
    /// Smallest relative rotation angle.
    pub rot_min_deg: f64,
    /// Largest relative rotation angle.
    pub rot_max_deg: f64,
    /// Number of pose pairs compared.
    pub num_pairs: usize,
    /// Number of associated poses the pairs were chosen from.
    pub num_matched: usize,
    /// The alignment applied to the estimate first.
    pub alignment: Alignment,
}

/// Relative pose error as `evo_rpe tum GT EST --delta D --delta_unit f|m [-a|-as] --t_max_diff
/// max_diff_secs` (`-r trans_part` and `-r angle_deg`): association ([`associate`]), the
/// alignment (RPE is invariant to a rigid change of frame, not to Sim(3)'s scale), then
/// [`rpe_with`].
///
/// ```
/// use cpose_core::eval::{Alignment, RpeDelta, Trajectory, rpe_report};
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion};
///
/// let times: Vec<f64> = (0..5).map(|i| 0.1 * i as f64).collect();
/// let step = |i: usize, len: f64| {
///     Isometry3::from_parts(Translation3::new(len * i as f64, 0.0, 0.0), UnitQuaternion::identity())
/// };
/// let gt = Trajectory::new(times.clone(), (0..5).map(|i| step(i, 1.0)).collect())?;
/// // Every step of the estimate is 2 cm too long.
/// let est = Trajectory::new(times, (0..5).map(|i| step(i, 1.02)).collect())?;
/// let report = rpe_report(&gt, &est, 0.01, RpeDelta::Frames(1), Alignment::None)?;
/// assert_eq!(report.num_pairs, 4);
/// assert!((report.trans_rmse_m - 0.02).abs() < 1e-12 && report.rot_max_deg < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn rpe_report(
    gt: &Trajectory,
    est: &Trajectory,
    max_diff_secs: f64,
    delta: RpeDelta,
    align: Alignment,
) -> Result<RpeReport, EvalError> {
    let association = associate(gt, est, max_diff_secs)?;
    let (reference, estimate) = association.poses(gt, est);
    let (_, aligned) = align_poses(&reference, &estimate, align)?;
    let errors = rpe_with(&reference, &aligned, delta)?;
    let trans = error_stats(&errors.translation)?;
    let deg: Vec<f64> = errors
        .rotation_angle_rad
        .iter()
        .map(|a| a.to_degrees())
        .collect();
    let rot = error_stats(&deg)?;
    Ok(RpeReport {
        trans_rmse_m: trans.rmse,
        trans_mean_m: trans.mean,
        trans_median_m: trans.median,
        trans_std_m: trans.std,
        trans_min_m: trans.min,
        trans_max_m: trans.max,
        rot_rmse_deg: rot.rmse,
        rot_mean_deg: rot.mean,
        rot_median_deg: rot.median,
        rot_std_deg: rot.std,
        rot_min_deg: rot.min,
        rot_max_deg: rot.max,
        num_pairs: errors.pairs.len(),
        num_matched: association.len(),
        alignment: align,
    })
}

/// Aligns associated `estimate` poses onto `reference` poses (evo `PosePath3D.align`): the
/// Umeyama similarity of the positions ([`Alignment::None`]: the identity), and the estimate with
/// it applied to every pose (positions and orientations, scale on positions).
pub fn align_poses(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
    align: Alignment,
) -> Result<(Sim3, Vec<Isometry3<f64>>), EvalError> {
    let sim3 = match align {
        Alignment::None => Sim3::identity(),
        Alignment::Se3 | Alignment::Sim3 => {
            let source: Vec<_> = estimate.iter().map(|p| p.translation.vector).collect();
            let target: Vec<_> = reference.iter().map(|p| p.translation.vector).collect();
            umeyama(&source, &target, align == Alignment::Sim3)?
        }
    };
    let aligned = estimate.iter().map(|p| sim3.transform_pose(p)).collect();
    Ok((sim3, aligned))
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    #[test]
    fn alignment_names_round_trip() {
        for a in Alignment::ALL {
            assert_eq!(a.as_str().parse::<Alignment>().unwrap(), a);
            let json = serde_json::to_string(&a).unwrap();
            assert_eq!(json, format!("\"{a}\""));
            assert_eq!(serde_json::from_str::<Alignment>(&json).unwrap(), a);
        }
        let err = "SE3".parse::<Alignment>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "expected alignment `none`, `se3` or `sim3`, got `SE3`"
        );
    }

    #[test]
    fn ate_recovers_known_similarity_and_reports_it() {
        let n = 40;
        let ts: Vec<f64> = (0..n).map(|i| 100.0 + 0.05 * i as f64).collect();
        let gt: Vec<_> = (0..n)
            .map(|i| {
                let t = i as f64 * 0.2;
                Isometry3::new(
                    Vector3::new(t.cos(), t.sin(), 0.1 * t),
                    Vector3::new(0.0, 0.1 * t, 0.2),
                )
            })
            .collect();
        let truth = Sim3 {
            rotation: nalgebra::Rotation3::from_scaled_axis(Vector3::new(0.5, 0.1, -0.7)),
            translation: Vector3::new(-3.0, 2.0, 1.0),
            scale: 0.4,
        };
        // est = truth⁻¹ applied to gt, timestamps shifted by 3 ms (within tolerance).
        let inv = Sim3 {
            rotation: truth.rotation.inverse(),
            translation: -(truth.rotation.inverse() * truth.translation) / truth.scale,
            scale: 1.0 / truth.scale,
        };
        let est: Vec<_> = gt.iter().map(|p| inv.transform_pose(p)).collect();
        let gt_t = Trajectory::new(ts.clone(), gt).unwrap();
        let est_t = Trajectory::new(ts.iter().map(|t| t + 0.003).collect(), est).unwrap();
        let sim = ate(&gt_t, &est_t, Alignment::Sim3, 0.01).unwrap();
        assert_eq!(sim.num_matched, n);
        assert!(sim.rmse_m < 1e-12, "{}", sim.rmse_m);
        assert!((sim.transform.scale - 0.4).abs() < 1e-12);
        assert!((sim.transform.translation_m[0] + 3.0).abs() < 1e-12);
        let se3 = ate(&gt_t, &est_t, Alignment::Se3, 0.01).unwrap();
        let none = ate(&gt_t, &est_t, Alignment::None, 0.01).unwrap();
        assert!(se3.rmse_m > 0.1 && none.rmse_m >= se3.rmse_m);
        assert_eq!(none.transform.scale, 1.0);
        let json = serde_json::to_value(&sim).unwrap();
        assert_eq!(json["alignment"], "sim3");
        assert!(json["rmse_m"].is_number() && json["transform"]["rotation"][2][2].is_number());
        // Rotations are aligned too: after Sim(3) the orientations agree with GT.
        let (ref_poses, est_poses) = associate(&gt_t, &est_t, 0.01).unwrap().poses(&gt_t, &est_t);
        let (_, aligned) = align_poses(&ref_poses, &est_poses, Alignment::Sim3).unwrap();
        let rot = error_stats(&ape_rotation_angle(&ref_poses, &aligned).unwrap()).unwrap();
        assert!(rot.max < 1e-7);
        // Tolerance too tight: an error naming the tolerance, not a panic.
        let err = ate(&gt_t, &est_t, Alignment::Se3, 0.001).unwrap_err();
        assert!(err.to_string().contains("within 0.001 s"), "{err}");
    }
}
