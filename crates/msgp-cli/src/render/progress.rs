//! Fit progress on stderr: an indicatif bar on a terminal, a line every few seconds when stderr
//! is redirected, nothing with `--quiet`.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use msgp_core::fit::FitProgress;

/// Seconds between progress lines when stderr is not a terminal.
const LINE_EVERY: f64 = 10.0;

enum Mode {
    Quiet,
    Bar(ProgressBar),
    Lines { last: Instant },
}

/// Reports one fit.
pub struct FitBar {
    label: String,
    mode: Mode,
    last_iteration: usize,
}

impl std::fmt::Debug for FitBar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FitBar")
            .field("label", &self.label)
            .finish()
    }
}

impl FitBar {
    /// Starts reporting a fit called `label` (e.g. "msgp on dryer").
    pub fn new(label: &str, quiet: bool) -> Self {
        Self::starting(label, quiet, "one-step initialisation")
    }

    /// Starts reporting a fit called `label` whose first stage, until the first solver
    /// iteration, the bar names `stage`.
    pub fn starting(label: &str, quiet: bool, stage: &str) -> Self {
        let mode = if quiet {
            Mode::Quiet
        } else if std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            let style = ProgressStyle::with_template(
                "{spinner} {prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar());
            bar.set_style(style);
            bar.set_prefix(label.to_string());
            bar.set_message(stage.to_string());
            bar.enable_steady_tick(Duration::from_millis(200));
            Mode::Bar(bar)
        } else {
            eprintln!("{label}: fitting");
            Mode::Lines {
                last: Instant::now(),
            }
        };
        Self {
            label: label.to_string(),
            mode,
            last_iteration: 0,
        }
    }

    /// One progress report from `msgp_core::fit::fit`.
    pub fn update(&mut self, p: &FitProgress) {
        let restarted = p.iteration < self.last_iteration;
        self.last_iteration = p.iteration;
        let validation = p
            .validation
            .map_or(String::new(), |v| format!(", validation NLL {v:.4}"));
        match &mut self.mode {
            Mode::Quiet => {}
            Mode::Bar(bar) => {
                if restarted || bar.length() != Some(p.iterations as u64) {
                    bar.set_length(p.iterations as u64);
                }
                bar.set_position(p.iteration as u64);
                bar.set_message(format!("loss {:.4}{validation}", p.loss));
            }
            Mode::Lines { last } => {
                if restarted || last.elapsed().as_secs_f64() >= LINE_EVERY {
                    *last = Instant::now();
                    eprintln!(
                        "{}: iteration {}/{}, loss {:.4}{validation} ({:.1} s)",
                        self.label, p.iteration, p.iterations, p.loss, p.elapsed
                    );
                }
            }
        }
    }

    /// Ends the report with a summary line.
    pub fn finish(self, summary: &str) {
        match self.mode {
            Mode::Quiet => {}
            Mode::Bar(bar) => {
                bar.finish_and_clear();
                eprintln!("{}: {summary}", self.label);
            }
            Mode::Lines { .. } => eprintln!("{}: {summary}", self.label),
        }
    }

    /// Drops the bar without a summary (on errors).
    pub fn abandon(self) {
        if let Mode::Bar(bar) = self.mode {
            bar.finish_and_clear();
        }
    }
}
