//! Progress bars on standard error for the long steps, every one with its unit (frames,
//! builders, runs) and its rate in that unit; hidden when standard error is not a terminal,
//! so logs and tests see only the lines the commands print.

use indicatif::{ProgressBar, ProgressState, ProgressStyle};
use std::io::IsTerminal;

/// A bar over `len` steps of `unit` (plural, e.g. "frames"), labelled `what`.
pub fn bar(len: u64, unit: &'static str, what: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() || len < 2 {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len);
    let style = ProgressStyle::with_template(&format!(
        "{{msg}} {{wide_bar}} {{pos}}/{{len}} {unit}, {{rate}}, eta {{eta}}"
    ))
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .with_key(
        "rate",
        move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
            let r = s.per_sec();
            let _ = if r >= 1.0 || r == 0.0 {
                write!(w, "{r:.1} {unit}/s")
            } else {
                write!(w, "{:.1} s per step", 1.0 / r)
            };
        },
    );
    b.set_style(style);
    b.set_message(what.to_string());
    b
}

/// A bar over named steps: each [`Steps::start`] counts the step before it as done and shows
/// the new one's name (printed as a line instead when the bar is hidden).
pub struct Steps {
    bar: ProgressBar,
    started: bool,
}

impl Steps {
    /// `len` steps of `unit` (plural), labelled `what`.
    pub fn new(len: u64, unit: &'static str, what: &str) -> Self {
        Self {
            bar: bar(len, unit, what),
            started: false,
        }
    }

    /// Step `name` starts.
    pub fn start(&mut self, name: &str) {
        if std::mem::replace(&mut self.started, true) {
            self.bar.inc(1);
        }
        if self.bar.is_hidden() {
            eprintln!("  {name} ...");
        } else {
            self.bar.set_message(name.to_string());
        }
    }

    /// All steps are done: the bar goes.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
