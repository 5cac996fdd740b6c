//! The model loop as a user waits for it (issue 37): one diagnosis round and three rounds on the
//! independent generator's paper-size dataset (`tests/independent/examples/paper3.json`:
//! 2560x2160, prints a, b and c, a 5 mm move, radial distortion hidden), and `ffdic reproduce`
//! (the README's first command) into an empty data folder. Each runs the `ffdic` binary of this
//! build as a user would; its peak resident memory (the child's `ru_maxrss`) is printed beside
//! divan's times.
//!
//! The dataset is generated once into `target/bench-data/` by the independent generator (Python
//! with numpy, in the venv the diagnosis tests make: `target/independent-venv`). Slow by nature:
//! `cargo bench --bench model_loop` takes some ten minutes on two cores.

#[path = "../tests/common/independent.rs"]
mod independent;

use independent::{repo, target_dir};

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

/// The paper-size dataset, generated on first use into a folder named by the content of its
/// spec and of the generator (another spec or generator is another dataset, not a stale one).
fn paper_dataset() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        use std::hash::{Hash, Hasher};
        let spec_bytes = std::fs::read(repo().join("tests/independent/examples/paper3.json"))
            .expect("paper3.json");
        let generator =
            std::fs::read(repo().join("tests/independent/generate.py")).expect("generate.py");
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        (&spec_bytes, &generator).hash(&mut hasher);
        let dir = target_dir().join(format!("bench-data/indep-paper3-{:016x}", hasher.finish()));
        if !dir.join("dataset.json").is_file() {
            let spec = serde_json::from_slice(&spec_bytes).expect("paper3.json is JSON");
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(dir.parent().expect("bench-data")).expect("bench-data");
            independent::generate(&spec, &dir);
        }
        dir
    })
}

/// Runs `ffdic args…` to its end (quiet, output discarded) and returns its peak resident memory
/// in MB; panics when it fails.
// The child is reaped by `wait4`, which clippy does not know for a wait.
#[allow(clippy::zombie_processes)]
fn ffdic_peak_mb(args: &[&std::ffi::OsStr]) -> f64 {
    let child = Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("ffdic starts");
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value of the plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // The child reaped here rather than by `Child::wait`, which reports no resource usage.
    // SAFETY: `pid` is our own child, not yet waited for; both pointers are to live locals.
    let reaped = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(reaped, pid, "wait4: {}", std::io::Error::last_os_error());
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "ffdic {args:?} failed: status {status}"
    );
    // Linux reports ru_maxrss in KiB.
    usage.ru_maxrss as f64 / 1024.0
}

fn diagnose(bencher: divan::Bencher, rounds: &str) {
    let dir = paper_dataset();
    bencher.bench(|| {
        let peak_mb = ffdic_peak_mb(&[
            "diagnose".as_ref(),
            dir.as_os_str(),
            "--rounds".as_ref(),
            rounds.as_ref(),
            "--json".as_ref(),
        ]);
        eprintln!("diagnose --rounds {rounds}: peak resident memory {peak_mb:.0} MB");
    });
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn diagnosis_one_round_paper_size(bencher: divan::Bencher) {
    diagnose(bencher, "1");
}

#[divan::bench(sample_count = 1, sample_size = 1)]
fn diagnosis_three_rounds_paper_size(bencher: divan::Bencher) {
    diagnose(bencher, "3");
}

#[divan::bench(sample_count = 3, sample_size = 1)]
fn reproduce_into_an_empty_data_folder(bencher: divan::Bencher) {
    bencher
        .with_inputs(|| tempfile::tempdir().expect("a temporary data folder"))
        .bench_values(|data| {
            let peak_mb = ffdic_peak_mb(&[
                "reproduce".as_ref(),
                "--data".as_ref(),
                data.path().as_os_str(),
            ]);
            eprintln!("reproduce: peak resident memory {peak_mb:.0} MB");
            data
        });
}
