//! Progress of long runs on stderr: a bar on a terminal; plain lines ("correlating: 40 %
//! (10368/25921)") at every tenth when stderr is a file or a pipe, so a redirected run still
//! shows it is alive; nothing when JSON is asked.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};

pub struct ProgressBar(Mode);

enum Mode {
    Off,
    Bar(indicatif::ProgressBar),
    /// The message, and the last tenth printed (0 = none yet).
    Lines(&'static str, AtomicUsize),
}

impl ProgressBar {
    /// Progress on stderr when `enabled`: a bar on a terminal, lines elsewhere.
    pub fn new(enabled: bool, message: &'static str) -> Self {
        if !enabled {
            return Self(Mode::Off);
        }
        if !std::io::stderr().is_terminal() {
            return Self(Mode::Lines(message, AtomicUsize::new(0)));
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
        Self(Mode::Bar(bar))
    }

    pub fn update(&self, done: usize, total: usize) {
        match &self.0 {
            Mode::Off => {}
            Mode::Bar(bar) => {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
            Mode::Lines(message, printed) => {
                if let Some(line) = line_for(message, printed, done, total) {
                    eprintln!("{line}");
                }
            }
        }
    }

    pub fn finish(&self) {
        if let Mode::Bar(bar) = &self.0 {
            bar.finish_and_clear();
        }
    }
}

/// The line to print for `done` of `total` when it reaches a tenth not printed yet.
fn line_for(message: &str, printed: &AtomicUsize, done: usize, total: usize) -> Option<String> {
    if total == 0 {
        return None;
    }
    let tenth = (done.min(total) * 10 / total).min(10);
    if tenth == 0 || printed.fetch_max(tenth, Ordering::Relaxed) >= tenth {
        return None;
    }
    Some(format!("{message}: {} % ({done}/{total})", tenth * 10))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_lines_at_each_tenth_once() {
        let printed = AtomicUsize::new(0);
        let lines: Vec<String> = [0, 5, 10, 11, 35, 99, 100, 100]
            .into_iter()
            .filter_map(|d| line_for("correlating", &printed, d, 100))
            .collect();
        assert_eq!(
            lines,
            [
                "correlating: 10 % (10/100)",
                "correlating: 30 % (35/100)",
                "correlating: 90 % (99/100)",
                "correlating: 100 % (100/100)"
            ]
        );
        assert!(line_for("x", &AtomicUsize::new(0), 3, 0).is_none());
    }
}
