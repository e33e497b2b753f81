//! Progress bars of the long commands (`run`, `study`, `stress`): drawn on stderr when it is
//! a terminal, hidden otherwise, so that piped output stays plain text for scripts.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::time::Duration;

/// A bar of `len` `unit`s with elapsed time and ETA, or a hidden bar (every call a no-op)
/// when stderr is not a terminal. Clear it with `finish_and_clear` before writing to stderr.
pub fn bar(len: u64, unit: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let template = format!(
        "{{elapsed_precise}} [{{bar:40.cyan/blue}}] {{pos}}/{{len}} {unit} (ETA {{eta}}) {{msg}}"
    );
    let style = ProgressStyle::with_template(&template)
        .expect("a valid template")
        .progress_chars("=> ");
    let bar = ProgressBar::new(len).with_style(style);
    // Steps and stress cases can take seconds each: keep the clock moving between them.
    bar.enable_steady_tick(Duration::from_millis(250));
    // With a ticker installed only the ticker draws: show the bar now, not a tick later, so
    // that a command shorter than one tick still shows where it was.
    bar.force_draw();
    bar
}
