#!/usr/bin/env bash
# The Python package as a user installs it, tested: a venv in target/python-venv with the pinned
# test requirements, `pip install ./python` (maturin from PyPI builds the wheel: release profile,
# the workspace's target dir; scripts/test-all.sh asks for the dev profile through
# MATURIN_PEP517_ARGS), pytest over python/tests, then the examples end to end.
#
#   python/run-tests.sh [DAEMON_BINARY]     (default: target/debug/ffdic)
#
# The daemon binary is what the client tests and the example start (`ffdic serve`) and what
# test_engine.py compares the bindings' numbers with (`ffdic analyze`, `simulate`, `compare`).
set -euo pipefail

HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/.." && pwd)"
cd "$ROOT"

VENV="${CARGO_TARGET_DIR:-$ROOT/target}/python-venv"
bash "$ROOT/scripts/pip-venv.sh" "$VENV" "$HERE/tests/requirements.txt" python

BIN="${1:-target/debug/ffdic}"
[ -x "$BIN" ] || { echo "python tests: no daemon binary at $BIN (cargo build --bin ffdic)" >&2; exit 2; }
BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"

echo "python: pip install ./python (at ${SECONDS} s)"
"$VENV/bin/pip" install --quiet --disable-pip-version-check --force-reinstall --no-deps ./python

echo "python: pytest python/tests (at ${SECONDS} s)"
FFDIC_BIN="$BIN" "$VENV/bin/python" -m pytest python/tests -q -p no:cacheprovider

echo "python: the example (python/examples/paper_study.py) on the mock bench (at ${SECONDS} s)"
EXAMPLE_DIR="$(mktemp -d "${TMPDIR:-/tmp}/ffdic-example.XXXXXX")"
trap 'rm -rf "$EXAMPLE_DIR"' EXIT
(cd "$EXAMPLE_DIR" && FFDIC_BIN="$BIN" "$VENV/bin/python" "$ROOT/python/examples/paper_study.py" >example.log 2>&1) || {
  cat "$EXAMPLE_DIR/example.log"; echo "python: the example failed" >&2; exit 1; }
tail -n 5 "$EXAMPLE_DIR/example.log"

echo "python: the Bluesky example (python/examples/bluesky_scan.py) on the mock bench (at ${SECONDS} s)"
(cd "$EXAMPLE_DIR" && FFDIC_BIN="$BIN" "$VENV/bin/python" "$ROOT/python/examples/bluesky_scan.py" >bluesky.log 2>&1) || {
  cat "$EXAMPLE_DIR/bluesky.log"; echo "python: the Bluesky example failed" >&2; exit 1; }
tail -n 8 "$EXAMPLE_DIR/bluesky.log"
echo "python: done (at ${SECONDS} s since this script began)"
