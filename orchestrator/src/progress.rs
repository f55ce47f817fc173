//! The one progress bar every long command shows: on stderr, only when it
//! is a terminal and the command is not `--quiet`.

use std::io::IsTerminal as _;

/// A bar of `len` steps of `unit` (`s simulated`, `messages`), hidden when
/// `enabled` is false or stderr is not a terminal.
pub fn bar(enabled: bool, len: u64, unit: &str) -> indicatif::ProgressBar {
    if !enabled || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    let template = format!(
        "{{spinner}} [{{elapsed_precise}}] {{bar:40.cyan/blue}} {{pos:>8}}/{{len}} {unit} ({{per_sec}}, eta {{eta}})"
    );
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar
}
