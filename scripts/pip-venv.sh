#!/usr/bin/env bash
# A Python virtual environment at VENV with the pinned REQUIREMENTS, made when missing or when the
# requirements changed since it was made (a stamp of their sha256 in the venv): the one recipe of
# the test suite's venvs — the independent generator's (tests/common/independent.rs),
# schemathesis's (tests/schemathesis/run.sh), the Python package's tests' (python/run-tests.sh).
# scripts/test-all.sh makes all three ahead, while the crate compiles.
#
#   scripts/pip-venv.sh VENV REQUIREMENTS LABEL
set -euo pipefail

VENV="$1"
REQUIREMENTS="$2"
LABEL="$3"
STAMP="$VENV/.requirements.sha256"
want="$(sha256sum "$REQUIREMENTS" | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "$want" ]; then
  echo "$LABEL: installing the pinned requirements into $VENV"
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --disable-pip-version-check -r "$REQUIREMENTS"
  echo "$want" >"$STAMP"
fi
