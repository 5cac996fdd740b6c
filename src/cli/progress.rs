//! Progress of long runs on stderr: a bar on a terminal; plain lines ("correlating: 40 %
//! (10368/25921)") at every tenth when stderr is a file or a pipe, so a redirected run still
//! shows it is alive; nothing when JSON is asked. Work counted in units (points, frames) shows
//! its counts and a whole-number rate; work known only as a fraction (a run of the service)
//! shows a percentage alone.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};

pub struct ProgressBar(Mode);

enum Mode {
    Off,
    Bar(indicatif::ProgressBar),
    /// The message, the last tenth printed (0 = none yet), and whether the counts are units
    /// of work (printed) or a fraction's thousandths (not).
    Lines(&'static str, AtomicUsize, Units),
}

/// What `update`'s numbers are.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Units {
    Counted,
    Fraction,
}

/// [`ProgressBar::update_fraction`]'s resolution.
const FRACTION_STEPS: usize = 1000;

impl ProgressBar {
    /// Progress on stderr when `enabled`: a bar on a terminal, lines elsewhere.
    pub fn new(enabled: bool, message: &'static str) -> Self {
        Self::with_units(enabled, message, Units::Counted)
    }

    /// [`ProgressBar::new`] for work known only as a fraction done: a percentage, no counts.
    pub fn fraction(enabled: bool, message: &'static str) -> Self {
        Self::with_units(enabled, message, Units::Fraction)
    }

    fn with_units(enabled: bool, message: &'static str, units: Units) -> Self {
        if !enabled {
            return Self(Mode::Off);
        }
        if !std::io::stderr().is_terminal() {
            return Self(Mode::Lines(message, AtomicUsize::new(0), units));
        }
        let template = match units {
            Units::Counted => "{msg} [{bar:40}] {pos}/{len} ({rate}, {eta})",
            Units::Fraction => "{msg} [{bar:40}] {percent} % ({eta})",
        };
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(template)
                .expect("static template")
                .with_key(
                    "rate",
                    |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                        let _ = write!(w, "{:.0}/s", state.per_sec());
                    },
                )
                .progress_chars("=> "),
        );
        bar.set_message(message);
        Self(Mode::Bar(bar))
    }

    /// The fraction done, 0 to 1, of a [`ProgressBar::fraction`].
    pub fn update_fraction(&self, done: f64) {
        let steps = (done.clamp(0.0, 1.0) * FRACTION_STEPS as f64).round() as usize;
        self.update(steps, FRACTION_STEPS);
    }

    pub fn update(&self, done: usize, total: usize) {
        match &self.0 {
            Mode::Off => {}
            Mode::Bar(bar) => {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
            Mode::Lines(message, printed, units) => {
                if let Some(line) = line_for(message, printed, done, total) {
                    match units {
                        Units::Counted => eprintln!("{line} ({done}/{total})"),
                        Units::Fraction => eprintln!("{line}"),
                    }
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
    Some(format!("{message}: {} %", tenth * 10))
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
                "correlating: 10 %",
                "correlating: 30 %",
                "correlating: 90 %",
                "correlating: 100 %"
            ]
        );
        assert!(line_for("x", &AtomicUsize::new(0), 3, 0).is_none());
    }
}
