//! Progress bars for long runs (indicatif), on stderr. Quiet when `--json -`
//! makes stdout machine-readable (the contract keeps a run's output to one JSON
//! document there, and a script reading it wants no chatter), and indicatif itself
//! draws nothing when stderr is not a terminal (CI logs, tests).
use indicatif::{ProgressBar, ProgressStyle};
use std::time::Duration;

pub struct Progress(Option<ProgressBar>);

impl Progress {
    /// A bar over `len` steps.
    pub fn bar(len: u64, what: &str, quiet: bool) -> Progress {
        if quiet {
            return Progress(None);
        }
        let pb = ProgressBar::new(len);
        pb.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} {elapsed_precise} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        pb.set_prefix(what.to_string());
        pb.enable_steady_tick(Duration::from_millis(200));
        Progress(Some(pb))
    }

    /// A spinner with elapsed time, for work of unknown length (an LM fit).
    pub fn spinner(what: &str, quiet: bool) -> Progress {
        if quiet {
            return Progress(None);
        }
        let pb = ProgressBar::new_spinner();
        pb.set_style(
            ProgressStyle::with_template("{spinner} {prefix} {elapsed_precise} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        pb.set_prefix(what.to_string());
        pb.enable_steady_tick(Duration::from_millis(120));
        Progress(Some(pb))
    }

    /// Name the step now running.
    pub fn message(&self, msg: &str) {
        if let Some(pb) = &self.0 {
            pb.set_message(msg.to_string());
        }
    }

    /// The number of steps, once known.
    pub fn set_length(&self, len: u64) {
        if let Some(pb) = &self.0 {
            pb.set_length(len);
        }
    }

    pub fn inc(&self) {
        if let Some(pb) = &self.0 {
            pb.inc(1);
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Some(pb) = &self.0 {
            pb.finish_and_clear();
        }
    }
}
