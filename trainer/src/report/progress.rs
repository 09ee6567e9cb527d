//! Progress bars on stderr (indicatif) for long fits and benchmarks.
//!
//! Silent when asked (`quiet`) or when stderr is not a terminal (pipes, CI, tests), so logs and
//! captured output never fill with redraws.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::Duration;

/// Whether a bar would be drawn: not `quiet` and stderr is a terminal.
pub fn progress_visible(quiet: bool) -> bool {
    !quiet && std::io::stderr().is_terminal()
}

fn bar(len: u64, visible: bool, template: &str) -> ProgressBar {
    let target = if visible { ProgressDrawTarget::stderr_with_hz(10) } else { ProgressDrawTarget::hidden() };
    let bar = ProgressBar::with_draw_target(Some(len), target);
    // The templates are constants; fall back to the default style should one ever be rejected.
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Levenberg–Marquardt progress: iteration of the limit, energy and current training error.
///
/// ```no_run
/// # use cbd_trainer::report::progress::FitProgress;
/// let p = FitProgress::new(50, false, "length units");
/// p.update(1, 3.2e-2, 1.1e-2);
/// p.finish("converged after 1 iteration");
/// ```
pub struct FitProgress {
    bar: ProgressBar,
    unit: String,
}

impl FitProgress {
    /// A bar over `max_iterations`; hidden when `quiet` or stderr is not a terminal.
    pub fn new(max_iterations: usize, quiet: bool, unit: &str) -> FitProgress {
        Self::with_visibility(max_iterations, progress_visible(quiet), unit)
    }

    /// As [`FitProgress::new`] with the visibility decided by the caller.
    pub fn with_visibility(max_iterations: usize, visible: bool, unit: &str) -> FitProgress {
        let bar =
            bar(max_iterations as u64, visible, "{prefix:.bold} [{elapsed_precise}] [{bar:30.cyan/blue}] iteration {pos}/{len}  {msg}");
        bar.set_prefix("fit");
        bar.set_message("starting");
        if visible {
            bar.enable_steady_tick(Duration::from_millis(250));
        }
        FitProgress { bar, unit: unit.to_string() }
    }

    /// Whether the bar is drawn.
    pub fn is_visible(&self) -> bool {
        !self.bar.is_hidden()
    }

    /// After each iteration: its number, the energy and the RMS training error (in the unit given).
    pub fn update(&self, iteration: usize, energy: f64, train_rms: f64) {
        self.bar.set_position(iteration as u64);
        self.bar.set_message(format!("energy {energy:.4e}  train RMS {train_rms:.3e} {}", self.unit));
    }

    /// Stops the bar where it is (the last iteration, not the limit), leaving `message` after it
    /// (shown only where the bar was drawn).
    pub fn finish(&self, message: &str) {
        self.bar.abandon_with_message(message.to_string());
    }

    /// The current message (for tests and logs).
    pub fn message(&self) -> String {
        self.bar.message()
    }
}

impl Drop for FitProgress {
    fn drop(&mut self) {
        if !self.bar.is_finished() {
            self.bar.abandon();
        }
    }
}

/// Progress over `total` items of any long job (benchmarks, comparisons): a label and a message.
pub struct TaskProgress {
    bar: ProgressBar,
}

impl TaskProgress {
    /// `what`: a short label, e.g. "compare". Hidden when `quiet` or stderr is not a terminal.
    pub fn new(total: usize, what: &str, quiet: bool) -> TaskProgress {
        let bar = bar(total as u64, progress_visible(quiet), "{prefix:.bold} [{elapsed_precise}] [{bar:30.cyan/blue}] {pos}/{len}  {msg}");
        bar.set_prefix(what.to_string());
        TaskProgress { bar }
    }

    /// Sets the message (e.g. the item now running) without advancing.
    pub fn message(&self, message: &str) {
        self.bar.set_message(message.to_string());
    }

    /// One item done.
    pub fn step(&self, message: &str) {
        self.bar.inc(1);
        self.bar.set_message(message.to_string());
    }

    pub fn finish(&self, message: &str) {
        self.bar.finish_with_message(message.to_string());
    }

    pub fn is_visible(&self) -> bool {
        !self.bar.is_hidden()
    }
}

impl Drop for TaskProgress {
    fn drop(&mut self) {
        if !self.bar.is_finished() {
            self.bar.abandon();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quiet_bars_are_hidden_and_still_track_state() {
        let p = FitProgress::new(20, true, "mm");
        assert!(!p.is_visible());
        p.update(3, 1.5e-2, 2.0e-3);
        assert!(p.message().contains("energy 1.5000e-2"), "{}", p.message());
        assert!(p.message().contains("mm"));
        p.finish("done");
        let t = TaskProgress::new(4, "compare", true);
        assert!(!t.is_visible());
        t.step("krr");
        t.finish("done");
    }

    #[test]
    fn visibility_follows_the_flag_and_the_terminal() {
        assert!(!progress_visible(true));
        // Under `cargo test` stderr is captured or piped unless run by hand in a terminal.
        assert_eq!(progress_visible(false), std::io::stderr().is_terminal());
        let p = FitProgress::with_visibility(5, false, "m");
        assert!(!p.is_visible());
    }
}
