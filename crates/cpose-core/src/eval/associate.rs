//! Association of two trajectories by nearest timestamp, as evo's
//! `sync.associate_trajectories` with `SyncMethod.nearest_time` / `sync.matching_time_indices`
//! (evo 1.38.1, sorted-timestamps path).
//!
//! evo's rule, reproduced operation by operation:
//! - the **shorter** trajectory drives (on equal lengths, the second one drives); the other one's
//!   stamps are shifted by `offset` (the second trajectory's time offset when the second is the
//!   longer one, its negation otherwise): `l_j ← l_j + offset`;
//! - a driving stamp `s` outside `[l_0 − max_diff, l_last + max_diff]` is skipped;
//! - `j` = first index with `l_j > s` (`np.searchsorted(…, side="right")`), clamped to the last
//!   index; `ub = l_j − s`, `lb = s − l_{j−1}` (∞ for `j = 0`);
//! - take `j` if `ub ≤ max_diff` and `ub < lb`, else `j − 1` if `lb ≤ max_diff` and `lb ≤ ub`
//!   (ties go to the earlier stamp), else nothing.
//!
//! An index of the longer trajectory may therefore be matched twice. Older evo releases searched
//! linearly for the first minimiser of `|l_j − s|`; that gives the same pairs except, possibly,
//! for differences within an ulp of `max_diff` (a unit test checks the two agree).

use super::EvalError;
use super::trajectory::Trajectory;

/// evo's default association tolerance, seconds (`--t_max_diff 0.01`).
pub const DEFAULT_MAX_DIFF_SECS: f64 = 0.01;

/// Matched index pairs between a first and a second trajectory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Association {
    /// `(index in first, index in second)`, in increasing order of both.
    pub pairs: Vec<(usize, usize)>,
}

impl Association {
    /// Number of matched pairs.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// Whether nothing matched (never the case for an `Association` returned by [`associate`]).
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// The matched poses of `first` and `second`, in pair order.
    pub fn poses(
        &self,
        first: &Trajectory,
        second: &Trajectory,
    ) -> (Vec<nalgebra::Isometry3<f64>>, Vec<nalgebra::Isometry3<f64>>) {
        self.pairs
            .iter()
            .map(|&(i, j)| (first.poses()[i], second.poses()[j]))
            .unzip()
    }
}

/// Associates `first` and `second` by nearest timestamp within `max_diff_secs` (evo's
/// `associate_trajectories(first, second, max_diff)`); see the module docs. Errors when
/// `max_diff_secs` is negative or not finite, or when nothing matches.
pub fn associate(
    first: &Trajectory,
    second: &Trajectory,
    max_diff_secs: f64,
) -> Result<Association, EvalError> {
    associate_with_offset(first, second, max_diff_secs, 0.0)
}

/// [`associate`] with the second trajectory's stamps shifted by `offset_second_secs` (evo's
/// `offset_2`, `--t_offset`).
pub fn associate_with_offset(
    first: &Trajectory,
    second: &Trajectory,
    max_diff_secs: f64,
    offset_second_secs: f64,
) -> Result<Association, EvalError> {
    if !(max_diff_secs >= 0.0 && max_diff_secs.is_finite()) {
        return Err(EvalError::InvalidMaxDiff { max_diff_secs });
    }
    if !offset_second_secs.is_finite() {
        return Err(EvalError::InvalidOffset { offset_second_secs });
    }
    let second_longer = second.len() > first.len();
    let pairs = if second_longer {
        matching_indices(
            first.timestamps_secs(),
            second.timestamps_secs(),
            max_diff_secs,
            offset_second_secs,
        )
    } else {
        matching_indices(
            second.timestamps_secs(),
            first.timestamps_secs(),
            max_diff_secs,
            -offset_second_secs,
        )
        .into_iter()
        .map(|(s, l)| (l, s))
        .collect()
    };
    if pairs.is_empty() {
        return Err(EvalError::NoMatches {
            first_len: first.len(),
            second_len: second.len(),
            max_diff_secs,
            offset_second_secs,
        });
    }
    Ok(Association { pairs })
}

/// evo's `matching_time_indices(short, long, max_diff, offset)`: `(index in short, index in long)`.
/// `long` must be sorted (strictly increasing, as a [`Trajectory`]'s stamps are).
fn matching_indices(
    short: &[f64],
    long: &[f64],
    max_diff: f64,
    offset: f64,
) -> Vec<(usize, usize)> {
    let mut pairs = Vec::new();
    let shifted: Vec<f64> = long.iter().map(|l| l + offset).collect();
    let (Some(&first), Some(&last)) = (shifted.first(), shifted.last()) else {
        return pairs;
    };
    for (i, &s) in short.iter().enumerate() {
        if s < first - max_diff || s > last + max_diff {
            continue;
        }
        let j = partition_point(shifted.len(), |j| shifted[j] <= s).min(shifted.len() - 1);
        let diff_ub = shifted[j] - s;
        let diff_lb = if j > 0 {
            s - shifted[j - 1]
        } else {
            f64::INFINITY
        };
        if diff_ub <= max_diff && diff_ub < diff_lb {
            pairs.push((i, j));
        } else if diff_lb <= max_diff && diff_lb <= diff_ub {
            pairs.push((i, j - 1));
        }
    }
    pairs
}

/// The first index in `0..n` for which `pred` is false, given `pred` true then false.
fn partition_point(n: usize, pred: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Older evo's linear search: argmin (first minimum) of |(l + offset) − s|.
    fn brute_force(short: &[f64], long: &[f64], max_diff: f64, offset: f64) -> Vec<(usize, usize)> {
        let mut pairs = Vec::new();
        for (i, &s) in short.iter().enumerate() {
            let mut best = 0;
            for j in 1..long.len() {
                if ((long[j] + offset) - s).abs() < ((long[best] + offset) - s).abs() {
                    best = j;
                }
            }
            if ((long[best] + offset) - s).abs() <= max_diff {
                pairs.push((i, best));
            }
        }
        pairs
    }

    fn traj(ts: Vec<f64>) -> Trajectory {
        let n = ts.len();
        Trajectory::new(ts, vec![Isometry3::identity(); n]).unwrap()
    }

    #[test]
    fn binary_search_equals_older_evo_linear_search() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for case in 0..200 {
            let mut a: Vec<f64> = (0..rng.random_range(1..40))
                .map(|_| (rng.random_range(0..400) as f64) * 0.005)
                .collect();
            let mut b: Vec<f64> = (0..rng.random_range(1..40))
                .map(|_| 1.3e9 + rng.random::<f64>() * 2.0)
                .collect();
            if case % 2 == 0 {
                b.iter_mut().for_each(|x| *x -= 1.3e9);
            }
            for v in [&mut a, &mut b] {
                v.sort_by(f64::total_cmp);
                v.dedup();
            }
            for (max_diff, offset) in [(0.01, 0.0), (0.05, 0.003), (1e9, 0.0), (0.0, 0.0)] {
                assert_eq!(
                    matching_indices(&a, &b, max_diff, offset),
                    brute_force(&a, &b, max_diff, offset)
                );
            }
        }
    }

    #[test]
    fn ties_pick_the_earlier_index_and_longer_may_repeat() {
        // 0.5 is equidistant from 0.25 and 0.75 (exactly representable): evo picks index 0.
        assert_eq!(
            matching_indices(&[0.5], &[0.25, 0.75], 1.0, 0.0),
            vec![(0, 0)]
        );
        // Two short stamps may match the same long stamp.
        assert_eq!(
            matching_indices(&[0.0, 0.001], &[0.0, 10.0], 0.01, 0.0),
            vec![(0, 0), (1, 0)]
        );
    }

    #[test]
    fn shorter_trajectory_drives_and_pairs_keep_first_second_order() {
        let first = traj(vec![0.0, 0.1, 0.2, 0.3]);
        let second = traj(vec![0.101, 0.299]);
        let a = associate(&first, &second, 0.01).unwrap();
        assert_eq!(a.pairs, vec![(1, 0), (3, 1)]);
        let b = associate(&second, &first, 0.01).unwrap();
        assert_eq!(b.pairs, vec![(0, 1), (1, 3)]);
        assert_eq!(a.poses(&first, &second).0.len(), 2);
    }

    #[test]
    fn no_match_and_bad_tolerance_are_errors() {
        let first = traj(vec![0.0, 1.0]);
        let second = traj(vec![0.5]);
        assert!(matches!(
            associate(&first, &second, 0.01),
            Err(EvalError::NoMatches { .. })
        ));
        assert!(matches!(
            associate(&first, &second, -1.0),
            Err(EvalError::InvalidMaxDiff { .. })
        ));
        assert!(matches!(
            associate(&first, &second, f64::NAN),
            Err(EvalError::InvalidMaxDiff { .. })
        ));
        // With an offset of 0.5 s on the second, 0.5 + 0.5 = 1.0 matches first[1].
        let a = associate_with_offset(&first, &second, 0.01, 0.5).unwrap();
        assert_eq!(a.pairs, vec![(1, 0)]);
    }
}
