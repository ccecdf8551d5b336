//! Progress bars for long loops, drawn only when stderr is a terminal (quiet in CI and tests).

use std::borrow::Cow;
use std::io::IsTerminal as _;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Template of the bar: message, bar, position/length, elapsed and ETA.
const TEMPLATE: &str = "{msg:>12} [{bar:30}] {pos}/{len} ({elapsed} elapsed, ETA {eta})";

/// A progress bar over `len` steps; a no-op when hidden.
#[derive(Clone, Debug)]
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar that draws on stderr if stderr is a terminal and `enabled`, else a hidden one.
    pub fn new(len: u64, message: impl Into<Cow<'static, str>>, enabled: bool) -> Self {
        let target = if enabled && std::io::stderr().is_terminal() {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let bar = ProgressBar::with_draw_target(Some(len), target);
        if let Ok(style) = ProgressStyle::with_template(TEMPLATE) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(message);
        Self { bar }
    }

    /// A bar that never draws.
    pub fn hidden() -> Self {
        Self::new(0, "", false)
    }

    /// Whether the bar draws anything.
    pub fn is_hidden(&self) -> bool {
        self.bar.is_hidden()
    }

    /// Advances by `steps`.
    pub fn inc(&self, steps: u64) {
        self.bar.inc(steps);
    }

    /// Sets the position.
    pub fn set_position(&self, position: u64) {
        self.bar.set_position(position);
    }

    /// The current position.
    pub fn position(&self) -> u64 {
        self.bar.position()
    }

    /// Sets the number of steps.
    pub fn set_length(&self, len: u64) {
        self.bar.set_length(len);
    }

    /// Replaces the message shown before the bar (e.g. the current loss).
    pub fn set_message(&self, message: impl Into<Cow<'static, str>>) {
        self.bar.set_message(message);
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disabled_bar_is_hidden_and_counts() {
        let p = Progress::new(10, "fit", false);
        assert!(p.is_hidden());
        p.inc(3);
        p.set_position(5);
        p.inc(1);
        assert_eq!(p.position(), 6);
        p.finish();
    }
}
