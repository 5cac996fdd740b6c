//! Logs for the daemon: tracing to stderr, `RUST_LOG` to filter (default `info`); colour only
//! when stderr is a terminal (a log file gets no escape codes).

use std::io::IsTerminal;

pub fn init() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
}

/// For the commands that are not the daemon: logs only when `RUST_LOG` asks for them (their
/// output is the command's own otherwise), with each span's time when it closes. `RUST_LOG=
/// ffdic::diagnose=debug ffdic diagnose DIR` prints where a round spends its time: the measured
/// side, each comparison's print calibration, rendering and DIC, each candidate
/// (docs/performance.md reads them).
pub fn init_if_asked() {
    let Ok(filter) = tracing_subscriber::EnvFilter::try_from_env("RUST_LOG") else {
        return;
    };
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .with_span_events(tracing_subscriber::fmt::format::FmtSpan::CLOSE)
        .try_init();
}
