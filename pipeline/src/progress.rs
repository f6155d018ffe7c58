//! Progress for the terminal: drawn on stderr only when it is a terminal,
//! never on stdout, and not at all with `--quiet`. A run shows one overall
//! line (where it is among variants and stages, elapsed time, stages found
//! cached) above the bar of the stage at work.

use std::cell::Cell;
use std::io::IsTerminal;
use std::time::Duration;

use alnlab_common::Progress;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

fn target(quiet: bool) -> ProgressDrawTarget {
    if quiet || !std::io::stderr().is_terminal() {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    }
}

/// A stage at work before it says how much there is to do: a spinner, not
/// an empty bar.
fn waiting() -> ProgressStyle {
    ProgressStyle::with_template("{prefix} {spinner} {elapsed}").expect("valid template")
}

/// The overall line of a run, and the stage bars under it.
pub struct Overall {
    multi: MultiProgress,
    line: ProgressBar,
    cached: Cell<usize>,
}

impl Overall {
    pub fn new(quiet: bool) -> Overall {
        let multi = MultiProgress::with_draw_target(target(quiet));
        let line = multi.add(ProgressBar::new_spinner());
        line.set_style(
            ProgressStyle::with_template("{msg} · {elapsed} elapsed").expect("valid template"),
        );
        line.enable_steady_tick(Duration::from_millis(200));
        Overall {
            multi,
            line,
            cached: Cell::new(0),
        }
    }

    /// Says where the run is: `variant` (e.g. "variant 2 of 4: walk"),
    /// stage `j` of `m` named `stage`.
    pub fn at(&self, variant: &str, (j, m): (usize, usize), stage: &str) {
        let cached = match self.cached.get() {
            0 => String::new(),
            n => format!(" · {n} cached"),
        };
        self.line
            .set_message(format!("{variant} · stage {j} of {m}: {stage}{cached}"));
    }

    /// Counts a stage found in the cache.
    pub fn found_cached(&self) {
        self.cached.set(self.cached.get() + 1);
    }

    /// A bar for one stage, under the overall line.
    pub fn bar(&self, label: &str) -> Bar {
        let bar = self.multi.add(ProgressBar::new_spinner());
        Bar::styled(bar, label)
    }
}

impl Drop for Overall {
    fn drop(&mut self) {
        self.line.finish_and_clear();
    }
}

/// A progress bar for one stage; hidden when `quiet` or stderr is no terminal.
pub struct Bar {
    bar: ProgressBar,
}

impl Bar {
    /// A bar of its own labelled `label` (e.g. `quickstart/base`).
    pub fn new(label: &str, quiet: bool) -> Bar {
        Bar::styled(ProgressBar::with_draw_target(None, target(quiet)), label)
    }

    fn styled(bar: ProgressBar, label: &str) -> Bar {
        bar.set_style(waiting());
        bar.set_prefix(label.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        Bar { bar }
    }
}

impl Progress for Bar {
    fn start(&self, what: &str, total: u64, unit: &str) {
        if total == 0 {
            self.bar.set_style(waiting());
            return;
        }
        self.bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{prefix}} {what:>9} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} ({{eta}})"
            ))
            .expect("valid template")
            .progress_chars("=> "),
        );
        self.bar.set_length(total);
        self.bar.set_position(0);
    }

    fn advance(&self, n: u64) {
        self.bar.inc(n);
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
