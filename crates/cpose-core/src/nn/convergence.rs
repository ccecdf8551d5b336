//! When a fit lowers its learning rate and when it stops: its errors on the samples it is fitted
//! to are within a tolerance, its loss has stopped falling at the lowest rate (a plateau), or
//! its step budget is spent.
//!
//! The loss is averaged over windows of [`StopRule::check_every`] steps. At the end of each
//! window the caller says whether its own errors are within tolerance; otherwise the window joins
//! the trend of the last [`StopRule::plateau_steps`] steps: the median of the slopes between every
//! two of their log mean losses (the Theil–Sen estimate). The loss is on a plateau when that trend
//! projects a fall of less than [`StopRule::plateau_rel`] over the next `plateau_steps` steps.
//! A median slope ignores the spikes of a noisy fit (stochastic IMU batches pulling against
//! the poses), which a comparison with the best window so far does not: a lucky low window would
//! pass for a plateau while the loss is still falling. At a plateau the learning rates fall by
//! [`StopRule::lr_factor`] (PyTorch's `ReduceLROnPlateau`), up to [`StopRule::lr_drops`] times,
//! and the trend starts again; a plateau after the last drop ends the fit. Adam at a fixed rate
//! keeps jumping around a minimum it cannot settle in; the drops let it settle without a
//! schedule tied to the step budget.

use serde::{Deserialize, Serialize};

/// How a fit decides that it has converged.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StopRule {
    /// Steps per window: the loss is averaged and the tolerance checked once per window.
    pub check_every: usize,
    /// The steps a trend is taken over (at least one window; 0: never stop on a plateau).
    pub plateau_steps: usize,
    /// The relative fall per `plateau_steps` below which the loss is on a plateau, e.g. 0.01.
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
    /// Learning-rate drops so far.
    drops: usize,
    /// The mean loss of the last closed window (NaN before the first).
    last_mean: f64,
    /// `ln` of the mean loss of the windows since the last drop, at most a trend's worth.
    trend: Vec<f64>,
}

impl Convergence {
    /// A fit that has not started.
    pub fn new(rule: StopRule) -> Self {
        Self {
            rule,
            window_sum: 0.0,
            window_steps: 0,
            drops: 0,
            last_mean: f64::NAN,
            trend: Vec::new(),
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

    /// Windows in a trend: `plateau_steps / check_every`, at least 2.
    fn trend_windows(&self) -> usize {
        (self.rule.plateau_steps / self.rule.check_every).max(2)
    }

    /// Closes the window; `within_tolerance` is the caller's own test on the fitted samples.
    /// `Some(reason)` when the fit should stop; at a plateau before the last drop, the rates
    /// fall ([`Convergence::lr_scale`]) and the trend starts again.
    pub fn check(&mut self, within_tolerance: bool) -> Option<StopReason> {
        let mean = self.window_sum / self.window_steps.max(1) as f64;
        self.last_mean = mean;
        self.window_sum = 0.0;
        self.window_steps = 0;
        if within_tolerance {
            return Some(StopReason::Tolerance);
        }
        if self.rule.plateau_steps == 0 {
            return None;
        }
        let windows = self.trend_windows();
        if self.trend.len() == windows {
            self.trend.remove(0);
        }
        // A zero loss cannot fall further: ln 0 = −∞ reads as flat.
        self.trend.push(mean.max(f64::MIN_POSITIVE).ln());
        if self.trend.len() < windows {
            return None;
        }
        // Projected fall of ln L over `windows` windows: −slope · windows ≈ relative fall.
        let fall = -theil_sen_slope(&self.trend) * windows as f64;
        if fall >= -(1.0 - self.rule.plateau_rel).ln() {
            return None;
        }
        if self.drops < self.rule.lr_drops {
            self.drops += 1;
            self.trend.clear();
            None
        } else {
            Some(StopReason::Plateau)
        }
    }

    /// The mean loss of the last closed window, if one has closed: a fit's final loss.
    pub fn last_mean(&self) -> Option<f64> {
        (!self.last_mean.is_nan()).then_some(self.last_mean)
    }

    /// The state, for a checkpoint: the window, the drops, the last mean and the trend.
    pub fn state(&self) -> Vec<f64> {
        let mut state = vec![
            self.window_sum,
            self.window_steps as f64,
            self.drops as f64,
            self.last_mean,
        ];
        state.extend(&self.trend);
        state
    }

    /// Restores a [`Convergence::state`] of the same rule.
    pub fn set_state(&mut self, state: &[f64]) -> anyhow::Result<()> {
        let [window_sum, window_steps, drops, last_mean, trend @ ..] = state else {
            anyhow::bail!("a fit state has at least 4 numbers, not {}", state.len());
        };
        anyhow::ensure!(
            trend.len() <= self.trend_windows(),
            "a fit state holds a trend of {} windows, more than the rule's {}",
            trend.len(),
            self.trend_windows()
        );
        self.window_sum = *window_sum;
        self.window_steps = *window_steps as usize;
        self.drops = *drops as usize;
        self.last_mean = *last_mean;
        self.trend = trend.to_vec();
        Ok(())
    }
}

/// The Theil–Sen slope of equally spaced values: the median of `(y_j − y_i) / (j − i)` over
/// every pair `i < j`.
fn theil_sen_slope(y: &[f64]) -> f64 {
    let mut slopes = Vec::with_capacity(y.len() * y.len().saturating_sub(1) / 2);
    for i in 0..y.len() {
        for j in i + 1..y.len() {
            slopes.push((y[j] - y[i]) / (j - i) as f64);
        }
    }
    slopes.sort_by(f64::total_cmp);
    match slopes.len() {
        0 => 0.0,
        n if n % 2 == 1 => slopes[n / 2],
        n => 0.5 * (slopes[n / 2 - 1] + slopes[n / 2]),
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
        // Flat from the start: a plateau once three windows make a trend.
        assert_eq!(
            first_stop(std::iter::repeat_n(1.0, 200), usize::MAX),
            Some((30, StopReason::Plateau))
        );
        // Falls below 1% per plateau span do not count.
        let creeping = (0..200).map(|i| 0.999f64.powi(i / 10));
        assert_eq!(
            first_stop(creeping, usize::MAX),
            Some((30, StopReason::Plateau))
        );
    }

    #[test]
    fn spikes_of_a_noisy_fit_neither_hide_a_fall_nor_fake_one() {
        let rule = StopRule {
            check_every: 1,
            plateau_steps: 10,
            ..rule()
        };
        // Every fourth window three times too high.
        let spiked = |base: f64, w: usize| if w % 4 == 3 { 3.0 * base } else { base };
        let run = |loss: &dyn Fn(usize) -> f64| {
            let mut c = Convergence::new(rule);
            (0..300).find_map(|w| {
                c.observe(loss(w));
                c.check(false).map(|_| w + 1)
            })
        };
        // Falling 2% a window under the spikes: never a plateau.
        assert_eq!(run(&|w| spiked(0.98f64.powi(w as i32), w)), None);
        // Flat under the spikes: a plateau as soon as the trend is full.
        assert_eq!(run(&|w| spiked(1.0, w)), Some(10));
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
        // A plateau at 30 (drop), 60 (drop), 90 (stop): each trend starts after the drop.
        assert_eq!(stopped, Some((90, StopReason::Plateau)));
        assert_eq!(scales[1], 1.0);
        assert!((scales[2] - 0.1).abs() < 1e-15 && (scales[4] - 0.1).abs() < 1e-15);
        assert!((scales[5] - 0.01).abs() < 1e-15);
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
        b.set_state(&a.state()).unwrap();
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
