//! A terminal progress bar for long runs; silent when stderr is not a terminal or JSON is asked.

use std::io::IsTerminal;

pub struct ProgressBar(Option<indicatif::ProgressBar>);

impl ProgressBar {
    /// A bar on stderr when `enabled` and stderr is a terminal, nothing otherwise.
    pub fn new(enabled: bool, message: &'static str) -> Self {
        if !enabled || !std::io::stderr().is_terminal() {
            return Self(None);
        }
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} ({per_sec}, {eta})",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        bar.set_message(message);
        Self(Some(bar))
    }

    pub fn update(&self, done: usize, total: usize) {
        if let Some(bar) = &self.0 {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.0 {
            bar.finish_and_clear();
        }
    }
}
