//! Progress bars for the terminal: drawn on stderr only when it is a
//! terminal, never on stdout, and not at all with `--quiet`.

use std::io::IsTerminal;
use std::time::Duration;

use alnlab_common::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar for one stage; hidden when `quiet` or stderr is no terminal.
pub struct Bar {
    bar: ProgressBar,
}

impl Bar {
    /// A bar labelled `label` (e.g. `quickstart/base`).
    pub fn new(label: &str, quiet: bool) -> Bar {
        let target = if quiet || !std::io::stderr().is_terminal() {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        };
        let bar = ProgressBar::with_draw_target(None, target);
        bar.set_prefix(label.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        Bar { bar }
    }
}

impl Progress for Bar {
    fn start(&self, what: &str, total: u64, unit: &str) {
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
