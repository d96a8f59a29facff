//! Progress bars of a run, all drawn through one process-wide [`MultiProgress`] on stderr, so
//! that whoever writes log lines to the same terminal can lift the bars out of the way first
//! ([`suspend`]) instead of having them redrawn under every line. The command line's log writer
//! does that; a library user who draws nothing needs none of it.
//!
//! indicatif draws only on a terminal: piped or redirected, the bars are silent by themselves.

use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar, ProgressState, ProgressStyle};

fn bars() -> &'static MultiProgress {
    static BARS: OnceLock<MultiProgress> = OnceLock::new();
    BARS.get_or_init(MultiProgress::new)
}

/// A bar of `len` units drawn with `template` (indicatif's template language, plus `{rate}`:
/// units per second with one decimal), or a hidden one when `show` is false. The bar stretches
/// with `{wide_bar}` so that its line never wraps.
pub fn bar(show: bool, len: usize, template: &str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let style = ProgressStyle::with_template(template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .with_key("rate", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{:.1}/s", s.per_sec());
        })
        .progress_chars("█▉▊▋▌▍▎▏ ");
    bars().add(ProgressBar::new(len as u64).with_style(style))
}

/// Runs `f` (a write to the terminal) with every bar cleared first and redrawn after.
pub fn suspend<R>(f: impl FnOnce() -> R) -> R {
    bars().suspend(f)
}
