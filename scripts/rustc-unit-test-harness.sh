#!/usr/bin/env bash
# RUSTC_WRAPPER for the suite (scripts/test-all.sh): compiles the library's unit-test harness —
# the whole library again, with its `#[cfg(test)]` modules — at opt-level 0 instead of the test
# profile's 3, and passes every other compilation through unchanged. The harness's LLVM passes
# were the build's largest unit: 144.5 s of one core at 3 against 113.7 s at 1 (unit tests 8.9
# and 10.1 s); at 0 it takes 26.9 unit-s against 79.5 at 1 in the same hour, for unit tests of
# 15.9–16.4 s against 9.8–9.9 s, most of it one test of a disk's coverage on one core, whose
# quadrature was then computed once for both renderings it checks: 12.1–14.9 s at 0
# (docs/performance.md). Cargo's profiles cannot tell the harness from the library it tests
# (both are the package `ffdic`), so this is done here; a plain `cargo test` builds both at 3.
# The float results are the same at any opt-level: Rust does not reassociate or contract
# floating-point operations. (Unoptimised, a test found an effect's three parsed expressions
# copied through 600 KB stack frames: `Expression` now boxes them.)
#
# Cargo calls it as `WRAPPER RUSTC ARGS…`.
set -euo pipefail
rustc="$1"
shift
if [[ " $* " == *" --crate-name ffdic "* && " $* " == *" --test "* && " $* " == *" src/lib.rs "* ]]; then
  args=()
  for arg in "$@"; do
    [[ $arg == opt-level=3 ]] && arg=opt-level=0
    args+=("$arg")
  done
  set -- "${args[@]}"
fi
exec "$rustc" "$@"
