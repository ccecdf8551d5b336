//! When a fit lowers its learning rate and when it stops: its errors on the samples it is fitted
//! to are within a tolerance, its loss has stopped falling at the lowest rate (a plateau), or
//! its step budget is spent.
//!
//! The loss is averaged over windows of [`StopRule::check_every`] steps, which smooths the
//! noise of stochastic batches (IMU samples, rays). At the end of each window the caller says
//! whether its own errors are within tolerance; otherwise the window's mean loss is compared
//! with the best so far. The loss is on a plateau when no window of the last
//! [`StopRule::plateau_steps`] steps improved on the best by [`StopRule::plateau_rel`]. At a
//! plateau the learning rates fall by [`StopRule::lr_factor`] (PyTorch's `ReduceLROnPlateau`),
//! up to [`StopRule::lr_drops`] times; a plateau after the last drop ends the fit. Adam at a
//! fixed rate keeps jumping around a minimum it cannot settle in; the drops let it settle
//! without a schedule tied to the step budget.

use serde::{Deserialize, Serialize};

/// How a fit decides that it has converged.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StopRule {
    /// Steps per window: the loss is averaged and the tolerance checked once per window.
    pub check_every: usize,
    /// A plateau: no window of this many steps lowered the best mean loss by `plateau_rel`
    /// (0: never stop on a plateau).
    pub plateau_steps: usize,
    /// The relative improvement that counts, e.g. 0.01 for 1%.
    pub plateau_rel: f64,
    /// The factor the learning rates fall by at a plateau.
    pub lr_factor: f64,
    /// How many times they fall before a plateau stops the fit.
    pub lr_drops: usize,
}

impl Default for StopRule {
    fn default() -> Self {
        Self {
            check_every: 100,
            plateau_steps: 1000,
            plateau_rel: 0.01,
            lr_factor: 0.1,
            lr_drops: 2,
        }
    }
}

impl StopRule {
    /// Errors naming the bad setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.check_every == 0 {
            return Err("check_every must be at least 1".into());
        }
        if !(self.plateau_rel.is_finite() && (0.0..1.0).contains(&self.plateau_rel)) {
            return Err(format!(
                "plateau_rel = {} must lie in [0, 1)",
                self.plateau_rel
            ));
        }
        if !(self.lr_factor > 0.0 && self.lr_factor < 1.0) {
            return Err(format!("lr_factor = {} must lie in (0, 1)", self.lr_factor));
        }
        Ok(())
    }
}

/// Why a fit stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// Its errors on the fitted samples fell within the tolerance.
    Tolerance,
    /// Its loss stopped falling at the lowest learning rate before that.
    Plateau,
    /// Its step budget ran out before either.
    Budget,
}

impl StopReason {
    /// The name in logs and `metrics.json`.
    pub fn key(self) -> &'static str {
        match self {
            Self::Tolerance => "tolerance",
            Self::Plateau => "plateau",
            Self::Budget => "budget",
        }
    }
}

/// The running state of a [`StopRule`]: feed every step's loss to [`Convergence::observe`]
/// and ask [`Convergence::check`] at the end of each window.
#[derive(Clone, Debug, PartialEq)]
pub struct Convergence {
    rule: StopRule,
    window_sum: f64,
    window_steps: usize,
    best: f64,
    steps_since_best: usize,
    /// Learning-rate drops so far.
    drops: usize,
    /// The mean loss of the last closed window (NaN before the first).
    last_mean: f64,
}

impl Convergence {
    /// A fit that has not started.
    pub fn new(rule: StopRule) -> Self {
        Self {
            rule,
            window_sum: 0.0,
            window_steps: 0,
            best: f64::INFINITY,
            steps_since_best: 0,
            drops: 0,
            last_mean: f64::NAN,
        }
    }

    /// The factor on the learning rates now: `lr_factor^drops`.
    pub fn lr_scale(&self) -> f64 {
        self.rule.lr_factor.powi(self.drops as i32)
    }

    /// Adds one step's loss; `true` when the window is complete and [`Convergence::check`] is due.
    pub fn observe(&mut self, loss: f64) -> bool {
        self.window_sum += loss;
        self.window_steps += 1;
        self.window_steps >= self.rule.check_every
    }

    /// Closes the window; `within_tolerance` is the caller's own test on the fitted samples.
    /// `Some(reason)` when the fit should stop; at a plateau before the last drop, the rates
    /// fall ([`Convergence::lr_scale`]) and the plateau count starts again.
    pub fn check(&mut self, within_tolerance: bool) -> Option<StopReason> {
        let steps = self.window_steps.max(1);
        let mean = self.window_sum / steps as f64;
        self.last_mean = mean;
        self.window_sum = 0.0;
        self.window_steps = 0;
        if within_tolerance {
            return Some(StopReason::Tolerance);
        }
        if mean < self.best * (1.0 - self.rule.plateau_rel) {
            self.best = mean;
            self.steps_since_best = 0;
        } else {
            self.best = self.best.min(mean);
            self.steps_since_best += steps;
        }
        if self.rule.plateau_steps == 0 || self.steps_since_best < self.rule.plateau_steps {
            return None;
        }
        if self.drops < self.rule.lr_drops {
            self.drops += 1;
            self.steps_since_best = 0;
            None
        } else {
            Some(StopReason::Plateau)
        }
    }

    /// The mean loss of the last closed window, if one has closed: a fit's final loss.
    pub fn last_mean(&self) -> Option<f64> {
        (!self.last_mean.is_nan()).then_some(self.last_mean)
    }

    /// The state, for a checkpoint.
    pub fn state(&self) -> [f64; 6] {
        [
            self.window_sum,
            self.window_steps as f64,
            self.best,
            self.steps_since_best as f64,
            self.drops as f64,
            self.last_mean,
        ]
    }

    /// Restores a [`Convergence::state`].
    pub fn set_state(&mut self, state: [f64; 6]) {
        self.window_sum = state[0];
        self.window_steps = state[1] as usize;
        self.best = state[2];
        self.steps_since_best = state[3] as usize;
        self.drops = state[4] as usize;
        self.last_mean = state[5];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule() -> StopRule {
        StopRule {
            check_every: 10,
            plateau_steps: 30,
            plateau_rel: 0.01,
            lr_factor: 0.1,
            lr_drops: 0,
        }
    }

    /// Runs `losses` through a rule, checking at every window end; the step and reason of the
    /// stop, if any.
    fn first_stop(
        losses: impl Iterator<Item = f64>,
        tolerance_from: usize,
    ) -> Option<(usize, StopReason)> {
        let mut c = Convergence::new(rule());
        for (i, loss) in losses.enumerate() {
            if c.observe(loss)
                && let Some(reason) = c.check(i + 1 >= tolerance_from)
            {
                return Some((i + 1, reason));
            }
        }
        None
    }

    #[test]
    fn a_falling_loss_runs_on_and_a_flat_one_stops_after_the_plateau_steps() {
        // Halving every window: never a plateau.
        let falling = (0..200).map(|i| 0.5f64.powi(i / 10));
        assert_eq!(first_stop(falling, usize::MAX), None);
        // Flat from the start: the first window sets the best, three more make the plateau.
        assert_eq!(
            first_stop(std::iter::repeat_n(1.0, 200), usize::MAX),
            Some((40, StopReason::Plateau))
        );
        // Improvements below 1% do not count.
        let creeping = (0..200).map(|i| 0.999f64.powi(i / 10));
        assert_eq!(
            first_stop(creeping, usize::MAX),
            Some((40, StopReason::Plateau))
        );
    }

    #[test]
    fn plateaus_lower_the_rate_before_they_stop_the_fit() {
        let mut c = Convergence::new(StopRule {
            lr_drops: 2,
            ..rule()
        });
        let mut scales = Vec::new();
        let mut stopped = None;
        for step in 1..=200 {
            if c.observe(1.0) {
                if let Some(reason) = c.check(false) {
                    stopped = Some((step, reason));
                    break;
                }
                scales.push(c.lr_scale());
            }
        }
        // Best at 10, a plateau at 40 (drop), 70 (drop), 100 (stop).
        assert_eq!(stopped, Some((100, StopReason::Plateau)));
        assert_eq!(scales[2], 1.0);
        assert!((scales[3] - 0.1).abs() < 1e-15 && (scales[8] - 0.01).abs() < 1e-15);
    }

    #[test]
    fn tolerance_stops_at_the_end_of_its_window() {
        let falling = (0..200).map(|i| 0.5f64.powi(i / 10));
        assert_eq!(first_stop(falling, 55), Some((60, StopReason::Tolerance)));
    }

    #[test]
    fn a_restored_state_continues_identically() {
        let losses: Vec<f64> = (0..95).map(|i| 1.0 + 0.1 * ((i * 7) % 5) as f64).collect();
        let mut a = Convergence::new(rule());
        for &l in &losses[..47] {
            if a.observe(l) {
                a.check(false);
            }
        }
        let mut b = Convergence::new(rule());
        b.set_state(a.state());
        for &l in &losses[47..] {
            let (da, db) = (a.observe(l), b.observe(l));
            assert_eq!(da, db);
            if da {
                assert_eq!(a.check(false), b.check(false));
            }
        }
        assert_eq!(a, b);
    }

    #[test]
    fn bad_rules_are_errors() {
        let bad = StopRule {
            check_every: 0,
            ..rule()
        };
        assert!(bad.validate().unwrap_err().contains("check_every"));
        let bad = StopRule {
            plateau_rel: f64::NAN,
            ..rule()
        };
        assert!(bad.validate().unwrap_err().contains("plateau_rel"));
        let bad = StopRule {
            lr_factor: 1.0,
            ..rule()
        };
        assert!(bad.validate().unwrap_err().contains("lr_factor"));
    }
}
