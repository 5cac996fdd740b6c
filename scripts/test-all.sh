#!/usr/bin/env bash
# The whole test suite, as CI runs it. Installs what the suite needs on a fresh Debian machine
# (as root; nothing is installed when everything is already there), then: format check, every
# target built with every feature in the optimised test profile and linted by clippy as it
# compiles, all tests, schemathesis, and the
# Python package (wheel, pytest, example).
set -euo pipefail
cd "$(dirname "$0")/.."
# A fresh build gains nothing from incremental compilation's bookkeeping (≈ 10 % of the crate's
# build here); a developer's own `cargo test` keeps it.
export CARGO_INCREMENTAL=0
# Nor from the test profile's line tables (Cargo.toml keeps them for a developer's backtraces):
# nothing here prints a backtrace (RUST_BACKTRACE is unset; a panic still names its file and
# line), and without them the library and its unit-test harness build with 14 % less CPU each
# (135 and 145 s against 161 and 165 s, interleaved, after a touch).
export CARGO_PROFILE_TEST_DEBUG=false
# The integration tests' allocator (mimalloc, tests/integration.rs) keeps freed memory a minute
# before it goes back to the kernel (mimalloc 3's purge delay, 1 s, times 60), as the binary
# sets it (src/main.rs says why).
export MIMALLOC_ARENA_PURGE_MULT=60

# Each phase says when it starts (seconds since the script began), and the end prints the time of
# every phase and the slowest ten tests: where the suite's time goes, in every CI log.
PHASES=()
phase() {
  PHASES+=("$SECONDS $1")
  echo "== $1 (at ${SECONDS} s)"
}

# Debian packages the features and tests need:
# - aravis: libaravis-dev (+ libusb-1.0-0-dev, which its -dev package forgets), and the fake
#   GigE Vision camera and CLI tools (aravis-tools, aravis-tools-cli);
# - v4l2: libclang-dev (bindgen);
# - the Zaber simulator is checked with zproto, which pulls serialport's libudev feature.
# - iproute2: the Aravis tests bring up loopback inside their own network namespace.
# - python3-venv: the independent dataset generator of the diagnosis tests (tests/independent/,
#   numpy and tifffile from PyPI into target/independent-venv, by scripts/pip-venv.sh);
# - chromium, nodejs, npm: the dashboard's end-to-end test (tests/dashboard_browser.rs) drives
#   headless Chromium with playwright-core, pinned in tests/browser/package-lock.json.
# - curl: tests/schemathesis/run.sh fetches the daemon's OpenAPI document with it.
# - slurmctld, slurmd, munge: tests/sweep_slurm.rs starts a single-node Slurm cluster on
#   localhost (its own slurm.conf, munge key and socket, free ports) and runs a sweep on it.
# - python3-venv also holds the Python package's tests (python/run-tests.sh: maturin, numpy and
#   pytest from PyPI into target/python-venv).
phase "system packages, npm"
APT_PACKAGES=(libaravis-dev libusb-1.0-0-dev aravis-tools-cli aravis-tools libclang-dev libudev-dev pkg-config iproute2 chromium python3-venv curl slurmctld slurmd munge)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
# Node.js may come from elsewhere (NodeSource ships npm inside its nodejs): check the commands.
{ command -v node && command -v npm; } >/dev/null 2>&1 || missing+=(nodejs npm)
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

{ cargo fmt --version && cargo clippy --version; } >/dev/null 2>&1 || rustup component add rustfmt clippy

# The browser test's driver (no browser download: it uses /usr/bin/chromium).
if [ ! -d tests/browser/node_modules ]; then
  echo "npm ci --prefix tests/browser"
  npm ci --prefix tests/browser --no-audit --no-fund
fi

# The three Python venvs — the independent generator's (the diagnosis tests), schemathesis's and
# the Python package's tests' — are made while the crates compile: pip waits on the
# network and the disk more than on the cores, and each venv was on the critical path of its
# phase (18, 25 and 20–35 s here, made one after another on a busy machine). Each script makes
# its venv only when missing or out of date; the tests wait for them below.
VENVS_LOG="$(mktemp "${TMPDIR:-/tmp}/ffdic-venvs.XXXXXX")"
TARGET="${CARGO_TARGET_DIR:-target}"
(bash scripts/pip-venv.sh "$TARGET/independent-venv" tests/independent/requirements.txt "independent generator" &&
  bash scripts/pip-venv.sh target/schemathesis-venv tests/schemathesis/requirements.txt schemathesis &&
  bash scripts/pip-venv.sh "$TARGET/python-venv" python/tests/requirements.txt python) >"$VENVS_LOG" 2>&1 &
VENVS_PID=$!

phase "cargo fmt --check"
cargo fmt --all --check
phase "cargo build of every target, linted by clippy as it compiles"
# The library's unit-test harness at opt-level 0 (the library itself, which the integration
# tests and the binaries run, stays at 3): scripts/rustc-unit-test-harness.sh says why. Exported
# for the wheel's build below too, which reuses this build's artefacts.
export RUSTC_WRAPPER="$PWD/scripts/rustc-unit-test-harness.sh"
# Clippy lints the workspace's crates while they are compiled for the tests, as `cargo clippy`'s
# own driver does in a check: clippy-driver is rustc with clippy's lint passes, and Cargo runs
# it for the workspace's members only (RUSTC_WORKSPACE_WRAPPER; the dependencies are compiled by
# rustc as before), with `-D warnings` through CLIPPY_ARGS as `cargo clippy -- -D warnings`
# passes it. A separate `cargo clippy` checked every dependency a second time in check mode:
# its phase took 112-171 s of the suite's 900-1,170 (docs/performance.md); the lints cost the
# build some 10 s of CPU. clippy-driver builds without MIR optimisations (LLVM still optimises
# at the profile's level): a paper3 round from the test profile's binary took the same time
# either way and wrote the same JSON to the byte. Exported: the wheel's build (below) lints
# the Python crate's cdylib the same way.
export RUSTC_WORKSPACE_WRAPPER
RUSTC_WORKSPACE_WRAPPER="$(command -v clippy-driver)"
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
# Each test's own time: libtest's --report-time, which the stable harness takes when
# RUSTC_BOOTSTRAP=1 is in its environment. Only the test binaries get it, through a runner: in
# cargo's environment it would change the build scripts' fingerprints (proc-macro2's and
# anyhow's probe the compiler's channel) and rebuild their dependants here and again for the wheel.
RUNNER='target."cfg(all())".runner = ["env", "RUSTC_BOOTSTRAP=1"]'
TEST_LOG="$(mktemp "${TMPDIR:-/tmp}/ffdic-tests.XXXXXX")"
ARTIFACTS_LOG="$(mktemp "${TMPDIR:-/tmp}/ffdic-artifacts.XXXXXX")"
trap 'rm -f "$TEST_LOG" "$VENVS_LOG" "$ARTIFACTS_LOG"' EXIT
# Every target the tests run and the benchmarks, with every feature: what `clippy
# --all-targets` checked, but for the two libraries with `test = false`, whose harness nobody
# runs: `ffdic-fft` (no test code of its own) and the Python module, which the wheel's build
# below compiles, and lints, with every feature of its own (its pyo3 and numpy stay in that
# phase, beside schemathesis, instead of on this one's path). Cargo prints its messages as JSON
# on stdout (kept) and the compiler's diagnostics rendered on stderr, as usual.
cargo test --all-features --workspace --tests --bench '*' --no-run --config "$RUNNER" \
  --message-format=json-render-diagnostics >"$ARTIFACTS_LOG"
# Cargo does not count the wrapper in a unit's fingerprint: a member compiled before this run
# (by a plain `cargo test` with the same settings) is fresh here and was not linted now. Then
# clippy checks the workspace as it used to. A fresh clone, as in CI, compiles every member here.
if python3 scripts/fresh-workspace-units.py "$ARTIFACTS_LOG"; then
  echo "every member of the workspace was compiled, and linted, in this build"
else
  echo "cargo clippy (the members above were compiled before this run, unlinted by it)"
  cargo clippy --workspace --all-targets --all-features -- -D warnings
fi
phase "cargo test"
# The venvs (above) before any test starts: the generator's is the tests' to use, not to race.
# Should one have failed, its phase makes it again and fails there with pip's own message.
wait "$VENVS_PID" || { cat "$VENVS_LOG"; echo "a venv failed ahead of its phase (it is made again there)"; }
cat "$VENVS_LOG"
# Doc tests are run by rustdoc, not through the runner: they run apart, without the flag.
# `--tests`: every target with `test = true` (the libraries' and binaries' unit tests, the
# integration tests); the Python module's (`test = false`: it is tested from Python, below) is
# left out, which `--lib` would build as a harness.
# Three tests at a time on two cores: the daemon's tests wait on sockets, timeouts and child
# processes (the suite's first minute, `api_bounded`, kept the cores 35–70 % idle), and with two
# at a time the integration binary left 131 of its 830 core-seconds idle (sampled each second).
# With three it took 378.8 s against 415.1 s within the hour, one run each of the same build (the
# cores 1.91–1.97 busy through the diagnoses against 1.84–1.89; two at a time have taken 369–415 s
# on this machine kind, three 340.2 and 342.3 s in two whole runs of this script); every test
# passed, the ones timed against a second included.
cargo test --all-features --workspace --tests --config "$RUNNER" \
  -- -Z unstable-options --report-time --test-threads 3 2>&1 | tee "$TEST_LOG"
cargo test --all-features --workspace --doc
phase "schemathesis against ffdic serve (every phase, bounded; see tests/schemathesis/), beside the Python package (pip install ./python in a venv, pytest, the example; see python/run-tests.sh)"
# The two side by side: schemathesis kept the cores 1.69 busy and the Python package 1.2 (its
# wheel's compile, then pytest), each alone; side by side they took 93 s against 122 s one after
# the other (88 + 34), one run each of the same build, both passing (schemathesis at 93 s
# against 88 s alone, within its own ten-second bound on a request by far). The package's
# output is held in a file and shown after schemathesis's, each under its own heading.
#
# The wheel reuses what the tests just built: the dev profile with the test profile's settings
# (optimised, debug assertions, no debug info; `--profile test` would build the module as a test
# harness) and python/Cargo.toml's `share-test-build` feature, which resolves the wheel's
# dependency graph as the test build's was resolved. Only pyo3, numpy and the module itself are
# compiled: the phase took 252 s (441 s of CPU) without the feature, 58 s (73 s) with it, one
# after the other on the same build. maturin's `--features` replaces pyproject.toml's list, so
# `extension-module` is named again. A user's `pip install ./python` builds the release profile
# without `share-test-build`.
PYTHON_LOG="$(mktemp "${TMPDIR:-/tmp}/ffdic-python.XXXXXX")"
trap 'rm -f "$TEST_LOG" "$VENVS_LOG" "$ARTIFACTS_LOG" "$PYTHON_LOG"' EXIT
(CARGO_PROFILE_DEV_OPT_LEVEL=3 CARGO_PROFILE_DEV_DEBUG_ASSERTIONS=true CARGO_PROFILE_DEV_DEBUG=false \
  MATURIN_PEP517_ARGS="--profile dev --features extension-module,share-test-build" \
  bash python/run-tests.sh "${CARGO_TARGET_DIR:-target}/debug/ffdic") >"$PYTHON_LOG" 2>&1 &
PYTHON_PID=$!
# The daemon binary the tests just built (test profile, in the target dir cargo used).
schemathesis_status=0
bash tests/schemathesis/run.sh "${CARGO_TARGET_DIR:-target}/debug/ffdic" || schemathesis_status=$?
python_status=0
wait "$PYTHON_PID" || python_status=$?
echo "== the Python package (beside schemathesis): exit $python_status"
cat "$PYTHON_LOG"
[ "$schemathesis_status" -eq 0 ] || { echo "schemathesis failed: exit $schemathesis_status"; exit "$schemathesis_status"; }
[ "$python_status" -eq 0 ] || { echo "the Python package's tests failed: exit $python_status"; exit "$python_status"; }
# The benchmarks are built in the test profile and linted (above) and run by hand (cargo bench):
# their release build (5 min here) proves nothing more.

phase "done"
echo "== time per phase, s"
for ((i = 0; i + 1 < ${#PHASES[@]}; i++)); do
  read -r start name <<<"${PHASES[$i]}"
  read -r end _ <<<"${PHASES[$((i + 1))]}"
  printf '%6d  %s\n' "$((end - start))" "${name%% (*}"
done
echo "== the slowest ten tests, s (wall time of each, beside the others running in parallel)"
# (awk reads to the end: `head` would end the pipe early, and pipefail would fail the suite.)
sed -n 's/^test \(.*\) \.\.\. ok <\([0-9.]*\)s>$/\2 \1/p' "$TEST_LOG" | sort -rn |
  awk 'NR <= 10 { printf "%8.1f  %s\n", $1, $2 }'
