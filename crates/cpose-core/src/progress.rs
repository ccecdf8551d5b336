//! Progress bars for long loops, drawn only when stderr is a terminal (quiet in CI and tests).
//!
//! Every bar of the process belongs to one [`MultiProgress`], so several units of a study can
//! draw at once, and [`eprint_line`] prints above them instead of through them.

use std::borrow::Cow;
use std::io::IsTerminal as _;
use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The bars of this process.
fn bars() -> &'static MultiProgress {
    static BARS: OnceLock<MultiProgress> = OnceLock::new();
    BARS.get_or_init(|| MultiProgress::with_draw_target(ProgressDrawTarget::stderr()))
}

/// Prints `line` to stderr above the progress bars (which are redrawn below it), so log lines
/// never leave fragments of a bar behind.
pub fn eprint_line(line: &str) {
    bars().suspend(|| eprintln!("{line}"));
}

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
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        if let Ok(style) = ProgressStyle::with_template(TEMPLATE) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(message);
        let bar = if enabled && std::io::stderr().is_terminal() {
            bars().add(bar)
        } else {
            bar
        };
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

    /// The number of steps, if set.
    pub fn length(&self) -> Option<u64> {
        self.bar.length()
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
        bars().remove(&self.bar);
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
