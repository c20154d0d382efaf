//! The progress line of `mems-replay` on stderr: recorded time replayed out of the total,
//! messages sent and their rate. On a terminal it is one line redrawn in place (indicatif);
//! asked for elsewhere (`--progress` into a log), a plain line each second.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::ReplaySummary;

/// How often a plain progress line is written.
const PLAIN_EVERY: Duration = Duration::from_secs(1);

/// The progress display (nothing when stderr is not a terminal and it was not asked for).
pub struct Progress {
    bar: Option<ProgressBar>,
    plain: bool,
    total_ns: u64,
    last: Instant,
}

impl Progress {
    /// A display for a pass of `total_ns` recorded time: on stderr if it is a terminal, or
    /// if `forced` (then as plain lines when it is not one).
    pub fn new(forced: bool, total_ns: u64) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let bar = terminal.then(|| {
            let bar = ProgressBar::with_draw_target(
                Some(total_ns / 1_000_000),
                ProgressDrawTarget::stderr_with_hz(5),
            );
            let style = ProgressStyle::with_template("[{bar:30}] {msg}")
                .expect("a valid template")
                .progress_chars("=> ");
            bar.set_style(style);
            bar
        });
        Self {
            bar,
            plain: forced && !terminal,
            total_ns,
            last: Instant::now(),
        }
    }

    /// The line for `summary`.
    pub fn line(&self, summary: &ReplaySummary) -> String {
        format!(
            "pass {}: {:.1} / {:.1} s recorded, {} messages sent, {:.0} messages/s",
            summary.passes,
            summary.pass_recorded_ns as f64 * 1e-9,
            self.total_ns as f64 * 1e-9,
            summary.total_sent(),
            summary.rate_hz()
        )
    }

    /// Shows `summary` (at most 5 times a second on a terminal, once a second as plain lines).
    pub fn update(&mut self, summary: &ReplaySummary) {
        if let Some(bar) = &self.bar {
            if self.last.elapsed() >= Duration::from_millis(200) {
                self.last = Instant::now();
                bar.set_position(summary.pass_recorded_ns / 1_000_000);
                bar.set_message(self.line(summary));
            }
        } else if self.plain && self.last.elapsed() >= PLAIN_EVERY {
            self.last = Instant::now();
            tracing::info!("{}", self.line(summary));
        }
    }

    /// Shows the final state and leaves the line.
    pub fn finish(&mut self, summary: &ReplaySummary) {
        if let Some(bar) = &self.bar {
            bar.set_position(summary.pass_recorded_ns / 1_000_000);
            bar.finish_with_message(self.line(summary));
        } else if self.plain {
            tracing::info!("{}", self.line(summary));
        }
    }
}
