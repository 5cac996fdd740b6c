#!/usr/bin/env bash
# The independent generator's virtual environment: numpy and tifffile from PyPI, pinned in
# tests/independent/requirements.txt, made when missing or when the requirements changed (a
# stamp of their sha256 in the venv). The diagnosis tests call it on first use
# (tests/common/independent.rs); scripts/test-all.sh calls it ahead, while the crate compiles.
#
#   tests/independent/venv.sh [VENV]     (default: ${CARGO_TARGET_DIR:-target}/independent-venv)
set -euo pipefail

HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
cd "$ROOT"
VENV="${1:-${CARGO_TARGET_DIR:-$ROOT/target}/independent-venv}"

STAMP="$VENV/.requirements.sha256"
want="$(sha256sum "$HERE/requirements.txt" | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "$want" ]; then
  echo "independent generator: installing the pinned requirements into $VENV"
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --disable-pip-version-check -r "$HERE/requirements.txt"
  echo "$want" >"$STAMP"
fi
