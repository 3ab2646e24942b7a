//! Progress of a long run (a benchmark, the evidence study, a live room series) on a terminal,
//! and nothing when stderr is piped or captured (CI logs, `2> file`): the bar draws only on a
//! terminal, while the run's own lines always print.
//!
//! ```
//! let p = softsync_benchkit::Progress::new(3, "cases");
//! for i in 0..3 {
//!     p.set_message(format!("case {i}"));
//!     p.line(format!("case {i}: done")); // printed above the bar, or plain when piped
//!     p.inc();
//! }
//! p.finish();
//! ```

use std::borrow::Cow;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar of `len` steps on stderr, drawn only when stderr is a terminal.
#[derive(Debug, Clone)]
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar of `len` steps named `what` (hidden unless stderr is a terminal).
    pub fn new(len: u64, what: &str) -> Self {
        Self::with_target(len, what, ProgressDrawTarget::stderr())
    }

    /// A spinner for a step of unknown length (loading a scene, clustering a big mesh).
    pub fn spinner(what: impl Into<Cow<'static, str>>) -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template("{spinner} {msg} {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_message(what);
        bar.enable_steady_tick(Duration::from_millis(120));
        Progress { bar }
    }

    fn with_target(len: u64, what: &str, target: ProgressDrawTarget) -> Self {
        let bar = ProgressBar::with_draw_target(Some(len), target);
        let template =
            format!("{what} [{{bar:30}}] {{pos}}/{{len}} {{elapsed}} (eta {{eta}}) {{msg}}");
        bar.set_style(
            ProgressStyle::with_template(&template)
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        Progress { bar }
    }

    /// Whether the bar is drawn (stderr is a terminal).
    pub fn is_drawn(&self) -> bool {
        !self.bar.is_hidden()
    }

    /// What the current step is.
    pub fn set_message(&self, msg: impl Into<Cow<'static, str>>) {
        self.bar.set_message(msg);
    }

    /// One step done.
    pub fn inc(&self) {
        self.bar.inc(1);
    }

    /// Steps done so far.
    pub fn position(&self) -> u64 {
        self.bar.position()
    }

    /// A line of the run's output on stderr, always printed (above the bar on a terminal).
    pub fn line(&self, line: impl AsRef<str>) {
        self.bar.suspend(|| eprintln!("{}", line.as_ref()));
    }

    /// A line of the run's results on stdout (a `RESULT` line), always printed, the bar
    /// cleared around it.
    pub fn result(&self, line: impl std::fmt::Display) {
        self.bar.suspend(|| println!("{line}"));
    }

    /// The bar is done: removed from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Drop for Progress {
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
    fn a_piped_bar_draws_nothing_but_counts_and_still_prints_its_lines() {
        let p = Progress::with_target(4, "cases", ProgressDrawTarget::hidden());
        assert!(!p.is_drawn());
        for i in 0..4 {
            p.set_message(format!("case {i}"));
            p.inc();
        }
        assert_eq!(p.position(), 4);
        p.finish();
    }
}
