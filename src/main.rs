//! The `ffdic` binary: a thin clap front over the library.

mod cli;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "ffdic",
    version,
    about = "Fill-factor DIC: camera accuracy from translation experiments"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run 2D DIC on a reference/deformed image pair.
    Analyze(cli::analyze::AnalyzeArgs),
    /// Synthesise a lower fill factor from a full-resolution frame.
    Reduce(cli::reduce::ReduceArgs),
    /// The paper's fill-factor study end to end: Figures 5 and 6.
    Reproduce(cli::reproduce::ReproduceArgs),
    /// Render the frames a camera on the bench would deliver, as a dataset.
    Simulate(cli::simulate::SimulateArgs),
    /// The daemon: bench actor, experiments over HTTP, run store.
    Serve(cli::serve::ServeArgs),
    /// Maintain the run store.
    Store(cli::store::StoreArgs),
    /// DIC of a dataset's frames against the same DIC on the model's frames.
    Compare(cli::compare::CompareArgs),
    /// Fit the effects the model lacks and name the one that is missing.
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// Run a calibration plan on the bench (or take a captured dataset) and write a camera card.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// The discrepancy of a dataset over model versions.
    History(cli::history::HistoryArgs),
    /// Datasets: write one for a folder of frames.
    Dataset(cli::dataset::DatasetArgs),
    /// A design map: error against dot size, fill factor, noise, blur and sub-pixel motion.
    Sweep(cli::sweep::SweepArgs),
}

impl Command {
    /// Whether the command renders and correlates the model's frames over and over (a diagnosis,
    /// a comparison, a calibration, the study's reproduction, the daemon that runs them), holding
    /// hundreds of MB: such a process runs without transparent huge pages
    /// ([`no_transparent_huge_pages`]).
    fn runs_the_model_loop(&self) -> bool {
        match self {
            Command::Reproduce(_)
            | Command::Serve(_)
            | Command::Compare(_)
            | Command::Diagnose(_)
            | Command::Calibrate(_) => true,
            Command::Analyze(_)
            | Command::Reduce(_)
            | Command::Simulate(_)
            | Command::Store(_)
            | Command::History(_)
            | Command::Dataset(_)
            | Command::Sweep(_) => false,
        }
    }
}

/// mimalloc instead of the system's allocator: a diagnosis renders thousands of frames, each dot's
/// footprint a small buffer and each band of rows a large one; glibc's malloc returned the large
/// ones to the kernel and faulted them back in (12 % of a round), mimalloc keeps them (a round on
/// a 640x540 control 19.5 -> 16.3 s).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc hands an arena's freed memory back to the kernel a purge delay after it is freed
/// (mimalloc 3's options: `purge_delay` 1000 ms times `arena_purge_mult` 1, one second). A
/// diagnosis frees a frame's buffers and allocates the next ones further apart than that, and
/// faulted them back in page by page: on the paper-size example ≈ 110,000 page faults and 1.3 s
/// of system time a round, 0.96 ± 0.20 s of its wall time (four interleaved pairs,
/// docs/performance.md). The arenas' multiplier is set so that freed memory is kept a minute:
/// the next frame takes it, and the next round's (with ten seconds, a paper-size
/// `diagnose --rounds 3` faulted 5,000–21,000 pages back in, +1.0 ± 0.2 s of its 15 s), and a
/// finished job, or a daemon's, still gives it back.
fn keep_freed_memory() {
    // `mi_option_purge_delay` and `mi_option_arena_purge_mult` in mimalloc 3's mimalloc.h
    // (libmimalloc-sys 0.1.49 builds mimalloc 3 and names no constant for either).
    const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;
    const ARENA_PURGE_MULT: libmimalloc_sys::mi_option_t = 24;
    const KEEP_FREED_MS: std::os::raw::c_long = 60_000;
    // SAFETY: reads and sets two of mimalloc's options, which it reads when it next purges.
    unsafe {
        let delay_ms = libmimalloc_sys::mi_option_get(PURGE_DELAY);
        // A delay of 0 purges at once and a negative one never: neither is multiplied.
        if delay_ms > 0 {
            libmimalloc_sys::mi_option_set(ARENA_PURGE_MULT, (KEEP_FREED_MS / delay_ms).max(1));
        }
    }
}

/// Transparent huge pages off for this process (and the processes it starts, which inherit the
/// setting), for the commands that run the model loop ([`Command::runs_the_model_loop`]).
/// mimalloc advises its arenas for huge pages, and on this machine kind (Debian, THP and its
/// defrag on `madvise`) a paper-size round faulted some 260 pages of 2 MiB in (its
/// `thp_fault_alloc` in /proc/vmstat) and spent 1.2–1.4 s of system time, ≈ 4.5 ms a page; with
/// pages of 4 KiB, 130,000–150,000 faults and 0.40–0.58 s. Over four interleaved pairs the round
/// was 0.46 ± 0.10 s faster (system time −0.80 ± 0.02 s, user time −0.08 ± 0.22 s: the same), its
/// output the same to the byte. One analysis of a 1280x1080 pair (85 MB) is the other way round:
/// its 40-odd huge pages came in at once, and without them it took 0.084 s against 0.068 s
/// (ten interleaved pairs; docs/performance.md), so `analyze` and the other short commands
/// keep them.
#[cfg(target_os = "linux")]
fn no_transparent_huge_pages() {
    // SAFETY: prctl with PR_SET_THP_DISABLE takes integer arguments only and changes nothing
    // but the process's page-fault policy; a kernel without it returns an error, ignored.
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0);
    }
}

fn main() {
    keep_freed_memory();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(err) if !err.use_stderr() => err.exit(), // --help, --version
        Err(err) => {
            // One line, like every other error of this binary.
            let text = err.render().to_string();
            let message: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
                .filter(|l| !l.is_empty())
                .collect();
            eprintln!("{}", message.join(" "));
            std::process::exit(2);
        }
    };
    if !matches!(cli.command, Command::Serve(_)) {
        cli::logging::init_if_asked();
    }
    #[cfg(target_os = "linux")]
    if cli.command.runs_the_model_loop() {
        no_transparent_huge_pages();
    }
    let outcome = match &cli.command {
        Command::Analyze(args) => cli::analyze::run(args),
        Command::Simulate(args) => cli::simulate::run(args),
        Command::Reproduce(args) => cli::reproduce::run(args),
        Command::Reduce(args) => cli::reduce::run(args),
        Command::Serve(args) => cli::serve::run(args),
        Command::Store(args) => cli::store::run(args),
        Command::Compare(args) => cli::compare::run(args),
        Command::Diagnose(args) => cli::diagnose::run(args),
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::History(args) => cli::history::run(args),
        Command::Dataset(args) => cli::dataset::run(args),
        Command::Sweep(args) => cli::sweep::run(args),
    };
    if let Err(err) = outcome {
        // One line naming the problem: the whole cause chain, each cause once.
        eprintln!("error: {}", cli::error_line(&err));
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Issue 34 (7): `sweep run`/`merge` and `--partition` had empty help. Every subcommand and
    /// every argument of every subcommand, at any depth, says what it is.
    #[test]
    fn every_command_and_argument_has_help() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in cmd.get_arguments() {
                let builtin = matches!(arg.get_id().as_str(), "help" | "version");
                if !builtin && arg.get_help().is_none() && arg.get_long_help().is_none() {
                    missing.push(format!("{path} {}", arg.get_id()));
                }
            }
            for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
                let here = format!("{path} {}", sub.get_name());
                if sub.get_about().is_none() && sub.get_long_about().is_none() {
                    missing.push(here.clone());
                }
                walk(sub, &here, missing);
            }
        }
        let mut missing = Vec::new();
        walk(&Cli::command(), "ffdic", &mut missing);
        assert!(missing.is_empty(), "without help: {missing:#?}");
    }
}
