//! Pose-error metrics as evo defines them (`metrics.APE`, `metrics.RPE`, `PE.get_statistic`).

use nalgebra::{Isometry3, UnitQuaternion};

use super::EvalError;

/// evo's statistics of an error array (`PE.get_all_statistics`), in the errors' unit (`sse` in
/// its square).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorStats {
    /// `sqrt(mean e_i²)`.
    pub rmse: f64,
    /// `mean e_i`.
    pub mean: f64,
    /// Median; the mean of the two middle values for an even count (`np.median`).
    pub median: f64,
    /// Population standard deviation, `sqrt(mean (e_i − mean)²)` (`np.std`, ddof = 0).
    pub std: f64,
    /// Smallest error.
    pub min: f64,
    /// Largest error.
    pub max: f64,
    /// Sum of squared errors, `Σ e_i²`.
    pub sse: f64,
}

/// Statistics of `errors` (evo `PE.get_statistic`); an error when `errors` is empty.
pub fn error_stats(errors: &[f64]) -> Result<ErrorStats, EvalError> {
    if errors.is_empty() {
        return Err(EvalError::TooFewPoses { needed: 1, got: 0 });
    }
    let n = errors.len() as f64;
    let sse: f64 = errors.iter().map(|e| e * e).sum();
    let mean = errors.iter().sum::<f64>() / n;
    let var = errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n;
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mid = sorted.len() / 2;
    let median = if sorted.len() % 2 == 1 {
        sorted[mid]
    } else {
        (sorted[mid - 1] + sorted[mid]) / 2.0
    };
    Ok(ErrorStats {
        rmse: (sse / n).sqrt(),
        mean,
        median,
        std: var.sqrt(),
        min: sorted[0],
        max: sorted[sorted.len() - 1],
        sse,
    })
}

/// The rotation angle of a unit quaternion, `|Log(q)|` in radians in `[0, π]`, computed as
/// `2·atan2(‖v‖, |w|)` (accurate near zero, where `2·acos(|w|)` is not). evo:
/// `lie.so3_log_angle`.
pub fn rotation_angle(q: &UnitQuaternion<f64>) -> f64 {
    2.0 * q.imag().norm().atan2(q.w.abs())
}

fn check_lengths(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
) -> Result<(), EvalError> {
    if reference.len() != estimate.len() {
        return Err(EvalError::LengthMismatch {
            reference: reference.len(),
            estimate: estimate.len(),
        });
    }
    if reference.is_empty() {
        return Err(EvalError::TooFewPoses { needed: 1, got: 0 });
    }
    Ok(())
}

/// APE, translation part (evo `APE(PoseRelation.translation_part)`): `e_i = ‖p_est,i − p_ref,i‖`
/// for associated (and, usually, aligned) poses.
pub fn ape_translation(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
) -> Result<Vec<f64>, EvalError> {
    check_lengths(reference, estimate)?;
    Ok(reference
        .iter()
        .zip(estimate)
        .map(|(r, e)| (e.translation.vector - r.translation.vector).norm())
        .collect())
}

/// APE, rotation angle (evo `APE(PoseRelation.rotation_angle_rad)`): with
/// `E_i = P_est,i⁻¹ · P_ref,i` (`ape_base`), `e_i = |Log(R(E_i))|` in radians.
pub fn ape_rotation_angle(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
) -> Result<Vec<f64>, EvalError> {
    check_lengths(reference, estimate)?;
    Ok(reference
        .iter()
        .zip(estimate)
        .map(|(r, e)| rotation_angle(&(e.rotation.inverse() * r.rotation)))
        .collect())
}

/// Relative pose errors, one per index pair.
#[derive(Clone, Debug, PartialEq)]
pub struct RpeErrors {
    /// The index pairs `(i, i + delta)` compared.
    pub pairs: Vec<(usize, usize)>,
    /// `‖t(E_i)‖`, in position units (evo `RPE(PoseRelation.translation_part)`).
    pub translation: Vec<f64>,
    /// `|Log(R(E_i))|`, radians (evo `RPE(PoseRelation.rotation_angle_rad)`).
    pub rotation_angle_rad: Vec<f64>,
}

/// The step between the two poses of an RPE pair (`evo_rpe --delta D --delta_unit f|m`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RpeDelta {
    /// Every this many poses.
    Frames(usize),
    /// Every this many metres travelled.
    Metres(f64),
}

/// The index pairs RPE compares among `poses`, as evo picks them without `--all_pairs`
/// (`filters.filter_pairs_by_index` and `filter_pairs_by_path`):
/// - [`RpeDelta::Frames`]`(Δ)`: `(0, Δ), (Δ, 2Δ), …`;
/// - [`RpeDelta::Metres`]`(d)`: the first pose is chosen; walking on, the path length since the
///   last chosen pose is accumulated and a pose is chosen once it reaches `d`; consecutive chosen
///   poses pair up (evo 1.38; earlier versions left the first pose out).
///
/// Errors when `Δ = 0`, `d` is not finite and positive, or no pair fits.
pub fn rpe_pairs(
    poses: &[Isometry3<f64>],
    delta: RpeDelta,
) -> Result<Vec<(usize, usize)>, EvalError> {
    let pairs: Vec<(usize, usize)> = match delta {
        RpeDelta::Frames(0) => return Err(EvalError::InvalidDelta),
        RpeDelta::Frames(step) => (0..poses.len())
            .step_by(step)
            .zip((step..poses.len()).step_by(step))
            .collect(),
        RpeDelta::Metres(d) if !(d.is_finite() && d > 0.0) => {
            return Err(EvalError::InvalidDelta);
        }
        RpeDelta::Metres(d) => {
            let mut chosen = vec![0];
            let mut path = 0.0;
            for (i, w) in poses.windows(2).enumerate() {
                path += (w[1].translation.vector - w[0].translation.vector).norm();
                if path >= d {
                    chosen.push(i + 1);
                    path = 0.0;
                }
            }
            chosen.windows(2).map(|w| (w[0], w[1])).collect()
        }
    };
    if pairs.is_empty() {
        return Err(EvalError::NoPairs {
            delta: match delta {
                RpeDelta::Frames(n) => format!("{n} frames"),
                RpeDelta::Metres(d) => format!("{d} m"),
            },
            poses: poses.len(),
        });
    }
    Ok(pairs)
}

/// RPE with a step of `delta_frames` (evo `RPE(delta, Unit.frames, all_pairs=False)`):
/// [`rpe_with`] with [`RpeDelta::Frames`].
pub fn rpe(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
    delta_frames: usize,
) -> Result<RpeErrors, EvalError> {
    rpe_with(reference, estimate, RpeDelta::Frames(delta_frames))
}

/// RPE over the pairs [`rpe_pairs`] picks on the estimate's poses (evo's default, without
/// `--pairs_from_reference`): for each pair `(i, j)`, `E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)`
/// (`RPE.rpe_base`), Q = reference, P = estimate. Errors when lengths differ or no pair fits.
pub fn rpe_with(
    reference: &[Isometry3<f64>],
    estimate: &[Isometry3<f64>],
    delta: RpeDelta,
) -> Result<RpeErrors, EvalError> {
    check_lengths(reference, estimate)?;
    let pairs = rpe_pairs(estimate, delta)?;
    let mut translation = Vec::with_capacity(pairs.len());
    let mut rotation_angle_rad = Vec::with_capacity(pairs.len());
    for &(i, j) in &pairs {
        let q_rel = reference[i].inverse() * reference[j];
        let p_rel = estimate[i].inverse() * estimate[j];
        let e = q_rel.inverse() * p_rel;
        translation.push(e.translation.vector.norm());
        rotation_angle_rad.push(rotation_angle(&e.rotation));
    }
    Ok(RpeErrors {
        pairs,
        translation,
        rotation_angle_rad,
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    #[test]
    fn stats_match_numpy_by_hand() {
        // numpy: e = [3, 1, 4, 1, 5, 9]; rmse = sqrt(133/6), mean = 23/6, median = 3.5,
        // std = sqrt(mean((e − 23/6)²)) = sqrt(133/6 − (23/6)²), sse = 133.
        let s = error_stats(&[3.0, 1.0, 4.0, 1.0, 5.0, 9.0]).unwrap();
        assert!((s.rmse - (133.0_f64 / 6.0).sqrt()).abs() < 1e-15);
        assert!((s.mean - 23.0 / 6.0).abs() < 1e-15);
        assert_eq!(s.median, 3.5);
        assert!((s.std - (133.0_f64 / 6.0 - (23.0_f64 / 6.0).powi(2)).sqrt()).abs() < 1e-14);
        assert_eq!((s.min, s.max, s.sse), (1.0, 9.0, 133.0));
        assert_eq!(error_stats(&[2.0, 7.0, 1.0]).unwrap().median, 2.0);
        assert!(error_stats(&[]).is_err());
    }

    fn wiggly(n: usize) -> Vec<Isometry3<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.1;
                Isometry3::new(
                    Vector3::new(t.sin(), t.cos(), 0.3 * t),
                    Vector3::new(0.2 * t, -0.1 * t, 0.05 * t * t),
                )
            })
            .collect()
    }

    #[test]
    fn rpe_of_identical_trajectories_is_zero() {
        let a = wiggly(30);
        let r = rpe(&a, &a, 1).unwrap();
        assert_eq!(r.pairs.len(), 29);
        assert!(r.translation.iter().all(|&e| e < 1e-14));
        assert!(r.rotation_angle_rad.iter().all(|&e| e < 1e-7));
        // A global rigid change of frame leaves RPE at zero as well.
        let g = Isometry3::new(Vector3::new(5.0, -1.0, 2.0), Vector3::new(0.4, 0.2, -1.0));
        let b: Vec<_> = a.iter().map(|p| g * p).collect();
        let r = rpe(&a, &b, 1).unwrap();
        assert!(r.translation.iter().all(|&e| e < 1e-13));
        assert_eq!(rpe(&a, &a, 7).unwrap().pairs[..2], [(0, 7), (7, 14)]);
        assert!(matches!(rpe(&a, &a, 0), Err(EvalError::InvalidDelta)));
        assert!(rpe(&a[..1], &a[..1], 1).is_err());
    }

    #[test]
    fn rpe_pairs_by_path_length_follow_evo() {
        // Steps of 0.4 m along x: from pose 0 the path reaches 1 m at pose 3 (1.2 m), then at 6
        // and 9 — evo's filter_pairs_by_path without all_pairs.
        let a: Vec<_> = (0..11)
            .map(|i| Isometry3::translation(0.4 * i as f64, 0.0, 0.0))
            .collect();
        assert_eq!(
            rpe_pairs(&a, RpeDelta::Metres(1.0)).unwrap(),
            [(0, 3), (3, 6), (6, 9)]
        );
        assert_eq!(
            rpe_pairs(&a, RpeDelta::Frames(5)).unwrap(),
            [(0, 5), (5, 10)]
        );
        assert!(matches!(
            rpe_pairs(&a, RpeDelta::Metres(100.0)),
            Err(EvalError::NoPairs { poses: 11, .. })
        ));
        for bad in [0.0, -1.0, f64::NAN] {
            assert!(matches!(
                rpe_pairs(&a, RpeDelta::Metres(bad)),
                Err(EvalError::InvalidDelta)
            ));
        }
    }

    #[test]
    fn rpe_sees_a_single_jump_twice_in_translation() {
        // Estimate = reference with pose 10 shifted by 0.5 along x (no rotation): the pairs
        // (9, 10) and (10, 11) see relative motions of 1.5 and 0.5 instead of 1, errors 0.5.
        let a: Vec<_> = (0..20)
            .map(|i| Isometry3::translation(i as f64, 0.0, 0.0))
            .collect();
        let mut b = a.clone();
        b[10].translation.vector.x += 0.5;
        let r = rpe(&a, &b, 1).unwrap();
        for (k, &e) in r.translation.iter().enumerate() {
            let expected = if k == 9 || k == 10 { 0.5 } else { 0.0 };
            assert!((e - expected).abs() < 1e-14, "{k}: {e}");
        }
    }

    #[test]
    fn ape_parts() {
        let a = wiggly(5);
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.25));
        let b: Vec<_> = a
            .iter()
            .map(|p| {
                Isometry3::from_parts(
                    (p.translation.vector + Vector3::new(0.0, 0.3, 0.4)).into(),
                    p.rotation * rot,
                )
            })
            .collect();
        assert!(
            ape_translation(&a, &b)
                .unwrap()
                .iter()
                .all(|&e| (e - 0.5).abs() < 1e-14)
        );
        assert!(
            ape_rotation_angle(&a, &b)
                .unwrap()
                .iter()
                .all(|&e| (e - 0.25).abs() < 1e-14)
        );
        assert!(matches!(
            ape_translation(&a, &b[..2]),
            Err(EvalError::LengthMismatch { .. })
        ));
        // The angle is accurate for tiny rotations.
        let tiny = UnitQuaternion::from_scaled_axis(Vector3::new(1e-9, 0.0, 0.0));
        assert!((rotation_angle(&tiny) - 1e-9).abs() < 1e-22);
    }
}
