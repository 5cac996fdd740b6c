#!/usr/bin/env bash
# The whole test suite, as CI runs it. Installs what the suite needs on a fresh Debian machine
# (as root; nothing is installed when everything is already there), then: format check, clippy
# with every feature and target, all tests in the optimised test profile, schemathesis, a benchmark
# build, and the Python package (wheel, pytest, example).
set -euo pipefail
cd "$(dirname "$0")/.."

# Debian packages the features and tests need:
# - aravis: libaravis-dev (+ libusb-1.0-0-dev, which its -dev package forgets), and the fake
#   GigE Vision camera and CLI tools (aravis-tools, aravis-tools-cli);
# - v4l2: libclang-dev (bindgen);
# - the Zaber simulator is checked with zproto, which pulls serialport's libudev feature.
# - iproute2: the Aravis tests bring up loopback inside their own network namespace.
# - python3-venv: the independent dataset generator of the diagnosis tests (tests/independent/,
#   numpy and tifffile from PyPI into target/independent-venv, made by the tests on first use);
# - chromium, nodejs, npm: the dashboard's end-to-end test (tests/dashboard_browser.rs) drives
#   headless Chromium with playwright-core, pinned in tests/browser/package-lock.json.
# - curl: tests/schemathesis/run.sh fetches the daemon's OpenAPI document with it.
# - slurmctld, slurmd, munge: tests/sweep_slurm.rs starts a single-node Slurm cluster on
#   localhost (its own slurm.conf, munge key and socket, free ports) and runs a sweep on it.
# - python3-venv also holds the Python package's tests (python/run-tests.sh: maturin, numpy and
#   pytest from PyPI into target/python-venv).
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
  echo "== npm ci --prefix tests/browser"
  npm ci --prefix tests/browser --no-audit --no-fund
fi

echo "== cargo fmt --check"
cargo fmt --all --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --all-features -- -D warnings
echo "== cargo test"
cargo test --all-features --workspace
echo "== schemathesis against ffdic serve (every phase, bounded; see tests/schemathesis/)"
# The daemon binary the tests just built (test profile, in the target dir cargo used).
bash tests/schemathesis/run.sh "${CARGO_TARGET_DIR:-target}/debug/ffdic"
echo "== benchmarks compile (they are run by hand: cargo bench)"
cargo bench --no-run --quiet
# After the benchmark build: the wheel's release build reuses the dependencies it compiled.
echo "== Python package: pip install ./python in a venv, pytest, the example (see python/run-tests.sh)"
bash python/run-tests.sh "${CARGO_TARGET_DIR:-target}/debug/ffdic"
